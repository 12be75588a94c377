"""`gni reproduce`: the options of the paper's reproduction (:mod:`gnipy.experiments.reproduce`)
and its errors."""

from __future__ import annotations

import inspect
from pathlib import Path

import typer

from .app import app
from .errors import relabel
from .held import hold, holding
from .output import EXIT_FAILURE, EXIT_USAGE, fail
from .progress import Progress, on_terminal

__all__ = ["reproduce"]


@app.command(name="reproduce")
def reproduce(
    out: Path = typer.Option(Path("gnipy-reproduction"), "--out",
                             help="Output folder for the figures (PNG, PDF) and the report (report.md, report.html)."),
    quick: bool = typer.Option(False, "--quick",
                               help="Short run, under a minute: fewer step sizes and shorter runs (full: a few minutes)."),
    overwrite: bool = typer.Option(False, "--overwrite",
                                   help="Replace the figures and reports in a folder gnipy did not create (in one it "
                                   "created, marked by its .gnipy-owned file, a rerun replaces them)."),
) -> None:
    """Reproduce the paper: figures 1–3 (§7.4), the theorem table (orders of Thm 5.1 and the
    remarks, adjointness of Thm 5.2, exact constraints, energy conservation on SO(3), the explicit
    schemes equal to the GNI) and the errata, each measured by running gnipy; writes report.md and
    a self-contained report.html into --out (a folder gnipy creates is marked .gnipy-owned and
    rerunning into it replaces the files; in another folder existing files need --overwrite).
    Exits with code 1 if a theorem row fails, a stage fails, or a file cannot be written; 2 if --out
    may not be written."""
    from gnipy.experiments import reproduce as reproduction
    from gnipy.files import OutputBusy, OutputError

    out = Path(out)
    try:
        reproduction.check_output_dir(out, overwrite)
    except OutputError as e:
        fail(relabel("--out", e), EXIT_USAGE)
    run = reproduction.run_reproduction
    with holding():
        try:
            hold("--out", out)  # one writer per folder: a second reproduction into it is refused now
        except OutputBusy as e:
            fail(str(e), EXIT_USAGE)
        result = _run(run, out, quick, overwrite)
    if not result.ok:
        raise typer.Exit(EXIT_FAILURE)


def _run(run, out: Path, quick: bool, overwrite: bool):
    from gnipy.files import OutputError

    try:
        if on_terminal():  # the reproduction's own display, a bar per stage
            result = run(out, quick, overwrite=overwrite)
        else:  # plain lines: the stages done where the reproduction counts them (`progress=`), else the time
            with Progress("reproduce", unit="stages", terminal=False, heartbeat=True) as progress:
                counted = {"progress": progress} if "progress" in inspect.signature(run).parameters else {}
                result = run(out, quick, overwrite=overwrite, **counted)
    except OutputError as e:  # the folder, or the report, could not be written (a full disk)
        fail(relabel("--out", e), EXIT_FAILURE)
    return result
