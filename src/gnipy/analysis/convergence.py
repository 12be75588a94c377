"""Convergence studies: run methods at several step sizes, measure their errors against an exact
solution or the continuous reference, and fit their orders.

:func:`convergence_study` is the study behind `gni convergence`:

    >>> import gnipy
    >>> from gnipy.analysis import convergence_study
    >>> spec = gnipy.get_model("vertical-disk")
    >>> params = spec.resolve_params()
    >>> study = convergence_study(spec.build(params), ["gni-trapezoid"], spec.q0, spec.v0, t_final=1.0,
    ...                           steps=[10, 20, 40], exact=lambda q0, v0, t: spec.exact(params, q0, v0, t))
    >>> round(study.orders["gni-trapezoid"])
    2
    >>> study.expected["gni-trapezoid"]
    2

The expected order of each method is its `order` (the method states it; see
:class:`~gnipy.Integrator`); the fitted one is :func:`gnipy.analysis.fitted_order` on the points
above round-off.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import verdicts_reported_by_caller
from .orders import fit_points, fitted_order

__all__ = ["ConvergenceStudy", "convergence_study", "MEASURES", "REFERENCE_FLOOR"]

#: What a study measures: `q` (the configuration), `v` (the reported velocity) or `state` (the
#: larger of the two errors).
MEASURES = ("q", "v", "state")

#: The round-off level of errors against the continuous reference (Dopri8 at tolerance 1e-12),
#: relative to max(1, |state|).
REFERENCE_FLOOR = 1e-10

_REFERENCE = "continuous reference (Dopri8, tolerance 1e-12)"


@dataclasses.dataclass(frozen=True)
class ConvergenceStudy:
    """The result of :func:`convergence_study`: plain arrays and numbers.

    Attributes:
        methods: the method names, in the order given.
        steps: the step counts (ascending); the step sizes are :attr:`h` = t_final / steps.
        t_final: the final time.
        saves: the number of saved intervals: errors are the largest over the nodes
            t = k·t_final/saves, k = 0 … saves.
        measure: what `errors` holds: `"q"`, `"v"` or `"state"` (:data:`MEASURES`).
        yardstick: `"exact"` (the exact solution) or `"reference"` (the continuous reference).
        yardstick_description: the yardstick in words (e.g. `"exact solution"`).
        floor: the round-off level: errors at or below it are not used in the fits.
        errors: method → the measured errors, one per step count (NaN where the run failed).
        errors_q, errors_v: method → the errors of q and of v.
        orders: method → the fitted order (NaN with fewer than 2 points above `floor`).
        expected: method → its expected order (the method's `order`; None when not known).
        failures: `(method, h)` of the runs whose solve failed (their errors are NaN).
        seconds: the wall time of the runs (compilation included).
    """

    methods: tuple[str, ...]
    steps: tuple[int, ...]
    t_final: float
    saves: int
    measure: str
    yardstick: str
    yardstick_description: str
    floor: float
    errors: dict[str, np.ndarray]
    errors_q: dict[str, np.ndarray]
    errors_v: dict[str, np.ndarray]
    orders: dict[str, float]
    expected: dict[str, int | None]
    failures: tuple[tuple[str, float], ...]
    seconds: float

    @property
    def h(self) -> np.ndarray:
        """The step sizes, t_final / steps."""
        return self.t_final / np.asarray(self.steps, dtype=float)

    def used_in_fit(self, method: str) -> np.ndarray:
        """Which of the method's errors the fitted order uses (finite and above :attr:`floor`)."""
        return fit_points(self.h, self.errors[method], self.floor)

    def rows(self) -> list[dict]:
        """One row per method and step size: `method`, `steps`, `h`, `t_final`, `error`, `error_q`,
        `error_v`, `used_in_fit` (0/1), `fitted_order`, `expected_order` ("" when not known),
        `yardstick` and `measure` (the columns of `gni convergence`'s convergence.csv)."""
        rows = []
        for name in self.methods:
            used = self.used_in_fit(name)
            expected = self.expected[name]
            for i, n in enumerate(self.steps):
                rows.append({
                    "method": name, "steps": int(n), "h": float(self.h[i]), "t_final": self.t_final,
                    "error": float(self.errors[name][i]), "error_q": float(self.errors_q[name][i]),
                    "error_v": float(self.errors_v[name][i]), "used_in_fit": int(used[i]),
                    "fitted_order": self.orders[name], "expected_order": "" if expected is None else expected,
                    "yardstick": self.yardstick, "measure": self.measure,
                })
        return rows


def convergence_study(
    system,
    methods: Sequence,
    q0,
    v0,
    *,
    t_final: float,
    steps: Sequence[int],
    R0=None,
    measure: str = "q",
    exact: Callable | None = None,
    saves: int = 1,
    project_v0: bool = False,
    floor: float | None = None,
    progress: Callable[[int, int, str], None] | None = None,
) -> ConvergenceStudy:
    """Run each method at each step count to `t_final`, measure its error, and fit its order.

    Every run saves only the nodes t = k·t_final/saves (one compilation per method serves every
    step size: the step count and h are traced). The error of a run is the largest max-norm
    difference from the yardstick over those nodes: the exact solution when `exact` gives one,
    else the continuous reference (:class:`~gnipy.ContinuousReference`, Dopri8 at tolerance
    1e-12). The fitted order is :func:`~gnipy.analysis.fitted_order` over the points above
    `floor`.

    Arguments:
        system: the :class:`~gnipy.System`.
        methods: method names (see :func:`gnipy.method_names`, not `"reference"`) or integrator
            objects; the results are keyed by their names, which must differ.
        q0, v0: the initial configuration and velocity.
        t_final: the final time.
        steps: the step counts (at least 2 distinct ones, each a multiple of `saves`).
        R0: the initial orientation on $\\mathbb{R}^n \\times G$.
        measure: `"q"`, `"v"` or `"state"` (:data:`MEASURES`).
        exact: `exact(q0, v0, t) -> (q, v)`, the exact solution at the times `t` (arrays (T, n)
            and (T, N)), or None for the model's parameters without a closed form; it receives
            the initial velocity the runs use (projected with `project_v0`).
        saves: the number of saved intervals the error is measured over (1: at t_final only).
        project_v0: project `v0` onto the constraints instead of raising when it violates them.
        floor: the round-off level (default: 2·√N·ε against an exact solution, N the largest
            step count, since the round-off of N steps grows like a random walk; 1e-10 against the
            reference; both times max(1, |state|)).
        progress: called as `progress(runs_done, runs_total, what)` before each run (`what`
            describes it) and once at the end (`what` empty); the reference, when it is needed,
            is one of the runs.

    Returns:
        A :class:`ConvergenceStudy`.

    Raises:
        InputError: bad arguments or initial condition (the message names the argument).
        MethodError: a method that cannot integrate this system (checked before anything runs).
    """
    from ..errors import MethodError

    counts, T = _check_arguments(system, measure=measure, saves=saves, steps=steps, t_final=t_final)
    b0, v0_used = system.check(q0, v0, R0=R0, project_v0=project_v0)
    v0_used = np.asarray(v0_used, dtype=float)
    resolved = _resolve(methods, system, b0, MethodError)

    times = np.linspace(0.0, T, saves + 1)
    truth = exact(q0, v0_used, times) if exact is not None else None
    runs = _Runs(progress, len(resolved) * len(counts) + (truth is None))
    t_start = time.perf_counter()
    q_true, v_true, yardstick, description, floor_rel = _yardstick(system, truth, q0, v0_used, R0, T, saves, counts,
                                                                    runs)
    if floor is None:
        scale = max(1.0, float(np.max(np.abs(np.concatenate([q_true.ravel(), v_true.ravel()])), initial=0.0)))
        floor = floor_rel * scale

    errors, errors_q, errors_v, failures = {}, {}, {}, []
    for name, method in resolved.items():
        errors_q[name], errors_v[name] = _method_errors(system, name, method, q0, v0_used, R0, T, saves, counts,
                                                        (q_true, v_true), runs, failures)
        errors[name] = {"q": errors_q[name], "v": errors_v[name],
                        "state": np.maximum(errors_q[name], errors_v[name])}[measure]
    runs.report("")
    hs = T / np.asarray(counts, dtype=float)
    return ConvergenceStudy(
        methods=tuple(resolved), steps=tuple(counts), t_final=T, saves=saves, measure=measure,
        yardstick=yardstick, yardstick_description=description, floor=float(floor), errors=errors,
        errors_q=errors_q, errors_v=errors_v,
        orders={name: fitted_order(hs, errors[name], floor) for name in resolved},
        expected={name: _order(m) for name, m in resolved.items()},
        failures=tuple(failures), seconds=time.perf_counter() - t_start,
    )


def _check_arguments(system, *, measure, saves, steps, t_final) -> tuple[list[int], float]:
    """`(counts, T)`: the distinct step counts, ascending, and the final time, with `measure` and
    `saves` checked (InputError naming the argument)."""
    from ..errors import InputError
    from ..inputs import refuse_text_or_bool

    if measure not in MEASURES:
        raise InputError(f"measure: expected one of {', '.join(MEASURES)}, got {measure!r}")
    if measure == "q" and not system.coordinates:
        raise InputError(f"measure: {system.name!r} has no coordinates q (it lives on a group): measure v or state")
    if isinstance(saves, bool) or not isinstance(saves, int) or saves < 1:
        raise InputError(f"saves: expected a positive integer, got {saves!r}")
    try:
        given = list(steps)
    except TypeError:
        raise InputError(f"steps: expected a sequence of step counts, got {steps!r}") from None
    if not all(isinstance(n, (int, np.integer)) and not isinstance(n, (bool, np.bool_)) for n in given):
        raise InputError(f"steps: expected whole numbers of steps, got {given!r}")
    counts = sorted({int(n) for n in given})
    if len(counts) < 2 or counts[0] < 1:
        raise InputError(f"steps: need at least 2 distinct positive step counts, got {given!r}")
    if any(n % saves for n in counts):
        raise InputError(f"steps: each step count must be a multiple of saves = {saves}, got {counts}")
    refuse_text_or_bool("t_final", t_final, "a positive finite number")
    try:
        T = float(t_final)
    except (TypeError, ValueError):
        raise InputError(f"t_final: expected a positive finite number, got {t_final!r}") from None
    if not (math.isfinite(T) and T > 0):
        raise InputError(f"t_final: expected a positive finite number, got {t_final!r}")
    return counts, T


class _Runs:
    """The runs of a study as they go: `progress(runs_done, runs_total, what)`, when given."""

    def __init__(self, progress: Callable[[int, int, str], None] | None, total: int):
        self.progress, self.total, self.done = progress, total, 0

    def report(self, what: str) -> None:
        if self.progress is not None:
            self.progress(self.done, self.total, what)


def _yardstick(system, truth, q0, v0_used, R0, T: float, saves: int, counts: list[int], runs: _Runs) -> tuple:
    """`(q_true, v_true, yardstick, description, floor_rel)`: the yardstick at the saved nodes (the
    exact solution `truth`, or the continuous reference, run here), its names and its relative
    round-off level."""
    from ..simulate import simulate

    if truth is not None:
        q_true, v_true = np.asarray(truth[0], dtype=float), np.asarray(truth[1], dtype=float)
        return q_true, v_true, "exact", "exact solution", 2.0 * math.sqrt(max(counts)) * float(np.finfo(np.float64).eps)
    runs.report(_REFERENCE)
    ref = simulate(system, "reference", q0, v0_used, R0=R0, h=T / saves, steps=saves)
    runs.done += 1
    return np.asarray(ref.q), np.asarray(ref.v), "reference", _REFERENCE, REFERENCE_FLOOR


def _method_errors(system, name: str, method, q0, v0_used, R0, T: float, saves: int, counts: list[int], true,
                   runs: _Runs, failures: list) -> tuple[np.ndarray, np.ndarray]:
    """The errors of q and of v of `method` at each step count against the yardstick `true`
    (`(q, v)` at the saved nodes); a failed run's are NaN, and `(name, h)` is added to `failures`."""
    from ..simulate import simulate

    q_true, v_true = true
    eq, ev = [], []
    for i, n in enumerate(counts):
        h = T / n
        runs.report(f"{name}, h = {h:.4g}" + (" (compiling)" if i == 0 else ""))
        with verdicts_reported_by_caller():  # the largest steps may fail: the study reports its points
            sol = simulate(system, method, q0, v0_used, R0=R0, h=h, steps=n, save_every=n // saves,
                           throw=False)
        e_q = e_v = float("nan")
        if sol.result == 0:
            q, v = np.asarray(sol.q), np.asarray(sol.v)
            e_q = float(np.max(np.abs(q - q_true), initial=0.0))
            e_v = float(np.max(np.abs(v - v_true), initial=0.0))
        if not (math.isfinite(e_q) and math.isfinite(e_v)):
            failures.append((name, h))
            e_q = e_v = float("nan")
        eq.append(e_q)
        ev.append(e_v)
        runs.done += 1
    return np.array(eq), np.array(ev)


def _resolve(methods, system, b0, MethodError) -> dict:
    """`{name: prepared method}`: each method checked against the system before any of them runs."""
    from ..integrators.base import Integrator
    from ..methods import get_method

    if isinstance(methods, str):
        methods = [methods]
    out = {}
    for m in methods:
        m = get_method(m) if isinstance(m, str) else m
        name = getattr(m, "name", None)
        if name == "reference":
            raise MethodError("methods: the continuous reference is the yardstick of the study, not a method to study")
        if not isinstance(m, Integrator):
            raise MethodError(f"methods: expected method names or integrators, got {type(m).__name__}")
        if name in out:
            raise MethodError(f"methods: {name!r} given twice")
        m.validate(system, b0)
        out[name] = m.prepare(system, b0)
    if not out:
        raise MethodError("methods: give at least one method")
    return out


def _order(method) -> int | None:
    order = method.order
    return order if isinstance(order, int) and not isinstance(order, bool) else None
