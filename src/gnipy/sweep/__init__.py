"""Parameter sweeps: grids of runs in vmapped chunks on dask.distributed, to zarr.

A sweep runs one model with one method over the Cartesian product of a few *grid axes*,
each `NAME=linspace(START, STOP, COUNT)` or `NAME=START:STOP:COUNT` (values
`numpy.linspace(START, STOP, COUNT)`). NAME is a
model parameter (`m`, `Omega`, ...) or a component of the initial condition:
`q0.<coordinate>` (e.g. `q0.x`) or `v0.<velocity>` (e.g. `v0.omega3`). The members (grid
points) are numbered in C order: the last axis varies fastest.

**Size.** Before anything is allocated or created, :func:`run_sweep` estimates the store's size
(members × saved nodes × bytes per node, uncompressed) and the memory of one chunk. A store
over `max_bytes` (default :data:`DEFAULT_MAX_BYTES`, 100 GiB; `None` lifts the bound) is
refused, as are, whatever `max_bytes`, a store larger than the free space of its file system,
a chunk over a quarter of this machine's memory and a grid whose members' results alone would
take a quarter of it. Each axis has at most :data:`MAX_COUNT` values.

**How it runs.** The grid is cut into chunks of at most `chunk_size` members, blocks of the grid
(:class:`ChunkLayout`: the last axes whole as far as they fit); each chunk is one task on the
cluster, :func:`run_chunk`, which runs the whole chunk as one vmapped program
(:func:`gnipy.simulate` with a batch of systems and initial conditions, `throw=False`).
Every chunk is run at the same size, so each worker compiles once and reuses the program for
all its other chunks: a shorter chunk (the last of a row of blocks) is *padded on input* by
repeating its last member, and the extra members are dropped before anything is written (no
padding ever reaches the store). The driver writes each chunk to the zarr store as soon as it
arrives. With `scheduler`, the address is checked (`tcp://HOST:PORT`, `tls://HOST:PORT`,
`inproc://...`, `HOST:PORT`, or a scheduler file) and the client connects, within
`connect_timeout` seconds (default :data:`DEFAULT_CONNECT_TIMEOUT`, 10), before the store is
created. A local cluster serves no dashboard.

**Failed members.** A member whose step fails does not stop the sweep: its `result` is 1, its
`failed_step`, `failed_time` and `failed_residual` (the residual of the failed solve) are
recorded, and every variable of it is NaN after its last good node (`valid` False there).
:class:`SweepReport` counts the failed members and lists the first few.

**The store** (a zarr directory, format 3, with consolidated metadata) opens with plain
`xarray.open_zarr(path)`: the grid axes are its first dimensions, named after the axes with
`.` written `_` (`q0.x` is the dimension `q0_x`), with the grid values as their coordinates. It holds `q(<grid>, time, coordinate)`, `v` and
`p(<grid>, time, velocity)`, `energy(<grid>, time)`, `constraint_residual(<grid>, time,
constraint)`, `R(<grid>, time, i, j)` on Rⁿ × G, `result(<grid>)` (0: ok, 1: a step failed),
`failed_step(<grid>)` (or -1), `failed_time(<grid>)` and `failed_residual(<grid>)` (NaN when
none), `valid(<grid>, time)` (False after a member's failed step), the coordinate `time` (the
saved times, in s) with `node(time)` and `step(time)`, and per chunk `chunk_checksum(chunk,
digest)` (the SHA-256 digest of the chunk's data) and `chunk_done(chunk)`; the names,
dimensions, units and long names are those of :mod:`gnipy.schema`. The zarr chunks along the
grid axes are the sweep's chunks. The attributes hold the sweep's specification as JSON
(`sweep_spec`: format :data:`FORMAT`, model, method, h, steps, save_every, grid, fixed
parameters, chunk size, gnipy version) and the same fields one by one for reading, the names of
the store's arrays (`store_arrays`), the CF attributes (`Conventions`, `title`, `source`,
`history`), `gnipy_owned` (gnipy created the store) and, on Rⁿ × G, `orientation`.

**Ownership.** The store is built in a temporary directory beside its destination
(`.NAME.gnipy-PID-HEX.partial`) and renamed into place, so a store either exists with all its
arrays or not at all. gnipy writes a store only where nothing is, into an empty directory, or
over a store it created (its attribute `gnipy_owned`; stores of earlier versions by their
marker file or their `sweep_spec`); `overwrite=True` replaces such a store only when everything
at its top level is gnipy's. It refuses a symbolic link, a file, and a non-empty directory it
cannot tell it created. Each run first removes the temporaries that runs killed while creating
or replacing a store at the same path left behind (those of a live process are kept).

**Resuming and integrity.** Running the same sweep again on the same store checks that the
specification is the same (else :class:`SweepError` names the field that differs), that the
store's metadata and arrays are intact (else :class:`SweepError` says what is damaged and what
to do), then reads every chunk flagged done back and recomputes its checksum: a chunk that
cannot be read or whose data differ is recomputed, with a :class:`SweepWarning` naming the chunk
and its members; the others are skipped. :func:`open_sweep` does the same check (and refuses a
damaged store), and :func:`verify_sweep` reports on a store without changing it. Chunks not yet
done read as NaN (floats) and `valid = False`. A store of an earlier format (`gnipy-sweep/1` to
`/4`: `/1` and `/2` with a flat `member` axis, `/3` without the members' verdicts, `/4` with the
dimensions named as the grid, `q0.x`) is not resumed or read: the error names it and says what to
do.

Two runs must not write to the same store at the same time.

The package's modules: :mod:`~gnipy.sweep.grid` (axes, chunk layout), :mod:`~gnipy.sweep.plan`
(validation, size), :mod:`~gnipy.sweep.task` (one chunk on a worker), :mod:`~gnipy.sweep.store`
(the zarr layout), :mod:`~gnipy.sweep.ownership`, :mod:`~gnipy.sweep.integrity` (checksums,
resume), :mod:`~gnipy.sweep.cluster`, :mod:`~gnipy.sweep.run` and :mod:`~gnipy.sweep.read`.
"""

from __future__ import annotations

from .cluster import DEFAULT_CONNECT_TIMEOUT
from .errors import SweepError, SweepFailure, SweepWarning
from .grid import MAX_COUNT, ChunkLayout, GridAxis, parse_grid
from .plan import DEFAULT_MAX_BYTES, FORMAT
from .read import open_sweep, verify_sweep
from .run import SweepReport, run_sweep
from .task import run_chunk

__all__ = [
    "GridAxis",
    "ChunkLayout",
    "SweepError",
    "SweepFailure",
    "SweepWarning",
    "SweepReport",
    "DEFAULT_MAX_BYTES",
    "DEFAULT_CONNECT_TIMEOUT",
    "FORMAT",
    "MAX_COUNT",
    "parse_grid",
    "run_sweep",
    "open_sweep",
    "verify_sweep",
    "run_chunk",
]
