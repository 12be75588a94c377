"""Measurements that choose each zoo model's default method (`gni models` shows the choice).

For every model and every method that applies to it, one long run (h = 0.01, T = 200, about 2000
saved nodes) against the continuous reference (Dopri8 at tolerance 1e-12, at the same times):

- the largest position error $\\max_k |q_k - q^{\\mathrm{ref}}(t_k)|$ (with the orientation
  $\\|R_k - R^{\\mathrm{ref}}(t_k)\\|$ on $\\mathbb{R}^n \\times G$),
- the largest drift of the energy (where the motion conserves it) and of the model's registered
  invariants, relative to their size,
- the run-time verdicts of :mod:`gnipy.diagnostics` (hidden momentum, energy drift) and solver
  failures.

Rule: a method qualifies when the run completes, raises no warning, and keeps every invariant to
1e-2 relative; the default is the qualifying method with the smallest position error, where
methods within a factor 1.5 of the best count as tied and the tie goes to the one that keeps the
constraints to round-off (the GNI family, mp; dla's reported velocity misses them by O(h)), then
to the higher order, then to a method whose failure modes the run-time diagnostics watch (the GNI
family's hidden momentum), then to fewer Newton iterations per step. Methods are compared at the
same h (euler-ab takes two half steps per step). When none qualifies, the default is
the continuous reference itself. The registry holds the outcome
(`ModelSpec.default_method`, `ModelSpec.default_reason`); `python -m gnipy.experiments.method_choice`
reruns the measurements and prints the table (about 5 minutes on 2 cores) that
docs/user-guide/models.md shows.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np

__all__ = ["MethodMeasurement", "measure_model", "choose", "main", "H", "T_FINAL"]

H = 0.01
T_FINAL = 200.0
NODES = 2000
INVARIANT_TOL = 1e-2


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


def _invariant_values(spec, params, sol):
    """Each registered invariant along the run, name -> (T,)."""
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    R = None if sol.R is None else np.asarray(sol.R)
    out = {}
    for name, f in spec.invariants.items():
        vals = []
        for k in range(len(q)):
            try:
                vals.append(float(f(params, q[k], v[k])))
            except TypeError:
                vals.append(float(f(params, q[k], v[k], R[k])))
        out[name] = np.asarray(vals)
    return out


def _drift(values, reference_values) -> float:
    """max |I_k − I_0| relative to the invariant's size along the reference, or absolute (to 1e-6)
    for an invariant that stays near zero (e.g. the rolling ball's spin ω₃ = 0)."""
    scale = max(float(np.max(np.abs(reference_values))), 1e-6)
    if not np.all(np.isfinite(values)):
        return math.inf
    return float(np.max(np.abs(values - values[0])) / scale)


def measure_model(name: str, *, h: float = H, t_final: float = T_FINAL, nodes: int = NODES,
                  methods=None, progress=None) -> list[MethodMeasurement]:
    """Measure every applicable method on the zoo model `name` (see the module docstring)."""
    import gnipy
    from gnipy.registry import get_model

    spec = get_model(name)
    params = spec.resolve_params()
    system = spec.system()
    steps = round(t_final / h)
    every = max(1, steps // nodes)
    ref = gnipy.simulate(system, "reference", h=h, steps=steps, save_every=every)
    ref_inv = _invariant_values(spec, params, ref)
    out = []
    for method in methods or [m for m in gnipy.method_names() if m != "reference"]:
        try:
            sol = gnipy.simulate(system, method, h=h, steps=steps, save_every=every, throw=False)
        except gnipy.MethodError:
            continue
        if progress is not None:
            progress(name, method)
        good = len(sol.t)
        err = np.max(np.abs(np.asarray(sol.q) - np.asarray(ref.q[:good])), initial=0.0)
        if sol.R is not None:
            err = max(err, float(np.max(np.abs(np.asarray(sol.R) - np.asarray(ref.R[:good])))))
        drift = 0.0
        if sol.energy_invariant:
            drift = _drift(np.asarray(sol.energy), np.asarray(ref.energy))
        for k, vals in _invariant_values(spec, params, sol).items():
            if np.all(np.isfinite(ref_inv[k])):
                drift = max(drift, _drift(vals, ref_inv[k]))
        its = np.asarray(sol.iterations)
        order = gnipy.get_method(method).order or 0  # the method's statement of its order (None: unknown)
        residual = float(np.max(np.abs(np.asarray(sol.constraint_residual)), initial=0.0))
        out.append(MethodMeasurement(method, float(err) if sol.result == 0 else math.inf, drift,
                                     tuple(sol.warnings()), sol.result != 0, float(its[0]) / max(sol.steps, 1),
                                     residual, int(order), sol.hidden_momentum is not None))
    return out


def choose(measurements: list[MethodMeasurement]) -> tuple[str, str]:
    """`(method, reason)` by the rule of the module docstring."""
    ok = [m for m in measurements if m.qualifies]
    if not ok:
        bad = ", ".join(f"{m.method} ({'failed' if m.failed else 'warning' if m.warnings else f'drift {m.invariant_drift:.1e}'})"
                        for m in measurements)
        return "reference", (f"no discrete method qualifies at h = {H:g} over T = {T_FINAL:g}: {bad}; "
                             "the continuous reference is the default")
    best = min(ok, key=lambda m: m.position_error)
    near = [m for m in ok if m.position_error <= 1.5 * best.position_error]
    choice = min(near, key=lambda m: (not m.exact_constraints, -m.order, not m.diagnosed, m.iterations,
                                      m.position_error))
    others = sorted((m for m in ok if m is not choice), key=lambda m: m.position_error)[:2]
    failing = [m.method for m in measurements if not m.qualifies]
    reason = (f"best error against the reference among the methods without warnings, ties within a factor 1.5 "
              f"broken by the rule (h = {H:g}, T = {T_FINAL:g}): "
              f"{choice.position_error:.1e}, invariants to {choice.invariant_drift:.1e}")
    if others:
        reason += "; next " + ", ".join(f"{m.method} {m.position_error:.1e}" for m in others)
    if failing:
        reason += "; disqualified: " + ", ".join(failing)
    return choice.method, reason


def main(argv=None) -> None:
    """Measure every model, print the table and each model's choice (Markdown)."""
    import gnipy

    names = list(argv if argv is not None else sys.argv[1:]) or gnipy.model_names()
    print("| model | method | position error | invariant drift | constraint residual | verdict |")
    print("|---|---|---|---|---|---|")
    choices = {}
    for name in names:
        ms = measure_model(name)
        for m in ms:
            verdict = "failed" if m.failed else ("warning" if m.warnings else "ok")
            print(f"| {name} | {m.method} | {m.position_error:.2e} | {m.invariant_drift:.2e} | "
                  f"{m.constraint_residual:.1e} | {verdict} |", flush=True)
        choices[name] = choose(ms)
    print()
    for name, (method, reason) in choices.items():
        print(f"- `{name}`: **{method}** — {reason}")


if __name__ == "__main__":
    main()
