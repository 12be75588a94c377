"""The benchmark baselines (benchmarks/) compute what gnipy computes.

The NumPy GNI baseline and the DOP853 right-hand sides are written by hand, independently of
gnipy's automatic differentiation, so agreement checks both formulations. Nothing is timed here.
"""

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnipy
from gnipy.models.rolling_ball import example_2
from gnipy.equations import lagrange_dalembert_acceleration
from gnipy.experiments.particle_study import paper_method

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ is not installed

from benchmarks import continuous, numpy_gni

H, STEPS = 0.1, 50


def _gnipy_case(name):
    """(system, q0, v0, R0) of gnipy's model for a benchmark case."""
    if name == "rolling_ball_ex2":
        system, q0, v0 = example_2()
        return system, q0, v0, None
    spec = gnipy.get_model(name.replace("_", "-"))
    q0, v0 = spec.initial_condition(spec.params)
    return spec.system(), q0, v0, spec.R0


def _rel(a, b):
    """Largest absolute difference relative to the size of the gnipy array `b`."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


CASE_METHODS = [(name, m) for name, (_, methods) in numpy_gni.CASES.items() for m in methods]


@pytest.mark.parametrize("name,method", CASE_METHODS)
def test_numpy_gni_matches_gnipy(name, method):
    system, q0, v0, R0 = _gnipy_case(name)
    # the baseline starts as the paper does, from rest (p⁺₀ = p̄₀)
    sol = gnipy.simulate(system, paper_method(method), q0, v0, R0=R0, h=H, steps=STEPS)
    out = numpy_gni.run(name, STEPS, H, method=method, save_all=True)
    assert out["q"].shape == np.asarray(sol.q).shape
    for key in ("q", "v", "p"):
        assert _rel(out[key], getattr(sol, key)) <= 1e-9, key
    if sol.R is not None:
        assert _rel(out["R"], sol.R) <= 1e-9
    else:
        assert out["R"] is None


def _gnipy_rhs(system):
    """gnipy's continuous equations (those of its "reference" method) as a NumPy f(t, y), jitted."""
    space, N = system.space, system.dim

    @jax.jit
    def f(y):
        b, v = space.unpack(y[:-N]), y[-N:]
        a, _ = lagrange_dalembert_acceleration(system, b, v)
        return jnp.concatenate([space.pack_velocity(b, v), a])

    return lambda t, y: np.asarray(f(jnp.asarray(y)))


@pytest.mark.parametrize("name", list(continuous.CASES))
def test_dop853_rhs_matches_gnipy_equations(name):
    # the same DOP853 run over t = 1 with the hand-written right-hand side and with the equations
    # of gnipy's "reference" method (automatic differentiation of l, mu, Y): the trajectories agree,
    # and so do the right-hand sides at the end point. (Comparing with gnipy.simulate(...,
    # "reference") itself costs a diffrax compile per case, ~4 s each, over this file's budget;
    # it agrees to < 1e-12 at t = 1, and ContinuousCase.reference(t, "gnipy") runs it.)
    case = continuous.get_case(name)
    system, q0, v0, _ = _gnipy_case(name)
    np.testing.assert_array_equal(case.q0, q0)  # the baselines start where gnipy's model does
    np.testing.assert_array_equal(case.v0, v0)
    theirs_rhs = _gnipy_rhs(system)
    ours = case.solve(1.0, 1e-12, 1e-14)
    sol = solve_ivp(theirs_rhs, (0.0, 1.0), case.y0(), method="DOP853", rtol=1e-12, atol=1e-14)
    assert continuous.final_error(ours, case.unpack(sol.y[:, -1])) <= 1e-8
    y = sol.y[:, -1]
    assert _rel(case.rhs(1.0, y), theirs_rhs(1.0, y)) <= 1e-12


def test_tuned_dop853_meets_its_target():
    case = continuous.get_case("contact_oscillator")
    ref = case.reference(2.0)
    rtol, nfev, err = case.tuned_dop853(1e-6, ref, 2.0, refine=2)
    assert err <= 1e-6 and nfev > 0
    out = case.solve(2.0, rtol, rtol * 1e-3)
    assert continuous.final_error(out, ref) == err
