"""Reproduce the paper in one call: figures 1–3, the theorem table, the errata, where the GNI
struggles (measured failures beyond the paper, :mod:`~gnipy.experiments.struggles`), and the report.

:func:`reproduce` runs every stage with a rich progress display (one bar per stage, fed by the
stages' `progress(advance, description)` callbacks), writes `report.md` and the self-contained
`report.html` (:func:`gnipy.experiments.report.write_report`) next to the figures, prints a short
summary and returns the path of the HTML report. The command `gni reproduce`
(:mod:`gnipy.cli.reproduce`) exits with code 1 when a theorem row fails or a stage fails.

A stage that raises does not stop the others: its failure is recorded in the report (a figure
with the error as its note, or a failed theorem row) and makes the command exit non-zero.

**The output folder** (:func:`check_output_dir`). A folder that does not exist is created with
gnipy's marker `.gnipy-owned`, and in such a folder a rerun replaces gnipy's own files (so
`gni reproduce` can always be run again into its own folder). In a folder gnipy did not create,
existing files of the names in :data:`OUTPUT_FILES` are replaced only with `overwrite=True`
; without it the run is refused before anything is computed. Every file is written
atomically (:mod:`gnipy.files`): a full disk leaves earlier files as they were, and the command
ends with a one-line message and exit code 1.
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import platform
import time
import traceback
from collections.abc import Callable
from pathlib import Path

__all__ = ["reproduce", "ReproductionResult", "run_reproduction", "check_output_dir",
           "OUTPUT_FILES"]

FIGURE_NAMES = ("figure_1", "figure_2", "figure_3")

#: The files a reproduction writes into its folder (the figures of :mod:`~gnipy.experiments.figures` and
#: :mod:`~gnipy.experiments.struggles`, PNG and PDF, and the report).
OUTPUT_FILES = tuple(
    f"{stem}.{ext}"
    for stem in ("figure1", "figure2", "figure3", "struggles_sleigh", "struggles_suslov", "struggles_oscillator")
    for ext in ("png", "pdf")
) + ("report.md", "report.html")


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


def machine_description() -> str:
    """The machine a report was made on: host name, operating system, processor and CPU count."""
    import os

    cpu = platform.processor() or platform.machine()
    return f"{platform.node()} ({platform.system()} {platform.release()}, {cpu}, {os.cpu_count()} CPUs)"


def version_info() -> dict:
    """The versions a report was made with: gnipy, Python and JAX (with its devices and whether x64 is on)."""
    import sys

    import jax

    from ..version import __version__

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
    """`figure_1` .. `figure_3` from :mod:`~gnipy.experiments.figures`, imported lazily (or the import error)."""
    try:
        from . import figures
    except Exception as e:  # the module may be missing or broken: report it, run the rest
        return {name: e for name in FIGURE_NAMES}
    return {name: getattr(figures, name, AttributeError(f"figures has no {name}")) for name in FIGURE_NAMES}


def _console(stderr: bool = False):
    from rich.console import Console

    return Console(stderr=stderr, highlight=False, soft_wrap=True)


def check_output_dir(out_dir, overwrite: bool = False, files=OUTPUT_FILES) -> Path:
    """Check, before anything is computed, that a reproduction may write into `out_dir`.

    Allowed: a folder that does not exist and can be created; a folder gnipy created (marker
    `.gnipy-owned`); any other folder when none of `files` (default :data:`OUTPUT_FILES`; the
    atlas passes its own) is there, or with `overwrite`. Never: a symbolic link, directory or
    special file at one of those names.

    Raises:
        gnipy.files.OutputError: the message (starting with `out_dir:`) says why.
    """
    from ..files import MARKER, OutputError, check_destination, is_owned_dir

    out_dir = Path(out_dir)
    text = str(out_dir)
    if "\x00" in text:
        raise OutputError(f"out_dir: {text!r}: a path cannot contain a NUL character")
    if not out_dir.exists():
        if out_dir.is_symlink():
            raise OutputError(f"out_dir: {text!r} is a dangling symbolic link")
        parent = out_dir.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise OutputError(f"out_dir: cannot create the folder {text!r}: {str(parent)!r} is not a directory")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise OutputError(f"out_dir: cannot create the folder {text!r}: {str(parent)!r} is not writable")
        return out_dir
    if not out_dir.is_dir():
        raise OutputError(f"out_dir: {text!r} is not a directory")
    replace = overwrite or is_owned_dir(out_dir)
    taken = []
    for name in files:
        check_destination(out_dir / name, overwrite=True, argument="out_dir")  # links, special files: never
        if (out_dir / name).exists():
            taken.append(name)
    if taken and not replace:
        raise OutputError(
            f"out_dir: {text!r} is a folder gnipy did not create (no {MARKER} marker) and already holds "
            f"{', '.join(taken[:4])}{', ...' if len(taken) > 4 else ''}; pass overwrite=True to replace gnipy's "
            "files there, or choose another folder"
        )
    return out_dir


def run_reproduction(out_dir: Path, quick: bool, *, console=None, overwrite: bool = False,
                     progress=None) -> ReproductionResult:
    """Run every stage and write the report (see :func:`reproduce`); returns everything produced.

    `overwrite`: replace the files of a reproduction in a folder gnipy did not create (see the
    module docstring; :func:`check_output_dir` is checked first, before anything is computed).
    `progress`: optional `progress(stages_done, stages, stage)` called as each stage starts and at
    the end (`gni reproduce` prints it as plain lines when stderr is not a terminal).

    Raises:
        gnipy.files.OutputError: the folder may not be written (see :func:`check_output_dir`), or
            the report could not be written (a full disk); a figure that cannot be written is a
            failed stage, recorded in the report."""
    from .report import ensure_output_dir, overwriting

    t_start = time.perf_counter()
    out_dir = ensure_output_dir(check_output_dir(out_dir, overwrite))
    with overwriting(overwrite):
        return _run_stages(out_dir, quick, console or _console(), t_start, progress)


def _run_stages(out_dir: Path, quick: bool, console, t_start: float, report_stage=None) -> ReproductionResult:
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

    figure_fns = _figure_functions()
    stages: list[tuple[str, str]] = [(name, f"Figure {name[-1]}") for name in FIGURE_NAMES]
    stages += [("theorems", "Theorem table"), ("errata", "Errata"), ("struggles", "Where the GNI struggles")]
    figures, theorems, errata, struggles, failures, stage_times = [], [], [], [], [], {}

    err_console = _console(stderr=True)
    columns = (SpinnerColumn(), TextColumn("{task.description:<44.44}", markup=False), BarColumn(bar_width=20),
               TaskProgressColumn(), TimeElapsedColumn())
    with Progress(*columns, console=err_console, disable=not err_console.is_terminal) as progress:
        tasks = {key: progress.add_task(f"{label}: waiting", total=1.0, start=False) for key, label in stages}
        for i, (key, label) in enumerate(stages):
            if report_stage is not None:
                report_stage(i, len(stages), label)
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
        if report_stage is not None:
            report_stage(len(stages), len(stages), "report")

    runtime = time.perf_counter() - t_start
    meta = {
        **version_info(),
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "machine": machine_description(),
        "mode": "quick" if quick else "full",
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

    from ..text import safe as _safe

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
        console.print(f"[bold red]stage failed[/bold red] {escape(_safe(f))}")
    console.print(f"Report: {escape(_safe(result.report))} (self-contained HTML) and "
                  f"{escape(_safe(result.markdown))}")


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
