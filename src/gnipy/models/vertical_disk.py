"""The vertical rolling disk (Bloch, *Nonholonomic Mechanics and Control*, §1.4).

A disk of radius $r$ rolls upright without slipping on the plane. Coordinates
$q = (x, y, \\varphi, \\theta)$: contact point, heading $\\varphi$, rolling angle $\\theta$.

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12 I_{flip}\\dot\\varphi^2 + \\tfrac12 I_{rot}\\dot\\theta^2,$$

with the rolling constraints $\\dot x = r\\cos\\varphi\\,\\dot\\theta$, $\\dot y = r\\sin\\varphi\\,\\dot\\theta$,
i.e. $\\mu = [[1, 0, 0, -r\\cos\\varphi], [0, 1, 0, -r\\sin\\varphi]]$.

**Exact solution.** The Lagrange–d'Alembert equations are $m\\ddot x = \\lambda_1$,
$m\\ddot y = \\lambda_2$, $I_{flip}\\ddot\\varphi = 0$,
$I_{rot}\\ddot\\theta = -r(\\lambda_1\\cos\\varphi + \\lambda_2\\sin\\varphi)$; differentiating the
constraints gives $(I_{rot} + m r^2)\\ddot\\theta = 0$. So $\\dot\\varphi$ and $\\dot\\theta$ are
constant, $\\varphi = \\varphi_0 + \\dot\\varphi t$, $\\theta = \\theta_0 + \\dot\\theta t$ and

$$x = x_0 + \\frac{r\\dot\\theta}{\\dot\\varphi}(\\sin\\varphi - \\sin\\varphi_0), \\qquad
  y = y_0 - \\frac{r\\dot\\theta}{\\dot\\varphi}(\\cos\\varphi - \\cos\\varphi_0),$$

a circle of radius $r\\dot\\theta/\\dot\\varphi$ (a straight line when $\\dot\\varphi = 0$). It is
evaluated as $x = x_0 + r\\dot\\theta\\,t\\,\\mathrm{sinc}(\\dot\\varphi t/2)\\cos(\\varphi_0 + \\dot\\varphi t/2)$
(and $\\sin$ for $y$), exact for every $\\dot\\varphi$ including 0.

**Invariants.** The energy $\\tfrac12 m(\\dot x^2+\\dot y^2) + \\tfrac12 I_{flip}\\dot\\varphi^2 +
\\tfrac12 I_{rot}\\dot\\theta^2$, the heading rate $\\dot\\varphi$ and the rolling rate $\\dot\\theta$.

Default initial condition: $q_0 = (0, 0, 0, 0)$, $v_0 = (r, 0, 1, 1)$ (= (1, 0, 1, 1) for $r = 1$).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from .elementary import sinc
from ..registry import ModelSpec, register

__all__ = ["MODEL", "exact"]

COORDINATES = ("x", "y", "phi", "theta")


def _lagrangian(q, v, p):
    m, I_flip, I_rot = p["m"], p["I_flip"], p["I_rot"]
    dx, dy, dphi, dtheta = v
    return 0.5 * m * (dx**2 + dy**2) + 0.5 * I_flip * dphi**2 + 0.5 * I_rot * dtheta**2


def _constraints(q, p):
    r = p["r"]
    phi = q[2]
    one, zero = jnp.ones_like(phi), jnp.zeros_like(phi)
    return jnp.stack(
        [
            jnp.stack([one, zero, zero, -r * jnp.cos(phi)]),
            jnp.stack([zero, one, zero, -r * jnp.sin(phi)]),
        ]
    )


def _default_ic(p):
    return (0.0, 0.0, 0.0, 0.0), (p["r"], 0.0, 1.0, 1.0)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=COORDINATES,
        name="vertical-disk",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def exact(p, q0, v0, t):
    """Exact `(q, v)`, arrays (T, 4), at times `t` (from t = 0) for `v0` on the constraints.

    Only $\\dot\\varphi_0$ and $\\dot\\theta_0$ are read from `v0`; $(\\dot x_0, \\dot y_0)$ follow from the
    constraints.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    x0, y0, phi0, theta0 = (float(c) for c in q0)
    dphi, dtheta = float(v0[2]), float(v0[3])
    r = p["r"]
    phi = phi0 + dphi * t
    half = phi0 + 0.5 * dphi * t
    chord = r * dtheta * t * sinc(0.5 * dphi * t)  # r θ̇ (2/φ̇) sin(φ̇t/2), safe at φ̇ = 0
    x = x0 + chord * np.cos(half)
    y = y0 + chord * np.sin(half)
    theta = theta0 + dtheta * t
    q = np.stack([x, y, phi, theta], axis=-1)
    ones = np.ones_like(t)
    v = np.stack([r * dtheta * np.cos(phi), r * dtheta * np.sin(phi), dphi * ones, dtheta * ones], axis=-1)
    return q, v


def _energy(p, q, v):
    return 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I_flip"] * v[2] ** 2 + 0.5 * p["I_rot"] * v[3] ** 2


def _heading_rate(p, q, v):
    return v[2]


def _rolling_rate(p, q, v):
    return v[3]


MODEL = register(
    ModelSpec(
        name="vertical-disk",
        description="upright disk rolling without slipping: ẋ = r cosφ θ̇, ẏ = r sinφ θ̇ (exact: circles)",
        build=_build,
        params={"m": 1.0, "r": 1.0, "I_flip": 1.0, "I_rot": 1.0},
        coordinates=COORDINATES,
        q0=(0.0, 0.0, 0.0, 0.0),
        v0=(1.0, 0.0, 1.0, 1.0),
        default_ic=_default_ic,
        exact=exact,
        invariants={"energy": _energy, "heading_rate": _heading_rate, "rolling_rate": _rolling_rate},
        notes=__doc__,
        positive=('m', 'r', 'I_flip', 'I_rot'),
    )
)
