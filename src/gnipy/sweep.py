"""Parameter sweeps: grids of runs in vmapped chunks on dask.distributed, to zarr.

A sweep runs one model with one method over the Cartesian product of a few *grid axes*,
each `NAME=START:STOP:COUNT` (values `numpy.linspace(START, STOP, COUNT)`). NAME is a
model parameter (`m`, `Omega`, ...) or a component of the initial condition:
`q0.<coordinate>` (e.g. `q0.x`) or `v0.<velocity>` (e.g. `v0.omega3`). The members (grid
points) are numbered in C order: the last axis varies fastest.

**Size.** Before anything is allocated or created, :func:`run_sweep` estimates the store's size
(members × saved nodes × bytes per node, uncompressed) and the memory of one chunk. A store
over `max_bytes` (default :data:`DEFAULT_MAX_BYTES`, 100 GiB; `None` lifts the bound, `gni
sweep --yes`) is refused, as are, whatever `max_bytes`, a store larger than the free space of
its file system, a chunk over a quarter of this machine's memory and a grid whose per-member
indices alone would take a quarter of it. Each axis has at most :data:`MAX_COUNT` values.

**How it runs.** The members are cut into chunks of `chunk_size`; each chunk is one task
on the cluster, :func:`run_chunk`, which runs the whole chunk as one vmapped program
(:func:`gnipy.simulate` with a batch of systems and initial conditions, `throw=False`).
Every chunk has the same size, so each worker compiles once and reuses the program for
all its other chunks: the last, shorter chunk is *padded on input* by repeating its last
member, and the extra members are dropped before anything is written (no padding ever
reaches the store). The driver writes each chunk to the zarr store as soon as it
arrives. With `scheduler`, the address is checked (`tcp://HOST:PORT`, `tls://HOST:PORT`,
`inproc://...`, `HOST:PORT`, or a scheduler file) and the client connects, within
`connect_timeout` seconds (default :data:`DEFAULT_CONNECT_TIMEOUT`, 10), before the store is
created. A local cluster serves no dashboard (its scheduler's HTTP server listens on a random
port of 127.0.0.1, with no pages).

**Failed members.** A member whose step fails does not stop the sweep: its `result` is 1, its
`failed_step`, `failed_time` and `failed_residual` (the residual of the failed solve) are
recorded, and every variable of it is NaN after its last good node (`valid` False there).
:class:`SweepReport` counts the failed members and lists the first few; `gni sweep` exits with
code 1 when there are any.

**The store** (a zarr directory) is created up front at full size, with zarr chunks aligned to
`chunk_size` along `member`. Its coordinate `time` holds the saved times (CF attributes,
`units = "s"`), with `node(time)` (the saved-node index) and `step(time)` (the step index)
beside it; it holds `q(member, time, coordinate)`, `v` and `p(member, time, velocity)`,
`energy(member, time)`, `constraint_residual(member, time, constraint)`, `R(member, time, i,
j)` on Rⁿ × G, `result(member)` (0: ok, 1: a step failed), `failed_step(member)` (or -1),
`failed_time(member)` and `failed_residual(member)` (NaN when none), `valid(member, time)`
(False after a member's failed step), `grid_<NAME>(member)` (each member's grid values),
`chunk_checksum(chunk, digest)` (the SHA-256 digest, 32 bytes, of each chunk's data:
:func:`gnipy.files.array_checksum` of the chunk's member variables and grid values) and
`chunk_done(chunk)`. The attributes hold the sweep's specification as JSON (`sweep_spec`:
model, method, h, steps, save_every, grid, fixed parameters, chunk size, gnipy version)
and the same fields one by one for reading, the names of the store's arrays
(`store_arrays`), the CF attributes (`Conventions`, `title`, `source`, `history`) and, on
Rⁿ × G, `orientation` (how R is reconstructed, :attr:`gnipy.System.orientation_description`).

**Ownership.** The store is built in a temporary directory beside its destination
(`.NAME.gnipy-PID-HEX.partial`), holding gnipy's marker file (:data:`gnipy.files.MARKER`),
and renamed into place, so a store either exists with all its arrays or not at all. gnipy
writes a store only where nothing is, or into an empty directory, or over a store it created
(with the marker; a store written by an earlier gnipy, without the marker but with a valid
`sweep_spec`, counts as one); `overwrite=True` replaces such a store only when everything at
its top level is gnipy's (its arrays, metadata and marker). It refuses a symbolic link, a file,
and a non-empty directory it did not create. Each run first removes the temporaries
(`.partial`, `.old`) that runs killed while creating or replacing a store at the same path
left behind (:func:`gnipy.files.clean_stale_temporaries`; those of a live process are kept).

**Resuming and integrity.** For each chunk, the data are written first, then its checksum,
and its `chunk_done` flag last, so an interrupted sweep leaves at worst one chunk whose data
were written and whose flag was not. Running the same sweep again on the same store checks
that the specification is the same (else :class:`SweepError` names the field that differs),
that the store's metadata and arrays are intact (else :class:`SweepError` says what is
damaged and to start afresh with `overwrite=True`), then reads every chunk flagged done back
and recomputes its checksum: a chunk that cannot be read or whose data differ is recomputed,
with a :class:`SweepWarning` naming the chunk and its members; the others are skipped. (This
reads the whole store once.) :func:`open_sweep` does the same check (and refuses a damaged
store), and :func:`verify_sweep` reports on a store without changing it. Chunks not yet done
read as NaN (floats) and `valid = False`, and :func:`open_sweep` refuses a store whose chunks
are not all done unless asked.

Two runs must not write to the same store at the same time.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import os
import re
import shutil
import stat
import time
import uuid
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .files import format_bytes

from . import files
from .errors import InputError

__all__ = [
    "GridAxis",
    "SweepError",
    "SweepFailure",
    "SweepWarning",
    "SweepReport",
    "DEFAULT_MAX_BYTES",
    "DEFAULT_CONNECT_TIMEOUT",
    "MAX_COUNT",
    "parse_grid",
    "run_sweep",
    "open_sweep",
    "verify_sweep",
    "run_chunk",
]

#: The format tag stored in the `sweep_spec` attribute (and compared on resume). Stores of
#: format `gnipy-sweep/1` (before checksums) can be read and replaced, not resumed.
FORMAT = "gnipy-sweep/2"
_OLD_FORMATS = ("gnipy-sweep/1",)

#: The default bound on a store's estimated size, in bytes (`run_sweep(max_bytes=...)`; `gni
#: sweep --yes` lifts it): 100 GiB.
DEFAULT_MAX_BYTES = 100 * 2**30

#: Seconds to wait for the connection to an existing scheduler (`run_sweep(connect_timeout=...)`).
DEFAULT_CONNECT_TIMEOUT = 10.0

#: The most values one grid axis may have.
MAX_COUNT = 10**9

# the `purpose` in the marker file of a sweep store
_PURPOSE = "gnipy sweep store"
# failed members listed in a SweepReport
_FAILURES_LISTED = 5

_MAX_ZARR_CHUNK_BYTES = 64 * 2**20
_MAX_PREFLIGHT = 64


class SweepError(InputError):
    """Bad sweep input, or a store that does not hold the requested sweep.

    The message starts with the argument it is about (`grid: ...`, `out: ...`,
    `chunk_size: ...`). A subclass of :class:`gnipy.InputError`.
    """


class SweepFailure(RuntimeError):
    """A chunk of a sweep failed on the cluster for a reason other than bad input (a
    worker died, a store write failed, ...). The chunks already done stay done: run the
    sweep again to resume."""


class SweepWarning(UserWarning):
    """A chunk of a store that was flagged done is damaged (unreadable, or its data differ from
    their checksum) and is computed again; the message names the chunk and its members."""


# --------------------------------------------------------------------------------------
# The grid
# --------------------------------------------------------------------------------------
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)?$")


@dataclasses.dataclass(frozen=True)
class GridAxis:
    """One axis of a sweep grid: `numpy.linspace(start, stop, count)` values of `name`.

    Attributes:
        name: a model parameter, `q0.<coordinate>` or `v0.<velocity name>`.
        start, stop: the first and last values (finite).
        count: the number of values (a positive integer, at most :data:`MAX_COUNT`; 1
            gives `start` only).
    """

    name: str
    start: float
    stop: float
    count: int

    def __post_init__(self):
        name = self.name
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise SweepError(
                f"grid: {name!r} is not a valid name (a parameter, q0.<coordinate> or "
                "v0.<velocity>)"
            )
        for what in ("start", "stop"):
            x = getattr(self, what)
            if isinstance(x, bool) or not isinstance(
                x, (int, float, np.integer, np.floating)
            ):
                raise SweepError(
                    f"grid: {name}: {what.upper()} must be a number, got {x!r}"
                )
            if not math.isfinite(float(x)):
                raise SweepError(
                    f"grid: {name}: {what.upper()} must be finite, got {x!r}"
                )
            object.__setattr__(self, what, float(x))
        c = self.count
        if isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1:
            raise SweepError(
                f"grid: {name}: COUNT must be a positive integer, got {c!r}"
            )
        if c > MAX_COUNT:
            raise SweepError(
                f"grid: {name}: COUNT must be at most {MAX_COUNT:,}, got {c!r}"
            )
        object.__setattr__(self, "count", int(c))

    @property
    def values(self) -> np.ndarray:
        """The grid values, `numpy.linspace(start, stop, count)`."""
        return np.linspace(self.start, self.stop, self.count)

    def to_dict(self) -> dict[str, Any]:
        """`{"name", "start", "stop", "count"}` (JSON-ready)."""
        return {
            "name": self.name,
            "start": self.start,
            "stop": self.stop,
            "count": self.count,
        }

    def __str__(self) -> str:
        return f"{self.name}={self.start!r}:{self.stop!r}:{self.count}"


def parse_grid(text: str) -> GridAxis:
    """Parse `NAME=START:STOP:COUNT` (e.g. `"m=0.5:2:4"`, `"q0.x=-1:1:5"`) into a
    :class:`GridAxis`.

    Raises:
        SweepError: a message starting `grid:` that quotes the text and says what is
            wrong.
    """
    if not isinstance(text, str):
        raise SweepError(f"grid: expected NAME=START:STOP:COUNT, got {text!r}")
    name, eq, rest = text.partition("=")
    name = name.strip()
    parts = [s.strip() for s in rest.split(":")]
    if not eq or not name or len(parts) != 3 or not all(parts):
        raise SweepError(
            f"grid: expected NAME=START:STOP:COUNT (e.g. m=0.5:2:4), got {text!r}"
        )
    values = []
    for what, s in zip(("START", "STOP"), parts[:2]):
        try:
            x = float(s)
        except ValueError:
            raise SweepError(
                f"grid: {name}: {what} must be a number, got {s!r} in {text!r}"
            ) from None
        if not math.isfinite(x):
            raise SweepError(
                f"grid: {name}: {what} must be finite, got {s!r} in {text!r}"
            )
        values.append(x)
    try:
        count = int(parts[2])
    except ValueError:
        raise SweepError(
            f"grid: {name}: COUNT must be a positive integer, got {parts[2]!r} in "
            f"{text!r}"
        ) from None
    if count < 1:
        raise SweepError(
            f"grid: {name}: COUNT must be a positive integer, got {parts[2]!r} in "
            f"{text!r}"
        )
    if count > MAX_COUNT:
        raise SweepError(
            f"grid: {name}: COUNT must be at most {MAX_COUNT:,}, got {parts[2]!r} in "
            f"{text!r}"
        )
    return GridAxis(name, values[0], values[1], count)


def _as_axes(grid) -> list[GridAxis]:
    if isinstance(grid, (str, GridAxis)):
        grid = [grid]
    if isinstance(grid, Mapping):
        items = []
        for name, value in grid.items():
            try:
                start, stop, count = value
            except (TypeError, ValueError):
                raise SweepError(
                    f"grid: {name}: expected (start, stop, count), got {value!r}"
                ) from None
            items.append(GridAxis(str(name), start, stop, count))
        grid = items
    if not isinstance(grid, Sequence):
        raise SweepError(
            "grid: expected a sequence of NAME=START:STOP:COUNT strings or GridAxis, "
            f"got {grid!r}"
        )
    axes = [g if isinstance(g, GridAxis) else parse_grid(g) for g in grid]
    if not axes:
        raise SweepError("grid: give at least one grid axis NAME=START:STOP:COUNT")
    seen = set()
    for a in axes:
        if a.name in seen:
            raise SweepError(f"grid: {a.name!r} is given twice")
        seen.add(a.name)
    return axes


# --------------------------------------------------------------------------------------
# The plan: the validated sweep
# --------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Plan:
    # the JSON specification, stored in the store and compared on resume
    spec: dict[str, Any]
    axes: tuple[GridAxis, ...]
    members: int
    chunk: int
    chunks: int
    times: np.ndarray
    coordinates: tuple[str, ...]
    velocities: tuple[str, ...]
    constraints: int
    matrix_size: int | None  # k of R (k, k), None on R^n
    orientation: str = ""  # the attribute `orientation` (on R^n x G)
    store_bytes: int = 0  # the store's estimated size (uncompressed)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.count for a in self.axes)

    @property
    def member_vars(self) -> tuple[str, ...]:
        """The per-member variables of the store (R on R^n x G only)."""
        return tuple(k for k in _MEMBER_VARS if k != "R" or self.matrix_size is not None)

    @property
    def array_names(self) -> tuple[str, ...]:
        """Every array of the store."""
        return _array_names(self.member_vars, [a.name for a in self.axes])

    def member_range(self, index: int) -> tuple[int, int]:
        a = index * self.chunk
        return a, min(a + self.chunk, self.members)

    def columns(self, index: int) -> dict[str, np.ndarray]:
        """The grid values of the chunk's members, padded to the chunk size by repeating
        the last."""
        a, b = self.member_range(index)
        idx = np.arange(a, b)
        if b - a < self.chunk:
            idx = np.concatenate([idx, np.full(self.chunk - (b - a), b - 1)])
        return _grid_columns(self.axes, idx)


def _grid_columns(axes, members: np.ndarray) -> dict[str, np.ndarray]:
    unravelled = np.unravel_index(members, tuple(a.count for a in axes))
    return {a.name: a.values[i] for a, i in zip(axes, unravelled)}


def _positive_int(argument: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise SweepError(f"{argument}: must be a positive integer, got {value!r}")
    return int(value)


def _saved_steps(steps: int, save_every: int) -> np.ndarray:
    """The step index of each saved node: 0, K, 2K, ... and the last."""
    n_blocks, remainder = divmod(steps, save_every)
    return np.concatenate(
        [np.arange(n_blocks + 1) * save_every, [steps] if remainder else []]
    ).astype(np.int64)




def _memory_total() -> int | None:
    """This machine's physical memory in bytes (None if unknown)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _check_size(axes, *, members, chunk, saved, node_bytes, member_bytes, max_bytes,
                disk) -> int:
    """Refuse a sweep too large for the bound `max_bytes` (None: no bound), for the free
    space of `disk` (a directory; None: not checked) or for this machine's memory; return the
    store's estimated size. Pure arithmetic: nothing is allocated."""
    grid = " ".join(str(a) for a in axes)
    chunks = -(-members // chunk)
    store = members * (saved * node_bytes + member_bytes) + chunks * 33
    what = (f"grid: {grid} gives {members:,} member(s) x {saved:,} saved node(s): the store "
            f"would hold about {format_bytes(store)} ({node_bytes} bytes per member and node, "
            "uncompressed)")
    if max_bytes is not None and store > max_bytes:
        raise SweepError(
            f"{what}, more than the bound max_bytes = {format_bytes(max_bytes)}; sweep a "
            "coarser grid or save fewer nodes (a larger save_every), or pass "
            "max_bytes=None to go ahead"
        )
    memory = _memory_total()
    if memory:
        # the member coordinate, the grid values and their indices, on the driver
        driver = members * 8 * (2 * len(axes) + 2)
        if 4 * driver > memory:
            raise SweepError(
                f"grid: {grid} gives {members:,} members: their indices and grid values "
                f"alone take about {format_bytes(driver)} of memory, more than a quarter of "
                f"this machine's {format_bytes(memory)}; sweep a coarser grid"
            )
        per_chunk = chunk * saved * node_bytes
        if 4 * per_chunk > memory:
            raise SweepError(
                f"chunk_size: a chunk of {chunk:,} member(s) x {saved:,} saved node(s) "
                f"holds about {format_bytes(per_chunk)} in memory (a worker, and this "
                "process while writing it, hold whole chunks), more than a quarter of this "
                f"machine's {format_bytes(memory)}; choose a smaller chunk_size or save "
                "fewer nodes (a larger save_every)"
            )
    if disk is not None:
        try:
            free = shutil.disk_usage(disk).free
        except OSError:
            free = None
        if free is not None and store > free:
            raise SweepError(
                f"out: {what.partition(': ')[2]}, and only {format_bytes(free)} are free "
                f"in {str(disk)!r}; free some space or write the store elsewhere"
            )
    return store


def _plan(
    model,
    grid,
    *,
    method,
    h,
    steps,
    t_final,
    save_every,
    set_params,
    project_v0,
    chunk_size,
    max_bytes=None,
    disk=None,
) -> _Plan:
    """Validate a sweep's input and work out its specification (or raise SweepError,
    InputError or MethodError). The sizes are checked (:func:`_check_size`, with
    `max_bytes` and `disk`) before anything of the sweep's size is allocated."""
    from . import __version__
    from .methods import method_names
    from .models import get_model
    from .models.registry import default_method_for

    if method is None:  # the model's measured default
        method = default_method_for(str(model))
    from .simulate import resolve_steps

    if not isinstance(model, str):
        raise SweepError(f"model: expected a model name, got {model!r}")
    spec = get_model(model)  # InputError "model: unknown model ..."
    if not isinstance(method, str) or method not in method_names():
        raise SweepError(
            f"method: unknown method {method!r} (known: {', '.join(method_names())})"
        )
    if method == "reference":
        raise SweepError(
            "method: the continuous reference runs one trajectory at a time; it cannot "
            "be swept"
        )
    h, steps = resolve_steps(h, steps, t_final)
    save_every = (
        steps if save_every is None else _positive_int("save_every", save_every)
    )
    save_every = min(save_every, steps)
    chunk_size = _positive_int("chunk_size", chunk_size)
    axes = _as_axes(grid)
    set_params = dict(set_params or {})
    try:
        params = spec.resolve_params(set_params)
    except InputError as e:
        raise SweepError(f"set_params: {str(e).partition(':')[2].strip()}") from None
    system = spec.build(params)
    coordinates, velocities = tuple(spec.coordinates), tuple(system.velocities)
    ic_names = [f"q0.{c}" for c in coordinates] + [f"v0.{v}" for v in velocities]
    for a in axes:
        if a.name in set_params:
            raise SweepError(
                f"grid: {a.name!r} is both swept (grid) and fixed (set_params)"
            )
        if a.name not in spec.params and a.name not in ic_names:
            known = ", ".join([*spec.params, *ic_names]) or "none"
            raise SweepError(
                f"grid: unknown name {a.name!r} for model {spec.name!r} (known: "
                f"{known})"
            )
    swept = {a.name for a in axes}
    members = math.prod(a.count for a in axes)
    chunk = min(chunk_size, members)
    k = system.group.matrix_size if system.group is not None else None
    n, N = len(coordinates), len(velocities)
    n_blocks, remainder = divmod(steps, save_every)
    saved = n_blocks + 1 + (1 if remainder else 0)
    # bytes per member and saved node: q, v, p, energy, constraint_residual (at most N
    # constraints), R, valid; per member: result, failed_step, failed_time,
    # failed_residual, the grid values and the member index
    node_bytes = 8 * (n + 2 * N + 1 + N + (k or 0) ** 2) + 1
    member_bytes = 4 + 4 + 8 + 8 + 8 * len(axes) + 8
    store_bytes = _check_size(axes, members=members, chunk=chunk, saved=saved,
                              node_bytes=node_bytes, member_bytes=member_bytes,
                              max_bytes=max_bytes, disk=disk)
    times = h * _saved_steps(steps, save_every).astype(np.float64)
    sweep_spec = {
        "format": FORMAT,
        "model": spec.name,
        "method": method,
        "h": h,
        "steps": steps,
        "save_every": save_every,
        "grid": [a.to_dict() for a in axes],
        "set_params": {k: float(v) for k, v in params.items() if k in set_params},
        "params": {k: float(v) for k, v in params.items() if k not in swept},
        "project_v0": bool(project_v0),
        "chunk_size": chunk,
        "gnipy_version": __version__,
    }
    m, orientation = _preflight(sweep_spec, axes, members)
    return _Plan(
        sweep_spec,
        tuple(axes),
        members,
        chunk,
        -(-members // chunk),
        times,
        coordinates,
        velocities,
        m,
        k,
        orientation,
        store_bytes,
    )


def _preflight(sweep_spec, axes, members) -> tuple[int, str]:
    """Check the corner members of the grid on the driver (fast, before any cluster
    starts); return the number of constraints and the attribute `orientation` (from the
    corner members' systems)."""
    from .methods import get_method
    from .system import describe_orientations

    corners = sorted(
        {
            int(np.ravel_multi_index(c, tuple(a.count for a in axes)))
            for c in itertools.islice(
                itertools.product(*[(0, a.count - 1) for a in axes]), _MAX_PREFLIGHT
            )
        }
    )
    idx = np.asarray(corners)
    columns = _grid_columns(axes, idx)
    systems, q0, v0, R0 = _member_inputs(sweep_spec, columns, len(idx))
    method = get_method(sweep_spec["method"])
    m = 0
    for i in range(len(idx)):
        s = systems[i] if isinstance(systems, list) else systems
        b0 = _check_member(s, sweep_spec, columns, i, int(idx[i]), q0, v0, R0)
        method.check(s, b0)
        m = s.num_constraints(b0)
    return m, describe_orientations(systems if isinstance(systems, list) else [systems])


def _describe_member(columns, i) -> str:
    return ", ".join(f"{k}={float(v[i]):.6g}" for k, v in columns.items())


def _check_member(system, sweep_spec, columns, i, member, q0, v0, R0):
    """System.check for one member (the velocity only when it is not to be projected:
    a projection always succeeds once the metric and the constraints pass)."""
    project = sweep_spec["project_v0"]
    try:
        b0, _ = system.check(q0[i], None if project else v0[i], R0=R0)
    except InputError as e:
        msg = str(e).replace(
            "pass project_v0=True to project it",
            "sweep with project_v0=True to project it",
        )
        raise SweepError(
            f"grid: member {member} ({_describe_member(columns, i)}): {msg}"
        ) from None
    return b0


# --------------------------------------------------------------------------------------
# The task: one chunk
# --------------------------------------------------------------------------------------
def _member_inputs(
    job: Mapping[str, Any], columns: Mapping[str, np.ndarray], size: int
):
    """`(systems, q0, v0, R0)` for `size` members: a list of Systems when parameters
    vary (else one System), q0 (size, n), v0 (size, N), R0 (k, k) or None."""
    from .ensembles import model_systems
    from .models import get_model

    spec = get_model(job["model"])
    base = dict(job["params"])
    pcols = {
        k: np.asarray(v, dtype=np.float64)
        for k, v in columns.items()
        if not k.startswith(("q0.", "v0."))
    }
    if pcols:
        systems = model_systems(job["model"], **base, **pcols)
        first = systems[0]
    else:
        systems = first = spec.build(dict(spec.params) | base)
    coordinates, velocities = list(spec.coordinates), list(first.velocities)
    if pcols and spec.default_ic is not None:
        # the default initial condition depends on the parameters: one per member
        ics = [
            spec.initial_condition(base | {k: float(v[i]) for k, v in pcols.items()})
            for i in range(size)
        ]
        q0 = np.array([q for q, _ in ics], dtype=np.float64).reshape(
            size, len(coordinates)
        )
        v0 = np.array([v for _, v in ics], dtype=np.float64).reshape(
            size, len(velocities)
        )
    else:
        q, v = spec.initial_condition(dict(spec.params) | base)
        q0 = np.tile(
            np.asarray(q, dtype=np.float64).reshape(1, len(coordinates)), (size, 1)
        )
        v0 = np.tile(
            np.asarray(v, dtype=np.float64).reshape(1, len(velocities)), (size, 1)
        )
    for k, col in columns.items():
        if k.startswith("q0."):
            q0[:, coordinates.index(k[3:])] = col
        elif k.startswith("v0."):
            v0[:, velocities.index(k[3:])] = col
    R0 = None
    if first.group is not None and spec.R0 is not None:
        kk = first.group.matrix_size
        R0 = np.asarray(spec.R0, dtype=np.float64).reshape(kk, kk)
    return systems, q0, v0, R0


def run_chunk(
    job: Mapping[str, Any], first: int, columns: Mapping[str, np.ndarray], size: int
) -> dict[str, np.ndarray]:
    """Simulate one chunk of a sweep: the task :func:`run_sweep` sends to the workers.

    Arguments:
        job: the sweep's specification (the `sweep_spec` of the store: model, method, h,
            steps, save_every, params, project_v0, ...).
        first: the index of the chunk's first member in the sweep (for error messages).
        columns: each grid axis's value for every member of the chunk, name -> (B,)
            arrays; B is the chunk size (the last chunk is padded by repeating its last
            member).
        size: the number of real members (the first `size` of the B); the others are
            dropped.

    Returns:
        numpy arrays with a leading member axis of length `size`: `q, v, p, energy,
        constraint_residual, valid, result, failed_step, failed_time, failed_residual`,
        and `R` on Rⁿ × G. A failed member's `q, v, p, energy, constraint_residual, R` are
        NaN after its last good node (where `valid` is False); `failed_time` is the time
        at the start of its failed step and `failed_residual` the residual of the failed
        solve (both NaN for a member that did not fail, and the residual NaN when the
        simulation does not report it).

    Raises:
        SweepError: a member whose parameters or initial condition are not acceptable
            (named by its index in the sweep and its grid values).
    """
    from .compilation import cache_requested, enable_compilation_cache
    from .simulate import simulate

    if cache_requested():  # opt-in (see gnipy.compilation): reuse programs compiled by earlier runs
        enable_compilation_cache()
    B = len(next(iter(columns.values())))
    systems, q0, v0, R0 = _member_inputs(job, columns, B)
    try:
        sol = simulate(
            systems,
            job["method"],
            q0,
            v0,
            R0=R0,
            h=job["h"],
            steps=job["steps"],
            save_every=job["save_every"],
            project_v0=job["project_v0"],
            throw=False,
        )
    except InputError:
        # name the member at fault: check them one by one (only on this error path)
        for i in range(B):
            s = systems[i] if isinstance(systems, list) else systems
            _check_member(s, job, columns, i, first + min(i, size - 1), q0, v0, R0)
        raise
    valid = np.asarray(sol.valid, dtype=bool)
    failed_steps = np.asarray(sol.failed_steps, dtype=np.int64)
    failed = failed_steps >= 0

    def blank(a):
        """NaN where the member's node is not valid (after its failed step)."""
        a = np.array(a, dtype=np.float64)
        return np.where(valid.reshape(valid.shape + (1,) * (a.ndim - 2)), a, np.nan)

    # the residual of each member's failed solve, where the simulation reports it
    residuals = getattr(sol, "failed_residuals", None)
    residuals = (
        np.full(B, np.nan)
        if residuals is None
        else np.asarray(residuals, dtype=np.float64).reshape(B)
    )
    out = {
        "q": blank(sol.q),
        "v": blank(sol.v),
        "p": blank(sol.p),
        "energy": blank(sol.energy),
        "constraint_residual": blank(sol.constraint_residual),
        "valid": valid,
        "result": np.asarray(sol.results),
        "failed_step": failed_steps.astype(np.int32),
        "failed_time": np.where(failed, float(job["h"]) * failed_steps, np.nan),
        "failed_residual": np.where(failed, residuals, np.nan),
    }
    if sol.R is not None:
        out["R"] = blank(sol.R)
    return {k: np.asarray(v)[:size] for k, v in out.items()}


# --------------------------------------------------------------------------------------
# The store
# --------------------------------------------------------------------------------------
_MEMBER_VARS = {
    # name: (dims after member, dtype, long name)
    "q": (("time", "coordinate"), np.float64, "configuration"),
    "v": (("time", "velocity"), np.float64, "reported velocity"),
    "p": (("time", "velocity"), np.float64, "reported momentum"),
    "energy": (("time",), np.float64, "energy ½vᵀGv + V"),
    "constraint_residual": (
        ("time", "constraint"),
        np.float64,
        "constraint residual mu(q)(v - Y(q))",
    ),
    "R": (("time", "i", "j"), np.float64, "orientation R (group matrix)"),
    "valid": (
        ("time",),
        bool,
        "saved node computed (False after a failed step, or chunk not done)",
    ),
    "result": ((), np.int32, "0: success, 1: a step failed"),
    "failed_step": ((), np.int32, "first failed step or -1"),
    "failed_time": ((), np.float64, "time at the start of the failed step, or NaN"),
    "failed_residual": ((), np.float64, "residual of the failed step's solve, or NaN"),
}
# the coordinates of the store (arrays too)
_COORDS = ("member", "time", "node", "step", "coordinate", "velocity", "constraint", "chunk")
# per chunk
_CHUNK_VARS = ("chunk_done", "chunk_checksum")
# the metadata files at the top of a zarr store (v3 and v2)
_META_FILES = ("zarr.json", ".zgroup", ".zattrs", ".zmetadata")


def _array_names(member_vars, grid_names) -> tuple[str, ...]:
    return tuple(sorted({*member_vars, *(f"grid_{g}" for g in grid_names), *_CHUNK_VARS,
                         *_COORDS}))


def _template(plan: _Plan):
    """The full-size Dataset of the store: lazily defined (dask) per-member arrays,
    whose zarr chunks are the sweep's chunks along `member`."""
    import dask.array as da
    import xarray as xr

    from . import __version__
    from .io import _jax_version, cf_attributes, time_coordinates
    from .solution import set_variable_attrs

    T = len(plan.times)
    sizes = {
        "time": T,
        "coordinate": len(plan.coordinates),
        "velocity": len(plan.velocities),
        "constraint": plan.constraints,
        "i": plan.matrix_size or 0,
        "j": plan.matrix_size or 0,
    }
    width = max(
        1,
        len(plan.coordinates),
        len(plan.velocities),
        plan.constraints,
        (plan.matrix_size or 0) ** 2,
    )
    t_chunk = max(1, min(T, _MAX_ZARR_CHUNK_BYTES // (8 * plan.chunk * width)))
    variables = {}
    for name, (dims, dtype, long_name) in _MEMBER_VARS.items():
        if name == "R" and plan.matrix_size is None:
            continue
        shape = (plan.members, *(sizes[d] for d in dims))
        chunks = (
            plan.chunk,
            *(t_chunk if d == "time" else max(1, sizes[d]) for d in dims),
        )
        variables[name] = (
            ("member", *dims),
            da.zeros(shape, chunks=chunks, dtype=dtype),
            {"long_name": long_name},
        )
    all_members = np.arange(plan.members)
    for a, col in _grid_columns(plan.axes, all_members).items():
        variables[f"grid_{a}"] = (("member",), col, {"long_name": f"grid value of {a}"})
    variables["chunk_done"] = (
        ("chunk",),
        da.zeros((plan.chunks,), chunks=(1,), dtype=bool),
        {"long_name": "True once the chunk's data and checksum are written (written last)"},
    )
    variables["chunk_checksum"] = (
        ("chunk", "digest"),
        da.zeros((plan.chunks, 32), chunks=(1, 32), dtype=np.uint8),
        {"long_name": "SHA-256 digest of the chunk's data (gnipy.files.array_checksum of its "
                      "member variables and grid values); zero until written"},
    )
    ds = xr.Dataset(
        variables,
        coords={
            "member": all_members,
            **time_coordinates(plan.times, plan.spec["h"]),
            "coordinate": np.array(plan.coordinates, dtype=object),
            "velocity": np.array(plan.velocities, dtype=object),
            "constraint": np.arange(plan.constraints),
            "chunk": np.arange(plan.chunks),
        },
    )
    for name in ("grid_" + a.name for a in plan.axes):
        ds[name].encoding["chunks"] = (plan.chunk,)
    ds["member"].encoding["chunks"] = (plan.chunk,)
    ds["time"].encoding["_FillValue"] = None  # CF: a coordinate variable has no missing values
    set_variable_attrs(ds)
    s = plan.spec
    created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    grid = " ".join(str(a) for a in plan.axes)
    ds.attrs.update(cf_attributes(s["model"], s["method"], created=created,
                                  title=f"sweep of {s['model']} with {s['method']} over {grid}"))
    if plan.orientation:
        ds.attrs["orientation"] = plan.orientation
    ds.attrs.update(
        {
            "sweep_spec": json.dumps(s, sort_keys=True),
            "model": s["model"],
            "method": s["method"],
            "h": s["h"],
            "steps": s["steps"],
            "t_final": float(plan.times[-1]),
            "save_every": s["save_every"],
            "project_v0": int(s["project_v0"]),
            "chunk_size": s["chunk_size"],
            "members": plan.members,
            "chunks": plan.chunks,
            "grid": json.dumps(s["grid"]),
            "grid_dims": json.dumps([a.name for a in plan.axes]),
            "set_params": json.dumps(s["set_params"]),
            "params": json.dumps(s["params"]),
            "start": "p+ = G v0",
            "gnipy_version": __version__,
            "jax_version": _jax_version(),
            "created": created,
            "store_arrays": json.dumps(sorted(ds.variables)),
        }
    )
    return ds


def _read_attrs(path: Path) -> dict[str, Any] | None:
    """The attributes of the zarr group at `path`, or None if it is not a zarr group."""
    import zarr

    if not (path / "zarr.json").is_file() and not (path / ".zgroup").is_file():
        return None
    try:
        return dict(zarr.open_group(str(path), mode="r").attrs)
    except Exception:  # noqa: BLE001 - unreadable: not a store we know
        return None


def _parse_spec(text) -> dict[str, Any] | None:
    try:
        spec = json.loads(text)
    except (TypeError, ValueError):
        return None
    ok = isinstance(spec, dict) and spec.get("format") in (FORMAT, *_OLD_FORMATS)
    return spec if ok else None


def _stored_spec(path: Path) -> dict[str, Any] | None:
    """The `sweep_spec` of the store at `path` (this format or an older one), or None."""
    attrs = _read_attrs(path)
    if attrs is None or "sweep_spec" not in attrs:
        return None
    return _parse_spec(attrs["sweep_spec"])


def _marker_purpose(path: Path) -> str | None:
    """The purpose recorded in the marker of the gnipy directory `path` (None if unreadable)."""
    try:
        purpose = json.loads((path / files.MARKER).read_text()).get("purpose")
    except (OSError, ValueError, AttributeError):
        return None
    return purpose if isinstance(purpose, str) else None


def _is_store(path: Path) -> bool:
    """Whether `path` is a sweep store: a directory gnipy created as one (it may be damaged),
    or one with a readable `sweep_spec` (stores of earlier versions have no marker)."""
    if files.is_owned_dir(path):
        return _marker_purpose(path) in (None, _PURPOSE)
    try:
        is_dir = stat.S_ISDIR(os.lstat(path).st_mode)
    except OSError:
        return False
    return is_dir and _stored_spec(path) is not None


def _why(e: BaseException) -> str:
    text = " ".join(str(e).split())
    if len(text) > 160:
        text = text[:157] + "..."
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _damaged(argument: str, path: Path, what: str) -> SweepError:
    return SweepError(
        f"{argument}: the sweep store {str(path)!r} is damaged: {what}; start afresh with "
        "overwrite=True (its data cannot be trusted)"
    )


def _open_group(path: Path, argument: str, mode: str = "r"):
    """`(group, spec)` of the store at `path`, or a SweepError saying what is damaged."""
    import zarr

    if not (path / "zarr.json").is_file() and not (path / ".zgroup").is_file():
        raise _damaged(argument, path, "its metadata file zarr.json is missing")
    try:
        group = zarr.open_group(str(path), mode=mode)
        attrs = dict(group.attrs)
    except Exception as e:  # noqa: BLE001 - any failure to parse the metadata
        raise _damaged(
            argument, path, f"its metadata (zarr.json) cannot be read ({_why(e)})"
        ) from None
    spec = _parse_spec(attrs.get("sweep_spec"))
    if spec is None:
        raise _damaged(
            argument, path, "its attribute sweep_spec (the sweep's specification) is "
            "missing or unreadable"
        )
    return group, spec


def _stored_array_names(group, spec) -> tuple[str, ...] | None:
    """The arrays the store was created with (None for a store of an older format)."""
    try:
        names = json.loads(group.attrs["store_arrays"])
    except (KeyError, TypeError, ValueError):
        return None
    return tuple(names) if isinstance(names, list) else None


def _check_arrays(argument: str, path: Path, group, names, spec) -> dict[str, Any]:
    """Open every array `names` of the store, check its length along `member`, `chunk` or
    `time`; return them (SweepError naming the first one damaged)."""
    import zarr

    members = math.prod(int(g["count"]) for g in spec["grid"])
    chunks = -(-members // int(spec["chunk_size"]))
    saved = len(_saved_steps(int(spec["steps"]), int(spec["save_every"])))
    arrays = {}
    for name in names:
        try:
            arr = group[name]
        except KeyError:
            raise _damaged(
                argument, path, f"its array {name!r} is missing (the directory {name}/ or "
                f"its metadata {name}/zarr.json was deleted)"
            ) from None
        except Exception as e:  # noqa: BLE001
            raise _damaged(
                argument, path, f"the metadata of its array {name!r} ({name}/zarr.json) "
                f"cannot be read ({_why(e)})"
            ) from None
        if not isinstance(arr, zarr.Array):
            raise _damaged(argument, path, f"{name!r} is not an array")
        if name in _MEMBER_VARS or name.startswith("grid_") or name == "member":
            length = members
        elif name in _CHUNK_VARS or name == "chunk":
            length = chunks
        elif name in ("time", "node", "step"):
            length = saved
        else:
            length = None
        if length is not None and (arr.ndim == 0 or arr.shape[0] != length):
            raise _damaged(
                argument, path, f"its array {name!r} has shape {arr.shape}, expected "
                f"{length} along its first axis"
            )
        arrays[name] = arr
    return arrays


def _check_coordinates(argument: str, path: Path, arrays, spec) -> None:
    """The coordinates the sweep's specification determines hold their values."""
    steps = _saved_steps(int(spec["steps"]), int(spec["save_every"]))
    h = float(spec["h"])
    expected = {
        "member": np.arange(arrays["member"].shape[0]),
        "chunk": np.arange(arrays["chunk"].shape[0]),
        "time": h * steps.astype(np.float64),
        "node": np.arange(len(steps)),
        "step": steps,
    }
    for name in _COORDS:
        if name not in arrays:
            continue
        try:
            values = np.asarray(arrays[name][...])
        except Exception as e:  # noqa: BLE001
            raise _damaged(
                argument, path, f"its coordinate {name!r} cannot be read ({_why(e)})"
            ) from None
        if name in expected and not np.array_equal(values, expected[name]):
            raise _damaged(
                argument, path, f"its coordinate {name!r} does not hold the sweep's values"
            )


def _read_done(argument: str, path: Path, arrays, chunks: int) -> np.ndarray:
    try:
        done = np.asarray(arrays["chunk_done"][...], dtype=bool)
    except Exception as e:  # noqa: BLE001
        raise _damaged(
            argument, path, f"its chunk flags (chunk_done) cannot be read ({_why(e)})"
        ) from None
    if done.shape != (chunks,):
        raise _damaged(
            argument, path, f"chunk_done has shape {done.shape}, expected ({chunks},)"
        )
    return done


def _digest(data: Mapping[str, np.ndarray]) -> bytes:
    """The SHA-256 digest (32 bytes) of a chunk's data, each array in its stored dtype."""
    typed = {
        name: np.asarray(a, dtype=_MEMBER_VARS[name][1] if name in _MEMBER_VARS else np.float64)
        for name, a in data.items()
    }
    return bytes.fromhex(files.array_checksum(typed).partition(":")[2])


def _data_names(names) -> list[str]:
    """The arrays a chunk's checksum covers: its member variables and grid values."""
    return sorted(n for n in names if n in _MEMBER_VARS or n.startswith("grid_"))


def _verify_chunks(arrays, names, chunk: int, members: int, done: np.ndarray,
                   block_bytes: int = _MAX_ZARR_CHUNK_BYTES) -> dict[int, str]:
    """Read every chunk flagged done back and compare its checksum: `{chunk: what is wrong}`
    for those unreadable or different. Consecutive chunks are read together, up to about
    `block_bytes` at a time (a block that cannot be read is read again chunk by chunk, to
    find the chunks at fault)."""
    bad = {}
    data_names = _data_names(names)
    try:
        sums = np.asarray(arrays["chunk_checksum"][...], dtype=np.uint8)
    except Exception:  # noqa: BLE001 - read them one by one below
        sums = None
    per_member = sum(
        math.prod(arrays[n].shape[1:]) * arrays[n].dtype.itemsize for n in data_names
    )
    per_block = max(1, block_bytes // max(1, chunk * per_member))

    def read(a, b):
        out = {}
        for name in data_names:
            try:
                out[name] = np.asarray(arrays[name][a:b])
            except Exception as e:  # noqa: BLE001 - a truncated or corrupted chunk file
                return f"its {name!r} data cannot be read ({_why(e)})"
        return out

    def check(i, data):
        if sums is not None:
            stored = sums[i]
        else:
            try:
                stored = np.asarray(arrays["chunk_checksum"][i], dtype=np.uint8)
            except Exception as e:  # noqa: BLE001
                return f"its checksum cannot be read ({_why(e)})"
        if stored.shape != (32,) or not stored.any():
            return "it has no checksum"
        if isinstance(data, str):
            return data
        if _digest(data) != stored.tobytes():
            return "its data differ from their checksum"
        return None

    todo = [int(i) for i in np.flatnonzero(done)]
    # runs of consecutive chunks, cut into blocks of at most `per_block` chunks
    blocks, start = [], 0
    for k in range(1, len(todo) + 1):
        if k == len(todo) or todo[k] != todo[k - 1] + 1 or k - start == per_block:
            blocks.append(todo[start:k])
            start = k
    for block in blocks:
        a0, b0 = block[0] * chunk, min((block[-1] + 1) * chunk, members)
        data = read(a0, b0) if len(block) > 1 else None
        for i in block:
            a, b = i * chunk, min((i + 1) * chunk, members)
            if isinstance(data, dict):
                part = {name: x[a - a0: b - a0] for name, x in data.items()}
            else:
                part = read(a, b)
            why = check(i, part)
            if why is not None:
                bad[i] = why
    return bad


def _describe_members(axes, a: int, b: int) -> str:
    """`member 6 (m=1.5, q0.x=-1)` or `members 6..7 (m=1.5, q0.x=-1 .. m=1.5, q0.x=1)`."""
    idx = np.array([a, b - 1])
    cols = _grid_columns(axes, idx)
    first, last = _describe_member(cols, 0), _describe_member(cols, 1)
    if b - a == 1:
        return f"member {a} ({first})"
    return f"members {a}..{b - 1} ({first} .. {last})"


def _fmt_value(key, value) -> str:
    if key == "grid" and isinstance(value, list):
        try:
            return " ".join(str(GridAxis(**g)) for g in value)
        except Exception:  # noqa: BLE001
            pass
    return (
        json.dumps(value, sort_keys=True)
        if isinstance(value, (dict, list))
        else repr(value)
    )


def _compare_specs(
    path: Path, stored: dict[str, Any], requested: dict[str, Any]
) -> None:
    if stored.get("format") != requested["format"]:
        raise SweepError(
            f"out: the store {str(path)!r} was written by an earlier gnipy (format "
            f"{stored.get('format')}, without chunk checksums) and cannot be resumed; "
            "start afresh with overwrite=True, or choose another output path"
        )
    for key in requested:
        if stored.get(key) != requested[key]:
            raise SweepError(
                f"out: the store {str(path)!r} holds a different sweep: {key} is "
                f"{_fmt_value(key, stored.get(key))} there and "
                f"{_fmt_value(key, requested[key])} here; choose another output path "
                "or start afresh with overwrite=True"
            )
    extra = sorted(set(stored) - set(requested))
    if extra:
        raise SweepError(
            f"out: the store {str(path)!r} holds a different sweep (it has "
            f"{extra[0]!r}); choose another output path or start afresh with "
            "overwrite=True"
        )


def _foreign_entries(path: Path) -> list[str]:
    """The entries at the top of the store `path` that gnipy does not write there."""
    foreign = []
    try:
        entries = sorted(os.scandir(path), key=lambda e: e.name)
    except OSError:
        return foreign
    for e in entries:
        if e.is_symlink():
            foreign.append(e.name)
        elif e.is_dir():
            ours = (
                e.name in _MEMBER_VARS or e.name in _COORDS or e.name in _CHUNK_VARS
                or e.name.startswith("grid_")
                or any(os.path.isfile(os.path.join(e.path, m)) for m in ("zarr.json", ".zarray"))
            )
            if not ours:
                foreign.append(e.name + "/")
        elif e.name not in (*_META_FILES, files.MARKER):
            foreign.append(e.name)
    return foreign


def _remove_store(path: Path) -> None:
    """Delete a store gnipy wrote (what :func:`_foreign_entries` does not list)."""
    foreign = set(_foreign_entries(path))
    try:
        entries = list(os.scandir(path))
    except OSError:
        return
    for e in entries:
        if e.name in foreign or e.name + "/" in foreign:
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
        except OSError:
            pass
    try:
        os.rmdir(path)
    except OSError:
        pass


def _check_out(out, overwrite: bool) -> tuple[Path, str]:
    """The store's path and what to do there: `"create"` (nothing there, or an empty
    directory), `"replace"` (a store gnipy wrote, with overwrite) or `"resume"`. Changes
    nothing; SweepError (`out: ...`) for a destination gnipy must not write."""
    if not isinstance(out, (str, os.PathLike)) or not os.fspath(out):
        raise SweepError(f"out: expected a path to a directory DIR.zarr, got {out!r}")
    path = Path(os.fspath(out)).expanduser()
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise SweepError(f"out: cannot use {str(path)!r}: {e.strerror or e}") from None
    is_dir = st is not None and stat.S_ISDIR(st.st_mode)
    owned = is_dir and files.is_owned_dir(path)
    if owned and _marker_purpose(path) not in (None, _PURPOSE):
        raise SweepError(
            f"out: {str(path)!r} is a directory gnipy created for something else "
            f"({_marker_purpose(path)}), not a sweep store; choose another path"
        )
    # a store written by an earlier gnipy has no marker: its sweep_spec tells it is one
    legacy = is_dir and not owned and _stored_spec(path) is not None
    try:
        if legacy:
            parent = path.parent if str(path.parent) else Path(".")
            for where in (path, parent):
                if not os.access(where, os.W_OK | os.X_OK):
                    raise files.OutputError(f"out: {where} is not writable")
        else:
            files.check_directory_destination(path, overwrite=overwrite, reuse=True,
                                              argument="out")
    except files.OutputError as e:
        raise SweepError(str(e)) from None
    if not (owned or legacy):
        return path, "create"
    if not overwrite:
        return path, "resume"
    foreign = _foreign_entries(path)
    if foreign:
        listed = ", ".join(repr(f) for f in foreign[:5]) + (", ..." if len(foreign) > 5 else "")
        raise SweepError(
            f"out: {str(path)!r} holds {listed}, which gnipy did not write; gnipy replaces "
            "a sweep store only when everything in it is its own: move them away, or "
            "choose another path"
        )
    return path, "replace"


def _create_store(path: Path, plan: _Plan, mode: str) -> None:
    """Write the store's metadata, its marker and the per-member grid values into a
    temporary directory beside `path`, then rename it into place (replacing, for `mode`
    "replace", the store there, else nothing or an empty directory)."""
    tmp = files.temporary_name(path, "partial")
    old = None
    try:
        _template(plan).to_zarr(str(tmp), mode="w-", compute=False, consolidated=False)
        marker = {"created_by": "gnipy", "purpose": _PURPOSE}
        (tmp / files.MARKER).write_text(json.dumps(marker) + "\n")
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
            _remove_store(old)


def _write_chunk(
    path: Path, plan: _Plan, index: int, result: Mapping[str, np.ndarray]
) -> None:
    """Write one chunk's data and grid values, then its checksum, then (last) its
    `chunk_done` flag."""
    import zarr

    a, b = plan.member_range(index)
    data = {}
    for name, arr in result.items():
        if name not in _MEMBER_VARS:
            raise SweepFailure(f"chunk {index}: the task returned an unknown variable {name!r}")
        arr = np.asarray(arr, dtype=_MEMBER_VARS[name][1])
        if arr.shape[:1] != (b - a,):
            raise SweepFailure(
                f"chunk {index}: the task returned {arr.shape[:1]} members for {name}, "
                f"expected {b - a}"
            )
        data[name] = arr
    missing = sorted(set(plan.member_vars) - set(data))
    if missing:
        raise SweepFailure(f"chunk {index}: the task returned no {missing[0]!r}")
    for name, col in plan.columns(index).items():
        data[f"grid_{name}"] = np.asarray(col[: b - a], dtype=np.float64)
    digest = np.frombuffer(_digest(data), dtype=np.uint8)
    group = zarr.open_group(str(path), mode="r+")
    for name, arr in data.items():
        group[name][a:b] = arr
    group["chunk_checksum"][index] = digest
    group["chunk_done"][index] = True


# --------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SweepReport:
    """What :func:`run_sweep` did.

    Attributes:
        path: the store.
        members: the number of members of the sweep (grid points).
        chunks: the number of chunks of the sweep.
        chunks_computed: chunks computed (and written) by this run.
        chunks_skipped: chunks found done (and intact) in the store and not recomputed.
        chunks_remaining: chunks still not done (non-zero only when `max_chunks` stopped
            the run).
        failed_members: members whose run failed (`result = 1`) over all done chunks.
        wall_time: seconds for the whole call (cluster start, compilation and writes
            included).
        members_computed: members computed by this run (padding excluded).
        steps: the number of steps per member.
        chunk_size: the number of members per chunk.
        spec: the sweep's specification (as stored in the store's `sweep_spec`
            attribute).
        chunks_repaired: chunks flagged done but found damaged (unreadable, or their data
            differ from their checksum), and so not skipped (a :class:`SweepWarning` named
            each).
        failures: the first failed members (at most 5), each a dict: `member` (its index),
            `grid` (its grid values, name -> value), `step`, `time` (the failed step and its
            start time) and `residual` (of the failed solve; NaN when not reported).
    """

    path: Path
    members: int
    chunks: int
    chunks_computed: int
    chunks_skipped: int
    chunks_remaining: int
    failed_members: int
    wall_time: float
    members_computed: int
    steps: int
    chunk_size: int
    spec: dict = dataclasses.field(repr=False, compare=False)
    chunks_repaired: int = 0
    failures: tuple = dataclasses.field(default=(), repr=False, compare=False)

    @property
    def complete(self) -> bool:
        """Whether every chunk of the sweep is done."""
        return self.chunks_remaining == 0

    @property
    def member_steps_per_second(self) -> float:
        """Member-steps computed per second of wall time in this run."""
        return (
            self.members_computed * self.steps / self.wall_time
            if self.wall_time > 0
            else float("nan")
        )


def _progress_bar(enabled: bool):
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    console = Console(stderr=True)
    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("chunks"),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=True,
        disable=not (enabled and console.is_terminal),
    )


def _default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


# HOST:PORT (a name, an IPv4 address, or an IPv6 address in brackets)
_HOST_PORT = re.compile(
    r"^(?:\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?):(\d{1,5})$"
)
_NETWORK_PROTOCOLS = ("tcp", "tls", "ws", "wss", "ucx")


def _scheduler_address(scheduler, *, _from_file: str | None = None) -> str:
    """The address to connect to for `scheduler` (an address or a scheduler file), or a
    SweepError (`scheduler: ...`); nothing is contacted."""
    where = f" (in the scheduler file {_from_file!r})" if _from_file else ""
    usage = ("an address tcp://HOST:PORT, tls://HOST:PORT, inproc://..., HOST:PORT, or a "
             "scheduler file (JSON, from `dask scheduler --scheduler-file`)")
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise SweepError(f"scheduler: expected {usage}, got {scheduler!r}{where}")
    text = scheduler.strip()
    if "://" in text:
        protocol, _, location = text.partition("://")
        if protocol == "inproc":
            if location and not any(c.isspace() for c in location):
                return text
        elif protocol in _NETWORK_PROTOCOLS:
            m = _HOST_PORT.match(location)
            if m and 0 < int(m.group(1)) < 65536:
                return text
        raise SweepError(f"scheduler: {text!r}{where} is not a valid address; expected {usage}")
    m = _HOST_PORT.match(text)
    if m and 0 < int(m.group(1)) < 65536:
        return "tcp://" + text
    if _from_file is None and os.path.isfile(os.path.expanduser(text)):
        try:
            with open(os.path.expanduser(text), encoding="utf-8") as fh:
                address = json.load(fh)["address"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise SweepError(
                f"scheduler: {text!r} is not a scheduler file (JSON with the scheduler's "
                f"address): {_why(e)}"
            ) from None
        return _scheduler_address(address, _from_file=text)
    raise SweepError(
        f"scheduler: {text!r}{where} is neither a valid address nor a scheduler file that "
        f"exists; expected {usage}"
    )


def _local_cluster_kwargs(workers: int) -> dict[str, Any]:
    """The arguments of the local `distributed.LocalCluster`: single-threaded worker
    processes, and no dashboard (the scheduler's HTTP server, which always starts, listens on
    a random port of 127.0.0.1 instead of 8787; its pages are switched off with the
    configuration `distributed.scheduler.http.routes = []` while it starts)."""
    import logging

    return dict(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address="127.0.0.1:0",
        scheduler_kwargs={"dashboard": False},
        worker_dashboard_address=None,
        silence_logs=logging.ERROR,
    )


class _Cluster:
    """The client to use: the caller's, one connected to `address` (within
    `connect_timeout` seconds), or a new local cluster."""

    def __init__(self, client, address, workers, connect_timeout, scheduler=None):
        self.given, self.address, self.workers = client, address, workers
        self.connect_timeout, self.scheduler = connect_timeout, scheduler
        self.client = self.cluster = None

    def __enter__(self):
        import dask
        from distributed import Client, LocalCluster

        if self.given is not None:
            self.client = self.given
            return self.client
        if self.address is not None:
            try:
                self.client = Client(
                    self.address, timeout=self.connect_timeout, set_as_default=False
                )
            except Exception as e:  # noqa: BLE001 - refused, timed out, bad TLS, ...
                raise SweepError(
                    f"scheduler: cannot connect to {self.scheduler!r} within "
                    f"{self.connect_timeout:g} s ({_why(e)}); check the address and that "
                    "the scheduler runs, or raise connect_timeout"
                ) from None
            return self.client
        try:
            with dask.config.set({"distributed.scheduler.http.routes": []}):
                self.cluster = LocalCluster(**_local_cluster_kwargs(self.workers))
            self.client = Client(self.cluster, set_as_default=False)
        except Exception as e:  # noqa: BLE001
            self.__exit__()
            raise SweepFailure(
                f"cannot start a local cluster: {type(e).__name__}: {e}"
            ) from e
        return self.client

    def __exit__(self, *exc):
        if self.client is not None and self.client is not self.given:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        return False


def run_sweep(
    model: str,
    grid,
    *,
    out,
    h: float,
    steps: int | None = None,
    t_final: float | None = None,
    method: str | None = None,
    save_every: int | None = None,
    set_params: Mapping[str, float] | None = None,
    project_v0: bool = True,
    chunk_size: int = 1000,
    scheduler: str | None = None,
    workers: int | None = None,
    client=None,
    overwrite: bool = False,
    max_chunks: int | None = None,
    progress: bool = True,
    max_bytes: int | None = DEFAULT_MAX_BYTES,
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
) -> SweepReport:
    """Run a parameter sweep on a dask.distributed cluster and write it to a zarr store.

    Arguments:
        model: a model name (see :func:`gnipy.model_names`).
        grid: the grid axes: `"NAME=START:STOP:COUNT"` strings, :class:`GridAxis`
            objects, or a mapping `{name: (start, stop, count)}`; NAME is a parameter,
            `q0.<coordinate>` or `v0.<velocity>`. The sweep is their Cartesian product
            (C order).
        out: the zarr store (a directory, e.g. `"sweep.zarr"`); its parent must exist.
        h: the step size.
        steps / t_final: the number of steps, or the final time (a whole number of
            steps).
        method: a method name (see :func:`gnipy.method_names`; not `"reference"`); default: the
            model's measured default (`gni models`).
        save_every: the save stride (nodes 0, K, 2K, ... and the last); default `steps`:
            the initial and the last node only.
        set_params: fixed values of other parameters (the rest keep the model's
            defaults).
        project_v0: project each member's initial velocity onto its constraints (on by
            default: a v0 grid, or parameters that change the constraints, move v0 off
            them).
        chunk_size: members per task (and per zarr chunk along `member`); the last
            chunk's inputs are padded to this size so that every chunk runs the same
            compiled program.
        scheduler: an existing cluster's scheduler: its address (`"tcp://host:8786"`,
            `"tls://..."`, `"inproc://..."`, `"host:8786"`) or a scheduler file (JSON, as
            written by `dask scheduler --scheduler-file`); its workers need gnipy installed.
            The address is checked and the connection made before the store is created.
        workers: the size of the local cluster started when neither `scheduler` nor
            `client` is given (one single-threaded worker process each; default: the
            number of cores).
        client: an existing `distributed.Client` to use (it is not closed).
        overwrite: replace an existing store at `out` and start afresh: only a store gnipy
            created (with its marker, or an earlier version's store with a valid
            `sweep_spec`), holding nothing else at its top level.
        max_chunks: compute at most this many chunks and stop (the store stays
            resumable): for runs under a time limit, and to test resumption.
        progress: show a progress bar (chunks done, members/s) on stderr when it is a
            terminal.
        max_bytes: the largest estimated store size (bytes, uncompressed) accepted when a
            store is created; default :data:`DEFAULT_MAX_BYTES` (100 GiB); None: no bound.
            (The free space of the file system, and this machine's memory for one chunk,
            are checked whatever it is.)
        connect_timeout: seconds to wait for the connection to `scheduler` (default 10).

    Returns:
        A :class:`SweepReport`.

    Running the same sweep again on an existing store resumes it: the chunks done are read
    back and their checksums compared; the intact ones are skipped, the damaged ones
    recomputed (with a :class:`SweepWarning`). If the store holds a different sweep,
    :class:`SweepError` names the field that differs.

    Raises:
        SweepError: bad input (the message starts with the argument: `grid:`, `out:`,
            `scheduler:`, ...), a sweep over the size bounds, a scheduler that cannot be
            reached, a store whose metadata or arrays are damaged, or a member whose
            parameters or initial condition are not acceptable.
        gnipy.InputError: bad `h`, `steps`, `t_final` or model name.
        gnipy.MethodError: a method that cannot integrate this model.
        gnipy.files.OutputError: the store cannot be created or written.
        SweepFailure: a chunk failed on the cluster (e.g. a worker died), or the local
            cluster did not start.
    """
    t_start = time.perf_counter()
    address = None
    if scheduler is not None:
        if client is not None:
            raise SweepError("scheduler: give either a scheduler address or a client")
    if workers is not None:
        workers = _positive_int("workers", workers)
        if scheduler is not None or client is not None:
            raise SweepError(
                "workers: sets the size of a local cluster; it cannot be used with an "
                "existing cluster"
            )
    if max_chunks is not None:
        max_chunks = _positive_int("max_chunks", max_chunks)
    if max_bytes is not None and (
        isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, float, np.integer, np.floating))
        or not max_bytes > 0
    ):
        raise SweepError(f"max_bytes: must be a positive number of bytes or None, got {max_bytes!r}")
    if (isinstance(connect_timeout, bool) or not isinstance(connect_timeout, (int, float))
            or not (math.isfinite(connect_timeout) and connect_timeout > 0)):
        raise SweepError(f"connect_timeout: must be a positive number of seconds, got {connect_timeout!r}")
    if scheduler is not None:
        address = _scheduler_address(scheduler)
    path, mode = _check_out(out, overwrite)
    creating = mode != "resume"
    plan = _plan(
        model,
        grid,
        method=method,
        h=h,
        steps=steps,
        t_final=t_final,
        save_every=save_every,
        set_params=set_params,
        project_v0=project_v0,
        chunk_size=chunk_size,
        max_bytes=max_bytes if creating else None,
        disk=(path.parent if str(path.parent) else Path(".")) if creating else None,
    )
    # temporaries of runs killed while creating or replacing this store
    files.clean_stale_temporaries(path)

    repaired = 0
    if creating:
        done = np.zeros(plan.chunks, dtype=bool)
    else:
        done, repaired = _resume(path, plan)

    todo = [int(i) for i in np.flatnonzero(~done)]
    skipped = plan.chunks - len(todo)
    if max_chunks is not None:
        todo = todo[:max_chunks]
    computed = members = 0
    if todo:
        name = f"sweep {plan.spec['model']}"
        with _progress_bar(progress) as bar:
            task = bar.add_task(f"{name}: starting the cluster", total=len(todo), rate="")
            with _Cluster(client, address, workers or _default_workers(), connect_timeout,
                          scheduler) as c:
                if creating:
                    _create_store(path, plan, mode)
                computed, members = _compute(path, plan, todo, c, bar, task, name)
    group, _ = _open_group(path, "out")
    arrays = {k: group[k] for k in ("chunk_done", "result", "failed_step", "failed_time",
                                    "failed_residual")}
    done = _read_done("out", path, arrays, plan.chunks)
    failed, failures = _failures(arrays, plan.axes, plan.chunk, plan.members, done)
    return SweepReport(
        path=path,
        members=plan.members,
        chunks=plan.chunks,
        chunks_computed=computed,
        chunks_skipped=skipped,
        chunks_remaining=int(np.sum(~done)),
        failed_members=failed,
        wall_time=time.perf_counter() - t_start,
        members_computed=members,
        steps=plan.spec["steps"],
        chunk_size=plan.chunk,
        spec=plan.spec,
        chunks_repaired=repaired,
        failures=failures,
    )


def _resume(path: Path, plan: _Plan) -> tuple[np.ndarray, int]:
    """Check the store at `path` holds this sweep, intact; return its chunk flags (the damaged
    chunks' flags cleared, with a warning each) and the number of damaged chunks."""
    group, stored = _open_group(path, "out", mode="r+")
    _compare_specs(path, stored, plan.spec)
    arrays = _check_arrays("out", path, group, plan.array_names, plan.spec)
    _check_coordinates("out", path, arrays, plan.spec)
    done = _read_done("out", path, arrays, plan.chunks)
    bad = _verify_chunks(arrays, plan.array_names, plan.chunk, plan.members, done)
    for i, why in bad.items():
        a, b = plan.member_range(i)
        warnings.warn(
            SweepWarning(
                f"out: chunk {i} of {str(path)!r}, {_describe_members(plan.axes, a, b)}, was "
                f"done but is damaged ({why}): computing it again"
            ),
            stacklevel=3,
        )
        try:
            arrays["chunk_done"][i] = False
        except Exception as e:  # noqa: BLE001
            raise _damaged("out", path, f"its chunk flags cannot be written ({_why(e)})") from None
        done[i] = False
    return done, len(bad)


def _failures(arrays, axes, chunk: int, members: int, done: np.ndarray):
    """`(count, first)`: the failed members of the done chunks and the first few of them."""
    result = np.asarray(arrays["result"][...])
    member_done = np.repeat(done, chunk)[:members]
    failed = np.flatnonzero((result != 0) & member_done)
    first = failed[:_FAILURES_LISTED]
    out = []
    if len(first):
        cols = _grid_columns(axes, first)
        fields = {k: np.asarray(arrays[f"failed_{k}"].get_orthogonal_selection((first,)))
                  for k in ("step", "time", "residual")}
        for j, m in enumerate(first):
            out.append({
                "member": int(m),
                "grid": {name: float(v[j]) for name, v in cols.items()},
                "step": int(fields["step"][j]),
                "time": float(fields["time"][j]),
                "residual": float(fields["residual"][j]),
            })
    return int(len(failed)), tuple(out)


def _compute(path, plan, todo, c, bar, task, name) -> tuple[int, int]:
    """Submit the chunks `todo` to the client `c`, write each as it completes; returns
    `(chunks, members)` computed."""
    from distributed import as_completed

    from .integrators.base import MethodError

    computed = members_done = 0
    bar.update(task, description=f"{name}: compiling")
    token = uuid.uuid4().hex[:8]
    futures = {}
    for i in todo:
        a, b = plan.member_range(i)
        f = c.submit(
            run_chunk,
            plan.spec,
            a,
            plan.columns(i),
            b - a,
            key=f"gnipy-sweep-{token}-chunk-{i}",
            pure=False,
        )
        futures[f] = i
    # (time, members) at the first completed chunk: the rate is measured from
    # there, after the compilation
    first = None
    try:
        for f in as_completed(list(futures), loop=c.loop):
            i = futures[f]
            try:
                result = f.result()
            except (InputError, MethodError):
                raise  # bad input (a member's parameters, the method)
            except Exception as e:  # noqa: BLE001 - a worker died, ...
                a, b = plan.member_range(i)
                raise SweepFailure(
                    f"chunk {i} (members {a}..{b - 1}) failed on the cluster: "
                    f"{type(e).__name__}: {e}"
                ) from e
            try:
                _write_chunk(path, plan, i, result)
            except OSError as e:
                raise files.OutputError(
                    f"cannot write chunk {i} to {str(path)!r}: {e.strerror or e}"
                ) from None
            del futures[f]
            f.release()
            computed += 1
            a, b = plan.member_range(i)
            members_done += b - a
            now = time.perf_counter()
            if first is None:
                first = (now, members_done)
                bar.update(task, description=name)
            elif now > first[0]:
                rate = (members_done - first[1]) / (now - first[0])
                bar.update(task, rate=f"{rate:,.0f} members/s")
            bar.update(task, advance=1)
    finally:
        for f in futures:
            f.cancel()
    return computed, members_done


# --------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------
def _inspect(p: Path, argument: str):
    """`(spec, arrays, done, bad)` of the store at `p`, all its done chunks read back and
    checked (`bad`: {chunk: what is wrong}; None for a store of an older format, which has no
    checksums). SweepError for a path that is not a sweep store, or damaged metadata."""
    if not _is_store(p):
        raise SweepError(f"{argument}: {str(p)!r} is not a gnipy sweep store")
    group, spec = _open_group(p, argument)
    names = _stored_array_names(group, spec)
    if spec["format"] != FORMAT or names is None:
        names = ("chunk_done", "result", "valid", "member", "time")
        arrays = _check_arrays(argument, p, group, names, spec)
        return spec, arrays, None
    arrays = _check_arrays(argument, p, group, names, spec)
    _check_coordinates(argument, p, arrays, spec)
    return spec, arrays, names


def _for_verify(message: str) -> str:
    """A SweepError's message as a report of :func:`verify_sweep` (no argument prefix)."""
    return message.partition(": ")[2].replace(
        "start afresh with overwrite=True",
        "start afresh: run the sweep with overwrite=True (gni sweep --overwrite)",
    )


def verify_sweep(path) -> tuple[bool, str, list[int]]:
    """Check a sweep store without changing it: its metadata, arrays and coordinates, and
    every chunk flagged done (read back, its checksum recomputed).

    Returns:
        `(ok, message, bad_chunks)`: `ok` is True when everything checked is intact (an
        incomplete sweep can be intact: the message says how many chunks are done);
        `message` a sentence naming the store and what is damaged; `bad_chunks` the indices
        of the done chunks that are unreadable or whose data differ from their checksum
        (running the same sweep again recomputes them). Damaged metadata or a missing array
        give `ok = False` and no chunk (start afresh with `overwrite=True`). A store of an
        earlier gnipy (format `gnipy-sweep/1`) has no checksums: `ok = False`, it cannot be
        verified.

    Raises:
        SweepError: `path` is not a gnipy sweep store.
    """
    p = Path(os.fspath(path)).expanduser()
    try:
        spec, arrays, names = _inspect(p, "path")
    except SweepError as e:
        if not _is_store(p):
            raise
        return False, _for_verify(str(e)), []
    if names is None:
        return (False, f"the sweep store {str(p)!r} was written by an earlier gnipy (format "
                f"{spec['format']}) without chunk checksums: its data cannot be verified", [])
    axes = [GridAxis(**g) for g in spec["grid"]]
    members = math.prod(a.count for a in axes)
    chunk = int(spec["chunk_size"])
    try:
        done = _read_done("path", p, arrays, -(-members // chunk))
    except SweepError as e:
        return False, _for_verify(str(e)), []
    bad = _verify_chunks(arrays, names, chunk, members, done)
    n_done = int(done.sum())
    if bad:
        listed = "; ".join(
            f"chunk {i}, {_describe_members(axes, i * chunk, min((i + 1) * chunk, members))}: {why}"
            for i, why in list(bad.items())[:5]
        )
        more = f"; and {len(bad) - 5} more" if len(bad) > 5 else ""
        return (False, f"the sweep store {str(p)!r} is damaged: {len(bad)} of its {n_done} done "
                f"chunk(s) cannot be trusted ({listed}{more}); run the same sweep again to "
                "compute them again", sorted(bad))
    state = ("complete" if n_done == done.size else
             f"incomplete: {n_done} of {done.size} chunks done (run the same sweep again to resume)")
    return True, (f"the sweep store {str(p)!r} is intact: {n_done} done chunk(s) read back and "
                  f"their checksums match; {state}"), []


def open_sweep(path, *, allow_incomplete: bool = False, verify: bool = True):
    """Open a sweep store as an `xarray.Dataset` with the grid axes as dimensions.

    The flat `member` dimension is reshaped to the grid's dimensions (named after the
    grid axes, e.g. `m`, `q0.x`, in the order of the grid), whose coordinates are the
    grid values: e.g. `q(m, Omega, time, coordinate)`. The data are loaded lazily
    (dask).

    Arguments:
        path: the store written by :func:`run_sweep` (or `gni sweep`).
        allow_incomplete: open a sweep whose chunks are not all done: the members of the
            chunks not done (and, with `verify`, of damaged chunks, with a
            :class:`SweepWarning`) get `valid = False` and `result = -1` (their other data
            are not meaningful).
        verify: first read every done chunk back and compare its checksum (see
            :func:`verify_sweep`; this reads the whole store once). Stores of an earlier
            gnipy have no checksums and are not verified.

    Raises:
        SweepError: not a sweep store, damaged metadata or arrays, (with `verify`) a
            damaged chunk, or (without `allow_incomplete`) an incomplete sweep.
    """
    import xarray as xr

    from .io import upgrade_layout

    p = Path(os.fspath(path)).expanduser()
    spec, arrays, names = _inspect(p, "path")
    axes = [GridAxis(**g) for g in spec["grid"]]
    shape = tuple(a.count for a in axes)
    members = math.prod(shape)
    chunk = int(spec["chunk_size"])
    done = _read_done("path", p, arrays, -(-members // chunk))
    if verify and names is not None:
        bad = _verify_chunks(arrays, names, chunk, members, done)
        if bad and not allow_incomplete:
            listed = "; ".join(
                f"chunk {i}, {_describe_members(axes, i * chunk, min((i + 1) * chunk, members))}: "
                f"{why}" for i, why in list(bad.items())[:5]
            )
            raise SweepError(
                f"path: the sweep store {str(p)!r} is damaged: {len(bad)} done chunk(s) "
                f"cannot be trusted ({listed}); run the same sweep again to compute them "
                "again, or pass allow_incomplete=True to open the rest"
            )
        for i, why in bad.items():
            warnings.warn(SweepWarning(
                f"path: chunk {i} of {str(p)!r}, "
                f"{_describe_members(axes, i * chunk, min((i + 1) * chunk, members))}, is "
                f"damaged ({why}): its members are marked not done"), stacklevel=2)
            done[i] = False
    with warnings.catch_warnings():
        # zarr lists the store's marker file as "not a component of a Zarr hierarchy"
        warnings.filterwarnings("ignore", message=f".*{re.escape(files.MARKER)}.*")
        ds = xr.open_zarr(str(p), consolidated=False)
    ds = upgrade_layout(ds)  # stores with `t(time)` too
    if not done.all():
        if not allow_incomplete:
            raise SweepError(
                f"path: the sweep in {str(p)!r} is incomplete ({int(done.sum())} of "
                f"{done.size} chunks done); run it again to resume, or pass "
                "allow_incomplete=True"
            )
        member_done = xr.DataArray(
            np.repeat(done, chunk)[: ds.sizes["member"]], dims=("member",)
        )
        ds["valid"] = ds["valid"] & member_done
        ds["result"] = ds["result"].where(member_done, -1)
    dims = tuple(a.name for a in axes)
    out = {}
    order = [*_MEMBER_VARS, *_CHUNK_VARS]
    for name in sorted(
        ds.data_vars, key=lambda k: order.index(k) if k in order else len(order)
    ):
        var = ds[name].variable
        if name.startswith("grid_"):
            continue
        if var.dims[:1] == ("member",):
            data = var.data.reshape(shape + var.shape[1:])
            out[name] = xr.Variable(dims + var.dims[1:], data, var.attrs)
        else:
            out[name] = var
    coords = {a.name: (a.name, a.values) for a in axes}
    coords.update({k: ds.coords[k] for k in ds.coords if k not in ("member",)})
    result = xr.Dataset(out, coords=coords, attrs=ds.attrs)
    for a in axes:
        result[a.name].attrs["long_name"] = f"grid axis {a.name}"
    return result
