"""Long runs streamed to a file in chunks, with verified checkpoints and resume.

:func:`simulate_to_file` integrates like :func:`gnipy.simulate` but never holds more than one chunk
of saved nodes in memory: every `chunk_steps` steps, the chunk's nodes and the integrator's state
at its end are committed to a *part file*; at the end the parts are copied, one at a time, into
the destination netCDF file. Memory is therefore bounded by one chunk, whatever the number of
steps.

**Files, and what gnipy owns.** The destination is checked first
(:func:`gnipy.files.check_destination`): nothing there, or a regular file and `overwrite=True`;
never a symbolic link, a directory or a special file. While the run is under way, the parts live
in the directory `PATH.parts/` next to the destination, which gnipy creates with its marker file
`.gnipy-owned` (:func:`gnipy.files.make_owned_dir`): `spec.json` (what is being computed) and
`part_000000.nc`, `part_000001.nc`, ... A `PATH.parts` that gnipy did not create (no marker) and
that is not empty is never written into nor deleted: the run stops with an
:class:`~gnipy.files.OutputError` asking to move it. Starting afresh in gnipy's own `PATH.parts`
removes only gnipy's files there (`spec.json`, `part_*.nc`, temporaries of dead processes); when
the destination is complete, those are removed and the directory with them, unless someone put
another file in it (the directory then stays, with that file).

**Atomic writes.** Each part and the destination are written to a temporary file and renamed
(:func:`gnipy.files.atomic_write`): a file either is complete or does not exist, whenever the
process dies, and an existing destination is untouched until the new one is complete. A failed
write (a full disk: the netCDF library's `HDF error` included) is an
:class:`~gnipy.files.OutputError` naming the file; the temporary is removed. Temporaries left by
a process that was killed (SIGKILL, power loss) are removed by the next run
(:func:`gnipy.files.clean_stale_temporaries`).

**Checksums.** Every part carries the checksum of its data (global attribute `gnipy_checksum`,
:func:`gnipy.io.netcdf_checksum`: every variable, the integrator state `state_*` included), the
chunk's index (`stream_chunk`) and the SHA-256 of the run's spec (`stream_spec_sha256`, the
canonical JSON of `spec.json`). The destination carries its own `gnipy_checksum`
(:func:`gnipy.io.verify_netcdf`, `gni verify`) and the spec as JSON (`stream_spec`).

**Resume.** With `resume=True`, a run whose `PATH.parts/` exists continues after its last good
part, from the integrator state stored in that part (float64, exact). The continuation runs the
same compiled chunks as an uninterrupted run, so the result is identical to the last bit. The
stored spec must equal the requested one (model, method, h, steps, stride, chunk length, initial
condition, parameters); a mismatch is an error that names the differing field, and an unreadable
`spec.json` is an error that names it. Every existing part is verified in order: readable, its
checksum, spec hash and chunk index match, its integrator state has the expected shapes and
dtypes and is finite, and its `time` and `step` continue exactly where the previous part ended.
The first part that fails (or is missing while later ones exist) and every later part are
removed and recomputed from the last good part's state, with a warning that names the part and
why (:attr:`StreamResult.warnings`, and the `notice` callback). The merge checks every part once
more as it copies it, so a damaged part never ends up in a complete-looking destination. A run
whose destination is already complete (its `stream_spec` equals the requested spec and its
checksum verifies) is not recomputed: the result is read from the file. A finished destination
that does not verify is an error (rerun with `overwrite=True` to compute it again).

**Interrupts.** The files are written with the netCDF4 library directly (no dask, no xarray
lock), and Ctrl-C (SIGINT) never lands inside an HDF5 call: while a part is written, it takes
effect once the part is committed; during the merge, between two parts: the merge stops within
one part, removes its temporary file and raises `KeyboardInterrupt`; the parts stay, so
`resume=True` finishes the run. (The handler that defers SIGINT is installed only in
the main thread, and only where SIGINT has Python's default handler.)

**Size.** Before computing anything, the size of the destination is estimated (saved nodes ×
bytes per node, from the system's dimensions). A destination larger than `max_bytes`
(:data:`DEFAULT_MAX_BYTES`, 64 GiB, by default) is refused, and so is a run that needs more than
the free space of the destination's file system (about the destination's size twice: the parts
and the destination coexist while they are merged); `max_bytes=None` lifts both checks. The
number of steps is bounded by :data:`gnipy.simulate.MAX_TOTAL_STEPS`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import signal
import stat
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .files import format_bytes, free_bytes

from .analysis.diagnostics import StreamedVerdicts, conserved_quantity, energy_is_invariant
from .files import (
    MARKER,
    DataChecksum,
    OutputError,
    as_output_error,
    atomic_write,
    atomic_write_text,
    check_destination,
    clean_stale_temporaries,
    is_owned_dir,
    make_owned_dir,
    remove_owned_dir,
)
from . import schema
from .integrators.base import Integrator, MethodError
from .models.registry import registered_invariants
from .saveat import SaveAt
from .simulate import MAX_STEPS, _init_one, default_initial_condition, resolve_steps, simulate
from .solution import RESULT_SOLVER_FAILED, SolverFailure
from .errors import InputError
from .system import System

__all__ = ["simulate_to_file", "StreamResult", "parts_directory", "DEFAULT_CHUNK_NODES", "DEFAULT_MAX_BYTES",
           "SPEC_ATTR"]

#: Saved nodes per chunk when `chunk_steps` is not given.
DEFAULT_CHUNK_NODES = 10_000

#: The largest destination :func:`simulate_to_file` writes unless told otherwise (`max_bytes`):
#: 64 GiB.
DEFAULT_MAX_BYTES = 2**36

#: The global attribute of a streamed result file that holds its spec (JSON).
SPEC_ATTR = "stream_spec"

_SPEC_HASH_ATTR = "stream_spec_sha256"
_CHUNK_ATTR = "stream_chunk"
_PURPOSE = "checkpoint parts of a streamed run (gnipy.simulate_to_file)"
_PART = re.compile(r"^part_(\d{6,})\.nc$")
#: gnipy's own files in a parts directory (all that starting afresh or finishing removes).
_OWN_FILES = ("spec.json", "part_*.nc")
#: Estimated overhead (HDF5 header, state, attributes) of one file, in bytes.
_FILE_OVERHEAD = 32 * 1024
#: Nodes read or written at a time when a finished destination is summarized.
_SLICE_NODES = 65_536

#: For tests: called as `_merge_hook(i)` after the merge has copied part `i` (e.g. to send
#: SIGINT to the process at a chosen moment).
_merge_hook: Callable[[int], None] | None = None


@dataclass(frozen=True)
class StreamResult:
    """What :func:`simulate_to_file` did.

    Attributes:
        path: the destination file.
        complete: False when the call stopped early (`stop_after_chunks`): the destination is not
            written, the parts directory holds the chunks done so far (resume continues).
        nodes: saved nodes written.
        steps: steps computed in total (including those of earlier, interrupted runs).
        chunks: number of chunks; `chunks_resumed`: how many came from an earlier run (all of
            them when the destination was already complete).
        result: 0 on success, 1 if a step failed (the file then ends at the last good node).
        failed_step: the failed step, or -1.
        energy_error: max |E − E₀| over the saved nodes.
        constraint_residual: max |μ(v − Y)| over the saved nodes.
        iterations: total Newton iterations and the maximum per step.
        final_q, final_v: the last saved node.
        warnings: the run-time warnings (:meth:`gnipy.Solution.warnings`; the verdicts are also
            file attributes), and those about checkpoints that did not verify and were computed
            again.
    """

    path: Path
    complete: bool
    nodes: int
    steps: int
    chunks: int
    chunks_resumed: int
    result: int
    failed_step: int
    energy_error: float
    constraint_residual: float
    iterations: tuple[int, int]
    final_q: np.ndarray
    final_v: np.ndarray
    warnings: list = dataclasses.field(default_factory=list)


def parts_directory(path) -> Path:
    """The directory of part files of a streamed run writing `path` (`PATH.parts`)."""
    path = Path(os.fspath(path))
    return path.with_name(path.name + ".parts")


def _part_path(parts: Path, c: int) -> Path:
    return parts / f"part_{c:06d}.nc"




# ------------------------------------------------------------------------------------------
# SIGINT deferred during HDF5 calls
# ------------------------------------------------------------------------------------------
class _DeferredInterrupt:
    """While active, SIGINT only sets `pending` (the HDF5 call under way completes); `check()`
    raises `KeyboardInterrupt` between calls. Installed only in the main thread and only where
    SIGINT has Python's default handler (an ignored SIGINT or the caller's own handler is left
    alone)."""

    def __init__(self):
        self.pending = False
        self._old = None

    def _handler(self, signum, frame):
        self.pending = True

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            try:
                if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
                    self._old = signal.signal(signal.SIGINT, self._handler)
            except (ValueError, OSError):  # pragma: no cover - not the main interpreter
                self._old = None
        return self

    def check(self) -> None:
        if self.pending:
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
            self._old = None
        return False


# ------------------------------------------------------------------------------------------
# Part files
# ------------------------------------------------------------------------------------------
def _storage(a) -> np.ndarray:
    """`a` as netCDF can store it (booleans as uint8)."""
    a = np.asarray(a)
    return a.astype(np.uint8) if a.dtype == np.bool_ else a


def _write_part(tmp: Path, variables: dict[str, tuple[tuple[str, ...], np.ndarray]], attrs: dict) -> None:
    """Write one part file (netCDF4, no xarray) at `tmp`, with the checksum of its data (that of
    :func:`gnipy.io.netcdf_checksum`, computed from the arrays written)."""
    import netCDF4

    from .io import CHECKSUM_ATTR

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
class _Plan:
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


def _check_part(file: Path, c: int, plan: _Plan) -> tuple[dict | None, str]:
    """Read and verify part `c`: `(part, "")`, or `(None, why)` when it does not verify."""
    import netCDF4

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


def _check_contents(attrs: dict, data: dict, c: int, plan: _Plan) -> tuple[dict | None, str]:
    for key in ("gnipy_checksum", _SPEC_HASH_ATTR, _CHUNK_ATTR, "result", "failed_step", "residual",
                "iterations_total", "iterations_max"):
        if key not in attrs:
            return None, f"it has no attribute {key!r} (not a checkpoint of this gnipy)"
    if attrs[_SPEC_HASH_ATTR] != plan.spec_hash:
        return None, "it belongs to a different run (its spec hash differs from spec.json's)"
    if int(attrs[_CHUNK_ATTR]) != c:
        return None, f"it holds chunk {int(attrs[_CHUNK_ATTR])}, not chunk {c}"
    actual = _checksum_of(data)
    if actual != attrs["gnipy_checksum"]:
        return None, f"its data do not match its checksum ({attrs['gnipy_checksum']}; computed {actual})"
    missing = [v for v in (*_REQUIRED, *(("R",) if plan.group else ())) if v not in data]
    if missing:
        return None, f"it lacks the variable(s) {', '.join(missing)}"
    result = int(attrs["result"])
    leaves = []
    for i, x in enumerate(plan.leaves):
        a = data.get(f"state_{i}")
        want = _storage(x)
        if a is None:
            return None, f"it lacks the integrator state state_{i}"
        if a.shape != want.shape or a.dtype != want.dtype:
            return None, (f"its integrator state state_{i} has shape {a.shape} and dtype {a.dtype}, "
                          f"expected {want.shape} and {want.dtype}")
        if result == 0 and a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
            return None, f"its integrator state state_{i} is not finite"
        leaves.append(a.astype(np.asarray(x).dtype) if a.dtype != np.asarray(x).dtype else a)
    if f"state_{len(plan.leaves)}" in data:
        return None, f"it holds more than the {len(plan.leaves)} arrays of the integrator state"
    k_start, length, _, _, k_local, keep = plan.chunk(c)
    want_steps = (k_start + k_local)[keep]
    want_times = plan.times(k_start, k_local)[keep]
    n = int(data["time"].shape[0])
    for v, dims in (*_DATA_DIMS.items(), ("time", ("time",)), ("step", ("time",))):
        if v in data and (data[v].ndim != len(dims) or data[v].shape[0] != n):
            return None, f"its variable {v} has shape {data[v].shape}, not {len(dims)} dimensions along {n} nodes"
    failed = int(attrs["failed_step"])
    if result == 0:
        if n != len(want_steps) or failed != -1:
            return None, f"it holds {n} nodes, expected {len(want_steps)}"
    elif n > len(want_steps) or not (k_start <= failed < k_start + length):
        return None, f"its failed step {failed} is not in the chunk (steps {k_start} to {k_start + length})"
    if not (np.array_equal(data["step"], want_steps[:n]) and np.array_equal(data["time"], want_times[:n])):
        return None, "its time and step do not continue where the previous part ended"
    return {"data": data, "attrs": attrs, "n": n, "result": result, "failed": failed, "leaves": leaves}, ""


def _own_temporaries(parts: Path) -> None:
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


def _part_indices(parts: Path) -> list[tuple[int, Path]]:
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


def _prepare_parts(parts: Path, path: Path, resume: bool, note) -> bool:
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
    _own_temporaries(parts)
    if resume and (parts / "spec.json").is_file():
        return True
    old = _part_indices(parts)
    if old:
        note(f"{parts}: the {len(old)} checkpoint part(s) of an earlier run are discarded (resume=True "
             "continues a run instead)")
    _remove([parts / "spec.json", *(f for _, f in old)], parts)
    return False


# ------------------------------------------------------------------------------------------
# The run
# ------------------------------------------------------------------------------------------
def simulate_to_file(
    system: System,
    method: Integrator | str | None = None,
    q0=None,
    v0=None,
    *,
    path,
    R0=None,
    h,
    steps: int | None = None,
    t_final: float | None = None,
    save_every: int = 1,
    chunk_steps: int | None = None,
    t0: float = 0.0,
    project_v0: bool = False,
    throw: bool = True,
    resume: bool = False,
    overwrite: bool = False,
    max_bytes: int | None = DEFAULT_MAX_BYTES,
    attrs: Mapping[str, Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
    notice: Callable[[str], None] | None = None,
    stop_after_chunks: int | None = None,
) -> StreamResult:
    """Integrate like :func:`gnipy.simulate`, streaming the saved nodes to a netCDF file in chunks.

    Arguments:
        system, method, q0, v0, R0, h, steps, t_final, save_every, t0, project_v0: as for
            :func:`gnipy.simulate` (one trajectory; the continuous reference is not streamed).
        path: the destination netCDF file (written atomically when the run completes).
        chunk_steps: steps per chunk, a multiple of `save_every` (default: the steps of
            :data:`DEFAULT_CHUNK_NODES` saved nodes). Memory holds one chunk; a checkpoint
            (part file) is written after every chunk.
        throw: raise :class:`~gnipy.SolverFailure` when a step fails (the file is still written,
            up to the last good node, with `result = 1`); with False, return the result.
        resume: continue an interrupted run of the same spec from its last good part (every
            part is verified first), or return the result of a finished one whose destination
            verifies.
        overwrite: replace an existing regular file at `path` (never a link, directory or
            special file).
        max_bytes: the largest destination to write, in bytes (default
            :data:`DEFAULT_MAX_BYTES`, 64 GiB); a larger estimate, or one that does not fit in
            the free disk space, is refused before anything is computed. None lifts both checks.
        attrs: extra global attributes for the file (a `save_every` among them is recorded as
            the stride used, `min(save_every, steps)`).
        progress: called as `progress(steps_done, steps_total)` after every chunk.
        notice: called with each warning about the checkpoints (a part that did not verify and
            is computed again) as it happens; they are also in :attr:`StreamResult.warnings`.
        stop_after_chunks: stop (without writing the destination) after computing this many
            chunks in this call: for tests of interruption and resume.

    Returns:
        A :class:`StreamResult`.

    Raises:
        InputError, MethodError: bad arguments (named).
        OutputError: the destination or its parts directory cannot be written (or is not
            gnipy's to write), the estimated output is too large, a resumed run's spec differs or
            its `spec.json` cannot be read, or a finished destination is damaged.
        SolverFailure: a step failed and `throw` is True.
        KeyboardInterrupt: SIGINT; the parts written so far stay for `resume=True`.
    """
    from .compilation import release_compiled_programs_if_needed
    from .methods import get_method
    from .reference import ContinuousReference

    release_compiled_programs_if_needed()
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if method is None:  # as simulate: the model's measured default
        from .models.registry import default_method_for

        method = default_method_for(system.name if isinstance(system, System) else "")
    if isinstance(method, str):
        method = get_method(method)
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference is not streamed; use gnipy.simulate")
    if not isinstance(method, Integrator):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    h, steps = resolve_steps(h, steps, t_final)  # steps <= MAX_TOTAL_STEPS
    if isinstance(save_every, bool) or int(save_every) != save_every or save_every < 1:
        raise InputError(f"save_every: must be a positive integer, got {save_every!r}")
    save_every = int(min(save_every, steps))
    if chunk_steps is None:
        chunk_steps = save_every * DEFAULT_CHUNK_NODES
    if isinstance(chunk_steps, bool) or int(chunk_steps) != chunk_steps or chunk_steps < 1:
        raise InputError(f"chunk_steps: must be a positive integer, got {chunk_steps!r}")
    chunk_steps = int(chunk_steps)
    if chunk_steps > MAX_STEPS:
        raise InputError(f"chunk_steps: at most {MAX_STEPS} steps per chunk, got {chunk_steps}")
    if chunk_steps % save_every:
        raise InputError(
            f"chunk_steps: {chunk_steps} is not a multiple of the save stride {save_every}"
        )
    chunk_steps = min(chunk_steps, steps + (-steps) % save_every)
    if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, float, np.integer))
                                  or not max_bytes >= 0):
        raise InputError(f"max_bytes: expected a number of bytes >= 0 or None, got {max_bytes!r}")
    t0 = float(t0)
    if not math.isfinite(t0):
        raise InputError(f"t0: must be finite, got {t0!r}")
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
    method.check(system, b0)
    method = method.prepare(system, b0)
    energy_invariant = energy_is_invariant(system, b0)
    attrs = dict(attrs or {})
    if "save_every" in attrs:  # the stride used (a larger one than the run saves only its ends)
        attrs["save_every"] = save_every
    gni_family = type(method).hidden_momentum is not Integrator.hidden_momentum
    attrs["conserved"] = conserved_quantity(system, b0, gni_family=gni_family,
                                            invariants=registered_invariants(system.name))

    n_chunks = -(-steps // chunk_steps)
    spec = {
        # the part files' layout: `time` holds the times (parts of an earlier layout are not resumed)
        "layout": "time-coordinate",
        "system": system.name, "params": dict(system.params), "method": method.name, "h": h, "steps": steps,
        "save_every": save_every, "chunk_steps": chunk_steps, "t0": t0,
        "q0": np.asarray(system.space.coordinates(b0)).tolist(), "v0": np.asarray(v0).tolist(),
        "R0": None if system.group is None else np.asarray(system.space.orientation(b0)).ravel().tolist(),
    }
    canonical = json.loads(json.dumps(spec))
    spec_text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    spec_hash = "sha256:" + hashlib.sha256(spec_text.encode()).hexdigest()
    notes: list[str] = []

    def note(message: str) -> None:
        notes.append(message)
        if notice is not None:
            notice(message)

    # --- the destination -----------------------------------------------------------------
    given = path
    finished = Path(os.fspath(given)).expanduser() if isinstance(given, (str, os.PathLike)) else None
    if resume and finished is not None and finished.is_file() and not finished.is_symlink():
        done_already = _finished_result(finished, canonical, method, system, h, t0, throw, overwrite, note)
        if done_already is not None:
            clean_stale_temporaries(done_already.path)
            finished_parts = parts_directory(done_already.path)
            if is_owned_dir(finished_parts):  # left by a process killed after the rename
                _own_temporaries(finished_parts)
                remove_owned_dir(finished_parts, _OWN_FILES)
            return done_already
    path = check_destination(given, overwrite=overwrite, argument="path")
    parts = parts_directory(path)

    # --- how large the output gets ---------------------------------------------------------
    if max_bytes is not None:
        _check_size(system, b0, steps, save_every, n_chunks, gni_family, path, parts, max_bytes)

    clean_stale_temporaries(path)
    resuming = _prepare_parts(parts, path, resume, note)

    hj = np.float64(h)  # as in simulate (the same compiled program)
    core = system.without_metadata()
    state = _init_one(method, core, b0, np.asarray(v0, dtype=np.float64), hj)
    leaves, treedef = jax.tree_util.tree_flatten(state)
    plan = _Plan(steps=steps, save_every=save_every, chunk_steps=chunk_steps, t0=t0, h=h, spec_hash=spec_hash,
                 leaves=[np.asarray(x) for x in leaves], group=system.group is not None)

    done = 0
    if resuming:
        try:
            stored = json.loads((parts / "spec.json").read_text(encoding="utf-8"))
            if not isinstance(stored, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as e:
            raise OutputError(
                f"resume: cannot read {parts / 'spec.json'} ({e}): the interrupted run's spec is damaged; "
                "rerun with resume=False to start afresh"
            ) from None
        for key, value in canonical.items():
            if stored.get(key) != value:
                raise OutputError(
                    f"resume: the interrupted run in {parts} has a different {key} "
                    f"({stored.get(key)!r}, requested {value!r}); rerun with resume=False to start afresh"
                )
        done, last, n_chunks = _verify_parts(parts, plan, n_chunks, note)
        if last is not None:
            leaves = [jnp.asarray(a) for a in last["leaves"]]
        if done and progress is not None:
            progress(min(steps, done * chunk_steps), steps)
    else:
        atomic_write_text(parts / "spec.json", json.dumps(spec, indent=1), checked=True)
    state = jax.tree_util.tree_unflatten(treedef, leaves)
    resumed = done

    failed_step = -1
    computed = 0
    for c in range(done, n_chunks):
        if stop_after_chunks is not None and computed >= stop_after_chunks:
            return _partial_result(path, parts, c, steps, n_chunks, resumed, notes)
        k_start, length, n_blocks, remainder, k_local, keep = plan.chunk(c)
        # the chunk is one call of the driver, continuing from the previous chunk's state
        sol = simulate(system, method, h=h, steps=length, saveat=SaveAt(every=save_every), state0=state,
                       t0=plan.times(k_start, np.zeros(1))[0], throw=False)
        state = sol.final_state
        fail_k, fail_res, its = sol.failed_step, sol.failed_residual, sol.iterations
        keep = keep[: len(sol.t)]  # a failed chunk stops at its last good node
        if fail_k >= 0:
            keep &= k_local[: len(sol.t)] <= fail_k  # may keep no node: the step after the previous part's last failed
            failed_step = k_start + fail_k
        k_local = k_local[: len(sol.t)]
        variables = {
            "time": (("time",), plan.times(k_start, k_local)[keep]),
            "step": (("time",), (k_start + k_local)[keep]),
            "q": (("time", "coordinate"), np.asarray(sol.q)[keep]),
            "v": (("time", "velocity"), np.asarray(sol.v)[keep]),
            "p": (("time", "velocity"), np.asarray(sol.p)[keep]),
            "energy": (("time",), np.asarray(sol.energy)[keep]),
            "constraint_residual": (("time", "constraint"), np.asarray(sol.constraint_residual)[keep]),
        }
        if sol.R is not None:
            variables["R"] = (("time", "i", "j"), np.asarray(sol.R)[keep])
        if sol.hidden_momentum is not None:  # the GNI family's diagnostics at the nodes (as Solution.to_xarray writes them)
            for name, a in zip(("hidden_momentum", "hidden_momentum_expected", "energy_plus"),
                               (sol.hidden_momentum, sol.hidden_expected, sol.energy_plus)):
                variables[name] = (("time",), np.asarray(a)[keep])
        for i, leaf in enumerate(jax.tree_util.tree_leaves(state)):
            a = _storage(leaf)
            variables[f"state_{i}"] = (tuple(f"state_{i}_d{j}" for j in range(a.ndim)), a)
        its = np.asarray(its)
        part_attrs = {
            "result": RESULT_SOLVER_FAILED if fail_k >= 0 else 0, "failed_step": failed_step,
            "residual": float(fail_res), "iterations_total": int(its[0]), "iterations_max": int(its[1]),
            _CHUNK_ATTR: c, _SPEC_HASH_ATTR: spec_hash,
        }
        with _DeferredInterrupt() as interrupt:
            atomic_write(_part_path(parts, c), lambda tmp: _write_part(tmp, variables, part_attrs), checked=True)
        if interrupt.pending:  # Ctrl-C while the part was written: it is committed, stop here
            raise KeyboardInterrupt
        computed += 1
        if progress is not None:
            progress(min(steps, k_start + length), steps)
        if fail_k >= 0:
            n_chunks = c + 1
            break

    return _finish(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant,
                   overwrite=overwrite, plan=plan, spec=canonical, notes=notes)


def _verify_parts(parts: Path, plan: _Plan, n_chunks: int, note) -> tuple[int, dict | None, int]:
    """Verify the parts of an interrupted run in order; remove the first bad one and every later
    one. Returns (good parts, the last good part, the number of chunks of the run)."""
    existing = _part_indices(parts)
    done, last, why = 0, None, ""
    while done < n_chunks:
        f = _part_path(parts, done)
        if not f.is_file():
            if any(i > done for i, _ in existing):
                why = "it is missing"
            break
        part, why = _check_part(f, done, plan)
        if part is None:
            break
        done, last = done + 1, part
        if part["result"] != 0:  # the interrupted run had already failed: nothing to add
            n_chunks = done
            break
    stale = [f for i, f in existing if i >= done]
    if why:
        later = len([i for i, _ in existing if i > done])
        start = f"from {_part_path(parts, done - 1).name}" if done else "from the start"
        note(f"checkpoint {_part_path(parts, done).name} in {parts} does not verify: {why}; it"
             + (f" and the {later} later part(s) are" if later else " is") + f" computed again {start}")
    _remove(stale, parts)
    return done, last, n_chunks


def _estimate(system, b0, steps: int, save_every: int, n_chunks: int, gni_family: bool) -> tuple[int, int, int]:
    """(saved nodes, bytes per node in the destination, estimated bytes of the destination)."""
    nodes = steps // save_every + 1 + (1 if steps % save_every else 0)
    n, N = len(np.atleast_1d(np.asarray(system.space.coordinates(b0)))), int(system.dim)
    m = system.num_constraints(b0)
    R = system.space.orientation(b0)
    k2 = 0 if R is None else int(np.asarray(R).size)
    per_node = 8 * (3 + n + 2 * N + 1 + m + k2 + (3 if gni_family else 0))  # time, node, step, q, v, p, E, res, R, diag
    return nodes, per_node, nodes * per_node + _FILE_OVERHEAD


def _check_size(system, b0, steps, save_every, n_chunks, gni_family, path: Path, parts: Path, max_bytes) -> None:
    nodes, per_node, size = _estimate(system, b0, steps, save_every, n_chunks, gni_family)
    allow = "pass max_bytes=None to write it anyway"
    if size > max_bytes:
        raise OutputError(
            f"path: {path} would hold {nodes:,} saved nodes of {per_node} bytes, about {format_bytes(size)}, more than "
            f"max_bytes = {format_bytes(max_bytes)}; save fewer nodes (a larger save_every, fewer steps), "
            f"or {allow}"
        )
    parts_size = size - 8 * nodes + n_chunks * _FILE_OVERHEAD  # the parts: no node index, a header each
    existing = 0
    if is_owned_dir(parts):
        for _, f in _part_indices(parts):
            try:
                existing += f.stat().st_size
            except OSError:
                pass
    need = size + max(0, parts_size - existing)
    directory = path.parent if str(path.parent) else Path(".")
    free = free_bytes(directory)
    if free is not None and need > free:
        raise OutputError(
            f"path: the run needs about {format_bytes(need)} of disk space ({nodes:,} saved nodes: the checkpoint parts "
            f"and {path}, about {format_bytes(size)}, coexist while they are merged), and {directory} has "
            f"{format_bytes(free)} free; free some space, save fewer nodes, or {allow}"
        )


# ------------------------------------------------------------------------------------------
# The destination
# ------------------------------------------------------------------------------------------
# the variables along `time` of a result file, with their dimensions (gnipy.schema)
_DATA_DIMS = {name: schema.dims(name) for name in (
    "q", "v", "p", "energy", "constraint_residual", "R", "hidden_momentum", "hidden_momentum_expected",
    "energy_plus")}


def _global_attrs(system, method, h, steps, result, it_tot, it_max, n_chunks, attrs) -> dict:
    """The destination's global attributes, as :func:`gnipy.io.write_netcdf` writes them."""
    import datetime as _dt

    from .io import CHECKSUM_ATTR, _attr_value, cf_attributes, provenance
    from .schema import CONVENTIONS, UNITS_CONVENTION
    from .system import describe_orientations

    created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    out = {
        **cf_attributes(system.name, method.name, created=created),
        "model": system.name, "method": method.name, "h": float(h), "steps": int(steps), "start": "p+ = G v0",
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
    return {k: _attr_value(v) for k, v in out.items()}


def _write_destination(tmp: Path, files, counts, system, first: dict, load, interrupt) -> tuple:
    """Copy the parts, one at a time, into a new netCDF file `tmp` (the layout of
    :meth:`gnipy.Solution.to_xarray` written by :func:`gnipy.io.write_netcdf`), acting on SIGINT
    between parts. `load(i)` reads and verifies part `i`. Returns the open file and the checksum
    of its data; the caller adds the global attributes and closes it."""
    import netCDF4

    data0 = first["data"]
    names = [v for v in _DATA_DIMS if v in data0]
    sizes = {"time": int(sum(counts))}
    for v in names:
        for d, n in zip(_DATA_DIMS[v][1:], data0[v].shape[1:]):
            sizes[d] = int(n)
    coordinates = [str(x) for x in system.coordinates]
    velocities = [str(x) for x in system.velocities]
    if len(coordinates) != sizes["coordinate"]:
        coordinates = [f"q{i}" for i in range(sizes["coordinate"])]
    if len(velocities) != sizes["velocity"]:
        velocities = [f"v{i}" for i in range(sizes["velocity"])]
    checksum = DataChecksum()  # as gnipy.io.netcdf_checksum will compute it from the file
    nc = netCDF4.Dataset(os.fspath(tmp), "w", clobber=False, format="NETCDF4")
    try:
        for d in ("time", "coordinate", "velocity", "constraint", "i", "j"):
            if d in sizes:
                nc.createDimension(d, sizes[d])
        out = {}
        names_of = {"coordinate": coordinates, "velocity": velocities}
        for v in names:  # the attributes of gnipy.schema.apply, in write_netcdf's order
            var = nc.createVariable(v, data0[v].dtype, _DATA_DIMS[v], fill_value=np.nan)
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
            checksum.update(name, a)
        constraint = np.arange(sizes["constraint"], dtype=np.int64)
        var = nc.createVariable("constraint", np.int64, schema.dims("constraint"))
        var.setncatts(schema.variable_attrs("constraint"))
        var[:] = constraint
        checksum.update("constraint", constraint)

        offset = 0
        for i, f in enumerate(files):
            part = first if i == 0 else load(i)
            n = part["n"]
            if n != counts[i]:
                raise OutputError(f"{f} changed while it was merged; rerun with resume=True")
            d = part["data"]
            if sorted(v for v in d if v in _DATA_DIMS) != sorted(names) or any(
                    d[v].shape[1:] != data0[v].shape[1:] for v in names):
                raise OutputError(f"{f}: its variables differ from those of {files[0].name}; rerun with "
                                  "resume=True to compute it again")
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
            if _merge_hook is not None:
                _merge_hook(i)
            interrupt.check()
        return nc, checksum
    except BaseException:
        nc.close()
        raise


def _finish(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant=False, *,
            overwrite, plan: _Plan, spec, notes):
    """Copy the parts (one in memory at a time, each verified again) into `path`, atomically;
    then remove them."""
    import netCDF4

    from .io import CHECKSUM_ATTR

    files = [_part_path(parts, c) for c in range(n_chunks)]
    stats = []
    verdicts = StreamedVerdicts(h, h * steps, energy_invariant)

    def load(c: int) -> dict:
        part, why = _check_part(files[c], c, plan)
        if part is None:
            raise OutputError(f"{files[c]} does not verify ({why}); rerun with resume=True to compute "
                              "it again")
        d, a = part["data"], part["attrs"]
        e = d["energy"]
        kinetic = 0.5 * np.sum(d["v"] * d["p"], axis=-1)
        hidden = (d["hidden_momentum"], d["hidden_momentum_expected"]) if "hidden_momentum" in d else (None, None)
        verdicts.update(d["time"], e, kinetic, *hidden)
        stats.append(dict(result=part["result"], failed=part["failed"], residual=float(a["residual"]),
                          it_tot=int(a["iterations_total"]), it_max=int(a["iterations_max"]),
                          e_min=float(e.min()) if e.size else np.inf, e_max=float(e.max()) if e.size else -np.inf,
                          res=float(np.max(np.abs(d["constraint_residual"]), initial=0.0)),
                          e0=float(e[0]) if e.size else np.nan, q=d["q"][-1:], v=d["v"][-1:], n=part["n"]))
        return part

    counts = []
    for f in files:  # the nodes of every part (headers only), for the size of `time`
        try:
            with netCDF4.Dataset(os.fspath(f), "r") as nc:
                counts.append(len(nc.dimensions["time"]))
        except Exception as e:  # noqa: BLE001
            raise OutputError(f"{f} does not verify (it cannot be read: {e}); rerun with resume=True "
                              "to compute it again") from None
    first = load(0)

    def write(tmp: Path) -> None:
        nc, checksum = _write_destination(tmp, files, counts, system, first, load, interrupt)
        try:
            result = max(s["result"] for s in stats)
            failed_step = next((s["failed"] for s in stats if s["result"]), -1)
            extra = dict(attrs, **verdicts.attrs(method.name, system.name))
            if result:  # as Solution.to_xarray records a failure
                s = next(s for s in stats if s["result"])
                extra = {"failed_step": int(failed_step), "failed_residual": float(s["residual"]),
                         "failed_time": float(t0 + h * failed_step), **extra}
            extra[SPEC_ATTR] = json.dumps(spec, sort_keys=True)
            nc.setncatts(_global_attrs(system, method, h, steps, result, sum(s["it_tot"] for s in stats),
                                       max(s["it_max"] for s in stats), n_chunks, extra))
            nc.setncattr(CHECKSUM_ATTR, checksum.hexdigest())
        finally:
            nc.close()
        interrupt.check()

    with _DeferredInterrupt() as interrupt:
        atomic_write(path, write, overwrite=overwrite, argument="path")
    _own_temporaries(parts)
    if not remove_owned_dir(parts, _OWN_FILES) and parts.exists():
        notes.append(f"{parts} is kept: it holds files gnipy did not write")
    if interrupt.pending:  # Ctrl-C as the file was renamed: it is complete; stop here
        raise KeyboardInterrupt
    result = max(s["result"] for s in stats)
    failed_step = next((s["failed"] for s in stats if s["result"]), -1)
    nodes = sum(s["n"] for s in stats)
    e0 = stats[0]["e0"]
    energy_error = max((max(abs(s["e_max"] - e0), abs(s["e_min"] - e0)) for s in stats if s["n"]), default=np.nan)
    last = next(s for s in reversed(stats) if s["n"])  # part 0 always holds the initial node
    out = StreamResult(
        path=path, complete=True, nodes=nodes, steps=steps if result == 0 else failed_step, chunks=n_chunks,
        chunks_resumed=resumed, result=result, failed_step=failed_step, energy_error=float(energy_error),
        constraint_residual=max(s["res"] for s in stats),
        iterations=(int(sum(s["it_tot"] for s in stats)), int(max(s["it_max"] for s in stats))),
        final_q=np.asarray(last["q"][-1]), final_v=np.asarray(last["v"][-1]),
        warnings=[*notes, *verdicts.warnings(method.name, system.name)],
    )
    if result and throw:
        s = next(s for s in stats if s["result"])
        raise _failure(method.name, failed_step, t0, h, s["residual"], path)
    return out


def _failure(method: str, failed_step: int, t0: float, h: float, residual: float, path: Path) -> SolverFailure:
    return SolverFailure(
        f"{method}: step {failed_step} (t = {t0 + h * failed_step:.6g} -> {t0 + h * (failed_step + 1):.6g}) "
        f"failed: the solve did not converge or gave a non-finite value (residual {residual:.3e}); "
        f"{path} holds the run up to the last good node",
        step=failed_step, time=t0 + h * failed_step, residual=residual, solution=None,
    )


def _finished_result(path: Path, spec: dict, method, system, h, t0, throw, overwrite, note) -> StreamResult | None:
    """The result of a run whose destination `path` is complete and holds `spec`; None when it
    holds another run (or is not a streamed result). A damaged one is an error, unless
    `overwrite` (then None: it is computed again)."""
    import netCDF4

    from .io import verify_netcdf

    try:
        with netCDF4.Dataset(os.fspath(path), "r") as nc:
            stored = nc.__dict__.get(SPEC_ATTR)
    except Exception as e:  # noqa: BLE001
        if overwrite:
            return None
        raise OutputError(f"path: {path} exists but cannot be read as netCDF ({type(e).__name__}: {e}); it is not a "
                          "finished run to resume: pass overwrite=True to replace it") from None
    try:
        if stored is None or json.loads(str(stored)) != spec:
            return None
    except ValueError:
        return None
    try:
        ok, message = verify_netcdf(path)
    except OutputError as e:
        ok, message = False, str(e)
    if not ok:
        if overwrite:
            note(f"{path} was the finished result of this run but is damaged ({message}); computing it again")
            return None
        raise OutputError(f"path: {path} is the finished result of this run but it is DAMAGED: {message}; "
                          "rerun with overwrite=True to compute it again")
    try:
        with netCDF4.Dataset(os.fspath(path), "r") as nc:
            nc.set_auto_maskandscale(False)
            a = nc.__dict__
            n = len(nc.dimensions["time"])
            e0 = float(nc.variables["energy"][0])
            e_err, res = 0.0, 0.0
            for i in range(0, n, _SLICE_NODES):
                e = np.asarray(nc.variables["energy"][i:i + _SLICE_NODES])
                e_err = max(e_err, abs(float(e.max()) - e0), abs(float(e.min()) - e0))
                r = np.asarray(nc.variables["constraint_residual"][i:i + _SLICE_NODES])
                res = max(res, float(np.max(np.abs(r), initial=0.0)))
            final_q, final_v = np.asarray(nc.variables["q"][n - 1]), np.asarray(nc.variables["v"][n - 1])
            result = int(a.get("result", 0))
            failed = int(a.get("failed_step", -1)) if result else -1
            residual = float(a.get("failed_residual", np.nan))
            chunks = int(a.get("streamed_chunks", 0))
            iterations = (int(a.get("newton_iterations_total", 0)), int(a.get("newton_iterations_max", 0)))
            warnings = [str(a[k]) for k in ("hidden_momentum_warning", "energy_drift_warning") if k in a]
            steps = int(a["steps"]) if not result else failed
    except Exception as e:  # noqa: BLE001
        raise as_output_error(e, path, "read") or OutputError(f"cannot read {path}: {type(e).__name__}: {e}") from None
    out = StreamResult(
        path=path, complete=True, nodes=n, steps=steps, chunks=chunks, chunks_resumed=chunks, result=result,
        failed_step=failed, energy_error=e_err, constraint_residual=res, iterations=iterations,
        final_q=final_q, final_v=final_v, warnings=warnings,
    )
    if result and throw:
        raise _failure(method.name, failed, t0, h, residual, path)
    return out


def _partial_result(path, parts, c, steps, n_chunks, resumed, notes=()):
    return StreamResult(
        path=path, complete=False, nodes=0, steps=0, chunks=n_chunks, chunks_resumed=resumed, result=0, failed_step=-1,
        energy_error=float("nan"), constraint_residual=float("nan"), iterations=(0, 0),
        final_q=np.zeros(0), final_v=np.zeros(0), warnings=list(notes),
    )
