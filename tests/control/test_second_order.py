"""The Hessian of single shooting's Lagrangian by the second-order adjoint
(gnipy.control.second_order), against forward over reverse mode through the whole run (JAX's
`jax.hessian` of the Lagrangian the SQP's functions define: an independent computation of the same
matrix), at the warm start with multipliers that are not the optimum's, on R^n and on
R^2 x SO(3), with a forced start, a smoothness term and methods whose states differ."""

from __future__ import annotations

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.compilation import bind, jit
from gnipy.control.control_arguments import control_arguments, terminal_residual
from gnipy.control.problems import WORKED_PROBLEMS, load_problem
from gnipy.control.shooting import ControlsProblem, SingleShooting
from gnipy.control.sqp import lagrangian_hessian


def _coarse(name: str, steps: int, h: float) -> str:
    text = re.sub(r"^steps = .*$", f"steps = {steps}", WORKED_PROBLEMS[name], flags=re.M)
    return re.sub(r"^h = .*$", f"h = {h!r}", text, flags=re.M)


def _problem(name, steps, h, method=None, running_cost=None):
    p = load_problem(_coarse(name, steps, h))
    a = control_arguments(p.system, steps=p.steps, h=p.h, effort=p.effort, smoothness=p.smoothness, t0=0.0,
                          target_tol=1e-10, kkt_tol=1e-6, running_cost=running_cost, segments=1, max_iterations=10,
                          check_continuous=False, project_v0=False, bounds=p.bounds, progress=False,
                          input_names=None)
    single = SingleShooting.make(p.system, method or p.method, terminal_residual(p.system, p.target),
                                 np.asarray(p.q0), np.asarray(p.v0), p.R0, a, running_cost)
    return ControlsProblem(single, (a.K, a.m)), np.asarray(p.controls0, dtype=float)


@jit
def _forward_over_reverse(problem, x, lam, sigma):
    return jax.hessian(lambda y: sigma * problem.cost(y) + lam @ problem.constraints(y))(x)


@pytest.mark.parametrize("name, steps, h, method", [
    ("sleigh-steering", 12, 0.3, None),  # gni-trapezoid on R^3, a torque bound
    ("sleigh-steering", 8, 0.5, "dla"),  # another method: its state, its start
    ("ball-plate", 10, 0.6, None),  # R^2 x SO(3), two inputs, smoothness, a forced consistent start
])
def test_the_adjoint_hessian_is_forward_over_reverse_modes(name, steps, h, method):
    problem, U0 = _problem(name, steps, h, method)
    x = jnp.asarray(U0.ravel() + 0.05 * np.sin(np.arange(U0.size)))  # not a special point
    d = jax.eval_shape(problem.constraints, x).shape[0]
    lam = jnp.asarray(np.random.default_rng(1).standard_normal(d))
    # what IPOPT is given: the SQP's Hessian program, which takes the problem's own (the adjoint)
    # where it has one (traced abstractly here: run eagerly, the adjoint takes 50 s on the ball)
    assert jax.eval_shape(problem.lagrangian_hessian, x, lam, 0.7) is not None
    H = np.asarray(bind(lagrangian_hessian, problem)(x, lam, jnp.asarray(0.7)))
    reference = np.asarray(_forward_over_reverse(problem, x, lam, jnp.asarray(0.7)))
    assert H.shape == reference.shape == (U0.size, U0.size)
    assert np.max(np.abs(H - reference)) <= 1e-12 * np.max(np.abs(reference))
    assert np.max(np.abs(H - H.T)) <= 1e-12 * np.max(np.abs(reference))

def test_a_running_cost_uses_forward_over_reverse_mode():
    """The second-order adjoint covers a cost that does not run the steps; with a running cost the
    problem declines (None) and the SQP's Hessian is forward over reverse mode."""
    problem, U0 = _problem("sleigh-steering", 6, 0.6, running_cost=lambda q, v, u, t: q[1] ** 2)
    assert problem.lagrangian_hessian(jnp.asarray(U0.ravel()), jnp.zeros(3), 1.0) is None
