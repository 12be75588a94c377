"""`gni stability`: the eigenvalues of a model's steady motions against one of its parameters.

The analysis is :func:`gnipy.analysis.stability_curve` (with :func:`gnipy.analysis.linearize` at
each value, and :func:`gnipy.analysis.discrete_linearization` for `--methods`); this command
parses the options, builds the family of steady motions from the model (at each value of the
parameter, the model's initial condition for those parameters is the steady motion), prints the
stability changes and the stable ranges, and writes `stability.csv` and `stability.png`.
"""

from __future__ import annotations

import math
from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded, writing
from .held import hold
from .output import console, safe, table
from .parsing import check_positive, model_spec, parse_methods, parse_set, parse_vector
from .paths import check_output_dir, create_output_dir
from .progress import Progress

__all__ = ["FILES", "stability", "stability_report", "write_stability_files"]

#: The files the command writes into its directory.
FILES = ("stability.csv", "stability.png")


@app.command()
def stability(
    model: str = typer.Argument(
        ..., help="Model name (see `gni models`), or your own system: FILE.py:NAME or module:NAME, "
        "NAME a function returning a gnipy.System whose default initial condition is the steady motion for "
        "its parameters (e.g. gnipy.models.whipple_bicycle:riding, the benchmark bicycle upright at speed v).",
        show_default=False, metavar="MODEL"),
    over: str = typer.Option(
        ..., "--over", help="The parameter and its values: NAME=START:STOP:COUNT or NAME=linspace(START, STOP, "
        "COUNT) (numpy.linspace's values, increasing). At each value the steady motion is the model's initial "
        "condition for those parameters (or --q0/--v0).", show_default=False),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Fix another parameter, NAME=VALUE (repeatable, or comma-separated).", show_default=False
    ),
    q0: str | None = typer.Option(None, "--q0", help="The steady motion's configuration at every value (default: "
                                  "the model's initial condition for the value).", show_default=False),
    v0: str | None = typer.Option(None, "--v0", help="Its velocity at every value (default: the model's).",
                                  show_default=False),
    methods_: str | None = typer.Option(
        None, "--methods", "-m", help="Also linearize these methods' one-step maps at step --h (comma-separated; "
        "see `gni methods`) and say where each keeps the motion's stability.", show_default=False),
    h: float = typer.Option(0.01, "--h", help="The methods' step size (with --methods)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (created if missing).", show_default=False),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace stability.csv and stability.png in a directory gnipy did not create "
        "(in one it created, marked by its .gnipy-owned file, they are replaced on a rerun).",
    ),
):
    """Linear stability of MODEL's steady motions against one parameter (--over).

    At each value the steady motion (q, v) is linearized with JAX derivatives of the
    Lagrange–d'Alembert equations on the constraint manifold (gnipy.analysis.linearize: ignorable
    coordinates dropped, conserved quantities' zero eigenvalues left out); where the stability
    changes between two values, the change is located to 1e-10 relative (Brent's method on the
    largest real part, or bisection where one side is neutrally stable). Prints the changes and the
    stable ranges (for the benchmark bicycle, its weave and capsize speeds: Meijaard et al. 2007);
    with --methods, the growth rate of each method's one-step map (log|μ|/h, its hidden state
    included) at each value and where the method keeps the motion's stability. Writes
    OUT/stability.csv (the eigenvalues at each value) and OUT/stability.png (real and imaginary
    parts against the parameter, unstable values shaded, changes marked).
    """

    def go():
        from gnipy.analysis import stability_curve
        from gnipy.sweep.grid import parse_grid
        from gnipy.sweep.errors import SweepError

        spec = model_spec(model)
        try:
            axis = parse_grid(over)
        except SweepError as e:
            raise UsageError("--over", str(e).partition(":")[2].strip()) from None
        if axis.name not in spec.params:
            known = ", ".join(spec.params) or "none"
            raise UsageError("--over", f"{axis.name!r} is not a parameter of {spec.name!r} (its parameters: {known})")
        if axis.count < 2 or not axis.stop > axis.start:
            raise UsageError("--over", f"expected at least two increasing values, got {over!r}")
        fixed = parse_set(set_)
        if axis.name in fixed:
            raise UsageError("--set", f"{axis.name!r} is the parameter of --over; set it there")
        import gnipy

        try:
            params = spec.resolve_params(fixed)
        except gnipy.InputError as e:  # an unknown name or a bad value
            raise UsageError("--set", str(e).partition(":")[2].strip()) from None
        probe = spec.build(params)
        if probe.group is not None:
            raise UsageError("MODEL", f"{spec.name!r} lives on R^n x {type(probe.group).__name__}: linear stability is "
                             "computed on R^n only (write the model in coordinates)")
        q_fixed = parse_vector("--q0", q0, len(spec.coordinates), spec.coordinates)
        v_fixed = parse_vector("--v0", v0, len(probe.velocities), probe.velocities)
        names = parse_methods(methods_) if methods_ else []
        if names:
            check_positive("--h", h)
        replace = check_output_dir(out, FILES, overwrite)
        hold("--out", out)

        def steady(value):
            p = dict(params, **{axis.name: value})
            dq, dv = spec.initial_condition(p)
            return spec.build(p), (dq if q_fixed is None else q_fixed), (dv if v_fixed is None else v_fixed)

        try:
            with Progress("stability", unit="linearizations") as progress:
                curve = stability_curve(probe, steady, axis.values, methods=names, h=h if names else None,
                                        progress=progress)
        except gnipy.InputError as e:  # "stability_curve: at VALUE: what is not steady": say whose state
            head, _, rest = str(e).partition("stability_curve: at ")
            if head or not rest:
                raise
            given = q_fixed is not None or v_fixed is not None
            raise UsageError("--q0/--v0" if given else "MODEL", f"at {axis.name} = {rest}" + (
                "" if given else " (the model's initial condition for each value is taken as the steady motion)"
            )) from None
        csv_path, png_path = write_stability_files(curve, spec, axis.name, out, replace)
        stability_report(curve, spec, params, axis.name, csv_path, png_path)

    guarded(go, method_option="--methods")


def _rows(curve, name: str) -> list[dict]:
    width = curve.eigenvalues.shape[1]
    rows = []
    for i, value in enumerate(curve.values):
        row = {name: float(value), "stable": bool(curve.stable[i]), "growth_rate": float(curve.growth_rate[i])}
        for k in range(width):
            e = curve.eigenvalues[i, k]
            row[f"eigenvalue{k + 1}_real"] = float(e.real)
            row[f"eigenvalue{k + 1}_imag"] = float(e.imag)
        for method, rates in curve.method_growth.items():
            row[f"{method}_growth_rate"] = float(rates[i])
            row[f"{method}_stable"] = bool(curve.method_stable(method)[i])
        rows.append(row)
    return rows


def write_stability_files(curve, spec, name: str, out: Path, replace: bool) -> tuple[Path, Path]:
    """Write `out/stability.csv` (one row per value: the stability, the growth rate, the
    eigenvalues' real and imaginary parts — empty where a value has fewer — and each method's map
    growth rate) and `out/stability.png` (:func:`gnipy.plots.plot_stability`), each atomically; a
    directory created here is removed again if either cannot be written."""
    import csv
    import io

    from gnipy.files import atomic_write_text, remove_owned_dir
    from gnipy.plots import plot_stability

    csv_path, png_path = out / FILES[0], out / FILES[1]
    rows = _rows(curve, name)
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=list(rows[0]))
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if isinstance(v, float) and math.isnan(v) else repr(v) if isinstance(v, float) else v)
                         for k, v in row.items()})
    with writing("--out", out):
        created = create_output_dir(out, "gni stability: " + ", ".join(FILES))
    try:
        with writing("--out", csv_path):
            atomic_write_text(csv_path, text.getvalue(), overwrite=replace, argument="--out")
        with writing("--out", png_path):
            plot_stability(curve, png_path, xlabel=name, title=f"{spec.name}: eigenvalues of the steady motions",
                           overwrite=replace)
    except BaseException:
        if created:
            remove_owned_dir(out, FILES)
        raise
    return csv_path, png_path


def _stable_intervals(curve) -> list[tuple[float, float]]:
    """The intervals of the parameter where the motion is stable: the samples' range cut at the
    changes (each change flips the stability of the samples before it)."""
    edges = [float(curve.values[0]), *curve.transitions, float(curve.values[-1])]
    stable, out = bool(curve.stable[0]), []
    for lo, hi in zip(edges[:-1], edges[1:]):
        if stable:
            out.append((lo, hi))
        stable = not stable
    return out


def stability_report(curve, spec, params, name: str, csv_path, png_path) -> None:
    """Print the stability changes, the stable ranges, each method's verdicts and the files."""
    con = console()
    fixed = ", ".join(f"{k}={v:g}" for k, v in params.items() if k != name)
    con.print(f"gni stability: {safe(spec.name)}" + (f" ({fixed})" if fixed else "") +
              f", {name} = {curve.values[0]:g} .. {curve.values[-1]:g} ({curve.values.size} values)", markup=False)
    grid = table(title="largest real part of the eigenvalues (1/s; stable: ≤ 0)", title_justify="left")
    grid.add_column(name, justify="right")
    grid.add_column("growth rate", justify="right")
    grid.add_column("stable")
    for method in curve.method_growth:
        grid.add_column(f"{safe(method)} map", justify="right")
    for i, value in enumerate(curve.values):
        cells = [f"{value:.6g}", f"{curve.growth_rate[i]:+.4g}", "yes" if curve.stable[i] else "no"]
        for method, rates in curve.method_growth.items():
            mark = "" if curve.method_agrees(method)[i] else " !"
            cells.append(f"{rates[i]:+.3g}{mark}")
        grid.add_row(*cells)
    con.print(grid)
    if curve.method_growth:
        con.print(f"map: growth rate of the method's one-step map at h = {curve.h:g} (log|μ|/h, 1/s; stable: ≤ "
                  f"{_tol():g}); ! where it differs from the motion's stability", markup=False)
    for value in curve.transitions:
        i = int(min(max(curve.values.searchsorted(value), 1), curve.values.size - 1))
        becomes = "stable" if curve.stable[i] else "unstable"
        con.print(f"change: {name} = {value:.10g} (becomes {becomes})", markup=False)
    stable = _stable_intervals(curve)
    con.print("stable: " + (", ".join(f"{name} in [{a:.10g}, {b:.10g}]" for a, b in stable) if stable
                            else f"nowhere in [{curve.values[0]:.10g}, {curve.values[-1]:.10g}]"), markup=False)
    for method in curve.method_growth:
        wrong = ~curve.method_agrees(method)
        if not wrong.any():
            con.print(f"method {method}: keeps the stability at every value (h = {curve.h:g})", markup=False)
        else:
            con.print(f"method {method}: differs at {int(wrong.sum())} of {wrong.size} values (h = {curve.h:g}): "
                      + ", ".join(f"{name} = {v:g}" for v in curve.values[wrong][:8])
                      + (" ..." if wrong.sum() > 8 else ""), markup=False)
    con.print(f"written: {safe(csv_path)}, {safe(png_path)}", markup=False)


def _tol() -> float:
    from gnipy.analysis.linearization import MAP_GROWTH_TOL

    return MAP_GROWTH_TOL
