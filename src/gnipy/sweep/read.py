"""Reading a sweep store back: :func:`open_sweep` and :func:`verify_sweep`."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

from ..extras import require
from .errors import SweepError, SweepWarning
from .grid import axes_of, describe_members
from .integrity import list_bad, verify_chunks
from .ownership import is_store
from .plan import layout_of
from .store import check_store, read_done

__all__ = ["open_sweep", "verify_sweep"]


def _inspect(p: Path, argument: str):
    """`(spec, layout, arrays, names)` of the store at `p`, its metadata, arrays and coordinates
    checked. SweepError for a path that is not a sweep store, a store of an earlier format, or
    damaged metadata."""
    if not is_store(p):
        raise SweepError(f"{argument}: {str(p)!r} is not a gnipy sweep store")
    spec, arrays, names = check_store(argument, p)
    return spec, layout_of(spec), arrays, names


def verify_sweep(path) -> tuple[bool, str, list[int]]:
    """Check a sweep store without changing it: its metadata, arrays and coordinates, and
    every chunk flagged done (read back, its checksum recomputed).

    Returns:
        `(ok, message, bad_chunks)`: `ok` is True when everything checked is intact (an
        incomplete sweep can be intact: the message says how many chunks are done);
        `message` a sentence naming the store and what is damaged; `bad_chunks` the indices
        of the done chunks that are unreadable or whose data differ from their checksum
        (running the same sweep again recomputes them). Damaged metadata or a missing array
        give `ok = False` and no chunk (start afresh: run the sweep again with
        `overwrite=True`). A store of an earlier format gives `ok = False`: it cannot be
        verified by this version.

    Raises:
        SweepError: `path` is not a gnipy sweep store.
    """
    p = Path(os.fspath(path)).expanduser()
    try:
        spec, layout, arrays, names = _inspect(p, "path")
        done = read_done("path", p, arrays, layout.chunks)
    except SweepError as e:
        if not is_store(p):
            raise
        return False, str(e).partition(": ")[2], []
    bad = verify_chunks(arrays, names, layout, done)
    n_done = int(done.sum())
    if bad:
        return (False, f"the sweep store {str(p)!r} is damaged: {len(bad)} of its {n_done} done chunk(s) "
                f"cannot be trusted ({list_bad(axes_of(spec), layout, bad)}); run the same sweep again to "
                "compute them again", sorted(bad))
    state = ("complete" if n_done == done.size else
             f"incomplete: {n_done} of {done.size} chunks done (run the same sweep again to resume)")
    return True, (f"the sweep store {str(p)!r} is intact: {n_done} done chunk(s) read back and "
                  f"their checksums match; {state}"), []


def open_sweep(path, *, allow_incomplete: bool = False, verify: bool = True):
    """Open a sweep store as an `xarray.Dataset` with the grid axes as dimensions.

    This is `xarray.open_zarr(path)` (the store holds its variables with the grid axes as
    dimensions, named after the axes (`.` written `_`: `q0_x`) in the order of the grid, with the
    grid values as coordinates: e.g. `q(m, Omega, time, coordinate)`; the data are loaded lazily with dask),
    after the checks below, and with the members of chunks not done marked.

    Arguments:
        path: the store written by :func:`run_sweep`.
        allow_incomplete: open a sweep whose chunks are not all done: the members of the
            chunks not done (and, with `verify`, of damaged chunks, with a
            :class:`SweepWarning`) get `valid = False` and `result = -1` (their other data
            are not meaningful).
        verify: first read every done chunk back and compare its checksum (see
            :func:`verify_sweep`; this reads the whole store once).

    Raises:
        SweepError: not a sweep store, a store of an earlier format, damaged metadata or
            arrays, (with `verify`) a damaged chunk, or (without `allow_incomplete`) an
            incomplete sweep.
    """
    xr = require("xarray", extra="sweeps")

    p = Path(os.fspath(path)).expanduser()
    spec, layout, arrays, names = _inspect(p, "path")
    axes = axes_of(spec)
    done = read_done("path", p, arrays, layout.chunks)
    if verify:
        bad = verify_chunks(arrays, names, layout, done)
        if bad and not allow_incomplete:
            raise SweepError(
                f"path: the sweep store {str(p)!r} is damaged: {len(bad)} done chunk(s) cannot be "
                f"trusted ({list_bad(axes, layout, bad)}); run the same sweep again to compute them "
                "again, or pass allow_incomplete=True to open the rest"
            )
        for i, reason in bad.items():
            warnings.warn(SweepWarning(
                f"path: chunk {i} of {str(p)!r}, {describe_members(axes, *layout.member_range(i))}, is "
                f"damaged ({reason}): its members are marked not done"), stacklevel=2)
            done[i] = False
    if not done.all() and not allow_incomplete:
        raise SweepError(
            f"path: the sweep in {str(p)!r} is incomplete ({int(done.sum())} of {done.size} chunks "
            "done); run it again to resume, or pass allow_incomplete=True"
        )
    ds = xr.open_zarr(str(p))
    if not done.all():
        member_done = xr.DataArray(layout.member_mask(done), dims=tuple(a.dim for a in axes))
        for name, masked in (("valid", ds["valid"] & member_done), ("result", ds["result"].where(member_done, -1))):
            ds[name] = masked.assign_attrs(ds[name].attrs)
    return ds
