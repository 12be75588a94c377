"""The rolling ball of paper §7.4: a reduced system on $\\mathbb{R}^2 \\times SO(3)$ (affine constraints).

A ball of radius r and mass m rolls without slipping on a table turning at constant rate $\\Omega$
about the vertical axis. A point is $b = (x, y; R)$, a velocity
$v = (\\dot x, \\dot y, \\omega_1, \\omega_2, \\omega_3)$ with $\\omega$ the angular velocity as the paper's
equations use it: the *space* angular velocity, $\\hat\\omega = \\dot R R^{-1}$ (the rolling constraints
below are those of a ball for the space angular velocity: an erratum of the paper, on the docs'
conventions page, "Errata in the paper"). The paper's reduced Lagrangian (LagCont) and
constraints (Cona), (Conb):

$$l = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12(I_1\\omega_1^2 + I_2\\omega_2^2 + I_3\\omega_3^2),$$
$$\\dot x - r\\omega_2 + \\Omega y = 0, \\qquad \\dot y + r\\omega_1 - \\Omega x = 0,$$

i.e. $\\mu(v - Y) = 0$ with $\\mu = [[1, 0, 0, -r, 0], [0, 1, r, 0, 0]]$ (rows $(\\mu^a, \\eta^a)$:
x-part, group part), $Y = (-\\Omega y, \\Omega x, 0, 0, 0)$ and $\\Pi = \\mathbb{G}Y = (-m\\Omega y, m\\Omega x, 0, 0, 0)$.
Nothing depends on R: the system is *reduced* (paper §7), and R is only reconstructed.

**Reconstruction.** R follows from the space angular velocity, $\\dot R = \\hat\\omega R$, and the steps
reconstruct $R_{k+1} = \\mathrm{cay}(\\sigma_k)\\,R_k$ (right trivialization: the System is built with
`reconstruction="right"`, :class:`~gnipy.spaces.GroupSpace`). The equations of $(x, y, \\omega)$ are
the paper's, unchanged (they do not involve R); only R depends on this reading. Reconstructed as
if $\\omega$ were the body angular velocity ($\\dot R = R\\hat\\omega$), R would not be the ball's attitude:
measured for $I_1 = I_2 = I_3$, $\\Omega = 1$, $\\omega_0 = (0.3, 2, -0.5)$, the continuous solutions' R is
then off from the physical ball's (model `chaplygin-sphere`) by up to 1.6 over t ≤ 20, while with
$\\dot R = \\hat\\omega R$ it agrees to 6e-11 (and $(x, y)$ to 2e-11). Result files say which
reconstruction was used (attribute `orientation`), and whether R is a physical attitude for the
parameters of the run.

**Which ball this is.** With unequal moments this is the paper's *simplified* model: the inertia
tensor $\\mathrm{diag}(I_1, I_2, I_3)$ is constant in the frame in which $\\omega$ enters the rolling
constraints, the table's, whereas a body's inertia tensor is constant in its body frame. It is what
the paper's Fig. 3 integrates, and the model is kept exactly as printed. It is **not** the physical
Chaplygin sphere (whose Lagrangian holds the body angular velocity $R^T\\omega$ and whose constraints
therefore depend on R): that is the separate model `chaplygin-sphere`, and with unequal moments R is
not a physical attitude. For $I_1 = I_2 = I_3$ the two agree, attitude included (the dynamics of
$(x, y, \\omega)$ are then those of `rotating-table-ball`).

**Retraction.** The System uses the Cayley map (the paper's choice for §7.4, whose explicit equations
are written for it). The registry holds float parameters only, so the retraction is not a model
parameter: for the exponential map call :func:`build_system` with `retraction="exp"` (the GNI core
supports any retraction of :mod:`gnipy.retractions` through `gnipy.System(..., retraction=...)`).

**Examples** (paper §7.4).

- Example 1 (the defaults; Figs. 1–2): homogeneous ball $I_1 = I_2 = I_3 = 2/3$, $m = r = \\Omega = 1$;
  $(x_0, y_0) = (1, 1)$, $(\\dot x_0, \\dot y_0) = (1, 1)$, $\\omega_0 = (0, 2, 0)$, $R_0 = I$.
- Example 2 (:data:`EXAMPLE_2`, Fig. 3): $I = (1, 1.1, 1.2)$, $m = 3$, $r = 1$, $\\Omega = 0.2$;
  $(x_0, y_0) = (1, 0)$, $\\omega_0 = (-0.2, 0, 0.4)$ and $(\\dot x_0, \\dot y_0) = (r\\omega_2 - \\Omega y_0,
  \\Omega x_0 - r\\omega_1) = (0, 0.4)$ from the constraints. :func:`example_2` returns its System and
  initial condition.

**Exact solution** (only for $I_1 = I_2 = I_3 = I$; :func:`exact` returns None otherwise). The
Lagrange–d'Alembert–Poincaré equations $m\\ddot x = \\lambda_1$, $m\\ddot y = \\lambda_2$,
$I\\dot\\omega - I\\omega\\times\\omega = I\\dot\\omega = (r\\lambda_2, -r\\lambda_1, 0)$ and the
differentiated constraints give $\\ddot x = -\\kappa\\dot y$, $\\ddot y = \\kappa\\dot x$ with
$\\kappa = I\\Omega/(I + mr^2)$: the contact point runs round a circle at angular rate $\\kappa$
(radius $|\\dot z_0|/\\kappa$, $z = x + iy$); $\\omega_1 = (\\Omega x - \\dot y)/r$,
$\\omega_2 = (\\dot x + \\Omega y)/r$, $\\omega_3$ is constant. These are the dynamics of $(x, y, \\omega)$
of the $\\mathbb{R}^5$ model `rotating-table-ball`, whose closed forms are reused. The attitude R has
no closed form here (it is reconstructed from $\\dot R = \\hat\\omega R$).

**Invariants.** The table does work on the ball: $dE/dt = \\lambda\\cdot\\mu Y = m\\Omega\\,
\\frac{d}{dt}(x\\dot y - y\\dot x)$ for *any* moments (the gyroscopic term $\\omega\\cdot(I\\omega\\times\\omega)$
vanishes), so $J = E - m\\Omega(x\\dot y - y\\dot x)$ is conserved (`jacobi`). When $I_1 = I_2$, Euler's
third equation $I_3\\dot\\omega_3 = (I_1 - I_2)\\omega_1\\omega_2$ makes $\\omega_3$ constant (`spin`;
NaN when $I_1 \\ne I_2$, where it is not conserved).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..inputs import provenance_number
from ..lie_groups import SO3
from ..system import System
from . import rotating_table_ball
from ..registry import ModelSpec, register

__all__ = ["EXAMPLE_2", "MODEL", "build_system", "exact", "example_2", "jacobi_integral", "orientation_note",
           "velocity_from_constraints"]

COORDINATES = ("x", "y")
VELOCITIES = ("dx", "dy", "omega1", "omega2", "omega3")
DEFAULT_PARAMS = {"m": 1.0, "r": 1.0, "I1": 2.0 / 3.0, "I2": 2.0 / 3.0, "I3": 2.0 / 3.0, "Omega": 1.0}
IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)

#: The paper's second example (§7.4, Fig. 3): parameters and initial position and angular velocity;
#: $(\\dot x_0, \\dot y_0)$ follow from the constraints (see :func:`example_2`).
EXAMPLE_2 = {
    "params": {"m": 3.0, "r": 1.0, "I1": 1.0, "I2": 1.1, "I3": 1.2, "Omega": 0.2},
    "x0": (1.0, 0.0),
    "omega0": (-0.2, 0.0, 0.4),
}


def _lagrangian(x, v, p):
    m, inertia = p["m"], jnp.asarray([p["I1"], p["I2"], p["I3"]])
    # ½ m(ẋ² + ẏ²) + ½ Σ I_i ω_i² as one weighted sum: slicing v into parts gives XLA several small
    # kernels per gradient in every Newton iteration (measured: 24 fewer kernels per GNI step)
    diag = jnp.concatenate([jnp.stack([m, m]), inertia])
    return 0.5 * jnp.sum(diag * v * v)


def _constraints(x, p):
    r = p["r"]
    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    return jnp.stack(
        [
            jnp.stack([one, zero, zero, -r * one, zero]),  # (Cona)
            jnp.stack([zero, one, r * one, zero, zero]),  # (Conb)
        ]
    )


def _affine(x, p):
    Omega = p["Omega"]
    zero = jnp.zeros_like(x[0])
    return jnp.stack([-Omega * x[1], Omega * x[0], zero, zero, zero])


def velocity_from_constraints(p, x0, omega0):
    """The velocity $(\\dot x, \\dot y, \\omega)$ on the constraints at $(x_0, y_0)$ with angular velocity
    $\\omega_0$: $\\dot x = r\\omega_2 - \\Omega y$, $\\dot y = \\Omega x - r\\omega_1$."""
    r, W = p["r"], p["Omega"]
    w = tuple(float(c) for c in omega0)
    return (r * w[1] - W * x0[1], W * x0[0] - r * w[0], *w)


def _default_ic(p):
    r, W = p["r"], p["Omega"]
    x0, y0, dx0, dy0 = 1.0, 1.0, 1.0, 1.0
    return (x0, y0), (dx0, dy0, (W * x0 - dy0) / r, (dx0 + W * y0) / r, 0.0)


def orientation_note(p) -> str:
    """Whether R is a physical attitude for parameters `p` (the file attribute `orientation` ends
    with it): only for $I_1 = I_2 = I_3$ is the model the physical ball (see the module docstring)."""
    if p["I1"] == p["I2"] == p["I3"]:
        return "I1 = I2 = I3: R is the attitude of the physical ball (as in model chaplygin-sphere)"
    return ("R is not a physical attitude: with unequal moments the paper's simplified model is not the "
            "physical Chaplygin sphere (model chaplygin-sphere)")


def build_system(p, *, retraction="cayley", defaults=None, reconstruction="right") -> System:
    """The System for parameters `p` (a dict with m, r, I1, I2, I3, Omega), on $\\mathbb{R}^2\\times SO(3)$.

    Arguments:
        p: the parameters.
        retraction: `"cayley"` (the model's choice) or `"exp"`.
        defaults: the default initial condition `(q0, v0)` (default: example 1's for these parameters).
        reconstruction: `"right"` (the model's: ω the space angular velocity, $\\dot R = \\hat\\omega R$) or
            `"left"` (ω read as the body angular velocity, $\\dot R = R\\hat\\omega$: not the ball's attitude;
            for comparisons). The motion of $(x, y, \\omega)$ is the same.
    """
    traced = any(isinstance(v, jax.core.Tracer) for v in p.values())  # differentiated: kept traced
    p = {k: v if isinstance(v, jax.core.Tracer) else float(v) for k, v in p.items()}
    if traced:  # the provenance numbers and the note from the values known now; no default start
        known = {k: provenance_number(v) for k, v in p.items()}
        note = orientation_note(known) if reconstruction == "right" else None
    return System(
        _lagrangian,
        _constraints,
        _affine,
        n=2,
        group=SO3(),
        retraction=retraction,
        reconstruction=reconstruction,
        coordinates=COORDINATES,
        velocities=VELOCITIES,
        name="rolling-ball",
        args=p,
        params=p,
        defaults=(None if traced else _default_ic(p)) if defaults is None else defaults,
        orientation_note=(note if traced else orientation_note(p)) if reconstruction == "right" else
        "R is not the ball's attitude: omega read as the body angular velocity (reconstruction='left')",
    )


def _build(p):
    return build_system(p)


def example_2(retraction="cayley"):
    """The paper's second example: `(system, q0, v0)` with $q_0 = (1, 0)$ and
    $v_0 = (0, 0.4, -0.2, 0, 0.4)$ (velocity from the constraints); $R_0 = I$."""
    p = dict(EXAMPLE_2["params"])
    q0 = tuple(EXAMPLE_2["x0"])
    v0 = velocity_from_constraints(p, q0, EXAMPLE_2["omega0"])
    return build_system(p, retraction=retraction, defaults=(q0, v0)), q0, v0


def exact(p, q0, v0, t):
    """Exact `(q, v)` at times `t` (from t = 0): q = (x, y) with shape (T, 2), v = (ẋ, ẏ, ω) with
    shape (T, 5), for $I_1 = I_2 = I_3$ and `v0` on the constraints; None for unequal moments
    (no closed form). Read from `v0`: $\\dot x_0, \\dot y_0, \\omega_3$ (the contact point moves on a
    circle at rate $\\kappa = I\\Omega/(I + mr^2)$; see the module docstring)."""
    if not (p["I1"] == p["I2"] == p["I3"]):
        return None
    p5 = {"m": p["m"], "r": p["r"], "I": p["I1"], "Omega": p["Omega"]}
    q5, v = rotating_table_ball.exact(p5, (float(q0[0]), float(q0[1]), 0.0, 0.0, 0.0), v0, t)
    return q5[:, :2], v


def jacobi_integral(p, q, v):
    """$J = E - m\\Omega(x\\dot y - y\\dot x)$, $E = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12\\sum_i I_i\\omega_i^2$
    (conserved for any moments). Works on single nodes or on arrays (..., 2), (..., 5)."""
    q, v = np.asarray(q, dtype=np.float64), np.asarray(v, dtype=np.float64)
    inertia = np.array([p["I1"], p["I2"], p["I3"]])
    energy = 0.5 * p["m"] * (v[..., 0] ** 2 + v[..., 1] ** 2) + 0.5 * np.sum(inertia * v[..., 2:] ** 2, axis=-1)
    return energy - p["m"] * p["Omega"] * (q[..., 0] * v[..., 1] - q[..., 1] * v[..., 0])


def _spin(p, q, v):
    if p["I1"] != p["I2"]:
        return float("nan")
    return v[4]


MODEL = register(
    ModelSpec(
        name="rolling-ball",
        description="ball rolling on a table turning at rate Ω, reduced on R²×SO(3) (paper §7.4; "
        "simplified model for unequal moments)",
        build=_build,
        params=dict(DEFAULT_PARAMS),
        coordinates=COORDINATES,
        q0=(1.0, 1.0),
        v0=(1.0, 1.0, 0.0, 2.0, 0.0),
        R0=IDENTITY,
        default_ic=_default_ic,
        exact=exact,
        invariants={"jacobi": jacobi_integral, "spin": _spin},
        notes=__doc__,
        positive=('m', 'r', 'I1', 'I2', 'I3'),
    )
)
