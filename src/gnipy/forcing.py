"""Forces and inputs: generalized forces $F(b, v, u, t)$ on a system, the inputs $u$ that drive
them, and their discrete counterparts $f_d^\\mp$ (discrete mechanics with forcing).

**Continuous.** A :class:`~gnipy.System` built with `force=` carries a generalized force, a
covector in the velocity coordinates ($(\\dot x, \\xi)$ on $\\mathbb{R}^n\\times G$: a body torque for
left trivialization, a space torque for `reconstruction="right"`). The Lagrange–d'Alembert
principle with forcing,
$\\delta\\int l\\,dt + \\int F\\cdot\\delta q\\,dt = 0$ for variations $\\delta q$ in the constraint
distribution, adds $F$ to the right-hand side of the equations of motion
(:func:`gnipy.equations.lagrange_dalembert_acceleration`).

**Inputs.** $u(t)$ comes from a :class:`Drive`: per-step values held constant over each step
$[t_k, t_{k+1})$ (zero-order hold, what a discrete optimal-control problem chooses), or a
function `u(t)`. :func:`gnipy.simulate` attaches it to the system (`controls=`); the stepping loop
tells the system the step it is taking (:meth:`Drive.at_step`).

**Discrete.** The discrete forced Lagrange–d'Alembert principle (Marsden & West, *Discrete mechanics
and variational integrators*, Acta Numerica 2001, §3.2; Kobilarov, Marsden & Sukhatme,
*Geometric discretization of nonholonomic systems with symmetries*, DCDS-S 2010, for the
constrained case)
$\\delta\\sum_k l_d(q_k, q_{k+1}) + \\sum_k\\big(f^-_d\\cdot\\delta q_k + f^+_d\\cdot\\delta q_{k+1}\\big) = 0$
replaces the discrete Legendre transforms by the forced ones

$$p_k = FL^-(q_k, q_{k+1}) - f^-_k, \\qquad p_{k+1} = FL^+(q_k, q_{k+1}) + f^+_k,$$

and the constraints are imposed as before. The pair $f^\\mp_k$ approximates the virtual work
$\\int_{t_k}^{t_{k+1}} F\\cdot\\delta q\\,dt$ by the quadrature of the discrete Lagrangian
(:func:`discrete_forces`): the trapezoid's $f^- = \\tfrac h2F(q_k)$, $f^+ = \\tfrac h2F(q_{k+1})$; the
midpoint's $f^\\mp = \\tfrac h2F(q_{k+1/2})$; Euler A's $f^- = hF(q_k)$, $f^+ = 0$; Euler B's
$f^- = 0$, $f^+ = hF(q_{k+1})$. The velocity argument is the step's velocity $z/h$ and the input
the step's $u_k$ (or $u(t)$ at the node's time). The symmetric rules keep the symmetric methods
of order 2 (measured against the reference in the tests); with no force nothing changes, to the
bit (the unforced code paths run).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .errors import InputError

__all__ = ["Drive", "discrete_forces", "FORCE_RULES", "InputForce", "input_force", "drive", "check_forced_run"]

FORCE_RULES: dict[str, tuple[tuple[tuple[float, float], ...], tuple[tuple[float, float], ...]]] = {
    "trapezoid": (((0.0, 0.5),), ((1.0, 0.5),)),
    "midpoint": (((0.5, 0.5),), ((0.5, 0.5),)),
    "left": (((0.0, 1.0),), ()),
    "right": ((), ((1.0, 1.0),)),
}
"""The force quadratures of the discrete Lagrangians (:func:`discrete_forces`): the nodes of the
virtual work on a step, as (fraction of the step, weight) pairs for $f^-$ and for $f^+$."""


class Drive(eqx.Module):
    """The inputs of a driven system, and the step being taken.

    Arguments:
        values: per-step inputs, shape (K, m): $u(t) = u_k$ on $[t_0 + kh, t_0 + (k+1)h)$
            (zero-order hold; steps past the last value keep it). None with `signal` or no inputs.
        signal: a function `u(t)` -> (m,) instead of `values` (evaluated at the nodes of the
            force quadrature).
        t0: the time of step 0.
        h: the step of the control grid (the run's step).
        t: the time at the start of the step or sub-step being taken (set by the loop; shifted
            by compositions for their sub-steps).
        held: the held input $u_k$ of the step being taken (set by the loop from `values`; a
            float array, so that the implicit steps' derivatives reach it, where an integer step
            index inside a solve's residual could not be differentiated through).
        inputs: m, the number of inputs.
    """

    values: jax.Array | None
    signal: Callable[..., Any] | None
    t0: jax.Array
    h: jax.Array
    t: jax.Array
    held: jax.Array
    inputs: int = eqx.field(static=True)

    @staticmethod
    def make(values=None, signal=None, *, t0=0.0, h=1.0, inputs: int = 0) -> "Drive":
        """A drive from per-step `values` or a `signal`, on the grid $t_0 + kh$, at step 0."""
        t0 = jnp.asarray(t0, jnp.float64)
        values = None if values is None else jnp.asarray(values, jnp.float64)
        held = jnp.zeros((int(inputs),), jnp.float64) if values is None else values[0]
        return Drive(values, signal, t0, jnp.asarray(h, jnp.float64), t0, held, int(inputs))

    def at_step(self, k) -> "Drive":
        """The drive at step k: `t = t0 + k h` and the held input $u_k$ set."""
        k = jnp.asarray(k, jnp.int32)
        held = self.held if self.values is None else self.values[jnp.clip(k, 0, self.values.shape[0] - 1)]
        return Drive(self.values, self.signal, self.t0, self.h, self.t0 + k.astype(self.t0.dtype) * self.h, held,
                     self.inputs)

    def shifted(self, dt) -> "Drive":
        """The same step, its start moved by `dt` (the sub-steps of a composition)."""
        return Drive(self.values, self.signal, self.t0, self.h, self.t + dt, self.held, self.inputs)

    def u(self, t):
        """The input at time `t` during the current step: $u_k$ (held values), `signal(t)`, or an
        empty vector when the system has no inputs."""
        if self.signal is not None:
            return jnp.asarray(self.signal(t), jnp.float64).reshape(self.inputs)
        return self.held

    def u_continuous(self, t):
        """The input at any time `t` (the continuous reference): the held value of the step that
        contains t, or `signal(t)`."""
        if self.signal is not None or self.values is None:
            return self.u(t)
        # the step whose start t0 + k h is the last at or before t, on the grid of the reference's
        # jump times (a floor of (t - t0)/h rounds a node's own time into the step before it)
        K = self.values.shape[0]
        starts = self.t0 + self.h * jnp.arange(1, K, dtype=self.t0.dtype)
        k = jnp.searchsorted(starts, t, side="right")
        return self.values[jnp.clip(k, 0, K - 1)]


def discrete_forces(system, b0, z, h, rule: str = "trapezoid"):
    """The discrete forces $(f^-_k, f^+_k)$ of the step from `b0` with unknowns `z` (module
    docstring): the virtual work of $F$ by the quadrature `rule` (a key of :data:`FORCE_RULES`),
    at the step's velocity $z/h$ and the drive's input and time (`system.drive`)."""
    b1, bm, vel = system.space.step_points(b0, z, h)
    points = {0.0: b0, 0.5: bm, 1.0: b1}
    t = system.drive.t

    def work(nodes):
        total = jnp.zeros_like(z)
        for theta, weight in nodes:
            total = total + (weight * h) * system.external_force(points[theta], vel, t + theta * h)
        return total

    minus, plus = FORCE_RULES[rule]
    return work(minus), work(plus)


class InputForce(eqx.Module):
    """A force linear in the inputs, $F = B u$: input j pushes along velocity components with
    gains (:func:`input_force`). A callable `F(*args, v, u, t)` for any system (the base point's
    arguments are ignored).

    Arguments:
        B: the (N, m) input matrix.
    """

    B: jax.Array

    def __call__(self, *args):
        # (..., v, u, t), or (..., v, u, t, args) on a system with named parameters (a dict)
        u = args[-3] if isinstance(args[-1], dict) else args[-2]
        return self.B @ u


def input_force(system, gains) -> tuple[InputForce, int, tuple[str, ...]]:
    """The force $F = Bu$ of actuators that act along named velocity components, for
    `system.with_force(F, inputs=m)` and the problem files of `gni control` and `gni fit`.

    Arguments:
        system: the System (its velocity names).
        gains: a mapping `{input name: {velocity name: gain}}` (ordered: the inputs' order), e.g.
            `{"torque": {"dtheta": 1.0}}` for a torque on the heading of the Chaplygin sleigh, or
            `{"ax": {"dx": -1.0}, "ay": {"dy": -1.0}}` for the acceleration of the plate under a
            rolling ball of unit mass (the inertial force $-m a$ in the plate's frame).

    Returns:
        `(F, m, input_names)`.

    Raises:
        InputError: (naming `inputs.<input name>`, the key of a problem file) unknown velocity
            names, no inputs, names that are not strings, gains that are not finite numbers (a
            string or a boolean is not one), or an input whose gains are all zero (it would act on
            nothing: the problem's derivatives with respect to it vanish, and the solver's
            Gauss-Newton systems are singular).
    """
    import math
    import numbers

    import numpy as np

    from .errors import InputError

    if not hasattr(gains, "items") or not gains:
        raise InputError("inputs: expected a mapping {input name: {velocity name: gain}} with at least one input, "
                         f"got {gains!r}")
    bad = [k for k in gains if not isinstance(k, str) or not k]
    if bad:
        raise InputError(f"inputs: input names must be non-empty strings, got {bad[0]!r}")
    names = tuple(gains)
    index = {c: i for i, c in enumerate(system.velocities)}
    B = np.zeros((system.dim, len(names)))
    for j, (name, row) in enumerate(gains.items()):
        key = _key("inputs", name)
        if not hasattr(row, "items") or not row:
            raise InputError(f"{key}: expected a mapping {{velocity name: gain}} with at least one entry, got {row!r}")
        for vel, gain in row.items():
            if vel not in index:
                raise InputError(f"{key}: unknown velocity {vel!r}; expected one of {', '.join(system.velocities)}")
            # a real scalar of Python, NumPy or JAX; a bool is an int to Python and a string converts
            # under float(): neither is a gain
            kind = getattr(getattr(gain, "dtype", None), "kind", None)
            real = kind in ("i", "u", "f") and np.ndim(gain) == 0 if kind is not None else (
                isinstance(gain, numbers.Real) and not isinstance(gain, bool))
            if not real:
                raise InputError(f"{key}: the gain of {vel!r} must be a number, got {type(gain).__name__} {gain!r}")
            g = float(gain)
            if not math.isfinite(g):
                raise InputError(f"{key}: the gain of {vel!r} must be finite, got {gain!r}")
            B[index[vel], j] = g
        if not np.any(B[:, j]):
            raise InputError(f"{key}: every gain is zero: the input would act on nothing (give a nonzero gain, or "
                             "leave the input out)")
    return InputForce(jnp.asarray(B)), len(names), names


def _key(section: str, name: str) -> str:
    """`section.name` as a TOML key (the name quoted where it is not a bare key)."""
    import json
    import re

    return f"{section}.{name}" if re.fullmatch(r"[A-Za-z0-9_-]+", name) else f"{section}.{json.dumps(name)}"


def drive(system, controls, h, t0, steps):
    """The forced `system` with its inputs attached (a :class:`gnipy.forcing.Drive` on the grid
    t0 + k h); the controls' shape checked where it is concrete (their number against the steps:
    :func:`check_forced_run`)."""
    m = system.inputs
    values = signal = None
    if controls is None:
        if m:
            raise InputError(f"controls: the system has {m} input{'s' if m > 1 else ''} u; give controls= "
                             f"(an array (steps, {m}) of per-step values, or a function u(t))")
    elif callable(controls) and not hasattr(controls, "shape"):
        if not m:
            raise InputError("controls: the system's force takes no inputs (inputs=0)")
        signal = controls
    else:
        if not m:
            raise InputError("controls: the system's force takes no inputs (inputs=0)")
        values = _control_values(controls, m)
    return system.driven(Drive.make(values, signal, t0=t0, h=h, inputs=m))


def _control_values(controls, m: int):
    """Per-step controls as an array (steps, m) of float64: a NumPy array where they are concrete
    (checked: real, finite, at least one step), traced ones as they are (their shape checked)."""
    if isinstance(controls, jax.core.Tracer):
        values = jnp.asarray(controls, jnp.float64)
        if values.ndim == 1 and m == 1:
            values = values[:, None]
        if values.ndim != 2 or values.shape[1] != m:
            raise InputError(f"controls: expected shape (steps, {m}), got {tuple(values.shape)}")
        return values
    arr = np.asarray(controls)
    if arr.dtype == object or not np.issubdtype(arr.dtype, np.number) or np.iscomplexobj(arr):
        raise InputError(f"controls: expected a real array (steps, {m}) or a function u(t), got {arr.dtype}")
    if arr.ndim == 1 and m == 1:
        arr = arr[:, None]
    if arr.ndim != 2 or arr.shape[1] != m or arr.shape[0] < 1:
        raise InputError(f"controls: expected shape (steps, {m}), got {np.shape(controls)}")
    if not np.all(np.isfinite(arr)):
        raise InputError("controls: contains NaN or infinite values")
    return arr.astype(np.float64)


def check_forced_run(system, h, total_steps):
    """A forced run's checks once its length is known: forward in time, and enough per-step controls."""
    if h < 0:
        raise InputError("h: a forced system runs forward in time (h > 0); its force is not reversible in general")
    values = system.drive.values
    if values is not None and values.shape[0] < total_steps:
        raise InputError(f"controls: {values.shape[0]} per-step values for {total_steps} steps")
