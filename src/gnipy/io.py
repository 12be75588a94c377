"""File output: solutions as netCDF through xarray, written atomically.

**Contents.** A result file holds the variables `t(time)`, `q(time, coordinate)`,
`v(time, velocity)`, `p(time, velocity)`, `energy(time)`,
`constraint_residual(time, constraint)`, and `R(time, i, j)` on Rⁿ × G; the coordinates
`coordinate` and `velocity` hold the names. Global attributes record the provenance:
`gnipy_version`, `jax_version`, `created` (UTC, ISO 8601), `model`, `params` (JSON) and one
`param_NAME` per parameter, `method`, `h`, `steps`, `start` (how the first node was set up, e.g.
`p+ = G v0`), and what the caller adds (`gni run` adds `q0`, `v0`, `save_every`, `command`, ...).

**Units.** The models are nondimensional unless their documentation says otherwise: `t` carries
`units = "time units"`, `energy` carries `units = "energy units"`, and the global attribute
`units_convention` says so. Coordinates mix lengths and angles (radians), so `q`, `v` and `p`
carry no single `units` attribute; their names are in the `coordinate` and `velocity`
coordinates.

**Atomic writes.**
A file either appears complete or not at all: the data go to a temporary file in the destination
directory, which then replaces the destination with `os.replace` (atomic on POSIX when both lie
on one file system, hence the same directory rather than `/tmp`). An existing file is kept
untouched until the new one is complete, and the temporary file is removed on any failure.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["OutputError", "check_writable", "write_netcdf", "read_netcdf", "provenance", "VARIABLE_UNITS", "UNITS_CONVENTION"]


class OutputError(OSError):
    """A file could not be written or read (the message names the path and why)."""


def _attr_value(v):
    """A netCDF-compatible attribute value (numbers, strings, lists of numbers; others as JSON)."""
    import numpy as np

    if isinstance(v, bool):
        return int(v)
    if isinstance(v, (int, float, str, np.integer, np.floating)):
        return v
    if isinstance(v, (list, tuple, np.ndarray)):
        a = np.asarray(v)
        if a.dtype.kind in "iuf" and a.ndim == 1 and a.size:
            return a.astype(np.float64)
        if a.dtype.kind in "iuf":
            return json.dumps(a.tolist())
    if isinstance(v, Mapping):
        return json.dumps({str(k): (float(x) if isinstance(x, (int, float)) else str(x)) for k, x in v.items()})
    return str(v)


#: Units of the variables that have one (the models are nondimensional unless stated).
VARIABLE_UNITS = {"t": "time units", "energy": "energy units"}

UNITS_CONVENTION = (
    "nondimensional unless the model states otherwise: t in time units, lengths in length units, "
    "angles in radians, energy in energy units"
)


def _jax_version() -> str:
    try:
        import jax

        return str(jax.__version__)
    except Exception:  # pragma: no cover
        return "unknown"


def provenance(**extra) -> dict[str, Any]:
    """Base provenance attributes: gnipy and JAX versions and creation time (UTC), plus `extra`."""
    from . import __version__

    attrs = {
        "gnipy_version": __version__,
        "jax_version": _jax_version(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
    }
    attrs.update(extra)
    return attrs


def _as_dataset(obj):
    import xarray as xr

    from .solution import Solution

    if isinstance(obj, Solution):
        ds = obj.to_xarray()
        # the parameters as one attribute as well (param_* are the individual entries)
        ds.attrs.setdefault("params", json.dumps(dict(obj.params)))
        return ds
    if isinstance(obj, xr.Dataset):
        return obj.copy()
    raise TypeError(f"write_netcdf: expected a gnipy.Solution or an xarray.Dataset, got {type(obj).__name__}")


def check_writable(path) -> Path:
    """`path` as a Path, if a file can be created there (its directory exists and is writable, and
    it is not a directory); else :class:`OutputError` naming the path and why."""
    path = Path(os.fspath(path))
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise OutputError(f"cannot write {path}: directory {directory} does not exist")
    if path.is_dir():
        raise OutputError(f"cannot write {path}: it is a directory")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {path}: directory {directory} is not writable")
    return path


def write_netcdf(solution_or_dataset, path, attrs: Mapping[str, Any] | None = None) -> Path:
    """Write a :class:`~gnipy.Solution` (via `Solution.to_xarray`) or an `xarray.Dataset` to netCDF.

    The write is atomic (see the module docstring). Provenance attributes are added when missing:
    `gnipy_version`, `jax_version`, `created`, `units_convention` (Solution.to_xarray also gives
    model, method, h, steps, start and the parameters), and `units` on `t` and `energy`.

    Arguments:
        solution_or_dataset: what to write.
        path: the destination file (overwritten if it exists).
        attrs: extra global attributes (values that netCDF cannot hold are stored as strings/JSON).

    Returns:
        The destination as a `Path`.

    Raises:
        OutputError: (an `OSError`) the directory does not exist, is not writable, the path is a
            directory, or writing failed; the message names the path.
        TypeError: `solution_or_dataset` is neither a Solution nor a Dataset.
    """
    path = Path(os.fspath(path))
    ds = _as_dataset(solution_or_dataset)
    for k, v in provenance().items():
        ds.attrs.setdefault(k, v)
    ds.attrs.setdefault("units_convention", UNITS_CONVENTION)
    for name, units in VARIABLE_UNITS.items():
        if name in ds.variables and "units" not in ds[name].attrs:
            ds[name].attrs["units"] = units
    for k, v in (attrs or {}).items():
        ds.attrs[str(k)] = v
    ds.attrs = {k: _attr_value(v) for k, v in ds.attrs.items()}

    directory = check_writable(path).parent

    # Rejected: tempfile.mkstemp, which creates the file with mode 0600 (the result would not get
    # the usual umask permissions); the netCDF library creates the file itself here.
    tmp = directory / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp"
    try:
        ds.to_netcdf(tmp)
        os.replace(tmp, path)
    except BaseException as e:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        if isinstance(e, OSError) and not isinstance(e, OutputError):
            raise OutputError(f"cannot write {path}: {e.strerror or e}") from e
        raise
    return path


def read_netcdf(path):
    """Read a netCDF file into memory as an `xarray.Dataset` (the file is closed on return).

    Raises:
        OutputError: (an `OSError`) the file does not exist or cannot be read; the message names it.
    """
    import xarray as xr

    path = Path(os.fspath(path))
    if not path.is_file():
        raise OutputError(f"cannot read {path}: no such file")
    try:
        return xr.load_dataset(path)
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from e
    except ValueError as e:  # xarray: no backend recognises the file
        raise OutputError(f"cannot read {path}: not a netCDF file that xarray can open") from e
