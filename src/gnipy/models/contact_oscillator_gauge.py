"""Modin–Verdier's non-reversible contact oscillator: the contact oscillator with its momenta
shifted by $c\\nabla S$, $S = \\cos z$.

The unperturbed problem is the contact oscillator (`contact-oscillator`, McLachlan–Perlmutter
§5.2): $l = \\tfrac12|\\dot q|^2 - \\tfrac12(|q|^2 + \\varepsilon x^2z^2)$ on $q = (x, y, z)$ with
$\\dot x + y\\dot z = 0$. Modin–Verdier's perturbation is

$$H_S(q, p) = \\tfrac12\\big(|p + c\\nabla S(q)|^2 + |q|^2 + \\varepsilon x^2 z^2\\big), \\qquad
S(q) = \\cos z,\\quad \\nabla S = (0, 0, -\\sin z),$$

i.e. $l_S = l - c\\langle\\nabla S(q), \\dot q\\rangle = l + c\\sin z\\,\\dot z$, a total derivative: the
motion of $q$ is the contact oscillator's, and the momenta are $p = \\dot q - c\\nabla S(q)$,
$p_z = \\dot z + c\\sin z$. gnipy writes it with the cyclic coordinate $w$ (:mod:`gnipy.models.gauge`):

$$\\hat l(x, y, z, w, \\dot x, \\dot y, \\dot z, \\dot w) = \\tfrac12|\\dot q|^2
  + \\tfrac12(\\dot w + \\sin z\\,\\dot z)^2 - \\tfrac12(|q|^2 + \\varepsilon x^2 z^2),
  \\qquad \\dot x + y\\dot z = 0,$$

on the level $p_w = \\dot w + \\sin z\\,\\dot z = c$ (the parameter `c`; `c = 0` is the unperturbed,
reversible problem in the same coordinates, a control).

**Invariants** (of the unperturbed motion, in $(q, \\dot q)$): $H = \\tfrac12(|\\dot q|^2 + |q|^2 +
\\varepsilon x^2z^2)$, $H_y = \\tfrac12(y^2 + \\dot y^2)$, and $p_w = c$. The energy of $\\hat l$ is
$H + \\tfrac12 c^2$. Exactly, $w(t) = w_0 + ct + \\cos z(t) - \\cos z_0$.

**Parameters and initial condition.** ε = 0 and c = 1, as in O. Verdier's odelab
(`NonReversibleContactOscillator`: $S = \\cos z$ unscaled, built with its default ε = 0 in
`tests/scheme/test_cvt.py`); the ε = 0 contact oscillator is the integrable, reversible member of
the family (Modin–Verdier, *Integrability of nonholonomically coupled oscillators*,
arXiv:1212.6618). The initial condition is McLachlan–Perlmutter's set-up
(`contact-oscillator-mp`: H = 1.5, H_y = 0.5, on the section y = 0, z₀ = 0.1√2, ż₀ = 0) with
$w_0 = 0$, $\\dot w_0 = c - \\sin z_0\\,\\dot z_0 = c$.

Sources: K. Modin and O. Verdier, *What makes nonholonomic integrators work?*, Numer. Math. 145
(2020) 405–435 (arXiv:1707.04514), the perturbed test problems; odelab
(`odelab/system/nonholonomic/contactoscillator.py`) for S, c and ε. The paper's text could not be
consulted here: its step sizes and run lengths are not reproduced, and the odelab class also
carries an unused `perturbation_size = 0.2` whose role (if any, e.g. S = 0.2 cos z) is unconfirmed.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from ..registry import ModelSpec, register
from .contact_oscillator import constraints as _base_constraints
from .contact_oscillator_mp import setup_initial_condition
from .gauge import gauge_momentum, kaluza_klein_term, lift_constraints, lift_initial_condition

__all__ = ["MODEL", "S", "grad_S"]


def S(q):
    """$S(q) = \\cos z$."""
    return np.cos(q[2])


def grad_S(q):
    """$\\nabla S = (0, 0, -\\sin z)$ (traceable)."""
    z = q[2]
    return jnp.stack([jnp.zeros_like(z), jnp.zeros_like(z), -jnp.sin(z)])


def _lagrangian(q, v, p):
    eps = p["epsilon"]
    x, _, z = q[0], q[1], q[2]
    u, r = v[:3], q[:3]
    return 0.5 * (u @ u) + kaluza_klein_term(grad_S(r), v) - 0.5 * (r @ r + eps * x**2 * z**2)


def _constraints(q, p):
    return lift_constraints(_base_constraints(q[:3]))


def _default_ic(p):
    q0, v0 = setup_initial_condition(float(p["epsilon"]))
    return lift_initial_condition(q0, v0, (0.0, 0.0, -np.sin(q0[2])), p["c"])


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        coordinates=("x", "y", "z", "w"),
        name="contact-oscillator-gauge",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def _H(p, q, v):
    x, z = q[0], q[2]
    u, r = np.asarray(v[:3]), np.asarray(q[:3])
    return 0.5 * (u @ u + r @ r + p["epsilon"] * x**2 * z**2)


def _Hy(p, q, v):
    return 0.5 * (q[1] ** 2 + v[1] ** 2)


def _pw(p, q, v):
    return gauge_momentum((0.0, 0.0, -np.sin(q[2])), v)


_DEFAULTS = {"epsilon": 0.0, "c": 1.0}

MODEL = register(
    ModelSpec(
        name="contact-oscillator-gauge",
        description="Modin–Verdier's non-reversible contact oscillator: momenta shifted by c∇S, S = cos z (motion unchanged)",
        build=_build,
        params=_DEFAULTS,
        coordinates=("x", "y", "z", "w"),
        q0=_default_ic(_DEFAULTS)[0],
        v0=_default_ic(_DEFAULTS)[1],
        default_ic=_default_ic,
        invariants={"H": _H, "H_y": _Hy, "p_w": _pw},
        notes=__doc__,
    )
)
