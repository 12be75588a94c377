"""The rolling disk free to tilt (Euler's disk, a rolling coin): O'Reilly, *Nonlinear Dynamics* 10
(1996) 287–305; Borisov, Mamaev and Kilin, *Regul. Chaotic Dyn.* 8 (2003) 201–212; Bloch,
*Nonholonomic Mechanics and Control*, §1.4 for the upright case (:mod:`gnipy.models.vertical_disk`).

A disk of radius $R$, mass $m$ and moments $A$ (about a diameter) and $C$ (about its axis) rolls
without slipping on the horizontal plane under gravity $g$. Coordinates
$q = (x, y, \\theta, \\varphi, \\psi)$: the horizontal position of the centre, the angle between the
disk's axis and the vertical ($\\theta = \\pi/2$: upright), the heading (the direction of the
horizontal diameter) and the spin, the Euler angles $z$-$x$-$z$ $(\\varphi, \\theta, \\psi)$. The
centre is at height $R\\sin\\theta$ (the disk touches the plane: a holonomic constraint solved in
these coordinates), and with $\\sigma = \\dot\\psi + \\dot\\varphi\\cos\\theta$ the spin about the axis,

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2 + R^2\\cos^2\\theta\\,\\dot\\theta^2)
  + \\tfrac12 A(\\dot\\theta^2 + \\dot\\varphi^2\\sin^2\\theta) + \\tfrac12 C\\sigma^2 - m g R\\sin\\theta.$$

The contact point does not slide: the centre moves with $-R\\sigma\\,n + R\\dot\\theta\\,k$ ($n$ the
horizontal diameter, $k$ the axis), whose horizontal part gives the two rows
$\\dot x + R\\cos\\varphi\\,\\sigma - R\\sin\\theta\\sin\\varphi\\,\\dot\\theta = 0$ and
$\\dot y + R\\sin\\varphi\\,\\sigma + R\\sin\\theta\\cos\\varphi\\,\\dot\\theta = 0$.

**Steady motions (exact).** With $\\theta$ constant, $\\dot\\varphi = \\Omega$ and $\\sigma = s$
constant, the Lagrange–d'Alembert equations hold if and only if

$$A\\Omega^2\\sin\\theta\\cos\\theta - (C + mR^2)\\,s\\,\\Omega\\sin\\theta - m g R\\cos\\theta = 0$$

(the $\\theta$ equation; the $\\psi$ and $\\varphi$ equations hold for every such motion), and the
centre then runs round a circle of radius $R|s/\\Omega|$ at speed $R|s|$ while the disk leans at
$\\theta$: :func:`steady_spin` gives $s$ for $\\theta$ and $\\Omega$. Upright ($\\theta = \\pi/2$) it
reads $s\\Omega = 0$: the disk rolls straight ($\\Omega = 0$) or spins in place about a vertical
diameter ($s = 0$). :data:`MODEL`'s `exact` is this motion, for an initial condition that is one
(to 1e-12), and None otherwise: the general motion has no elementary closed form (Appell and
Korteweg reduced it to hypergeometric functions).

**Invariants.** The energy $l$'s kinetic part plus $m g R\\sin\\theta$. (Two more integrals exist,
Chaplygin's, through hypergeometric functions of $\\cos\\theta$; they are not registered.)

**Linear stability.** Upright and rolling straight at speed $V = R|\\dot\\psi|$ the uniform disk
($A = mR^2/4$, $C = mR^2/2$) is stable when $V^2 > gR/3$ (`gnipy.linearize` at that motion gives
the lean's eigenvalues: the docs' models guide).

Default parameters: the uniform disk $m = R = g = 1$, $A = 1/4$, $C = 1/2$. Default initial
condition: the steady motion leaning at $\\theta_0 = 1.2$ (0.37 rad from upright) and turning at
$\\Omega = 1$, for which $s = (A\\Omega^2\\sin\\theta_0\\cos\\theta_0 - mgR\\cos\\theta_0)/((C + mR^2)
\\Omega\\sin\\theta_0)$; a push on $\\dot\\theta$ makes it nutate about that motion.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from ..registry import ModelSpec, register
from ..system import System
from .elementary import sinc

__all__ = ["MODEL", "exact", "steady_spin", "steady_motion", "energy"]

COORDINATES = ("x", "y", "theta", "phi", "psi")
PARAMS = {"m": 1.0, "R": 1.0, "A": 0.25, "C": 0.5, "g": 1.0}
#: the default initial condition's lean and turning rate
THETA0, OMEGA0 = 1.2, 1.0


def _lagrangian(q, v, p):
    m, R, A, C, g = p["m"], p["R"], p["A"], p["C"], p["g"]
    th = q[2]
    dx, dy, dth, dphi, dpsi = v
    s, c = jnp.sin(th), jnp.cos(th)
    sigma = dpsi + dphi * c
    return (0.5 * m * (dx**2 + dy**2 + (R * c * dth) ** 2) + 0.5 * A * (dth**2 + (dphi * s) ** 2)
            + 0.5 * C * sigma**2 - m * g * R * s)


def _constraints(q, p):
    R = p["R"]
    th, phi = q[2], q[3]
    st, ct, sp, cp = jnp.sin(th), jnp.cos(th), jnp.sin(phi), jnp.cos(phi)
    one, zero = jnp.ones_like(th), jnp.zeros_like(th)
    return jnp.stack([
        jnp.stack([one, zero, -R * st * sp, R * ct * cp, R * cp]),
        jnp.stack([zero, one, R * st * cp, R * ct * sp, R * sp]),
    ])


def steady_spin(p, theta, omega):
    """The spin $s = \\dot\\psi + \\Omega\\cos\\theta$ that makes the lean `theta` and the turning rate
    `omega` ($\\ne 0$, $\\sin\\theta \\ne 0$) a steady motion (the module docstring's condition)."""
    m, R, A, C, g = p["m"], p["R"], p["A"], p["C"], p["g"]
    st, ct = math.sin(theta), math.cos(theta)
    if omega == 0.0 or st == 0.0:
        raise ValueError(f"omega: a steady motion turning at {omega} with sin(theta) = {st} has no unique spin")
    return (A * omega**2 * st * ct - m * g * R * ct) / ((C + m * R**2) * omega * st)


def steady_motion(p, theta=THETA0, omega=OMEGA0, q0=(0.0, 0.0, None, 0.0, 0.0)):
    """`(q0, v0)` of the steady motion leaning at `theta` and turning at `omega` from the position,
    heading and spin of `q0` (its lean replaced by `theta`)."""
    s = steady_spin(p, theta, omega)
    x0, y0, _, phi0, psi0 = q0
    R = p["R"]
    q = (float(x0), float(y0), float(theta), float(phi0), float(psi0))
    v = (-R * s * math.cos(phi0), -R * s * math.sin(phi0), 0.0, float(omega), s - omega * math.cos(theta))
    return q, v


def _default_ic(p):
    return steady_motion(p)


def _build(p):
    return System(_lagrangian, _constraints, coordinates=COORDINATES, name="rolling-disk", args=p, params=p,
                  defaults=_default_ic(p))


def exact(p, q0, v0, t):
    """The steady motion from `(q0, v0)` at times `t` (from t = 0), arrays (T, 5), when `(q0, v0)` is
    one (θ̇ = 0 and the condition of the module docstring to 1e-12, on the constraints); None
    otherwise."""
    q0, v0 = np.asarray(q0, dtype=np.float64), np.asarray(v0, dtype=np.float64)
    x0, y0, th, phi0, psi0 = q0
    dx, dy, dth, omega, dpsi = v0
    m, R, A, C, g = p["m"], p["R"], p["A"], p["C"], p["g"]
    s = dpsi + omega * math.cos(th)
    condition = A * omega**2 * math.sin(th) * math.cos(th) - (C + m * R**2) * s * omega * math.sin(th) - m * g * R * math.cos(th)
    scale = A * omega**2 + (C + m * R**2) * abs(s * omega) + m * g * R
    rolling = max(abs(dx + R * s * math.cos(phi0)), abs(dy + R * s * math.sin(phi0)))
    if abs(dth) > 1e-12 or abs(condition) > 1e-12 * scale or rolling > 1e-12 * (1.0 + R * abs(s)):
        return None
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    phi = phi0 + omega * t
    half = phi0 + 0.5 * omega * t
    chord = -R * s * t * sinc(0.5 * omega * t)  # −R s (2/Ω) sin(Ωt/2), safe at Ω = 0
    ones = np.ones_like(t)
    q = np.stack([x0 + chord * np.cos(half), y0 + chord * np.sin(half), th * ones, phi, psi0 + dpsi * t], axis=-1)
    v = np.stack([-R * s * np.cos(phi), -R * s * np.sin(phi), 0.0 * ones, omega * ones, dpsi * ones], axis=-1)
    return q, v


def energy(p, q, v):
    """The energy: kinetic plus $m g R\\sin\\theta$."""
    m, R, A, C, g = p["m"], p["R"], p["A"], p["C"], p["g"]
    th = q[2]
    dx, dy, dth, dphi, dpsi = v[0], v[1], v[2], v[3], v[4]
    s, c = jnp.sin(th), jnp.cos(th)
    sigma = dpsi + dphi * c
    return (0.5 * m * (dx**2 + dy**2 + (R * c * dth) ** 2) + 0.5 * A * (dth**2 + (dphi * s) ** 2)
            + 0.5 * C * sigma**2 + m * g * R * s)


_Q0, _V0 = steady_motion(PARAMS)

MODEL = register(
    ModelSpec(
        name="rolling-disk",
        description="disk rolling without slipping, free to lean (Euler's disk): steady circles exact",
        build=_build,
        params=PARAMS,
        coordinates=COORDINATES,
        q0=_Q0,
        v0=_V0,
        default_ic=_default_ic,
        exact=exact,
        invariants={"energy": energy},
        notes=__doc__,
        positive=('m', 'R', 'A', 'C'),
    )
)
