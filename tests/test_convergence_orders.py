"""Convergence orders: Theorem 5.1 and the remarks of §5, the GNI family, and the comparators.

Each method integrates the nonholonomic particle to T = 2 with h = T/2^j, and the error is the
largest |q − q_ref| over the common saved times t = 0, 0.5, 1, 1.5, 2, against the continuous
reference (Dopri8 at tolerance 1e-12, landing a step on every save time): one
:func:`gnipy.analysis.convergence_study` of every method. The order is
:func:`gnipy.analysis.fitted_order`, the least-squares slope of log(error) against log(h) on the
points above round-off, and it must match the order the method states (`method.order`):

Thm 5.1 (nonholonomic Euler A/B: 1, also as the GNI with the Euler l_d); Remark 5.1 and [SDD2]
(RATTLE = GNI with the trapezoid l_d: 2); the remark after Thm 5.2 (the composition of Euler A
and B, adjoint to each other, is second order); the GNI midpoint, DLA with the midpoint l_d and the
McLachlan–Perlmutter scheme (4.18) are symmetric: 2.
"""

import numpy as np
import pytest

import gnipy
from gnipy.analysis import ROUND_OFF, convergence_study, fitted_order

T_FINAL = 2.0
SAVES = 4  # saved intervals: t = 0, 0.5, 1, 1.5, 2
STEPS = [2**j for j in range(5, 9)]  # h = T/32 ... T/256
ORDER_TOL = 0.15

METHODS = ["euler-a", "euler-b", "gni-euler-a", "gni-euler-b", "rattle", "euler-ab", "gni-trapezoid",
           "gni-midpoint", "dla", "mp"]


@pytest.fixture(scope="module")
def study():
    spec = gnipy.get_model("nonholonomic-particle")
    return convergence_study(spec.system(), METHODS, spec.q0, spec.v0, t_final=T_FINAL, steps=STEPS, saves=SAVES,
                             measure="q", floor=ROUND_OFF)


def test_fitted_order_recovers_known_slopes():
    hs = 2.0 / 2.0 ** np.arange(5, 10)
    assert abs(fitted_order(hs, 3.0 * hs**2) - 2.0) < 1e-12
    # round-off plateau points are dropped
    assert abs(fitted_order(hs, np.maximum(5.0 * hs**3, 1e-13)) - 3.0) < 1e-12


def test_the_study_measures_against_the_reference(study):
    assert study.yardstick == "reference" and not study.failures
    assert study.steps == tuple(STEPS) and study.saves == SAVES
    # the study's error of one run is the error of that run against the reference at the saved times
    spec = gnipy.get_model("nonholonomic-particle")
    system, q0, v0 = spec.system(), np.asarray(spec.q0), np.asarray(spec.v0)
    ref = gnipy.ContinuousReference().solve(system, q0, v0, np.linspace(0.0, T_FINAL, SAVES + 1))
    n = STEPS[0]
    sol = gnipy.simulate(system, "gni-midpoint", q0, v0, h=T_FINAL / n, steps=n, save_every=n // SAVES)
    np.testing.assert_allclose(np.asarray(sol.t), np.asarray(ref.t), rtol=0, atol=1e-12)
    err = float(np.max(np.abs(np.asarray(sol.q) - np.asarray(ref.q))))
    assert study.errors["gni-midpoint"][0] == pytest.approx(err, rel=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_convergence_order(study, method, capsys):
    expected = gnipy.get_method(method).order
    errors, order = study.errors[method], study.orders[method]
    assert study.expected[method] == expected
    assert study.used_in_fit(method).sum() >= 3, f"fewer than 3 errors above round-off: {errors}"
    order_v = fitted_order(study.h, study.errors_v[method], ROUND_OFF)
    with capsys.disabled():
        print(
            f"\n  {method:14s} order q {order:5.2f}  v {order_v:5.2f}  "
            f"(expected {expected}; |q err| at h=T/{STEPS[0]}: {errors[0]:.2e}, h=T/{STEPS[-1]}: {errors[-1]:.2e})"
        )
    assert abs(order - expected) <= ORDER_TOL, (method, order, errors)
