"""The `gni` command line: run a model with any method and write netCDF; the demo; listings.

    gni run MODEL --method METHOD --h H (--steps N | --t-final T) [--set NAME=VALUE ...]
            [--x0 a,b,...] [--v0 a,b,...] [--R0 r11,...,r33] [--project-v0] [--save-every K] --out FILE.nc
    gni demo [--out FILE.nc]
    gni models
    gni methods

Bad input gives a one-line message naming the option and exit code 2; a solver failure or a file
that cannot be written gives exit code 1. Neither prints a Python traceback.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import typer

__all__ = ["app", "main"]

EXIT_USAGE = 2
EXIT_FAILURE = 1

app = typer.Typer(
    name="gni",
    help="Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

# Prefixes of gnipy's error messages (`name: ...`) and the CLI option each one is about.
_OPTION_OF = {
    "h": "--h",
    "steps": "--steps",
    "t_final": "--t-final",
    "steps/t_final": "--steps/--t-final",
    "save_every": "--save-every",
    "q0": "--x0",
    "v0": "--v0",
    "q0/v0": "--x0/--v0",
    "R0": "--R0",
    "t0": "--t0",
    "--set/params": "--set",
    "model": "MODEL",
    "method": "--method",
    "lagrangian": "--set/--x0",
    "constraints": "--set/--x0",
    "affine": "--set/--x0",
}


class _UsageError(Exception):
    """Bad command-line input: `option` is named in the message."""

    def __init__(self, option: str, message: str):
        super().__init__(f"{option}: {message}")
        self.option = option


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("gnipy")
    except Exception:  # not installed as a distribution: ask the package
        from . import __version__

        return __version__


def _version_callback(value: bool):
    if value:
        typer.echo(f"gni (gnipy) {_version()}")
        raise typer.Exit()


def _fail(message: str, code: int) -> None:
    """Print a one-line error on stderr and exit with `code` (no traceback)."""
    typer.echo("Error: " + " ".join(str(message).split()), err=True)
    raise typer.Exit(code)


def _rename(message: str) -> str:
    """Rewrite the `name:` prefix of a gnipy error message to the CLI option it is about."""
    head, sep, rest = str(message).partition(":")
    if sep and head.strip() in _OPTION_OF:
        rest = rest.replace("project_v0=True", "--project-v0")
        return f"{_OPTION_OF[head.strip()]}:{rest}"
    return str(message)


def _console():
    from rich.console import Console

    return Console(highlight=False, soft_wrap=True)


# --------------------------------------------------------------------------------------------
# Parsing helpers
# --------------------------------------------------------------------------------------------
def _parse_vector(option: str, text: str | None, n: int, names) -> tuple[float, ...] | None:
    if text is None:
        return None
    parts = [s for s in text.replace(" ", ",").split(",") if s != ""]
    try:
        values = tuple(float(s) for s in parts)
    except ValueError:
        raise _UsageError(option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {text!r}") from None
    if len(values) != n:
        raise _UsageError(
            option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {len(values)} in {text!r}"
        )
    if not all(math.isfinite(x) for x in values):
        raise _UsageError(option, f"contains NaN or infinite values: {text!r}")
    return values


def _parse_set(items: list[str] | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items or []:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            name, eq, value = part.partition("=")
            name, value = name.strip(), value.strip()
            if not eq or not name or not value:
                raise _UsageError("--set", f"expected NAME=VALUE, got {part!r}")
            try:
                x = float(value)
            except ValueError:
                raise _UsageError("--set", f"parameter {name!r} must be a number, got {value!r}") from None
            if not math.isfinite(x):
                raise _UsageError("--set", f"parameter {name!r} must be finite, got {value!r}")
            out[name] = x
    return out


def _check_positive(option: str, value, kind: str = "number"):
    if value is None:
        return
    if isinstance(value, float) and not math.isfinite(value):
        raise _UsageError(option, f"must be a positive finite {kind}, got {value!r}")
    if value <= 0:
        raise _UsageError(option, f"must be a positive {kind}, got {value!r}")


def _check_output(path: Path) -> None:
    import os

    directory = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise _UsageError("--out", f"{str(path)!r} is a directory")
    if not directory.is_dir():
        raise _UsageError("--out", f"cannot write {str(path)!r}: directory {str(directory)!r} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise _UsageError("--out", f"cannot write {str(path)!r}: directory {str(directory)!r} is not writable")


# --------------------------------------------------------------------------------------------
# Running and reporting
# --------------------------------------------------------------------------------------------
def _invariant_drifts(spec, params, q, v, R=None) -> dict[str, float]:
    import inspect

    import numpy as np

    out = {}
    for name, f in spec.invariants.items():
        # on R^n × G an invariant may also take the orientation: f(params, q, v, R)
        with_R = R is not None and len(inspect.signature(f).parameters) >= 4
        args = zip(q, v, R) if with_R else zip(q, v)
        vals = np.array([float(f(params, *a)) for a in args])
        out[name] = float(np.max(np.abs(vals - vals[0])))
    return out


def _exact_errors(spec, params, sol, q0, v0):
    """`(q_exact, v_exact, max|q − q_exact|, max|v − v_exact|)` or None."""
    import numpy as np

    if spec.exact is None:
        return None
    t = np.asarray(sol.t) - float(sol.t[0])
    result = spec.exact(params, q0, v0, t)
    if result is None:  # no closed form for these parameters (e.g. rolling-ball, unequal moments)
        return None
    qe, ve = result
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    # initial=0: on R^0 × G there are no coordinates q
    return qe, ve, float(np.max(np.abs(q - qe), initial=0.0)), float(np.max(np.abs(v - ve), initial=0.0))


def _prepare(model: str, method: str, h, steps, t_final, set_items, x0_text, v0_text, save_every):
    """Validate the input (raising `_UsageError` naming the option); returns `(spec, params, q0, v0)`."""
    import gnipy

    try:
        spec = gnipy.get_model(model)
    except gnipy.SystemError as e:
        raise _UsageError("MODEL", str(e).partition(":")[2].strip()) from None
    if method not in gnipy.method_names():
        raise _UsageError("--method", f"unknown method {method!r} (known: {', '.join(gnipy.method_names())})")
    _check_positive("--h", h)
    if (steps is None) == (t_final is None):
        raise _UsageError("--steps/--t-final", "give exactly one of --steps and --t-final")
    _check_positive("--steps", steps, "integer")
    _check_positive("--t-final", t_final)
    _check_positive("--save-every", save_every, "integer")
    try:
        params = spec.resolve_params(_parse_set(set_items))
    except gnipy.SystemError as e:
        raise _UsageError("--set", str(e).partition(":")[2].strip()) from None
    names = spec.coordinates
    x0 = _parse_vector("--x0", x0_text, len(names), names)
    vnames = spec.build(params).velocities  # (ẋ, ξ) on R^n × G: longer than x
    v0 = _parse_vector("--v0", v0_text, len(vnames), vnames)
    dq, dv = spec.initial_condition(params)
    return spec, params, tuple(dq if x0 is None else x0), tuple(dv if v0 is None else v0)


def _parse_R0(spec, params, text: str | None):
    """The initial orientation (flattened row-major) for a model on R^n × G: `--R0`, else the
    model's documented one (None: the identity); None for models without a group part."""
    group = spec.build(params).group
    if group is None:
        if text is not None:
            raise _UsageError("--R0", f"model {spec.name!r} has no orientation (no group part)")
        return None
    k = group.matrix_size
    if text is None:
        return tuple(spec.R0) if spec.R0 is not None else tuple(float(x) for x in group.identity().reshape(-1))
    return _parse_vector("--R0", text, k * k, [f"r{i + 1}{j + 1}" for i in range(k) for j in range(k)])


def _simulate(spec, params, method, q0, v0, h, steps, t_final, project_v0, save_every, R0=None):
    """Run; returns `(sol, v0_used, seconds)` (v0_used is the projected v0 with --project-v0)."""
    import gnipy

    system = spec.build(params)
    # the initial velocity actually used: G-orthogonally projected onto the constraints if asked
    _, v0_used = system.check(q0, v0, R0=R0, project_v0=project_v0)
    v0_used = tuple(float(x) for x in v0_used)
    t0 = time.perf_counter()
    sol = gnipy.simulate(
        system, method, q0, v0_used, R0=R0, h=h, steps=steps, t_final=t_final, save_every=save_every
    )
    sol.q.block_until_ready()
    seconds = time.perf_counter() - t0
    return sol, v0_used, seconds


def _report(
    title: str, spec, params, sol, exact, drifts, seconds: float, out: Path | None, note: str | None = None
) -> None:
    import numpy as np
    from rich.table import Table

    e = np.asarray(sol.energy)
    r = np.asarray(sol.constraint_residual)
    table = Table(title=title, show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column()
    table.add_row("model", f"{spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())})")
    span = f"t = {float(sol.t[0]):g} .. {float(sol.t[-1]):g}"
    table.add_row("method", f"{sol.method}, h = {sol.h:g}, {sol.steps} steps, {span}")
    table.add_row("final q", ", ".join(f"{c} = {x:.10g}" for c, x in zip(spec.coordinates, np.asarray(sol.q[-1]))))
    vnames = sol.velocities or tuple(f"d{c}" for c in spec.coordinates)
    table.add_row("final v", ", ".join(f"{c} = {x:.10g}" for c, x in zip(vnames, np.asarray(sol.v[-1]))))
    table.add_row("energy", f"initial {e[0]:.12g}, max |E - E0| = {np.max(np.abs(e - e[0])):.3e}")
    table.add_row("constraint residual", f"max |mu(q)(v - Y)| = {np.max(np.abs(r)) if r.size else 0.0:.3e}")
    for name, d in drifts.items():
        table.add_row(f"invariant {name}", f"max drift {d:.3e}")
    if exact is not None:
        table.add_row("error vs exact", f"max |q - q_exact| = {exact[2]:.3e}, max |v - v_exact| = {exact[3]:.3e}")
    table.add_row("time", f"{seconds:.2f} s (including compilation)")
    if out is not None:
        table.add_row("written", str(out))
    if note:
        table.add_row("note", note)
    _console().print(table)


def _attrs_for(spec, params, sol, q0, v0, exact, drifts, extra: dict[str, Any]) -> dict[str, Any]:
    attrs: dict[str, Any] = {
        "q0": list(q0),
        "v0": list(v0),
        "coordinates": ",".join(spec.coordinates),
        "t_final": float(sol.t[-1]),
        **extra,
    }
    for name, d in drifts.items():
        attrs[f"invariant_drift_{name}"] = d
    if exact is not None:
        attrs["max_error_q_vs_exact"] = exact[2]
        attrs["max_error_v_vs_exact"] = exact[3]
    return attrs


def _guarded(fn):
    """Run `fn()` turning gnipy's errors into one-line messages and exit codes."""
    import gnipy
    from gnipy.io import OutputError

    try:
        return fn()
    except _UsageError as e:
        _fail(str(e), EXIT_USAGE)
    except gnipy.SystemError as e:
        _fail(_rename(str(e)), EXIT_USAGE)
    except gnipy.MethodError as e:
        msg = _rename(str(e))
        _fail(msg if msg.startswith("--method") else f"--method: {msg}", EXIT_USAGE)
    except gnipy.SolverFailure as e:
        _fail(f"solver failure: {e}", EXIT_FAILURE)
    except OutputError as e:
        _fail(f"--out: {e}", EXIT_FAILURE)
    except OSError as e:
        where = f": {e.filename}" if getattr(e, "filename", None) else ""
        _fail(f"--out: {e.strerror or e}{where}", EXIT_FAILURE)


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------
@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the gnipy version and exit."
    ),
):
    """Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI)."""


@app.command()
def run(
    model: str = typer.Argument(..., help="Model name (see `gni models`).", show_default=False, metavar="MODEL"),
    method: str = typer.Option("gni-trapezoid", "--method", "-m", help="Method name (see `gni methods`)."),
    h: float = typer.Option(..., "--h", help="Step size (> 0).", show_default=False),
    steps: int | None = typer.Option(None, "--steps", help="Number of steps (give this or --t-final)."),
    t_final: float | None = typer.Option(
        None, "--t-final", help="Final time, a whole number of steps (give this or --steps)."
    ),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Parameter override NAME=VALUE (repeatable, or comma-separated)."
    ),
    x0: str | None = typer.Option(None, "--x0", help="Initial configuration a,b,... (default: the model's)."),
    v0: str | None = typer.Option(None, "--v0", help="Initial velocity a,b,... (default: the model's)."),
    R0: str | None = typer.Option(
        None, "--R0", help="Initial orientation on R^n x G, row-major r11,...,r33 (default: the model's, or identity)."
    ),
    project_v0: bool = typer.Option(
        False, "--project-v0", help="Project v0 onto the constraints instead of rejecting it."
    ),
    save_every: int = typer.Option(1, "--save-every", help="Save every K-th node (and always the last)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output netCDF file.", show_default=False),
):
    """Integrate MODEL with METHOD and write the trajectory to a netCDF file.

    The file holds t(time), q(time, coordinate), v(time, velocity), p(time, velocity),
    energy(time) and constraint_residual(time, constraint), and R(time, i, j) on R^n x G, with
    provenance attributes.
    """

    def go():
        from gnipy.io import write_netcdf

        spec, params, q0, v0_ = _prepare(model, method, h, steps, t_final, set_, x0, v0, save_every)
        R0_ = _parse_R0(spec, params, R0)
        _check_output(out)
        sol, v0_used, seconds = _simulate(
            spec, params, method, q0, v0_, h, steps, t_final, project_v0, save_every, R0=R0_
        )
        exact = _exact_errors(spec, params, sol, q0, v0_used)
        drifts = _invariant_drifts(spec, params, sol.q, sol.v, sol.R)
        extra = {"save_every": int(save_every), "project_v0": int(project_v0), "command": "gni run"}
        if R0_ is not None:
            extra["R0"] = list(R0_)
        attrs = _attrs_for(spec, params, sol, q0, v0_used, exact, drifts, extra)
        write_netcdf(sol, out, attrs=attrs)
        _report("gni run", spec, params, sol, exact, drifts, seconds, out)

    _guarded(go)


DEMO_MODEL, DEMO_METHOD, DEMO_H, DEMO_T = "rotating-table-ball", "gni-trapezoid", 0.01, 10.0


@app.command()
def demo(
    out: Path = typer.Option(Path("gnipy-demo.nc"), "--out", "-o", help="Output netCDF file."),
):
    """Roll a ball on a rotating table (paper §7.4) with the GNI and compare with the exact solution.

    Runs the rotating-table-ball model (m = r = Ω = 1, I = 2/3, the paper's first example) with
    gni-trapezoid, h = 0.01, up to t = 10; prints the final state, energy and constraint residuals,
    the drift of the conserved quantities and the error against the exact solution (the contact
    point runs round a circle); writes the trajectory and the exact solution to OUT.
    """

    def go():
        import numpy as np

        from gnipy.io import write_netcdf

        spec, params, q0, v0 = _prepare(DEMO_MODEL, DEMO_METHOD, DEMO_H, None, DEMO_T, None, None, None, 1)
        _check_output(out)
        sol, v0, seconds = _simulate(spec, params, DEMO_METHOD, q0, v0, DEMO_H, None, DEMO_T, False, 1)
        exact = _exact_errors(spec, params, sol, q0, v0)
        drifts = _invariant_drifts(spec, params, sol.q, sol.v)
        ds = sol.to_xarray()
        ds["q_exact"] = (("time", "coordinate"), np.asarray(exact[0]), {"long_name": "exact configuration"})
        ds["v_exact"] = (("time", "velocity"), np.asarray(exact[1]), {"long_name": "exact velocity"})
        attrs = _attrs_for(spec, params, sol, q0, v0, exact, drifts, {"command": "gni demo"})
        write_netcdf(ds, out, attrs=attrs)
        _report(
            "gni demo: ball on a rotating table, GNI (trapezoid) against the exact solution",
            spec, params, sol, exact, drifts, seconds, out,
            note="the turning table does work on the ball: the energy changes, the Jacobi integral "
            "E − mΩ(xẏ − yẋ), the speed |ż| and the spin ω₃ are conserved",
        )

    _guarded(go)


@app.command()
def models():
    """List the models with their parameters (defaults), coordinates and initial condition."""
    import gnipy

    con = _console()
    for name in gnipy.model_names():
        spec = gnipy.get_model(name)
        params = ", ".join(f"{k}={v:g}" for k, v in spec.params.items()) or "none"
        q0, v0 = spec.initial_condition(spec.params)
        extras = ["exact solution" if spec.exact is not None else None,
                  f"invariants: {', '.join(spec.invariants)}" if spec.invariants else None]
        con.print(f"[bold]{name}[/bold]: ", end="")
        con.print(spec.description, markup=False)
        con.print(f"    params: {params}", markup=False)
        con.print(f"    q = ({', '.join(spec.coordinates)}); default q0 = {q0}, v0 = {v0}", markup=False)
        more = "; ".join(x for x in extras if x)
        if more:
            con.print(f"    {more}", markup=False)


@app.command()
def methods():
    """List the method names with one-line descriptions."""
    from gnipy.methods import METHOD_DESCRIPTIONS

    con = _console()
    width = max(len(k) for k in METHOD_DESCRIPTIONS)
    for name, desc in METHOD_DESCRIPTIONS.items():
        con.print(f"[bold]{name:<{width}}[/bold]  ", end="")
        con.print(desc, markup=False)


if __name__ == "__main__":  # pragma: no cover
    app()
