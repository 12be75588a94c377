"""`gni sweep`: the options of a parameter sweep (:func:`gnipy.sweep.run_sweep`), its messages
and its summary."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import typer

from .app import app
from .errors import ARGUMENT_OPTIONS, UsageError, guarded, option_message
from .output import EXIT_FAILURE, EXIT_USAGE, console, exit_for_health, fail, safe, warn
from .parsing import check_positive, parse_set
from .progress import Progress, on_terminal
from .held import hold

__all__ = ["SWEEP_OPTIONS", "failures_message", "sweep", "sweep_message", "sweep_report"]

#: The argument names of gnipy.sweep's error messages (`grid: ...`) and the option of each.
SWEEP_OPTIONS = {
    **ARGUMENT_OPTIONS,
    "grid": "--grid",
    # gni sweep has no --q0/--v0: a member's initial condition comes from the model and the grid
    "q0": "--grid",
    "v0": "--grid",
    "q0/v0": "--grid",
    "out": "--out",
    "chunk_size": "--chunk-size",
    "workers": "--workers",
    "scheduler": "--scheduler",
    "set_params": "--set",
    "save_every": "--save-every",
    "method": "--method",
    "max_chunks": "--max-chunks",
    "connect_timeout": "--connect-timeout",
    "max_bytes": "--yes",
}

# the arguments gnipy.sweep's messages suggest changing, as the options
_SWEEP_HINTS = (("overwrite=True", "--overwrite"), ("project_v0=True", "--project-v0"), ("set_params", "--set"),
                ("pass max_bytes=None", "pass --yes"), ("the bound max_bytes = ", "the bound of "),
                ("a smaller chunk_size", "a smaller --chunk-size"), ("a larger save_every", "a larger --save-every"),
                ("raise connect_timeout", "raise --connect-timeout"),
                ("write the store elsewhere", "choose another --out"))


def sweep_message(message: str) -> str:
    """A gnipy.sweep error message with its argument names written as the CLI options."""
    message = option_message(message, SWEEP_OPTIONS)
    for name, option in _SWEEP_HINTS:
        message = message.replace(name, option)
    return message


def sweep_report(report, spec: dict[str, Any]) -> None:
    """Print what a sweep ran, how many chunks were computed, skipped, repaired or remain, its
    failed members and its rate."""
    from gnipy.sweep import GridAxis

    con = console()
    axes = [GridAxis(**g) for g in spec["grid"]]
    fixed = ", ".join(f"{k}={v:g}" for k, v in spec["params"].items())
    con.print(f"gni sweep: {spec['model']}" + (f" ({fixed})" if fixed else "") + f" with {spec['method']}, "
              f"h = {spec['h']:g}, {spec['steps']} steps, saved every {spec['save_every']}", markup=False)
    grid = " x ".join(f"{a.name} = {a.start:g} .. {a.stop:g} ({a.count})" for a in axes)
    con.print(f"  grid: {grid}: {report.members} members in {report.chunks} chunk(s) of {report.chunk_size}",
              markup=False)
    con.print(f"  chunks: {report.chunks_computed} computed, {report.chunks_skipped} skipped (done before), "
              f"{report.chunks_remaining} remaining", markup=False)
    repaired = getattr(report, "chunks_repaired", 0)
    if repaired:
        con.print(f"  damaged chunks found and computed again: {repaired}", markup=False)
    con.print(f"  failed members: {report.failed_members}", markup=False)
    unhealthy = getattr(report, "unhealthy_members", 0)
    con.print(f"  qualitatively wrong members (converged, a verdict out of band): {unhealthy}", markup=False)
    if unhealthy:
        warn(f"WARNING: {unhealthy} of {report.members} members went qualitatively wrong (see the store's "
             "variables healthy, hidden_momentum_first_time and energy_drift_first_time)")
    rate = ""
    if report.members_computed:
        rate = (f"; {report.members_computed / report.wall_time:.3g} members/s, "
                f"{report.member_steps_per_second:.3g} member-steps/s")
    con.print(f"  time: {report.wall_time:.2f} s (including cluster start and compilation){rate}", markup=False)
    if report.complete:
        con.print(f"written: {safe(report.path)}", markup=False)
    else:
        con.print(f"written (incomplete, run the same command again to resume): {safe(report.path)}", markup=False)


@app.command()
def sweep(
    model: str = typer.Argument(
        ..., help="Model name (see `gni models`), or your own system: FILE.py:NAME or module:NAME, "
        "NAME a function returning a gnipy.System (its number-valued keyword parameters are what --set "
        "reaches).",
        show_default=False, metavar="MODEL"),
    grid: list[str] | None = typer.Option(
        None, "--grid", "-g", help="A grid axis NAME=linspace(START, STOP, COUNT), or its short form "
        "NAME=START:STOP:COUNT (the same values: COUNT values, not a step); NAME is a parameter, "
        "q0.<coordinate> or v0.<velocity> (e.g. m=linspace(0.5, 2, 10), q0.x=-1:1:5, v0.omega3=0:1:3). "
        "Repeatable: the sweep is the Cartesian product.", show_default=False,
    ),
    method: str | None = typer.Option(
        None, "--method", "-m", help="Method name (see `gni methods`). [default: the model's, see `gni models`]",
        show_default=False,
    ),
    h: float | None = typer.Option(None, "--h", help="Step size (> 0).", show_default=False),
    steps: int | None = typer.Option(
        None, "--steps", help="Number of steps (give this or --t-final).", show_default=False
    ),
    t_final: float | None = typer.Option(
        None, "--t-final", help="Final time, a whole number of steps (give this or --steps).", show_default=False
    ),
    save_every: int | None = typer.Option(
        None, "--save-every", help="Save every K-th node (and always the last). [default: the number of steps: "
        "only the initial and the last node]", show_default=False,
    ),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Fix a parameter that is not swept, NAME=VALUE (repeatable, or comma-separated).",
        show_default=False,
    ),
    project_v0: bool = typer.Option(
        True, "--project-v0/--no-project-v0", help="Project each member's initial velocity onto its constraints "
        "(on by default for sweeps: a v0 grid, or parameters that change the constraints, move v0 off them).",
    ),
    chunk_size: int = typer.Option(
        1000, "--chunk-size", help="Members per task (one vmapped batch) and per zarr chunk along `member`."
    ),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="An existing dask scheduler: its address, e.g. tcp://host:8786, or a scheduler "
        "file (JSON); its workers need gnipy. [default: start a local cluster]", show_default=False,
    ),
    connect_timeout: float = typer.Option(
        10.0, "--connect-timeout", help="Seconds to wait for the connection to --scheduler.",
    ),
    workers: int | None = typer.Option(
        None, "--workers", help="Number of worker processes of the local cluster. [default: the number of cores]",
        show_default=False,
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace an existing sweep store at --out (only one gnipy created) and start "
        "afresh (without it, the same sweep is resumed).",
    ),
    max_chunks: int | None = typer.Option(
        None, "--max-chunks", help="Compute at most this many chunks, then stop (run again to go on), e.g. under "
        "a batch-job time limit.", show_default=False,
    ),
    yes: bool = typer.Option(
        False, "--yes", help="Create a store larger than 100 GiB (estimated, uncompressed): lift the size bound. "
        "(The free disk space is checked anyway.)",
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output zarr store, a directory (e.g. sweep.zarr); its parent must exist.",
        show_default=False,
    ),
    accept_out_of_band: bool = typer.Option(
        False, "--accept-out-of-band", help="Exit 0 even when members went qualitatively wrong (a verdict out of "
        "band at some step), which otherwise exits with code 3 (the store is written all the same).",
    ),
):
    """Run MODEL over a grid of parameters and initial conditions on a dask cluster; write zarr.

    The members (the grid's Cartesian product) run in chunks of --chunk-size, each one vmapped
    batch, on a local dask.distributed cluster (or an existing one: --scheduler), and each chunk
    is written to the zarr store OUT as it completes, with a progress display on a terminal.
    Running the same command again resumes an interrupted sweep: the chunks already written are
    read back and checked, and skipped (a damaged one is computed again). Read the result with
    gnipy.sweep.open_sweep(OUT), which gives the grid axes as dimensions.

    Exit codes: 0 when every member ran; 1 when members failed (the store is written, and the
    first failed members are listed), a chunk failed on the cluster or the store cannot be
    written; 2 for bad input (also a store that holds another sweep or is damaged, a sweep over
    the size bound, or a scheduler that cannot be reached); 3 when members converged but went
    qualitatively wrong (the store's variable `healthy`; --accept-out-of-band: 0).
    """

    def go():
        return _sweep(model, grid, method=method, h=h, steps=steps, t_final=t_final, save_every=save_every, set_=set_,
                      project_v0=project_v0, chunk_size=chunk_size, scheduler=scheduler,
                      connect_timeout=connect_timeout, workers=workers, overwrite=overwrite, max_chunks=max_chunks,
                      yes=yes, out=out)

    exit_for_health(guarded(go), accept_out_of_band)


def _sweep(model, grid, *, method, h, steps, t_final, save_every, set_, project_v0, chunk_size, scheduler,
           connect_timeout, workers, overwrite, max_chunks, yes, out) -> bool:
    """`gni sweep` with the command line's options: checks them, runs the sweep, prints its
    summary; returns whether no member went qualitatively wrong (failed members: exit code 1)."""
    import gnipy.sweep as sweep_module
    from gnipy.sweep import SweepError, SweepFailure, run_sweep

    if not grid:
        raise UsageError("--grid", "missing: give at least one --grid NAME=linspace(START, STOP, COUNT)")
    check_positive("--h", h)
    if h is None:
        raise UsageError("--h", "missing: give --h")
    if (steps is None) == (t_final is None):
        raise UsageError("--steps/--t-final", "give exactly one of --steps and --t-final")
    check_positive("--steps", steps, "integer")
    check_positive("--t-final", t_final)
    set_params = parse_set(set_)
    hold("--out", out)  # one writer per store: a second sweep into it is refused now

    def run(progress):
        return run_sweep(
            model, list(grid), out=out, h=h, steps=steps, t_final=t_final, method=method,
            save_every=save_every, set_params=set_params, project_v0=project_v0, chunk_size=chunk_size,
            scheduler=scheduler, workers=workers, overwrite=overwrite, max_chunks=max_chunks,
            progress=progress, max_bytes=None if yes else sweep_module.DEFAULT_MAX_BYTES,
            connect_timeout=connect_timeout,
        )

    try:
        report = _shown(run)
    except SweepError as e:
        fail(sweep_message(str(e)), EXIT_USAGE)
    except SweepFailure as e:
        fail(f"{e}; the chunks done are kept: run the same command again to resume", EXIT_FAILURE)
    except KeyboardInterrupt:
        fail("interrupted; the chunks done are kept: run the same command again to resume", 130)
    sweep_report(report, report.spec)
    if report.failed_members:
        fail(failures_message(report), EXIT_FAILURE)
    return getattr(report, "unhealthy_members", 0) == 0


def _shown(run):
    """`run(progress)`, a sweep, shown: each :class:`~gnipy.sweep.SweepWarning` (a damaged chunk
    computed again) as one line, and its progress: on a terminal the sweep's own bar (chunks,
    members/s); elsewhere plain lines (the sweep calls `progress(chunks_done, chunks_total)`, and
    the last line is written from its report). Returns the sweep's report."""
    import warnings

    from gnipy.sweep import SweepWarning

    original = warnings.showwarning

    def show(message, category, *args, **kwargs):  # a damaged chunk computed again: one line
        if not issubclass(category, SweepWarning):
            return original(message, category, *args, **kwargs)
        typer.echo("warning: " + safe(" ".join(sweep_message(str(message)).split())), err=True)

    terminal = on_terminal()
    lines = Progress("sweep", unit="chunks", terminal=False, heartbeat=not terminal)
    with warnings.catch_warnings(), lines:
        warnings.simplefilter("always", SweepWarning)
        warnings.showwarning = show
        report = run(True if terminal else lines)
        if not terminal:
            lines.update(report.chunks - report.chunks_remaining, report.chunks)
    return report


def failures_message(report) -> str:
    """The error line of a sweep with failed members: how many, and the first few."""

    def one(f) -> str:
        grid = ", ".join(f"{k}={v:.6g}" for k, v in f["grid"].items())
        residual = "n/a" if math.isnan(f["residual"]) else f"{f['residual']:.3e}"
        return f"member {f['member']} ({grid}): step {f['step']}, t = {f['time']:.6g}, residual {residual}"

    listed = "; ".join(one(f) for f in report.failures)
    more = ", ..." if report.failed_members > len(report.failures) else ""
    return (f"{report.failed_members} of {report.members} members failed (a step's solve did not converge): "
            f"{listed}{more}. Their data are NaN after their failed step (result = 1; failed_step, failed_time, "
            "failed_residual in the store); the others are written")
