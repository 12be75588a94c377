"""`gni fit`: estimate a model's parameters (and/or its initial condition) from an observed run,
as a TOML problem file says, and write the fitted run with the estimates to netCDF (and a figure).

The problem file's format is that of :func:`gnipy.control.fit_problems.load_fit_problem`.
"""

from __future__ import annotations

import time
from pathlib import Path

import typer

from .app import app
from .errors import guarded, writing
from .output import report_result
from .held import hold
from .paths import check_out_and_plot, check_readable
from .progress import Progress
from .resources import check_result_file, memory_bound
from .run import write_plot

__all__ = ["FIT_KEYWORDS", "FIT_OPTIONS", "fit"]

#: What gnipy's error messages name (`h: ...`, `observations: ...`), as the keys of a fit problem file
#: that set it: every message of `gni fit` names a key of the file or one of its options.
FIT_OPTIONS = {
    "system": "system.model",
    "model": "system.model",
    "params": "estimate.params",
    "fixed": "system.params",
    "lagrangian": "system.params/estimate.params",
    "constraints": "system.params/estimate.params",
    "affine": "system.params/estimate.params",
    "initial": "estimate.initial",
    "bounds": "estimate.bounds",
    "params/initial": "estimate",
    "observations": "observations.file",
    "observations/h": "observations.file/integration.h",
    "sigma": "observations.sigma",
    "q0": "start.q0",
    "v0": "start.v0",
    "q0/v0": "start.q0/start.v0",
    "R0": "start.R0",
    "h": "integration.h",
    "steps": "observations.file/integration.h",
    "t0": "integration.t0",
    "method": "integration.method",
}
#: The keyword arguments gnipy's messages suggest, as what `gni fit` takes instead.
FIT_KEYWORDS = {"max_bytes=None": "--yes", "overwrite=True": "--overwrite"}


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
    yes: bool = typer.Option(
        False, "--yes", help="Fit even when the memory or the file the fit needs is estimated beyond gnipy's bounds "
        "(the fitted run holds every node from t0 to the last observation).",
    ),
):
    """Fit a model's parameters and/or initial condition to an observed run (gnipy.fit).

    The problem file names the model, the parameters to estimate with their initial guesses, the
    observation file (a gnipy result file, e.g. from `gni run`; some of its coordinates or
    velocities), the measurement error if known, the start and the integration (method, h). The
    fit is Levenberg-Marquardt least squares through the differentiated simulation; the standard
    errors come from the Jacobian. --out gets the fitted run's nodes, estimate(quantity),
    standard_error(quantity), covariance(quantity, quantity_) and the fit's chi2 and iterations
    as attributes. It exits with code 1 when the fit does not converge (the file is written all
    the same). A fit whose memory (or result file) is estimated beyond gnipy's bounds is refused
    before anything is computed, naming observations.file/integration.h; --yes fits it anyway.
    """

    def go():
        from gnipy.control.identification import MAX_STEPS
        from gnipy.control.fit_problems import load_fit_problem, write_fit_result

        check_readable(problem, "PROBLEM")
        check_out_and_plot(out, plot, overwrite)
        hold("--out", out)  # one writer per output: a second fit into it is refused now, not at the end
        hold("--plot", plot)
        bound = None if yes else memory_bound()
        prob = load_fit_problem(problem, max_bytes=bound)
        if not yes:
            check_result_file(_system(prob), _span(prob) + 1, out, "observations.file/integration.h")
        start = time.perf_counter()
        # the solver's iterations (rejected steps included) are at most its max_steps
        with Progress("fit", MAX_STEPS, "iterations", description=f"{prob.name}: compiling and iterating") as progress:
            def report(i, chi2):
                progress.update(i + 1, description=f"{prob.name}: chi2 {chi2:.6g}")

            result = prob.solve(progress=report, max_bytes=bound)
        seconds = time.perf_counter() - start
        with writing("--out", out):
            write_fit_result(result, prob, out, overwrite=overwrite)
        written = str(out)
        if plot is not None:
            from gnipy.plots import plot_fit

            write_plot(result, plot, overwrite, plot_fit)
            written += f", {plot}"
        report_result("gni fit", prob.name, result, written, seconds)

    guarded(go, method_option="integration.method", options=FIT_OPTIONS, keywords=FIT_KEYWORDS,
            out_of_memory="out of memory: observe a shorter span or use a larger integration.h")


def _system(prob):
    """The System of a fit problem at its initial guess (the size of its nodes)."""
    from gnipy.registry import get_model

    spec = get_model(prob.model)
    return spec.build(spec.resolve_params({**prob.fixed, **prob.params}))


def _span(prob) -> int:
    """The steps from t0 to the last observation time (the nodes of the fitted run, less one); 0
    when that is not a finite number (gnipy.fit refuses the times then)."""
    import math

    steps = (float(prob.observations.times[-1]) - prob.t0) / prob.h
    return max(0, round(steps)) if math.isfinite(steps) else 0
