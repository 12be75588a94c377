"""`gni convergence`: the options of a convergence study, its table and its files.

The study itself is :func:`gnipy.analysis.convergence_study`; this command parses the options,
calls it, prints the errors and the fitted orders, and writes `convergence.csv` and
`convergence.png`.
"""

from __future__ import annotations

import math
from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded, writing
from .output import console, safe, table
from .parsing import parse_methods, parse_R0, prepare_model, step_counts
from .held import hold
from .paths import check_output_dir, create_output_dir
from .progress import Progress

__all__ = ["FILES", "convergence", "convergence_report", "write_convergence_files"]

#: The files a study writes into its directory.
FILES = ("convergence.csv", "convergence.png")

_WHAT = {"state": "max(|q − q*|, |v − v*|)", "q": "|q − q*|", "v": "|v − v*|"}


@app.command()
def convergence(
    model: str = typer.Argument(
        ..., help="Model name (see `gni models`), or your own system: FILE.py:NAME or module:NAME, "
        "NAME a function returning a gnipy.System (its number-valued keyword parameters are what --set "
        "reaches).",
        show_default=False, metavar="MODEL"),
    methods_: str = typer.Option(
        "gni-trapezoid", "--methods", "-m", help="Comma-separated method names (see `gni methods`)."
    ),
    h_max: float = typer.Option(0.1, "--h-max", help="Largest step size."),
    h_min: float = typer.Option(0.01, "--h-min", help="Smallest step size."),
    count: int = typer.Option(5, "--count", help="Number of step sizes (log-spaced, at least 2)."),
    t_final: float = typer.Option(1.0, "--t-final", help="Final time: each h is adjusted to T / round(T / h)."),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Parameter override NAME=VALUE (repeatable, or comma-separated).", show_default=False
    ),
    q0: str | None = typer.Option(None, "--q0", "--x0", help="Initial configuration (default: the model's; --x0 is "
                                  "its older name).", show_default=False),
    v0: str | None = typer.Option(None, "--v0", help="Initial velocity (default: the model's).", show_default=False),
    R0: str | None = typer.Option(
        None, "--R0", help="Initial orientation on R^n x G, row-major (default: the model's).", show_default=False
    ),
    project_v0: bool = typer.Option(False, "--project-v0", help="Project v0 onto the constraints."),
    error: str = typer.Option(
        "auto", "--error", help="What to measure at the final time: q (the configuration), v (the reported "
        "velocity), state (the larger of the two), or auto (q; v on models without coordinates q)."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (created if missing).", show_default=False),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace convergence.csv and convergence.png in a directory gnipy did not "
        "create (in one it created, marked by its .gnipy-owned file, they are replaced on a rerun).",
    ),
):
    """Measure the order of convergence of methods on MODEL.

    For each method and each of COUNT log-spaced step sizes from H-MAX to H-MIN (each adjusted so
    that T is a whole number of steps), the error at the final time T (max-norm; of the
    configuration q by default, see --error) is measured against the model's exact solution when
    it has one, else against the continuous reference (Dopri8 at tolerance 1e-12). The order is
    the least-squares slope of log(error) against log(h) over the points above round-off
    (2·√N·ε against an exact solution, N the largest step count: the steps' round-off grows like a
    random walk, gnipy.spaces; 1e-10 against the reference; times max(1, |state|)). Writes
    OUT/convergence.csv and OUT/convergence.png and prints the table and the fitted orders.
    """

    def go():
        import functools

        from gnipy.analysis import convergence_study

        if error not in ("auto", "state", "q", "v"):
            raise UsageError("--error", f"expected auto, state, q or v, got {error!r}")
        spec, params, q0_, v0_ = prepare_model(model, set_, q0, v0)
        measure = ("q" if spec.coordinates else "v") if error == "auto" else error
        names = parse_methods(methods_)
        counts = step_counts(h_max, h_min, count, t_final)
        R0_ = parse_R0(spec, params, R0)
        if measure == "q" and not spec.coordinates:
            raise UsageError("--error", f"model {spec.name!r} has no coordinates q (it lives on a group): "
                             "use v or state")
        replace = check_output_dir(out, FILES, overwrite)
        hold("--out", out)

        exact = None if spec.exact is None else functools.partial(spec.exact, params)
        with Progress("convergence", unit="runs") as progress:
            study = convergence_study(spec.build(params), names, q0_, v0_, R0=R0_, t_final=t_final, steps=counts,
                                      measure=measure, exact=exact, project_v0=project_v0, progress=progress)
        csv_path, png_path = write_convergence_files(study, spec, out, replace)
        convergence_report(study, spec, params, csv_path, png_path)

    guarded(go, method_option="--methods")


def write_convergence_files(study, spec, out: Path, replace: bool) -> tuple[Path, Path]:
    """Write `out/convergence.csv` (:meth:`~gnipy.analysis.ConvergenceStudy.rows`) and
    `out/convergence.png`, each atomically; a directory created here is removed again if either
    cannot be written."""
    import csv
    import io

    from gnipy.files import atomic_write_text, remove_owned_dir
    from gnipy.plots import plot_convergence

    csv_path, png_path = out / FILES[0], out / FILES[1]
    rows = study.rows()
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=list(rows[0]))
    writer.writeheader()
    for row in rows:
        writer.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in row.items()})
    guides = sorted({p for p in study.expected.values() if p is not None}) or [1, 2]
    T = study.t_final
    with writing("--out", out):
        created = create_output_dir(out, "gni convergence: " + ", ".join(FILES))
    try:
        # each file whole or not at all (a full disk leaves an earlier file as it was)
        with writing("--out", csv_path):
            atomic_write_text(csv_path, text.getvalue(), overwrite=replace, argument="--out")
        with writing("--out", png_path):
            plot_convergence(
                {name: study.h for name in study.methods}, study.errors, png_path, guides=guides, floor=study.floor,
                title=f"{spec.name}: error at t = {T:g} against the {study.yardstick_description.split(' (')[0]}",
                ylabel=f"{_WHAT[study.measure]} at t = {T:g}", overwrite=replace,
            )
    except BaseException:
        if created:  # nothing of this study is left behind (the csv, if written, goes too)
            remove_owned_dir(out, FILES)
        raise
    return csv_path, png_path


def convergence_report(study, spec, params, csv_path, png_path) -> None:
    """Print the errors of a study, its fitted against expected orders, one grep-able line
    `order METHOD: VALUE` per method, the failed runs and the files written."""
    T, measure, floor = study.t_final, study.measure, study.floor
    con = console()
    con.print(f"gni convergence: {spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())}), "
              f"t = 0 .. {T:g}", markup=False)
    con.print(f"errors at t = {T:g} ({measure}, max-norm) against the {study.yardstick_description}", markup=False)
    errors = table(title_justify="left")
    for head in ("method", "steps", "h", f"error ({measure})"):
        errors.add_column(head, justify="left" if head == "method" else "right", no_wrap=True)
    for name in study.methods:
        for i, n in enumerate(study.steps):
            e = study.errors[name][i]
            text = "failed" if not math.isfinite(e) else f"{e:.3e}" + ("" if e > floor else " *")
            errors.add_row(name if i == 0 else "", str(n), f"{T / n:.4g}", text, end_section=i == len(study.steps) - 1)
    con.print(errors)
    if any(not (e > floor) for name in study.methods for e in study.errors[name] if math.isfinite(e)):
        con.print(f"* at or below round-off ({floor:.1e}): not used in the fit", markup=False)
    orders = table(title="fitted orders (least squares, log error against log h)", title_justify="left")
    orders.add_column("method")
    orders.add_column("fitted order", justify="right")
    orders.add_column("expected", justify="right")
    for name in study.methods:
        o, expected = study.orders[name], study.expected[name]
        orders.add_row(name, f"{o:.2f}" if math.isfinite(o) else "n/a (fewer than 2 points above round-off)",
                       "?" if expected is None else str(expected))
    con.print(orders)
    for name in study.methods:  # one plain line per method, easy to grep
        o = study.orders[name]
        con.print(f"order {name}: {o:.3f}" if math.isfinite(o) else f"order {name}: n/a", markup=False)
    for name, h in study.failures:
        con.print(f"warning: solver failure for {name} at h = {h:.6g} (left out)", markup=False)
    con.print(f"time: {study.seconds:.2f} s (including compilation)", markup=False)
    con.print(f"written: {safe(csv_path)}, {safe(png_path)}", markup=False)
