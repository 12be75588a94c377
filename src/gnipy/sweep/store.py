"""The zarr store of a sweep: its layout, its creation, the writing of a chunk, and the checks of
its metadata, arrays and coordinates.

The store is a zarr (format 3) group with consolidated metadata, so that
`xarray.open_zarr(path)` opens it as it is: the per-member variables have the grid axes as
their first dimensions (named after the axes, with the grid values as coordinates), followed by
the dimensions :mod:`gnipy.schema` states (`q(m, Omega, time, coordinate)`); the zarr chunks
along the grid axes are the sweep's chunks (:class:`~gnipy.sweep.grid.ChunkLayout`).
"""

from __future__ import annotations

import json
import os
import shutil
import time
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..extras import require
from .. import files, schema
from .errors import SweepError, SweepFailure, damaged, why
from .grid import axes_of
from .ownership import CHUNK_VARS, COORDS, OWNER_ATTR, PURPOSE, open_group
from .plan import FORMAT, MEMBER_VARS, Plan, layout_of, saved_steps

__all__ = ["digest", "create_store", "write_chunk", "open_group", "check_arrays", "check_coordinates", "read_done"]

# the largest zarr chunk of a per-member variable, and of a grid axis (values)
MAX_ZARR_CHUNK_BYTES = 64 * 2**20
_MAX_AXIS_CHUNK = 2**22


def array_names(member_vars, grid_names) -> tuple[str, ...]:
    """Every array of a store with these per-member variables and grid axes."""
    return tuple(sorted({*member_vars, *grid_names, *CHUNK_VARS, *COORDS}))


def template(plan: Plan):
    """The full-size Dataset of the store: lazily defined (dask) per-member arrays, whose zarr
    chunks are the sweep's chunks along the grid axes."""
    require("dask", extra="sweeps")
    import dask.array as da
    xr = require("xarray", extra="sweeps")

    from ..version import __version__
    from ..file_attributes import cf_attributes, jax_version

    grid = tuple(a.dim for a in plan.axes)
    layout = plan.layout
    T = len(plan.times)
    sizes = {"time": T, "coordinate": len(plan.coordinates), "velocity": len(plan.velocities),
             "constraint": plan.constraints, "i": plan.matrix_size or 0, "j": plan.matrix_size or 0}
    width = max(1, len(plan.coordinates), len(plan.velocities), plan.constraints, (plan.matrix_size or 0) ** 2)
    t_chunk = max(1, min(T, MAX_ZARR_CHUNK_BYTES // (8 * layout.size * width)))
    variables = {}
    for name in plan.member_vars:
        var = schema.VARIABLES[name]
        shape = (*layout.shape, *(sizes[d] for d in var.dims))
        chunks = (*layout.block, *(t_chunk if d == "time" else max(1, sizes[d]) for d in var.dims))
        variables[name] = (schema.dims(name, grid), da.zeros(shape, chunks=chunks, dtype=var.dtype))
    variables["chunk_done"] = (schema.dims("chunk_done"), da.zeros((layout.chunks,), chunks=(1,), dtype=bool))
    variables["chunk_checksum"] = (schema.dims("chunk_checksum"),
                                   da.zeros((layout.chunks, 32), chunks=(1, 32), dtype=np.uint8))
    coords = {a.dim: ((a.dim,), a.values, schema.grid_axis_attrs(a.name)) for a in plan.axes}
    coords.update({
        **schema.time_coordinates(plan.times, plan.spec["h"]),
        "coordinate": np.array(plan.coordinates, dtype=object),
        "velocity": np.array(plan.velocities, dtype=object),
        "constraint": np.arange(plan.constraints),
        "chunk": np.arange(layout.chunks),
    })
    ds = xr.Dataset(variables, coords=coords)
    for a in plan.axes:
        ds[a.dim].encoding["chunks"] = (min(a.count, _MAX_AXIS_CHUNK),)
    ds["time"].encoding["_FillValue"] = None  # CF: a coordinate variable has no missing values
    schema.apply(ds, sweep=True)
    s = plan.spec
    from ..methods import get_method

    method_obj = get_method(s["method"])
    created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    title = f"sweep of {s['model']} with {s['method']} over {' '.join(str(a) for a in plan.axes)}"
    ds.attrs.update(cf_attributes(s["model"], s["method"], created=created, title=title))
    if plan.orientation:
        ds.attrs["orientation"] = plan.orientation
    ds.attrs.update({
        OWNER_ATTR: PURPOSE,
        "sweep_spec": json.dumps(s, sort_keys=True),
        "model": s["model"],
        "method": s["method"],
        "h": s["h"],
        "steps": s["steps"],
        "t_final": float(plan.times[-1]),
        "save_every": s["save_every"],
        "project_v0": int(s["project_v0"]),
        "chunk_size": s["chunk_size"],
        "chunk_shape": json.dumps(list(layout.block)),
        "members": layout.members,
        "chunks": layout.chunks,
        "grid": json.dumps(s["grid"]),
        "grid_dims": json.dumps(list(grid)),
        "set_params": json.dumps(s["set_params"]),
        "params": json.dumps(s["params"]),
        "start": method_obj.start_label,
        "method_settings": json.dumps(method_obj.settings(), sort_keys=True),
        "backend": "per member: the variable native (the native backend where the step lowers and a chunk "
                   "has enough trajectory-steps, else XLA)",
        "gnipy_version": __version__,
        "jax_version": jax_version(),
        "created": created,
        "store_arrays": json.dumps(sorted(ds.variables)),
    })
    return ds


def create_store(path: Path, plan: Plan, mode: str) -> None:
    """Write the store's metadata (consolidated) and coordinates into a temporary directory
    beside `path`, then rename it into place (replacing, for `mode` "replace", the store there,
    else nothing or an empty directory)."""
    from .ownership import remove_store

    tmp = files.temporary_name(path, "partial")
    old = None
    try:
        with warnings.catch_warnings():
            # zarr-python: consolidated metadata are an extension of the zarr 3 format (which
            # xarray reads); the store is a zarr store without them too
            warnings.filterwarnings("ignore", message="Consolidated metadata is currently not part")
            template(plan).to_zarr(str(tmp), mode="w-", compute=False, consolidated=True)
        if mode == "replace":
            old = files.temporary_name(path, "old")
            os.rename(path, old)
            try:
                os.rename(tmp, path)
            except OSError:
                os.rename(old, path)  # put the old store back
                old = None
                raise
        else:
            # nothing there, or an empty directory (replaced atomically); a file, link or
            # anything else put there meanwhile makes the rename fail
            os.rename(tmp, path)
    except OSError as e:
        err = files.as_output_error(e, path, "create")
        raise (err or e) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            remove_store(old)


def digest(data: Mapping[str, np.ndarray]) -> bytes:
    """The SHA-256 digest (32 bytes) of a chunk's data, each array in its stored dtype, with the
    chunk's members along the first axis."""
    typed = {name: np.asarray(a, dtype=schema.VARIABLES[name].dtype) for name, a in data.items()}
    return bytes.fromhex(files.array_checksum(typed).partition(":")[2])


def write_chunk(path: Path, plan: Plan, index: int, result: Mapping[str, np.ndarray]) -> None:
    """Write one chunk's data, then its checksum, then (last) its `chunk_done` flag."""
    zarr = require("zarr", extra="sweeps")

    a, b = plan.member_range(index)
    data = {}
    for name, arr in result.items():
        if name not in MEMBER_VARS:
            raise SweepFailure(f"chunk {index}: the task returned an unknown variable {name!r}")
        arr = np.asarray(arr, dtype=schema.VARIABLES[name].dtype)
        if arr.shape[:1] != (b - a,):
            raise SweepFailure(f"chunk {index}: the task returned {arr.shape[:1]} members for {name}, "
                               f"expected {b - a}")
        data[name] = arr
    missing = sorted(set(plan.member_vars) - set(data))
    if missing:
        raise SweepFailure(f"chunk {index}: the task returned no {missing[0]!r}")
    checksum = np.frombuffer(digest(data), dtype=np.uint8)
    region = plan.layout.slices(index)
    block = tuple(s.stop - s.start for s in region)
    group = zarr.open_group(str(path), mode="r+")
    for name, arr in data.items():
        group[name][region] = arr.reshape(block + arr.shape[1:])
    group["chunk_checksum"][index] = checksum
    group["chunk_done"][index] = True


def stored_array_names(group) -> tuple[str, ...] | None:
    """The arrays the store was created with (None if its attribute store_arrays is unreadable)."""
    try:
        names = json.loads(group.attrs["store_arrays"])
    except (KeyError, TypeError, ValueError):
        return None
    return tuple(names) if isinstance(names, list) and all(isinstance(n, str) for n in names) else None


def check_arrays(argument: str, path: Path, group, names, spec) -> dict[str, Any]:
    """Open every array `names` of the store, check its leading shape (the grid, the chunks or
    the saved nodes); return them (SweepError naming the first one damaged)."""
    zarr = require("zarr", extra="sweeps")

    axes = axes_of(spec)
    grid = tuple(a.count for a in axes)
    counts = {a.dim: a.count for a in axes}
    chunks = layout_of(spec).chunks
    saved = len(saved_steps(int(spec["steps"]), int(spec["save_every"])))
    arrays = {}
    for name in names:
        try:
            arr = group[name]
        except KeyError:
            raise damaged(argument, path, f"its array {name!r} is missing (the directory {name}/ or "
                          f"its metadata {name}/zarr.json was deleted)") from None
        except Exception as e:  # noqa: BLE001
            raise damaged(argument, path, f"the metadata of its array {name!r} ({name}/zarr.json) "
                          f"cannot be read ({why(e)})") from None
        if not isinstance(arr, zarr.Array):
            raise damaged(argument, path, f"{name!r} is not an array")
        if name in MEMBER_VARS:
            expected, what = grid, "along the grid axes"
        elif name in CHUNK_VARS or name == "chunk":
            expected, what = (chunks,), "along its first axis"
        elif name in ("time", "node", "step"):
            expected, what = (saved,), "along its first axis"
        elif name in counts:
            expected, what = (counts[name],), "(the grid axis's values)"
        else:
            continue
        if tuple(arr.shape[: len(expected)]) != expected:
            raise damaged(argument, path, f"its array {name!r} has shape {arr.shape}, expected "
                          f"{expected} {what}")
        arrays[name] = arr
    return arrays


def check_coordinates(argument: str, path: Path, arrays, spec) -> None:
    """The coordinates the sweep's specification determines hold their values (the grid axes,
    the times, the node and step indices, the chunk numbers); the others can be read."""
    steps = saved_steps(int(spec["steps"]), int(spec["save_every"]))
    expected = {
        "chunk": np.arange(layout_of(spec).chunks),
        "time": float(spec["h"]) * steps.astype(np.float64),
        "node": np.arange(len(steps)),
        "step": steps,
        **{a.dim: a.values for a in axes_of(spec)},
    }
    for name in (*COORDS, *(a.dim for a in axes_of(spec))):
        if name not in arrays:
            continue
        try:
            values = np.asarray(arrays[name][...])
        except Exception as e:  # noqa: BLE001
            raise damaged(argument, path, f"its coordinate {name!r} cannot be read ({why(e)})") from None
        if name in expected and not np.array_equal(values, expected[name]):
            raise damaged(argument, path, f"its coordinate {name!r} does not hold the sweep's values")


def read_done(argument: str, path: Path, arrays, chunks: int) -> np.ndarray:
    """The chunk flags `chunk_done` (SweepError if they cannot be read)."""
    try:
        done = np.asarray(arrays["chunk_done"][...], dtype=bool)
    except Exception as e:  # noqa: BLE001
        raise damaged(argument, path, f"its chunk flags (chunk_done) cannot be read ({why(e)})") from None
    if done.shape != (chunks,):
        raise damaged(argument, path, f"chunk_done has shape {done.shape}, expected ({chunks},)")
    return done


def old_format(argument: str, path: Path, spec, action: str) -> SweepError:
    """The SweepError for a store of an earlier format, which this version cannot `action`."""
    fmt = spec.get("format")
    what = {"gnipy-sweep/4": "its dimensions named as the grid, q0.x where they are now q0_x",
            "gnipy-sweep/3": "without the members' verdicts",
            "gnipy-sweep/2": "with a flat member axis (the grid values in grid_NAME)"}.get(
        fmt, "with a flat member axis and without chunk checksums")
    return SweepError(
        f"{argument}: the sweep store {str(path)!r} was written by an earlier gnipy (format {fmt}, {what}) "
        f"and cannot be {action} by this version; its data can still be read with "
        f"xarray.open_zarr(path, consolidated=False); to get a store of the present format, run the "
        "sweep again with overwrite=True, or into another path"
    )


def check_store(argument: str, path: Path, mode: str = "r"):
    """`(spec, arrays, names)` of the sweep store at `path`, its metadata, arrays and coordinates
    checked (SweepError for a store of an earlier format, or one that is damaged)."""
    group, spec = open_group(path, argument, mode)
    if spec["format"] != FORMAT:
        raise old_format(argument, path, spec, "read" if mode == "r" else "resumed")
    names = stored_array_names(group)
    if names is None:
        raise damaged(argument, path, "its attribute store_arrays (the names of its arrays) is missing or "
                      "unreadable")
    arrays = check_arrays(argument, path, group, names, spec)
    check_coordinates(argument, path, arrays, spec)
    return spec, arrays, names
