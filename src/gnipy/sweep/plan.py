"""The plan of a sweep: its input validated, its specification (what the store records and a
resume compares), its size checked before anything of that size is allocated."""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .. import schema
from ..errors import InputError
from ..inputs import positive_integer
from ..files import format_bytes, free_bytes
from .errors import SweepError
from .grid import ChunkLayout, GridAxis, as_axes, grid_columns
from .task import check_member, member_inputs

__all__ = ["FORMAT", "OLD_FORMATS", "DEFAULT_MAX_BYTES", "MEMBER_VARS", "Plan", "make_plan",
           "saved_steps", "positive_int"]

#: The format tag stored in the `sweep_spec` attribute (and compared on resume). Stores of the
#: earlier formats (`gnipy-sweep/1`, before checksums; `gnipy-sweep/2`, a flat `member` axis;
#: `gnipy-sweep/3`, before the members' verdicts; `gnipy-sweep/4`, dimensions named as the grid,
#: `q0.x` where they are now `q0_x`) are recognised as gnipy's (and may be replaced), not read or
#: resumed.
FORMAT = "gnipy-sweep/5"
OLD_FORMATS = ("gnipy-sweep/1", "gnipy-sweep/2", "gnipy-sweep/3", "gnipy-sweep/4")

#: The default bound on a store's estimated size, in bytes (`run_sweep(max_bytes=...)`): 100 GiB.
DEFAULT_MAX_BYTES = 100 * 2**30

#: The per-member variables of a store (`R` on Rⁿ × G only), as :mod:`gnipy.schema` states them.
MEMBER_VARS = ("q", "v", "p", "energy", "constraint_residual", "R", "valid", "result", "failed_step",
               "failed_time", "failed_residual", "native", "healthy", "hidden_momentum_first_time",
               "hidden_momentum_max_band_ratio", "energy_drift_first_time", "energy_drift_max")

# the names a grid axis cannot take: the store's variables and dimensions
_RESERVED = frozenset({*schema.VARIABLES, "i", "j", "digest"})
_MAX_PREFLIGHT = 64


@dataclasses.dataclass(frozen=True)
class Plan:
    """A validated sweep: its specification and what follows from it."""

    spec: dict[str, Any]  # the JSON specification, stored in the store and compared on resume
    axes: tuple[GridAxis, ...]
    layout: ChunkLayout
    times: np.ndarray
    coordinates: tuple[str, ...]
    velocities: tuple[str, ...]
    constraints: int
    matrix_size: int | None  # k of R (k, k), None on R^n
    orientation: str = ""  # the attribute `orientation` (on R^n x G)
    store_bytes: int = 0  # the store's estimated size (uncompressed)

    @property
    def members(self) -> int:
        return self.layout.members

    @property
    def chunk(self) -> int:
        """Members per (full) chunk."""
        return self.layout.size

    @property
    def chunks(self) -> int:
        return self.layout.chunks

    @property
    def member_vars(self) -> tuple[str, ...]:
        """The per-member variables of the store (R on Rⁿ × G only)."""
        return tuple(k for k in MEMBER_VARS if k != "R" or self.matrix_size is not None)

    def member_range(self, index: int) -> tuple[int, int]:
        return self.layout.member_range(index)

    def columns(self, index: int) -> dict[str, np.ndarray]:
        """The grid values of the chunk's members, padded to the chunk size by repeating the last."""
        a, b = self.member_range(index)
        idx = np.arange(a, b)
        if b - a < self.chunk:
            idx = np.concatenate([idx, np.full(self.chunk - (b - a), b - 1)])
        return grid_columns(self.axes, idx)


def positive_int(argument: str, value) -> int:
    """`value` as an int of at least 1, or a SweepError naming `argument` (:func:`gnipy.inputs.positive_integer`)."""
    return positive_integer(argument, value, SweepError)


def saved_steps(steps: int, save_every: int) -> np.ndarray:
    """The step index of each saved node: 0, K, 2K, ... and the last."""
    n_blocks, remainder = divmod(steps, save_every)
    return np.concatenate([np.arange(n_blocks + 1) * save_every, [steps] if remainder else []]).astype(np.int64)


def _memory_total() -> int | None:
    """This machine's physical memory in bytes (None if unknown)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def check_size(axes, *, layout: ChunkLayout, saved, node_bytes, member_bytes, max_bytes, disk) -> int:
    """Refuse a sweep too large for the bound `max_bytes` (None: no bound), for the free
    space of `disk` (a directory; None: not checked) or for this machine's memory; return the
    store's estimated size. Pure arithmetic: nothing is allocated."""
    grid = " ".join(str(a) for a in axes)
    members, chunk = layout.members, layout.size
    store = members * (saved * node_bytes + member_bytes) + layout.chunks * 33
    what = (f"grid: {grid} gives {members:,} member(s) x {saved:,} saved node(s): the store "
            f"would hold about {format_bytes(store)} ({node_bytes} bytes per member and node, "
            "uncompressed)")
    if max_bytes is not None and store > max_bytes:
        raise SweepError(
            f"{what}, more than the bound max_bytes = {format_bytes(max_bytes)}; sweep a "
            "coarser grid or save fewer nodes (a larger save_every), or pass max_bytes=None to go ahead"
        )
    memory = _memory_total()
    if memory:
        # the members' results and flags, read back on the driver at the end of a run
        driver = members * 16
        if 4 * driver > memory:
            raise SweepError(
                f"grid: {grid} gives {members:,} members: reading their results back alone takes "
                f"about {format_bytes(driver)} of memory, more than a quarter of this machine's "
                f"{format_bytes(memory)}; sweep a coarser grid"
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
        free = free_bytes(disk)
        if free is not None and store > free:
            raise SweepError(
                f"out: {what.partition(': ')[2]}, and only {format_bytes(free)} are free "
                f"in {str(disk)!r}; free some space or write the store elsewhere"
            )
    return store


def make_plan(model, grid, *, method, h, steps, t_final, save_every, set_params, project_v0, chunk_size,
              max_bytes=None, disk: Path | None = None) -> Plan:
    """Validate a sweep's input and work out its specification (or raise SweepError,
    InputError or MethodError). The sizes are checked (:func:`check_size`, with `max_bytes` and
    `disk`) before anything of the sweep's size is allocated."""
    from ..version import __version__
    from ..simulate import resolve_steps

    spec, method = _model_and_method(model, method)
    h, steps = resolve_steps(h, steps, t_final)
    save_every = min(steps if save_every is None else positive_int("save_every", save_every), steps)
    chunk_size = positive_int("chunk_size", chunk_size)
    axes = as_axes(grid)
    set_params = dict(set_params or {})
    try:
        params = spec.resolve_params(set_params)
    except InputError as e:
        raise SweepError(f"set_params: {str(e).partition(':')[2].strip()}") from None
    system = spec.build(params)
    coordinates, velocities = tuple(spec.coordinates), tuple(system.velocities)
    _check_axes(axes, spec, set_params, [f"q0.{c}" for c in coordinates] + [f"v0.{v}" for v in velocities])
    swept = {a.name for a in axes}
    layout = ChunkLayout.of([a.count for a in axes], chunk_size)
    k = system.group.matrix_size if system.group is not None else None
    n, N = len(coordinates), len(velocities)
    saved = len(saved_steps(steps, save_every))
    # bytes per member and saved node: q, v, p, energy, constraint_residual (at most N
    # constraints), R, valid; per member: result, failed_step, failed_time, failed_residual, the
    # backend and the verdicts (healthy, two first times, two maxima)
    node_bytes = 8 * (n + 2 * N + 1 + N + (k or 0) ** 2) + 1
    store_bytes = check_size(axes, layout=layout, saved=saved, node_bytes=node_bytes, member_bytes=58,
                             max_bytes=max_bytes, disk=disk)
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
        "chunk_size": layout.size,
        "gnipy_version": __version__,
    }
    if spec.origin is not None:  # a user's system: the SHA-256 of its source (the workers check it)
        sweep_spec["model_source"] = spec.origin[1]
    m, orientation = _preflight(sweep_spec, axes)
    times = h * saved_steps(steps, save_every).astype(np.float64)
    return Plan(sweep_spec, tuple(axes), layout, times, coordinates, velocities, m, k, orientation, store_bytes)


def _model_and_method(model, method) -> tuple[Any, str]:
    """The model's spec and the method's name (None: the model's measured default), checked."""
    from ..methods import is_method_name, method_names
    from ..models import get_model
    from ..registry import default_method_for

    if not isinstance(model, str):
        raise SweepError(f"model: expected a model name or a reference FILE.py:NAME, got {model!r}")
    spec = get_model(model)  # InputError "model: unknown model ..."
    if method is None:  # the model's measured default
        method = default_method_for(model)
    if not is_method_name(method):
        raise SweepError(f"method: unknown method {method!r} (known: {', '.join(method_names())})")
    if method == "reference":
        raise SweepError("method: the continuous reference runs one trajectory at a time; it cannot be swept")
    return spec, method


def _check_axes(axes, spec, set_params: dict, ic_names: list[str]) -> None:
    """Refuse a grid axis that is also fixed in `set_params`, names neither a parameter of the
    model nor an initial condition (`ic_names`), or names a variable or dimension of the store."""
    for a in axes:
        if a.name in set_params:
            raise SweepError(f"grid: {a.name!r} is both swept (grid) and fixed (set_params)")
        if a.name not in spec.params and a.name not in ic_names:
            known = ", ".join([*spec.params, *ic_names]) or "none"
            raise SweepError(f"grid: unknown name {a.name!r} for model {spec.name!r} (known: {known})")
        if a.name in _RESERVED or a.dim in _RESERVED:
            raise SweepError(f"grid: {a.name!r} cannot be swept: the sweep store has a variable or "
                             "dimension of that name")


def layout_of(spec) -> ChunkLayout:
    """The chunk layout of a sweep's specification."""
    return ChunkLayout.of([int(g["count"]) for g in spec["grid"]], int(spec["chunk_size"]))


def _preflight(sweep_spec, axes) -> tuple[int, str]:
    """Check the corner members of the grid on the driver (fast, before any cluster
    starts); return the number of constraints and the attribute `orientation` (from the
    corner members' systems)."""
    from ..methods import get_method
    from ..system import describe_orientations

    shape = tuple(a.count for a in axes)
    corners = sorted({
        int(np.ravel_multi_index(c, shape))
        for c in itertools.islice(itertools.product(*[(0, n - 1) for n in shape]), _MAX_PREFLIGHT)
    })
    idx = np.asarray(corners)
    columns = grid_columns(axes, idx)
    systems, q0, v0, R0 = member_inputs(sweep_spec, columns, len(idx))
    method = get_method(sweep_spec["method"])
    m = 0
    for i in range(len(idx)):
        s = systems[i] if isinstance(systems, list) else systems
        b0 = check_member(s, sweep_spec, columns, i, int(idx[i]), q0, v0, R0)
        method.validate(s, b0)
        m = s.num_constraints(b0)
    if isinstance(systems, list) and len(systems) > 1:
        _check_batchable(systems, sweep_spec["model"])
    return m, describe_orientations(systems if isinstance(systems, list) else [systems])


def _check_batchable(systems, model: str) -> None:
    """The members' systems run as one batch (their parameters are array leaves), else a SweepError
    that says how to write the model so that they do."""
    from ..ensembles import stack_systems

    try:
        stack_systems(systems)
    except InputError as e:
        why = str(e).partition(", but ")[2].partition(". Build")[0] or str(e)
        raise SweepError(
            f"grid: the members of {model!r} for different parameter values cannot run as one batch ({why}). "
            "Write its functions once, at module level, taking the parameters as their last argument, and "
            "return gnipy.System(l, mu, ..., args=dict(m=m, ...)): then l(q, v, args) reads args['m'] and "
            "the members differ only in arrays (see the user guide, 'Parameters as arguments')"
        ) from None


def members_of(spec) -> int:
    """The number of members of a sweep's specification."""
    return math.prod(int(g["count"]) for g in spec["grid"])
