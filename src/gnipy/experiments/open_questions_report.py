"""`gni open-questions`: the studies of :mod:`gnipy.experiments.open_questions` run in one call,
with their figures and a report (`open-questions.md`, and every number in `open-questions.json`).

The verdicts in the report are read off the numbers by the rules stated beside them (thresholds
:data:`SAME_CONSTRAINTS` and :data:`DRIFT_FRACTION`), so a change in the library that changes a
measurement changes the report's words too.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from ..analysis.modified_equations import NEAR_IDENTITY
from .figure_tools import new_figure, write_figure
from .open_questions import (PREDICTION_SPAN, BE_METHODS, BE_MODELS, SISTER_CASES, backward_error_row, long_runs, sister_convergence,
                             sister_relations)
from .report import ensure_output_dir, markdown_table, may_replace

__all__ = ["OPEN_QUESTIONS_FILES", "OpenQuestionsResult", "run_open_questions", "measure_open_questions",
           "write_open_questions", "SAME_CONSTRAINTS", "BREAKDOWN",
           "DRIFT_FRACTION"]

#: The files a run writes into its folder.
OPEN_QUESTIONS_FILES = ("open-questions.md", "open-questions.json") + tuple(
    f"{stem}.{ext}" for stem in ("sister_convergence", "sister_paths", "energy_prediction") for ext in ("png", "pdf"))

#: $|\mu f_{j,q}|$ and $|\nabla E\cdot f_j|$ below this (relative to $1 + |f_1|$) count as zero: above
#: the extrapolation's noise in $f_3$ (up to 5e-8 relative, measured on the discrete gradient)
SAME_CONSTRAINTS = 1e-7
#: a measured energy error this many times the predicted one: the expansion does not describe the run
BREAKDOWN = 10.0
#: an energy error whose fitted slope times the span exceeds this fraction of its largest value
#: is called a drift, else bounded
DRIFT_FRACTION = 0.5


@dataclasses.dataclass
class OpenQuestionsResult:
    """What :func:`run_open_questions` produced: the report's path, the JSON's, the figures, the
    measurements (as dicts) and the run time."""

    markdown: Path
    data: Path
    figures: list
    measurements: dict
    runtime_s: float


def _premise(row) -> bool:
    """Whether the method's map tends to the identity at the sampled states (the expansion holds)."""
    return row["defect"] <= NEAR_IDENTITY * (1.0 + row["coefficient_sizes"][0])


def _constraint_verdict(row) -> str:
    if not _premise(row):
        return f"no modified field at the visited states (Φ_0 ≠ id there: {row['defect']:.1g})"
    scale = 1.0 + row["coefficient_sizes"][0]
    off = [j for j, x in enumerate(row["normal_velocity"], start=1) if x > SAME_CONSTRAINTS * scale]
    if not off:
        return "same constraints to h^2"
    return f"modified constraints from h^{off[0] - 1}" if off[0] > 1 else "off the constraints at h^0"


def _energy_verdict(row) -> str:
    if not _premise(row):
        return "—"
    if max(row["energy_rate"]) <= SAME_CONSTRAINTS * (1.0 + row["coefficient_sizes"][0]):
        return "conserved to h^2 (every f_j tangent to E = const)"
    if row["failure"]:
        return "run failed"
    span = row["h"] * row["steps"]
    measured = "drift" if abs(row["measured_slope"]) * span > DRIFT_FRACTION * row["run_max"] else "bounded"
    window = min(span, PREDICTION_SPAN)
    predicted = "drift" if abs(row["predicted_slope"]) * window > DRIFT_FRACTION * row["predicted_max"] else "bounded"
    if row["measured_max"] > BREAKDOWN * row["predicted_max"]:
        return (f"measured {row['measured_max'] / row['predicted_max']:.2g} times the prediction: the expansion "
                "breaks down (the hidden momentum grows)")
    return f"predicted {predicted}, measured {measured}"


def _g(x: float) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{x:.2g}"


def _figures(out_dir: Path, sisters, be_rows, paths) -> list[Path]:
    files = []
    fig = new_figure(10, 4)
    ax1, ax2 = fig.subplots(1, 2)
    for s in sisters:
        style = "o-" if s["kind"] == "system" else "s--"
        label = f"{s['model']} ({s['constraint']}, {'sister motion' if s['kind'] == 'system' else 'sister method'})"
        ax1.loglog(s["taus"], s["errors"], style, label=label, markersize=4)
        ax2.loglog(s["taus"], np.abs(s["dissipation"]), style, markersize=4)
    for ax, what in ((ax1, "largest configuration error, t ≤ 2"), (ax2, "energy lost per unit time")):
        ax.set_xlabel("τ (time between switches) or h (sister method)")
        ax.set_ylabel(what)
        ax.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=6)
    fig.suptitle("Sister systems approach the nonholonomic motion at order 1 in τ, dissipating O(τ)")
    files += write_figure(fig, out_dir, "sister_convergence")

    fig = new_figure(6, 4.5)
    ax = fig.subplots()
    ax.plot(paths["reference"][:, 0], paths["reference"][:, 1], "k-", label="nonholonomic (reference)")
    for tau, q in paths["sister"].items():
        ax.plot(q[:, 0], q[:, 1], ".-", markersize=3, label=f"sister motion, rail, τ = {tau:g}")
    ax.set_xlabel("x (down the slope)")
    ax.set_ylabel("y")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7)
    ax.set_title("Knife edge on an incline: the blade on rails re-laid every τ")
    files += write_figure(fig, out_dir, "sister_paths")

    shown = [r for r in be_rows if r.get("series") and _premise(r)]  # a prediction where the expansion holds
    fig = new_figure(10, 2.6 * max(1, (len(shown) + 1) // 2))
    axes = np.atleast_1d(fig.subplots(max(1, (len(shown) + 1) // 2), 2)).ravel()
    for ax, r in zip(axes, shown):
        s = r["series"]
        ax.plot(s["t"], s["measured"], "-", lw=0.8, label="measured E_k − E_0")
        ax.plot(s["t"], s["predicted"], "--", lw=0.8, label="predicted H G_2 + H² G_3")
        ax.set_title(f"{r['model']}, {r['method']} (h = {r['h']:g})", fontsize=8)
        ax.set_xlabel("t")
        ax.legend(fontsize=6)
    for ax in axes[len(shown):]:
        ax.set_visible(False)
    fig.suptitle("Energy error: measured against the modified equations' prediction")
    files += write_figure(fig, out_dir, "energy_prediction")
    return files


def _markdown(m: dict) -> str:
    lines = ["# The paper's open questions 1 and 3, measured", "",
             f"gnipy {m['meta']['gnipy_version']}, {m['meta']['date']}, {m['meta']['mode']} run, "
             f"{m['meta']['runtime_s']:.0f} s on {m['meta']['machine']}.", "",
             "## Question 1: is the discrete evolution the flow of a nonholonomic system?", "",
             "Modified field f̃ = f1 + H f2 + H² f3 of each method's map (the GNI family: two steps of h/2, "
             "H = 2h; the others one step, H = h), at states of the method's own run. Columns: the size of "
             "f2 and f3; the largest normal velocity |μ f_j,q| (zero for every j exactly when the modified "
             "flow keeps the constraints); |∇E·f_j|; tr Df1 (phase volume); the energy error predicted by "
             "E(t) − E(0) ≈ H G2(t) + H² G3(t), G_j = ∫∇E·f_j along the reference motion, against the "
             f"measured one over the run (largest |E_k − E_0|). Verdict rules: a normal velocity or energy rate below "
             f"{SAME_CONSTRAINTS:g}·(1 + |f1|) counts as zero; a fitted slope times the span above "
             f"{DRIFT_FRACTION:g} of the largest error is a drift; a measured error above {BREAKDOWN:g} times the "
             "predicted one is a breakdown of the expansion.", ""]
    header = ["model", "method", "|Φ_0(y) − y|", "|f2|, |f3|", "|μ f_j,q| j=1,2,3", "|∇E·f_j| j=1,2,3", "tr Df1",
              f"predicted max ΔE, t ≤ {PREDICTION_SPAN:g}", f"measured, t ≤ {PREDICTION_SPAN:g}",
              "measured over the run (steps)", "constraints", "energy"]
    rows = []
    for r in m["backward_error"]:
        if "not_applicable" in r:
            # the refusal's first clause: what the method needs (the message goes on to name alternatives)
            rows.append([r["model"], r["method"], *["—"] * (len(header) - 4), "does not apply",
                         r["not_applicable"].split(";")[0]])
            continue
        measured = "failed: " + r["failure"][:60] if r["failure"] else _g(r["measured_max"])
        whole = "—" if r["failure"] else f"{_g(r['run_max'])} ({r['steps']:,})"
        rows.append([r["model"], r["method"], _g(r["defect"]), f"{_g(r['coefficient_sizes'][1])}, {_g(r['coefficient_sizes'][2])}",
                     ", ".join(_g(x) for x in r["normal_velocity"]), ", ".join(_g(x) for x in r["energy_rate"]),
                     _g(r["divergence"]), _g(r["predicted_max"]) if _premise(r) else "—", measured, whole,
                     _constraint_verdict(r),
                     _energy_verdict(r)])
    lines += markdown_table(header, rows)
    lines += ["", "![Energy error against its prediction](energy_prediction.png)", "",
              "## Question 3: sister systems", "",
              "The sister motion (holonomic phases of length τ on a constraint through the switch point, "
              "tangent to the distribution there, each ended by the plastic impact onto the distribution) and "
              "the sister method (one switch per step), against the continuous reference, t ≤ 2:", ""]
    rows = [[s["model"], s["constraint"], "motion" if s["kind"] == "system" else "method",
             ", ".join(_g(e) for e in s["errors"]), f"{s['order']:.2f}", _g(s["constant"]),
             f"{s['dissipation_order']:.2f}", _g(s["dissipation_constant"]), _g(s["constraint_kept"])]
            for s in m["sister_convergence"]]
    lines += markdown_table(["model", "constraint", "kind", "errors at τ = " + ", ".join(
        _g(t) for t in m["sister_convergence"][0]["taus"]), "order", "constant", "dissipation order",
        "dissipation constant", "largest |φ_k|"], rows)
    lines += ["", "![Sister convergence](sister_convergence.png)", "", "![Sister paths](sister_paths.png)", "",
              "One step of the sister method against one step of another map from the same state (largest "
              "configuration difference; a local difference of order r + 1 means agreement to order r, "
              "round-off means the same map):", ""]
    rows = []
    for model, rel in m["sister_relations"].items():
        for other, d in rel.items():
            same = max(d["difference"]) < 1e-13
            rows.append([model, other, ", ".join(_g(x) for x in d["difference"]),
                         "round-off: the same map" if same else f"{d['order']:.2f}"])
    lines += markdown_table(["model", "compared with", "difference at h = " + ", ".join(
        _g(h) for h in next(iter(next(iter(m["sister_relations"].values())).values()))["h"]), "order"], rows)
    lines += ["", "Long runs (h = 0.01): where the sister method fails and where it does better:", ""]
    rows = [[r["model"], r["method"], _g(r["t_final"]), _g(r["error"]), _g(r["energy_error"]),
             ("failed: " + r["failure"][:70]) if r["failure"] else ("; ".join(v[:70] for v in r["verdicts"]) or "—")]
            for r in m["long_runs"]]
    lines += markdown_table(["model", "method", "t_final", "error at t_final", "max |E − E0|", "failure / warnings"],
                            rows)
    return "\n".join(lines) + "\n"


def measure_open_questions(quick: bool = False, *, progress=None) -> dict:
    """Run the studies (quick: the nonholonomic particle's rows of question 1 with 10⁵ steps, and
    fewer sister cases; full: every model × method of :data:`~gnipy.experiments.open_questions.BE_MODELS`
    × :data:`~gnipy.experiments.open_questions.BE_METHODS` with 10⁶ steps) and return the
    measurements (plain dicts and lists, as `open-questions.json` holds them). `progress(done,
    total, stage)` is called as each study starts."""
    from .reproduce import machine_description, version_info

    start = time.perf_counter()
    be_models = BE_MODELS[:1] if quick else BE_MODELS
    be_methods = ("gni-trapezoid", "dla") if quick else BE_METHODS
    steps = 100_000 if quick else 1_000_000
    cases = SISTER_CASES[:3] if quick else SISTER_CASES
    relation_models = ("knife-edge", "nonholonomic-particle") if quick else ("knife-edge", "chaplygin-sleigh",
                                                                             "vertical-disk", "nonholonomic-particle")
    long_models = ("chaplygin-sleigh",) if quick else ("chaplygin-sleigh", "nonholonomic-particle", "knife-edge")
    total = len(be_models) * len(be_methods) + 2 * len(cases) + len(relation_models) + len(long_models) + 1
    done = 0

    def tick(stage):
        nonlocal done
        if progress is not None:
            progress(done, total, stage)
        done += 1

    sisters = []
    for model, constraint in cases:
        for kind in ("system", "method"):
            tick(f"sister {kind}: {model} ({constraint})")
            sisters.append(dataclasses.asdict(sister_convergence(model, constraint, kind)))
    relations = {}
    for model in relation_models:
        tick(f"sister relations: {model}")
        relations[model] = sister_relations(model)
    longs = []
    for model in long_models:
        tick(f"long runs: {model}")
        longs += [dataclasses.asdict(r) for r in long_runs(model)]
    tick("sister paths")
    paths = _paths()
    be_rows = []
    # each row in a fresh process: a row compiles large programs (nested derivatives through the
    # steps' solves), and one process holding all of them slowed a row from 84 s to 540 s here
    # (gnipy.compilation releases compiled programs when memory maps run short)
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=context, max_tasks_per_child=1) as pool:
        for model in be_models:
            for method in be_methods:
                tick(f"modified equations: {method} on {model}")
                be_rows.append(pool.submit(_row, model, method, steps).result())
    if progress is not None:
        progress(total, total, "report")
    meta = {**version_info(), "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": machine_description(), "mode": "quick" if quick else "full",
            "runtime_s": time.perf_counter() - start}
    return {"meta": meta, "backward_error": be_rows, "sister_convergence": sisters, "sister_relations": relations,
            "long_runs": longs, "sister_paths": paths}


def write_open_questions(out_dir, measurements: dict) -> OpenQuestionsResult:
    """Write the figures, `open-questions.md` and `open-questions.json` of `measurements`
    (:func:`measure_open_questions`) into `out_dir` (created with gnipy's marker if missing; files
    replaced as :func:`gnipy.experiments.report.may_replace` allows, each written atomically)."""
    from ..files import atomic_write_text

    start = time.perf_counter()
    out_dir = ensure_output_dir(out_dir, "gni open-questions: figures and report")
    replace = may_replace(out_dir)
    m = measurements
    figures = _figures(out_dir, m["sister_convergence"], m["backward_error"], m["sister_paths"])
    md = atomic_write_text(out_dir / "open-questions.md", _markdown(m), overwrite=replace, argument="out_dir")
    kept = {k: v for k, v in m.items() if k != "sister_paths"}  # the paths are the figure's
    data = atomic_write_text(out_dir / "open-questions.json", json.dumps(kept, indent=1, default=float),
                             overwrite=replace, argument="out_dir")
    return OpenQuestionsResult(markdown=md, data=data, figures=figures, measurements=m,
                               runtime_s=m["meta"]["runtime_s"] + time.perf_counter() - start)


def run_open_questions(out_dir, quick: bool = False, *, progress=None) -> OpenQuestionsResult:
    """:func:`measure_open_questions`, then :func:`write_open_questions` into `out_dir`."""
    return write_open_questions(out_dir, measure_open_questions(quick, progress=progress))


def _row(model: str, method: str, steps: int) -> dict:
    """One row of question 1 as a dict (run in a worker process); a method that does not apply to the
    model gives `{"model", "method", "not_applicable": why}`."""
    from ..errors import MethodError

    try:
        return dataclasses.asdict(backward_error_row(model, method, steps=steps))
    except MethodError as e:
        return {"model": model, "method": method, "not_applicable": str(e)}


def _paths() -> dict:
    """The knife edge's path and its rail sisters' at τ = 0.5 and 0.2 (the figure `sister_paths`)."""
    from ..analysis.sister import sister_trajectory
    from ..ensembles import model_systems
    from ..simulate import simulate

    system = model_systems("knife-edge")[0]
    q0, v0 = system.defaults[:2]
    ref = simulate(system, "reference", q0, v0, h=0.02, steps=200)
    sister = {tau: sister_trajectory(system, q0, v0, tau=tau, t_final=4.0).q for tau in (0.5, 0.2)}
    return {"reference": np.asarray(ref.q), "sister": sister}
