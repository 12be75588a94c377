"""The Chaplygin sleigh (Bloch, *Nonholonomic Mechanics and Control*, §1.7).

A rigid body on the plane supported by a knife edge at distance $a$ behind its centre of mass.
Coordinates $q = (x, y, \\theta)$: centre of mass and heading. With $I$ the moment of inertia about
the centre of mass,

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12 I\\dot\\theta^2,$$

and the contact point $(x, y) - a(\\cos\\theta, \\sin\\theta)$ cannot move sideways:
$-\\dot x\\sin\\theta + \\dot y\\cos\\theta - a\\dot\\theta = 0$,
$\\mu = [-\\sin\\theta, \\cos\\theta, -a]$.

**Exact solution in body velocities.** Let $u = \\dot x\\cos\\theta + \\dot y\\sin\\theta$ (forward
speed), $\\omega = \\dot\\theta$; the constraint makes the lateral speed $a\\omega$. The equations
$m\\ddot x = -\\lambda\\sin\\theta$, $m\\ddot y = \\lambda\\cos\\theta$, $I\\ddot\\theta = -a\\lambda$ reduce to

$$\\dot u = a\\omega^2, \\qquad (I + m a^2)\\dot\\omega = -m a u\\omega,$$

with the energy $E = \\tfrac12 m u^2 + \\tfrac12 (I + m a^2)\\omega^2$ conserved. With
$J = I + m a^2$, $U = \\sqrt{2E/m}$, $\\kappa = a m U / J$ and $c_0 = \\operatorname{artanh}(u_0/U)$:

$$u = U\\tanh(\\kappa t + c_0), \\qquad \\omega = \\omega_0\\frac{\\cosh c_0}{\\cosh(\\kappa t + c_0)}
  = \\operatorname{sign}(\\omega_0)\\sqrt{(2E - m u^2)/J},$$

(the second form of $\\omega$ from $\\dot\\omega/\\omega = -(ma/J)u$), and the heading
$\\theta = \\theta_0 + \\frac{\\omega_0\\cosh c_0}{\\kappa}\\big(\\operatorname{gd}(\\kappa t + c_0) -
\\operatorname{gd}(c_0)\\big)$ with the Gudermannian $\\operatorname{gd}(s) = 2\\arctan\\tanh(s/2)$.
The sleigh turns through a finite total angle and ends sliding straight at speed $U$ in the
direction of $\\operatorname{sign}(a)$. When $\\omega_0 = 0$ it slides straight at constant $u_0$;
when $a = 0$, $u$ and $\\omega$ are constant.

The position has no elementary closed form for generic parameters: the contact point moves with
velocity $u(\\cos\\theta, \\sin\\theta)$, and in the variable $g = \\operatorname{gd}(\\kappa t + c_0)$ its
displacement is an integral of $\\tan g\\, e^{i\\beta g}$ with a non-integer $\\beta$. So
:data:`MODEL` has no `exact`; :func:`exact_body_velocities` and :func:`exact_heading` give the
closed forms, and :func:`body_velocities` converts a numerical solution for comparison.

**Invariants.** The energy.

Default initial condition: $q_0 = (0, 0, 0)$, $v_0 = (1, a, 1)$ (on the constraint for every $a$).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from ..registry import ModelSpec, register
from .elementary import cosh_ratio, gudermannian

__all__ = ["MODEL", "exact_body_velocities", "exact_heading", "body_velocities"]

COORDINATES = ("x", "y", "theta")


def _lagrangian(q, v, p):
    m, I = p["m"], p["I"]
    dx, dy, dtheta = v
    return 0.5 * m * (dx**2 + dy**2) + 0.5 * I * dtheta**2


def _constraints(q, p):
    th = q[2]
    return jnp.stack([-jnp.sin(th), jnp.cos(th), -p["a"] * jnp.ones_like(th)])[None, :]


def _default_ic(p):
    return (0.0, 0.0, 0.0), (1.0, p["a"], 1.0)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=COORDINATES,
        name="chaplygin-sleigh",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def body_velocities(q, v):
    """Forward speed $u = \\dot x\\cos\\theta + \\dot y\\sin\\theta$ and $\\omega = \\dot\\theta$ of
    arrays `q`, `v` of shape (..., 3)."""
    q, v = np.asarray(q), np.asarray(v)
    th = q[..., 2]
    return v[..., 0] * np.cos(th) + v[..., 1] * np.sin(th), v[..., 2]


def _constants(p, q0, v0):
    m, I, a = p["m"], p["I"], p["a"]
    J = I + m * a**2
    u0, w0 = (float(x) for x in body_velocities(np.asarray(q0, float), np.asarray(v0, float)))
    E = 0.5 * m * u0**2 + 0.5 * J * w0**2
    U = np.sqrt(2 * E / m)
    kappa = a * m * U / J
    return u0, w0, U, kappa


def exact_body_velocities(p, q0, v0, t):
    """Exact forward speed $u(t)$ and angular velocity $\\omega(t)$, arrays (T,), from t = 0.

    `v0` must satisfy the constraint; only $u_0$ and $\\omega_0$ are read from it.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    u0, w0, U, kappa = _constants(p, q0, v0)
    if w0 == 0.0 or kappa == 0.0:  # straight sliding, or a = 0: both constant
        return u0 + 0 * t, w0 + 0 * t
    c0 = np.arctanh(u0 / U)
    s = kappa * t + c0
    return U * np.tanh(s), w0 * cosh_ratio(c0, s)


def exact_heading(p, q0, v0, t):
    """Exact heading $\\theta(t)$, array (T,), from t = 0 (see the module docstring)."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    u0, w0, U, kappa = _constants(p, q0, v0)
    th0 = float(q0[2])
    if w0 == 0.0 or kappa == 0.0:
        return th0 + w0 * t
    c0 = np.arctanh(u0 / U)
    return th0 + w0 * np.cosh(c0) / kappa * (gudermannian(kappa * t + c0) - gudermannian(c0))


def _energy(p, q, v):
    return 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I"] * v[2] ** 2


MODEL = register(
    ModelSpec(
        name="chaplygin-sleigh",
        description="Chaplygin sleigh: knife edge a behind the centre of mass, −ẋ sinθ + ẏ cosθ = a θ̇",
        build=_build,
        params={"m": 1.0, "I": 1.0, "a": 0.5},
        coordinates=COORDINATES,
        q0=(0.0, 0.0, 0.0),
        v0=(1.0, 0.5, 1.0),
        default_ic=_default_ic,
        invariants={"energy": _energy},
        notes=__doc__,
        positive=('m', 'I'),
    )
)
