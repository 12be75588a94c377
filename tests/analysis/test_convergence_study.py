"""The analysis layer: gnipy.analysis.convergence_study (the study behind `gni convergence`), the
invariant drifts and exact errors, the module's examples, and the order each method states.

The runs share compilations: the vertical disk and the nonholonomic particle over T = 1 with one
saved interval (the step count and h are traced).
"""

import doctest

import numpy as np
import pytest

import gnipy
import gnipy.analysis
from gnipy.analysis import ConvergenceStudy, convergence_study, exact_errors, fitted_order, invariant_drifts

#: numerics (errors, orders, drifts), not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

DISK = gnipy.get_model("vertical-disk")
PARTICLE = gnipy.get_model("nonholonomic-particle")


def _exact(spec):
    params = spec.resolve_params()
    return lambda q0, v0, t: spec.exact(params, q0, v0, t)


@pytest.mark.parametrize("module", ["gnipy.analysis.convergence", "gnipy.analysis.orders"])
def test_the_examples_of_the_docstrings_run(module):
    import importlib

    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted > 0 and result.failed == 0, result


def test_against_the_exact_solution_each_error_is_the_runs_error():
    steps = [10, 20, 40]
    study = convergence_study(DISK.system(), ["gni-trapezoid", "gni-euler-b"], DISK.q0, DISK.v0, t_final=1.0,
                              steps=steps, exact=_exact(DISK))
    assert isinstance(study, ConvergenceStudy)
    assert study.yardstick == "exact" and study.methods == ("gni-trapezoid", "gni-euler-b")
    np.testing.assert_allclose(study.h, [0.1, 0.05, 0.025], rtol=1e-15)
    # the floor: 2·√N·ε times max(1, |state|) against an exact solution
    assert 2 * np.sqrt(40) * np.finfo(float).eps <= study.floor < 1e-12
    params = DISK.resolve_params()
    for i, n in enumerate(steps):  # computed here from a plain run and the exact solution
        sol = gnipy.simulate(DISK.system(), "gni-trapezoid", DISK.q0, DISK.v0, h=1.0 / n, steps=n, save_every=n)
        qe, ve = DISK.exact(params, DISK.q0, DISK.v0, np.asarray(sol.t))
        assert study.errors_q["gni-trapezoid"][i] == pytest.approx(np.max(np.abs(np.asarray(sol.q) - qe)), rel=1e-12)
        assert study.errors_v["gni-trapezoid"][i] == pytest.approx(np.max(np.abs(np.asarray(sol.v) - ve)), rel=1e-12)
    np.testing.assert_array_equal(study.errors["gni-trapezoid"], study.errors_q["gni-trapezoid"])  # measure q
    for name in study.methods:
        assert study.orders[name] == fitted_order(study.h, study.errors[name], study.floor)
        assert study.expected[name] == gnipy.get_method(name).order


def test_rows_are_the_csv_table():
    study = convergence_study(DISK.system(), ["gni-trapezoid"], DISK.q0, DISK.v0, t_final=1.0, steps=[10, 20],
                              exact=_exact(DISK), measure="state")
    rows = study.rows()
    assert [r["steps"] for r in rows] == [10, 20]
    assert list(rows[0]) == ["method", "steps", "h", "t_final", "error", "error_q", "error_v", "used_in_fit",
                             "fitted_order", "expected_order", "yardstick", "measure"]
    for r in rows:
        assert r["error"] == max(r["error_q"], r["error_v"]) and r["measure"] == "state"
        assert r["expected_order"] == 2 and r["yardstick"] == "exact" and r["used_in_fit"] == 1


def test_against_the_reference_with_progress_and_a_failing_method():
    calls = []
    failing = gnipy.GNI(gnipy.Midpoint(), max_steps=1)  # one Newton iteration cannot solve the particle's steps
    study = convergence_study(PARTICLE.system(), [failing, "gni-euler-a"], PARTICLE.q0, PARTICLE.v0, t_final=1.0,
                              steps=[40, 10, 20], progress=lambda *a: calls.append(a))
    assert study.yardstick == "reference" and study.steps == (10, 20, 40)
    assert study.failures == (("gni-midpoint", 0.1), ("gni-midpoint", 0.05), ("gni-midpoint", 0.025))
    assert np.all(np.isnan(study.errors["gni-midpoint"])) and np.isnan(study.orders["gni-midpoint"])
    assert not study.used_in_fit("gni-midpoint").any()
    assert abs(study.orders["gni-euler-a"] - 1) < 0.15
    # the reference and six runs: called before each, and once at the end
    assert [c[:2] for c in calls] == [(k, 7) for k in range(8)]
    assert "reference" in calls[0][2] and "(compiling)" in calls[1][2] and calls[-1][2] == ""


def test_a_custom_discrete_lagrangian_declares_its_order():
    def ld(q0, q1, h):  # the midpoint rule of a free particle of unit mass
        v = (q1 - q0) / h
        return 0.5 * h * (v @ v)

    assert gnipy.GNI(gnipy.CustomDiscreteLagrangian(ld)).order is None
    assert gnipy.GNI(gnipy.CustomDiscreteLagrangian(ld, order=2)).order == 2
    assert gnipy.DiscreteLagrangeDAlembert(gnipy.CustomDiscreteLagrangian(ld, order=2)).order == 2


def test_every_method_states_its_order():
    orders = {name: gnipy.get_method(name).order for name in gnipy.method_names()}
    assert orders.pop("reference") is None
    assert set(orders.values()) <= {1, 2, 4, 6}
    for name, order in orders.items():
        method = gnipy.get_method(name)
        if name.startswith(("gni-", "sgni-")):
            assert order == method.discrete_lagrangian.order
        if isinstance(method, gnipy.Composition):  # the scheme's order, at most 4 on a GNI
            expected = gnipy.integrators.COMPOSITIONS[method.scheme][0]
            assert order == (min(expected, 4) if isinstance(method.base, gnipy.GNI) else expected)


@pytest.mark.parametrize("kwargs, argument", [
    ({"measure": "energy"}, "measure"),
    ({"steps": [10]}, "steps"),
    ({"steps": [10, 10]}, "steps"),
    ({"steps": [10, 15], "saves": 2}, "steps"),
    ({"saves": 0}, "saves"),
    ({"t_final": -1.0}, "t_final"),
    ({"v0": (1.0, 2.0, 3.0)}, "v0"),
])
def test_bad_arguments_name_the_argument(kwargs, argument):
    args = dict(t_final=1.0, steps=[10, 20], v0=PARTICLE.v0) | kwargs
    v0 = args.pop("v0")
    with pytest.raises(gnipy.InputError, match=f"^{argument}"):
        convergence_study(PARTICLE.system(), ["gni-trapezoid"], PARTICLE.q0, v0, **args)


@pytest.mark.parametrize("methods", [["reference"], ["gni-trapezoid", "gni-trapezoid"], [], ["rat"]])
def test_bad_methods_are_refused_before_anything_runs(methods, monkeypatch):
    monkeypatch.setattr(gnipy, "simulate", lambda *a, **k: pytest.fail("ran before checking the methods"))
    with pytest.raises(gnipy.MethodError):
        convergence_study(PARTICLE.system(), methods, PARTICLE.q0, PARTICLE.v0, t_final=1.0, steps=[10, 20])


def test_invariant_drifts_and_exact_errors_of_a_run():
    spec = gnipy.get_model("rotating-table-ball")
    params = spec.resolve_params()
    q0, v0 = spec.initial_condition(params)
    sol = gnipy.simulate(spec.build(params), "gni-trapezoid", q0, v0, h=0.1, steps=10)
    drifts = invariant_drifts(spec, params, sol.q, sol.v)
    assert set(drifts) == set(spec.invariants) and drifts
    for name, f in spec.invariants.items():  # computed here, node by node
        values = [float(f(params, q, v)) for q, v in zip(np.asarray(sol.q), np.asarray(sol.v))]
        assert drifts[name] == pytest.approx(max(abs(x - values[0]) for x in values), abs=1e-15)
    exact = exact_errors(spec, params, sol, q0, v0)
    qe, ve = spec.exact(params, q0, v0, np.asarray(sol.t))
    np.testing.assert_allclose(exact.q, qe)
    assert exact.max_error_q == pytest.approx(np.max(np.abs(np.asarray(sol.q) - qe)), rel=1e-12)
    assert exact.max_error_v == pytest.approx(np.max(np.abs(np.asarray(sol.v) - ve)), rel=1e-12)
    assert exact_errors(PARTICLE, PARTICLE.resolve_params(), sol, q0, v0) is None  # no exact solution


def test_the_package_root_keeps_the_verdicts():
    assert gnipy.EnergyVerdict is gnipy.analysis.EnergyVerdict
    assert gnipy.HiddenMomentumVerdict is gnipy.diagnostics.HiddenMomentumVerdict
