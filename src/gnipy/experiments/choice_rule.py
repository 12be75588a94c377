"""The rule that chooses each zoo model's default method (`gni models` shows the choice), from the
measurements of the method atlas (:mod:`gnipy.experiments.atlas`; what is measured, and the commands
that run it: :mod:`gnipy.experiments.method_choice`): one :class:`MethodMeasurement` per method.

Rule: a method qualifies when the run completes, raises no warning, and keeps every invariant to
1e-2 relative; the default is the qualifying method with the smallest position error, where
methods within a factor 1.5 of the best, or below `REFERENCE_FLOOR` (1e-9: the reference's own
error, measured against the exact solutions over T = 200, is up to 2.4e-10, on the knife edge),
count as tied and the tie goes to the one that keeps the
constraints to round-off (the GNI family, mp; dla's reported velocity misses them by O(h)), then
to the higher order, then to a method whose failure modes the run-time diagnostics watch (the GNI
family's hidden momentum), then to fewer Newton iterations per step. Methods are compared at the
same h (euler-ab takes two half steps per step). When none qualifies, the default is
the continuous reference itself.
"""

from __future__ import annotations

import dataclasses
import math

__all__ = ["MethodMeasurement", "choose", "H", "T_FINAL", "NODES", "INVARIANT_TOL", "REFERENCE_FLOOR"]

H = 0.01
T_FINAL = 200.0
NODES = 2000
INVARIANT_TOL = 1e-2
#: Position errors below this are at the reference's accuracy and count as tied (module docstring).
REFERENCE_FLOOR = 1e-9


@dataclasses.dataclass(frozen=True)
class MethodMeasurement:
    """One method on one model (see the module docstring).

    Attributes:
        method: the method name.
        position_error: the largest position (and orientation) error against the reference.
        invariant_drift: the largest relative drift of the energy (where conserved) and of the
            registered invariants.
        warnings: the run's warnings (empty when healthy).
        failed: whether a step failed.
        iterations: Newton iterations per step (mean).
        constraint_residual: the largest constraint residual of the reported velocities.
        order: the method's expected order (0 when unknown).
        diagnosed: whether the run carries the hidden-momentum diagnostic (the GNI family).
    """

    method: str
    position_error: float
    invariant_drift: float
    warnings: tuple[str, ...]
    failed: bool
    iterations: float
    constraint_residual: float = 0.0
    order: int = 0
    diagnosed: bool = False

    @property
    def exact_constraints(self) -> bool:
        """Whether the reported velocities satisfy the constraints to round-off (1e-10)."""
        return self.constraint_residual <= 1e-10

    @property
    def qualifies(self) -> bool:
        """Completed, no warning, invariants kept to `INVARIANT_TOL`."""
        return (not self.failed and not self.warnings and math.isfinite(self.position_error)
                and self.invariant_drift <= INVARIANT_TOL)


def choose(measurements: list[MethodMeasurement], *, h: float = H, t_final: float = T_FINAL,
           t_ref: float | None = None) -> tuple[str, str]:
    """`(method, reason)` by the rule of the module docstring, for measurements at step `h` over
    `t_final` (the error against the reference over t <= `t_ref`, default the whole run; the reason
    states them)."""
    where = f"h = {h:g}, T = {t_final:g}" + ("" if t_ref is None or t_ref >= t_final else f", error over t <= {t_ref:g}")
    ok = [m for m in measurements if m.qualifies]
    if not ok:
        bad = ", ".join(f"{m.method} ({'failed' if m.failed else 'warning' if m.warnings else f'drift {m.invariant_drift:.1e}'})"
                        for m in measurements)
        return "reference", (f"no discrete method qualifies ({where}): {bad}; "
                             "the continuous reference is the default")
    best = min(ok, key=lambda m: m.position_error)
    near = [m for m in ok if m.position_error <= max(1.5 * best.position_error, REFERENCE_FLOOR)]
    choice = min(near, key=lambda m: (not m.exact_constraints, -m.order, not m.diagnosed, m.iterations,
                                      m.position_error))
    others = sorted((m for m in ok if m is not choice), key=lambda m: m.position_error)[:2]
    failing = [m.method for m in measurements if not m.qualifies]
    reason = (f"best error against the reference among the methods without warnings, ties within a factor 1.5 "
              f"or below {REFERENCE_FLOOR:g} broken by the rule ({where}): "
              f"{choice.position_error:.1e}, invariants to {choice.invariant_drift:.1e}")
    if others:
        reason += "; next " + ", ".join(f"{m.method} {m.position_error:.1e}" for m in others)
    if failing:
        reason += "; disqualified: " + ", ".join(failing)
    return choice.method, reason
