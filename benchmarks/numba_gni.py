"""The GNI step hand-written in Numba: the speed limit for issue 16's "native backend" benchmark.

This module is the *upper bound* of the per-step benchmark, not a baseline to beat by a large
factor: the same three GNI steps as :mod:`benchmarks.numpy_gni` (and thus as gnipy's GNI), ported
by hand to scalar, allocation-free Numba code the way a performance-minded researcher would write
them for one model. Issue 16's target for gnipy's native backend is to come within 2× of these
timings (µs/step of one trajectory, trajectory-steps/s of a batch). gnipy itself never imports or
uses this module; it exists only for the benchmark and its test
(`tests/test_benchmark_numba.py`, which checks it against numpy_gni and gnipy).

How it was derived. Every formula is numpy_gni's (read its docstring: reflection (Comb), the
discrete Legendre transforms FL⁻/FL⁺ of the trapezoid and midpoint discrete Lagrangians, the Cayley
retraction and dcay⁻¹, the node report p̄, v̄), written out component by component:

- the projectors: $C = \\mu\\mathbb{G}^{-1}\\mu^T$ is 2×2 (balls) or 1×1 (contact oscillator) and is
  inverted in closed form; $\\mathbb{G}$ is diagonal;
- 3×3 matrices (R, cay(σ), dcay⁻¹, the Newton Jacobians) are written as nine scalars, cross products
  and outer products are expanded; the state is kept in a tuple of scalars inside the step loop, so
  the loop allocates nothing;
- the balls' FL⁻ is block diagonal in $z = (x_{k+1}, \\sigma_k)$: its x-part $m(x_{k+1} - x_k)/h$
  is linear, so the increment $\\Delta x = (h/m)p^-_x$ is solved in closed form (what Newton on the
  full 5×5 system does in its first iteration anyway) and Newton runs on the 3×3 σ-part only;
- the unknowns are increments (σ for the balls, $d = q_{k+1} - q_k$ for the oscillator, Δx), and
  FL⁺ is evaluated from the increment itself rather than from the rounded difference
  $x_{k+1} - x_k$: every term of the residual is then O(h) and its round-off that of the increment,
  not that of $q_k$. This is the same map in exact arithmetic; in floating point it keeps the
  trajectory within ~1e-14 of a long-double run of the same scheme over 1000 steps at h = 0.01
  (numpy_gni, which solves for $q_{k+1}$ and differences it, drifts by ~4e-13);
- divisions by h, m and the inertia are kept as divisions outside Newton's update: replacing them
  by products with precomputed reciprocals (1/h is not exact) biases every step the same way and
  was measured to make the drift from gnipy ~1e-13 instead of ~1e-14, for at most ~10% of
  speed (within the timing noise of the 2-core test machine);
- Newton's method on $FL^-(b_k, z) = p^-_k$ uses the analytic Jacobian (numpy_gni's
  `legendre_minus_jacobian`: $I + \\tfrac12(\\hat\\sigma I - \\widehat{I\\sigma}) +
  \\tfrac14((\\sigma^TI\\sigma)E + 2\\sigma\\sigma^TI)$ for the balls, $E + \\tfrac{h^2}{4}\\nabla^2V$ for
  the oscillator, both multiplied by h together with the residual) and a hand-written 3×3 Gaussian
  elimination with partial pivoting, from numpy_gni's (and gnipy's) first guess
  $z_0 = (x_k + h\\dot{\\bar x}_k, h\\bar\\xi_k)$: $\\sigma_0 = h\\bar\\xi_k$ for the balls,
  $d_0 = h\\bar v_k$ (i.e. $q_k + h\\bar v_k$) for the oscillator.

Newton's stopping rule: iterate $z \\leftarrow z + \\delta$ until the update's max-norm satisfies
$\\|\\delta\\|_\\infty \\le 10^{-14}\\max(1, \\|z\\|_\\infty)$ (`NEWTON_TOL`, with z = σ for the balls and
$z = q_{k+1} = q_k + d$ for the oscillator), at most 20 iterations
(`NEWTON_MAXITER`). A step whose Newton iteration has not met the test after 20 iterations (or
produced a non-finite value) returns NaN for the whole state, which then stays NaN: a failure is
never silent. At h = 0.01 Newton takes 2-3 iterations per step.

States (flat float64 vectors, the integrator state, not the reported node):

- balls ("rolling-ball-ex2", "chaplygin-sphere"): 16 numbers `(x, y, R (3×3, row-major), p⁺ (5))`;
- "contact-oscillator" (gni-midpoint): 6 numbers `(q (3), p⁺ (3))`.

API:

- `run_rolling_ball_ex2(state0, h, steps)`, `run_contact_oscillator(state0, h, steps)`,
  `run_chaplygin_sphere(state0, h, steps)` -> the final state (one trajectory; the whole loop is
  compiled);
- `run_rolling_ball_ex2_batch(states0, h, steps)` etc. -> the final states (B, m): `numba.prange`
  over the trajectories (`parallel=True`, all cores);
- the general kernels `run_ball(state0, h, steps, params, chaplygin)` /
  `run_ball_batch(...)` (params `(m, r, I1, I2, I3, Omega)`) and
  `run_oscillator(state0, h, steps, eps)` / `run_oscillator_batch(...)`;
- `CASES[name]` (names as gnipy's models: "rolling-ball-ex2", "contact-oscillator",
  "chaplygin-sphere") -> a :class:`Case` with `initial_state()`, `run(state0, h, steps)`,
  `run_batch(states0, h, steps)`, `observe(state)` (`dict(q, v, p, R)` as numpy_gni's observe:
  the reported node $\\bar v$, $\\bar p$), and `numpy_case`/`method` (numpy_gni's name and method).

Parameters and initial conditions are copied from numpy_gni (so from gnipy's models). All
functions are compiled with `@numba.njit(cache=True, fastmath=False, error_model="numpy")`: IEEE
arithmetic, no reassociation or FMA contraction. Over 1000 steps at h = 0.01 the final nodes agree
with gnipy's to ~1e-14 and with numpy_gni's to ~1e-12 (relative; numpy_gni's own round-off).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "CASES",
    "CHAPLYGIN_PARAMS",
    "EX2_PARAMS",
    "NEWTON_MAXITER",
    "NEWTON_TOL",
    "OSCILLATOR_EPS",
    "Case",
    "get_case",
    "run_ball",
    "run_ball_batch",
    "run_chaplygin_sphere",
    "run_chaplygin_sphere_batch",
    "run_contact_oscillator",
    "run_contact_oscillator_batch",
    "run_oscillator",
    "run_oscillator_batch",
    "run_rolling_ball_ex2",
    "run_rolling_ball_ex2_batch",
]

NEWTON_TOL = 1e-14  # stop when max|δ| <= NEWTON_TOL * max(1, max|z|)
NEWTON_MAXITER = 20

#: (m, r, I1, I2, I3, Omega): numpy_gni.RollingBallEx2.PARAMS (gnipy's rolling_ball.example_2())
EX2_PARAMS = (3.0, 1.0, 1.0, 1.1, 1.2, 0.2)
#: (m, r, I1, I2, I3, Omega): numpy_gni.ChaplyginSphere.PARAMS (gnipy's "chaplygin-sphere")
CHAPLYGIN_PARAMS = (1.0, 1.0, 0.3, 0.4, 0.5, 0.0)
#: epsilon of numpy_gni.ContactOscillator (gnipy's "contact-oscillator")
OSCILLATOR_EPS = 0.3

_JIT = {"cache": True, "fastmath": False, "error_model": "numpy"}
_NAN16 = (math.nan,) * 16
_NAN6 = (math.nan,) * 6


# ---------------------------------------------------------------------------------------------
# 3×3 Gaussian elimination with partial pivoting, on scalars
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def solve3(a00, a01, a02, a10, a11, a12, a20, a21, a22, b0, b1, b2):
    """Solve A u = b for a 3×3 A (row-major scalars) by Gaussian elimination with partial pivoting.

    The pivots' reciprocals are taken once (3 divisions): this only rounds the Newton update, which
    the next iteration corrects, so it changes no result (measured: bit-identical final states)."""
    # column 0: bring the largest |a_i0| to row 0
    if abs(a10) > abs(a00) and abs(a10) >= abs(a20):
        a00, a01, a02, b0, a10, a11, a12, b1 = a10, a11, a12, b1, a00, a01, a02, b0
    elif abs(a20) > abs(a00):
        a00, a01, a02, b0, a20, a21, a22, b2 = a20, a21, a22, b2, a00, a01, a02, b0
    i0 = 1.0 / a00
    f1 = a10 * i0
    f2 = a20 * i0
    a11 -= f1 * a01
    a12 -= f1 * a02
    b1 -= f1 * b0
    a21 -= f2 * a01
    a22 -= f2 * a02
    b2 -= f2 * b0
    # column 1: pivot between rows 1 and 2
    if abs(a21) > abs(a11):
        a11, a12, b1, a21, a22, b2 = a21, a22, b2, a11, a12, b1
    i1 = 1.0 / a11
    f2 = a21 * i1
    a22 -= f2 * a12
    b2 -= f2 * b1
    # back substitution
    u2 = b2 / a22
    u1 = (b1 - a12 * u2) * i1
    u0 = (b0 - a01 * u1 - a02 * u2) * i0
    return u0, u1, u2


# ---------------------------------------------------------------------------------------------
# A ball on a table, R^2 x SO(3), trapezoid l_d (rolling ball ex. 2 and the Chaplygin sphere)
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def _ball_reflect(s, params, chaplygin):
    """(p⁻, p̄) of the ball at state `s` (16-tuple): numpy_gni.reflect_and_report written out.

    μ = [[1, 0, a], [0, 1, c]] with a = (0, −r, 0), c = (r, 0, 0) (rolling ball: constant) or
    a = −r R[1, :], c = r R[0, :] (Chaplygin sphere); G = diag(m, m, I); Π = G Y,
    Y = (−Ω y, Ω x, 0, 0, 0). Returns the 10-tuple (p⁻ (5), p̄ (5)).
    """
    m, r, I1, I2, I3, W = params
    x, y = s[0], s[1]
    if chaplygin:
        a0, a1, a2 = -r * s[5], -r * s[6], -r * s[7]
        c0, c1, c2 = r * s[2], r * s[3], r * s[4]
    else:
        a0, a1, a2 = 0.0, -r, 0.0
        c0, c1, c2 = r, 0.0, 0.0
    # w = G⁻¹(p⁺ − Π)
    w0 = (s[11] - m * (-W * y)) / m
    w1 = (s[12] - m * (W * x)) / m
    w2, w3, w4 = s[13] / I1, s[14] / I2, s[15] / I3
    # C = μG⁻¹μᵀ (2×2, symmetric), μw, λ = C⁻¹μw
    im = 1.0 / m
    C00 = im + a0 * a0 / I1 + a1 * a1 / I2 + a2 * a2 / I3
    C01 = a0 * c0 / I1 + a1 * c1 / I2 + a2 * c2 / I3
    C11 = im + c0 * c0 / I1 + c1 * c1 / I2 + c2 * c2 / I3
    g0 = w0 + a0 * w2 + a1 * w3 + a2 * w4
    g1 = w1 + c0 * w2 + c1 * w3 + c2 * w4
    det = C00 * C11 - C01 * C01
    l0 = (C11 * g0 - C01 * g1) / det
    l1 = (C00 * g1 - C01 * g0) / det
    # Q*(p⁺ − Π) = μᵀλ
    q0, q1 = l0, l1
    q2, q3, q4 = a0 * l0 + c0 * l1, a1 * l0 + c1 * l1, a2 * l0 + c2 * l1
    return (
        s[11] - 2.0 * q0, s[12] - 2.0 * q1, s[13] - 2.0 * q2, s[14] - 2.0 * q3, s[15] - 2.0 * q4,
        s[11] - q0, s[12] - q1, s[13] - q2, s[14] - q3, s[15] - q4,
    )  # fmt: skip


@numba.njit(**_JIT)
def _ball_step(s, h, params, chaplygin):
    """One GNI (trapezoid, Cayley) step of a ball: 16-tuple -> 16-tuple (NaNs if Newton fails)."""
    m, r, I1, I2, I3, W = params
    x, y = s[0], s[1]
    rf = _ball_reflect(s, params, chaplygin)
    pm0, pm1, pm2, pm3, pm4 = rf[0], rf[1], rf[2], rf[3], rf[4]
    # x-part of FL⁻ = p⁻: m (x_{k+1} − x_k)/h = p⁻_x, linear: the increment is (h/m) p⁻_x
    dx = h * pm0 / m
    dy = h * pm1 / m
    # σ-part: h dcay⁻¹_σᵀ(Iσ/h) − h p⁻_ω = Iσ + ½ σ×Iσ + ¼ σ(σ·Iσ) − h p⁻_ω = 0; guess σ = h ξ̄ = h p̄_ω/I
    t0, t1, t2 = h * pm2, h * pm3, h * pm4
    s0, s1, s2 = h * rf[7] / I1, h * rf[8] / I2, h * rf[9] / I3
    ok = False
    for _ in range(NEWTON_MAXITER):
        M0, M1, M2 = I1 * s0, I2 * s1, I3 * s2
        sM = s0 * M0 + s1 * M1 + s2 * M2
        F0 = M0 + 0.5 * (s1 * M2 - s2 * M1) + 0.25 * s0 * sM - t0
        F1 = M1 + 0.5 * (s2 * M0 - s0 * M2) + 0.25 * s1 * sM - t1
        F2 = M2 + 0.5 * (s0 * M1 - s1 * M0) + 0.25 * s2 * sM - t2
        # J = I + ½(σ̂ I − (Iσ)^) + ¼((σᵀIσ)E + 2σ(Iσ)ᵀ)
        q = 0.25 * sM
        J00 = I1 + q + 0.5 * s0 * M0
        J01 = 0.5 * (-s2 * I2 + M2) + 0.5 * s0 * M1
        J02 = 0.5 * (s1 * I3 - M1) + 0.5 * s0 * M2
        J10 = 0.5 * (s2 * I1 - M2) + 0.5 * s1 * M0
        J11 = I2 + q + 0.5 * s1 * M1
        J12 = 0.5 * (-s0 * I3 + M0) + 0.5 * s1 * M2
        J20 = 0.5 * (-s1 * I1 + M1) + 0.5 * s2 * M0
        J21 = 0.5 * (s0 * I2 - M0) + 0.5 * s2 * M1
        J22 = I3 + q + 0.5 * s2 * M2
        d0, d1, d2 = solve3(J00, J01, J02, J10, J11, J12, J20, J21, J22, -F0, -F1, -F2)
        s0 += d0
        s1 += d1
        s2 += d2
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL * max(1.0, abs(s0), abs(s1), abs(s2)):
            ok = True
            break
    if not ok:  # also when an update is NaN (comparisons with NaN are false)
        return _NAN16
    # cay(σ) = E + α(σ̂ + ½σ̂²), σ̂² = σσᵀ − |σ|²E, α = 4/(4 + |σ|²)
    n2 = s0 * s0 + s1 * s1 + s2 * s2
    al = 4.0 / (4.0 + n2)
    ah = 0.5 * al
    g00 = 1.0 + ah * (s0 * s0 - n2)
    g11 = 1.0 + ah * (s1 * s1 - n2)
    g22 = 1.0 + ah * (s2 * s2 - n2)
    g01 = -al * s2 + ah * s0 * s1
    g10 = al * s2 + ah * s0 * s1
    g02 = al * s1 + ah * s0 * s2
    g20 = -al * s1 + ah * s0 * s2
    g12 = -al * s0 + ah * s1 * s2
    g21 = al * s0 + ah * s1 * s2
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10]
    if chaplygin:  # R_{k+1} = R_k cay(σ) (body angular velocity)
        A00, A01, A02, A10, A11, A12, A20, A21, A22 = R00, R01, R02, R10, R11, R12, R20, R21, R22
        B00, B01, B02, B10, B11, B12, B20, B21, B22 = g00, g01, g02, g10, g11, g12, g20, g21, g22
    else:  # R_{k+1} = cay(σ) R_k (space angular velocity)
        A00, A01, A02, A10, A11, A12, A20, A21, A22 = g00, g01, g02, g10, g11, g12, g20, g21, g22
        B00, B01, B02, B10, B11, B12, B20, B21, B22 = R00, R01, R02, R10, R11, R12, R20, R21, R22
    # FL⁺ = (m Δx/h, dcay⁻¹_{−σ}ᵀ M), M = Iσ/h: M − ½σ×M + ¼σ(σ·M)
    M0, M1, M2 = I1 * s0 / h, I2 * s1 / h, I3 * s2 / h
    sM = s0 * M0 + s1 * M1 + s2 * M2
    return (
        x + dx, y + dy,
        A00 * B00 + A01 * B10 + A02 * B20, A00 * B01 + A01 * B11 + A02 * B21, A00 * B02 + A01 * B12 + A02 * B22,
        A10 * B00 + A11 * B10 + A12 * B20, A10 * B01 + A11 * B11 + A12 * B21, A10 * B02 + A11 * B12 + A12 * B22,
        A20 * B00 + A21 * B10 + A22 * B20, A20 * B01 + A21 * B11 + A22 * B21, A20 * B02 + A21 * B12 + A22 * B22,
        m * dx / h, m * dy / h,
        M0 - 0.5 * (s1 * M2 - s2 * M1) + 0.25 * s0 * sM,
        M1 - 0.5 * (s2 * M0 - s0 * M2) + 0.25 * s1 * sM,
        M2 - 0.5 * (s0 * M1 - s1 * M0) + 0.25 * s2 * sM,
    )  # fmt: skip


@numba.njit(**_JIT)
def _ball_loop(state0, h, steps, params, chaplygin, out):
    """`steps` steps from state0 (16,) into out (16,): the state lives in a tuple of scalars."""
    s = (
        state0[0], state0[1], state0[2], state0[3], state0[4], state0[5], state0[6], state0[7],
        state0[8], state0[9], state0[10], state0[11], state0[12], state0[13], state0[14], state0[15],
    )  # fmt: skip
    for _ in range(steps):
        s = _ball_step(s, h, params, chaplygin)
    for i in range(16):
        out[i] = s[i]


@numba.njit(**_JIT)
def run_ball(state0, h, steps, params, chaplygin):
    """`steps` GNI steps of a ball from the flat state0 (16,); returns the final state (16,).

    params = (m, r, I1, I2, I3, Omega); chaplygin: False for the rolling ball (constant μ,
    R_{k+1} = cay(σ)R_k), True for the Chaplygin sphere (μ(R), R_{k+1} = R_k cay(σ)).
    """
    out = np.empty(16)
    _ball_loop(state0, h, steps, params, chaplygin, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_ball_batch(states0, h, steps, params, chaplygin):
    """:func:`run_ball` for each row of states0 (B, 16), in parallel over the rows (all cores)."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, params, chaplygin, out[b])
    return out


@numba.njit(**_JIT)
def ball_observe(state, params, chaplygin):
    """The reported node of a ball state: (x (2), v̄ (5), p̄ (5), R (3, 3))."""
    m, r, I1, I2, I3, W = params
    s = (
        state[0], state[1], state[2], state[3], state[4], state[5], state[6], state[7],
        state[8], state[9], state[10], state[11], state[12], state[13], state[14], state[15],
    )  # fmt: skip
    rf = _ball_reflect(s, params, chaplygin)
    p = np.array([rf[5], rf[6], rf[7], rf[8], rf[9]])
    v = np.array([rf[5] / m, rf[6] / m, rf[7] / I1, rf[8] / I2, rf[9] / I3])
    return state[:2].copy(), v, p, state[2:11].copy().reshape(3, 3)


@numba.njit(**_JIT)
def run_rolling_ball_ex2(state0, h, steps):
    """The rolling ball, example 2 (gni-trapezoid): final state (16,) after `steps` steps."""
    return run_ball(state0, h, steps, EX2_PARAMS, False)


@numba.njit(parallel=True, **_JIT)
def run_rolling_ball_ex2_batch(states0, h, steps):
    """The rolling ball, example 2: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, EX2_PARAMS, False, out[b])
    return out


@numba.njit(**_JIT)
def run_chaplygin_sphere(state0, h, steps):
    """The Chaplygin sphere (gni-trapezoid): final state (16,) after `steps` steps."""
    return run_ball(state0, h, steps, CHAPLYGIN_PARAMS, True)


@numba.njit(parallel=True, **_JIT)
def run_chaplygin_sphere_batch(states0, h, steps):
    """The Chaplygin sphere: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, CHAPLYGIN_PARAMS, True, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# The contact oscillator on R^3, midpoint l_d (gni-midpoint)
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def _osc_reflect(s):
    """(p⁻, p̄) at s = (q, p⁺): μ = (1, 0, y), G = E, Π = 0, C = 1 + y², λ = μp⁺/C, Q*p⁺ = μᵀλ."""
    y = s[1]
    lam = (s[3] + y * s[5]) / (1.0 + y * y)
    ly = y * lam
    return s[3] - 2.0 * lam, s[4], s[5] - 2.0 * ly, s[3] - lam, s[4], s[5] - ly


@numba.njit(**_JIT)
def _osc_step(s, h, eps):
    """One GNI (midpoint) step of the contact oscillator: 6-tuple -> 6-tuple (NaNs if Newton fails).

    With V = ½(|q|² + εx²z²) and the unknown increment d = q_{k+1} − q_k:
    h FL⁻ − h p⁻ = d + (h²/2)∇V(q_k + d/2) − h p⁻ = 0, Jacobian E + (h²/4)∇²V(q_k + d/2);
    FL⁺ = d/h − (h/2)∇V(q_k + d/2). (Solving for d rather than q_{k+1} keeps every term of the
    residual O(h): its round-off is that of d, not of q_k, and FL⁺ uses d itself rather than the
    rounded difference q_{k+1} − q_k.)
    """
    x, y, z = s[0], s[1], s[2]
    rf = _osc_reflect(s)
    t0, t1, t2 = h * rf[0], h * rf[1], h * rf[2]  # h p⁻
    u0, u1, u2 = h * rf[3], h * rf[4], h * rf[5]  # guess d = h v̄ (G = E), i.e. q_{k+1} = q_k + h v̄
    c = 0.5 * h * h
    c4 = 0.25 * h * h
    ok = False
    for _ in range(NEWTON_MAXITER):
        mx, my, mz = x + 0.5 * u0, y + 0.5 * u1, z + 0.5 * u2
        F0 = u0 + c * (mx + eps * mx * mz * mz) - t0
        F1 = u1 + c * my - t1
        F2 = u2 + c * (mz + eps * mx * mx * mz) - t2
        J00 = 1.0 + c4 * (1.0 + eps * mz * mz)
        J02 = c4 * (2.0 * eps * mx * mz)
        J11 = 1.0 + c4
        J22 = 1.0 + c4 * (1.0 + eps * mx * mx)
        d0, d1, d2 = solve3(J00, 0.0, J02, 0.0, J11, 0.0, J02, 0.0, J22, -F0, -F1, -F2)
        u0 += d0
        u1 += d1
        u2 += d2
        # z = q_{k+1} = q_k + d
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL * max(1.0, abs(x + u0), abs(y + u1), abs(z + u2)):
            ok = True
            break
    if not ok:
        return _NAN6
    mx, my, mz = x + 0.5 * u0, y + 0.5 * u1, z + 0.5 * u2
    hh = 0.5 * h
    return (
        x + u0, y + u1, z + u2,
        u0 / h - hh * (mx + eps * mx * mz * mz),
        u1 / h - hh * my,
        u2 / h - hh * (mz + eps * mx * mx * mz),
    )  # fmt: skip


@numba.njit(**_JIT)
def _osc_loop(state0, h, steps, eps, out):
    s = (state0[0], state0[1], state0[2], state0[3], state0[4], state0[5])
    for _ in range(steps):
        s = _osc_step(s, h, eps)
    for i in range(6):
        out[i] = s[i]


@numba.njit(**_JIT)
def run_oscillator(state0, h, steps, eps):
    """`steps` GNI-midpoint steps of the contact oscillator from state0 = (q, p⁺) (6,)."""
    out = np.empty(6)
    _osc_loop(state0, h, steps, eps, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_oscillator_batch(states0, h, steps, eps):
    """:func:`run_oscillator` for each row of states0 (B, 6), in parallel over the rows."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop(states0[b], h, steps, eps, out[b])
    return out


@numba.njit(**_JIT)
def oscillator_observe(state):
    """The reported node of an oscillator state: (q (3), v̄ (3), p̄ (3)) (G = E, so v̄ = p̄)."""
    rf = _osc_reflect((state[0], state[1], state[2], state[3], state[4], state[5]))
    p = np.array([rf[3], rf[4], rf[5]])
    return state[:3].copy(), p.copy(), p


@numba.njit(**_JIT)
def run_contact_oscillator(state0, h, steps):
    """The contact oscillator (gni-midpoint, ε = 0.3): final state (6,) after `steps` steps."""
    return run_oscillator(state0, h, steps, OSCILLATOR_EPS)


@numba.njit(parallel=True, **_JIT)
def run_contact_oscillator_batch(states0, h, steps):
    """The contact oscillator: final states (B, 6), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop(states0[b], h, steps, OSCILLATOR_EPS, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# The Python API
# ---------------------------------------------------------------------------------------------


class Case:
    """One benchmark case: its compiled runs, initial state and node report.

    Attributes:
        name: gnipy's model name; numpy_case, method: numpy_gni's case name and the gnipy method.
        size: the length of the flat state.
    """

    def __init__(self, name, numpy_case, method, size, state0, run, run_batch, observe):
        self.name, self.numpy_case, self.method, self.size = name, numpy_case, method, size
        self._state0, self._run, self._run_batch, self._observe = state0, run, run_batch, observe

    def __repr__(self):
        return f"numba_gni.Case({self.name!r}, {self.method!r})"

    def initial_state(self):
        """The flat float64 start state (numpy_gni's initial_state(), flattened; p⁺₀ = G v₀)."""
        return self._state0.copy()

    def run(self, state0, h, steps):
        """The final state after `steps` steps of size h from `state0` (one trajectory)."""
        return self._run(np.ascontiguousarray(state0, dtype=np.float64), float(h), int(steps))

    def run_batch(self, states0, h, steps):
        """The final states (B, size) from `states0` (B, size), in parallel over the trajectories."""
        states0 = np.ascontiguousarray(states0, dtype=np.float64)
        if states0.ndim != 2 or states0.shape[1] != self.size:
            raise ValueError(f"states0: expected shape (B, {self.size}), got {states0.shape}")
        return self._run_batch(states0, float(h), int(steps))

    def observe(self, state):
        """The reported node `dict(q, v, p, R)` as numpy_gni's observe (v̄, p̄; R None for the oscillator)."""
        return self._observe(np.ascontiguousarray(state, dtype=np.float64))


def _ball_state0(params, q0, v0):
    m, _, I1, I2, I3, _ = params
    p0 = np.array([m, m, I1, I2, I3]) * np.asarray(v0)
    return np.concatenate([np.asarray(q0, dtype=float), np.eye(3).ravel(), p0])


def _ball_observer(params, chaplygin):
    def observe(state):
        q, v, p, R = ball_observe(state, params, chaplygin)
        return {"q": q, "v": v, "p": p, "R": R}

    return observe


def _osc_observe(state):
    q, v, p = oscillator_observe(state)
    return {"q": q, "v": v, "p": p, "R": None}


CASES = {
    "rolling-ball-ex2": Case(
        "rolling-ball-ex2", "rolling_ball_ex2", "gni-trapezoid", 16,
        _ball_state0(EX2_PARAMS, (1.0, 0.0), (0.0, 0.4, -0.2, 0.0, 0.4)),
        run_rolling_ball_ex2, run_rolling_ball_ex2_batch, _ball_observer(EX2_PARAMS, False),
    ),
    "contact-oscillator": Case(
        "contact-oscillator", "contact_oscillator", "gni-midpoint", 6,
        np.array([1.0, 1.0, 1.0, -1.0, 1.0, 1.0]),  # (q0, p⁺0 = v0)
        run_contact_oscillator, run_contact_oscillator_batch, _osc_observe,
    ),
    "chaplygin-sphere": Case(
        "chaplygin-sphere", "chaplygin_sphere", "gni-trapezoid", 16,
        _ball_state0(CHAPLYGIN_PARAMS, (0.0, 0.0), (0.5, -1.0, 1.0, 0.5, 2.0)),
        run_chaplygin_sphere, run_chaplygin_sphere_batch, _ball_observer(CHAPLYGIN_PARAMS, True),
    ),
}  # fmt: skip


def get_case(name):
    """The :class:`Case` called `name` (also accepts numpy_gni's names, e.g. "rolling_ball_ex2")."""
    key = name.replace("_", "-")
    if key not in CASES:
        raise ValueError(f"case: expected one of {tuple(CASES)}, got {name!r}")
    return CASES[key]
