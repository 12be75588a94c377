"""The rolling disk free to lean (gnipy.models.rolling_disk) against closed forms and SymPy:

- the steady circular motions of the module's condition are solutions: the continuous reference
  and gni-trapezoid keep one to its closed form (gni-trapezoid at order 2, fitted on points above
  round-off);
- the upright disk rolling straight: gnipy.linearize's lean eigenvalues against the closed form
  λ² = (mgR − C(C + mR²)Ω²/A)/(A + mR²), stable above Ω_c = √(g/3R);
- a nutating motion (the steady motion pushed in θ̇): the zoo's hand-written model and the same disk
  written independently with sympy.physics.mechanics (tests/sympy_models.py: contact-point
  coordinates, another Euler sequence, Kane's method integrated by SciPy's DOP853) follow the same
  centre of mass, and the energy is conserved.
"""

import math

import numpy as np
import pytest

import gnipy
from gnipy.models import rolling_disk as rd

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

P = dict(rd.PARAMS)


def test_registered_with_its_steady_default():
    spec = gnipy.get_model("rolling-disk")
    assert spec.coordinates == ("x", "y", "theta", "phi", "psi") and "energy" in spec.invariants
    q0, v0 = spec.initial_condition(spec.params)
    system = spec.system()
    assert np.max(np.abs(np.asarray(system.constraint_residual(np.array(q0), np.array(v0))))) < 1e-15
    # the documented condition of a steady motion holds for the default's lean, turning rate and spin
    s, th, om = v0[4] + v0[3] * math.cos(q0[2]), q0[2], v0[3]
    assert (th, om, v0[2]) == (rd.THETA0, rd.OMEGA0, 0.0)
    m, R, A, C, g = (P[k] for k in ("m", "R", "A", "C", "g"))
    condition = A * om**2 * math.sin(th) * math.cos(th) - (C + m * R**2) * s * om * math.sin(th) - m * g * R * math.cos(th)
    assert abs(condition) < 1e-15
    assert rd.exact(P, q0, (*v0[:2], 1e-3, *v0[3:]), [0.0, 1.0]) is None  # not steady: no closed form
    with pytest.raises(ValueError, match="omega"):
        rd.steady_spin(P, 1.0, 0.0)


def test_steady_motion_is_kept_by_the_reference_and_gni_at_order_two():
    spec = gnipy.get_model("rolling-disk")
    system = spec.system()
    q0, v0 = rd.steady_motion(P, theta=1.0, omega=1.5, q0=(0.2, -0.1, None, 0.3, 0.0))
    t_final = 2.0
    ref = gnipy.simulate(system, "reference", q0, v0, h=0.05, t_final=t_final)
    qe, ve = rd.exact(P, q0, v0, np.asarray(ref.t))
    assert np.max(np.abs(np.asarray(ref.q) - qe)) < 1e-9 and np.max(np.abs(np.asarray(ref.v) - ve)) < 1e-9
    hs = np.array([0.04, 0.02, 0.01])
    errors = []
    for h in hs:  # one program (100 steps, h traced); the error at t = 1, node 1/h
        sol = gnipy.simulate(system, "gni-trapezoid", q0, v0, h=float(h), steps=100)
        assert sol.healthy
        node = int(round(1.0 / h))
        assert float(sol.t[node]) == pytest.approx(1.0, abs=1e-12)
        qe, _ = rd.exact(P, q0, v0, [1.0])
        errors.append(np.max(np.abs(np.asarray(sol.q[node]) - qe[0])))
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    # measured: errors 6.09e-5, 1.52e-5, 3.81e-6 at t = 1: slope 2.000, far above round-off
    assert min(errors) > 1e-10 and 1.9 < slope < 2.1, (errors, slope)


def test_upright_rolling_lean_eigenvalues_are_the_closed_form():
    system = gnipy.make_system("rolling-disk")
    m, R, A, C, g = (P[k] for k in ("m", "R", "A", "C", "g"))
    critical = math.sqrt(g / (3 * R))  # the uniform disk: A = mR²/4, C = mR²/2
    for spin in (0.5 * critical, 2.0 * critical):
        q = np.array([0.0, 0.0, math.pi / 2, 0.0, 0.0])
        v = np.array([-R * spin, 0.0, 0.0, 0.0, spin])  # straight along −n, σ = ψ̇
        lin = gnipy.linearize(system, q, v)
        lam2 = (m * g * R - C * (C + m * R**2) * spin**2 / A) / (A + m * R**2)
        lam = np.sqrt(complex(lam2))
        expected = np.sort_complex(np.array([lam, -lam]))
        ours = np.sort_complex(lin.nonzero_eigenvalues)
        assert ours.shape == (2,) and np.max(np.abs(ours - expected)) < 1e-10, (ours, expected)
        assert lin.stable == (spin > critical)


def _sympy_disk_centre(q_s, u_s, t):
    """The disk of tests/sympy_models.py with the zoo's default parameters, integrated by SciPy's
    DOP853 from Kane's equations (System.form_eoms, rhs): its centre of mass at the times `t`, (T, 3)."""
    import sympy as sp
    from scipy.integrate import solve_ivp
    from sympy_models import rolling_disk_system

    system = rolling_disk_system()
    system.form_eoms()
    symbols, values = sp.symbols("m R g"), [P["m"], P["R"], P["g"]]
    state = [*system.q, *system.u]
    rhs = sp.lambdify([state, symbols], system.rhs(), "numpy")
    centre = system.bodies[0].masscenter.pos_from(system.fixed_point).to_matrix(system.frame)
    where = sp.lambdify([state, symbols], centre, "numpy")
    ref = solve_ivp(lambda _, y: np.ravel(rhs(y, values)).astype(float), (0.0, float(t[-1])), [*q_s, *u_s],
                    method="DOP853", rtol=1e-13, atol=1e-13, t_eval=t)
    assert ref.success
    return np.array([np.ravel(where(y, values)) for y in ref.y.T])


def test_nutation_matches_sympys_disk_and_keeps_the_energy():
    """The zoo's disk against tests/sympy_models.py's, written independently: the contact point
    (x_c, y_c), heading ψ, lean θ_s about the horizontal diameter A.x, spin φ_s about the axis B.y,
    centre = contact + R B.z. The zoo's axis is k = −B.y, so θ = π/2 + θ_s, φ = ψ, ψ_zoo = −φ_s."""
    R = P["R"]
    lean_s, heading_rate, spin_s, lean_rate = -0.4, 1.2, -2.0, 0.3
    theta = math.pi / 2 + lean_s
    bz = np.array([0.0, -math.sin(lean_s), math.cos(lean_s)])  # B.z at ψ = 0
    q0 = np.array([R * bz[0], R * bz[1], theta, 0.0, 0.0])  # the centre's horizontal position
    sigma = -spin_s + heading_rate * math.cos(theta)  # the zoo's spin about its axis
    # the centre's velocity from the zoo's rolling rows at φ = 0
    v0 = np.array([-R * sigma, -R * math.sin(theta) * lean_rate, lean_rate, heading_rate, -spin_s])
    system = gnipy.make_system("rolling-disk")
    assert np.max(np.abs(np.asarray(system.constraint_residual(q0, v0)))) < 1e-15
    # the contact point's velocity: the centre's minus R d(B.z)/dt, B turning at ψ̇ N.z + θ̇_s A.x
    centre_velocity = np.array([v0[0], v0[1], R * math.cos(theta) * lean_rate])
    contact_velocity = centre_velocity - R * np.cross([lean_rate, 0.0, heading_rate], bz)
    assert abs(contact_velocity[2]) < 1e-15
    q_s = [0.0, 0.0, 0.0, lean_s, 0.0]
    u_s = [heading_rate, lean_rate, spin_s, contact_velocity[0], contact_velocity[1]]
    t = np.linspace(0.0, 2.0, 41)
    centre_s = _sympy_disk_centre(q_s, u_s, t)
    sol = gnipy.simulate(system, "reference", q0, v0, h=0.05, t_final=2.0)
    q = np.asarray(sol.q)
    centre = np.stack([q[:, 0], q[:, 1], R * np.sin(q[:, 2])], axis=-1)
    assert np.max(np.abs(centre - centre_s)) < 1e-8
    assert np.ptp(q[:, 2]) > 0.05  # it nutates: the lean changes
    e = np.array([float(rd.energy(P, qi, vi)) for qi, vi in zip(q, np.asarray(sol.v))])
    assert np.max(np.abs(e - e[0])) < 1e-10
