r"""The rattleback (celt): an ellipsoidal rigid body rolling without slipping on a horizontal plane,
whose principal axes of inertia are turned against its geometric axes, so that a spin one way
turns into rocking and then into a spin the other way (spin reversal).

The parameters are Kane and Levinson's (*Realistic mathematical modeling of the rattleback*,
Int. J. Non-Linear Mech. 17 (1982) 175–186), in SI units: the ellipsoid's semi-axes
$a = 0.2$, $b = 0.03$, $c = 0.02$ m along the body axes 1, 2, 3; the centre of mass $G$ a distance
$h = 0.01$ m below the ellipsoid's centre on axis 3; the inertia about $G$ per unit mass
$A = 2\cdot10^{-4}$, $B = 1.6\cdot10^{-3}$, $C = 1.7\cdot10^{-3}$ m² on the diagonal and the
product $D = -2\cdot10^{-5}$ m² between axes 1 and 2, $I = m\begin{pmatrix}A & D & 0\\ D & B & 0\\
0 & 0 & C\end{pmatrix}$ (the sign of D chooses which spin reverses); $m = 1$ kg (the motion does
not depend on m), $g = 9.81$.

**Configuration and conventions.** $Q = \mathbb{R}^3\times SO(3)$: $x$ the position of G, $R$ the
attitude (body to space, z up); velocities $v = (\dot x, \Omega)$ with $\Omega$ the body angular
velocity; $\gamma = R^Te_3$ (the third row of R) is the upward vertical seen in the body frame.

$$l = \tfrac12 m|\dot x|^2 + \tfrac12\Omega^TI\Omega - mgx_3.$$

**Contact.** The body point in contact is the one whose outward normal is $-\gamma$: from G,
$r(\gamma) = o - A_e\gamma/\sqrt{\gamma^TA_e\gamma}$ with $o = (0, 0, h)$ the ellipsoid's centre and
$A_e = \mathrm{diag}(a^2, b^2, c^2)$. Holonomic: it is on the plane, $\varphi(x, R) = x_3 +
e_3^TRr(\gamma) = 0$. Nonholonomic (2): it does not slide, the horizontal components of
$\dot x + R(\Omega\times r)$ vanish (the vertical one is $d\varphi$, which gnipy adds).

**Invariant.** The energy $E = \tfrac12 m|\dot x|^2 + \tfrac12\Omega^TI\Omega + mgx_3$ (the contact
force does no work on a rolling body).

**Checked** (tests/models/test_rattleback.py) against an independent formulation: the rolling
body's equations about the contact point (Borisov and Mamaev, *Rolling of a rigid body on a plane
and sphere. Hierarchy of dynamics*, Regul. Chaotic Dyn. 7 (2002) 177–200),
$\dot M = M\times\Omega + m\dot r\times(\Omega\times r) + mg\,r\times\gamma$,
$M = I\Omega + m\,r\times(\Omega\times r)$, $\dot\gamma = \gamma\times\Omega$, in $(\Omega, \gamma)$
alone, integrated by SciPy.

Default initial condition (:func:`build`, made by :func:`spinning`): upright, spinning at
$\Omega_3 = -5$ rad/s with a small rocking $\Omega_1 = 0.1$ rad/s, the direction that reverses
with these parameters (near t = 8 s).

**Which methods.** Like the Whipple bicycle, the reversal contracts phase volume, which the GNI's
volume-preserving map cannot follow: its hidden momentum takes over after the reversal and the run
is flagged; `sgni-trapezoid` and `dla` keep it (the models guide, "The rattleback", measures it).
The rocking is fast (a period of about 0.06 s about the short axis, by the small-oscillation
estimate), so steps of 0.002 or less are needed: at h = 0.02 the GNI's solve fails at t = 0.26 s
(measured).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..lie_groups import SO3
from ..system import System

__all__ = ["PARAMS", "build", "spinning", "contact_vector", "energy"]

#: Kane and Levinson (1982), SI units (module docstring)
PARAMS = {"a": 0.2, "b": 0.03, "c": 0.02, "h": 0.01, "A": 2e-4, "B": 1.6e-3, "C": 1.7e-3, "D": -2e-5, "m": 1.0,
          "g": 9.81}


def _inertia(p):
    zero = 0.0 * p["A"]
    return p["m"] * jnp.stack([jnp.stack([p["A"], p["D"], zero]), jnp.stack([p["D"], p["B"], zero]),
                               jnp.stack([zero, zero, p["C"]])])


def contact_vector(gamma, p):
    """$r(\\gamma)$: from the centre of mass to the point in contact, in the body frame, when the
    upward vertical seen in the body frame is `gamma`."""
    axes = jnp.stack([p["a"] ** 2, p["b"] ** 2, p["c"] ** 2])
    centre = jnp.stack([0.0 * p["h"], 0.0 * p["h"], p["h"]])
    return centre - axes * gamma / jnp.sqrt(jnp.sum(axes * gamma * gamma))


def _lagrangian(x, R, v, p):
    m = p["m"]
    return 0.5 * m * v[:3] @ v[:3] + 0.5 * v[3:] @ _inertia(p) @ v[3:] - m * p["g"] * x[2]


def _holonomic(x, R, p):
    return jnp.stack([x[2] + R[2] @ contact_vector(R[2], p)])


def _constraints(x, R, p):
    r = contact_vector(R[2], p)
    cross = jnp.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])  # r× (r × Ω = cross @ Ω)
    rows = -R[:2] @ cross  # R(Ω × r) = −R (r × Ω)
    return jnp.concatenate([jnp.eye(3, dtype=R.dtype)[:2], rows], axis=1)


def energy(p, q, v, R):
    """The energy $\\tfrac12 m|\\dot x|^2 + \\tfrac12\\Omega^TI\\Omega + mgx_3$."""
    q, v = jnp.asarray(q), jnp.asarray(v)
    return 0.5 * p["m"] * v[:3] @ v[:3] + 0.5 * v[3:] @ _inertia(p) @ v[3:] + p["m"] * p["g"] * q[2]


def spinning(params: dict | None = None, omega=(0.0, 0.0, 5.0)):
    """`(q0, v0)` upright (R the identity, G at height c − h) with the body angular velocity
    `omega`, and the velocity of G that rolling requires."""
    p = dict(PARAMS)
    p.update(params or {})
    d = p["c"] - p["h"]
    w = np.asarray(omega, dtype=float)
    # r = (0, 0, −d) upright: ẋ = −Ω × r = (Ω₂ d, −Ω₁ d, 0)
    return np.array([0.0, 0.0, d]), np.array([w[1] * d, -w[0] * d, 0.0, *w])


def build(params: dict | None = None, *, omega=(0.1, 0.0, -5.0)) -> System:
    """The rattleback as a System on R³ × SO(3) with the parameters `params` (default
    :data:`PARAMS`; a partial dict updates it) as `args`, its default initial condition upright
    with the body angular velocity `omega` (default: a spin of −5 rad/s about the vertical and a
    rocking of 0.1 rad/s, which reverses with the default D)."""
    p = dict(PARAMS)
    p.update(params or {})
    q0, v0 = spinning(p, omega)
    return System(_lagrangian, _constraints, holonomic=_holonomic, n=3, group=SO3(), depends_on_orientation=True,
                  coordinates=("x", "y", "z"), velocities=("dx", "dy", "dz", "Omega1", "Omega2", "Omega3"),
                  name="rattleback", args={k: float(v) for k, v in p.items()}, defaults=(q0, v0))
