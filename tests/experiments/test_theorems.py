"""The quick theorem table and errata (gnipy.experiments.theorems, .errata, .particle_study).

The expected values are the paper's: the orders of Theorem 5.1, Remark 5.1 and the remark after
Theorem 5.2; zero for the identities (Theorem 5.2, exact constraints, the explicit schemes equal
to the GNI, energy conservation), within round-off bounds derived from the size of the numbers;
and, for the errata, a printed form that fails clearly (> 1e-3) against a corrected form that holds
to round-off (≤ 1e-10). One quick table and one quick errata list are computed for the module.
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

EPS = np.finfo(np.float64).eps
ORDER_TOL = 0.15
# the paper's claims (Theorem 5.1; Remark 5.1, [SDD2]; remark after Theorem 5.2; the GNI variants)
PAPER_ORDERS = {"euler-a": 1, "euler-b": 1, "rattle": 2, "euler-ab": 2, "gni-midpoint": 2,
                "gni-euler-a": 1, "gni-euler-b": 1, "gni-trapezoid": 2}


class _Recorder:
    def __init__(self):
        self.advances, self.descriptions = [], []

    def __call__(self, advance, description):
        self.advances.append(advance)
        self.descriptions.append(description)


@pytest.fixture(scope="module")
def table():
    rec = _Recorder()
    rows = th.theorem_table(quick=True, progress=rec)
    return rows, rec


@pytest.fixture(scope="module")
def errata():
    rec = _Recorder()
    out = th.errata_rows(quick=True, progress=rec)
    return {e.location: e for e in out}, rec


def _rows_with(rows, key):
    return [r for r in rows if key in r.values]


def test_every_row_passes(table):
    rows, _ = table
    assert len(rows) >= 15
    failed = [(r.claim, r.measured, r.detail) for r in rows if not r.passed]
    assert not failed, failed
    for r in rows:
        assert r.claim and r.paper_ref and r.expected and r.measured and r.detail


def test_measured_orders_match_the_paper(table, capsys):
    rows, _ = table
    orders = {r.values["method"]: r.values["order"] for r in _rows_with(rows, "order")}
    assert set(PAPER_ORDERS) <= set(orders)
    with capsys.disabled():
        print("\n  " + "  ".join(f"{k} {v:.3f}" for k, v in orders.items()))
    for method, claim in PAPER_ORDERS.items():
        assert abs(orders[method] - claim) <= ORDER_TOL, (method, orders[method])
    # the order rows' errors decrease monotonically with h (convergence, not noise)
    for r in _rows_with(rows, "order"):
        assert np.all(np.diff(r.values["errors"]) < 0), r.values


def test_theorem_5_2_residual_and_control(table):
    rows, _ = table
    (row,) = [r for r in rows if r.paper_ref == "Theorem 5.2"]
    v = row.values
    assert v["residual"] <= 1e-12  # F_A^h ∘ F_B^{-h} = Id to round-off on M_A
    assert v["manifold_B"] <= 1e-12  # F_B^{-h} maps M_A into itself
    assert v["off_domain"] > 1e-3  # off M_A the identity fails: the domain of the theorem matters
    assert v["manifold_A"] > 1e-4  # F_A^{-h} leaves M_A: it is not the inverse there


def test_reported_momentum_on_the_constraints(table):
    rows, _ = table
    rs = [r for r in _rows_with(rows, "step_velocity_residual")]
    assert {r.values["method"] for r in rs} == {"gni-euler-a", "gni-euler-b", "gni-trapezoid", "gni-midpoint"}
    for r in rs:
        assert r.values["residual"] <= 1e-12
        assert r.values["step_velocity_residual"] > 1e-5  # the check is not vacuous


def test_explicit_schemes_equal_the_gni(table):
    rows, _ = table
    pairs = {r.values["methods"]: r.values["difference"] for r in _rows_with(rows, "difference")}
    assert set(pairs) >= {("euler-a", "gni-euler-a"), ("euler-b", "gni-euler-b"), ("rattle", "gni-trapezoid")}
    # round-off of 256 steps: a few eps per step, accumulated at most linearly (20·N·eps)
    assert max(pairs.values()) <= 20 * 256 * EPS


def test_energy_theorem_quick(table):
    rows, _ = table
    (row,) = [r for r in rows if "drift" in r.values]
    v = row.values
    assert v["steps"] == 10_000
    bound = 25.0 * math.sqrt(10_000) * EPS  # round-off random walk of a few eps per step
    assert v["drift"] <= bound and v["trend"] <= bound
    assert v["constraint_residual"] <= 1e-12
    assert v["reported_energy_variation"] >= 1e-2  # the reflection acts: p̄ is not conserved


def test_progress_advances_add_up_to_one(table, errata):
    for rec in (table[1], errata[1]):
        assert rec.advances and min(rec.advances) >= 0.0
        assert sum(rec.advances) == pytest.approx(1.0, abs=1e-9)
        assert all(isinstance(d, str) and d for d in rec.descriptions)


# ------------------------------------------------------------------------------------------------
# Errata
# ------------------------------------------------------------------------------------------------
def _erratum(errata, where):
    (e,) = [e for loc, e in errata[0].items() if where in loc]
    assert e.printed and e.corrected and e.measurement and math.isfinite(e.evidence_value)
    return e


@pytest.mark.parametrize("where", ["(RBb)", "Remark 5.1", "(Cona)", "(RATc)"])
def test_printed_form_fails_and_corrected_form_holds(errata, where):
    e = _erratum(errata, where)
    assert e.values["printed_residual"] > 1e-3, e.measurement
    assert e.values["corrected_residual"] <= 1e-10, e.measurement
    assert e.evidence_value == e.values["printed_residual"]


def test_sign_of_pi_erratum_details(errata):
    """The printed (RBb) keeps the P* part (equations 1–3) and breaks the rolling constraints."""
    v = _erratum(errata, "(RBb)").values
    assert v["equations_1_3_residual"] <= 1e-12
    assert v["printed_constraint_residual"] > 0.1 and v["corrected_constraint_residual"] <= 1e-12


def test_literal_composition_is_first_order(errata):
    e = _erratum(errata, "composition")
    assert abs(e.values["printed_order"] - 1.0) <= ORDER_TOL
    assert abs(e.values["corrected_order"] - 2.0) <= ORDER_TOL
    assert e.evidence_value == e.values["printed_order"]


def test_all_five_errata_present(errata):
    locs = list(errata[0])
    assert len(locs) == 5
    for key in ["(RBb)", "Remark 5.1", "(Cona)", "composition", "(RATc)"]:
        assert any(key in loc for loc in locs), (key, locs)


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


def test_study_runs_are_simulate_runs(table):
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
