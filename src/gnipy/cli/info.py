"""`gni info` and `gni verify`: summarize a result file, and check files against the checksums
they carry (result files, sweep stores, the checkpoints of a streamed run)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import typer

from .app import app
from .errors import UsageError, guarded
from .output import EXIT_FAILURE, console, fail, safe, table
from .paths import check_readable
from .sweep import sweep_message

__all__ = ["SHOWN_ATTRS", "checksum_text", "format_attr", "info", "info_table", "is_parts_dir", "parts_info",
           "store_info", "unfinished", "verify", "verify_store"]

#: The attributes `gni info` shows in their own rows (the others follow, each in a row of its own).
SHOWN_ATTRS = {"model", "params", "method", "h", "steps", "start", "save_every", "t_final", "gnipy_version",
               "jax_version", "created", "command", "config_file", "result", "newton_iterations_total",
               "newton_iterations_max", "units_convention", "q0", "v0", "R0", "project_v0", "coordinates",
               "gnipy_checksum"}


def format_attr(v) -> str:
    """An attribute's value as `gni info` shows it (arrays as lists, floats to 10 digits)."""
    import numpy as np

    if isinstance(v, np.ndarray):
        return "[" + ", ".join(f"{x:.10g}" for x in v.reshape(-1)) + "]"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.10g}"
    return str(v)


@app.command()
def info(
    file: Path = typer.Argument(..., help="A result file written by `gni run` (or gnipy.io.write_netcdf), a "
                                "sweep store (DIR.zarr) or the checkpoint directory of a streamed run (FILE.nc.parts).",
                                show_default=False, metavar="FILE"),
):
    """Summarize what gnipy wrote: a result file (model, parameters, method, times, variables,
    energy drift, constraint residual and provenance), a sweep store (the run, the grid, the chunks
    done, the failed and qualitatively wrong members, the checksums) or the checkpoints of an
    unfinished streamed run."""

    def go():
        from gnipy.io import OutputError, read_netcdf

        if file.is_dir():  # a store or checkpoints, read as `gni verify` reads them (a link followed)
            if is_parts_dir(file):
                return parts_info(file)
            return store_info(file)
        check_readable(file, "FILE")
        try:
            ds = read_netcdf(file)
        except OutputError as e:
            raise UsageError("FILE", str(e)) from None
        except RuntimeError as e:  # the netCDF library on a damaged file ("NetCDF: HDF error")
            raise UsageError("FILE", f"cannot read {str(file)!r}: {e}") from None
        try:
            info_table(file, ds, checksum_text(file))
        except (ValueError, TypeError, AttributeError, OverflowError, KeyError, IndexError) as e:
            raise UsageError(
                "FILE", f"{str(file)!r} is not a result file gnipy can summarize ({type(e).__name__}: {e})"
            ) from None

    guarded(go)


def store_info(path: Path) -> None:
    """`gni info` of a sweep store: what ran, the grid, the chunks done and the members' health
    (read with :func:`gnipy.sweep.open_sweep`, which verifies every done chunk's checksum)."""
    import json

    import numpy as np

    from gnipy.files import OutputError
    from gnipy.sweep import SweepError, open_sweep, verify_sweep

    try:
        ok, message, damaged = verify_sweep(path)  # every done chunk read back against its checksum
        ds = open_sweep(path, allow_incomplete=True, verify=False)
    except SweepError as e:
        raise UsageError("FILE", re.sub(r"^(--out|path|out): ", "", sweep_message(str(e)))) from None
    except (OutputError, OSError, ValueError, KeyError, TypeError) as e:
        raise UsageError("FILE", f"cannot read {str(path)!r}: {e}") from None
    a = dict(ds.attrs)
    rows = table(title=f"gni info: {path}", show_header=False, title_justify="left", box=None)
    rows.add_column(style="bold")
    rows.add_column(overflow="fold")
    rows.add_row("kind", "sweep store (gni sweep, gnipy.run_sweep)")
    for key in ("model", "method", "h", "steps", "t_final", "save_every", "params", "set_params", "start"):
        if key in a:
            rows.add_row(key, format_attr(a[key]))
    for axis in json.loads(a.get("grid", "[]")):
        rows.add_row(f"grid {axis['name']}", f"{axis['count']} values, {axis['start']:g} .. {axis['stop']:g}")
    done = np.asarray(ds["chunk_done"].values, dtype=bool).copy()
    done[list(damaged)] = False  # a damaged chunk is computed again on resume: not done
    rows.add_row("members", f"{a.get('members', '?')} in {done.size} chunk(s): {int(done.sum())} done"
                 + ("" if done.all() else ", incomplete (run the same gni sweep again to resume)"))
    from gnipy.sweep.plan import layout_of

    member_done = layout_of(json.loads(a["sweep_spec"])).member_mask(done).reshape(np.shape(ds["result"]))
    result = np.where(member_done, np.asarray(ds["result"].values), -1)
    healthy = np.asarray(ds["healthy"].values, dtype=bool)
    computed = result >= 0
    rows.add_row("failed members", str(int(np.sum(result > 0))))
    rows.add_row("qualitatively wrong", f"{int(np.sum(computed & (result == 0) & ~healthy))} member(s) (a verdict "
                 "out of band: the variables healthy, hidden_momentum_first_time, energy_drift_first_time)")
    rows.add_row("checksum", f"NOT verified: {message}" if damaged or not ok
                 else f"verified: the {int(done.sum())} done chunk(s) match their checksums")
    rows.add_row("variables", ", ".join(f"{k}({', '.join(map(str, ds[k].dims))})" for k in ds.data_vars))
    for key in ("gnipy_version", "jax_version", "created"):
        if key in a:
            rows.add_row(key, format_attr(a[key]))
    console().print(rows)


def parts_info(parts: Path) -> None:
    """`gni info` of the checkpoint directory of a streamed run: what it holds and how to finish it."""
    result = parts.with_name(parts.name[: -len(".parts")])
    rows = table(title=f"gni info: {parts}", show_header=False, title_justify="left", box=None)
    rows.add_column(style="bold")
    rows.add_column(overflow="fold")
    rows.add_row("kind", f"the checkpoints of an unfinished streamed run of {result} (not a result yet)")
    rows.add_row("parts", f"{len(list(parts.glob('part_*.nc')))} committed chunk(s)")
    rows.add_row("to finish", "run the same `gni run ... --checkpoint-every K` again with --resume (it verifies "
                 "the parts, continues from the last good one and writes the file)")
    console().print(rows)


def checksum_text(path: Path) -> str:
    """What `gni info` says of a file's checksum (:func:`gnipy.io.verify_netcdf`)."""
    from gnipy.io import OutputError, verify_netcdf

    try:
        ok, message = verify_netcdf(path)
    except OutputError as e:
        return f"cannot be verified: {e}"
    prefix = f"{Path(path)}: "
    message = message[len(prefix):] if message.startswith(prefix) else message
    return f"verified: {message}" if ok else f"NOT verified: {message}"


def info_table(file, ds, checksum: str | None = None) -> None:
    """Print the summary table of `gni info` (raises on attributes of unexpected types)."""
    a = dict(ds.attrs)
    rows = table(title=f"gni info: {file}", show_header=False, title_justify="left", box=None)
    rows.add_column(style="bold")
    rows.add_column(overflow="fold")
    _run_rows(rows, a, ds)
    _data_rows(rows, ds)
    _attribute_rows(rows, a)
    if checksum is not None:
        rows.add_row("checksum", checksum)
    console().print(rows)


def _file_params(a: dict) -> dict:
    """The parameters of a result file with attributes `a`: its attribute `params` (JSON), else
    its attributes `param_NAME`."""
    import json

    params = {}
    if "params" in a:
        try:
            params = json.loads(str(a["params"]))
        except ValueError:
            params = {}
        if not isinstance(params, dict):
            params = {}
    if not params:
        params = {k[len("param_"):]: a[k] for k in a if k.startswith("param_")}
    return params


def _run_rows(rows, a: dict, ds) -> None:
    """The rows of `gni info` on what ran: the model and its parameters, the method, the times."""
    import numpy as np

    model_ = a.get("model", "(unknown)")
    ptxt = ", ".join(f"{k}={float(v):g}" if isinstance(v, (int, float, np.number)) else f"{k}={v}"
                     for k, v in _file_params(a).items())
    rows.add_row("model", f"{model_} ({ptxt})" if ptxt else str(model_))
    if "method" in a:
        parts = [str(a["method"])]
        if "h" in a:
            parts.append(f"h = {float(a['h']):g}")
        if "steps" in a:
            parts.append(f"{int(a['steps'])} steps")
        if "start" in a:
            parts.append(f"start: {a['start']}")
        rows.add_row("method", ", ".join(parts))
    if "time" in ds.coords and ds["time"].dtype.kind == "f" and ds["time"].size:  # read_netcdf: times in `time`
        t = np.asarray(ds["time"].values, dtype=float)
        units = ds["time"].attrs.get("units", "")
        more = f", saved every {int(a['save_every'])} steps" if "save_every" in a else ""
        rows.add_row("times", f"t = {t[0]:g} .. {t[-1]:g} {units}".rstrip() + f", {t.size} saved nodes{more}")


def _data_rows(rows, ds) -> None:
    """The rows of `gni info` on the data: the variables, the component names, the energy and the
    constraint residual."""
    import numpy as np

    for name, var in ds.data_vars.items():
        dims = ", ".join(f"{d}={ds.sizes[d]}" for d in var.dims)
        long = var.attrs.get("long_name", "")
        rows.add_row(f"variable {name}", f"({dims}) {var.dtype}" + (f"  {long}" if long else ""))
    for dim in ("coordinate", "velocity"):
        if dim in ds.coords and ds.sizes.get(dim):
            rows.add_row(f"{dim} names", ", ".join(str(x) for x in ds[dim].values))
    if "energy" in ds.variables and ds["energy"].size:
        e = np.asarray(ds["energy"].values, dtype=float)
        rows.add_row("energy", f"initial {e[0]:.12g}, final {e[-1]:.12g}, max |E - E0| = "
                      f"{np.max(np.abs(e - e[0])):.3e}")
    if "constraint_residual" in ds.variables:
        r = np.asarray(ds["constraint_residual"].values, dtype=float)
        rows.add_row("constraint residual", f"max |mu(q)(v - Y)| = {np.max(np.abs(r), initial=0.0):.3e}")


def _attribute_rows(rows, a: dict) -> None:
    """The rows of `gni info` on the file's other attributes: the invariants' drifts, the error
    against an exact solution, the provenance, and every attribute not shown in a row of its own."""
    for k in sorted(a):
        if k.startswith("invariant_drift_"):
            rows.add_row(f"invariant {k[len('invariant_drift_'):]}", f"max drift {float(a[k]):.3e}")
    if "max_error_q_vs_exact" in a:
        rows.add_row("error vs exact", f"max |q - q_exact| = {float(a['max_error_q_vs_exact']):.3e}, "
                      f"max |v - v_exact| = {float(a.get('max_error_v_vs_exact', float('nan'))):.3e}")
    for k in ("q0", "v0", "R0", "project_v0", "save_every", "result", "newton_iterations_total",
              "newton_iterations_max", "gnipy_version", "jax_version", "created", "command", "config_file",
              "units_convention"):
        if k in a:
            rows.add_row(k, format_attr(a[k]))
    for k in sorted(a):
        if k in SHOWN_ATTRS or k.startswith(("param_", "invariant_drift_", "max_error_")):
            continue
        rows.add_row(k, format_attr(a[k]))


def is_parts_dir(path: Path) -> bool:
    """Whether `path` is the checkpoint directory `OUT.parts` of a streamed run."""
    return path.name.endswith(".parts") and path.is_dir() and (
        (path / "spec.json").exists() or any(path.glob("part_*.nc"))
    )


def unfinished(parts: Path) -> None:
    """Exit (code 1) saying that `parts` holds an unfinished streamed run, to resume."""
    result = parts.with_name(parts.name[: -len(".parts")])
    fail(f"PATH: {parts} holds the checkpoints of an unfinished streamed run of {result} (not a result yet): "
         "run the same `gni run ... --checkpoint-every K` again with --resume, which verifies the parts and "
         "completes the file", EXIT_FAILURE)


def verify_store(path: Path) -> None:
    """`gni verify` of a directory: a sweep store, through gnipy.sweep.verify_sweep."""
    try:
        from gnipy import sweep as sweep_module
    except ImportError as e:  # pragma: no cover - the sweep's dependencies are installed with gnipy
        raise UsageError("PATH", f"{str(path)!r} is a directory, and sweep stores cannot be read here ({e})") from None
    verify_sweep = getattr(sweep_module, "verify_sweep", None)
    if verify_sweep is None:
        raise UsageError("PATH", f"{str(path)!r} is a directory: this version of gnipy cannot verify sweep stores "
                         "(gnipy.sweep.verify_sweep is missing)")
    from gnipy.files import OutputError

    sweep_error = getattr(sweep_module, "SweepError", OutputError)
    try:
        ok, message, bad = verify_sweep(path)
    except sweep_error as e:  # not a sweep store, or one that cannot be read
        raise UsageError("PATH", re.sub(r"^(--out|path|out): ", "", sweep_message(str(e)))) from None
    except (OutputError, OSError, ValueError, KeyError, TypeError) as e:
        raise UsageError("PATH", f"cannot verify {str(path)!r}: {e}") from None
    if ok:
        console().print(safe(message), markup=False)
        return
    if bad:
        shown = ", ".join(str(c) for c in list(bad)[:10]) + (", ..." if len(bad) > 10 else "")
        message = f"{message} (damaged chunks: {shown})" if shown not in str(message) else message
    fail(f"PATH: {message}", EXIT_FAILURE)


@app.command()
def verify(
    path: Path = typer.Argument(..., help="A result file (FILE.nc), a sweep store (DIR.zarr) or the checkpoint "
                                "directory of a streamed run (FILE.nc.parts).", show_default=False, metavar="PATH"),
):
    """Check that a file gnipy wrote is whole: recompute the checksums it carries.

    A result file (`gni run`, gnipy.io.write_netcdf) carries the checksum of its data in its
    attribute gnipy_checksum; a sweep store one per chunk. Exit code 0: the data match ("ok");
    1: they do not (the file is damaged: the message says what), the file carries no checksum, or
    PATH is an unfinished streamed run (resume it with `gni run ... --resume`); 2: PATH does not
    exist or cannot be read.
    """

    def go():
        import stat

        from gnipy.io import OutputError, verify_netcdf

        text = str(path)
        if "\x00" in text:
            raise UsageError("PATH", f"{text!r}: a path cannot contain a NUL character")
        try:
            st = os.stat(path)
        except FileNotFoundError:
            parts = path.with_name(path.name + ".parts") if path.name else None
            if parts is not None and is_parts_dir(parts):
                unfinished(parts)
            raise UsageError("PATH", f"cannot read {text!r}: no such file or directory") from None
        except OSError as e:
            raise UsageError("PATH", f"cannot read {text!r}: {e.strerror or e}") from None
        if stat.S_ISDIR(st.st_mode):
            if is_parts_dir(path):
                unfinished(path)
            verify_store(path)
            return
        if not stat.S_ISREG(st.st_mode):
            raise UsageError("PATH", f"cannot read {text!r}: not a regular file (a FIFO, socket or device)")
        try:
            ok, message = verify_netcdf(path)
        except OutputError as e:
            raise UsageError("PATH", str(e)) from None
        if not ok:
            fail(f"PATH: {message}", EXIT_FAILURE)
        console().print(safe(message), markup=False)

    guarded(go)
