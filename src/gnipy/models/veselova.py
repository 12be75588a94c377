"""The Veselova system: a rigid body whose angular velocity has no vertical component.

Pure rotation, $Q = SO(3)$ ($n = 0$): velocities $v = \\Omega = (R^T\\dot R)^\\vee$ (body angular
velocity), $\\gamma = R^Te_3$ the vertical in the body frame (the third row of $R$). With principal
moments $I = \\mathrm{diag}(I_1, I_2, I_3)$,

$$l = \\tfrac12\\Omega^T I\\Omega, \\qquad \\langle\\Omega, \\gamma\\rangle = 0$$

(the space angular velocity $\\omega = R\\Omega$ stays horizontal: $\\omega_3 = \\langle\\Omega, \\gamma\\rangle$).
The constraint depends on the attitude, $\\mu(R) = \\gamma^T$: the Lie groupoid case (paper §9).
The equations are $\\dot M = M\\times\\Omega + \\lambda\\gamma$, $\\dot\\gamma = \\gamma\\times\\Omega$, $M = I\\Omega$.

**Invariants** (functions `f(params, q, v, R)`, R the 3×3 attitude).

- The energy $E = \\tfrac12\\langle M, \\Omega\\rangle$ (`energy`).
- $F = |M|^2 - \\langle M, \\gamma\\rangle^2$ (`F`):
  $\\frac{d}{dt}|M|^2 = 2\\langle M, M\\times\\Omega + \\lambda\\gamma\\rangle = 2\\lambda\\langle M, \\gamma\\rangle$,
  and $\\frac{d}{dt}\\langle M, \\gamma\\rangle = \\langle M\\times\\Omega, \\gamma\\rangle +
  \\lambda|\\gamma|^2 + \\langle M, \\gamma\\times\\Omega\\rangle = \\lambda$ (the two triple products cancel), so
  $\\frac{d}{dt}\\langle M, \\gamma\\rangle^2 = 2\\lambda\\langle M, \\gamma\\rangle$ as well.

Defaults: $(I_1, I_2, I_3) = (1, 2, 3)$, $R_0$ the identity ($\\gamma_0 = e_3$), $\\Omega_0 = (1, 0.5, 0)$.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..lie_groups import SO3
from ..system import System
from ..registry import ModelSpec, register

__all__ = ["MODEL"]

VELOCITIES = ("Omega1", "Omega2", "Omega3")


def _inertia(p):
    return jnp.asarray([p["I1"], p["I2"], p["I3"]])


def _lagrangian(x, R, v, p):
    return 0.5 * jnp.sum(_inertia(p) * v**2)


def _constraints(x, R, p):
    return R[2][None, :]  # γ = Rᵀe₃


def _energy(p, q, v, R):
    v = jnp.asarray(v)
    return 0.5 * jnp.sum(_inertia(p) * v**2)


def _F(p, q, v, R):
    M = _inertia(p) * jnp.asarray(v)
    gamma = jnp.asarray(R).reshape(3, 3)[2]
    return M @ M - (M @ gamma) ** 2


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        n=0,
        group=SO3(),
        depends_on_orientation=True,
        coordinates=(),
        velocities=VELOCITIES,
        name="veselova",
        args=p,
        params=p,
        defaults=((), (1.0, 0.5, 0.0)),
    )


MODEL = register(
    ModelSpec(
        name="veselova",
        description="Veselova system: rigid body with horizontal angular velocity, <Omega, gamma> = 0, on SO(3)",
        build=_build,
        params={"I1": 1.0, "I2": 2.0, "I3": 3.0},
        coordinates=(),
        q0=(),
        v0=(1.0, 0.5, 0.0),
        invariants={"energy": _energy, "F": _F},
        notes=__doc__,
        positive=('I1', 'I2', 'I3'),
    )
)
