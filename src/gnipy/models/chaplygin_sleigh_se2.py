"""The Chaplygin sleigh as a left-invariant system on SE(2).

The sleigh of :mod:`~gnipy.models.chaplygin_sleigh` (mass $m$, moment of inertia $I$ about the centre
of mass, knife edge a distance $a$ behind the centre of mass), written on the group: $Q = SE(2)$
($n = 0$), $g = (R(\\theta), p)$ with the body frame at the *contact point* $p$ and its first axis
along the blade. Velocities are the body velocities $v = \\xi = (g^{-1}\\dot g)^\\vee = (v_x, v_y, \\omega)$
(SE(2) algebra coordinates of :class:`~gnipy.lie_groups.SE2`): $(v_x, v_y)$ the velocity of the
contact point in the body frame, $\\omega = \\dot\\theta$. The centre of mass sits at body $(a, 0)$
and moves with body velocity $(v_x, v_y + a\\omega)$, so

$$l = \\tfrac12 m\\bigl(v_x^2 + (v_y + a\\omega)^2\\bigr) + \\tfrac12 I\\omega^2, \\qquad v_y = 0$$

(the blade does not slip sideways). Lagrangian and constraint do not depend on $g$: a reduced
system (paper §7), integrated with the Euler–Poincaré–d'Alembert equations
($\\mathrm{ad}^*_\\xi$ of SE(2)).

**Exact solution.** With $u = v_x$ the forward speed and $\\omega$ the turning rate, these are the
body velocities of the $\\mathbb{R}^3$ model, so :func:`~gnipy.models.chaplygin_sleigh.exact_body_velocities`
applies: $\\dot u = a\\omega^2$, $(I + ma^2)\\dot\\omega = -mau\\omega$ and
$u = U\\tanh(\\kappa t + c_0)$, $\\omega = \\omega_0\\cosh c_0/\\cosh(\\kappa t + c_0)$. :func:`exact` returns
$v = (u, 0, \\omega)$ (and an empty $q$); the attitude's heading is
:func:`~gnipy.models.chaplygin_sleigh.exact_heading`. The two formulations correspond through
$x_{cm} = p + aR(\\theta)e_1$ (the $\\mathbb{R}^3$ coordinates $(x, y)$ are the centre of mass) and
$(\\dot x, \\dot y) = R(\\theta)(u, a\\omega)$.

**Invariant.** The energy (`energy`, a function `f(params, q, v)`).

Same parameters as `chaplygin-sleigh` ($m = I = 1$, $a = 0.5$). Default initial condition:
$g_0$ the identity (contact point at the origin, heading 0), $v_0 = (1, 0, 1)$.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..lie_groups import SE2
from ..system import System
from .chaplygin_sleigh import exact_body_velocities
from ..registry import ModelSpec, register

__all__ = ["MODEL", "exact"]

VELOCITIES = ("vx", "vy", "omega")


def _lagrangian(x, v, p):
    m, I, a = p["m"], p["I"], p["a"]
    vx, vy, w = v
    return 0.5 * m * (vx**2 + (vy + a * w) ** 2) + 0.5 * I * w**2


def _constraints(x, p):
    return jnp.array([[0.0, 1.0, 0.0]])


def _energy(p, q, v):
    vx, vy, w = (v[i] for i in range(3))
    return 0.5 * p["m"] * (vx**2 + (vy + p["a"] * w) ** 2) + 0.5 * p["I"] * w**2


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        n=0,
        group=SE2(),
        coordinates=(),
        velocities=VELOCITIES,
        name="chaplygin-sleigh-se2",
        args=p,
        params=p,
        defaults=((), (1.0, 0.0, 1.0)),
    )


def exact(p, q0, v0, t):
    """Exact body velocities $v = (u, 0, \\omega)$, array (T, 3), and an empty (T, 0) `q`, from t = 0.

    `v0` must satisfy the constraint $v_y = 0$; $u_0 = v_{x,0}$ and $\\omega_0$ are read from it.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    u0, w0 = float(v0[0]), float(v0[2])
    # the R^3 model's state with the same body velocities: heading 0, centre of mass velocity (u, aω)
    u, w = exact_body_velocities(p, (0.0, 0.0, 0.0), (u0, p["a"] * w0, w0), t)
    return np.zeros((t.size, 0)), np.stack([u, np.zeros_like(u), w], axis=-1)


MODEL = register(
    ModelSpec(
        name="chaplygin-sleigh-se2",
        description="Chaplygin sleigh on SE(2): body frame at the knife edge, centre of mass at body (a, 0), v_y = 0",
        build=_build,
        params={"m": 1.0, "I": 1.0, "a": 0.5},
        coordinates=(),
        q0=(),
        v0=(1.0, 0.0, 1.0),
        exact=exact,
        invariants={"energy": _energy},
        notes=__doc__,
        positive=('m', 'I'),
    )
)
