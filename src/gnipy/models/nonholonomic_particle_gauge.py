"""A non-reversible nonholonomic particle in the manner of Modin–Verdier: the nonholonomic particle
with its momenta shifted by $c\\nabla S$, $S = \\cos x$.

The unperturbed problem is `nonholonomic-particle`: $l = \\tfrac12|\\dot q|^2 - \\tfrac k2(x^2 + y^2)$
on $q = (x, y, z)$ with $\\dot z = y\\dot x$. The perturbation is Modin–Verdier's gauge
(:mod:`gnipy.models.gauge`),

$$H_S(q, p) = \\tfrac12|p + c\\nabla S(q)|^2 + \\tfrac k2(x^2 + y^2), \\qquad S(q) = \\cos x,
\\quad \\nabla S = (-\\sin x, 0, 0),$$

i.e. $l_S = l + c\\sin x\\,\\dot x$, a total derivative: the motion is the particle's, the momenta are
$p = \\dot q - c\\nabla S$, $p_x = \\dot x + c\\sin x$. gnipy writes it with the cyclic coordinate $w$:

$$\\hat l = \\tfrac12|\\dot q|^2 + \\tfrac12(\\dot w + \\sin x\\,\\dot x)^2 - \\tfrac k2(x^2 + y^2),
\\qquad \\dot z = y\\dot x,$$

on the level $p_w = \\dot w + \\sin x\\,\\dot x = c$ (`c = 0`: the unperturbed, reversible problem in the
same coordinates, a control).

**Invariants**: the particle's energy $E = \\tfrac12|\\dot q|^2 + \\tfrac k2(x^2 + y^2)$ (in
$(q, \\dot q)$; the energy of $\\hat l$ is $E + \\tfrac12c^2$), $H_y = \\tfrac12(\\dot y^2 + ky^2)$ (the
constraint force $\\lambda(-y, 0, 1)$ has no y-component), and $p_w = c$. Exactly,
$w(t) = w_0 + ct + \\cos x(t) - \\cos x_0$.

**Parameters and initial condition.** k = 1 and the particle's initial condition $q_0 = (1, 1, 0)$,
$\\dot q_0 = (1, 0, 1)$, with $w_0 = 0$, $\\dot w_0 = c - \\sin x_0\\,\\dot x_0 = 1 - \\sin 1$; c = 1.

Source and what is a choice: the perturbation is that of K. Modin and O. Verdier, *What makes
nonholonomic integrators work?*, Numer. Math. 145 (2020) 405–435 (arXiv:1707.04514), who perturb
the nonholonomic particle among their test problems; their S, parameters and initial condition for
the particle could not be confirmed here (the paper's text was not available, and O. Verdier's
odelab implements only the perturbed contact oscillator). $S = \\cos x$ is our choice, by analogy
with their $S = \\cos z$ for the contact oscillator: S acts on a coordinate of the coupled,
potential-carrying part (for the particle z is cyclic, the fibre of the foliation, and y a free
oscillator, so x is that coordinate). With $S = \\cos z$ the effect on the discrete methods is
weaker (documented in the models guide).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from ..registry import ModelSpec, register
from .gauge import gauge_momentum, kaluza_klein_term, lift_constraints, lift_initial_condition
from .nonholonomic_particle import constraints as _base_constraints

__all__ = ["MODEL", "S", "grad_S"]


def S(q):
    """$S(q) = \\cos x$."""
    return np.cos(q[0])


def grad_S(q):
    """$\\nabla S = (-\\sin x, 0, 0)$ (traceable)."""
    x = q[0]
    return jnp.stack([-jnp.sin(x), jnp.zeros_like(x), jnp.zeros_like(x)])


def _lagrangian(q, v, p):
    k = p["k"]
    x, y = q[0], q[1]
    u = v[:3]
    return 0.5 * (u @ u) + kaluza_klein_term(grad_S(q[:3]), v) - 0.5 * k * (x**2 + y**2)


def _constraints(q, p):
    return lift_constraints(_base_constraints(q[:3]))


_Q0, _V0 = (1.0, 1.0, 0.0), (1.0, 0.0, 1.0)


def _default_ic(p):
    return lift_initial_condition(_Q0, _V0, (-np.sin(_Q0[0]), 0.0, 0.0), p["c"])


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=("x", "y", "z", "w"),
        name="nonholonomic-particle-gauge",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def _energy(p, q, v):
    u = np.asarray(v[:3])
    return 0.5 * (u @ u) + 0.5 * p["k"] * (q[0] ** 2 + q[1] ** 2)


def _Hy(p, q, v):
    return 0.5 * (v[1] ** 2 + p["k"] * q[1] ** 2)


def _pw(p, q, v):
    return gauge_momentum((-np.sin(q[0]), 0.0, 0.0), v)


_DEFAULTS = {"k": 1.0, "c": 1.0}

MODEL = register(
    ModelSpec(
        name="nonholonomic-particle-gauge",
        description="nonholonomic particle with momenta shifted by c∇S, S = cos x (Modin–Verdier's gauge; motion unchanged)",
        build=_build,
        params=_DEFAULTS,
        coordinates=("x", "y", "z", "w"),
        q0=_default_ic(_DEFAULTS)[0],
        v0=_default_ic(_DEFAULTS)[1],
        default_ic=_default_ic,
        invariants={"energy": _energy, "H_y": _Hy, "p_w": _pw},
        notes=__doc__,
    )
)
