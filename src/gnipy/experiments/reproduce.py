"""Reproduce the paper in one call: figures 1–3, the theorem table, the errata, where the GNI
struggles (measured failures beyond the paper, :mod:`.struggles`), and the report.

:func:`reproduce` runs every stage with a rich progress display (one bar per stage, fed by the
stages' `progress(advance, description)` callbacks), writes `report.md` and the self-contained
`report.html` (:func:`gnipy.experiments.report.write_report`) next to the figures, prints a short
summary and returns the path of the HTML report. :func:`reproduce_command` is the same as a typer
command (`gni reproduce`), which exits with code 1 when a theorem row fails or a stage fails.

A stage that raises does not stop the others: its failure is recorded in the report (a figure
with the error as its note, or a failed theorem row) and makes the command exit non-zero.
"""

from __future__ import annotations

import dataclasses
import datetime
import platform
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import typer

__all__ = ["reproduce", "reproduce_command", "ReproductionResult", "run_reproduction"]

FIGURE_NAMES = ("figure_1", "figure_2", "figure_3")


@dataclasses.dataclass
class ReproductionResult:
    """What :func:`run_reproduction` produced.

    Attributes:
        report: the HTML report (self-contained).
        markdown: the Markdown report.
        figures: the figure results (failed figures carry the error in their notes).
        theorems: the theorem table rows.
        errata: the errata.
        failures: the stages that raised, as "stage: error" strings.
        struggles: the figures of "Where the GNI struggles" (:mod:`gnipy.experiments.struggles`).
        runtime_s: total run time.
    """

    report: Path
    markdown: Path
    figures: list
    theorems: list
    errata: list
    failures: list[str]
    runtime_s: float
    struggles: list = dataclasses.field(default_factory=list)

    @property
    def ok(self) -> bool:
        """Every theorem row passed and no stage failed."""
        return not self.failures and all(r.passed for r in self.theorems)


def _machine() -> str:
    import os

    cpu = platform.processor() or platform.machine()
    return f"{platform.node()} ({platform.system()} {platform.release()}, {cpu}, {os.cpu_count()} CPUs)"


def _versions() -> dict:
    import sys

    import jax

    from .. import __version__

    try:
        from importlib.metadata import version

        gnipy_version = version("gnipy")
    except Exception:  # not installed as a distribution
        gnipy_version = __version__
    devices = ", ".join(sorted({d.platform for d in jax.devices()}))
    return {"gnipy_version": gnipy_version, "python": sys.version.split()[0],
            "jax_version": f"{jax.__version__} ({devices}, x64 {'on' if jax.config.jax_enable_x64 else 'off'})"}


def _failed_figure(name: str, error: BaseException):
    """A figure result that records a stage failure (no files)."""
    try:
        from .figures import FigureResult
    except ImportError:
        FigureResult = None
    fields = dict(name=name.replace("_", ""), title=f"{name.replace('_', ' ').capitalize()} — FAILED",
                  caption="This figure could not be produced.", files=[], metrics={}, table=[],
                  notes=[f"FAILED: {type(error).__name__}: {error}"])
    if FigureResult is not None:
        return FigureResult(**fields)
    return _SimpleFigure(**fields)


@dataclasses.dataclass
class _SimpleFigure:
    name: str
    title: str
    caption: str
    files: list
    metrics: dict
    table: list
    notes: list


def _figure_functions() -> dict[str, Callable | BaseException]:
    """`figure_1` .. `figure_3` from :mod:`.figures`, imported lazily (or the import error)."""
    try:
        from . import figures
    except Exception as e:  # the module may be missing or broken: report it, run the rest
        return {name: e for name in FIGURE_NAMES}
    return {name: getattr(figures, name, AttributeError(f"figures has no {name}")) for name in FIGURE_NAMES}


def _console(stderr: bool = False):
    from rich.console import Console

    return Console(stderr=stderr, highlight=False, soft_wrap=True)


def run_reproduction(out_dir: Path, quick: bool, *, console=None) -> ReproductionResult:
    """Run every stage and write the report (see :func:`reproduce`); returns everything produced."""
    from rich.progress import (
        BarColumn,
        Progress,
        SpinnerColumn,
        TaskProgressColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    from .report import write_report
    from .theorems import Row, errata_rows, theorem_table

    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    console = console or _console()
    figure_fns = _figure_functions()
    stages: list[tuple[str, str]] = [(name, f"Figure {name[-1]}") for name in FIGURE_NAMES]
    stages += [("theorems", "Theorem table"), ("errata", "Errata"), ("struggles", "Where the GNI struggles")]
    figures, theorems, errata, struggles, failures, stage_times = [], [], [], [], [], {}

    err_console = _console(stderr=True)
    columns = (SpinnerColumn(), TextColumn("{task.description:<44.44}", markup=False), BarColumn(bar_width=20),
               TaskProgressColumn(), TimeElapsedColumn())
    with Progress(*columns, console=err_console, disable=not err_console.is_terminal) as progress:
        tasks = {key: progress.add_task(f"{label}: waiting", total=1.0, start=False) for key, label in stages}
        for key, label in stages:
            task = tasks[key]
            progress.start_task(task)
            progress.update(task, description=f"{label}: starting")

            def advance(adv: float, description: str, task=task) -> None:
                progress.update(task, advance=max(float(adv), 0.0), description=description)

            t0 = time.perf_counter()
            try:
                if key in figure_fns:
                    fn = figure_fns[key]
                    if isinstance(fn, BaseException):
                        raise fn
                    figures.append(fn(out_dir, quick, advance))
                elif key == "theorems":
                    theorems = theorem_table(quick, advance)
                elif key == "struggles":
                    from .struggles import struggle_figures

                    struggles = struggle_figures(out_dir, quick, advance)
                else:
                    errata = errata_rows(quick, advance)
                progress.update(task, completed=1.0, description=f"{label}: done")
            except Exception as e:  # one failed stage must not lose the others' results
                failures.append(f"{label}: {type(e).__name__}: {e}")
                detail = "".join(traceback.format_exception_only(type(e), e)).strip()
                if key in figure_fns:
                    figures.append(_failed_figure(key, e))
                elif key == "theorems":
                    theorems = [Row(claim="the theorem table could be computed", paper_ref="—", expected="no error",
                                    measured="error", passed=False, detail=detail)]
                progress.update(task, completed=1.0, description=f"{label}: FAILED")
            stage_times[label] = time.perf_counter() - t0

    runtime = time.perf_counter() - t_start
    meta = {
        **_versions(),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": _machine(),
        "mode": "quick (--quick)" if quick else "full",
        "runtime_s": runtime,
        "stage_runtimes_s": stage_times,
    }
    if failures:
        meta["failed_stages"] = "; ".join(failures)
    md_path, html_path = write_report(out_dir, figures, theorems, errata, meta, struggles)
    result = ReproductionResult(html_path, md_path, figures, theorems, errata, failures,
                                time.perf_counter() - t_start, struggles)
    _print_summary(console, result, quick)
    return result


def _print_summary(console, result: ReproductionResult, quick: bool) -> None:
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=f"Theorem table ({'quick' if quick else 'full'} run)", show_lines=False, expand=True)
    table.add_column("#", justify="right")
    table.add_column("claim (paper)", overflow="fold", ratio=4)
    table.add_column("expected", overflow="fold", ratio=2)
    table.add_column("measured", overflow="fold", ratio=2)
    table.add_column("result", no_wrap=True)
    for i, r in enumerate(result.theorems, 1):
        table.add_row(str(i), escape(f"{r.claim} ({r.paper_ref})"), escape(r.expected), escape(r.measured),
                      "[green]PASS[/green]" if r.passed else "[bold red]FAIL[/bold red]")
    console.print(table)
    n_pass = sum(r.passed for r in result.theorems)
    console.print(f"{n_pass} of {len(result.theorems)} theorem rows pass; {len(result.errata)} errata measured; "
                  f"{len(result.figures)} figures; {result.runtime_s:.1f} s.")
    for f in result.failures:
        console.print(f"[bold red]stage failed[/bold red] {escape(f)}")
    console.print(f"Report: {escape(str(result.report))} (self-contained HTML) and {escape(str(result.markdown))}")


def reproduce(out_dir: Path, quick: bool) -> Path:
    """Reproduce the paper's figures 1–3, measure its theorems and errata, and write the report.

    Arguments:
        out_dir: the output folder (created if missing): `figure1.png`, `figure1.pdf`, …,
            `report.md` and the self-contained `report.html`.
        quick: the short run (under a minute on two cores): fewer step sizes, shorter runs.

    Returns:
        The path of the HTML report.
    """
    return run_reproduction(Path(out_dir), quick).report


def reproduce_command(
    out: Path = typer.Option(Path("gnipy-reproduction"), "--out",
                             help="Output folder for the figures (PNG, PDF) and the report (report.md, report.html)."),
    quick: bool = typer.Option(False, "--quick",
                               help="Short run, under a minute: fewer step sizes and shorter runs (full: a few minutes)."),
) -> None:
    """Reproduce the paper: figures 1–3 (§7.4), the theorem table (orders of Thm 5.1 and the
    remarks, adjointness of Thm 5.2, exact constraints, energy conservation on SO(3), the explicit
    schemes equal to the GNI) and the errata, each measured by running gnipy; writes report.md and
    a self-contained report.html into --out. Exits with code 1 if a theorem row fails or a stage
    fails."""
    out = Path(out)
    if "\x00" in str(out) or out.exists() and not out.is_dir():
        typer.echo(f"Error: --out: {str(out)!r} is not a directory", err=True)
        raise typer.Exit(2)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        typer.echo(f"Error: --out: cannot create the folder {str(out)!r}: {e.strerror or e}", err=True)
        raise typer.Exit(2) from None
    result = run_reproduction(out, quick)
    if not result.ok:
        raise typer.Exit(1)
