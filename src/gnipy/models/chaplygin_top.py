"""The Chaplygin top: a rolling ball whose centre of mass is off its geometric centre, under gravity.

The ball of :mod:`~gnipy.models.chaplygin_sphere` (mass $m$, radius $r$, rolling without slipping on
a table turning at rate $\\Omega_t$, parameter `Omega`, default 0) with its centre of mass at the
body vector $s = (0, 0, -a)$ from the geometric centre (so for $a > 0$ it hangs below the centre
when $R = I$), principal moments $I_1, I_2, I_3$ *about the centre of mass* along the body axes, and
gravity $g$ along $-e_3$. Paper §7.4 calls this the Chaplygin top. The metric and the potential
depend on the attitude: the Lie groupoid case of paper §9.

**Conventions** as in :mod:`~gnipy.models.chaplygin_sphere`: $q = (x, y)$ the geometric centre (at
height $r$), $R$ body to space, $v = (\\dot x, \\dot y, \\Omega)$ with $\\Omega = (R^T\\dot R)^\\vee$ the body
angular velocity, $\\omega = R\\Omega$, $\\gamma = R^Te_3$.

The centre of mass is at $c = (x, y, r) + Rs$ and moves with $\\dot c = v_c + \\omega\\times(Rs) =
v_c + R(\\Omega\\times s)$, $v_c = (\\dot x, \\dot y, 0)$, so

$$l = \\tfrac12 m\\,|v_c + R(\\Omega\\times s)|^2 + \\tfrac12\\Omega^T I_c\\Omega - m g\\, e_3^T R s,
\\qquad I_c = \\mathrm{diag}(I_1, I_2, I_3),$$

($V = m g\\langle\\gamma, s\\rangle = -m g a\\gamma_3$ up to the constant $m g r$). The rolling
constraints are those of the sphere (they concern the geometric centre):
$\\dot x - r\\omega_2 + \\Omega_t y = 0$, $\\dot y + r\\omega_1 - \\Omega_t x = 0$.

**Invariant** (`f(params, q, v, R)`): the energy $E = T + V$ on a fixed table; on a turning table
the Jacobi integral $J = E - \\Omega_t L_z$ with $L_z = m(c\\times\\dot c)_3 + (R I_c\\Omega)_3$, the
vertical angular momentum about the origin (the table's friction force $F$ at the contact point
does the work $\\Omega_t(xF_y - yF_x) = \\Omega_t\\dot L_z$; gravity and the normal force are vertical and
exert no vertical torque about the origin). Registered as `jacobi`. Unlike the sphere, the
angular momentum about the contact point is not conserved (gravity has a torque about it).

Defaults: $m = r = 1$, $a = 0.3$, $(I_1, I_2, I_3) = (0.3, 0.4, 0.5)$, $g = 9.81$, $\\Omega_t = 0$;
$q_0 = (0, 0)$, a tilted attitude $R_0 = \\exp(\\hat\\theta_0)$ with $\\theta_0 = (0.5, 0.2, 0)$
(:data:`R0`; the centre of mass starts off the vertical through the contact point, so the top
rocks), $\\Omega_0 = (0.3, -0.2, 2)$, and $(\\dot x, \\dot y)$ from the constraints at $R_0$.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..lie_groups import SO3
from ..system import System
from .chaplygin_sphere import rolling_constraints, table_drift
from ..registry import ModelSpec, register

__all__ = ["MODEL", "R0", "center_of_mass_offset"]

COORDINATES = ("x", "y")
VELOCITIES = ("dx", "dy", "Omega1", "Omega2", "Omega3")
THETA0 = (0.5, 0.2, 0.0)  # rotation vector of the default tilted attitude
OMEGA0 = (0.3, -0.2, 2.0)  # default body angular velocity


def _rotation(theta):
    """Rodrigues' formula in NumPy (host-side defaults)."""
    theta = np.asarray(theta, dtype=np.float64)
    t = np.linalg.norm(theta)
    K = np.array([[0, -theta[2], theta[1]], [theta[2], 0, -theta[0]], [-theta[1], theta[0], 0]])
    if t == 0:
        return np.eye(3)
    return np.eye(3) + np.sin(t) / t * K + (1 - np.cos(t)) / t**2 * (K @ K)


R0_MATRIX = _rotation(THETA0)
R0 = tuple(float(x) for x in R0_MATRIX.ravel())  # row-major, as ModelSpec.R0


def center_of_mass_offset(a):
    """The body vector $s = (0, 0, -a)$ from the geometric centre to the centre of mass."""
    zero = jnp.zeros_like(a)
    return jnp.stack([zero, zero, -a])


def _parts(p, q, v, R):
    """(T, V, c, ċ): kinetic and potential energy, centre-of-mass position and velocity."""
    m, r, g = p["m"], p["r"], p["g"]
    s = center_of_mass_offset(jnp.asarray(p["a"]))
    I = jnp.stack([jnp.asarray(p["I1"]), jnp.asarray(p["I2"]), jnp.asarray(p["I3"])])
    W = v[2:]
    vc = jnp.stack([v[0], v[1], jnp.zeros_like(v[0])])
    cdot = vc + R @ jnp.cross(W, s)  # ċ = v_c + R(Ω × s)
    c = jnp.stack([q[0], q[1], r + jnp.zeros_like(q[0])]) + R @ s
    T = 0.5 * m * (cdot @ cdot) + 0.5 * jnp.sum(I * W**2)
    V = m * g * (R @ s)[2]
    return T, V, c, cdot, I


def _lagrangian(x, R, v, p):
    T, V, *_ = _parts(p, x, v, R)
    return T - V


def _constraints(x, R, p):
    return rolling_constraints(p["r"], x, R)


def _affine(x, R, p):
    return table_drift(p["Omega"], x, R)


def _jacobi(p, q, v, R):
    q, v, R = jnp.asarray(q), jnp.asarray(v), jnp.asarray(R).reshape(3, 3)
    T, V, c, cdot, I = _parts(p, q, v, R)
    Lz = p["m"] * (c[0] * cdot[1] - c[1] * cdot[0]) + (R @ (I * v[2:]))[2]
    return T + V - p["Omega"] * Lz


def _default_ic(p):
    w = R0_MATRIX @ np.asarray(OMEGA0)
    # at q0 = 0 the table term vanishes: ẋ = r ω₂, ẏ = −r ω₁
    return (0.0, 0.0), (float(p["r"] * w[1]), float(-p["r"] * w[0]), *OMEGA0)


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
        name="chaplygin-top",
        args=p,
        params=p,
        defaults=(*_default_ic(p), R0),
    )


_DEFAULTS = {"m": 1.0, "r": 1.0, "a": 0.3, "I1": 0.3, "I2": 0.4, "I3": 0.5, "g": 9.81, "Omega": 0.0}

MODEL = register(
    ModelSpec(
        name="chaplygin-top",
        description="Chaplygin top: rolling ball with its centre of mass a below the centre, under gravity, "
        "on R^2 x SO(3)",
        build=_build,
        params=_DEFAULTS,
        coordinates=COORDINATES,
        q0=(0.0, 0.0),
        v0=_default_ic(_DEFAULTS)[1],
        R0=R0,
        default_ic=_default_ic,
        invariants={"jacobi": _jacobi},
        notes=__doc__,
        positive=('m', 'r', 'I1', 'I2', 'I3'),
    )
)
