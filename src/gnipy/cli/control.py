"""`gni control`: solve a discrete optimal-control problem from a TOML problem file (or a worked
problem) and write the controlled run with its inputs to netCDF (and a figure).

The problem file's format is that of :mod:`gnipy.control.problems`; `gni control --example NAME
--print` prints a worked problem's file to start from.
"""

from __future__ import annotations

import time
from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded, writing
from .output import report_result
from .paths import check_out_and_plot, check_readable
from .progress import Progress
from .run import write_plot

__all__ = ["control"]


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
        None, "--plot", help="Also write a figure (path, inputs, velocities, angle turned), e.g. control.png.",
        show_default=False,
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace existing --out and --plot files."),
):
    """Solve an optimal-control problem on the GNI's steps and write the controlled run.

    The problem (a TOML file, or a worked problem with --example) names a model, how the inputs act
    on it, the start, the horizon (h, steps), the target and the solver's options. The solution
    (direct shooting with SQP on exact gradients, then Gauss-Newton polish; gnipy.control)
    is written to --out: the run's nodes as `gni run` writes them, the inputs u(control_step,
    input) and the solver's figures (cost, target and KKT residuals, iterations) as attributes.
    It exits with code 1 when the solver does not converge (the file is written all the same).
    """
    from gnipy.control.problems import WORKED_PROBLEMS

    def go():
        from gnipy.control.problems import load_problem, write_control_result

        if (problem is None) == (example is None):
            raise UsageError("PROBLEM", "give a problem file or --example NAME (one of them)")
        if example is not None:
            if example not in WORKED_PROBLEMS:
                raise UsageError("--example", f"unknown worked problem {example!r}; expected one of "
                                 f"{', '.join(WORKED_PROBLEMS)}")
            source = WORKED_PROBLEMS[example]
        else:
            check_readable(problem, "PROBLEM")
            source = problem
        if print_problem:
            text = source if isinstance(source, str) else Path(source).read_text(encoding="utf-8")
            typer.echo(text, nl=not text.endswith("\n"))
            return
        check_out_and_plot(out, plot, overwrite)
        prob = load_problem(source, name=example or "problem")
        start = time.perf_counter()
        with Progress("control", prob.max_iterations, "iterations",
                      description=f"{prob.name}: compiling and iterating") as progress:
            def report(i, cost, miss):
                progress.update(i, description=f"{prob.name}: cost {cost:.6g}, target miss {miss:.1e}")

            result = prob.solve(progress=report)
        seconds = time.perf_counter() - start
        with writing("--out", out):
            write_control_result(result, prob, out, overwrite=overwrite)
        written = str(out)
        if plot is not None:
            from gnipy.plots import plot_control

            write_plot(result, plot, overwrite, plot_control, title=f"{prob.name}: {result.method}")
            written += f", {plot}"
        report_result("gni control", prob.name, result, written, seconds)

    guarded(go)
