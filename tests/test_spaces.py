"""The configuration space R^n × G: discrete Legendre transforms (RedLegTr) against closed forms.

The expected values are written out by hand from the Appendix's closed forms for the Cayley map
on SO(3) — an independent formulation of what `GroupSpace` computes by automatic differentiation.

Compilation: the two systems are built once for the module (compiled programs are keyed by the
system and method objects), simulate checks the saved nodes only (the module tests numerics, not
verdicts), and the right-reconstruction test runs the left-reconstructed system exactly as the
orthogonality test does (200 steps, every 10th saved), so that run's program is shared; its
comparison (q, v, p bit for bit, R different) is as strong over 200 steps as over 40. Summed test
time on the shared 2-core machine (noisy): 21.9 s (full-suite run) -> about 14.5 s.
"""

import functools

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.discrete_lagrangians import EulerA, Trapezoid
from gnipy.lie_groups import SO3
from gnipy.spaces import Point

INERTIA = np.array([[1.0, 0.1, 0.0], [0.1, 1.5, 0.2], [0.0, 0.2, 2.0]])
S = np.array([0.1, -0.2, 0.3])  # centre-of-mass offset in the body


def _hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def _dcay_inv(w):
    return np.eye(3) - _hat(w) / 2 + np.outer(w, w) / 4  # Appendix, Cayley on SO(3)


def _cay(w):
    W = _hat(w)
    return np.eye(3) + 4.0 / (4.0 + w @ w) * (W + W @ W / 2)


#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False
#: one method object and (below) one pair of system objects for the module: the compiled programs
#: are keyed by them, so the runs of `reduced` in two tests share one program
GNI_TRAPEZOID = gnipy.GNI(Trapezoid())


@functools.cache
def _systems():
    reduced = gnipy.System(
        lambda x, v: 0.5 * v[0] ** 2 + 0.5 * v[1:] @ jnp.asarray(INERTIA) @ v[1:] + 0.3 * v[0] * v[2] - 0.5 * x[0] ** 2,
        lambda x: jnp.array([[1.0, 0.0, 0.0, -1.0]]),
        n=1,
        group=SO3(),
    )
    # R-dependent potential V(R) = e₃ᵀ R s (a heavy top): the Lie groupoid case
    groupoid = gnipy.System(
        lambda x, R, v: 0.5 * v[1:] @ jnp.asarray(INERTIA) @ v[1:] + 0.5 * v[0] ** 2 - R[2] @ jnp.asarray(S),
        lambda x, R: jnp.concatenate([jnp.zeros(1), R[2]])[None, :],
        n=1,
        group=SO3(),
        depends_on_orientation=True,
    )
    return reduced, groupoid


@pytest.mark.parametrize("seed", range(3))
def test_legendre_transforms_reduced_euler_a(seed):
    reduced, _ = _systems()
    rng = np.random.default_rng(seed)
    h = 0.1
    x0, x1 = rng.standard_normal(1), rng.standard_normal(1)
    sigma = 0.3 * rng.standard_normal(3)
    R0 = _cay(rng.standard_normal(3))
    b0 = Point(jnp.asarray(x0), jnp.asarray(R0))
    z = jnp.concatenate([jnp.asarray(x1 - x0), jnp.asarray(sigma)])  # the unknowns are increments

    def ld(b, zz):
        return EulerA()(reduced, b, zz, h)

    fm = np.asarray(reduced.space.legendre_minus(ld, b0, z))
    fp = np.asarray(reduced.space.legendre_plus(ld, b0, z))
    # the jump FL⁺ − FL⁻, computed without the difference (GNI momentum update)
    np.testing.assert_allclose(np.asarray(reduced.space.legendre_jump(ld, b0, z)), fp - fm, rtol=1e-12, atol=1e-13)
    # l_d = h[½Δ² + ½ξᵀIξ + 0.3 Δ ξ₂ − ½x_k²] with Δ = (x1 − x0)/h, ξ = σ/h
    d, xi = (x1 - x0) / h, sigma / h
    dl_dsigma = INERTIA @ xi + np.array([0.0, 0.3 * d[0], 0.0])
    fm_x = d + 0.3 * xi[1] + h * x0  # −∂l_d/∂x_k
    fp_x = d + 0.3 * xi[1]  # ∂l_d/∂x_{k+1}
    np.testing.assert_allclose(fm, np.concatenate([fm_x, _dcay_inv(sigma).T @ dl_dsigma]), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(fp, np.concatenate([fp_x, _dcay_inv(-sigma).T @ dl_dsigma]), rtol=1e-13, atol=1e-13)
    # (dτ⁻¹_{−σ})ᵀ = Ad*_{τ(σ)} (dτ⁻¹_σ)ᵀ: FL⁺'s group part is the rotated FL⁻'s (Appendix)
    np.testing.assert_allclose(fp[1:], _cay(sigma).T @ fm[1:], rtol=1e-12, atol=1e-13)


def test_legendre_minus_includes_the_left_gradient_in_R():
    _, groupoid = _systems()
    h = 0.05
    rng = np.random.default_rng(7)
    R0 = _cay(rng.standard_normal(3))
    sigma = 0.2 * rng.standard_normal(3)
    b0 = Point(jnp.asarray([0.4]), jnp.asarray(R0))
    z = jnp.concatenate([jnp.asarray([0.5 - 0.4]), jnp.asarray(sigma)])  # x1 = 0.5

    def ld(b, zz):
        return EulerA()(groupoid, b, zz, h)

    fm = np.asarray(groupoid.space.legendre_minus(ld, b0, z))
    fp = np.asarray(groupoid.space.legendre_plus(ld, b0, z))
    np.testing.assert_allclose(np.asarray(groupoid.space.legendre_jump(ld, b0, z)), fp - fm, rtol=1e-12, atol=1e-13)
    # ∇ᴸ_R V = d/dε e₃ᵀ R exp(εη) s = η·(s × γ), γ = Rᵀe₃, and −∇ᴸ_R l_d = h ∇ᴸ_R V
    gamma = R0[2]
    expected = _dcay_inv(sigma).T @ (INERTIA @ sigma / h) + h * np.cross(S, gamma)
    np.testing.assert_allclose(fm[1:], expected, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(fm[0], (0.5 - 0.4) / h, rtol=1e-13)


def test_step_points_and_reconstruction():
    reduced, _ = _systems()
    rng = np.random.default_rng(3)
    R0 = _cay(rng.standard_normal(3))
    sigma = 0.3 * rng.standard_normal(3)
    b0 = Point(jnp.asarray([1.0]), jnp.asarray(R0))
    z = jnp.concatenate([jnp.asarray([1.0]), jnp.asarray(sigma)])  # x1 − x0 = 1
    b1, bm, vel = reduced.space.step_points(b0, z, 0.5)
    np.testing.assert_allclose(np.asarray(b1.x), [2.0], atol=0)
    np.testing.assert_allclose(np.asarray(b1.R), R0 @ _cay(sigma), atol=1e-14)
    np.testing.assert_allclose(np.asarray(bm.R), R0 @ _cay(sigma / 2), atol=1e-14)
    np.testing.assert_allclose(np.asarray(vel), np.concatenate([[2.0], sigma / 0.5]), atol=1e-14)
    np.testing.assert_allclose(np.asarray(bm.x), [1.5], atol=1e-15)


def test_right_reconstruction_moves_R_from_the_left_and_nothing_else():
    """reconstruction="right" (ξ the space velocity): R_{k+1} = τ(σ)R_k, the midpoint τ(σ/2)R_k,
    Ṙ = ξ̂R; x and the step velocity as on the left; a GNI run changes only R."""
    reduced, _ = _systems()
    right = gnipy.System(reduced.lagrangian, reduced.constraints, n=1, group=SO3(), reconstruction="right")
    assert right.reconstruction == "right" and reduced.reconstruction == "left"
    rng = np.random.default_rng(4)
    R0 = _cay(rng.standard_normal(3))
    sigma = 0.3 * rng.standard_normal(3)
    b0 = Point(jnp.asarray([1.0]), jnp.asarray(R0))
    z = jnp.concatenate([jnp.asarray([1.0]), jnp.asarray(sigma)])
    b1, bm, vel = right.space.step_points(b0, z, 0.5)
    np.testing.assert_allclose(np.asarray(b1.R), _cay(sigma) @ R0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(bm.R), _cay(sigma / 2) @ R0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(right.space.advance(b0, z).R), _cay(sigma) @ R0, atol=1e-14)
    np.testing.assert_array_equal(np.asarray(b1.x), [2.0])
    np.testing.assert_allclose(np.asarray(vel), np.concatenate([[2.0], sigma / 0.5]), atol=1e-14)
    w = np.concatenate([[0.0], sigma])
    packed = np.asarray(right.space.pack_velocity(b0, jnp.asarray(w)))
    np.testing.assert_allclose(packed[1:].reshape(3, 3), _hat(sigma) @ R0, atol=1e-15)
    v0 = [0.2, 0.5, 0.3, 0.2]
    # the run of test_gni_on_a_group_keeps_R_orthogonal_and_constraints_exact (its program, shared)
    a = gnipy.simulate(reduced, GNI_TRAPEZOID, [0.3], v0, h=0.05, steps=200, save_every=10)
    b = gnipy.simulate(right, GNI_TRAPEZOID, [0.3], v0, h=0.05, steps=200, save_every=10)
    for name in ("q", "v", "p"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)), err_msg=name)
    assert np.max(np.abs(np.asarray(a.R) - np.asarray(b.R))) > 1e-3
    assert "dR/dt = hat(xi) R" in b.orientation and "dR/dt = R hat(xi)" in a.orientation


def test_right_reconstruction_is_refused_where_the_system_depends_on_R():
    _, groupoid = _systems()
    with pytest.raises(gnipy.InputError, match=r"^reconstruction: 'right' .*\(depends_on_orientation=True\)"):
        gnipy.System(groupoid.lagrangian, groupoid.constraints, n=1, group=SO3(), depends_on_orientation=True,
                     reconstruction="right")
    with pytest.raises(gnipy.InputError, match=r"^reconstruction: expected 'left' or 'right'"):
        gnipy.System(groupoid.lagrangian, groupoid.constraints, n=1, group=SO3(), reconstruction="space")
    with pytest.raises(gnipy.InputError, match=r"^reconstruction: only meaningful with a group"):
        gnipy.System(lambda q, v: 0.5 * v @ v, lambda q: jnp.ones((1, 2)), n=2, reconstruction="right")


def test_gni_on_a_group_keeps_R_orthogonal_and_constraints_exact():
    reduced, groupoid = _systems()
    # reduced: ẋ = ξ₃; groupoid: ⟨ξ, γ⟩ = 0 with γ = e₃ at R = I
    for system, v0 in ((reduced, [0.2, 0.5, 0.3, 0.2]), (groupoid, [0.2, 0.5, 0.3, 0.0])):
        sol = gnipy.simulate(system, GNI_TRAPEZOID, [0.3], v0, h=0.05, steps=200, save_every=10)
        R = np.asarray(sol.R)
        np.testing.assert_allclose(np.einsum("tji,tjk->tik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
        assert np.max(np.abs(np.asarray(sol.constraint_residual))) < 1e-12
        assert sol.v.shape == (21, 4) and sol.q.shape == (21, 1)


def test_initial_orientation_is_validated():
    reduced, _ = _systems()
    with pytest.raises(gnipy.InputError, match=r"R0: not a rotation matrix"):
        gnipy.simulate(reduced, "gni-trapezoid", [0.0], [0.2, 0.5, 0.3, 0.2], R0=2 * np.eye(3), h=0.1, steps=1)
    with pytest.raises(gnipy.InputError, match=r"R0: expected a 3x3"):
        gnipy.simulate(reduced, "gni-trapezoid", [0.0], [0.2, 0.5, 0.3, 0.2], R0=np.eye(2), h=0.1, steps=1)
    with pytest.raises(gnipy.InputError, match=r"v0: expected a vector of length 4"):
        gnipy.simulate(reduced, "gni-trapezoid", [0.0], [0.2, 0.5, 0.2], h=0.1, steps=1)
