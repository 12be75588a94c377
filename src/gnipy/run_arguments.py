"""The arguments that say how long a run is and where it starts, checked once for every driver
(:func:`gnipy.simulate`, its transformed and batched runs, streamed runs, sweeps, control): the
step size, the number of steps or the final time (:func:`resolve_run`), the initial time, and the
systems' documented initial conditions (:func:`default_initial_condition`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import InputError
from .inputs import refuse_text_or_bool
from .saveat import GRID_RTOL
from .system import System

__all__ = ["MAX_STEPS", "MAX_TOTAL_STEPS", "MIN_STEP_SIZE", "real_argument", "whole_steps", "resolve_run",
           "resolve_steps", "default_initial_condition", "member_initial_conditions"]

#: Most steps in one `simulate` call (the compiled loop counts steps in int32).
MAX_STEPS = 2**31 - 2

#: The most steps of any run, streamed ones included (t = t0 + k h needs k exact in float64).
MAX_TOTAL_STEPS = 2**53

#: The smallest step size accepted: the smallest normal float64 (below it, precision is lost).
MIN_STEP_SIZE = float(np.finfo(np.float64).tiny)


def real_argument(name: str, x, *, positive: bool) -> float:
    """`x` (a run's `h`, `t0` or `t_final`) as a finite float, positive when `positive`;
    :class:`InputError` naming `name` for a string, a boolean, a complex number, what `float()`
    refuses, a value that is not finite, or one not positive when it must be."""
    refuse_text_or_bool(name, x, f"a {'positive ' if positive else ''}number")
    if isinstance(x, (complex, np.complexfloating)) or (hasattr(x, "dtype") and np.iscomplexobj(x)):
        raise InputError(f"{name}: expected a {'positive ' if positive else ''}real number, got {x!r}")
    try:
        value = float(x)
    except (TypeError, ValueError, OverflowError) as e:
        raise InputError(f"{name}: expected a {'positive ' if positive else ''}number, got {x!r}") from e
    if not math.isfinite(value) or (positive and value <= 0):
        raise InputError(f"{name}: must be a {'positive ' if positive else ''}finite number, got {x!r}")
    return value


def whole_steps(steps) -> int:
    """`steps` as an int from 1 to :data:`MAX_TOTAL_STEPS` (a whole float such as `10.0` is
    accepted); :class:`InputError` naming `steps` otherwise."""
    if isinstance(steps, bool) or isinstance(steps, (complex, np.complexfloating)):
        raise InputError(f"steps: must be a positive integer, got {steps!r}")
    try:
        whole = int(steps) == steps
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"steps: must be a positive integer, got {steps!r}") from None
    if not whole or steps < 1:
        raise InputError(f"steps: must be a positive integer, got {steps!r}")
    if steps > MAX_TOTAL_STEPS:
        raise InputError(
            f"steps: {int(steps)} steps is more than any run can take (at most {MAX_TOTAL_STEPS:.3g}: the "
            "step index must stay exact in float64)"
        )
    return int(steps)


def resolve_run(h, steps=None, t_final=None, t0: float = 0.0, *, shorten: bool = True,
                backward: bool = False) -> tuple[float, int, float]:
    """Validate `h` and exactly one of `steps`, `t_final` (the final time); return `(h, steps,
    partial)`: the number of full steps of h and the shortened last step as a fraction of h (0
    when `t_final - t0` is a whole number of steps to within 1e-9 relative). With `shorten=False`
    a fraction is refused with an error that says how to choose h or t_final. With `backward=True`
    a negative h is allowed (a run backward in time, `t_final` before `t0`)."""
    h = real_argument("h", h, positive=not backward)
    if h == 0:
        raise InputError("h: must be nonzero (h > 0 runs forward in time, h < 0 backward), got 0")
    if abs(h) < MIN_STEP_SIZE:
        raise InputError(
            f"h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision (subnormal numbers; "
            "the time t0 + k h and the momenta divided by h would be meaningless)"
        )
    if (steps is None) == (t_final is None):
        raise InputError("steps/t_final: give exactly one of steps and t_final")
    if steps is not None:
        return h, whole_steps(steps), 0.0
    t_final = real_argument("t_final", t_final, positive=False)
    span = t_final - t0
    if span * h <= 0:
        raise InputError(f"t_final: must be {'after' if h > 0 else 'before'} t0 = {t0!r} for h = {h!r}, "
                         f"got {t_final!r}")
    ratio = span / h
    if not math.isfinite(ratio) or ratio > MAX_TOTAL_STEPS:
        raise InputError(
            f"t_final: {span!r} / h = {ratio:.3g} steps, more than any run can take "
            f"(at most {MAX_TOTAL_STEPS:.3g}); choose a larger h or an earlier t_final"
        )
    n = round(ratio)
    if n >= 1 and abs(n - ratio) <= GRID_RTOL * ratio:
        return h, n, 0.0
    full = math.floor(ratio)
    if not shorten:
        up = full + 1
        raise InputError(
            f"t_final: t_final - t0 = {span!r} is not a whole number of steps of h = {h!r} ({ratio:.6g} steps); "
            f"choose h = {span / up!r} ({up} steps) or t_final = {t0 + up * h!r}"
        )
    if full < 1:
        raise InputError(f"t_final: the run {span!r} is shorter than one step of h = {h!r}; choose a smaller h")
    return h, full, ratio - full


def resolve_steps(h, steps=None, t_final=None) -> tuple[float, int]:
    """Validate `h` and exactly one of `steps`, `t_final`; return `(h, steps)`, where `t_final`
    (measured from 0) must be a whole number of steps of `h` to within 1e-9 relative (the error
    says how to choose otherwise). For runs saved in chunks (streamed runs, sweeps)."""
    h, steps, _ = resolve_run(h, steps, t_final, 0.0, shorten=False)
    return h, steps


def default_initial_condition(system: System | Sequence[System], q0, v0, R0):
    """`(q0, v0, R0)` with the system's documented defaults filling what is None; for a sequence of
    systems (a parameter batch), each member's own defaults (see :func:`member_initial_conditions`)."""
    if isinstance(system, (list, tuple)):
        return member_initial_conditions(system, q0, v0, R0)
    if q0 is None and system.n == 0:
        q0 = ()
    if q0 is None or v0 is None:
        if system.defaults is None:
            raise InputError(f"q0/v0: the system {system.name!r} has no default initial condition; give q0 and v0")
        q0 = system.defaults[0] if q0 is None else q0
        v0 = system.defaults[1] if v0 is None else v0
        if R0 is None and len(system.defaults) > 2:
            R0 = system.defaults[2]
    return q0, v0, R0


def member_initial_conditions(systems: Sequence[System], q0, v0, R0):
    """`(q0, v0, R0)` for a batch of systems: each of q0, v0, R0 that is None is filled with every
    member's own documented default (its `System.defaults`, built for its parameter values, so on
    its own constraints), stacked along a leading member axis; what is given is returned as given."""
    filled = [default_initial_condition(s, q0, v0, R0) for s in systems]

    def stacked(j):
        return np.stack([np.asarray(ic[j], dtype=np.float64) for ic in filled])

    R_missing = R0 is None and any(ic[2] is None for ic in filled)
    return (stacked(0) if q0 is None else filled[0][0], stacked(1) if v0 is None else v0,
            R0 if R0 is not None or R_missing else stacked(2))
