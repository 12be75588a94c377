"""`gni fit`: estimate a model's parameters (and/or its initial condition) from an observed run,
as a TOML problem file says, and write the fitted run with the estimates to netCDF (and a figure).

The problem file's format is that of :func:`gnipy.control.problems.load_fit_problem`.
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

__all__ = ["fit"]


@app.command()
def fit(
    problem: Path = typer.Argument(..., help="A TOML fit problem file (see the control guide).", show_default=False,
                                   metavar="PROBLEM"),
    out: Path | None = typer.Option(None, "--out", "-o", help="Output netCDF file.", show_default=False),
    plot: Path | None = typer.Option(
        None, "--plot", help="Also write a figure (observed and fitted variables, residuals), e.g. fit.png.",
        show_default=False,
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace existing --out and --plot files."),
):
    """Fit a model's parameters and/or initial condition to an observed run (gnipy.fit).

    The problem file names the model, the parameters to estimate with their initial guesses, the
    observation file (a gnipy result file, e.g. from `gni run`; some of its coordinates or
    velocities), the measurement error if known, the start and the integration (method, h). The
    fit is Levenberg-Marquardt least squares through the differentiated simulation; the standard
    errors come from the Jacobian. --out gets the fitted run's nodes, estimate(quantity),
    standard_error(quantity), covariance(quantity, quantity_) and the fit's chi2 and iterations
    as attributes. It exits with code 1 when the fit does not converge (the file is written all
    the same).
    """

    def go():
        from gnipy.control.problems import load_fit_problem, write_fit_result

        check_readable(problem, "PROBLEM")
        check_out_and_plot(out, plot, overwrite)
        prob = load_fit_problem(problem)
        start = time.perf_counter()
        with Progress("fit", None, "iterations", description=f"{prob.name}: compiling and iterating") as progress:
            def report(i, chi2):
                progress.update(i + 1, description=f"{prob.name}: chi2 {chi2:.6g}")

            result = prob.solve(progress=report)
        seconds = time.perf_counter() - start
        with writing("--out", out):
            write_fit_result(result, prob, out, overwrite=overwrite)
        written = str(out)
        if plot is not None:
            from gnipy.plots import plot_fit

            write_plot(result, plot, overwrite, plot_fit)
            written += f", {plot}"
        report_result("gni fit", prob.name, result, written, seconds)

    guarded(go)
