"""The continuous reference (Lagrange–d'Alembert with λ eliminated, DESIGN.md §2).

Every number here comes from an exact solution (the free harmonic coordinate y of the nonholonomic
particle and of its variants), a conserved quantity, the energy balance $\\dot E = \\lambda^T\\mu Y$,
or an independent formulation written by hand (the paper's Hamiltonian form (H), and the
Euler–Lagrange equations of a diagonal position-dependent metric).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import simpson

import gnipy
from gnipy import System
from gnipy.models.nonholonomic_particle import exact_y
from gnipy.equations import lagrange_dalembert_acceleration

H_SAVE = 0.1
T_FINAL = 10.0
TIMES = np.linspace(0.0, T_FINAL, 101)  # one shape for every reference solve below: one compile each


# ---------------------------------------------------------------------------------------------
# A position-dependent metric with (optionally) affine constraints, and an exact coordinate.
#
#   l = ½(g1(z) ẋ² + ẏ² + g3(x) ż²) − ½k(x² + y²),  g1 = 1 + a z²,  g3 = 1 + b x²,
#   constraint ż − y ẋ = c   (μ = (−y, 0, 1), Y = (0, 0, c)).
#
# The metric does not depend on y and the constraint force λ(−y, 0, 1) has no y-component, so
# ÿ = −k y exactly: y is the harmonic oscillator of exact_y whatever the metric and c.
# With c = 0 the energy is conserved; otherwise Ė = λᵀμY = cλ.
# ---------------------------------------------------------------------------------------------
A_METRIC, B_METRIC, K_SPRING = 0.5, 0.3, 1.0


def _varmetric_lagrangian(q, v):
    x, y, z = q
    g1 = 1.0 + A_METRIC * z**2
    g3 = 1.0 + B_METRIC * x**2
    return 0.5 * (g1 * v[0] ** 2 + v[1] ** 2 + g3 * v[2] ** 2) - 0.5 * K_SPRING * (x**2 + y**2)


def _particle_mu(q):
    return jnp.stack([-q[1], jnp.zeros_like(q[1]), jnp.ones_like(q[1])])[None, :]


def varmetric_system(c: float) -> System:
    affine = None if c == 0.0 else (lambda q: jnp.array([0.0, 0.0, c]) + 0.0 * q)
    return System(_varmetric_lagrangian, _particle_mu, affine, n=3, name=f"varmetric-c{c:g}")


def varmetric_ic(c: float):
    q0 = np.array([0.4, 0.8, -0.2])
    vx, vy = 0.7, -0.5
    return q0, np.array([vx, vy, q0[1] * vx + c])  # on the constraint ż = yẋ + c


def _ref(system, q0, v0):
    return gnipy.ContinuousReference().solve(system, q0, v0, TIMES, h=H_SAVE)


# ---------------------------------------------------------------------------------------------
# Nonholonomic particle: exact y, energy, constraint
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def particle_ref():
    spec = gnipy.get_model("nonholonomic-particle")
    sol = gnipy.simulate(spec.system(), "reference", h=H_SAVE, t_final=T_FINAL)
    return spec, sol


def test_particle_y_is_the_exact_harmonic_solution(particle_ref):
    spec, sol = particle_ref
    y, vy = exact_y(spec.resolve_params(), spec.q0, spec.v0, np.asarray(sol.t))
    np.testing.assert_allclose(np.asarray(sol.t), TIMES, rtol=0, atol=1e-12)
    assert np.max(np.abs(np.asarray(sol.q[:, 1]) - y)) <= 1e-9
    assert np.max(np.abs(np.asarray(sol.v[:, 1]) - vy)) <= 1e-9


def test_particle_energy_and_constraint_conserved(particle_ref):
    spec, sol = particle_ref
    energy = jax.vmap(lambda q, v: spec.invariants["energy"](spec.resolve_params(), q, v))(sol.q, sol.v)
    assert np.max(np.abs(np.asarray(energy) - float(energy[0]))) <= 1e-10
    np.testing.assert_allclose(np.asarray(sol.energy), np.asarray(energy), rtol=0, atol=1e-13)  # System.energy
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-10
    assert sol.method == "reference" and sol.result == 0


# ---------------------------------------------------------------------------------------------
# Contact oscillator: H and H_y
# ---------------------------------------------------------------------------------------------
def test_contact_oscillator_invariants_conserved():
    spec = gnipy.get_model("contact-oscillator")
    params = spec.resolve_params()
    sol = gnipy.simulate(spec.system(), "reference", h=H_SAVE, t_final=T_FINAL)
    assert set(spec.invariants) == {"H", "H_y"}
    for name, f in spec.invariants.items():
        values = np.asarray(jax.vmap(lambda q, v: f(params, q, v))(sol.q, sol.v))
        assert np.max(np.abs(values - values[0])) <= 1e-10, name
    # H_y changes along the motion only through y, which does move: the test is not vacuous
    assert np.ptp(np.asarray(sol.q[:, 1])) > 1.0
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-10


# ---------------------------------------------------------------------------------------------
# Position-dependent metric, linear and affine constraints
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def varmetric_refs():
    out = {}
    for c in (0.0, 0.5):
        system = varmetric_system(c)
        q0, v0 = varmetric_ic(c)
        out[c] = (system, q0, v0, _ref(system, q0, v0))
    return out


def test_varmetric_metric_really_depends_on_q(varmetric_refs):
    system, q0, _, _ = varmetric_refs[0.0]
    assert not system.has_constant_metric(q0)


@pytest.mark.parametrize("c", [0.0, 0.5])
def test_varmetric_exact_y_and_constraints(varmetric_refs, c):
    system, q0, v0, sol = varmetric_refs[c]
    y, vy = exact_y({"k": K_SPRING}, q0, v0, TIMES)
    assert np.max(np.abs(np.asarray(sol.q[:, 1]) - y)) <= 1e-9
    assert np.max(np.abs(np.asarray(sol.v[:, 1]) - vy)) <= 1e-9
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-10


def test_varmetric_linear_conserves_energy(varmetric_refs):
    _, _, _, sol = varmetric_refs[0.0]
    e = np.asarray(sol.energy)
    assert np.max(np.abs(e - e[0])) <= 1e-10


def test_varmetric_affine_energy_balance(varmetric_refs):
    """Ė = vᵀμᵀλ = λᵀμY for Gq̈ = F + μᵀλ (the power of the constraint force), so
    E(T) − E(0) = c ∫ λ dt. λ at 101 nodes on [0, 2.5] (the same array shape as the other solves,
    so no new compile); the integral by Simpson's rule, Richardson-extrapolated with Simpson on every
    other node: (16 S_h − S_2h)/15, which removes the O(h⁴) error term of Simpson's rule (of order
    T h⁴ max|λ⁗|/180 ~ 1e-9 here: λ has large fourth derivatives) and leaves O(h⁶)."""
    system, q0, v0, _ = varmetric_refs[0.5]
    times = np.linspace(0.0, 2.5, TIMES.size)
    sol = gnipy.ContinuousReference().solve(system, q0, v0, times)
    lam = np.asarray(jax.vmap(lambda q, v: lagrange_dalembert_acceleration(system, q, v)[1][0])(sol.q, sol.v))
    e = np.asarray(sol.energy)
    s_h, s_2h = simpson(lam, x=times), simpson(lam[::2], x=times[::2])
    work = 0.5 * (16.0 * s_h - s_2h) / 15.0
    assert abs(e[-1] - e[0]) > 1e-2  # the affine constraint does work: the balance is not vacuous
    assert abs((e[-1] - e[0]) - work) <= 1e-9


def test_affine_field_inside_D_is_the_linear_system(varmetric_refs):
    """Y = c(1, 0, y) lies in D (μY = 0), so μ(v − Y) = μv: the same motion as Y = 0, but through
    the affine branch of the λ-elimination (μ Ẏ − μ̇(v − Y))."""
    system0, q0, v0, sol0 = varmetric_refs[0.0]
    system_d = System(_varmetric_lagrangian, _particle_mu, lambda q: 0.8 * jnp.array([1.0, 0.0, q[1]]), n=3)
    sol_d = _ref(system_d, q0, v0)
    np.testing.assert_allclose(np.asarray(sol_d.q), np.asarray(sol0.q), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(sol_d.v), np.asarray(sol0.v), rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# The λ-elimination against independent formulations
# ---------------------------------------------------------------------------------------------
def _random_constrained_points(rng, count, c=0.0):
    q = rng.standard_normal((count, 3))
    v = rng.standard_normal((count, 3))
    v[:, 2] = q[:, 1] * v[:, 0] + c  # on ż = yẋ + c
    return q, v


@pytest.mark.parametrize("random_mass", [False, True])
def test_acceleration_matches_hamiltonian_form_H(random_mass):
    """Paper (H): ṗ = −V_q − μᵀC⁻¹(μ_q[M⁻¹p, M⁻¹p] − μM⁻¹V_q), C = μM⁻¹μᵀ, written by hand for
    μ = (−y, 0, 1), V = ½k(x² + y²): μ_q[u, u] = ∂_j μ_i u_j u_i = −u_x u_y."""
    rng = np.random.default_rng(7)
    k = 1.3
    if random_mass:
        A = rng.standard_normal((3, 3))
        M = A @ A.T + 3.0 * np.eye(3)
    else:
        M = np.eye(3)
    Mj = jnp.asarray(M)
    system = System(
        lambda q, v: 0.5 * v @ Mj @ v - 0.5 * k * (q[0] ** 2 + q[1] ** 2), _particle_mu, n=3, name="particle-M"
    )
    Minv = np.linalg.inv(M)
    for q, v in zip(*_random_constrained_points(rng, 5)):
        x, y, _ = q
        mu = np.array([[-y, 0.0, 1.0]])
        Vq = np.array([k * x, k * y, 0.0])
        mu_q_uu = np.array([-v[0] * v[1]])
        C = mu @ Minv @ mu.T
        lam_H = np.linalg.solve(C, mu_q_uu - mu @ Minv @ Vq)
        pdot = -Vq - mu.T @ lam_H  # (Hb)
        a, lam = lagrange_dalembert_acceleration(system, jnp.asarray(q), jnp.asarray(v))
        np.testing.assert_allclose(np.asarray(a), Minv @ pdot, rtol=1e-12, atol=1e-12)
        # the reference writes Gq̈ = F + μᵀλ, the paper ṗ = −V_q − μᵀλ: opposite signs
        np.testing.assert_allclose(np.asarray(lam), -lam_H, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("c", [0.0, 0.5])
def test_acceleration_matches_euler_lagrange_by_hand_varmetric(c):
    """For the diagonal metric above, the Lagrange–d'Alembert equations by hand:
        g1 ẍ + a·2zż ẋ − b x ż² + kx = −yλ,   ÿ + ky = 0,   g3 z̈ + 2b x ẋ ż − a z ẋ² = λ,
    and the derivative of the constraint z̈ = ẏẋ + yẍ; a 3×3 linear solve for (ẍ, z̈, λ)."""
    system = varmetric_system(c)
    a_, b_, k = A_METRIC, B_METRIC, K_SPRING
    rng = np.random.default_rng(11)
    for q, v in zip(*_random_constrained_points(rng, 5, c)):
        x, y, z = q
        xd, yd, zd = v
        g1, g3 = 1 + a_ * z**2, 1 + b_ * x**2
        # unknowns (ẍ, z̈, λ)
        Amat = np.array([[g1, 0.0, y], [0.0, g3, -1.0], [-y, 1.0, 0.0]])
        rhs = np.array(
            [-2 * a_ * z * zd * xd + b_ * x * zd**2 - k * x, -2 * b_ * x * xd * zd + a_ * z * xd**2, yd * xd]
        )
        xdd, zdd, lam_hand = np.linalg.solve(Amat, rhs)
        acc, lam = lagrange_dalembert_acceleration(system, jnp.asarray(q), jnp.asarray(v))
        np.testing.assert_allclose(np.asarray(acc), [xdd, -k * y, zdd], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(lam), [lam_hand], rtol=1e-12, atol=1e-12)
