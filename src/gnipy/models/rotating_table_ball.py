"""A homogeneous ball rolling on a table that turns at constant rate $\\Omega$ (paper §7.4, affine case).

The reduced system of the paper's rolling-ball example with $I_1 = I_2 = I_3 = I$, written on
$\\mathbb{R}^5$: $q = (x, y, \\theta_1, \\theta_2, \\theta_3)$ with $\\dot\\theta = \\omega$, the space
angular velocity (for a homogeneous ball the kinetic energy and the rolling constraints do not
depend on the attitude, so the attitude is not needed; $\\theta$ is the integral of $\\omega$, not
an attitude parametrization).

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12 I|\\omega|^2,$$

with the affine rolling constraints ((Cona), (Conb)) $\\dot x - r\\omega_2 + \\Omega y = 0$,
$\\dot y + r\\omega_1 - \\Omega x = 0$, i.e. $\\mu(v - Y) = 0$ with
$\\mu = [[1, 0, 0, -r, 0], [0, 1, r, 0, 0]]$ and $Y = (-\\Omega y, \\Omega x, 0, 0, 0)$.

**Exact solution.** The equations $m\\ddot x = \\lambda_1$, $m\\ddot y = \\lambda_2$,
$I\\dot\\omega = (r\\lambda_2, -r\\lambda_1, 0)$ and the differentiated constraints give
$\\ddot x = -\\kappa\\dot y$, $\\ddot y = \\kappa\\dot x$ with $\\kappa = I\\Omega/(I + m r^2)$. With
$z = x + iy$: $\\dot z = \\dot z_0 e^{i\\kappa t}$ and

$$z = z_0 + \\frac{\\dot z_0}{i\\kappa}(e^{i\\kappa t} - 1), \\qquad
  \\int_0^t z = z_0 t - \\frac{\\dot z_0}{\\kappa^2}(e^{i\\kappa t} - 1 - i\\kappa t):$$

the contact point runs round a circle of radius $|\\dot z_0/\\kappa|$ centred at
$z_0 + i\\dot z_0/\\kappa$, at angular rate $\\kappa$ ($\\kappa = \\tfrac25\\Omega$ for the default
$I = \\tfrac23$, $m = r = 1$; $\\tfrac27\\Omega$ for a solid ball, $I = \\tfrac25 m r^2$). Then
$\\omega_3$ is constant, $\\omega_1 = (\\Omega x - \\dot y)/r$, $\\omega_2 = (\\dot x + \\Omega y)/r$, and
$\\theta_1 = \\theta_{1,0} + (\\Omega\\,\\mathrm{Re}\\!\\int_0^t z - (y - y_0))/r$,
$\\theta_2 = \\theta_{2,0} + (x - x_0 + \\Omega\\,\\mathrm{Im}\\!\\int_0^t z)/r$,
$\\theta_3 = \\theta_{3,0} + \\omega_3 t$. The closed forms are evaluated with small-argument-safe
ratios, so they hold for $\\Omega = 0$ (fixed table: straight-line rolling) as well.

**Invariants.** The energy is *not* conserved (the table does work on the ball):
$\\frac{d}{dt}\\big(\\tfrac12 m|\\dot z|^2 + \\tfrac12 I|\\omega|^2\\big)
= m\\Omega\\frac{d}{dt}(x\\dot y - y\\dot x)$. Conserved: the Jacobi-type integral
$\\tfrac12 m|\\dot z|^2 + \\tfrac12 I|\\omega|^2 - m\\Omega(x\\dot y - y\\dot x)$, the squared speed
$|\\dot z|^2$ of the contact point, and the spin $\\omega_3$.

Default parameters are the paper's first example (m = r = Ω = 1, I = 2/3); default initial
condition $(x_0, y_0, \\dot x_0, \\dot y_0) = (1, 1, 1, 1)$, $\\omega_3 = 0$ and $\\omega_1, \\omega_2$ from
the constraints: $v_0 = (1, 1, 0, 2, 0)$ for the default parameters.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..system import System
from .elementary import sinc, sine_defect_ratio, versine_ratio
from ..registry import ModelSpec, register

__all__ = ["MODEL", "exact"]

COORDINATES = ("x", "y", "theta1", "theta2", "theta3")


def _lagrangian(q, v, p):
    m, I = p["m"], p["I"]
    return 0.5 * m * (v[0] ** 2 + v[1] ** 2) + 0.5 * I * (v[2:] @ v[2:])


def _constraints(q, p):
    r = p["r"]
    one, zero = jnp.ones_like(q[0]), jnp.zeros_like(q[0])
    return jnp.stack(
        [
            jnp.stack([one, zero, zero, -r * one, zero]),  # (Cona)
            jnp.stack([zero, one, r * one, zero, zero]),  # (Conb)
        ]
    )


def _affine(q, p):
    Omega = p["Omega"]
    zero = jnp.zeros_like(q[0])
    return jnp.stack([-Omega * q[1], Omega * q[0], zero, zero, zero])


def _default_ic(p):
    r, W = p["r"], p["Omega"]
    x0, y0, dx0, dy0 = 1.0, 1.0, 1.0, 1.0
    return (x0, y0, 0.0, 0.0, 0.0), (dx0, dy0, (W * x0 - dy0) / r, (dx0 + W * y0) / r, 0.0)


def _build(p):
    return System(
        _lagrangian,
        _constraints,
        _affine,
        coordinates=COORDINATES,
        name="rotating-table-ball",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


def exact(p, q0, v0, t):
    """Exact `(q, v)`, arrays (T, 5), at times `t` (from t = 0) for `v0` on the constraints.

    Read from `v0`: $\\dot x_0, \\dot y_0, \\omega_3$ ($\\omega_1, \\omega_2$ follow from the constraints).
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    m, r, I, W = p["m"], p["r"], p["I"], p["Omega"]
    kappa = I * W / (I + m * r**2)
    z0 = complex(float(q0[0]), float(q0[1]))
    dz0 = complex(float(v0[0]), float(v0[1]))
    w3 = float(v0[4])
    kt = kappa * t
    dz = dz0 * np.exp(1j * kt)
    z = z0 + dz0 * t * np.exp(0.5j * kt) * sinc(0.5 * kt)  # (e^{iκt} − 1)/(iκ)
    zint = z0 * t + dz0 * (t**2 * versine_ratio(kt) + 1j * kappa * t**3 * sine_defect_ratio(kt))
    x, y, dx, dy = z.real, z.imag, dz.real, dz.imag
    th1 = float(q0[2]) + (W * zint.real - (y - q0[1])) / r
    th2 = float(q0[3]) + ((x - q0[0]) + W * zint.imag) / r
    th3 = float(q0[4]) + w3 * t
    q = np.stack([x, y, th1, th2, th3], axis=-1)
    v = np.stack([dx, dy, (W * x - dy) / r, (dx + W * y) / r, w3 * np.ones_like(t)], axis=-1)
    return q, v


def _jacobi(p, q, v):
    kinetic = 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I"] * (v[2] ** 2 + v[3] ** 2 + v[4] ** 2)
    return kinetic - p["m"] * p["Omega"] * (q[0] * v[1] - q[1] * v[0])


def _speed_squared(p, q, v):
    return v[0] ** 2 + v[1] ** 2


def _spin(p, q, v):
    return v[4]


MODEL = register(
    ModelSpec(
        name="rotating-table-ball",
        description="homogeneous ball on a table turning at rate Ω (paper §7.4, affine constraints)",
        build=_build,
        params={"m": 1.0, "r": 1.0, "I": 2.0 / 3.0, "Omega": 1.0},
        coordinates=COORDINATES,
        q0=(1.0, 1.0, 0.0, 0.0, 0.0),
        v0=(1.0, 1.0, 0.0, 2.0, 0.0),
        default_ic=_default_ic,
        exact=exact,
        invariants={"jacobi": _jacobi, "speed_squared": _speed_squared, "spin": _spin},
        notes=__doc__,
        positive=('m', 'r', 'I'),
    )
)
