"""The destination of a streamed run (:mod:`gnipy.streaming`): the parts copied, one at a time
and each verified again, into one netCDF file, written atomically."""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..extras import require
from .. import schema
from ..monitor import RunVerdicts
from ..files import DataChecksum, OutputError, as_stored, atomic_write, remove_owned_dir
from .interrupts import DeferredInterrupt
from .parts import DATA_DIMS, OWN_FILES, ChunkPlan, check_part, clean_own_temporaries, part_path
from .result import SPEC_ATTR, StreamResult, solver_failure

#: For tests: called as `_merge_hook(i)` after the merge has copied part `i` (e.g. to send
#: SIGINT to the process at a chosen moment). Looked up here, where the merge runs: set
#: `gnipy.streaming.merge._merge_hook`.
_merge_hook: Callable[[int], None] | None = None


def _global_attrs(system, method, h, steps, result, it_tot, it_max, n_chunks, attrs, backend: str) -> dict:
    """The destination's global attributes, as :func:`gnipy.io.write_netcdf` writes them."""
    import datetime as _dt

    from ..file_attributes import attribute_value, cf_attributes, provenance
    from ..io import CHECKSUM_ATTR
    from ..schema import CONVENTIONS, UNITS_CONVENTION
    from ..system import describe_orientations

    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out = {
        **cf_attributes(system.name, method.name, created=created),
        "model": system.name, "method": method.name, "h": float(h), "steps": int(steps), "start": method.start_label,
        "method_settings": json.dumps(method.settings(), sort_keys=True), "backend": backend,
        "result": int(result), "newton_iterations_total": int(it_tot), "newton_iterations_max": int(it_max),
        "streamed_chunks": int(n_chunks), "params": json.dumps(dict(system.params)),
        **{f"param_{k}": float(v) for k, v in system.params},
    }
    if system.group is not None:
        out["orientation"] = describe_orientations(system)
    for k, v in provenance(created=created).items():
        out.setdefault(k, v)
    out.setdefault("units_convention", UNITS_CONVENTION)
    out.setdefault("Conventions", CONVENTIONS)
    out.setdefault("history", f"{out['created']} gnipy {out['gnipy_version']}: write_netcdf")
    for k, v in attrs.items():
        out[str(k)] = v
    out.pop(CHECKSUM_ATTR, None)
    return {k: attribute_value(v) for k, v in out.items()}


def _write_destination(tmp: Path, files, counts, system, first: dict, load, interrupt) -> tuple:
    """Copy the parts, one at a time, into a new netCDF file `tmp` (the layout of
    :meth:`gnipy.Solution.to_xarray` written by :func:`gnipy.io.write_netcdf`), acting on SIGINT
    between parts. `load(i)` reads and verifies part `i`. Returns the open file and the checksum
    of its data; the caller adds the global attributes and closes it."""
    netCDF4 = require("netCDF4", extra="files")

    data0 = first["data"]
    names = [v for v in DATA_DIMS if v in data0]
    sizes = {"time": int(sum(counts))}
    for v in names:
        for d, n in zip(DATA_DIMS[v][1:], data0[v].shape[1:]):
            sizes[d] = int(n)
    checksum = DataChecksum()  # as gnipy.io.netcdf_checksum will compute it from the file
    nc = netCDF4.Dataset(os.fspath(tmp), "w", clobber=False, format="NETCDF4")
    try:
        out = _create_variables(nc, names, data0, sizes, _component_names(system, sizes), checksum)
        offset = 0
        for i, f in enumerate(files):
            part = first if i == 0 else load(i)
            if part["n"] != counts[i]:
                raise OutputError(f"{f} changed while it was merged; rerun with resume=True")
            d = part["data"]
            if sorted(v for v in d if v in DATA_DIMS) != sorted(names) or any(
                    d[v].shape[1:] != data0[v].shape[1:] for v in names):
                raise OutputError(f"{f}: its variables differ from those of {files[0].name}; rerun with "
                                  "resume=True to compute it again")
            offset = _copy_part(out, d, names, offset, part["n"], checksum)
            if _merge_hook is not None:
                _merge_hook(i)
            interrupt.check()
        return nc, checksum
    except BaseException:
        nc.close()
        raise


def _component_names(system, sizes: dict) -> dict[str, list[str]]:
    """The names of the components along `coordinate` and `velocity` (the system's, or numbered
    when their number is not the file's)."""
    coordinates = [str(x) for x in system.coordinates]
    velocities = [str(x) for x in system.velocities]
    if len(coordinates) != sizes["coordinate"]:
        coordinates = [f"q{i}" for i in range(sizes["coordinate"])]
    if len(velocities) != sizes["velocity"]:
        velocities = [f"v{i}" for i in range(sizes["velocity"])]
    return {"coordinate": coordinates, "velocity": velocities}


def _create_variables(nc, names, data0: dict, sizes: dict, names_of: dict, checksum: DataChecksum) -> dict:
    """Create the dimensions and variables of the destination `nc` (the attributes of
    :func:`gnipy.schema.apply`, in write_netcdf's order), writing the coordinates that do not run
    along `time`. Returns the variables along `time`, by name."""
    for d in ("time", "coordinate", "velocity", "constraint", "i", "j"):
        if d in sizes:
            nc.createDimension(d, sizes[d])
    out = {}
    for v in names:
        var = nc.createVariable(v, data0[v].dtype, DATA_DIMS[v], fill_value=np.nan)
        var.setncatts(schema.variable_attrs(v))
        components = schema.VARIABLES[v].components
        if components:
            var.setncattr("components", ", ".join(names_of[components]))
        var.setncattr("coordinates", "node step")
        out[v] = var
    for name in ("time", "step", "node"):
        out[name] = nc.createVariable(name, schema.VARIABLES[name].dtype, schema.dims(name))
        out[name].setncatts(schema.variable_attrs(name))
    for name, values in names_of.items():
        a = np.array(values, dtype=object)
        var = nc.createVariable(name, str, schema.dims(name))
        var.setncatts(schema.variable_attrs(name))
        var[:] = a
        checksum.update(name, as_stored(a))  # (none: the coordinates of a model on G alone)
    constraint = np.arange(sizes["constraint"], dtype=np.int64)
    var = nc.createVariable("constraint", np.int64, schema.dims("constraint"))
    var.setncatts(schema.variable_attrs("constraint"))
    var[:] = constraint
    checksum.update("constraint", as_stored(constraint))
    return out


def _copy_part(out: dict, d: dict, names, offset: int, n: int, checksum: DataChecksum) -> int:
    """Write the `n` nodes of a part's data `d` into the variables `out` from node `offset` on;
    returns the next offset."""
    if n:
        rows = slice(offset, offset + n)
        for v in (*names, "time", "step"):
            if d[v].size:  # (a variable with an empty dimension, e.g. no constraints, holds nothing)
                out[v][rows] = d[v]
            checksum.update(v, d[v])
        node = np.arange(offset, offset + n, dtype=np.int64)
        out["node"][rows] = node
        checksum.update("node", node)
        offset += n
    return offset


def _part_stats(part: dict) -> dict:
    """What the merge keeps of a verified part: its outcome, iterations, energy range, largest
    constraint residual and last node."""
    d, a = part["data"], part["attrs"]
    e = d["energy"]
    return dict(result=part["result"], failed=part["failed"], residual=float(a["residual"]),
                backend=str(a.get("backend", "unknown")),
                it_tot=int(a["iterations_total"]), it_max=int(a["iterations_max"]),
                e_min=float(e.min()) if e.size else np.inf, e_max=float(e.max()) if e.size else -np.inf,
                res=float(np.max(np.abs(d["constraint_residual"]), initial=0.0)),
                e0=float(e[0]) if e.size else np.nan, q=d["q"][-1:], v=d["v"][-1:], n=part["n"])


def _node_counts(files) -> list[int]:
    """The nodes of every part (headers only), for the size of `time`."""
    netCDF4 = require("netCDF4", extra="files")

    counts = []
    for f in files:
        try:
            with netCDF4.Dataset(os.fspath(f), "r") as nc:
                counts.append(len(nc.dimensions["time"]))
        except Exception as e:  # noqa: BLE001
            raise OutputError(f"{f} does not verify (it cannot be read: {e}); rerun with resume=True "
                              "to compute it again") from None
    return counts


def _outcome(stats: list[dict]) -> tuple[int, int]:
    """`(result, failed_step)` of the run whose parts have `stats` (failed_step -1: none failed)."""
    result = max(s["result"] for s in stats)
    failed_step = next((s["failed"] for s in stats if s["result"]), -1)
    return result, failed_step


def _destination_attrs(stats: list[dict], found: RunVerdicts, method, system, h, t0, steps, n_chunks, attrs,
                       spec) -> dict:
    """The destination's global attributes: the outcome, health and verdicts of the run, its spec
    and `attrs`."""
    result, failed_step = _outcome(stats)
    health = "failed" if result else ("healthy" if found.in_band else "qualitatively wrong")
    extra = dict(attrs, **found.attrs(method.name, system.name), health=health)
    if result:  # as Solution.to_xarray records a failure
        s = next(s for s in stats if s["result"])
        extra = {"failed_step": int(failed_step), "failed_residual": float(s["residual"]),
                 "failed_time": float(t0 + h * failed_step), **extra}
    extra[SPEC_ATTR] = json.dumps(spec, sort_keys=True)
    backends = sorted({s["backend"] for s in stats})
    return _global_attrs(system, method, h, steps, result, sum(s["it_tot"] for s in stats),
                         max(s["it_max"] for s in stats), n_chunks, extra, " and ".join(backends))


def merge_parts(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant=False, *,
            overwrite, plan: ChunkPlan, spec, notes):
    """Copy the parts (one in memory at a time, each verified again) into `path`, atomically;
    then remove them."""
    from ..io import CHECKSUM_ATTR

    files = [part_path(parts, c) for c in range(n_chunks)]
    stats = []
    watch = []  # the last part's monitor: the verdicts of the whole run (gnipy.monitor)

    def load(c: int) -> dict:
        part, why = check_part(files[c], c, plan)
        if part is None:
            raise OutputError(f"{files[c]} does not verify ({why}); rerun with resume=True to compute "
                              "it again")
        watch[:] = [part["data"]["monitor"]]
        stats.append(_part_stats(part))
        return part

    counts = _node_counts(files)
    first = load(0)
    gni_family = "hidden_momentum" in first["data"]

    def verdicts() -> RunVerdicts:
        return RunVerdicts(watch[0], gni_family)

    def write(tmp: Path) -> None:
        nc, checksum = _write_destination(tmp, files, counts, system, first, load, interrupt)
        try:
            nc.setncatts(_destination_attrs(stats, verdicts(), method, system, h, t0, steps, n_chunks, attrs, spec))
            nc.setncattr(CHECKSUM_ATTR, checksum.hexdigest())
        finally:
            nc.close()
        interrupt.check()

    with DeferredInterrupt() as interrupt:
        atomic_write(path, write, overwrite=overwrite, argument="path")
    clean_own_temporaries(parts)
    if not remove_owned_dir(parts, OWN_FILES) and parts.exists():
        notes.append(f"{parts} is kept: it holds files gnipy did not write")
    if interrupt.pending:  # Ctrl-C as the file was renamed: it is complete; stop here
        raise KeyboardInterrupt
    out = _merged_result(path, stats, verdicts(), method, system, steps, n_chunks, resumed, notes)
    if out.result and throw:
        s = next(s for s in stats if s["result"])
        raise solver_failure(method.name, out.failed_step, t0, h, s["residual"], path)
    return out


def _merged_result(path, stats: list[dict], found: RunVerdicts, method, system, steps, n_chunks, resumed,
                   notes) -> StreamResult:
    """The :class:`StreamResult` of the run merged into `path`, from its parts' `stats`."""
    result, failed_step = _outcome(stats)
    nodes = sum(s["n"] for s in stats)
    e0 = stats[0]["e0"]
    energy_error = max((max(abs(s["e_max"] - e0), abs(s["e_min"] - e0)) for s in stats if s["n"]), default=np.nan)
    last = next(s for s in reversed(stats) if s["n"])  # part 0 always holds the initial node
    return StreamResult(
        path=path, complete=True, nodes=nodes, steps=steps if result == 0 else failed_step, chunks=n_chunks,
        chunks_resumed=resumed, result=result, failed_step=failed_step, energy_error=float(energy_error),
        constraint_residual=max(s["res"] for s in stats),
        iterations=(int(sum(s["it_tot"] for s in stats)), int(max(s["it_max"] for s in stats))),
        final_q=np.asarray(last["q"][-1]), final_v=np.asarray(last["v"][-1]),
        warnings=[*notes, *found.warnings(method.name, system.name)],
        healthy=not result and found.in_band,
    )
