"""The figures of paper §7.4 (gnipy.experiments.figures): the derivations behind their expected
numbers, and the checks that need no run of a figure. The figures' own numbers are checked in
tests/experiments/test_reproduce.py, on the figures `gni reproduce --quick` computes.

Every expected number comes from theory or from the exact solution, never from an earlier run:

- Example 1 (homogeneous ball, V = 0, constant metric): the paper's Euler A discrete Lagrangian
  h·l(q_k, Δ, ω_k) does not depend on q_k, so it *is* the trapezoid l_d (checked below) and the GNI is
  the reduced RATTLE, a symmetric method: order 2 in position, ω and energy.
- DLA [IMMM]: positions order 2 (a symmetric two-step scheme), but the velocity it reports,
  𝔾⁻¹p⁺_k = FL⁺ of the previous step, is the velocity at t_k − h/2 up to O(h²): its ω error is
  (h/2)|ω̇| + O(h²), and for the exact circular motion |ω̇| = (Ω − κ)|ż₀| is constant.
- Figure 2: the exact contact point runs round the circle of centre z₀ + iż₀/κ and radius |ż₀|/κ;
  an order-2 method stays within O(h²) of it, so halving h divides the distance by 4.
- Figure 3: the momentum start gives the order-2 GNI; the paper's start perturbs σ₀ by
  −(h²/2)I⁻¹(ω⁰ × Iω⁰) + O(h³) and so p⁺₁ by O(h): order 1 in position and ω (caption: 1, 1, 2).
"""

import math

import numpy as np
import pytest

import gnipy
from gnipy.experiments import figures as F
from gnipy.experiments.figure_tools import asymptotic_order, observed_order
from gnipy.models import rolling_ball as rb
from gnipy.spaces import Point


def test_figure_1_euler_a_is_the_trapezoid_here():
    """The derivation behind the expected order 2: with V = 0 and a constant metric, h·l(q_k, Δ, ω)
    equals h·(l(q_k, Δ, ω) + l(q_{k+1}, Δ, ω))/2 for any step."""
    s = rb.build_system(rb.DEFAULT_PARAMS)
    rng = np.random.default_rng(0)
    b0 = Point(rng.standard_normal(2), np.asarray(gnipy.SO3().exp(rng.standard_normal(3))))
    z = rng.standard_normal(5)
    a, t = float(gnipy.EulerA()(s, b0, z, 0.1)), float(gnipy.Trapezoid()(s, b0, z, 0.1))
    assert a == pytest.approx(t, rel=1e-15)


def test_figure_3_paper_start_first_step():
    """The paper's start agrees with the GNI's own first step in (x₁, y₁) and differs in σ₀ by
    −(h²/2)I⁻¹(ω⁰ × Iω⁰) + O(h³)."""
    s, q0, v0 = rb.example_2()
    w0 = np.asarray(rb.EXAMPLE_2["omega0"])
    inertia = np.array([1.0, 1.1, 1.2])
    h = 0.01
    sol = gnipy.simulate(s, gnipy.GNI(gnipy.EulerA(), start="rest"), q0, v0, h=h, steps=1)  # the momentum start's first step
    x1, Rm = np.asarray(sol.q)[1], np.asarray(sol.R)[1]
    start = F.paper_start(s, q0, w0, h)
    np.testing.assert_allclose(np.asarray(start.b.x), x1, rtol=0, atol=1e-15)
    S = 2.0 * (Rm - np.eye(3)) @ np.linalg.inv(Rm + np.eye(3))  # Cayley inverse
    sigma = np.array([S[2, 1], S[0, 2], S[1, 0]])
    predicted = h * w0 - 0.5 * h**2 * np.cross(w0, inertia * w0) / inertia
    assert np.max(np.abs(sigma - predicted)) < 0.1 * h**3
    assert np.max(np.abs(sigma - h * w0)) > 0.9 * np.max(np.abs(predicted - h * w0))  # the h² term is seen


def test_figure_3_paper_start_continues_with_the_gni_step():
    """A run continued from the paper's start (state0 at node 1, t0 = h) takes the GNI's steps from
    (b₁, p⁺₁): its node 2 is one step of the GNI from that state, whatever the run's length."""
    s, q0, _ = rb.example_2()
    w0 = np.asarray(rb.EXAMPLE_2["omega0"])
    h = 0.05
    method = gnipy.GNI(gnipy.EulerA())
    start = F.paper_start(s, q0, w0, h)
    one = gnipy.simulate(s, method, state0=start, t0=h, h=h, steps=1)
    long = gnipy.simulate(s, method, state0=start, t0=h, h=h, steps=20, saveat=gnipy.SaveAt(ts=[2 * h, 21 * h]))
    assert np.asarray(long.t) == pytest.approx([2 * h, 21 * h], rel=1e-12)
    np.testing.assert_array_equal(np.asarray(one.q)[-1], np.asarray(long.q)[0])
    np.testing.assert_allclose(np.asarray(one.q)[0], np.asarray(start.b.x), rtol=0, atol=0)  # node 1 is the start


def test_fitted_order_leaves_out_round_off():
    """The figures' slopes: gnipy.analysis.fitted_order with stop_at_minimum=True, and over the
    three smallest fitted h for the 'finest 3' slopes."""
    hs = np.array([0.1, 0.05, 0.025, 0.0125, 0.00625])
    errors = 3.0 * hs**2
    assert observed_order(hs, errors) == pytest.approx(2.0, abs=1e-12)
    # a floor, and a point past the smallest error (round-off growing again), are left out
    errors_ro = np.concatenate([errors[:4], [1e-2]])
    assert observed_order(hs, errors_ro) == pytest.approx(2.0, abs=1e-12)
    assert observed_order(hs, errors, floor=3.0 * 0.025**2 * 0.99) == pytest.approx(2.0, abs=1e-12)
    assert math.isnan(observed_order(hs, errors, floor=1.0))
    # the finest three: slope 1 there although the coarse points have slope 2
    mixed = np.where(hs > 0.03, 3.0 * hs**2, 3.0 * 0.025 * hs)
    assert asymptotic_order(hs, mixed) == pytest.approx(1.0, abs=1e-12)
    assert observed_order(hs, mixed) > 1.2
