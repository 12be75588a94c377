"""The measurements behind each zoo model's default method (`gni models` shows the choice), and the
command that makes them.

The measurements are the method atlas's (:mod:`gnipy.experiments.atlas`, `gni atlas`): for every
model and every method that applies to it, one long run at h = 0.01 (10⁵ or 10⁶ steps) against
the continuous reference (Dopri8 at tolerance 1e-12, at the same times, up to T = 200):

- the largest position error $\\max_k |q_k - q^{\\mathrm{ref}}(t_k)|$ over t <= 200 (with the
  orientation $\\|R_k - R^{\\mathrm{ref}}(t_k)\\|$ on $\\mathbb{R}^n \\times G$),
- the largest drift of the energy (where the motion conserves it) and of the model's registered
  invariants over the whole run, relative to their size,
- the run-time verdicts of :mod:`gnipy.diagnostics` (hidden momentum, energy drift) over the whole
  run, and solver failures.

The rule that chooses among them is :mod:`gnipy.experiments.choice_rule` (:func:`choose`, re-exported
here). The registry holds the outcome
(`ModelSpec.default_method`, `ModelSpec.default_reason`, recorded in
:mod:`gnipy.models.default_methods`). The atlas is the one source of the record: `gni atlas --out
DIR` writes `DIR/default_methods.py` (its recommendations; copy it over
src/gnipy/models/default_methods.py) beside its report, and `python -m
gnipy.experiments.method_choice [MODEL ...]` runs the same full measurement and prints the table,
the choices and that module (about 30 minutes on 2 cores for every model).
:func:`measure_model` measures one model over a single run of `t_final` (the atlas's
measurement with the reference horizon the whole run).
"""

from __future__ import annotations

import sys

from .atlas import Plan, invariant_functions, invariants_along, measure_model as atlas_model, run_atlas
from .atlas_report import default_methods_source
from .choice_rule import H, INVARIANT_TOL, NODES, REFERENCE_FLOOR, T_FINAL, MethodMeasurement, choose

__all__ = ["MethodMeasurement", "measure_model", "registered_invariants_along", "choose", "main", "H", "T_FINAL",
           "REFERENCE_FLOOR", "INVARIANT_TOL", "NODES"]


def registered_invariants_along(spec, params, sol):
    """Each registered invariant of the model `spec` (with parameters `params`) along the run `sol`,
    name -> (T,) (computed as the atlas does)."""
    return invariants_along(invariant_functions(spec, params), sol)


def measure_model(name: str, *, h: float = H, t_final: float = T_FINAL, nodes: int = NODES,
                  methods=None, progress=None) -> list[MethodMeasurement]:
    """Measure every applicable method on the zoo model `name` over one run of `t_final` (the
    atlas's measurement, :func:`gnipy.experiments.atlas.measure_model`, with the reference horizon
    the whole run and no reversibility run); `progress(name, method)` after each method."""
    steps = round(t_final / h)
    p = Plan(h=h, steps=steps, t_ref=t_final, ref_every=max(1, steps // nodes), long_nodes=0, reverse=False)
    return [r.measurement for r in atlas_model(name, p, methods=methods, progress=progress).pairs]


def main(argv=None) -> None:
    """The full atlas's measurements of the named models (default: all), without its report files:
    prints each model's table, its choice, and the module :mod:`gnipy.models.default_methods` that
    records the choices (:func:`gnipy.experiments.atlas_report.default_methods_source`)."""
    names = list(argv if argv is not None else sys.argv[1:]) or None
    result = run_atlas(models=names)
    print("| model | method | error vs reference | invariant drift | constraint residual | verdict |")
    print("|---|---|---|---|---|---|")
    for model in result.models:
        for r in model.pairs:
            print(f"| {model.model} | {r.method} | {r.error:.2e} | {r.invariant_drift:.2e} | "
                  f"{r.constraint_residual:.1e} | {r.verdict} |")
    print()
    for model in result.models:
        print(f"- `{model.model}`: **{model.recommended[0]}** — {model.recommended[1]}")
    print()
    print(default_methods_source(result))


if __name__ == "__main__":
    main()
