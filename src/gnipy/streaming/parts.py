"""The part files of a streamed run (:mod:`gnipy.streaming`): the parts directory `PATH.parts/`,
writing a part, reading and verifying one (checksum, spec hash, chunk index, integrator state,
`time` and `step`), and preparing the directory for a fresh or resumed run."""

from __future__ import annotations

import os
import re
import stat
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..extras import require
from .. import schema
from ..files import MARKER, DataChecksum, OutputError, clean_stale_temporaries, is_owned_dir, make_owned_dir

#: The attribute of a part file that holds the SHA-256 of the run's specification (what is computed).
SPEC_HASH_ATTR = "stream_spec_sha256"
#: The attribute of a part file that holds its chunk index.
CHUNK_ATTR = "stream_chunk"
_PURPOSE = "checkpoint parts of a streamed run (gnipy.simulate_to_file)"
_PART = re.compile(r"^part_(\d{6,})\.nc$")
#: gnipy's own files in a parts directory (all that starting afresh or finishing removes).
OWN_FILES = ("spec.json", "part_*.nc")

#: The variables along `time` of a result file, with their dimensions (gnipy.schema).
DATA_DIMS = {name: schema.dims(name) for name in (
    "q", "v", "p", "energy", "constraint_residual", "R", "hidden_momentum", "hidden_momentum_expected",
    "energy_plus")}


def parts_directory(path) -> Path:
    """The directory of part files of a streamed run writing `path` (`PATH.parts`)."""
    path = Path(os.fspath(path))
    return path.with_name(path.name + ".parts")


def part_path(parts: Path, c: int) -> Path:
    """The part file of chunk `c` in the parts directory `parts` (`part_000012.nc`)."""
    return parts / f"part_{c:06d}.nc"


# ------------------------------------------------------------------------------------------
# Part files
# ------------------------------------------------------------------------------------------
def storable_array(a) -> np.ndarray:
    """`a` as netCDF can store it (booleans as uint8)."""
    a = np.asarray(a)
    return a.astype(np.uint8) if a.dtype == np.bool_ else a


def write_part(tmp: Path, variables: dict[str, tuple[tuple[str, ...], np.ndarray]], attrs: dict) -> None:
    """Write one part file (netCDF4, no xarray) at `tmp`, with the checksum of its data (that of
    :func:`gnipy.io.netcdf_checksum`, computed from the arrays written)."""
    netCDF4 = require("netCDF4", extra="files")

    from ..io import CHECKSUM_ATTR

    arrays = {name: np.asarray(a) for name, (_, a) in variables.items()}
    with netCDF4.Dataset(os.fspath(tmp), "w", clobber=False, format="NETCDF4") as nc:
        for name, (dims, a) in variables.items():
            for d, n in zip(dims, a.shape):
                if d not in nc.dimensions:
                    nc.createDimension(d, n)
        for name, (dims, a) in variables.items():
            var = nc.createVariable(name, a.dtype, dims)
            if a.ndim == 0:
                var.assignValue(a)
            elif a.size:
                var[...] = a
        nc.setncatts(attrs)
        nc.setncattr(CHECKSUM_ATTR, _checksum_of(arrays))


def _read_raw(nc) -> dict[str, np.ndarray]:
    """Every variable of an open netCDF file as stored (no masking or scaling)."""
    nc.set_auto_maskandscale(False)
    nc.set_always_mask(False)
    out = {}
    for name, var in nc.variables.items():
        out[name] = np.asarray(var[...]) if var.ndim == 0 or var.shape[0] else np.zeros(var.shape, var.dtype)
    return out


def _checksum_of(arrays: Mapping[str, np.ndarray]) -> str:
    """:func:`gnipy.io.netcdf_checksum` of a file whose variables are `arrays` (as stored)."""
    c = DataChecksum()
    for name in sorted(arrays):
        a = arrays[name]
        if a.ndim and a.shape[0] == 0:
            c.update(name, np.zeros((0, *a.shape[1:])))  # as netcdf_checksum reads an empty variable
        else:
            c.update(name, a)
    return c.hexdigest()


@dataclass
class ChunkPlan:
    """What the chunks of a run are: for checking parts against it."""

    steps: int
    save_every: int
    chunk_steps: int
    t0: float
    h: float
    spec_hash: str
    leaves: list  # the integrator state's leaves at the start (shapes and dtypes)
    group: bool

    def chunk(self, c: int):
        """(k_start, length, n_blocks, remainder, k_local, keep) of chunk `c`."""
        k_start = c * self.chunk_steps
        length = min(self.chunk_steps, self.steps - k_start)
        n_blocks, remainder = divmod(length, self.save_every)
        k_local = np.concatenate([np.arange(n_blocks + 1) * self.save_every, [length] if remainder else []]
                                 ).astype(np.int64)
        keep = np.ones(len(k_local), dtype=bool)
        if c > 0:
            keep[0] = False  # the chunk's first node is the previous chunk's last
        return k_start, length, n_blocks, remainder, k_local, keep

    def times(self, k_start: int, k_local: np.ndarray) -> np.ndarray:
        return self.t0 + self.h * (k_start + k_local)


_REQUIRED = ("time", "step", "q", "v", "p", "energy", "constraint_residual")


def check_part(file: Path, c: int, plan: ChunkPlan) -> tuple[dict | None, str]:
    """Read and verify part `c`: `(part, "")`, or `(None, why)` when it does not verify."""
    netCDF4 = require("netCDF4", extra="files")

    try:
        with netCDF4.Dataset(os.fspath(file), "r") as nc:
            attrs = {k: nc.getncattr(k) for k in nc.ncattrs()}
            data = _read_raw(nc)
    except Exception as e:  # noqa: BLE001 - any failure to read is "does not verify"
        return None, f"it cannot be read ({type(e).__name__}: {e})"
    try:
        return _check_contents(attrs, data, c, plan)
    except (ValueError, TypeError, KeyError, IndexError, OverflowError) as e:
        return None, f"its contents are not those of a checkpoint ({type(e).__name__}: {e})"


def _check_contents(attrs: dict, data: dict, c: int, plan: ChunkPlan) -> tuple[dict | None, str]:
    why = _check_attributes(attrs, data, c, plan)
    if why:
        return None, why
    result = int(attrs["result"])
    leaves, why = _check_state(data, plan, result)
    if why:
        return None, why
    n = int(data["time"].shape[0])
    why = _check_nodes(attrs, data, c, plan, result, n)
    if why:
        return None, why
    return {"data": data, "attrs": attrs, "n": n, "result": result, "failed": int(attrs["failed_step"]),
            "leaves": leaves}, ""


def _check_attributes(attrs: dict, data: dict, c: int, plan: ChunkPlan) -> str:
    """Why a part's attributes (and checksum) are not those of chunk `c` of the run, with the
    variables it must hold; "" when they are."""
    for key in ("gnipy_checksum", SPEC_HASH_ATTR, CHUNK_ATTR, "result", "failed_step", "residual",
                "iterations_total", "iterations_max"):
        if key not in attrs:
            return f"it has no attribute {key!r} (not a checkpoint of this gnipy)"
    if attrs[SPEC_HASH_ATTR] != plan.spec_hash:
        return "it belongs to a different run (its spec hash differs from spec.json's)"
    if int(attrs[CHUNK_ATTR]) != c:
        return f"it holds chunk {int(attrs[CHUNK_ATTR])}, not chunk {c}"
    actual = _checksum_of(data)
    if actual != attrs["gnipy_checksum"]:
        return f"its data do not match its checksum ({attrs['gnipy_checksum']}; computed {actual})"
    missing = [v for v in (*_REQUIRED, "monitor", *(("R",) if plan.group else ())) if v not in data]
    if missing:
        return f"it lacks the variable(s) {', '.join(missing)}"
    return ""


def _check_state(data: dict, plan: ChunkPlan, result: int) -> tuple[list, str]:
    """`(leaves, "")`, the integrator state stored in a part (as the plan's leaves), or `([], why)`
    when it is not one of the plan's shapes and dtypes (or, in a part that did not fail, not finite)."""
    leaves = []
    for i, x in enumerate(plan.leaves):
        a = data.get(f"state_{i}")
        want = storable_array(x)
        if a is None:
            return [], f"it lacks the integrator state state_{i}"
        if a.shape != want.shape or a.dtype != want.dtype:
            return [], (f"its integrator state state_{i} has shape {a.shape} and dtype {a.dtype}, "
                        f"expected {want.shape} and {want.dtype}")
        if result == 0 and a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
            return [], f"its integrator state state_{i} is not finite"
        leaves.append(a.astype(np.asarray(x).dtype) if a.dtype != np.asarray(x).dtype else a)
    if f"state_{len(plan.leaves)}" in data:
        return [], f"it holds more than the {len(plan.leaves)} arrays of the integrator state"
    return leaves, ""


def _check_nodes(attrs: dict, data: dict, c: int, plan: ChunkPlan, result: int, n: int) -> str:
    """Why the `n` nodes of a part (their variables' shapes, the monitor, `time` and `step`, the
    failed step) are not those of chunk `c`; "" when they are."""
    k_start, length, _, _, k_local, keep = plan.chunk(c)
    want_steps = (k_start + k_local)[keep]
    want_times = plan.times(k_start, k_local)[keep]
    for v, dims in (*DATA_DIMS.items(), ("time", ("time",)), ("step", ("time",))):
        if v in data and (data[v].ndim != len(dims) or data[v].shape[0] != n):
            return f"its variable {v} has shape {data[v].shape}, not {len(dims)} dimensions along {n} nodes"
    from ..monitor import SIZE

    if data["monitor"].shape != (SIZE,) or data["monitor"].dtype != np.float64:
        return f"its monitor has shape {data['monitor'].shape}, expected ({SIZE},)"
    failed = int(attrs["failed_step"])
    if result == 0:
        if n != len(want_steps) or failed != -1:
            return f"it holds {n} nodes, expected {len(want_steps)}"
    elif n > len(want_steps) or not (k_start <= failed < k_start + length):
        return f"its failed step {failed} is not in the chunk (steps {k_start} to {k_start + length})"
    if not (np.array_equal(data["step"], want_steps[:n]) and np.array_equal(data["time"], want_times[:n])):
        return "its time and step do not continue where the previous part ended"
    return ""


def clean_own_temporaries(parts: Path) -> None:
    """Remove the temporaries of dead processes inside the parts directory."""
    names = set()
    try:
        entries = list(os.scandir(parts))
    except OSError:
        return
    pattern = re.compile(r"^\.(spec\.json|part_\d{6,}\.nc)\.")
    for entry in entries:
        m = pattern.match(entry.name)
        if m:
            names.add(m.group(1))
    for name in names:
        clean_stale_temporaries(parts / name)


def part_indices(parts: Path) -> list[tuple[int, Path]]:
    """`(chunk, file)` of every part file in `parts`, in chunk order (none when it cannot be read)."""
    out = []
    try:
        entries = list(os.scandir(parts))
    except OSError:
        return out
    for entry in entries:
        m = _PART.match(entry.name)
        if m:
            out.append((int(m.group(1)), Path(entry.path)))
    return sorted(out)


def _remove(files, parts: Path) -> None:
    for f in files:
        try:
            f.unlink()
        except FileNotFoundError:
            pass
        except OSError as e:
            raise OutputError(f"cannot remove {f} (in {parts}): {e.strerror or e}") from None


def prepare_parts(parts: Path, path: Path, resume: bool, note) -> bool:
    """Make `parts` gnipy's working directory; returns whether it holds a run to resume."""
    try:
        st = os.lstat(parts)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise OutputError(f"cannot use {parts}: {e.strerror or e}") from None
    move = (f"gnipy keeps the checkpoints of {path} there and will not write into or delete it: "
            "move it away (or choose another destination)")
    if st is None:
        make_owned_dir(parts, _PURPOSE)
        return False
    if not stat.S_ISDIR(st.st_mode):
        kind = "a symbolic link" if stat.S_ISLNK(st.st_mode) else "not a directory"
        raise OutputError(f"{parts} is {kind}; {move}")
    if not is_owned_dir(parts):
        try:
            empty = not any(parts.iterdir())
        except OSError as e:
            raise OutputError(f"cannot use {parts}: {e.strerror or e}") from None
        if not empty:
            raise OutputError(f"{parts} is a directory gnipy did not create (it has no {MARKER} marker) and is "
                              f"not empty; {move}")
        try:
            parts.rmdir()  # an empty directory: gnipy's own from here on
        except OSError as e:
            raise OutputError(f"cannot use {parts}: {e.strerror or e}") from None
        make_owned_dir(parts, _PURPOSE)
        return False
    if not os.access(parts, os.W_OK | os.X_OK):
        raise OutputError(f"cannot write {parts}: permission denied")
    clean_own_temporaries(parts)
    if resume and (parts / "spec.json").is_file():
        return True
    old = part_indices(parts)
    if old:
        note(f"{parts}: the {len(old)} checkpoint part(s) of an earlier run are discarded (resume=True "
             "continues a run instead)")
    _remove([parts / "spec.json", *(f for _, f in old)], parts)
    return False


def verify_parts(parts: Path, plan: ChunkPlan, n_chunks: int, note) -> tuple[int, dict | None, int]:
    """Verify the parts of an interrupted run in order; remove the first bad one and every later
    one. Returns (good parts, the last good part, the number of chunks of the run)."""
    existing = part_indices(parts)
    done, last, why = 0, None, ""
    while done < n_chunks:
        f = part_path(parts, done)
        if not f.is_file():
            if any(i > done for i, _ in existing):
                why = "it is missing"
            break
        part, why = check_part(f, done, plan)
        if part is None:
            break
        done, last = done + 1, part
        if part["result"] != 0:  # the interrupted run had already failed: nothing to add
            n_chunks = done
            break
    stale = [f for i, f in existing if i >= done]
    if why:
        later = len([i for i, _ in existing if i > done])
        start = f"from {part_path(parts, done - 1).name}" if done else "from the start"
        note(f"checkpoint {part_path(parts, done).name} in {parts} does not verify: {why}; it"
             + (f" and the {later} later part(s) are" if later else " is") + f" computed again {start}")
    _remove(stale, parts)
    return done, last, n_chunks
