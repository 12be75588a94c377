"""File output: solutions as netCDF through xarray, written atomically.

**Contents** (CF-1.8 conventions). The coordinate `time` holds the physical times of the saved
nodes (float64, `units = "s"`, `standard_name = "time"`), so `ds.sel(time=5.0)` is the node at
t = 5; beside it, `node(time)` holds the saved-node index 0, 1, ... and `step(time)` the step
index k, t = t0 + kh. A result file holds the variables `q(time, coordinate)`,
`v(time, velocity)`, `p(time, velocity)`, `energy(time)`,
`constraint_residual(time, constraint)`, and `R(time, i, j)` on Rⁿ × G; the coordinates
`coordinate` and `velocity` hold the names (also in the attribute `components` of `q`, `v`,
`p`). Every variable has a `long_name`. Global attributes: `Conventions`, `title`, `source`,
`history`, and the provenance: `gnipy_version`, `jax_version`, `created` (UTC, ISO 8601),
`model`, `params` (JSON) and one `param_NAME` per parameter, `method`, `h`, `steps`, `start`
(how the first node was set up, e.g. `p+ = G v0`), `orientation` on Rⁿ × G (how R was
reconstructed, and whether it is a physical attitude), and what the caller adds (`gni run` adds
`q0`, `v0`, `save_every`, `command`, ...). The variables, their dimensions, units and long
names are stated once, in :mod:`gnipy.schema` (`VARIABLE_ATTRS`, `VARIABLE_UNITS`, `TIME_UNITS`,
`CONVENTIONS`, `UNITS_CONVENTION` and :func:`time_coordinates` are that module's, named here too).

Files written before the times moved into `time` (`time` the node index, the times in a
variable `t`) still read: :func:`read_netcdf` gives them the present layout
(:func:`upgrade_layout`), and :func:`result_times` reads the times of either.

**Units.** Time is in seconds (`"s"`): the models' parameters are SI values or nondimensional
unit scales unless a model states otherwise (the global attribute `units_convention` says so).
Ratios carry `units = "1"`. Coordinates mix lengths and angles (radians), so `q`, `v`, `p`
and the constraint residual carry no single `units` attribute, and no model states an energy
unit, so `energy` carries none (none is invented).

**Atomic writes, and what gets replaced** (:mod:`gnipy.files`).
A file either appears complete or not at all: the data go to a temporary file in the destination
directory, which then replaces the destination with `os.replace` (atomic on POSIX when both lie
on one file system, hence the same directory rather than `/tmp`). An existing file is kept
untouched until the new one is complete, and the temporary file is removed on any failure
(a full disk included: the netCDF library's `HDF error` becomes an :class:`OutputError`). An
existing file is replaced only with `overwrite=True`; a symbolic link, a directory or a special
file never is.

**Checksum.** Every result file carries the global attribute `gnipy_checksum`, the
:class:`gnipy.files.DataChecksum` of its variables (names, dtypes, shapes and bytes):
:func:`verify_netcdf` (and `gni verify`) recompute it.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .extras import require
from .file_attributes import attribute_value, cf_attributes, provenance
from .files import OutputError, atomic_write, check_destination
from .schema import (
    CONVENTIONS,
    TIME_UNITS,
    UNITS_CONVENTION,
    VARIABLE_ATTRS,
    VARIABLE_UNITS,
    time_coordinates,
)

__all__ = ["OutputError", "check_writable", "write_netcdf", "read_netcdf", "verify_netcdf", "provenance",
           "VARIABLE_UNITS", "UNITS_CONVENTION", "TIME_UNITS", "CONVENTIONS", "VARIABLE_ATTRS", "time_coordinates",
           "cf_attributes", "result_times", "upgrade_layout", "netcdf_checksum", "stamp_checksum", "CHECKSUM_ATTR"]

#: The global attribute that holds a result file's data checksum.
CHECKSUM_ATTR = "gnipy_checksum"


def result_times(ds):
    """The times of the saved nodes of a result dataset (a NumPy array): its `time` coordinate, or
    the variable `t` of a file written when `time` held the node index."""
    import numpy as np

    if "t" in ds.variables and ds["t"].dims == ("time",):
        return np.asarray(ds["t"].values, dtype=np.float64)
    return np.asarray(ds["time"].values, dtype=np.float64)


def upgrade_layout(ds):
    """`ds` in the present layout: for a result written when `time` held the node index and the times
    were a variable `t(time)`, the times become the `time` coordinate (keeping the file's `t`
    attributes) with `node` (the old index) and `step` beside it; other datasets are returned as
    they are."""
    import numpy as np

    if "t" not in ds.data_vars or ds["t"].dims != ("time",):
        return ds
    t = ds["t"]
    nodes = ds["time"].values if "time" in ds.coords else np.arange(ds.sizes["time"])
    h = ds.attrs.get("h")
    coords = time_coordinates(t.values, float(h) if isinstance(h, (int, float, np.number)) else None, nodes=nodes)
    coords["time"][2].update({k: v for k, v in t.attrs.items() if k in ("units", "long_name")})
    return ds.drop_vars(["t", *(["time"] if "time" in ds.coords else [])]).assign_coords(coords)


def _as_dataset(obj):
    xr = require("xarray", extra="files")

    from .solution import Solution

    if isinstance(obj, Solution):
        ds = obj.to_xarray()
        # the parameters as one attribute as well (param_* are the individual entries)
        ds.attrs.setdefault("params", json.dumps(dict(obj.params)))
        return ds
    if isinstance(obj, xr.Dataset):
        return obj.copy()
    raise TypeError(f"write_netcdf: expected a gnipy.Solution or an xarray.Dataset, got {type(obj).__name__}")


def check_writable(path, *, overwrite: bool = False, argument: str = "path") -> Path:
    """`path` as a Path, if a result file may be written there
    (:func:`gnipy.files.check_destination`): its directory exists and is writable, and nothing is
    there, or a regular file and `overwrite`; never a directory, link or special file. Else
    :class:`OutputError` naming the path and why."""
    return check_destination(path, overwrite=overwrite, argument=argument)


def netcdf_checksum(path) -> str:
    """The :class:`gnipy.files.DataChecksum` of a netCDF file's variables as stored (raw values,
    no masking or scaling; by name; attributes not included), read in slices along the first
    axis so memory stays bounded whatever the file's size."""
    netCDF4 = require("netCDF4", extra="files")
    import numpy as np

    from .files import DataChecksum, as_stored

    c = DataChecksum()
    with netCDF4.Dataset(os.fspath(path), "r") as nc:
        nc.set_auto_maskandscale(False)
        nc.set_always_mask(False)
        for name in sorted(nc.variables):
            var = nc.variables[name]
            if var.ndim == 0:
                c.update(name, np.asarray(var[...]))
                continue
            row = max(1, int(np.prod(var.shape[1:], dtype=np.int64)) * var.dtype.itemsize
                      if isinstance(var.dtype, np.dtype) else 64)
            step = max(1, (64 * 2**20) // row)
            if var.shape[0] == 0:
                c.update(name, as_stored(np.asarray(var[:0])))
            for i in range(0, var.shape[0], step):
                c.update(name, np.asarray(var[i:i + step]))
    return c.hexdigest()


def stamp_checksum(path) -> str:
    """Compute :func:`netcdf_checksum` of the netCDF file `path` and store it in its global
    attribute `gnipy_checksum` (in place); returns it."""
    netCDF4 = require("netCDF4", extra="files")

    digest = netcdf_checksum(path)
    with netCDF4.Dataset(os.fspath(path), "a") as nc:
        nc.setncattr(CHECKSUM_ATTR, digest)
    return digest


def write_netcdf(solution_or_dataset, path, attrs: Mapping[str, Any] | None = None, *,
                 overwrite: bool = False) -> Path:
    """Write a :class:`~gnipy.Solution` (via `Solution.to_xarray`) or an `xarray.Dataset` to netCDF.

    The write is atomic (see the module docstring). Provenance attributes are added when missing:
    `gnipy_version`, `jax_version`, `created`, `units_convention`, `Conventions`, `history`,
    `gnipy_checksum` (the data checksum, :func:`verify_netcdf`)
    (Solution.to_xarray also gives model, method, h, steps, start, the parameters and the other
    CF attributes), and `units` on the variables of :data:`VARIABLE_UNITS` (on `time` when it
    holds times, i.e. floats).

    Arguments:
        solution_or_dataset: what to write.
        path: the destination file.
        attrs: extra global attributes (values that netCDF cannot hold are stored as strings/JSON).
        overwrite: replace an existing regular file at `path` (without it, an existing file is an
            error; a directory, symbolic link or special file is always refused).

    Returns:
        The destination as a `Path`.

    Raises:
        OutputError: (an `OSError`) the directory does not exist, is not writable, the path is
            taken (see `overwrite`), or writing failed (a full disk included); the message names
            the path.
        TypeError: `solution_or_dataset` is neither a Solution nor a Dataset.
    """
    path = Path(os.fspath(path))
    ds = _as_dataset(solution_or_dataset)
    for k, v in provenance().items():
        ds.attrs.setdefault(k, v)
    ds.attrs.setdefault("units_convention", UNITS_CONVENTION)
    ds.attrs.setdefault("Conventions", CONVENTIONS)
    ds.attrs.setdefault("history", f"{ds.attrs['created']} gnipy {ds.attrs['gnipy_version']}: write_netcdf")
    for name, units in VARIABLE_UNITS.items():
        if name in ds.variables and "units" not in ds[name].attrs and ds[name].dtype.kind == "f":
            ds[name].attrs["units"] = units
    if "time" in ds.coords and ds["time"].dtype.kind == "f":
        ds["time"].encoding["_FillValue"] = None  # CF: a coordinate variable has no missing values
    for k, v in (attrs or {}).items():
        ds.attrs[str(k)] = v
    ds.attrs = {k: attribute_value(v) for k, v in ds.attrs.items()}

    ds.attrs.pop(CHECKSUM_ATTR, None)

    def write(tmp):
        ds.to_netcdf(tmp)
        stamp_checksum(tmp)

    atomic_write(path, write, overwrite=overwrite, argument="path")
    return path


def read_netcdf(path):
    """Read a netCDF file into memory as an `xarray.Dataset` (the file is closed on return).

    A result file of the earlier layout (`time` the node index, the times in `t`) is returned in
    the present one (:func:`upgrade_layout`): `ds.sel(time=...)` selects by time in both.

    Raises:
        OutputError: (an `OSError`) the file does not exist or cannot be read; the message names it.
    """
    xr = require("xarray", extra="files")

    path = Path(os.fspath(path))
    if not path.is_file():
        raise OutputError(f"cannot read {path}: no such file")
    try:
        return upgrade_layout(xr.load_dataset(path))
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from e
    except ValueError as e:  # xarray: no backend recognises the file
        raise OutputError(f"cannot read {path}: not a netCDF file that xarray can open") from e


def verify_netcdf(path) -> tuple[bool, str]:
    """Check a result file: readable, and its data match the checksum it carries.

    Returns:
        `(ok, message)`: `ok` is True when the recomputed :func:`netcdf_checksum` equals the
        file's `gnipy_checksum`; the message says what was checked or what differs. A file without
        a checksum (written by another tool, or before gnipy kept one) gives `(False, ...)` saying so.

    Raises:
        OutputError: the file does not exist or cannot be read as netCDF.
    """
    netCDF4 = require("netCDF4", extra="files")

    path = Path(os.fspath(path))
    if not path.is_file():
        raise OutputError(f"cannot read {path}: no such file")
    try:
        with netCDF4.Dataset(os.fspath(path), "r") as nc:
            stored = nc.__dict__.get(CHECKSUM_ATTR)
            n = len(nc.variables)
        actual = netcdf_checksum(path)
    except OSError as e:
        raise OutputError(f"cannot read {path}: {e.strerror or e}") from e
    except (ValueError, RuntimeError, KeyError, IndexError, TypeError) as e:
        raise OutputError(f"cannot read {path}: not a readable netCDF file ({type(e).__name__}: {e})") from e
    if stored is None:
        return False, f"{path}: no {CHECKSUM_ATTR} attribute (not written by this gnipy); nothing to verify against"
    if actual != stored:
        return False, f"{path}: DAMAGED: the data do not match the stored checksum ({stored}; computed {actual})"
    return True, f"{path}: ok ({n} variables match {stored})"
