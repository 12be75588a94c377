"""The paper's explicit schemes (§5, §6.1) against the GNI core, the paper's two-step form, and
Theorem 5.2.

Every expected value is exact, an invariant of the scheme, or produced by an independent
formulation: the GNI core (reflection + discrete Legendre transforms) and the explicit maps of
`gnipy.integrators.paper_schemes` are written separately, and the Lagrangian two-step equations
(EuALag), (EuBLag), (Afin) are checked on the saved trajectories with plain numpy.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
# equinox's filter_jit with gnipy's compiler options (simulate's own): about half the compile time
from gnipy.compilation import jit
from gnipy.experiments.identities import constrained_tilde_states
from gnipy.integrators import paper_schemes as ps
from gnipy.integrators.shake import Shake
from gnipy.integrators.base import MethodError

H = 0.02
STEPS = 1000  # one step count for every trajectory: one compile per (system, method)
EPS = np.finfo(np.float64).eps

from shared_systems import cached_runner, BALL, BALL_Q0, BALL_V0, CURVED, PARTICLE, PARTICLE_Q0, PARTICLE_V0  # noqa: E402

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

CASES = {"linear": (PARTICLE, PARTICLE_Q0, PARTICLE_V0), "affine": (BALL, BALL_Q0, BALL_V0)}


@pytest.fixture(scope="module")
def run():
    """`run(case, method)`: a cached `gnipy.simulate` of STEPS steps, every node saved."""
    return cached_runner(CASES, H, STEPS)


def _rel(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


# --------------------------------------------------------------------------------------------
# The explicit schemes are the GNI
# --------------------------------------------------------------------------------------------
PAIRS = [("gni-euler-a", "euler-a"), ("gni-euler-b", "euler-b"), ("gni-trapezoid", "rattle"), ("gni-trapezoid", "shake")]


@pytest.mark.parametrize("case", ["linear", "affine"])
@pytest.mark.parametrize("gni_name,explicit_name", PAIRS)
def test_explicit_scheme_reproduces_gni(run, case, gni_name, explicit_name):
    """Same q_k, reported v_k and p_k as the GNI core over 1000 steps (relative ≤ 1e-12), both from the
    paper's start (the GNI from rest, p⁺₀ = p̄₀)."""
    g, e = run(case, gni_name, start="rest"), run(case, explicit_name)
    assert e.result == 0 and e.method == explicit_name
    assert g.q.shape == e.q.shape == (STEPS + 1, CASES[case][0].n)
    assert _rel(e.q, g.q) <= 1e-12
    assert _rel(e.v, g.v) <= 1e-12
    assert _rel(e.p, g.p) <= 1e-12
    # the explicit schemes take no Newton iterations
    assert np.asarray(e.iterations).tolist() == [0, 0]


@pytest.mark.parametrize("case", ["linear", "affine"])
def test_variants_are_distinguishable(run, case):
    """The agreement above is not vacuous: Euler A, Euler B and RATTLE differ at O(h)."""
    a, b, r = run(case, "euler-a"), run(case, "euler-b"), run(case, "rattle")
    assert _rel(a.q, b.q) > 1e-4
    assert _rel(a.q, r.q) > 1e-4
    assert _rel(b.q, r.q) > 1e-4


@jit
def _node_data(system, q):
    """V_q, μ and Y at a batch of configurations."""
    return jax.vmap(lambda x: (system.potential_gradient(x), system.mu(x), system.Y(x)))(q)


@pytest.mark.parametrize("case", ["linear", "affine"])
@pytest.mark.parametrize("name,s", [("euler-a", 1.0), ("euler-b", -1.0), ("rattle", 0.0)])
def test_trajectory_solves_two_step_lagrangian_form(run, case, name, s):
    """The saved q_k solve the paper's Lagrangian two-step equations, checked with numpy.

    (EuALag)/(EuBLag)/(Afin): with a_k = (q_{k+1} − 2q_k + q_{k−1})/h² + M⁻¹V_q(q_k),
    a_k ∈ span(M⁻¹μᵀ) (P a_k = 0, i.e. (EuALaga) for some λ̃_k) and
    μ(q_k)((q_{k+1} − q_{k−1})/2h + s (h/2) M⁻¹V_q(q_k) − Y(q_k)) = 0 ((EuALagb), (EuBLagb), (Afinb)),
    s = +1, −1, 0. The same equations with the wrong sign of s must fail (checks the test).
    """
    system, _, _ = CASES[case]
    q = np.asarray(run(case, name).q)
    qm, qk, qp = q[:-2], q[1:-1], q[2:]
    M = np.asarray(system.metric(jnp.asarray(qk[0])))
    Minv = np.linalg.inv(M)
    Vq, mu, Y = (np.asarray(a) for a in _node_data(system, jnp.asarray(qk)))
    acc = (qp - 2 * qk + qm) / H**2 + Vq @ Minv.T
    # P = I − M⁻¹μᵀC⁻¹μ applied to acc
    Minv_muT = np.einsum("ij,klj->kil", Minv, mu)
    C = np.einsum("kaj,kjb->kab", mu, Minv_muT)
    Pacc = acc - np.einsum("kia,ka->ki", Minv_muT, np.linalg.solve(C, np.einsum("kaj,kj->ka", mu, acc)[..., None])[..., 0])
    # round-off of a second difference: eps |q| / h²
    scale_acc = np.max(np.abs(q)) / H**2
    assert np.max(np.abs(Pacc)) <= 100 * EPS * scale_acc
    vel = (qp - qm) / (2 * H)

    def constraint(sign):
        return np.einsum("kaj,kj->ka", mu, vel + sign * 0.5 * H * Vq @ Minv.T - Y)

    scale_vel = np.max(np.abs(q)) / H
    assert np.max(np.abs(constraint(s))) <= 100 * EPS * scale_vel
    wrong = -1.0 if s >= 0 else 1.0
    assert np.max(np.abs(constraint(wrong))) > 1e-4


@jit
def _gni_composition(system, q0, v0, h, n):
    """q_0..q_n of the GNI core composed: G_A^{h/2} ∘ G_B^{h/2} on (q, p⁺) (GNI with L_B, then L_A)."""
    ga, gb = (gnipy.GNI(gnipy.EulerA(), explicit=True, start="rest"),
              gnipy.GNI(gnipy.EulerB(), explicit=True, start="rest"))

    def body(state, _):
        state = ga.step(system, gb.step(system, state, 0.5 * h)[0], 0.5 * h)[0]
        return state, ga.observe(system, state, 0.5 * h)

    state0 = ga.init(system, q0, v0, h)
    _, (q, v, _) = jax.lax.scan(body, state0, None, length=n)
    q0_, v0_, _ = ga.observe(system, state0, 0.5 * h)
    return jnp.concatenate([q0_[None], q]), jnp.concatenate([v0_[None], v])


@pytest.mark.parametrize("case", ["linear", "affine"])
def test_composition_is_the_composed_gni_and_not_rattle(run, case):
    """euler-ab equals the GNI core composed (Euler B then Euler A at h/2) to round-off, and
    differs from RATTLE clearly above round-off (Remark after Thm 5.2)."""
    system, q0, v0 = CASES[case]
    c, r = run(case, "euler-ab"), run(case, "rattle")
    assert c.result == 0
    q_ref, v_ref = _gni_composition(system, jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(H), STEPS)
    assert _rel(c.q, q_ref) <= 1e-12
    assert _rel(c.v, v_ref) <= 1e-12
    # round-off between equal schemes is ~1e-13 (tests above); the two differ at O(h²)
    assert _rel(c.q, r.q) > 1e-7
    assert _rel(c.q, r.q) < 1e-2


# --------------------------------------------------------------------------------------------
# Theorem 5.2: the nonholonomic Euler A and B methods are each other's adjoint
# --------------------------------------------------------------------------------------------
def _random_states(system, n_states, h, sign, seed):
    """Random (q, p̃, λ̃) (standard normal) with μM⁻¹(p̃ + sign (h/2) V_q − Π) = 0 (p̃ projected
    M⁻¹-orthogonally, in one compiled program): the theorem table's sampler."""
    return constrained_tilde_states(system, n_states, h, sign, seed)


@jit
def _round_trip(system, first, second, states, h):
    """second^{h}(first^{-h}(state)) for a batch of states, and the intermediate first^{-h}(state)."""

    def both(s):
        mid = first(system, s, -h)
        return second(system, mid, h), mid

    return jax.vmap(both)(states)


def _max_rel(out, states):
    return max(
        float(jnp.max(jnp.abs(a - b)) / jnp.maximum(1.0, jnp.max(jnp.abs(b)))) for a, b in zip(out, states) if b is not None
    )


@pytest.mark.parametrize("case", ["linear", "affine"])
@pytest.mark.parametrize("h", [0.1, 0.01])
def test_theorem_5_2_euler_a_after_euler_b_reversed_is_identity(case, h):
    """F_A^h ∘ F_B^{−h} = Id on states where F_B^{−h} is defined: μM⁻¹(p̃ + (h/2)V_q − Π) = 0."""
    system = CASES[case][0]
    for seed in range(3):
        states = _random_states(system, 64, h, +1.0, seed)
        out, mid = _round_trip(system, ps.euler_b_map, ps.euler_a_map, states, jnp.asarray(h))
        assert _max_rel(out, states) <= 1e-12
        # the intermediate state really moved (the test is not a trivial identity)
        assert float(jnp.max(jnp.abs(mid.q - states.q))) > 1e-3


@pytest.mark.parametrize("case", ["linear", "affine"])
def test_theorem_5_2_symmetric_statement_and_control(case):
    """F_B^h ∘ F_A^{−h} = Id (the same theorem with h → −h), while F_A^h ∘ F_A^{−h} ≠ Id:
    Euler A alone is not self-adjoint (it is of order 1), so the round trip is sensitive."""
    system = CASES[case][0]
    h = jnp.asarray(0.05)
    states = _random_states(system, 64, 0.05, -1.0, 7)
    out, _ = _round_trip(system, ps.euler_a_map, ps.euler_b_map, states, h)
    assert _max_rel(out, states) <= 1e-12
    # F_A^{-h} acts on the same states (its output constraint is B's at +h); F_A^h does not undo it
    out_aa, _ = _round_trip(system, ps.euler_a_map, ps.euler_a_map, states, h)
    assert _max_rel(out_aa, states) > 1e-6


# --------------------------------------------------------------------------------------------
# Order of the composition (Remark after Thm 5.2) and of Euler A (Thm 5.1)
# --------------------------------------------------------------------------------------------
@jit
def _final_q(method, system, q0, v0, h, n):
    """q after n steps (n traced: one compile for every step count)."""
    state = method.init(system, q0, v0, h)
    state = jax.lax.fori_loop(0, n, lambda i, s: method.step(system, s, h)[0], state)
    return method.observe(system, state, h)[0]


ORDER_NS = (40, 80, 160)  # steps to t = 1


def _order_from(qs):
    """Observed order from q at t = 1 after n = 40, 80, 160 steps (self-convergence)."""
    e1 = np.max(np.abs(qs[0] - qs[1]))
    e2 = np.max(np.abs(qs[1] - qs[2]))
    return np.log2(e1 / e2)


def _observed_order(method, system, q0, v0, T=1.0, ns=ORDER_NS):
    return _order_from([np.asarray(_final_q(method, system, jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(T / n),
                                            jnp.asarray(n))) for n in ns])


def _observed_order_of_named(name, system, q0, v0, T=1.0, ns=ORDER_NS):
    """As _observed_order, for a registered method through `gnipy.simulate`: runs of STEPS steps with
    h = T/n, every node saved, node n is t = T. These are the compiled programs of the `run` fixture
    (same system, method and saved-node count; h is traced), so the orders compile nothing new."""
    return _order_from([np.asarray(gnipy.simulate(system, name, q0, v0, h=T / n, steps=STEPS).q[n]) for n in ns])


class _LiteralComposition(ps.EulerABComposition):
    """(EuAHam) at h/2 after (EuBHam) at h/2 on (q, p̃, λ̃) with no change of reading in between."""

    def step(self, system, state, h):
        new = ps.euler_a_map(system, ps.euler_b_map(system, state, 0.5 * h), 0.5 * h)
        return new, None


@pytest.mark.parametrize("case", ["linear", "affine"])
def test_orders(run, case):
    """Self-convergence |q_h − q_{h/2}| at t = 1: order 2 for euler-ab, rattle and shake, order 1
    for euler-a and euler-b (Thm 5.1). The literal composition of the two maps on (q, p̃, λ̃),
    without the change of p̃ reading at the junctions, is only of order 1 (see EulerABComposition)."""
    system, q0, v0 = CASES[case]
    for name in ("euler-ab", "rattle", "shake"):
        run(case, name)  # compiled here if this test runs alone
        assert 1.8 < _observed_order_of_named(name, system, q0, v0) < 2.3, name
    for name in ("euler-a", "euler-b"):
        run(case, name)
        assert 0.8 < _observed_order_of_named(name, system, q0, v0) < 1.3, name
    assert 0.8 < _observed_order(_LiteralComposition(), system, q0, v0) < 1.3


# --------------------------------------------------------------------------------------------
# Starts, names, refusals
# --------------------------------------------------------------------------------------------
def test_starts_follow_the_gni_start():
    """λ̃_0 = 0 and p̃_0 = Mv_0 ∓ (h/2)V_q (A: −, B: +, RATTLE: 0, composition: −(h/4)V_q);
    SHAKE's q_{±1} = q_0 ± h v_0 − (h²/2)M⁻¹V_q (RATTLE's first step back and forth)."""
    system, q0, v0 = BALL, jnp.asarray(BALL_Q0), jnp.asarray(BALL_V0)
    h = 0.1
    M = np.asarray(system.metric(q0))
    Vq = np.asarray(system.potential_gradient(q0))
    assert np.max(np.abs(Vq)) > 0.1  # the shifts are visible
    for cls, shift in [(ps.NonholonomicEulerA, -0.5 * h), (ps.NonholonomicEulerB, 0.5 * h),
                       (ps.Rattle, 0.0), (ps.EulerABComposition, -0.25 * h)]:
        state = cls().init(system, q0, v0, h)
        np.testing.assert_allclose(np.asarray(state.lambda_tilde), 0.0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(state.p_tilde), M @ BALL_V0 + shift * Vq, rtol=0, atol=1e-14)
        q, v, p = cls().observe(system, state, h)
        np.testing.assert_allclose(np.asarray(v), BALL_V0, rtol=0, atol=1e-14)
    s = Shake().init(system, q0, v0, h)
    r1 = ps.rattle_map(system, ps.Rattle().init(system, q0, v0, h), h)
    np.testing.assert_allclose(np.asarray(s.q_next), np.asarray(r1.q), rtol=0, atol=1e-14)
    kick = 0.5 * h * h * np.linalg.solve(M, Vq)
    np.testing.assert_allclose(np.asarray(s.q_prev), BALL_Q0 - h * BALL_V0 - kick, rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "name,cls,order",
    [("euler-a", ps.NonholonomicEulerA, 1), ("euler-b", ps.NonholonomicEulerB, 1), ("rattle", ps.Rattle, 2),
     ("shake", Shake, 2), ("euler-ab", ps.EulerABComposition, 2)],
)
def test_method_names_and_constant_metric_check(name, cls, order):
    """The names resolve to the classes; a position-dependent metric is refused with MethodError."""
    method = gnipy.get_method(name)
    assert type(method) is cls and method.name == name and method.order == order
    with pytest.raises(MethodError, match="constant metric"):
        gnipy.simulate(CURVED, name, [0.5, 1.0, 0.0], [1.0, 0.3, 1.0], h=0.1, steps=2)
