"""The contact oscillator of McLachlan–Perlmutter (2006, §5.2).

$H = \\tfrac12(|v|^2 + |q|^2 + \\varepsilon x^2 z^2)$ on $q = (x, y, z)$, constraint
$\\dot x + y\\dot z = 0$. Both $H$ and $H_y = \\tfrac12(y^2 + \\dot y^2)$ are conserved (the constraint
force has no y-component, so y is a free harmonic oscillator).

The equations and ε = 0.3 are McLachlan–Perlmutter's; the initial condition $q_0 = (1, 1, 1)$,
$\\dot q_0 = (-1, 1, 1)$ ($H = 3.15$, $H_y = 1$) is not their experimental set-up, which is the model
`contact-oscillator-mp` (H = 1.5, H_y = 0.5, started on the section y = 0;
:mod:`gnipy.models.contact_oscillator_mp`).
"""

from __future__ import annotations

import jax.numpy as jnp

from ..system import System
from ..registry import ModelSpec, register

__all__ = ["MODEL"]


def lagrangian(eps, q, v):
    """l(q, v) of the contact oscillator with coupling `eps`."""
    x, _, z = q
    return 0.5 * (v @ v) - 0.5 * (q @ q + eps * x**2 * z**2)


def constraints(q):
    """The constraint ẋ + y ż = 0 as the row μ(q) = (1, 0, y)."""
    y = q[1]
    return jnp.stack([jnp.ones_like(y), jnp.zeros_like(y), y])[None, :]


def lagrangian_args(q, v, p):
    """:func:`lagrangian` with the coupling read from the named parameters (`p["epsilon"]`)."""
    return lagrangian(p["epsilon"], q, v)


def constraints_args(q, p):
    """:func:`constraints`, taking the named parameters (unused) last."""
    return constraints(q)


def _build(p):
    return System(
        lagrangian_args,
        constraints_args,
        coordinates=("x", "y", "z"),
        name="contact-oscillator",
        args=p,
        params=p,
        defaults=MODEL.initial_condition(p),
    )


def total_energy(p, q, v):
    """The energy H (conserved), with the parameters `p`."""
    x, _, z = q
    return 0.5 * (v @ v + q @ q + p["epsilon"] * x**2 * z**2)


def y_energy(p, q, v):
    """The energy of the y oscillator, H_y = (y² + ẏ²)/2 (conserved)."""
    return 0.5 * (q[1] ** 2 + v[1] ** 2)


MODEL = register(
    ModelSpec(
        name="contact-oscillator",
        description="McLachlan–Perlmutter contact oscillator, ẋ + y ż = 0, H and H_y conserved",
        build=_build,
        params={"epsilon": 0.3},
        coordinates=("x", "y", "z"),
        q0=(1.0, 1.0, 1.0),
        v0=(-1.0, 1.0, 1.0),
        invariants={"H": total_energy, "H_y": y_energy},
        notes=__doc__,
    )
)
