"""The knife edge on an inclined plane (Bloch, *Nonholonomic Mechanics and Control*, §1.6).

A blade slides on a plane inclined at angle $\\alpha$; $x$ points down the slope, $\\varphi$ is the
blade's heading. Coordinates $q = (x, y, \\varphi)$,

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12 J\\dot\\varphi^2 + m g\\sin\\alpha\\, x,$$

and the blade cannot move sideways: $\\dot x\\sin\\varphi - \\dot y\\cos\\varphi = 0$,
$\\mu = [\\sin\\varphi, -\\cos\\varphi, 0]$.

**Exact solution.** With $a = g\\sin\\alpha$ and the speed along the blade
$s = \\dot x\\cos\\varphi + \\dot y\\sin\\varphi$ (so $\\dot x = s\\cos\\varphi$, $\\dot y = s\\sin\\varphi$),
the equations $m\\ddot x = m a + \\lambda\\sin\\varphi$, $m\\ddot y = -\\lambda\\cos\\varphi$,
$J\\ddot\\varphi = 0$ give $\\varphi = \\varphi_0 + \\omega t$ and $\\dot s = a\\cos\\varphi$. Let
$A(t) = \\int_0^t\\cos\\varphi$, $B(t) = \\int_0^t\\sin\\varphi$. Then $s = s_0 + aA$ and

$$x = x_0 + s_0 A + \\tfrac12 a A^2, \\qquad
  y = y_0 + s_0 B + \\tfrac a2\\big(AB + \\omega t^3\\,\\tfrac{\\omega t - \\sin\\omega t}{(\\omega t)^3}\\big),$$

using $\\int_0^t A\\cos\\varphi = A^2/2$ and $\\int_0^t (A\\sin\\varphi - B\\cos\\varphi) =
(\\omega t - \\sin\\omega t)/\\omega^2$. For $\\omega \\ne 0$ this is the textbook form: with
$k = a/\\omega$, $c = s_0 - k\\sin\\varphi_0$, $s = c + k\\sin\\varphi$,
$x = x_0 + \\frac c\\omega(\\sin\\varphi - \\sin\\varphi_0) + \\frac k{2\\omega}(\\sin^2\\varphi - \\sin^2\\varphi_0)$,
$y = y_0 - \\frac c\\omega(\\cos\\varphi - \\cos\\varphi_0) + k\\big[\\frac{\\varphi - \\varphi_0}{2\\omega}
- \\frac{\\sin 2\\varphi - \\sin 2\\varphi_0}{4\\omega}\\big]$. The $A, B$ form is evaluated with
small-argument-safe ratios, so it holds for every $\\omega$, including $\\omega = 0$ (straight
uniformly accelerated sliding, $x = x_0 + \\cos\\varphi_0(s_0 t + \\tfrac12 a\\cos\\varphi_0 t^2)$).
The blade drifts sideways down the slope: $y$ grows like $a t/(2\\omega)$ on average.

**Invariants.** The energy $\\tfrac12 m(\\dot x^2+\\dot y^2) + \\tfrac12 J\\dot\\varphi^2 - m g\\sin\\alpha\\,x$
and the turning rate $\\dot\\varphi$.

Default initial condition: $q_0 = (0, 0, 0)$, $v_0 = (0, 0, 1)$.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from .elementary import sinc, sine_defect_ratio, versine_ratio
from ..registry import ModelSpec, register

__all__ = ["MODEL", "exact"]

COORDINATES = ("x", "y", "phi")


def _lagrangian(q, v, p):
    m, J, g, alpha = p["m"], p["J"], p["g"], p["alpha"]
    dx, dy, dphi = v
    return 0.5 * m * (dx**2 + dy**2) + 0.5 * J * dphi**2 + m * g * jnp.sin(alpha) * q[0]


def _constraints(q, p):
    phi = q[2]
    return jnp.stack([jnp.sin(phi), -jnp.cos(phi), jnp.zeros_like(phi)])[None, :]


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=COORDINATES,
        name="knife-edge",
        args=p,
        params=p,
        defaults=MODEL.initial_condition(p),
    )


def exact(p, q0, v0, t):
    """Exact `(q, v)`, arrays (T, 3), at times `t` (from t = 0) for `v0` on the constraint.

    The speed along the blade is read as $s_0 = \\dot x_0\\cos\\varphi_0 + \\dot y_0\\sin\\varphi_0$.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    x0, y0, phi0 = (float(c) for c in q0)
    omega = float(v0[2])
    s0 = float(v0[0]) * np.cos(phi0) + float(v0[1]) * np.sin(phi0)
    a = p["g"] * np.sin(p["alpha"])
    wt = omega * t
    phi = phi0 + wt
    # A = (sin φ − sin φ0)/ω, B = (cos φ0 − cos φ)/ω, written without the 1/ω
    S, C = t * sinc(wt), omega * t**2 * versine_ratio(wt)
    A = np.cos(phi0) * S - np.sin(phi0) * C
    B = np.sin(phi0) * S + np.cos(phi0) * C
    s = s0 + a * A
    x = x0 + s0 * A + 0.5 * a * A**2
    y = y0 + s0 * B + 0.5 * a * (A * B + omega * t**3 * sine_defect_ratio(wt))
    q = np.stack([x, y, phi], axis=-1)
    v = np.stack([s * np.cos(phi), s * np.sin(phi), omega * np.ones_like(t)], axis=-1)
    return q, v


def _energy(p, q, v):
    return (
        0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2)
        + 0.5 * p["J"] * v[2] ** 2
        - p["m"] * p["g"] * jnp.sin(p["alpha"]) * q[0]
    )


def _turning_rate(p, q, v):
    return v[2]


MODEL = register(
    ModelSpec(
        name="knife-edge",
        description="knife edge on an inclined plane (Bloch §1.6): ẋ sinφ − ẏ cosφ = 0, gravity down x",
        build=_build,
        params={"m": 1.0, "J": 1.0, "g": 9.81, "alpha": 0.5},
        coordinates=COORDINATES,
        q0=(0.0, 0.0, 0.0),
        v0=(0.0, 0.0, 1.0),
        exact=exact,
        invariants={"energy": _energy, "turning_rate": _turning_rate},
        notes=__doc__,
        positive=('m', 'J'),
    )
)
