"""Multiple shooting with every step a segment (gnipy.control.step_shooting, `segments = steps`):
its sparse Jacobian equals JAX's dense derivative of the same constraints (an independent
computation: forward mode through the whole function) on R^n and on R^2 x SO(3) (the orientation's
nine entries, the consistent start's dependence on the first input, the target's orientation), and
its sparse Hessian of the Lagrangian JAX's dense Hessian on R^n; IPOPT on it reaches single shooting's optimum (two transcriptions, two
solvers: SLSQP on the controls, IPOPT on the controls and every state); what it refuses."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.control.control_arguments import control_arguments, terminal_residual
from gnipy.control.problems import load_problem, worked_problem
from gnipy.control.shooting import SingleShooting
from gnipy.control.step_shooting import SparseFunctions, StepShooting
from gnipy.errors import InputError


def _single(problem, running_cost=None):
    a = control_arguments(problem.system, steps=problem.steps, h=problem.h, effort=problem.effort,
                          smoothness=problem.smoothness, t0=0.0, target_tol=1e-10, kkt_tol=1e-6,
                          running_cost=running_cost, segments=problem.steps, max_iterations=10,
                          check_continuous=False, project_v0=False, bounds=problem.bounds, progress=False,
                          input_names=None)
    g = terminal_residual(problem.system, problem.target)
    R0 = None if problem.R0 is None else np.asarray(problem.R0)
    single = SingleShooting.make(problem.system, problem.method, g, np.asarray(problem.q0), np.asarray(problem.v0),
                                 R0, a, running_cost)
    return single, a


@pytest.mark.parametrize("name, steps", [("sleigh-steering", 20), ("ball-plate", 6)])
def test_the_sparse_derivatives_are_the_dense_ones(name, steps):
    """Every entry against JAX's dense derivatives, and nothing outside the structures. The Hessian
    on the sleigh only: its code is the same on a group (the state's layout, the start and the
    target's log are what the group changes, and the Jacobian checks them), and the ball-plate's
    vectorized Hessian of the implicit step takes about 30 s to compile."""
    problem = load_problem(worked_problem(name, steps))
    single, a = _single(problem)
    rng = np.random.default_rng(3)
    U0 = np.clip(0.3 * rng.standard_normal((a.K, a.m)), a.lo, a.hi)
    shooting = StepShooting.make(single, U0)
    n_target = int(np.asarray(single.g(*_final(single, U0))).size)
    F = SparseFunctions.of_steps(shooting, n_target)
    # a point off the trajectories (defects nonzero) and random multipliers: nothing cancels
    x = np.concatenate([U0.ravel(), np.asarray(shooting.s0).ravel()])
    x = x + 1e-2 * rng.standard_normal(x.size)
    c = np.asarray(F.constraints(x))
    assert np.max(np.abs(c[: a.K * shooting.ns])) > 1e-4  # the defects are not zero there
    constraints = jax.jit(jax.vmap(lambda y: shooting.constraints(y)))  # (one compile for the value and jacfwd)
    np.testing.assert_allclose(c, np.asarray(constraints(jnp.asarray(x)[None]))[0], rtol=0, atol=1e-13)
    J = np.asarray(jax.jit(jax.jacfwd(lambda y: shooting.constraints(y)))(jnp.asarray(x)))
    np.testing.assert_allclose(F.constraints_jacobian(x), J, rtol=0, atol=1e-12 * np.max(np.abs(J)))
    rows, cols = F.jacobian_structure  # each nonzero once, every nonzero of J in it
    assert len(set(zip(rows.tolist(), cols.tolist()))) == rows.size
    outside = np.ones(J.shape, dtype=bool)
    outside[rows, cols] = False
    assert not np.any(J[outside])
    if problem.system.group is not None:
        return
    lam, sigma = rng.standard_normal(c.size), 0.7
    H = np.asarray(jax.jit(jax.hessian(lambda y: sigma * shooting.cost(y) + jnp.asarray(lam) @ shooting.constraints(y)))(
        jnp.asarray(x)))
    np.testing.assert_allclose(F.hessian(x, lam, sigma), H, rtol=0, atol=1e-12 * np.max(np.abs(H)))
    hrows, hcols = F.hessian_structure  # IPOPT's lower triangle, each position once, every nonzero in it
    assert np.all(hrows >= hcols) and len(set(zip(hrows.tolist(), hcols.tolist()))) == hrows.size
    lower = np.tril(np.ones(H.shape, dtype=bool))
    lower[hrows, hcols] = False
    assert not np.any(H[lower])
    assert np.array_equal(F.hessian_values(x, lam, sigma), F.hessian(x, lam, sigma)[hrows, hcols])


def _final(single, U):
    from gnipy.control.shooting import final_point

    sol = single.run(U, concrete=True)
    return final_point(single.system, sol), sol.v[-1]


def test_ipopt_on_every_step_reaches_the_single_shooting_optimum():
    problem = load_problem(worked_problem("sleigh-steering", 20))
    single = problem.solve(check_continuous=False)
    steps = dataclasses.replace(problem, optimizer="ipopt", segments=problem.steps).solve(check_continuous=False)
    assert single.success and steps.success, (single.message, steps.message)
    assert steps.message.startswith("IPOPT: ") and "IPOPT failed" not in steps.message
    assert abs(steps.cost - single.cost) <= 1e-9 * single.cost
    np.testing.assert_allclose(steps.controls, single.controls, rtol=0, atol=1e-6)
    assert steps.target_residual <= 1e-10 and steps.kkt_residual <= 1e-6 and steps.bound_multipliers_ok


def test_every_step_refuses_a_running_cost_and_a_state_that_is_not_the_gnis():
    problem = load_problem(worked_problem("sleigh-steering", 4))
    single, a = _single(problem, running_cost=lambda q, v, u, t: jnp.sum(v**2))
    with pytest.raises(InputError, match="segments: every step a segment .* running cost"):
        StepShooting.make(single, np.zeros((a.K, a.m)))
    single, a = _single(dataclasses.replace(problem, method="dla"))
    with pytest.raises(InputError, match=r"segments: .*\(b, p\+\)"):
        StepShooting.make(single, np.zeros((a.K, a.m)))


def test_a_step_whose_solve_fails_stops_the_evaluation():
    """A step whose implicit solve does not converge is NaN in the compiled program (as a compiled
    run leaves NaN nodes), and the optimizer's host side raises SolverFailure instead of handing
    IPOPT a defect computed from an unconverged step (here: the GNI allowed one Newton iteration)."""
    import equinox as eqx

    import gnipy
    from gnipy.errors import SolverFailure

    problem = load_problem(worked_problem("sleigh-steering", 4))
    single, a = _single(problem)
    U0 = np.zeros((a.K, a.m))
    shooting = StepShooting.make(single, U0)
    x = np.concatenate([U0.ravel() + 0.3, np.asarray(shooting.s0).ravel() + 0.1])
    assert np.all(np.isfinite(SparseFunctions.of_steps(shooting, 3).constraints(x)))
    capped = eqx.tree_at(lambda t: t.single.method, shooting, gnipy.GNI(max_steps=1))
    with pytest.raises(SolverFailure, match="not finite at an iterate"):
        SparseFunctions.of_steps(capped, 3).constraints(x)
