"""Parameter sweeps: grids of runs in vmapped chunks on dask.distributed, to zarr.

A sweep runs one model with one method over the Cartesian product of a few *grid axes*,
each `NAME=START:STOP:COUNT` (values `numpy.linspace(START, STOP, COUNT)`). NAME is a
model parameter (`m`, `Omega`, ...) or a component of the initial condition:
`q0.<coordinate>` (e.g. `q0.x`) or `v0.<velocity>` (e.g. `v0.omega3`). The members (grid
points) are numbered in C order: the last axis varies fastest.

**How it runs.** The members are cut into chunks of `chunk_size`; each chunk is one task
on the cluster, :func:`run_chunk`, which runs the whole chunk as one vmapped program
(:func:`gnipy.simulate` with a batch of systems and initial conditions, `throw=False`).
Every chunk has the same size, so each worker compiles once and reuses the program for
all its other chunks: the last, shorter chunk is *padded on input* by repeating its last
member, and the extra members are dropped before anything is written (no padding ever
reaches the store). The driver writes each chunk to the zarr store as soon as it
arrives.

**The store** (a zarr directory, written through xarray) is created up front at full
size, with zarr chunks aligned to `chunk_size` along `member`. Its coordinate `time` holds
the saved times (CF attributes, `units = "s"`), with `node(time)` (the saved-node index)
and `step(time)` (the step index) beside it; it holds `q(member, time, coordinate)`,
`v` and `p(member, time, velocity)`, `energy(member, time)`, `constraint_residual(member,
time, constraint)`, `R(member, time, i, j)` on Rⁿ × G, `result(member)` (0: ok, 1: a
step failed), `failed_step(member)` (or -1), `valid(member, time)` (False after a
member's failed step), `grid_<NAME>(member)` (each member's grid values) and
`chunk_done(chunk)`. The attributes hold the sweep's specification as JSON (`sweep_spec`:
model, method, h, steps, save_every, grid, fixed parameters, chunk size, gnipy version)
and the same fields one by one for reading, the CF attributes (`Conventions`, `title`,
`source`, `history`) and, on Rⁿ × G, `orientation` (how R is reconstructed,
:attr:`gnipy.System.orientation_description`).

**Resuming.** For each chunk, the data are written first and its `chunk_done` flag last,
so an interrupted sweep (killed, out of time, Ctrl-C) leaves at worst one chunk whose
data were written and whose flag was not. Running the same sweep again on the same store
checks that the specification is the same (else :class:`SweepError` names the field that
differs), skips the chunks whose flag is set and computes the others. The store is
created in a temporary directory beside its destination and renamed into place, so a
store either exists with all its arrays or not at all; chunks not yet done read as NaN
(floats) and `valid = False`, and :func:`open_sweep` refuses a store whose chunks are
not all done unless asked.

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
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .system import SystemError

__all__ = [
    "GridAxis",
    "SweepError",
    "SweepFailure",
    "SweepReport",
    "parse_grid",
    "run_sweep",
    "open_sweep",
    "run_chunk",
]

#: The format tag stored in the `sweep_spec` attribute (and compared on resume).
FORMAT = "gnipy-sweep/1"

_MAX_ZARR_CHUNK_BYTES = 64 * 2**20
_MAX_PREFLIGHT = 64


class SweepError(SystemError):
    """Bad sweep input, or a store that does not hold the requested sweep.

    The message starts with the argument it is about (`grid: ...`, `out: ...`,
    `chunk_size: ...`). A subclass of :class:`gnipy.SystemError`.
    """


class SweepFailure(RuntimeError):
    """A chunk of a sweep failed on the cluster for a reason other than bad input (a
    worker died, a store write failed, ...). The chunks already done stay done: run the
    sweep again to resume."""


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
        count: the number of values (a positive integer; 1 gives `start` only).
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

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.count for a in self.axes)

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
) -> _Plan:
    """Validate a sweep's input and work out its specification (or raise SweepError,
    SystemError or MethodError)."""
    from . import __version__
    from .methods import method_names
    from .models import get_model
    from .models.registry import default_method_for

    if method is None:  # the model's measured default
        method = default_method_for(str(model))
    from .simulate import resolve_steps

    if not isinstance(model, str):
        raise SweepError(f"model: expected a model name, got {model!r}")
    spec = get_model(model)  # SystemError "model: unknown model ..."
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
    except SystemError as e:
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
    n_blocks, remainder = divmod(steps, save_every)
    k_saved = np.concatenate(
        [np.arange(n_blocks + 1) * save_every, [steps] if remainder else []]
    )
    times = h * k_saved.astype(np.float64)
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
    k = system.group.matrix_size if system.group is not None else None
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
    except SystemError as e:
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
        constraint_residual, valid, result, failed_step`, and `R` on Rⁿ × G.

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
    except SystemError:
        # name the member at fault: check them one by one (only on this error path)
        for i in range(B):
            s = systems[i] if isinstance(systems, list) else systems
            _check_member(s, job, columns, i, first + min(i, size - 1), q0, v0, R0)
        raise
    out = {
        "q": sol.q,
        "v": sol.v,
        "p": sol.p,
        "energy": sol.energy,
        "constraint_residual": sol.constraint_residual,
        "valid": sol.valid,
        "result": sol.results,
        "failed_step": sol.failed_steps,
    }
    if sol.R is not None:
        out["R"] = sol.R
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
}


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
        {"long_name": "True once the chunk's data are written (written last)"},
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


def _stored_spec(path: Path) -> dict[str, Any] | None:
    attrs = _read_attrs(path)
    if attrs is None or "sweep_spec" not in attrs:
        return None
    try:
        spec = json.loads(attrs["sweep_spec"])
    except (TypeError, ValueError):
        return None
    return spec if isinstance(spec, dict) and spec.get("format") == FORMAT else None


def _read_done(path: Path, chunks: int) -> np.ndarray:
    import zarr

    try:
        done = np.asarray(
            zarr.open_group(str(path), mode="r")["chunk_done"][:], dtype=bool
        )
    except Exception as e:  # noqa: BLE001
        raise SweepError(
            f"out: cannot read the chunk flags of {str(path)!r} ({e}); start afresh "
            "with overwrite=True"
        ) from None
    if done.shape != (chunks,):
        raise SweepError(
            f"out: the store {str(path)!r} is damaged (chunk_done has shape "
            f"{done.shape}, expected ({chunks},)); start afresh with overwrite=True"
        )
    return done


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


def _check_out(out) -> Path:
    if not isinstance(out, (str, os.PathLike)) or not str(out):
        raise SweepError(f"out: expected a path to a directory DIR.zarr, got {out!r}")
    path = Path(out).expanduser()
    parent = path.parent if str(path.parent) else Path(".")
    if path.exists() and not path.is_dir():
        raise SweepError(
            f"out: {str(path)!r} exists and is not a directory (a sweep store is a "
            "directory)"
        )
    if not parent.is_dir():
        raise SweepError(
            f"out: cannot create {str(path)!r}: directory {str(parent)!r} does not "
            "exist"
        )
    if not os.access(parent, os.W_OK | os.X_OK):
        raise SweepError(
            f"out: cannot create {str(path)!r}: directory {str(parent)!r} is not "
            "writable"
        )
    if path.is_dir() and not os.access(path, os.W_OK | os.X_OK):
        raise SweepError(f"out: {str(path)!r} is not writable")
    return path


def _create_store(path: Path, plan: _Plan) -> None:
    """Write the store's metadata and the per-member grid values into a temporary
    directory beside `path`, then rename it into place (replacing an old store or an
    empty directory there)."""
    from .io import OutputError

    tmp = path.parent / f".{path.name}.{uuid.uuid4().hex}.partial"
    old = None
    try:
        _template(plan).to_zarr(str(tmp), mode="w", compute=False, consolidated=False)
        if path.exists():
            old = path.parent / f".{path.name}.{uuid.uuid4().hex}.old"
            os.rename(path, old)
        os.rename(tmp, path)
    except OSError as e:
        raise OutputError(f"cannot create {str(path)!r}: {e.strerror or e}") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)


def _write_chunk(
    path: Path, plan: _Plan, index: int, result: Mapping[str, np.ndarray]
) -> None:
    """Write one chunk's data, then (last) its `chunk_done` flag."""
    import xarray as xr

    a, b = plan.member_range(index)
    data = {}
    for name, arr in result.items():
        dims, _, _ = _MEMBER_VARS[name]
        arr = np.asarray(arr)
        if arr.shape[0] != b - a:
            raise SweepFailure(
                f"chunk {index}: the task returned {arr.shape[0]} members for {name}, "
                f"expected {b - a}"
            )
        data[name] = (("member", *dims), arr)
    xr.Dataset(data).to_zarr(
        str(path), region={"member": slice(a, b)}, consolidated=False
    )
    flag = xr.Dataset({"chunk_done": (("chunk",), np.ones(1, dtype=bool))})
    flag.to_zarr(
        str(path), region={"chunk": slice(index, index + 1)}, consolidated=False
    )


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
        chunks_skipped: chunks found done in the store and not recomputed.
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


class _Cluster:
    """The client to use: the caller's, one connected to `scheduler`, or a new local
    cluster."""

    def __init__(self, client, scheduler, workers):
        self.given, self.scheduler, self.workers = client, scheduler, workers
        self.client = self.cluster = None

    def __enter__(self):
        import logging

        from distributed import Client, LocalCluster

        if self.given is not None:
            self.client = self.given
            return self.client
        if self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout=20, set_as_default=False)
            except (OSError, ValueError, TypeError) as e:
                raise SweepError(
                    f"scheduler: cannot connect to {self.scheduler!r}: {e}"
                ) from None
            return self.client
        try:
            self.cluster = LocalCluster(
                n_workers=self.workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                silence_logs=logging.ERROR,
            )
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
        scheduler: the address of an existing cluster's scheduler (e.g.
            `"tcp://host:8786"`); its workers need gnipy installed.
        workers: the size of the local cluster started when neither `scheduler` nor
            `client` is given (one single-threaded worker process each; default: the
            number of cores).
        client: an existing `distributed.Client` to use (it is not closed).
        overwrite: delete an existing store at `out` (only a gnipy sweep store) and
            start afresh.
        max_chunks: compute at most this many chunks and stop (the store stays
            resumable): for runs under a time limit, and to test resumption.
        progress: show a progress bar (chunks done, members/s) on stderr when it is a
            terminal.

    Returns:
        A :class:`SweepReport`.

    Running the same sweep again on an existing store resumes it: the chunks already
    done are skipped. If the store holds a different sweep, :class:`SweepError` names
    the field that differs.

    Raises:
        SweepError: bad input (the message starts with the argument: `grid:`, `out:`,
            ...), or a member whose parameters or initial condition are not acceptable.
        gnipy.SystemError: bad `h`, `steps`, `t_final` or model name.
        gnipy.MethodError: a method that cannot integrate this model.
        gnipy.io.OutputError: the store cannot be created.
        SweepFailure: a chunk failed on the cluster (e.g. a worker died).
    """
    t_start = time.perf_counter()
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
    )
    if scheduler is not None and not isinstance(scheduler, str):
        raise SweepError(
            "scheduler: expected an address such as 'tcp://host:8786', got "
            f"{scheduler!r}"
        )
    if scheduler is not None and client is not None:
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
    path = _check_out(out)

    stored = _stored_spec(path) if path.is_dir() else None
    if path.is_dir() and stored is None and any(path.iterdir()):
        raise SweepError(
            f"out: {str(path)!r} exists and is not a gnipy sweep store; choose another "
            "output path"
        )
    if stored is not None and not overwrite:
        _compare_specs(path, stored, plan.spec)
        done = _read_done(path, plan.chunks)
    else:
        _create_store(path, plan)
        done = np.zeros(plan.chunks, dtype=bool)

    todo = [int(i) for i in np.flatnonzero(~done)]
    skipped = plan.chunks - len(todo)
    if max_chunks is not None:
        todo = todo[:max_chunks]
    computed = members = 0
    if todo:
        computed, members = _compute(
            path, plan, todo, client, scheduler, workers or _default_workers(), progress
        )
    done = _read_done(path, plan.chunks)
    failed = _count_failed(path, plan, done)
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
    )


def _count_failed(path: Path, plan: _Plan, done: np.ndarray) -> int:
    import zarr

    result = np.asarray(zarr.open_group(str(path), mode="r")["result"][:])
    member_done = np.repeat(done, plan.chunk)[: plan.members]
    return int(np.sum((result != 0) & member_done))


def _compute(path, plan, todo, client, scheduler, workers, progress) -> tuple[int, int]:
    """Submit the chunks `todo`, write each as it completes; returns `(chunks, members)`
    computed."""
    from distributed import as_completed

    from .integrators.base import MethodError
    from .io import OutputError

    computed = members_done = 0
    name = f"sweep {plan.spec['model']}"
    with _progress_bar(progress) as bar:
        task = bar.add_task(f"{name}: starting the cluster", total=len(todo), rate="")
        with _Cluster(client, scheduler, workers) as c:
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
                    except (SystemError, MethodError):
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
                        raise OutputError(
                            f"cannot write chunk {i} to {str(path)!r}: "
                            f"{e.strerror or e}"
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
def open_sweep(path, *, allow_incomplete: bool = False):
    """Open a sweep store as an `xarray.Dataset` with the grid axes as dimensions.

    The flat `member` dimension is reshaped to the grid's dimensions (named after the
    grid axes, e.g. `m`, `q0.x`, in the order of the grid), whose coordinates are the
    grid values: e.g. `q(m, Omega, time, coordinate)`. The data are loaded lazily
    (dask).

    Arguments:
        path: the store written by :func:`run_sweep` (or `gni sweep`).
        allow_incomplete: open a sweep whose chunks are not all done: the members of the
            chunks not done get `valid = False` and `result = -1` (their other data are
            not meaningful).

    Raises:
        SweepError: not a sweep store, or (without `allow_incomplete`) an incomplete
            one.
    """
    import xarray as xr

    from .io import upgrade_layout

    p = Path(path).expanduser()
    spec = _stored_spec(p) if p.is_dir() else None
    if spec is None:
        raise SweepError(f"path: {str(p)!r} is not a gnipy sweep store")
    ds = upgrade_layout(xr.open_zarr(str(p), consolidated=False))  # stores with `t(time)` too
    axes = [GridAxis(**g) for g in spec["grid"]]
    shape = tuple(a.count for a in axes)
    done = np.asarray(ds["chunk_done"].values, dtype=bool)
    if not done.all():
        if not allow_incomplete:
            raise SweepError(
                f"path: the sweep in {str(p)!r} is incomplete ({int(done.sum())} of "
                f"{done.size} chunks done); run it again to resume, or pass "
                "allow_incomplete=True"
            )
        member_done = xr.DataArray(
            np.repeat(done, spec["chunk_size"])[: ds.sizes["member"]], dims=("member",)
        )
        ds["valid"] = ds["valid"] & member_done
        ds["result"] = ds["result"].where(member_done, -1)
    dims = tuple(a.name for a in axes)
    out = {}
    order = [*_MEMBER_VARS, "chunk_done"]
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
