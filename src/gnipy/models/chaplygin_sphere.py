"""The physical Chaplygin sphere: a dynamically asymmetric ball rolling on a (possibly turning) table.

A ball of mass $m$ and radius $r$ whose centre of mass is its geometric centre, with principal
moments of inertia $I_1, I_2, I_3$ (body frame = principal axes), rolls without slipping on a
horizontal table that turns about the vertical axis through the origin at the constant rate
$\\Omega_t$ (parameter `Omega`; 0, the default, is a fixed table). Paper §7.4 treats the same
contact; its model is the physical ball only for $I_1 = I_2 = I_3$ (an erratum of the paper: the
docs' conventions page, "Errata in the paper"): here the constraints depend on the attitude, the Lie groupoid case of paper §9.

**Configuration and conventions.** $Q = \\mathbb{R}^2\\times SO(3)$, $q = (x, y)$ the position of the
centre (at height $r$), $R$ the attitude (body to space). Velocities
$v = (\\dot x, \\dot y, \\Omega_1, \\Omega_2, \\Omega_3)$ with $\\Omega = (R^T\\dot R)^\\vee$ the *body*
angular velocity; $\\omega = R\\Omega$ is the *space* angular velocity and $\\gamma = R^Te_3$ (the
third row of $R$) the upward vertical seen in the body frame.

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12\\Omega^T I\\Omega, \\qquad I = \\mathrm{diag}(I_1, I_2, I_3).$$

**Rolling.** The body point in contact, $(x, y, 0)$, moves with the table point under it,
$\\Omega_t e_3\\times(x, y, 0)$: with the centre velocity $v_c = (\\dot x, \\dot y, 0)$,
$v_c + \\omega\\times(-r e_3) = \\Omega_t(-y, x, 0)$, i.e. ((Cona), (Conb) with $\\omega$ the space angular
velocity)

$$\\dot x - r\\omega_2 + \\Omega_t y = 0, \\qquad \\dot y + r\\omega_1 - \\Omega_t x = 0, \\qquad \\omega = R\\Omega,$$

so $\\mu(R) = \\begin{pmatrix} 1 & 0 & -r R_{2,:}\\\\ 0 & 1 & r R_{1,:}\\end{pmatrix}$ (rows $R_{i,:}$ of $R$,
1-based) and $Y = (-\\Omega_t y, \\Omega_t x, 0, 0, 0)$: $\\mu(R)(v - Y) = 0$.

**Invariants** (functions `f(params, q, v, R)`, R the 3×3 attitude matrix).

- *Angular momentum about the contact point.* $K_A = R I\\Omega + m\\,r e_3\\times v_c$ (space frame).
  Its rate is $\\tau_A - v_A\\times m v_c$; the contact forces act at the contact point $A$ and
  gravity acts along $r e_3$ (the centre minus A), so $\\tau_A = 0$; $v_A = v_c$ (A is always under the
  centre). So $K_A$ is constant in space, on a fixed *and* on a turning table. In the body frame
  $M = R^T K_A = I\\Omega + m r\\,\\gamma\\times R^T v_c$, which obeys $\\dot M = M\\times\\Omega$; on a
  fixed table $R^Tv_c = r\\,\\Omega\\times\\gamma$ and $M = I\\Omega + m r^2\\gamma\\times(\\Omega\\times\\gamma)$,
  the classical form. Registered: $\\langle M, \\gamma\\rangle = (K_A)_3$ (`M_gamma`) and
  $|M|^2 = |K_A|^2$ (`M_squared`), the two integrals of the reduced (Chaplygin) equations.
- *Energy / Jacobi integral.* The table does work $F\\cdot\\Omega_t(-y, x, 0) = \\Omega_t\\,\\dot L_z$ on
  the ball through the friction force $F$ at the contact point, where
  $L_z = m(x\\dot y - y\\dot x) + (R I\\Omega)_3$ is the vertical angular momentum about the origin
  (gravity and the normal force are vertical and exert no vertical torque). So
  $J = E - \\Omega_t L_z$ with $E = l$ (`jacobi`) is conserved; it is the energy on a fixed table.

Default parameters $m = r = 1$, $(I_1, I_2, I_3) = (0.3, 0.4, 0.5)$ (a realizable ball:
$I_1 + I_2 + I_3 = 2\\int|\\rho|^2dm \\le 2mr^2$ and the triangle inequalities hold), $\\Omega_t = 0$.
Default initial condition: $q_0 = (0, 0)$, $R_0$ the identity, $\\Omega_0 = (1, 0.5, 2)$ and
$(\\dot x, \\dot y)$ from the constraints: $v_0 = (0.5, -1, 1, 0.5, 2)$ for the default parameters.
"""

from __future__ import annotations

import jax.numpy as jnp

from ..lie_groups import SO3
from ..system import System
from ..registry import ModelSpec, register

__all__ = [
    "MODEL",
    "contact_momentum_body",
    "contact_momentum_space",
    "rolling_constraints",
    "rolling_velocity",
    "table_drift",
]

COORDINATES = ("x", "y")
VELOCITIES = ("dx", "dy", "Omega1", "Omega2", "Omega3")
OMEGA0 = (1.0, 0.5, 2.0)  # default body angular velocity


def rolling_constraints(r, x, R):
    """$\\mu(R)$ of the rolling constraints ((Cona), (Conb) with $\\omega = R\\Omega$), shape (2, 5)."""
    one, zero = jnp.ones_like(r), jnp.zeros_like(r)
    return jnp.stack(
        [
            jnp.concatenate([jnp.stack([one, zero]), -r * R[1]]),  # ẋ − r ω₂ (+ Ω_t y) = 0
            jnp.concatenate([jnp.stack([zero, one]), r * R[0]]),  # ẏ + r ω₁ (− Ω_t x) = 0
        ]
    )


def table_drift(Omega, x, R):
    """The affine part $Y = (-\\Omega_t y, \\Omega_t x, 0, 0, 0)$ (the table's velocity at the contact)."""
    zero = jnp.zeros_like(Omega)
    return jnp.stack([-Omega * x[1], Omega * x[0], zero, zero, zero])


def rolling_velocity(r, Omega, x, R, Omega_body):
    """$(\\dot x, \\dot y)$ that the constraints require for the body angular velocity `Omega_body`."""
    w = R @ Omega_body
    return jnp.stack([r * w[1] - Omega * x[1], -r * w[0] + Omega * x[0]])


def _inertia(p):
    return jnp.asarray([p["I1"], p["I2"], p["I3"]])


def _lagrangian(x, R, v, p):
    m, I = p["m"], _inertia(p)
    # one weighted sum rather than slices of v: fewer XLA kernels per step (as in `rolling_ball`)
    return 0.5 * jnp.sum(jnp.concatenate([jnp.stack([m, m]), I]) * v * v)


def _constraints(x, R, p):
    return rolling_constraints(p["r"], x, R)


def _affine(x, R, p):
    return table_drift(p["Omega"], x, R)


def contact_momentum_space(p, q, v, R):
    """$K_A = R I\\Omega + m r e_3\\times v_c$: the angular momentum about the contact point, space frame."""
    R, v = jnp.asarray(R).reshape(3, 3), jnp.asarray(v)
    m, r = p["m"], p["r"]
    return R @ (_inertia(p) * v[2:]) + m * r * jnp.stack([-v[1], v[0], jnp.zeros_like(v[0])])


def contact_momentum_body(p, q, v, R):
    """$M = R^T K_A = I\\Omega + m r\\,\\gamma\\times R^T v_c$ (body frame)."""
    R = jnp.asarray(R).reshape(3, 3)
    return R.T @ contact_momentum_space(p, q, v, R)


def _M_gamma(p, q, v, R):
    R = jnp.asarray(R).reshape(3, 3)
    return contact_momentum_body(p, q, v, R) @ R[2]


def _M_squared(p, q, v, R):
    K = contact_momentum_space(p, q, v, R)
    return K @ K


def _jacobi(p, q, v, R):
    R, q, v = jnp.asarray(R).reshape(3, 3), jnp.asarray(q), jnp.asarray(v)
    m = p["m"]
    I = _inertia(p)
    E = 0.5 * m * (v[0] ** 2 + v[1] ** 2) + 0.5 * jnp.sum(I * v[2:] ** 2)
    Lz = m * (q[0] * v[1] - q[1] * v[0]) + (R @ (I * v[2:]))[2]
    return E - p["Omega"] * Lz


def _default_ic(p):
    # at q0 = 0 and R0 = I (ω = Ω) the table term vanishes: ẋ = r Ω₂, ẏ = −r Ω₁
    return (0.0, 0.0), (float(p["r"] * OMEGA0[1]), float(-p["r"] * OMEGA0[0]), *OMEGA0)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        _affine,
        n=2,
        group=SO3(),
        depends_on_orientation=True,
        coordinates=COORDINATES,
        velocities=VELOCITIES,
        name="chaplygin-sphere",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


MODEL = register(
    ModelSpec(
        name="chaplygin-sphere",
        description="Chaplygin sphere: asymmetric ball (centre of mass at the centre) rolling on a table "
        "turning at rate Omega, on R^2 x SO(3)",
        build=_build,
        params={"m": 1.0, "r": 1.0, "I1": 0.3, "I2": 0.4, "I3": 0.5, "Omega": 0.0},
        coordinates=COORDINATES,
        q0=(0.0, 0.0),
        v0=(0.5, -1.0, *OMEGA0),
        default_ic=_default_ic,
        invariants={"jacobi": _jacobi, "M_gamma": _M_gamma, "M_squared": _M_squared},
        notes=__doc__,
        positive=('m', 'r', 'I1', 'I2', 'I3'),
    )
)
