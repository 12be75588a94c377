"""gnipy.linearize: the linear stability of a steady motion, against the closed form of the upright
rolling disk, and what it refuses.

**The closed form.** A disk of mass m, radius R, moments of inertia A about a diameter and C about
its axis, rolls upright and straight with spin rate Ω (speed RΩ). Linearized in the lean θ and the
heading rate ψ̇ (the classical result: e.g. Neimark & Fufaev, *Dynamics of Nonholonomic Systems*,
§ on the rolling disk; O'Reilly, *Nonlinear Dynamics* 10 (1996) 287–305):

    (A + mR²) θ̈ + (C + mR²) Ω ψ̇ − m g R θ = 0,      A ψ̈ − C Ω θ̇ = 0,

so ψ̇ − (CΩ/A) θ is conserved and θ obeys (A + mR²) θ̈ = (m g R − C(C + mR²)Ω²/A) θ: eigenvalues
±λ with λ² = (m g R − C(C + mR²)Ω²/A)/(A + mR²), stable for Ω² > m g R A/(C(C + mR²)). For the
uniform disk (A = mR²/4, C = mR²/2) that is v² = R²Ω² > gR/3; for a hoop (A = mR²/2, C = mR²)
v² > gR/4, the textbook thresholds. The ignorable coordinates x, y, φ and then ψ (it entered only
the contact point's velocity) are dropped, leaving the state (θ, ψ̇, θ̇, φ̇): its other two
eigenvalues are zero, of the conserved spin and ψ̇ − (CΩ/A)θ.
The disk is built with sympy.physics.mechanics (tests/sympy_models.py) and differentiated by JAX
through gnipy's Lagrange–d'Alembert equations: an independent formulation of the same physics.
"""

import numpy as np
import pytest
from sympy_models import rolling_disk_system

import gnipy

M, R, G = 1.0, 0.5, 9.81
A, C = M * R ** 2 / 4, M * R ** 2 / 2
CRITICAL_SPIN = np.sqrt(M * G * R * A / (C * (C + M * R ** 2)))  # = sqrt(g / 3R) for the uniform disk


@pytest.fixture(scope="module")
def disk():
    return gnipy.from_sympy(rolling_disk_system(), params={"m": M, "R": R, "g": G}, name="rolling-disk")


def _upright(spin):
    # q = (x, y, psi, theta, phi); rolling along x: ẋ = R φ̇ (ψ = 0)
    return np.zeros(5), np.array([R * spin, 0.0, 0.0, 0.0, spin])


def test_the_critical_speed_is_the_textbook_one():
    np.testing.assert_allclose(CRITICAL_SPIN * R, np.sqrt(G * R / 3), rtol=1e-15)


@pytest.mark.parametrize("spin", [1.0, 2.0, 0.9 * CRITICAL_SPIN, 1.1 * CRITICAL_SPIN, 4.0, 8.0])
def test_upright_rolling_disk_eigenvalues(disk, spin):
    lin = gnipy.linearize(disk, *_upright(spin))
    lam2 = (M * G * R - C * (C + M * R ** 2) * spin ** 2 / A) / (A + M * R ** 2)
    lam = np.sqrt(complex(lam2))
    assert lin.state == ("theta", "dpsi", "dtheta", "dphi") and lin.zero_count == 2
    nonzero = lin.nonzero_eigenvalues
    np.testing.assert_allclose(np.sort_complex(nonzero), np.sort_complex(np.array([lam, -lam])), rtol=1e-10)
    assert lin.stable == (spin > CRITICAL_SPIN)
    if spin > CRITICAL_SPIN:
        assert lin.growth_rate == 0.0 and np.all(nonzero.real == 0.0)  # neutral: a conservative system
    else:
        np.testing.assert_allclose(lin.growth_rate, lam.real, rtol=1e-10)


def test_the_critical_speed_is_found_along_the_family_of_steady_motions(disk, tmp_path):
    curve = gnipy.analysis.stability_curve(disk, _upright, np.linspace(1.0, 6.0, 6), tol=1e-11)
    fig = gnipy.plots.plot_stability(curve, tmp_path / "disk.png", xlabel="spin rate (rad/s)")
    assert (tmp_path / "disk.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"{CRITICAL_SPIN:.6g}" in [t.get_text() for t in fig.axes[0].texts]  # the transition, marked
    assert list(curve.stable) == [False, False, True, True, True, True]
    assert len(curve.transitions) == 1
    np.testing.assert_allclose(curve.transitions[0], CRITICAL_SPIN, rtol=1e-9)
    np.testing.assert_allclose(curve.growth_rate[0], np.sqrt((M * G * R - C * (C + M * R ** 2) / A) / (A + M * R ** 2)),
                               rtol=1e-10)
    with pytest.raises(gnipy.InputError, match="increasing"):
        gnipy.analysis.stability_curve(disk, _upright, [2.0, 1.0])


def test_a_methods_discrete_map_converges_to_the_continuous_eigenvalues(disk):
    """Above the critical speed (Ω = 4, λ = ±4.7649i): the exponents log(μ)/h of gni-midpoint's
    step map converge to ±λ at order 2 and stay on the imaginary axis (the neutral stability kept;
    measured for gni-trapezoid, dla, sgni-trapezoid and the discrete gradient too); gni-euler-b's
    have a positive real part (+0.082 at h = 0.005: a stable disk made to grow), gni-euler-a's the
    opposite (numerical damping). mp is refused (a metric that depends on q)."""
    q, v = _upright(4.0)
    lam = gnipy.linearize(disk, q, v).nonzero_eigenvalues
    hs = np.array([0.02, 0.01, 0.005])
    errors = []
    for h in hs:
        near = gnipy.analysis.discrete_linearization(disk, "gni-midpoint", q, v, float(h)).nearest(lam)
        assert np.max(np.abs(near.real)) < 1e-10
        errors.append(np.max(np.abs(near - lam)))
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.95 < slope < 2.05 and errors[-1] < 1e-3, (errors, slope)
    growth = gnipy.analysis.discrete_linearization(disk, "gni-euler-b", q, v, 0.005).nearest(lam).real
    assert np.all(growth > 0.05), growth
    with pytest.raises(gnipy.MethodError, match="constant metric"):
        gnipy.analysis.discrete_linearization(disk, "mp", q, v, 0.01)
    with pytest.raises(gnipy.InputError, match="h: must be > 0"):
        gnipy.analysis.discrete_linearization(disk, "gni-midpoint", q, v, -0.01)


def test_what_is_not_a_steady_motion_is_refused(disk):
    q, v = _upright(4.0)
    with pytest.raises(gnipy.InputError, match="not on the constraints"):
        gnipy.linearize(disk, q, v + np.array([0.0, 0.1, 0.0, 0.0, 0.0]))
    leaning = q + np.array([0.0, 0.0, 0.0, 0.2, 0.0])
    with pytest.raises(gnipy.InputError, match="is not a steady motion: the velocity"):
        gnipy.linearize(disk, leaning, v)  # gravity tips a leaning disk that does not turn
    # a particle passing through the bottom of a well x²/2, with ż = y ẋ: no acceleration there,
    # but x moves and the equations depend on it
    import jax.numpy as jnp

    well = gnipy.System(lambda q, v: 0.5 * v @ v - 0.5 * q[0] ** 2, lambda q: jnp.stack([-q[1], 0.0 * q[1], 1.0 + 0.0 * q[1]])[None],
                        coordinates=("x", "y", "z"))
    with pytest.raises(gnipy.InputError, match="the coordinates 'x' move"):
        gnipy.linearize(well, np.zeros(3), np.array([1.0, 0.0, 0.0]))
    assert gnipy.linearize(well, np.zeros(3), np.zeros(3)).stable  # at rest at the bottom
    # forces: one of (q, v) alone is part of the equations. A drag −c v makes the rest point
    # asymptotically stable: at y = 0 the constraint holds ż = 0, so ẍ = −x − c ẋ and ÿ = −c ẏ,
    # eigenvalues −c/2 ± i√(1 − c²/4) and −c (derived by hand); inputs and a force in t have no
    # steady motion
    drag = well.with_force(lambda q, v, u, t: -0.3 * v)
    lin = gnipy.linearize(drag, np.zeros(3), np.zeros(3))
    assert lin.stable
    expected = [-0.15 - 1j * np.sqrt(1 - 0.15 ** 2), -0.15 + 1j * np.sqrt(1 - 0.15 ** 2), -0.3]
    np.testing.assert_allclose(sorted(lin.eigenvalues, key=lambda z: (z.imag, z.real)),
                               sorted(expected, key=lambda z: (z.imag, z.real)), rtol=1e-12)
    with pytest.raises(gnipy.InputError, match="has 1 input"):
        gnipy.linearize(well.with_force(lambda q, v, u, t: u[0] * v, inputs=1), np.zeros(3), np.zeros(3))
    with pytest.raises(gnipy.InputError, match="force that depends on the time"):
        gnipy.linearize(well.with_force(lambda q, v, u, t: jnp.sin(t) + 0.0 * v), np.zeros(3), np.zeros(3))
    with pytest.raises(gnipy.InputError, match=r"q: expected a vector of length 5"):
        gnipy.linearize(disk, np.zeros(4), v)
    with pytest.raises(gnipy.InputError, match="R\\^n x G"):
        gnipy.linearize(gnipy.make_system("rolling-ball"), np.zeros(2), np.zeros(5))


def test_the_sleigh_sliding_straight_and_the_gnis_parasitic_growth():
    """The Chaplygin sleigh sliding straight at speed u (chaplygin_sleigh.py: (I + m a²) ω̇ = −m a u ω)
    is stable for a·u > 0 with λ = −m a u/(I + m a²) = −0.4 (m = I = 1, a = 0.5, u = 1), unstable
    for a·u < 0. dla's map contracts that perturbation like the motion and has nothing that grows;
    the GNI's map (volume-preserving) has a multiplier −1.0408 at h = 0.1: a growth of +0.4 in the
    hidden momentum, the mirror of the contraction (methods guide, 'Where the GNI struggles')."""
    sleigh = gnipy.make_system("chaplygin-sleigh").with_args(m=1.0, I=1.0, a=0.5)
    q, v = np.zeros(3), np.array([1.0, 0.0, 0.0])
    lam = gnipy.linearize(sleigh, q, v).nonzero_eigenvalues
    np.testing.assert_allclose(lam, [-0.4], rtol=1e-12)
    assert not gnipy.linearize(sleigh, q, -v).stable
    dla = gnipy.analysis.discrete_linearization(sleigh, "dla", q, v, 0.1)
    gni = gnipy.analysis.discrete_linearization(sleigh, "gni-midpoint", q, v, 0.1)
    assert abs(dla.nearest(lam)[0] - lam[0]) < 1e-3 and dla.growth_rate < 1e-12
    assert abs(gni.nearest(lam)[0] - lam[0]) < 1e-3
    np.testing.assert_allclose(gni.growth_rate, 0.4, rtol=1e-3)
    # a change of stability at 0 (a·u changes sign with a) is found, and the bisection stops
    curve = gnipy.analysis.stability_curve(sleigh, lambda a: (sleigh.with_args(a=a), q, v), [-0.5, 0.25], tol=1e-9)
    assert len(curve.transitions) == 1 and abs(curve.transitions[0]) <= 1e-9
    with pytest.raises(gnipy.InputError, match=r"steady\(0\) must return"):
        gnipy.analysis.stability_curve(sleigh, lambda a: None, [0.0, 0.25])
