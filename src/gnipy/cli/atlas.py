"""`gni atlas`: every method on every zoo model over long horizons, the recommended method per model,
and the report (:mod:`gnipy.experiments.atlas`, :mod:`gnipy.experiments.atlas_report`)."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded, relabel
from .held import hold, holding
from .output import EXIT_FAILURE, EXIT_USAGE, console, fail, safe, table
from .parsing import parse_methods
from .progress import Progress

__all__ = ["atlas", "parse_models"]


def parse_models(text: str) -> list[str]:
    """`--models a,b`: zoo model names or the user's systems (`FILE.py:NAME`, `module:NAME`, loaded
    here and named by their canonical reference), without repeats."""
    import gnipy
    from gnipy.user_systems import is_reference

    known = gnipy.model_names()
    names = []
    for part in text.split(","):
        name = part.strip()
        if not name:
            continue
        if is_reference(name):
            try:
                name = gnipy.get_model(name).name
            except gnipy.InputError as e:
                raise UsageError("--models", str(e).partition(":")[2].strip()) from None
        elif name not in known:
            raise UsageError("--models", f"unknown model {name!r} (known: {', '.join(known)}; or the user's "
                             "system as FILE.py:NAME)")
        if name not in names:
            names.append(name)
    if not names:
        raise UsageError("--models", f"give at least one model name, got {text!r}")
    return names


@app.command(name="atlas")
def atlas(
    out: Path = typer.Option(Path("gnipy-atlas"), "--out", "-o",
                             help="Output folder: atlas.md, atlas.html (self-contained), the heat maps (PNG, PDF), "
                             "atlas.json and default_methods.py (the recommendations as the record gni models "
                             "shows)."),
    quick: bool = typer.Option(False, "--quick", help="Short runs (2000 steps) of three models (unless --models "
                               "names others): about 3 minutes on 2 cores; full: 10^5-10^6 steps of every model, "
                               "up to 30 minutes."),
    models: str | None = typer.Option(None, "--models", help="Comma-separated model names, or your own systems "
                                      "as FILE.py:NAME or module:NAME (default: every zoo model; with --quick, "
                                      "three of them).", show_default=False),
    methods: str | None = typer.Option(None, "--methods", "-m", help="Comma-separated method names (default: "
                                       "every method but the reference).", show_default=False),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace the atlas's files in a folder gnipy did not "
                                   "create (in one it created, marked by its .gnipy-owned file, a rerun replaces them)."),
) -> None:
    """Run every method on every zoo model over a long horizon and recommend a method per model.

    Per (model, method that applies): one run of N steps of h = 0.01 measuring the error against the
    continuous reference up to t_ref, the energy and invariant errors and their growth, the
    constraint residual, the run-time verdicts (hidden momentum, energy), reversibility (N steps
    back, for the methods symmetric on the model) and the cost per step (compiled). The
    recommendation is the rule of the recorded defaults (gnipy.experiments.method_choice). Writes OUT/atlas.md, OUT/atlas.html, the heat maps,
    OUT/atlas.json and OUT/default_methods.py, and prints each model's recommendation beside its
    recorded default. Exits with 1 if a file cannot be written, 2 on bad input or if --out may not
    be written.
    """
    import shlex
    import sys

    from gnipy.experiments.atlas_report import OUTPUT_FILES, atlas as run
    from gnipy.experiments.reproduce import check_output_dir
    from gnipy.files import OutputBusy, OutputError

    def parse():
        return (parse_models(models) if models else None, parse_methods(methods) if methods else None)

    model_names, method_names = guarded(parse, method_option="--methods")
    try:
        check_output_dir(Path(out), overwrite, files=OUTPUT_FILES)
    except OutputError as e:
        fail(relabel("--out", e), EXIT_USAGE)
    command = "gni " + " ".join(shlex.quote(a) for a in ["atlas", *sys.argv[2:]]) if len(sys.argv) > 1 else None
    with holding():
        try:
            hold("--out", out)  # one writer per folder: a second atlas into it is refused now
        except OutputBusy as e:
            fail(str(e), EXIT_USAGE)
        try:
            with Progress("atlas", unit="runs", heartbeat=True) as progress:
                report = run(Path(out), quick=quick, models=model_names, methods=method_names, progress=progress,
                             overwrite=overwrite, command=command)
        except OutputError as e:
            fail(relabel("--out", e), EXIT_FAILURE)
    _print_summary(report)


def _print_summary(report) -> None:
    from gnipy.experiments.atlas_report import agreement

    result = report.result
    con = console()
    rows = table(title=f"gni atlas ({'quick' if result.quick else 'full'}): recommended method per model",
                 title_justify="left")
    for head in ("model", "recommended", "its error", "recorded default", "agrees"):
        rows.add_column(head, overflow="fold")
    for m in result.models:
        best = m.pair(m.recommended[0])
        rows.add_row(m.model, m.recommended[0], "—" if best is None else f"{best.error:.1e}", m.recorded or "—",
                     agreement(m, "NO"))
    con.print(rows)
    n = sum(len(m.pairs) for m in result.models)
    con.print(f"{n} runs measured in {result.runtime_s:.0f} s; report written in {report.runtime_s:.1f} s.",
              markup=False)
    con.print(f"written: {safe(report.markdown)}, {safe(report.html)} (self-contained), "
              f"{safe(report.markdown.with_suffix('.json'))}, {safe(report.defaults)}", markup=False)
