"""The GNI's energy theorem (paper §4, end; [SDD1]): on a Lie group with a bi-invariant metric, for
ANY constraint distribution and a left-invariant discrete Lagrangian, the GNI conserves energy.

Here G = SO(3), l = ½ c ΩᵀΩ (I = c·identity: bi-invariant), V = 0, and Euler A,
l_d(R_k, σ_k) = h l(σ_k/h), which does not depend on R_k (left-invariant). Which energy:

- the reflection (Comb) p⁻_k = (P* − Q*) p⁺_k is orthogonal for the metric c·I, so |p⁻_k| = |p⁺_k|;
- the Legendre transforms (RedLegTr) are p⁻_k = (dτ⁻¹_σ)ᵀ cσ/h and p⁺_{k+1} = (dτ⁻¹_{−σ})ᵀ cσ/h.
  For Cayley, (dcay⁻¹_{±σ})ᵀσ = σ(1 + |σ|²/4), so both equal c(σ_k/h)(1 + |σ_k|²/4); for exp,
  (dexp⁻¹_{±σ})ᵀσ = σ and both equal cσ_k/h.

So |p⁺_k| = |p⁺_0| = c|v₀| for every k: the step speed |σ_k|/h is conserved exactly (up to
round-off), and the energy |p⁺_k|²/2c = c|v₀|²/2 with it. The step σ_k is recovered from
consecutive saved attitudes, σ_k = τ⁻¹(R_kᵀR_{k+1}). The reported p̄_k = (p⁻_k + p⁺_k)/2 is a
projection of p⁺_k, and its energy is NOT conserved once the reflection acts (the control).

Constraint distributions: a random constant body one-form (Suslov-type), Veselova's γ = Rᵀe₃ —
for both, D is invariant along the discrete flow when I = c·identity (σ_k ∈ D_k implies
σ_k ∈ D_{k+1}, as cay(σ)σ = σ), so the reflection never acts — and random attitude-dependent
distributions μ(R) (one constraint, and two orthonormal ones), where it acts.

Each distribution and retraction is its own program (2-5 s over 10⁵ steps). The random
attitude-dependent distributions run once each: one constraint with the exponential map, two with
Cayley (a run of one constraint with Cayley, the pairing of the other two, is left out: the
reflection acts in both runs, and each retraction's Legendre transforms are checked in closed form
for the one-constraint μ(R) in test_legendre_transforms_of_the_bi_invariant_lagrangian). Measured on
the 2-core machine (noisy, shared): 19 s before, 14 s after.

The drift bound is a round-off model: a relative error of a few eps per step (one Newton solve,
the retraction, a matrix product, the recovery of σ), accumulating as a random walk, whose maximum
over N steps stays below ROUNDOFF·√N·eps with ROUNDOFF = 25 (≈ 3 standard deviations of a walk
with steps of 8 eps).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.lie_groups import SO3

EPS = np.finfo(np.float64).eps
ROUNDOFF = 25.0
C = 1.7  # l = ½ c |Ω|²
H = 0.05
STEPS = 100_000

_rng = np.random.default_rng(20240601)
A_CONST = _rng.standard_normal(3)
B1, B1_0 = _rng.standard_normal((3, 9)), _rng.standard_normal(3)
P2 = _rng.standard_normal(3)  # rotation vector of a fixed rotation P
R0_VEC = (0.3, -0.5, 0.8)
W0 = (1.0, -2.0, 0.5)  # initial velocity before projection onto D(R0)


def _lagrangian_reduced(x, v):
    return 0.5 * C * v @ v


def _lagrangian_groupoid(x, R, v):
    return 0.5 * C * v @ v


def _mu_constant(x):
    return jnp.asarray(A_CONST)[None, :]


def _mu_gamma(x, R):
    return R[2][None, :]  # γ = Rᵀe₃ (Veselova)


def _mu_random1(x, R):
    return (jnp.asarray(B1) @ R.reshape(-1) + jnp.asarray(B1_0))[None, :]


def _mu_random2(x, R):
    # two orthonormal rows, the first two rows of R P R: well conditioned at every attitude (a
    # generic two-row μ(R) passes near rank 1, where the reflection loses eps·cond(μ)² accuracy)
    return (R @ SO3().exp(jnp.asarray(P2)) @ R)[:2]


CASES = {  # name: (constraints, depends on R, retraction, does the reflection act?)
    "constant-body": (_mu_constant, False, "cayley", False),
    "veselova-gamma": (_mu_gamma, True, "cayley", False),
    "random-R-m2": (_mu_random2, True, "cayley", True),
    "random-R-m1-exp": (_mu_random1, True, "exp", True),
}


def _system(name):
    mu, dep, retraction, _ = CASES[name]
    lag = _lagrangian_groupoid if dep else _lagrangian_reduced
    return gnipy.System(lag, mu, n=0, group=SO3(), depends_on_orientation=dep, retraction=retraction,
                        name=f"bi-invariant-{name}")


def _start(system):
    R0 = np.asarray(SO3().exp(jnp.asarray(R0_VEC)))
    mu = np.asarray(system.mu(system.initial_point((), R0)))
    w = np.asarray(W0)
    v0 = w - mu.T @ np.linalg.solve(mu @ mu.T, mu @ w)  # the orthogonal projection onto D(R0)
    return R0, v0


def _polar(R):
    """The nearest rotations (removes the accumulated loss of orthogonality before recovering σ)."""
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def recovered_steps(R, retraction):
    """σ_k = τ⁻¹(R_kᵀ R_{k+1}) from the saved attitudes, shape (N, 3)."""
    R = _polar(np.asarray(R))
    g = np.einsum("kji,kjl->kil", R[:-1], R[1:])
    if retraction == "cayley":  # cay⁻¹(g) = 4 vee(g)/(1 + tr g)  (Appendix, SO(3))
        vee = 0.5 * np.stack([g[:, 2, 1] - g[:, 1, 2], g[:, 0, 2] - g[:, 2, 0], g[:, 1, 0] - g[:, 0, 1]], axis=-1)
        return 4.0 * vee / (1.0 + np.trace(g, axis1=1, axis2=2))[:, None]
    return np.asarray(jax.vmap(SO3().log)(jnp.asarray(g)))


def step_momentum_norm(sigma, retraction):
    """|p⁺_{k+1}| = |p⁻_k| from |σ_k| (module docstring)."""
    s = np.linalg.norm(sigma, axis=-1)
    return C * (s / H) * ((1.0 + 0.25 * s**2) if retraction == "cayley" else 1.0)


@pytest.mark.parametrize("retraction", ["cayley", "exp"])
def test_legendre_transforms_of_the_bi_invariant_lagrangian(retraction):
    """p⁻ and p⁺ of Euler A are the closed forms the theorem uses, at a random attitude and step."""
    sys_ = gnipy.System(_lagrangian_groupoid, _mu_random1, n=0, group=SO3(), depends_on_orientation=True,
                        retraction=retraction)
    space = sys_.space
    b0 = sys_.initial_point((), np.asarray(SO3().random(jax.random.PRNGKey(1))))
    sigma = jnp.asarray([0.3, -0.7, 0.45])

    def ld(b, z):
        return gnipy.EulerA()(sys_, b, z, H)

    factor = 1.0 + 0.25 * float(sigma @ sigma) if retraction == "cayley" else 1.0
    expected = C * np.asarray(sigma) / H * factor
    np.testing.assert_allclose(np.asarray(space.legendre_minus(ld, b0, sigma)), expected, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(space.legendre_plus(ld, b0, sigma)), expected, rtol=1e-14)


@pytest.fixture(scope="module", params=list(CASES))
def long_run(request):
    name = request.param
    sys_ = _system(name)
    R0, v0 = _start(sys_)
    # from rest, p⁺₀ = c v₀ (the theorem's E₀; the default consistent start carries an impulse)
    sol = gnipy.simulate(sys_, gnipy.GNI(gnipy.EulerA(), start="rest"), (), v0, R0=R0, h=H, steps=STEPS)
    return name, sys_, v0, sol


def test_gni_conserves_the_step_energy(long_run):
    """|p⁺_k| = c|v₀| for all k, i.e. the energy |p⁺|²/2c = E₀, to the round-off model."""
    name, _, v0, sol = long_run
    retraction = CASES[name][2]
    sigma = recovered_steps(sol.R, retraction)
    assert sigma.shape == (STEPS, 3)
    p_norm = step_momentum_norm(sigma, retraction)
    rel = np.abs(p_norm / (C * np.linalg.norm(v0)) - 1.0)
    bound = ROUNDOFF * np.sqrt(STEPS) * EPS
    assert np.max(rel) <= bound, (name, np.max(rel), bound)
    # ... and no systematic trend (the fitted change over the run is within the same model)
    k = np.arange(STEPS)
    slope = np.polyfit(k, p_norm / p_norm[0] - 1.0, 1)[0]
    assert abs(slope) * STEPS <= bound
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-13


def test_reported_energy_is_not_the_conserved_one(long_run):
    """Control: where the reflection acts, the energy of the reported p̄ changes by O(1)."""
    name, _, v0, sol = long_run
    E = np.asarray(sol.energy)
    E0 = 0.5 * C * float(v0 @ v0)
    assert E[0] == pytest.approx(E0, rel=1e-14)
    bound = ROUNDOFF * np.sqrt(STEPS) * EPS
    if CASES[name][3]:
        assert np.ptp(E) / E0 >= 1e-2 > bound
    else:  # D invariant along the discrete flow: no reflection, p̄ = p⁺
        assert np.ptp(E) / E0 <= bound
