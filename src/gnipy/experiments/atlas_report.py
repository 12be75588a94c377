"""The method atlas's report (`gni atlas`): `atlas.md`, the self-contained `atlas.html` (figures
embedded as base64 PNG, as the reproduction's report, :mod:`gnipy.experiments.report`), the heat
maps (PNG and PDF), `atlas.json` (every measurement: :func:`from_json` reads it back, e.g. to
redraw the report with :func:`write_atlas`), and `default_methods.py`, the record of the
recommendations (:func:`default_methods_source`).

:func:`atlas` measures (:func:`gnipy.experiments.atlas.run_atlas`) and writes. The output folder
follows the reproduction's rules (:func:`gnipy.experiments.reproduce.check_output_dir`): a folder
gnipy creates is marked `.gnipy-owned` and a rerun replaces its files; in another folder existing
files of the names in :data:`OUTPUT_FILES` are replaced only with `overwrite=True`. Every file is
written atomically (:mod:`gnipy.files`).
"""

from __future__ import annotations

import dataclasses
import datetime
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

__all__ = ["OUTPUT_FILES", "FIGURES", "AtlasReport", "atlas", "write_atlas", "default_methods_source", "to_json",
           "from_json"]

#: The heat maps: file stem -> (title, what each cell holds).
FIGURES = {
    "atlas_error": ("error against the reference", "log10 of max |q - q_ref| (and |R - R_ref|) over t <= t_ref"),
    "atlas_drift": ("energy and invariant drift", "log10 of the largest relative error of the energy (where "
                    "conserved) and of the registered invariants over the whole run"),
    "atlas_reversibility": ("reversibility", "log10 of the distance to the start after N steps forward and N back"),
    "atlas_cost": ("cost per step", "log10 of the microseconds per step (compiled; 2 cores, shared)"),
}
#: The files an atlas writes into its folder.
OUTPUT_FILES = tuple(f"{stem}.{ext}" for stem in FIGURES for ext in ("png", "pdf")) + (
    "atlas.md", "atlas.html", "atlas.json", "default_methods.py")

TITLE = "gnipy method atlas: which method works where"
RULE = ("A method qualifies when its long run completes, raises no run-time warning (hidden momentum out of its "
        "O(h) band, a conserved energy drifting away) and keeps the energy and every registered invariant to 1e-2 "
        "relative over the whole run; the recommendation is the qualifying method with the smallest error against "
        "the reference, methods within a factor 1.5 of the best or below 1e-9 (the reference's own accuracy) counting "
        "as tied and the tie going to exact "
        "constraints, then the higher order, then a method the run-time diagnostics watch, then fewer Newton "
        "iterations (gnipy.experiments.method_choice.choose). When none qualifies, the continuous reference.")
MEASURED = ("Each method runs once per model at h = 0.01 for N steps, saving the nodes of every 10 steps up to "
            "t_ref and 1000 nodes after it. Error: max |q - q_ref| (and |R - R_ref|) over t <= t_ref against the "
            "continuous reference (Dopri8, tolerance 1e-12). Energy (where the motion conserves it) and invariants: "
            "max |I - I0| relative to the invariant's size along the reference, over the whole run; growth: the "
            "largest deviation in the last quarter of the run over that in the first (about 1: bounded; 3-4: a "
            "linear drift). Reversibility: N steps forward then N steps of -h from the final state (a symmetric "
            "method runs its exact inverse), distance of (q, v, R) to the start relative to max(1, |start|). Cost: "
            "wall time of the long run over N, after a short run that compiles the same program (the first call's "
            "time, compilation included, is shown apart).")


@dataclasses.dataclass
class AtlasReport:
    """What :func:`atlas` produced: the measurements, the report files and the figures."""

    result: object
    markdown: Path
    html: Path
    defaults: Path
    figures: list[Path]
    runtime_s: float


def _log10(x) -> float:
    if x is None or not isinstance(x, (int, float)) or math.isnan(x):
        return math.nan
    if math.isinf(x):
        return math.inf
    return math.log10(max(float(x), 1e-16))


def _grid(result, value) -> np.ndarray:
    """models × methods of log10(value(pair)); NaN where the method does not apply, inf where failed."""
    out = np.full((len(result.models), len(result.methods)), np.nan)
    for i, m in enumerate(result.models):
        for j, name in enumerate(result.methods):
            p = m.pair(name)
            if p is not None:
                out[i, j] = _log10(value(p))
    return out


_VALUES = {
    "atlas_error": lambda p: p.error if p.completed else math.inf,
    "atlas_drift": lambda p: p.invariant_drift if p.completed else math.inf,
    "atlas_reversibility": lambda p: (p.reversibility if p.reversibility is not None else math.nan)
    if p.completed else math.inf,
    "atlas_cost": lambda p: p.cost_us,
}


def _heat_map(result, stem: str, out_dir: Path) -> list[Path]:
    from matplotlib import colormaps
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    from .report import save_figure

    title, what = FIGURES[stem]
    grid = _grid(result, _VALUES[stem])
    finite = grid[np.isfinite(grid)]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    if stem != "atlas_cost":  # errors of 100 and of 1e20 are equally useless: one colour
        lo, hi = min(lo, 1.0), min(hi, 2.0)
    if hi - lo < 1.0:
        lo, hi = lo - 0.5, hi + 0.5
    n_models, n_methods = grid.shape
    fig = Figure(figsize=(max(6.0, 2.8 + 0.55 * n_methods), max(3.2, 1.9 + 0.36 * n_models)), layout="constrained")
    ax = fig.add_subplot()
    cmap = colormaps["viridis_r" if stem != "atlas_cost" else "magma_r"].with_extremes(bad="#eeeeee")
    shown = np.where(np.isfinite(grid), grid, np.nan)
    image = ax.imshow(shown, cmap=cmap, vmin=lo, vmax=hi, aspect="auto")
    for i, m in enumerate(result.models):
        for j, name in enumerate(result.methods):
            p = m.pair(name)
            if p is None:
                ax.text(j, i, "n/a", ha="center", va="center", fontsize=6, color="#888888")
                continue
            value = grid[i, j]
            if not p.completed:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, color="#b00020"))
                label = "failed"
            else:
                label = "" if not np.isfinite(value) else f"{int(np.round(value))}" if stem != "atlas_cost" else f"{10**value:.0f}"
                if p.warnings:
                    label += " W"
                elif not p.qualifies:
                    label += " D"
            dark = np.isfinite(value) and (min(value, hi) - lo) / (hi - lo) > 0.6
            ax.text(j, i, label, ha="center", va="center", fontsize=6.5,
                    color="white" if (dark or not p.completed) else "black")
            if name == m.recommended[0]:
                ax.add_patch(Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="#e8590c", linewidth=2.2))
    ax.set_xticks(range(n_methods), result.methods, rotation=60, ha="right", fontsize=7.5)
    ax.set_yticks(range(n_models), [m.model for m in result.models], fontsize=7.5)
    mode = "quick" if result.quick else "full"
    ax.set_title(f"{title} ({mode} atlas)", fontsize=9)
    bar = fig.colorbar(image, ax=ax, shrink=0.9)
    bar.set_label("log10 µs per step (cells: µs)" if stem == "atlas_cost" else "log10 (cells: the exponent)", fontsize=7.5)
    ax.set_xlabel("W: run-time warning; D: an invariant drifts by more than 1e-2; failed: a step failed; "
                  "n/a: the method does not apply; orange box: recommended", fontsize=7)
    return save_figure(fig, out_dir, stem, dpi=130)


# ------------------------------------------------------------------------------------------------
# tables
# ------------------------------------------------------------------------------------------------
def _e(x, digits: int = 1) -> str:
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        if math.isnan(x):
            return "—"
        if math.isinf(x):
            return "inf"
        return f"{x:.{digits}e}"
    return str(x)


def _growth(g) -> str:
    return "—" if g is None or (isinstance(g, float) and math.isnan(g)) else f"{g:.2g}"


def _reversibility(p) -> str:
    """The distance back to the start; for a method not symmetric on the model, why it is not measured."""
    return "not symmetric" if p.reversibility is None and not p.symmetric else _e(p.reversibility)


def _hidden(p) -> str:
    if p.hidden_max is None:
        return "—"
    return f"{p.hidden_max:.1e} ({'in band' if p.hidden_in_band else 'OUT of band'})"


PAIR_HEADER = ["method", "order", "symmetric", "verdict", "error vs reference", "energy error", "energy growth",
               "invariants (error, growth)", "constraint residual", "hidden momentum", "reversibility",
               "µs/step", "first call (s)", "note"]


def pair_row(p) -> list[str]:
    """One method's row of a model's table (:data:`PAIR_HEADER`)."""
    inv = "; ".join(f"{k}: {_e(e)}, {_growth(g)}" for k, (e, g) in p.invariants.items()) or "—"
    return [p.method, str(p.order or "?"), _e(p.symmetric), p.verdict, _e(p.error), _e(p.energy_error),
            _growth(p.energy_growth), inv, _e(p.constraint_residual), _hidden(p), _reversibility(p),
            f"{p.cost_us:.3g}", f"{p.compile_s:.2g}",
            "; ".join(x for x in (_short(p.note, 160), *(_short(w, 130) for w in p.warnings)) if x)]


def agreement(m, no: str = "no") -> str:
    """`yes`, `no`, or that the recorded default was not among the methods measured."""
    if m.agrees:
        return "yes"
    return no if m.pair(m.recorded or "") is not None else f"{no} (the default was not measured)"


def summary_rows(result) -> list[list[str]]:
    """model, recommended, recorded default, agrees, its error, the run, why."""
    rows = []
    for m in result.models:
        best = m.pair(m.recommended[0])
        rows.append([m.model, m.recommended[0], m.recorded or "—", agreement(m, "**no**"),
                     _e(best.error) if best else "—", f"{m.plan.steps:,} steps (T = {m.plan.t_final:g}), "
                     f"t_ref = {m.plan.t_ref:g}", m.recommended[1]])
    return rows


SUMMARY_HEADER = ["model", "recommended", "recorded default (gni models)", "agrees", "its error",
                  "run", "why (the rule on the measurements)"]


def _meta(result, command: str | None) -> dict:
    from .reproduce import machine_description, version_info

    meta = {**version_info(), "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "machine": machine_description(), "mode": "quick" if result.quick else "full", "runtime_s": result.runtime_s}
    if command:
        meta["command"] = command
    return meta


def _counts(result) -> str:
    pairs = sum(len(m.pairs) for m in result.models)
    agree = sum(m.agrees for m in result.models)
    return (f"{len(result.models)} models × {len(result.methods)} methods: {pairs} pairs measured "
            f"(the others do not apply); the recommendation agrees with the recorded default on {agree} of "
            f"{len(result.models)} models.")


def _markdown(result, meta, figures: list[Path], out_dir: Path) -> str:
    from .report import markdown_table, meta_items

    lines = [f"# {TITLE}", "", "## Provenance", ""]
    lines += markdown_table(["", ""], meta_items(meta))
    lines += ["", f"**{_counts(result)}**", "", "## Recommendations", ""]
    lines += markdown_table(SUMMARY_HEADER, summary_rows(result))
    lines += ["", f"The rule: {RULE}", "", f"What is measured: {MEASURED}", "",
              "To record these recommendations as the defaults that `gni models` shows (a full atlas), copy "
              "`default_methods.py`, written beside this report, over `src/gnipy/models/default_methods.py`.",
              "", "## Heat maps", ""]
    for f in figures:
        if f.suffix == ".png":
            stem = f.stem
            lines += [f"### {FIGURES[stem][0]}", "", f"![{stem}]({f.name})", "", f"*{FIGURES[stem][1]}.*", ""]
    lines += ["## Per model", ""]
    for m in result.models:
        lines += [f"### {m.model}", "",
                  f"{m.plan.steps:,} steps of h = {m.plan.h:g} (T = {m.plan.t_final:g}), error against the reference "
                  f"over t <= {m.plan.t_ref:g}; {m.runtime_s:.0f} s (reference {m.reference_s:.1f} s). "
                  f"Recommended: **{m.recommended[0]}** (recorded default: {m.recorded}; "
                  f"{'agrees' if m.agrees else 'differs'}).", ""]
        lines += markdown_table(PAIR_HEADER, (pair_row(p) for p in m.pairs))
        if m.not_applicable:
            lines += ["", "Not applicable: " + "; ".join(f"{k} ({_short(v)})" for k, v in m.not_applicable.items())]
        lines += [""]
    return "\n".join(lines) + "\n"


def _short(text: str, n: int = 110) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[: n - 1] + "…"


def _html(result, meta, figures: list[Path]) -> str:
    import html as _h

    from .report import REPORT_CSS, png_data_uri, html_table, meta_items

    def e(x) -> str:
        return _h.escape(str(x))

    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">', f"<title>{e(TITLE)}</title>",
             f"<style>{REPORT_CSS} td {{ font-size: .9em; }} .no {{ color: #b00020; font-weight: bold; }}</style>",
             "</head>", "<body>", f"<h1>{e(TITLE)}</h1>", f'<p class="summary">{e(_counts(result))}</p>',
             "<h2>Provenance</h2>"]
    parts += html_table(["item", "value"], meta_items(meta))
    parts.append("<h2>Recommendations</h2>")
    rows = [[c.replace("**", "") for c in r] for r in summary_rows(result)]
    parts += html_table(SUMMARY_HEADER, rows)
    parts += [f"<p><b>The rule.</b> {e(RULE)}</p>", f"<p><b>What is measured.</b> {e(MEASURED)}</p>",
              "<p>To record these recommendations as the defaults that <code>gni models</code> shows (a full atlas), "
              "copy <code>default_methods.py</code>, written beside this report, over "
              "<code>src/gnipy/models/default_methods.py</code>.</p>", "<h2>Heat maps</h2>"]
    for f in figures:
        if f.suffix == ".png":
            uri = png_data_uri(f)
            title, what = FIGURES[f.stem]
            parts.append(f"<h3>{e(title)}</h3>")
            parts.append(f'<figure><img alt="{e(f.stem)}" src="{uri}"></figure>' if uri else
                         f'<p class="fail">Image missing: {e(f.name)}</p>')
            parts.append(f'<p class="caption">{e(what)}.</p>')
    parts.append("<h2>Per model</h2>")
    for m in result.models:
        parts.append(f'<h3 id="{e(m.model)}">{e(m.model)}</h3>')
        verdict = "agrees" if m.agrees else '<span class="no">differs</span>'
        parts.append(f"<p>{m.plan.steps:,} steps of h = {m.plan.h:g} (T = {m.plan.t_final:g}), error against the "
                     f"reference over t &le; {m.plan.t_ref:g}; {m.runtime_s:.0f} s (reference {m.reference_s:.1f} s). "
                     f"Recommended: <b>{e(m.recommended[0])}</b> (recorded default: {e(m.recorded)}; {verdict}).</p>")
        parts += html_table(PAIR_HEADER, (pair_row(p) for p in m.pairs))
        if m.not_applicable:
            parts.append('<p class="small">Not applicable: '
                         + e("; ".join(f"{k} ({_short(v)})" for k, v in m.not_applicable.items())) + "</p>")
        parts.append(f'<p class="detail">{e(m.recommended[1])}</p>')
    parts += ["</body>", "</html>"]
    return "\n".join(parts) + "\n"


def write_atlas(out_dir, result, *, command: str | None = None) -> AtlasReport:
    """Write the figures, `atlas.md`, `atlas.html` and `default_methods.py` of `result` (an
    :class:`~gnipy.experiments.atlas.AtlasResult`) into `out_dir` (created, marked, if missing;
    files replaced as :func:`gnipy.experiments.report.may_replace` allows)."""
    import time

    from ..files import atomic_write_text
    from .report import ensure_output_dir, may_replace

    t = time.perf_counter()
    out_dir = ensure_output_dir(out_dir, "gni atlas: heat maps and report")
    replace = may_replace(out_dir)
    figures = [f for stem in FIGURES for f in _heat_map(result, stem, out_dir)] if result.models else []
    meta = _meta(result, command)
    md, page = out_dir / "atlas.md", out_dir / "atlas.html"
    defaults = out_dir / "default_methods.py"
    atomic_write_text(out_dir / "atlas.json", to_json(result), overwrite=replace, argument="out_dir")
    atomic_write_text(defaults, default_methods_source(result), overwrite=replace, argument="out_dir")
    atomic_write_text(md, _markdown(result, meta, figures, out_dir), overwrite=replace, argument="out_dir")
    atomic_write_text(page, _html(result, meta, figures), overwrite=replace, argument="out_dir")
    return AtlasReport(result, md, page, defaults, figures, time.perf_counter() - t)


def to_json(result) -> str:
    """Every measurement of `result` (an :class:`~gnipy.experiments.atlas.AtlasResult`) as JSON
    (infinities and NaN as JSON's `Infinity` and `NaN`)."""
    import json

    return json.dumps(dataclasses.asdict(result), indent=1) + "\n"


def from_json(text: str):
    """The :class:`~gnipy.experiments.atlas.AtlasResult` that :func:`to_json` wrote."""
    import json

    from .atlas import AtlasResult, ModelResult, PairResult, Plan

    data = json.loads(text)
    models = []
    for m in data["models"]:
        pairs = []
        for p in m["pairs"]:
            p = dict(p, warnings=tuple(p["warnings"]), invariants={k: tuple(v) for k, v in p["invariants"].items()})
            pairs.append(PairResult(**p))
        models.append(ModelResult(**dict(m, plan=Plan(**m["plan"]), pairs=pairs, recommended=tuple(m["recommended"]))))
    return AtlasResult(models, list(data["methods"]), bool(data["quick"]), float(data["runtime_s"]))


def atlas(out_dir, *, quick: bool = False, models: Sequence[str] | None = None, methods: Sequence[str] | None = None,
          progress=None, overwrite: bool = False, command: str | None = None) -> AtlasReport:
    """Measure the atlas (:func:`gnipy.experiments.atlas.run_atlas`) and write its report into
    `out_dir` (module docstring). The folder is checked before anything is computed.

    Raises:
        gnipy.files.OutputError: the folder may not be written, or a file could not be."""
    from .atlas import run_atlas
    from .report import overwriting
    from .reproduce import check_output_dir

    out_dir = check_output_dir(Path(out_dir), overwrite, files=OUTPUT_FILES)
    result = run_atlas(quick=quick, models=models, methods=methods, progress=progress)
    with overwriting(overwrite):
        return write_atlas(out_dir, result, command=command)


# ------------------------------------------------------------------------------------------------
# the record of defaults
# ------------------------------------------------------------------------------------------------
def default_methods_source(result) -> str:
    """The module :mod:`gnipy.models.default_methods` with the atlas's recommendations (models the
    atlas did not measure keep their recorded entries): copy it over
    src/gnipy/models/default_methods.py to update the defaults that `gni models` shows."""
    from ..models import default_methods

    entries = dict(default_methods.DEFAULT_METHODS)
    for m in result.models:
        if ":" not in m.model:  # the zoo's record only: a user's system (FILE.py:NAME) is not one of its models
            entries[m.model] = m.recommended
    lines = ['"""' + (default_methods.__doc__ or "").strip() + '\n"""', "",
             "from __future__ import annotations", "",
             "from ..registry import FALLBACK_METHOD, set_default_methods", "",
             '__all__ = ["DEFAULT_METHODS", "FALLBACK_METHOD"]', "",
             "#: model name -> (method, why), the method atlas's recommendations (gnipy.experiments.atlas).",
             "DEFAULT_METHODS: dict[str, tuple[str, str]] = {"]
    for name in sorted(entries):
        method, reason = entries[name]
        pieces = _split_reason(reason)
        lines += [f"    {name!r}: (".replace("'", '"'), f"        {_q(method)},"]
        lines += [f"        {_q(pieces[0])}"] + [f"        {_q(x)}" for x in pieces[1:]]
        lines[-1] += ","
        lines += ["    ),"]
    lines += ["}", "", "set_default_methods(DEFAULT_METHODS)", ""]
    return "\n".join(lines)


def _split_reason(reason: str) -> list[str]:
    out = [reason]
    for marker in ("; next ", "; disqualified: "):
        head, sep, tail = out[-1].partition(marker)
        if sep:
            out[-1:] = [head, sep + tail]
    return out


def _q(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'
