"""Convergence orders: Theorem 5.1 and the remarks of §5, the GNI family, and the comparators.

Each method integrates the nonholonomic particle to T = 2 with h = T/2^j, and the error is the
largest |q − q_ref| over the common saved times t = 0, 0.5, 1, 1.5, 2, against the continuous
reference (Dopri8 at tolerance 1e-12, landing a step on every save time). The order is the
least-squares slope of log(error) against log(h), on the points above round-off.

Expected orders: Thm 5.1 (nonholonomic Euler A/B: 1, also as the GNI with the Euler l_d);
Remark 5.1 and [SDD2] (RATTLE = GNI with the trapezoid l_d: 2); the remark after Thm 5.2 (the
composition of Euler A and B, adjoint to each other, is second order); the GNI midpoint, DLA with
the midpoint l_d and the McLachlan–Perlmutter scheme (4.18) are symmetric: 2.
"""

import numpy as np
import pytest

import gnipy

T_FINAL = 2.0
SAVES = 4  # saved intervals: t = 0, 0.5, 1, 1.5, 2
JS = range(5, 9)  # h = T/32 ... T/256
ORDER_TOL = 0.15
ROUND_OFF = 1e-11  # errors below this are round-off, not truncation (not used in the fit)

EXPECTED = {
    "euler-a": 1,
    "euler-b": 1,
    "gni-euler-a": 1,
    "gni-euler-b": 1,
    "rattle": 2,
    "euler-ab": 2,
    "gni-trapezoid": 2,
    "gni-midpoint": 2,
    "dla": 2,
    "mp": 2,
}


@pytest.fixture(scope="module")
def problem():
    spec = gnipy.get_model("nonholonomic-particle")
    system = spec.system()
    q0, v0 = np.asarray(spec.q0), np.asarray(spec.v0)
    times = np.linspace(0.0, T_FINAL, SAVES + 1)
    ref = gnipy.ContinuousReference().solve(system, q0, v0, times)
    return system, q0, v0, ref


def fitted_order(hs, errors):
    """Least-squares slope of log(error) vs log(h) over the points above round-off."""
    hs, errors = np.asarray(hs), np.asarray(errors)
    keep = errors > ROUND_OFF
    if keep.sum() < 3:
        raise AssertionError(f"fewer than 3 errors above round-off: {errors}")
    return float(np.polyfit(np.log(hs[keep]), np.log(errors[keep]), 1)[0])


def test_fitted_order_recovers_known_slopes():
    hs = 2.0 / 2.0 ** np.arange(5, 10)
    assert abs(fitted_order(hs, 3.0 * hs**2) - 2.0) < 1e-12
    # round-off plateau points are dropped
    assert abs(fitted_order(hs, np.maximum(5.0 * hs**3, 1e-13)) - 3.0) < 1e-12


@pytest.mark.parametrize("method", list(EXPECTED))
def test_convergence_order(problem, method, capsys):
    system, q0, v0, ref = problem
    hs, err_q, err_v = [], [], []
    for j in JS:
        steps = 2**j
        h = T_FINAL / steps
        sol = gnipy.simulate(system, method, q0, v0, h=h, steps=steps, save_every=steps // SAVES)
        np.testing.assert_allclose(np.asarray(sol.t), np.asarray(ref.t), rtol=0, atol=1e-12)
        hs.append(h)
        err_q.append(float(np.max(np.abs(np.asarray(sol.q) - np.asarray(ref.q)))))
        err_v.append(float(np.max(np.abs(np.asarray(sol.v) - np.asarray(ref.v)))))
    order_q = fitted_order(hs, err_q)
    order_v = fitted_order(hs, err_v)
    with capsys.disabled():
        print(
            f"\n  {method:14s} order q {order_q:5.2f}  v {order_v:5.2f}  "
            f"(expected {EXPECTED[method]}; |q err| at h=T/{2 ** JS[0]}: {err_q[0]:.2e}, "
            f"h=T/{2 ** JS[-1]}: {err_q[-1]:.2e})"
        )
    assert abs(order_q - EXPECTED[method]) <= ORDER_TOL, (method, order_q, err_q)
