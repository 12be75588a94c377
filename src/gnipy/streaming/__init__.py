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

from .parts import parts_directory
from .result import SPEC_ATTR, StreamResult
from .run import DEFAULT_CHUNK_NODES, simulate_to_file
from .size import DEFAULT_MAX_BYTES

__all__ = ["simulate_to_file", "StreamResult", "parts_directory", "DEFAULT_CHUNK_NODES", "DEFAULT_MAX_BYTES",
           "SPEC_ATTR"]
