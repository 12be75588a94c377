"""The theorem table's parts (gnipy.experiments.theorems, .particle_study): the fitted-order rule,
the Cayley steps, the study's runs and the energy theorem's system.

The quick theorem table and errata themselves are checked in tests/experiments/test_reproduce.py,
as `gni reproduce --quick` computes them (one computation for the suite).
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.analysis import fitted_order
from gnipy.experiments import theorems as th
from gnipy.experiments.particle_study import particle, particle_study
from gnipy.experiments.records import all_nodes
from gnipy.lie_groups import SO3
from test_reproduce import PAPER_ORDERS


# ------------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------------
def test_fitted_order_recovers_known_slopes():
    """The table's rule: gnipy.analysis.fitted_order above ROUND_OFF, on at least three points."""
    hs = 2.0 / 2.0 ** np.arange(5, 10)
    assert abs(fitted_order(hs, 3.0 * hs**2, th.ROUND_OFF, min_points=3) - 2.0) < 1e-12
    # round-off dropped
    assert abs(fitted_order(hs, np.maximum(5.0 * hs**3, 1e-13), th.ROUND_OFF, min_points=3) - 3.0) < 1e-12
    assert math.isnan(fitted_order(hs, np.full(5, 1e-14), th.ROUND_OFF, min_points=3))
    assert math.isnan(fitted_order(hs, np.concatenate([3.0 * hs[:2] ** 2, np.full(3, 1e-14)]), th.ROUND_OFF,
                                   min_points=3))


def test_cayley_steps_invert_the_cayley_map():
    rng = np.random.default_rng(0)
    sig = 0.3 * rng.standard_normal((6, 3))
    R, R_right = [np.eye(3)], [np.eye(3)]
    for s in sig:
        S = np.array([[0.0, -s[2], s[1]], [s[2], 0.0, -s[0]], [-s[1], s[0], 0.0]])
        cay = np.linalg.solve(np.eye(3) - S / 2, np.eye(3) + S / 2)
        R.append(R[-1] @ cay)
        R_right.append(cay @ R_right[-1])  # R_{k+1} = cay(σ_k) R_k (e.g. rolling-ball)
    np.testing.assert_allclose(th.cayley_steps(np.array(R)), sig, atol=1e-14)
    np.testing.assert_allclose(th.cayley_steps(np.array(R_right), right=True), sig, atol=1e-14)


def test_study_runs_are_simulate_runs():
    """The study's runs (each takes the steps of the finest h and keeps the nodes up to T) are, node
    by node, gnipy.simulate's runs of their own length; the errors are taken at t = 0, 0.5, ..., 2
    against the continuous reference; the expected orders (the methods' `order`) are the paper's."""
    study = particle_study(True)
    system, q0, v0 = particle()
    N, h = study["Ns"][0], study["hs"][0]
    sol = gnipy.simulate(system, "rattle", q0, v0, h=h, steps=N)
    out = study["runs"]["rattle"][0]
    assert out["q"].shape == (N + 1, 3)
    for k in ("q", "v", "p"):
        np.testing.assert_allclose(out[k], np.asarray(getattr(sol, k)), rtol=0, atol=1e-13)
    ref = gnipy.simulate(system, "reference", q0, v0, h=0.5, steps=4)
    error = float(np.max(np.abs(np.asarray(sol.q)[:: N // 4] - np.asarray(ref.q))))
    assert study["errors"]["rattle"][0] == pytest.approx(error, rel=1e-9, abs=1e-15)
    assert {k: study["expected"][k] for k in PAPER_ORDERS} == PAPER_ORDERS
    assert study["expected"]["euler-ab-literal"] == 1  # the errata: the literal composition
    # the initial condition is checked by simulate (no own check): a v0 off the constraints raises
    with pytest.raises(gnipy.InputError, match="violates the constraints"):
        all_nodes(system, gnipy.get_method("rattle"), q0, v0 + np.array([0.0, 0.0, 0.5]), h=h, steps=N)


def test_energy_theorem_system_is_bi_invariant_with_attitude_dependent_constraints():
    s, R0, v0 = th.energy_theorem_system()
    b = s.initial_point((), np.asarray(SO3().exp(jnp.asarray([0.2, 0.1, -0.4]))))
    np.testing.assert_allclose(np.asarray(s.metric(b)), 1.7 * np.eye(3), atol=1e-15)
    assert np.max(np.abs(np.asarray(s.mu(b)) - np.asarray(s.mu(s.initial_point((), R0))))) > 1e-2
    assert abs(float(np.asarray(s.constraint_residual(s.initial_point((), R0), jnp.asarray(v0)))[0])) < 1e-14
