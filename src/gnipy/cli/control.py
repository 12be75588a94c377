"""`gni control`: solve a discrete optimal-control problem from a TOML problem file (or a worked
problem) and write the controlled run with its inputs to netCDF (and a figure).

The problem file's format is that of :mod:`gnipy.control.problems`; `gni control --example NAME
--print` prints a worked problem's file to start from.
"""

from __future__ import annotations

import dataclasses

import time
from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded, writing
from .output import report_result, safe
from .held import hold
from .paths import check_out_and_plot, check_readable
from .progress import Progress
from .resources import check_result_file, memory_bound
from .run import write_plot

__all__ = ["CONTROL_KEYWORDS", "CONTROL_OPTIONS", "control", "plot_title"]

#: What gnipy's error messages name (`steps: ...`), as the keys of a control problem file that set it:
#: every message of `gni control` names a key of the file or one of its options.
CONTROL_OPTIONS = {
    "system": "system.model",
    "model": "system.model",
    "params": "system.params",
    "lagrangian": "system.params/start.q0",
    "constraints": "system.params/start.q0",
    "affine": "system.params/start.q0",
    "force": "inputs",
    "inputs": "inputs",
    "input_names": "inputs",
    "q0": "start.q0",
    "v0": "start.v0",
    "q0/v0": "start.q0/start.v0",
    "R0": "start.R0",
    "project_v0": "start.project_v0",
    "h": "horizon.h",
    "steps": "horizon.steps",
    "steps/t_final": "horizon.steps",
    "target": "target",
    "method": "solver.method",
    "bounds": "solver.bounds",
    "effort": "solver.effort",
    "smoothness": "solver.smoothness",
    "max_iterations": "solver.max_iterations",
    "segments": "solver.segments",
    "starts": "solver.starts (or --starts)",
    "optimizer": "solver.optimizer (or --optimizer)",
    "controls0": "warm_start",
    "controls": "warm_start",
}
#: The keyword arguments gnipy's messages suggest, as what `gni control` takes instead.
CONTROL_KEYWORDS = {"max_bytes=None": "--yes", "project_v0=True": "project_v0 = true in [start]",
                    "overwrite=True": "--overwrite"}


def plot_title(text: str) -> str:
    """`text` (a name from a file) as a figure title shown literally: control characters escaped
    (:func:`gnipy.text.safe`) and `$` not read as the start of matplotlib's mathematics (an unclosed
    `$x^` would fail when the figure is drawn)."""
    return safe(text).replace("$", r"\$")


@app.command()
def control(
    problem: Path | None = typer.Argument(
        None, help="A TOML problem file (see the control guide), or none with --example.", show_default=False,
        metavar="PROBLEM",
    ),
    example: str | None = typer.Option(
        None, "--example", help="A worked problem instead of a file: sleigh-steering or ball-plate.",
        show_default=False,
    ),
    print_problem: bool = typer.Option(
        False, "--print", help="Print the problem file (of --example: a template to edit) and exit.",
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Output netCDF file.", show_default=False),
    plot: Path | None = typer.Option(
        None, "--plot", help="Also write a figure (path, inputs, velocities and, on R^n x G, the angle the "
        "body turned), e.g. control.png.",
        show_default=False,
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace existing --out and --plot files."),
    yes: bool = typer.Option(
        False, "--yes", help="Solve even when the memory or the file the problem needs is estimated beyond gnipy's "
        "bounds (the SQP's matrices grow as the square of steps x inputs).",
    ),
    starts: int | None = typer.Option(
        None, "--starts", help="A multistart: the warm start and STARTS - 1 random ones on the same compiled "
        "functions; returns the best and lists the distinct local optima (default: the file's solver.starts, or 1).",
        show_default=False, min=1, max=1000,
    ),
    optimizer: str | None = typer.Option(
        None, "--optimizer", help="slsqp (SciPy's SLSQP) or ipopt (IPOPT with the exact Hessian; the ipopt extra) "
        "(default: the file's solver.optimizer, or slsqp).", show_default=False,
    ),
):
    """Solve an optimal-control problem on the GNI's steps and write the controlled run.

    The problem (a TOML file, or a worked problem with --example) names a model, how the inputs act
    on it, the start, the horizon (h, steps), the target and the solver's options. The solution
    (direct shooting with SQP on exact gradients, then Gauss-Newton polish; gnipy.control)
    is written to --out: the run's nodes as `gni run` writes them, the inputs u(control_step,
    input) and the solver's figures (cost, target and KKT residuals, iterations) as attributes.
    It exits with code 1 when the solver does not converge (the file is written all the same).
    A problem whose memory (or result file) is estimated beyond gnipy's bounds is refused before
    anything is computed, naming horizon.steps; --yes solves it anyway.
    """

    def go():
        source = _problem_source(problem, example)
        if print_problem:
            from gnipy.control.problem_files import problem_text

            # the file as read for solving (UTF-8, bounded in size), printed as it is: a template
            text = source if isinstance(source, str) else problem_text(source)
            typer.echo(text, nl=not text.endswith("\n"))
            return
        _solve(source, example, out=out, plot=plot, overwrite=overwrite, yes=yes, starts=starts, optimizer=optimizer)

    guarded(go, method_option="solver.method", options=CONTROL_OPTIONS, keywords=CONTROL_KEYWORDS,
            out_of_memory="out of memory: use fewer steps (horizon.steps) or inputs")


def _problem_source(problem: Path | None, example: str | None):
    """The problem to solve: the text of the worked problem `example`, or the file `problem`
    (checked readable); UsageError unless exactly one of them is given."""
    from gnipy.control.problems import WORKED_PROBLEMS

    if (problem is None) == (example is None):
        raise UsageError("PROBLEM", "give a problem file or --example NAME (one of them)")
    if example is not None:
        if example not in WORKED_PROBLEMS:
            raise UsageError("--example", f"unknown worked problem {example!r}; expected one of "
                             f"{', '.join(WORKED_PROBLEMS)}")
        return WORKED_PROBLEMS[example]
    check_readable(problem, "PROBLEM")
    return problem


def _solve(source, example: str | None, *, out: Path | None, plot: Path | None, overwrite: bool, yes: bool,
           starts: int | None = None, optimizer: str | None = None) -> None:
    """Solve the problem `source` (the text of `example`, or a file) and write --out (and --plot),
    within gnipy's bounds on memory and file size unless `yes`; then report."""
    from gnipy.control.problems import load_problem, write_control_result

    check_out_and_plot(out, plot, overwrite)
    hold("--out", out)  # one writer per output: a second solve into it is refused now, not at the end
    hold("--plot", plot)
    # the memory bound is checked as the problem is read (before its warm start is built)
    bound = None if yes else memory_bound()
    prob = load_problem(source, name=example or "problem", max_bytes=bound)
    if not yes:
        check_result_file(prob.system, prob.steps + 1, out, "horizon.steps")
    start = time.perf_counter()
    if starts is not None:  # --starts over the file's solver.starts
        prob = dataclasses.replace(prob, starts=starts)
    if optimizer is not None:  # --optimizer over the file's solver.optimizer (checked by the solve)
        prob = dataclasses.replace(prob, optimizer=optimizer)
    with Progress("control", prob.max_iterations * prob.starts, "iterations",
                  description=f"{prob.name}: compiling and iterating") as progress:
        # the total grows when the optimizer fails and its fallback starts (SLSQP: trust-constr, then SLSQP;
        # IPOPT: the SLSQP chain)
        def report(i, cost, miss, total):
            progress.update(i, total=total, description=f"{prob.name}: cost {cost:.6g}, target miss {miss:.1e}")

        result = prob.solve(progress=report, max_bytes=bound)
    seconds = time.perf_counter() - start
    with writing("--out", out):
        write_control_result(result, prob, out, overwrite=overwrite)
    written = str(out)
    if plot is not None:
        from gnipy.plots import plot_control

        write_plot(result, plot, overwrite, plot_control, title=plot_title(f"{prob.name}: {result.method}"))
        written += f", {plot}"
    report_result("gni control", prob.name, result, written, seconds)
