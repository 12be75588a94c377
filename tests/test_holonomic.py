"""Holonomic constraints (gnipy.holonomic): each number compared with an exact solution, a conserved
quantity or an independent formulation.

- The spherical pendulum in Cartesian coordinates (φ = (|q|² − l²)/2, no nonholonomic constraint):
  φ at round-off, the angular momentum about the vertical conserved exactly (discrete Noether: the
  discrete Lagrangian and φ are invariant under rotations about z, and the position multiplier is
  radial), the energy bounded over 10⁵ steps; the paper's explicit maps equal the GNI step for step.
- The Chaplygin sleigh with its heading as a point (c, s) of the unit circle (φ = (c² + s² − 1)/2,
  the knife edge as a nonholonomic row): against the closed-form solution of
  gnipy.models.chaplygin_sleigh, order 2 fitted on the GNI, dla and the reference.
- The heavy top as a free rigid body on R³ × SO(3) whose pivot is held by φ(x, R) = x + Rc
  (orientation-dependent): against the Euler–Poisson equations about the pivot, solved by SciPy.
"""

import numpy as np
import pytest

import jax
import jax.numpy as jnp

import gnipy
from gnipy.errors import InputError, MethodError
from gnipy.holonomic import HOLONOMIC_METHODS, affine_part
from gnipy.models.chaplygin_sleigh import exact_body_velocities, exact_heading

#: numerics, and the verdicts at the saved nodes: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

G_ACC, LENGTH = 9.81, 1.0


def _pendulum_lagrangian(q, v):
    return 0.5 * v @ v - G_ACC * q[2]


def _pendulum_phi(q):
    return jnp.array([0.5 * (q @ q - LENGTH**2)])


PENDULUM = gnipy.System(_pendulum_lagrangian, None, holonomic=_pendulum_phi, n=3, coordinates=("x", "y", "z"),
                        name="spherical-pendulum")
P_Q0 = np.array([np.sin(1.0), 0.0, -np.cos(1.0)])
P_V0 = np.array([0.0, 1.2, 0.0])


def _pendulum_invariants(sol):
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    phi = 0.5 * (np.sum(q * q, axis=1) - LENGTH**2)
    energy = 0.5 * np.sum(v * v, axis=1) + G_ACC * q[:, 2]
    lz = q[:, 0] * v[:, 1] - q[:, 1] * v[:, 0]
    return phi, energy, lz


@pytest.mark.parametrize("method", ["gni-trapezoid", "gni-euler-a", "dla", "rattle", "suzuki4-gni-trapezoid",
                                    "sgni-midpoint"])
def test_pendulum_keeps_phi_and_the_angular_momentum(method):
    sol = gnipy.simulate(PENDULUM, method, q0=P_Q0, v0=P_V0, h=0.01, t_final=5.0)
    phi, _, lz = _pendulum_invariants(sol)
    assert np.max(np.abs(phi)) < 1e-15
    assert np.max(np.abs(lz - lz[0])) < 1e-13
    res = np.asarray(sol.constraint_residual)
    assert res.shape[1] == 2  # dphi.v, then phi itself
    assert np.max(np.abs(res[:, 1])) < 1e-15
    if method != "dla":  # dla reports G⁻¹p⁺, off the velocity constraint by O(h)
        assert np.max(np.abs(res[:, 0])) < 1e-14


def test_pendulum_reference_keeps_phi_and_energy():
    sol = gnipy.simulate(PENDULUM, "reference", q0=P_Q0, v0=P_V0, h=0.05, t_final=20.0)
    phi, energy, lz = _pendulum_invariants(sol)
    assert np.max(np.abs(phi)) < 1e-15
    assert np.max(np.abs(energy - energy[0])) < 1e-11
    assert np.max(np.abs(lz - lz[0])) < 1e-11  # the solver's tolerance, 1e-12, over T = 20


def test_pendulum_energy_is_bounded_over_long_runs():
    """The GNI with holonomic constraints only is the Marsden–West constrained variational
    integrator: symplectic on φ = 0, so its energy error oscillates without drift (measured over
    10⁵ steps: the last tenth's error no larger than the first tenth's), and φ stays at round-off."""
    sol = gnipy.simulate(PENDULUM, "gni-trapezoid", q0=P_Q0, v0=P_V0, h=0.01, steps=100_000, save_every=10)
    phi, energy, _ = _pendulum_invariants(sol)
    err = np.abs(energy - energy[0])
    tenth = len(err) // 10
    assert np.max(np.abs(phi)) < 1e-15
    assert 1e-4 < np.max(err[:tenth]) < 5e-3  # O(h²), not round-off: the check below can fail
    assert np.max(err[-tenth:]) < 1.05 * np.max(err[:tenth])


@pytest.mark.parametrize("name,ld", [("rattle", "trapezoid"), ("euler-a", "euler-a"), ("euler-b", "euler-b")])
def test_explicit_maps_equal_the_gni_with_holonomic_constraints(name, ld):
    from gnipy.discrete_lagrangians import DISCRETE_LAGRANGIANS
    from gnipy.integrators.gni import GNI

    a = gnipy.simulate(PENDULUM, name, q0=P_Q0, v0=P_V0, h=0.01, t_final=3.0)
    b = gnipy.simulate(PENDULUM, GNI(DISCRETE_LAGRANGIANS[ld](), start="rest"), q0=P_Q0, v0=P_V0, h=0.01,
                       t_final=3.0)
    assert np.max(np.abs(np.asarray(a.q) - np.asarray(b.q))) < 1e-13
    assert np.max(np.abs(np.asarray(a.v) - np.asarray(b.v))) < 1e-12


@pytest.mark.parametrize("method", ["gni-midpoint", "sgni-trapezoid"])
def test_symmetric_methods_run_back_to_their_start(method):
    fwd = gnipy.simulate(PENDULUM, method, q0=P_Q0, v0=P_V0, h=0.01, steps=500)
    back = gnipy.simulate(PENDULUM, method, h=-0.01, steps=500, t0=float(fwd.t[-1]), state0=fwd.final_state)
    assert np.max(np.abs(np.asarray(back.q[-1]) - P_Q0)) < 1e-12
    assert np.max(np.abs(np.asarray(back.v[-1]) - P_V0)) < 1e-11


def test_native_backend_agrees_with_xla():
    a = gnipy.simulate(PENDULUM, "gni-trapezoid", q0=P_Q0, v0=P_V0, h=0.01, t_final=2.0, backend="native")
    b = gnipy.simulate(PENDULUM, "gni-trapezoid", q0=P_Q0, v0=P_V0, h=0.01, t_final=2.0, backend="xla")
    assert a.backend == "native"
    assert np.max(np.abs(np.asarray(a.q) - np.asarray(b.q))) < 1e-13


# ---------------------------------------------------------------------------------------------
# The sleigh with its heading on the unit circle, against the closed form
# ---------------------------------------------------------------------------------------------
SLEIGH = dict(m=1.0, I=0.5, a=0.3)


def _sleigh_lagrangian(q, v, p):
    # on c² + s² = 1, ċ² + ṡ² = θ̇²: the zoo sleigh's l, with a constant metric
    return 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I"] * (v[2] ** 2 + v[3] ** 2)


def _sleigh_mu(q, p):
    c, s = q[2], q[3]  # -ẋ sinθ + ẏ cosθ − a θ̇ = 0 with θ̇ = c ṡ − s ċ
    return jnp.stack([-s, c, p["a"] * s, -p["a"] * c])[None]


def _sleigh_phi(q, p):
    return jnp.array([0.5 * (q[2] ** 2 + q[3] ** 2 - 1.0)])


SLEIGH4 = gnipy.System(_sleigh_lagrangian, _sleigh_mu, holonomic=_sleigh_phi, n=4, coordinates=("x", "y", "c", "s"),
                       args=SLEIGH, name="sleigh-on-the-circle")
S_Q0 = np.array([0.0, 0.0, 1.0, 0.0])
S_V0 = np.array([1.0, SLEIGH["a"], 0.0, 1.0])  # u = 1, ω = 1, heading 0


def _sleigh_errors(sol):
    q, v, t = np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.t)
    u = v[:, 0] * q[:, 2] + v[:, 1] * q[:, 3]
    omega = q[:, 2] * v[:, 3] - q[:, 3] * v[:, 2]
    theta = np.arctan2(q[:, 3], q[:, 2])
    ue, oe = exact_body_velocities(SLEIGH, (0.0, 0.0, 0.0), (1.0, SLEIGH["a"], 1.0), t)
    te = exact_heading(SLEIGH, (0.0, 0.0, 0.0), (1.0, SLEIGH["a"], 1.0), t)
    return np.max(np.abs(theta - te)), max(np.max(np.abs(u - ue)), np.max(np.abs(omega - oe)))


def _slope(hs, errs):
    return np.polyfit(np.log(hs), np.log(errs), 1)[0]


def test_sleigh_on_the_circle_reference_matches_the_closed_form():
    sol = gnipy.simulate(SLEIGH4, "reference", q0=S_Q0, v0=S_V0, h=0.1, t_final=4.0)
    e_theta, e_vel = _sleigh_errors(sol)
    assert max(e_theta, e_vel) < 1e-12
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) < 1e-14


@pytest.mark.parametrize("method,part", [("gni-trapezoid", 1), ("dla", 0)])
def test_sleigh_on_the_circle_converges_at_order_two(method, part):
    """The GNI: velocities and heading at order 2; dla: its configurations (its reported velocity
    G⁻¹p⁺ is first order, by construction)."""
    hs = np.array([0.04, 0.02, 0.01])
    errs, phis = [], []
    for h in hs:
        sol = gnipy.simulate(SLEIGH4, method, q0=S_Q0, v0=S_V0, h=float(h), t_final=4.0)
        errs.append(_sleigh_errors(sol)[part])
        phis.append(np.max(np.abs(np.asarray(sol.constraint_residual)[:, -1])))
    assert min(errs) > 1e-8  # above round-off
    assert abs(_slope(hs, errs) - 2.0) < 0.1
    assert max(phis) < 1e-15


# ---------------------------------------------------------------------------------------------
# The heavy top as a rigid body held at a pivot: R³ × SO(3), φ depends on the orientation
# ---------------------------------------------------------------------------------------------
TOP_I = np.diag([0.1, 0.2, 0.3])
TOP_C = np.array([0.1, 0.2, -0.5])  # body vector from the centre of mass to the pivot
TOP_W0 = np.array([1.0, 0.5, 3.0])


def _top_lagrangian(x, R, v):
    return 0.5 * v[:3] @ v[:3] + 0.5 * v[3:] @ jnp.asarray(TOP_I) @ v[3:] - G_ACC * x[2]


def _top_phi(x, R):
    return x + R @ jnp.asarray(TOP_C)


def _euler_poisson(T, n):
    """ω and Γ = Rᵀe₃ of the heavy top (mass 1) about its fixed pivot: I_p ω̇ = I_p ω × ω + g Γ × χ,
    Γ̇ = Γ × ω, χ = −c, I_p = I + |χ|² − χχᵀ (Steiner), by SciPy's DOP853 at 1e-13."""
    from scipy.integrate import solve_ivp

    chi = -TOP_C
    Ip = TOP_I + (chi @ chi) * np.eye(3) - np.outer(chi, chi)

    def rhs(t, y):
        w, gam = y[:3], y[3:]
        return np.concatenate([np.linalg.solve(Ip, np.cross(Ip @ w, w) + G_ACC * np.cross(gam, chi)),
                               np.cross(gam, w)])

    ts = np.linspace(0.0, T, n)
    sol = solve_ivp(rhs, (0.0, T), np.concatenate([TOP_W0, [0.0, 0.0, 1.0]]), t_eval=ts, rtol=1e-13,
                    atol=1e-13, method="DOP853")
    return sol.y[:3].T, sol.y[3:].T


@pytest.fixture(scope="module")
def top():
    from gnipy.lie_groups import SO3

    system = gnipy.System(_top_lagrangian, None, holonomic=_top_phi, n=3, group=SO3(), depends_on_orientation=True,
                          name="pivoted-top")
    x0 = -TOP_C
    v0 = np.concatenate([-np.cross(TOP_W0, TOP_C), TOP_W0])  # d/dt(x) = −R(ω × c)
    return system, x0, v0, _euler_poisson(2.0, 401)


def _top_error(sol, exact):
    w_exact, gamma_exact = exact
    idx = np.round(np.asarray(sol.t) / 0.005).astype(int)
    R = np.asarray(sol.R)
    return max(np.max(np.abs(np.asarray(sol.v)[:, 3:] - w_exact[idx])), np.max(np.abs(R[:, 2, :] - gamma_exact[idx])))


def test_top_reference_matches_euler_poisson(top):
    system, x0, v0, exact = top
    sol = gnipy.simulate(system, "reference", q0=x0, v0=v0, h=0.02, t_final=2.0)
    assert _top_error(sol, exact) < 1e-10
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) < 1e-14


def test_top_gni_converges_at_order_two_on_the_pivot(top):
    system, x0, v0, exact = top
    hs = np.array([0.02, 0.01, 0.005])
    errs = []
    for h in hs:
        sol = gnipy.simulate(system, "gni-trapezoid", q0=x0, v0=v0, h=float(h), t_final=2.0)
        errs.append(_top_error(sol, exact))
        assert np.max(np.abs(np.asarray(sol.constraint_residual))) < 1e-14  # φ = x + Rc and d φ.v
    assert abs(_slope(hs, errs) - 2.0) < 0.1


# ---------------------------------------------------------------------------------------------
# Refusals, checks, and the linear algebra
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["mp", "discrete-gradient", "shake", "euler-ab", "rat"])
def test_methods_that_would_let_phi_drift_refuse(method):
    with pytest.raises(MethodError, match="does not keep holonomic constraints") as info:
        gnipy.simulate(PENDULUM, method, q0=P_Q0, v0=P_V0, h=0.01, steps=3)
    assert "gni-trapezoid" in str(info.value)


def test_the_list_of_methods_is_the_methods_own_statement():
    from gnipy.methods import get_method, method_names

    from gnipy.integrators.composition import Composition

    methods = {name: get_method(name) for name in method_names()}
    single = {name for name, m in methods.items() if not isinstance(m, Composition)}
    keeps = {name for name in single if methods[name].holonomic}
    assert keeps == set(HOLONOMIC_METHODS)
    composed = [m for m in methods.values() if isinstance(m, Composition)]
    assert composed and all(m.holonomic == m.base.holonomic for m in composed)


def test_initial_configuration_off_phi_is_refused_and_projected():
    with pytest.raises(InputError, match="q0: the initial configuration violates the holonomic") as info:
        gnipy.simulate(PENDULUM, "gni-trapezoid", q0=1.01 * P_Q0, v0=P_V0, h=0.01, steps=3)
    assert "project_configuration" in str(info.value)
    q = np.asarray(PENDULUM.project_configuration(1.01 * P_Q0))
    assert abs(q @ q - LENGTH**2) < 1e-15
    assert np.max(np.abs(q - P_Q0)) < 1e-15  # the nearest point, radially


def test_bad_arguments_name_themselves():
    with pytest.raises(InputError, match="constraints: expected a callable mu"):
        gnipy.System(_pendulum_lagrangian, None, n=3)
    with pytest.raises(InputError, match="holonomic: expected a callable phi"):
        gnipy.System(_pendulum_lagrangian, None, holonomic=3.0, n=3)


def test_affine_part_on_the_joint_constraints():
    """Ỹ keeps μỸ = μY on the nonholonomic rows and has dφ Ỹ = 0 (exact linear algebra)."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((5, 5))
    G = A @ A.T + 5 * np.eye(5)
    mu, dphi, Y = rng.standard_normal((2, 5)), rng.standard_normal((1, 5)), rng.standard_normal(5)
    Yt = np.asarray(affine_part(jnp.asarray(G), jnp.asarray(mu), jnp.asarray(dphi), jnp.asarray(Y)))
    assert np.max(np.abs(mu @ Yt - mu @ Y)) < 1e-13
    assert np.max(np.abs(dphi @ Yt)) < 1e-13
