"""The differential-drive robot, coasting: two wheels on one axle and a chassis whose centre of mass
is ahead of the axle (Bloch, *Nonholonomic Mechanics and Control*, §1.7 for the sleigh it reduces
to; Siegwart, Nourbakhsh and Scaramuzza, *Introduction to Autonomous Mobile Robots*, §3.2 for the
robot's kinematics).

Coordinates $q = (x, y, \\varphi, \\theta_R, \\theta_L)$: the midpoint of the axle, the heading and
the two wheels' rolling angles. The wheels (radius $r$, mass $m_w$, moment $I_w$ about the axle and
$I_m$ about a vertical diameter) are at $\\pm b$ along the axle; the chassis (mass $m_c$, moment
$I_c$ about its centre of mass) has its centre of mass at distance $d$ ahead of the axle. With
$M = m_c + 2m_w$ and $I_\\varphi = I_c + m_c d^2 + 2m_w b^2 + 2I_m$,

$$l = \\tfrac12 M(\\dot x^2 + \\dot y^2) + m_c d\\,\\dot\\varphi(-\\dot x\\sin\\varphi + \\dot y\\cos\\varphi)
  + \\tfrac12 I_\\varphi\\dot\\varphi^2 + \\tfrac12 I_w(\\dot\\theta_R^2 + \\dot\\theta_L^2),$$

and the wheels roll without slipping: each wheel's forward speed is $r$ times its rolling rate and
the axle does not move sideways,

$$\\dot x\\cos\\varphi + \\dot y\\sin\\varphi \\pm b\\dot\\varphi = r\\dot\\theta_{R,L},\\qquad
  -\\dot x\\sin\\varphi + \\dot y\\cos\\varphi = 0 .$$

**Exact solution in body velocities.** With $u$ the forward speed and $\\omega = \\dot\\varphi$, the
Lagrange–d'Alembert equations reduce to those of the Chaplygin sleigh with the wheels' inertia
added ($M_e = M + 2I_w/r^2$, $I_e = I_\\varphi + 2I_w b^2/r^2$):

$$M_e\\dot u = m_c d\\,\\omega^2, \\qquad I_e\\dot\\omega = -m_c d\\,u\\,\\omega,$$

with the energy $E = \\tfrac12 M_e u^2 + \\tfrac12 I_e\\omega^2$. With $U = \\sqrt{2E/M_e}$,
$\\kappa = m_c d\\,U/I_e$ and $c_0 = \\operatorname{artanh}(u_0/U)$: $u = U\\tanh(\\kappa t + c_0)$,
$\\omega = \\omega_0\\cosh c_0/\\cosh(\\kappa t + c_0)$, the heading
$\\varphi = \\varphi_0 + \\frac{\\omega_0\\cosh c_0}{\\kappa}(\\operatorname{gd}(\\kappa t + c_0) -
\\operatorname{gd}(c_0))$ and the wheels' angles
$\\theta_{R,L} = \\theta_{R,L}(0) + \\big(\\frac{U}{\\kappa}\\log\\frac{\\cosh(\\kappa t + c_0)}{\\cosh c_0}
\\pm b(\\varphi - \\varphi_0)\\big)/r$: the robot turns through a finite angle and ends rolling
straight at speed $U$, whichever way it started (the sleigh's behaviour). The position has no
elementary closed form (as for the sleigh): :func:`exact_body_velocities` and :func:`exact_angles`
give the closed forms.

**Invariants.** The energy, and $\\varphi - r(\\theta_R - \\theta_L)/(2b)$: the difference of the two
rolling rows, $2b\\dot\\varphi = r(\\dot\\theta_R - \\dot\\theta_L)$, is integrable (its coefficients are
constant), so the heading is a function of the wheels' angles.

The free motion contracts phase volume as the sleigh's does, so the GNI (volume-preserving) cannot
follow it: the run-time diagnostics flag it, and the atlas chooses another default method.

Default parameters: a small robot, $m_c = 1$, $I_c = 0.05$, $d = 0.1$, $b = 0.15$, $r = 0.05$,
$m_w = 0.1$, $I_w = m_w r^2/2$, $I_m = m_w r^2/4$ (SI units). Default initial condition: at the origin
heading along $x$, driving at $u_0 = 0.5$ m/s and turning at $\\omega_0 = 2$ rad/s.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..registry import ModelSpec, register
from ..system import System
from .elementary import cosh_ratio, gudermannian, log_cosh_ratio

__all__ = ["MODEL", "exact_body_velocities", "exact_angles", "body_velocities", "energy", "wheel_heading",
           "rolling_velocity"]

COORDINATES = ("x", "y", "phi", "theta_R", "theta_L")
PARAMS = {"m_c": 1.0, "I_c": 0.05, "d": 0.1, "b": 0.15, "r": 0.05, "m_w": 0.1, "I_w": 1.25e-4, "I_m": 6.25e-5}
#: the default initial condition's forward speed (m/s) and turning rate (rad/s)
U0, OMEGA0 = 0.5, 2.0


def _masses(p):
    M = p["m_c"] + 2 * p["m_w"]
    I_phi = p["I_c"] + p["m_c"] * p["d"] ** 2 + 2 * p["m_w"] * p["b"] ** 2 + 2 * p["I_m"]
    return M, I_phi


def _lagrangian(q, v, p):
    M, I_phi = _masses(p)
    phi = q[2]
    dx, dy, dphi, dR, dL = v
    lateral = -dx * jnp.sin(phi) + dy * jnp.cos(phi)
    return (0.5 * M * (dx**2 + dy**2) + p["m_c"] * p["d"] * dphi * lateral + 0.5 * I_phi * dphi**2
            + 0.5 * p["I_w"] * (dR**2 + dL**2))


def _constraints(q, p):
    b, r = p["b"], p["r"]
    phi = q[2]
    c, s = jnp.cos(phi), jnp.sin(phi)
    one, zero = jnp.ones_like(phi), jnp.zeros_like(phi)
    return jnp.stack([
        jnp.stack([c, s, b * one, -r * one, zero]),
        jnp.stack([c, s, -b * one, zero, -r * one]),
        jnp.stack([-s, c, zero, zero, zero]),
    ])


def rolling_velocity(p, phi, u, omega):
    """The velocity $(\\dot x, \\dot y, \\dot\\varphi, \\dot\\theta_R, \\dot\\theta_L)$ of forward speed
    `u` and turning rate `omega` at heading `phi` (on the constraints)."""
    b, r = p["b"], p["r"]
    return (u * float(np.cos(phi)), u * float(np.sin(phi)), omega, (u + b * omega) / r, (u - b * omega) / r)


def _default_ic(p):
    return (0.0, 0.0, 0.0, 0.0, 0.0), rolling_velocity(p, 0.0, U0, OMEGA0)


def _build(p):
    return System(_lagrangian, _constraints, coordinates=COORDINATES, name="differential-drive", args=p, params=p,
                  defaults=_default_ic(p))


def body_velocities(q, v):
    """Forward speed $u = \\dot x\\cos\\varphi + \\dot y\\sin\\varphi$ and $\\omega = \\dot\\varphi$ of arrays
    `q`, `v` of shape (..., 5)."""
    q, v = np.asarray(q), np.asarray(v)
    phi = q[..., 2]
    return v[..., 0] * np.cos(phi) + v[..., 1] * np.sin(phi), v[..., 2]


def _effective(p):
    M, I_phi = _masses(p)
    Me = M + 2 * p["I_w"] / p["r"] ** 2
    Ie = I_phi + 2 * p["I_w"] * p["b"] ** 2 / p["r"] ** 2
    return Me, Ie


def _constants(p, q0, v0):
    Me, Ie = _effective(p)
    u0, w0 = (float(x) for x in body_velocities(np.asarray(q0, float), np.asarray(v0, float)))
    U = np.sqrt(u0**2 + Ie / Me * w0**2)
    kappa = p["m_c"] * p["d"] * U / Ie
    return u0, w0, U, kappa


def exact_body_velocities(p, q0, v0, t):
    """Exact forward speed $u(t)$ and turning rate $\\omega(t)$, arrays (T,), from t = 0 (`v0` on the
    constraints; only $u_0$ and $\\omega_0$ are read from it)."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    u0, w0, U, kappa = _constants(p, q0, v0)
    if w0 == 0.0 or kappa == 0.0:  # straight, or d = 0: both constant
        return u0 + 0 * t, w0 + 0 * t
    c0 = np.arctanh(u0 / U)
    s = kappa * t + c0
    return U * np.tanh(s), w0 * cosh_ratio(c0, s)


def exact_angles(p, q0, v0, t):
    """Exact heading $\\varphi(t)$ and wheel angles $\\theta_R(t)$, $\\theta_L(t)$, arrays (T,), from
    t = 0 (the module docstring)."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    u0, w0, U, kappa = _constants(p, q0, v0)
    phi0, thR0, thL0 = (float(q0[i]) for i in (2, 3, 4))
    if w0 == 0.0 or kappa == 0.0:
        turned, travelled = w0 * t, u0 * t
    else:
        c0 = np.arctanh(u0 / U)
        s = kappa * t + c0
        turned = w0 * np.cosh(c0) / kappa * (gudermannian(s) - gudermannian(c0))
        travelled = U / kappa * log_cosh_ratio(s, c0)
    b, r = p["b"], p["r"]
    return phi0 + turned, thR0 + (travelled + b * turned) / r, thL0 + (travelled - b * turned) / r


def energy(p, q, v):
    """The kinetic energy $l$ (no potential)."""
    return _lagrangian(q, v, p)


def wheel_heading(p, q, v):
    """$\\varphi - r(\\theta_R - \\theta_L)/(2b)$, constant by the rolling constraints."""
    return q[2] - p["r"] * (q[3] - q[4]) / (2 * p["b"])


MODEL = register(
    ModelSpec(
        name="differential-drive",
        description="two-wheeled robot coasting, centre of mass d ahead of the axle: the sleigh with wheels",
        build=_build,
        params=PARAMS,
        coordinates=COORDINATES,
        q0=(0.0, 0.0, 0.0, 0.0, 0.0),
        v0=rolling_velocity(PARAMS, 0.0, U0, OMEGA0),
        default_ic=_default_ic,
        invariants={"energy": energy, "wheel_heading": wheel_heading},
        notes=__doc__,
        positive=('m_c', 'I_c', 'b', 'r', 'm_w', 'I_w', 'I_m'),
    )
)
