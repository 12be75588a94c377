"""The reduced RATTLE algorithm (RAT) of paper §7.2 against the GNI core.

(RAT) is written as in the paper (explicit x-update, multipliers in closed form, a Newton solve for
ξ_{k+1}); the GNI core with the trapezoid l_d and the Cayley map solves the same discrete equations
in other variables. They must agree to round-off over hundreds of steps: on the rolling ball
(example 2 of §7.4, affine constraints, V = 0) and on a test system with a coupling block
G_xξ ≠ 0, a potential V(x) and x-dependent constraint rows (μ(x), η(x)), linear and affine.
The variables of (RAT) are also checked against their definitions in §7.2 (numpy, from the
saved configurations alone).

test_reading_RATc_with_the_block_of_the_inverse_metric_is_wrong compares with the module's run of RAT
on the linear test system (the same step count: its program and its result shared). Measured on the
2-core machine (noisy, shared): 22 s before, 18 s after.
"""

import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import pytest
from shared_systems import PARTICLE, PARTICLE_Q0, PARTICLE_V0

import gnipy
from gnipy.integrators.reduced_rattle import ReducedRattle
from gnipy.lie_groups import SO3
from gnipy.models import rolling_ball as rb
from gnipy.spaces import Point

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

H, N = 0.05, 200


def _np(x):
    return np.asarray(x, dtype=np.float64)


# --------------------------------------------------------------------------------------------
# A reduced system with coupling: constant metric with G_xξ ≠ 0, V(x), (μ(x), η(x)), Y = a·Y₁(x)
# --------------------------------------------------------------------------------------------
G_XX = np.array([[2.0, 0.3], [0.3, 1.5]])
G_XS = np.array([[0.2, -0.1, 0.05], [0.0, 0.15, -0.1]])
G_SS = np.array([[1.0, 0.1, 0.0], [0.1, 1.3, -0.05], [0.0, -0.05, 0.8]])
METRIC = np.block([[G_XX, G_XS], [G_XS.T, G_SS]])


def _coupled_lagrangian(x, v):
    G = jnp.asarray(METRIC)
    V = 0.5 * (x[0] ** 2 + 2.0 * x[1] ** 2) + 0.1 * jnp.sin(x[0] * x[1])
    return 0.5 * v @ G @ v - V


def _coupled_mu(x):
    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    return jnp.stack(
        [
            jnp.stack([one, zero, zero, -one, 0.2 * jnp.sin(x[1])]),
            jnp.stack([0.3 * x[0], one, 0.8 * one, zero, 0.1 * x[1]]),
        ]
    )


def _coupled_Y(a, x):
    return a * jnp.stack([-0.5 * x[1], 0.5 * x[0], 0.1 * jnp.ones_like(x[0]), jnp.zeros_like(x[0]), 0.2 * x[0]])


def coupled(a):
    """The coupled test system; a = 0: linear constraints, a ≠ 0: affine (one compilation for both)."""
    return gnipy.System(_coupled_lagrangian, _coupled_mu, jtu.Partial(_coupled_Y, jnp.asarray(float(a))),
                        n=2, group=SO3(), retraction="cayley", name="coupled-reduced-test")


COUPLED_Q0 = np.array([0.5, -0.3])
COUPLED_V0 = np.array([0.4, -0.2, 0.3, 0.5, -0.6])  # projected onto the constraints by simulate


def _case(name):
    if name == "rolling-ball-ex2":
        s, q0, v0 = rb.example_2()
        return s, q0, v0
    return coupled(0.0 if name == "coupled-linear" else 0.7), COUPLED_Q0, COUPLED_V0


CASES = ["rolling-ball-ex2", "coupled-linear", "coupled-affine"]


@pytest.fixture(scope="module")
def runs():
    out = {}
    for name in CASES:
        s, q0, v0 = _case(name)
        out[name] = (
            gnipy.simulate(s, "rat", q0, v0, h=H, steps=N, project_v0=True),
            gnipy.simulate(s, gnipy.GNI(gnipy.Trapezoid(), start="rest"), q0, v0, h=H, steps=N, project_v0=True),
        )
    return out


# --------------------------------------------------------------------------------------------
# Independent numpy formulas: Cayley (Appendix, SO(3)) and the definitions of §7.2
# --------------------------------------------------------------------------------------------
def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cay(w):
    return np.linalg.solve(np.eye(3) - hat(w) / 2, np.eye(3) + hat(w) / 2)


def cay_inv(Q):
    S = 2.0 * (Q - np.eye(3)) @ np.linalg.inv(Q + np.eye(3))
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2.0


def dcay_inv(w):
    """dcay⁻¹_ω = I − ω̂/2 + ωωᵀ/4 (Appendix)."""
    return np.eye(3) - hat(w) / 2 + np.outer(w, w) / 4


# --------------------------------------------------------------------------------------------
# RAT = GNI(trapezoid)
# --------------------------------------------------------------------------------------------
def test_metric_blocks_of_the_test_system():
    s = coupled(0.0)
    b = Point(jnp.asarray(COUPLED_Q0), jnp.eye(3))
    np.testing.assert_allclose(_np(s.metric(b)), METRIC, atol=1e-15)
    assert np.linalg.eigvalsh(METRIC)[0] > 0.1 and np.max(np.abs(G_XS)) > 0.1
    # (RATc) needs the inverse of the block G_xx, which here differs from the block of G⁻¹
    assert np.max(np.abs(np.linalg.inv(METRIC)[:2, :2] - np.linalg.inv(G_XX))) > 1e-2
    assert s.has_constant_metric(b)


@pytest.mark.parametrize("name", CASES)
def test_rat_equals_the_gni_core(name, runs):
    rat, gni = runs[name]
    assert rat.method == "rat" and gni.method == "gni-trapezoid" and len(rat.t) == N + 1
    scale = max(1.0, np.max(np.abs(_np(gni.q))), np.max(np.abs(_np(gni.v))))
    for attr in ("q", "v", "p", "R", "energy"):
        diff = np.max(np.abs(_np(getattr(rat, attr)) - _np(getattr(gni, attr))))
        assert diff <= 1e-12 * scale, (attr, diff)
    # both report v̄ on the constraints, and orientations in SO(3)
    assert np.max(np.abs(_np(rat.constraint_residual))) <= 1e-13
    R = _np(rat.R)
    assert np.max(np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3))) < 1e-13
    # the run goes somewhere: the orientation turns and x moves
    assert np.max(np.abs(R[-1] - R[0])) > 0.1 and np.max(np.abs(_np(rat.q)[-1] - _np(rat.q)[0])) > 0.1


@pytest.mark.parametrize("name", CASES)
def test_rat_variables_match_their_definitions(name, runs):
    """From the saved (x_k, R_k) alone: ξ_k = cay⁻¹(R_kᵀR_{k+1})/h (cay⁻¹(R_{k+1}R_kᵀ)/h for the rolling
    ball, whose R is reconstructed from the space angular velocity, R_{k+1} = cay(hξ_k)R_k), then the paper's
    p̃_k = G_xx(x_{k+1} − x_{k−1})/2h + ½G_xξ(ξ_k + ξ_{k−1}) and, with
    M̃_k = (dcay⁻¹_{hξ_k})ᵀ D₃l_d(x_k, x_{k+1}, hξ_k), D₃l_d = G_ξx Δ_k + G_ξξ ξ_k, the group part
    ½(M̃_k + Ad*_{cay(hξ_{k−1})}M̃_{k−1}) of the reported momentum p̄_k (Ad*_R = Rᵀ)."""
    rat, _ = runs[name]
    s, _, _ = _case(name)
    G = _np(s.metric(Point(jnp.zeros(2), jnp.eye(3))))
    Gxx, Gxs, Gss = G[:2, :2], G[:2, 2:], G[2:, 2:]
    x, R, p = _np(rat.q), _np(rat.R), _np(rat.p)
    if s.reconstruction == "right":
        increments = np.einsum("kij,klj->kil", R[1:], R[:-1])  # R_{k+1}R_kᵀ
    else:
        increments = np.einsum("kji,kjl->kil", R[:-1], R[1:])  # R_kᵀR_{k+1}
    sig = np.array([cay_inv(g) for g in increments])
    np.testing.assert_allclose([cay(sg) for sg in sig], increments, atol=1e-14)
    xi = sig / H
    D = np.diff(x, axis=0) / H
    pt = (x[2:] - x[:-2]) @ Gxx.T / (2 * H) + 0.5 * (xi[1:] + xi[:-1]) @ Gxs.T
    M = np.array([dcay_inv(sig[k]).T @ (Gxs.T @ D[k] + Gss @ xi[k]) for k in range(N)])
    Mbar = 0.5 * (M[1:] + np.einsum("kji,kj->ki", np.array([cay(sg) for sg in sig[:-1]]), M[:-1]))
    scale = np.max(np.abs(p))
    assert np.max(np.abs(p[1:N, :2] - pt)) <= 1e-11 * scale
    assert np.max(np.abs(p[1:N, 2:] - Mbar)) <= 1e-11 * scale


def test_reading_RATc_with_the_block_of_the_inverse_metric_is_wrong(runs):
    """(RATc) with (G̃⁻¹)^{ij} read as the xx block of G⁻¹ (the meaning of the same symbol in A^{i,a})
    instead of the inverse of G_xx: with G_xξ ≠ 0 the result leaves the GNI at O(h). The right
    reading is the module's run of RAT on the linear test system (the same N steps: its program and
    its result are shared; a shorter run compiled both anew)."""

    class WrongBlock(ReducedRattle):
        @staticmethod
        def _blocks(system, R):
            G, _, Gxs = ReducedRattle._blocks(system, R)
            return G, jnp.linalg.inv(jnp.linalg.inv(G)[:2, :2]), Gxs

    s = coupled(0.0)
    good = runs["coupled-linear"][0]
    bad = gnipy.simulate(s, WrongBlock(), COUPLED_Q0, COUPLED_V0, h=H, steps=N, project_v0=True)
    assert np.max(np.abs(_np(bad.q) - _np(good.q))) > 1e-3


# --------------------------------------------------------------------------------------------
# Registration and refusals
# --------------------------------------------------------------------------------------------
def test_registered_as_rat():
    assert "rat" in gnipy.method_names()
    m = gnipy.get_method("rat")
    assert isinstance(m, ReducedRattle) and m.name == "rat" and m.order == 2


def _orientation_lagrangian(x, R, v):
    return 0.5 * (v[0] ** 2 + v[1:] @ v[1:]) + R[2, 2]


def _orientation_mu(x, R):
    return jnp.array([[1.0, 0.0, 0.0, -1.0]])


def _curved_lagrangian(x, v):
    return 0.5 * (1.0 + x[0] ** 2) * v[0] ** 2 + 0.5 * (v[1:] @ v[1:])


def _curved_mu(x):
    return jnp.array([[1.0, 0.0, 0.0, -1.0]])


@pytest.mark.parametrize("which", ["no-group", "orientation-dependent", "non-constant-metric"])
def test_check_refuses_systems_outside_section_7_2(which):
    if which == "no-group":
        s, q0, v0, match = PARTICLE, PARTICLE_Q0, PARTICLE_V0, "no group part"
    elif which == "orientation-dependent":
        s = gnipy.System(_orientation_lagrangian, _orientation_mu, n=1, group=SO3(), depends_on_orientation=True)
        q0, v0, match = [0.0], [1.0, 0.5, 0.0, 1.0], "depends on the orientation"
    else:
        s = gnipy.System(_curved_lagrangian, _curved_mu, n=1, group=SO3())
        q0, v0, match = [0.5], [1.0, 0.5, 0.0, 1.0], "constant metric"
    with pytest.raises(gnipy.MethodError, match=match):
        gnipy.simulate(s, "rat", q0, v0, h=0.1, steps=2)
