"""The nonholonomic particle: $l = \\tfrac12(\\dot x^2+\\dot y^2+\\dot z^2) - \\tfrac k2(x^2+y^2)$,
constraint $\\dot z = y\\dot x$.

The constraint force $\\lambda(-y, 0, 1)$ has no y-component, so $y$ is an exact harmonic
oscillator: $y(t) = y_0\\cos\\sqrt k t + (\\dot y_0/\\sqrt k)\\sin\\sqrt k t$. The energy is conserved.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from ..registry import ModelSpec, register

__all__ = ["MODEL"]


def lagrangian(k, q, v):
    """l(q, v) of the nonholonomic particle with spring constant `k`."""
    x, y, _ = q
    return 0.5 * (v @ v) - 0.5 * k * (x**2 + y**2)


def constraints(q):
    """The constraint ż = y ẋ as the row μ(q) = (−y, 0, 1)."""
    return jnp.stack([-q[1], jnp.zeros_like(q[1]), jnp.ones_like(q[1])])[None, :]


def _lagrangian(q, v, p):
    return lagrangian(p["k"], q, v)


def _constraints(q, p):
    return constraints(q)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=("x", "y", "z"),
        name="nonholonomic-particle",
        args=p,
        params=p,
        defaults=MODEL.initial_condition(p),
    )


def _energy(p, q, v):
    return 0.5 * (v @ v) + 0.5 * p["k"] * (q[0] ** 2 + q[1] ** 2)


def _exact_y(p, q0, v0, t):
    """Exact y(t), ẏ(t) (the only coordinate with a closed form)."""
    w = np.sqrt(p["k"])
    t = np.asarray(t)
    if w == 0:
        return q0[1] + v0[1] * t, v0[1] + 0 * t
    return q0[1] * np.cos(w * t) + v0[1] / w * np.sin(w * t), -q0[1] * w * np.sin(w * t) + v0[1] * np.cos(w * t)


MODEL = register(
    ModelSpec(
        name="nonholonomic-particle",
        description="particle in R³ with ż = y ẋ in the potential ½k(x²+y²)",
        build=_build,
        params={"k": 1.0},
        coordinates=("x", "y", "z"),
        q0=(1.0, 1.0, 0.0),
        v0=(1.0, 0.0, 1.0),
        invariants={"energy": _energy},
        notes=__doc__,
    )
)
exact_y = _exact_y
