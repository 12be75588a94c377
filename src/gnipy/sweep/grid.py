"""The grid of a sweep: its axes (`NAME=linspace(START, STOP, COUNT)`, or `NAME=START:STOP:COUNT`),
its members, and how it is cut into chunks.

The members are the points of the Cartesian product of the axes, numbered in C order (the last
axis varies fastest). A chunk is a block of the grid, :class:`ChunkLayout`: the last axes whole
as far as `chunk_size` allows, so that its members are consecutive in that numbering and it is
one zarr chunk of every per-member array of the store.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .errors import SweepError

__all__ = ["MAX_COUNT", "GridAxis", "ChunkLayout", "parse_grid"]

#: The most values one grid axis may have.
MAX_COUNT = 10**9

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
                f"grid: {name!r} is not a valid name (a parameter, q0.<coordinate> or v0.<velocity>)"
            )
        for what in ("start", "stop"):
            x = getattr(self, what)
            if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
                raise SweepError(f"grid: {name}: {what.upper()} must be a number, got {x!r}")
            if not math.isfinite(float(x)):
                raise SweepError(f"grid: {name}: {what.upper()} must be finite, got {x!r}")
            object.__setattr__(self, what, float(x))
        c = self.count
        if isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1:
            raise SweepError(f"grid: {name}: COUNT must be a positive integer, got {c!r}")
        if c > MAX_COUNT:
            raise SweepError(f"grid: {name}: COUNT must be at most {MAX_COUNT:,}, got {c!r}")
        object.__setattr__(self, "count", int(c))

    @property
    def dim(self) -> str:
        """The axis's dimension in the store and the Dataset: `name` with `.` written `_` (`q0.x` ->
        `q0_x`), a Python identifier, so that `ds.sel(q0_x=0.5)` and `ds.q0_x` work."""
        return self.name.replace(".", "_")

    @property
    def values(self) -> np.ndarray:
        """The grid values, `numpy.linspace(start, stop, count)`."""
        return np.linspace(self.start, self.stop, self.count)

    def to_dict(self) -> dict[str, Any]:
        """`{"name", "start", "stop", "count"}` (JSON-ready)."""
        return {"name": self.name, "start": self.start, "stop": self.stop, "count": self.count}

    def __str__(self) -> str:
        return f"{self.name}={self.start!r}:{self.stop!r}:{self.count}"


#: What the colon form means, said where it may have been read as a slice or START:STEP:STOP.
_COLON_FORM = ("NAME=START:STOP:COUNT is numpy.linspace(START, STOP, COUNT), not a slice or START:STEP:STOP; "
               "NAME=linspace(START, STOP, COUNT) says the same unambiguously")
_LINSPACE_RE = re.compile(r"^linspace\((?P<args>[^()]*)\)$")


def parse_grid(text: str) -> GridAxis:
    """Parse `NAME=linspace(START, STOP, COUNT)` or its short form `NAME=START:STOP:COUNT` (the
    same values, `numpy.linspace(START, STOP, COUNT)`; e.g. `"m=linspace(0.5, 2, 4)"`,
    `"q0.x=-1:1:5"`) into a :class:`GridAxis`.

    The short form reads like a slice or START:STEP:STOP; where it was probably meant so (a COUNT
    that is not a whole number, or COUNT = 1 with STOP different from START, which linspace
    ignores), the error says what it means instead.

    Raises:
        SweepError: a message starting `grid:` that quotes the text and says what is
            wrong.
    """
    expected = "expected NAME=linspace(START, STOP, COUNT) or NAME=START:STOP:COUNT (e.g. m=linspace(0.5, 2, 4))"
    if not isinstance(text, str):
        raise SweepError(f"grid: {expected}, got {text!r}")
    name, eq, rest = text.partition("=")
    name, rest = name.strip(), rest.strip()
    call = _LINSPACE_RE.match(rest)
    parts = [s.strip() for s in (call.group("args").split(",") if call else rest.split(":"))]
    if not eq or not name or len(parts) != 3 or not all(parts):
        raise SweepError(f"grid: {expected}, got {text!r}")
    hint = "" if call else f" ({_COLON_FORM})"
    values = []
    for what, s in zip(("START", "STOP"), parts[:2]):
        try:
            x = float(s)
        except ValueError:
            raise SweepError(f"grid: {name}: {what} must be a number, got {s!r} in {text!r}") from None
        if not math.isfinite(x):
            raise SweepError(f"grid: {name}: {what} must be finite, got {s!r} in {text!r}")
        values.append(x)
    try:
        count = int(parts[2])
    except ValueError:
        raise SweepError(
            f"grid: {name}: COUNT must be a positive integer, got {parts[2]!r} in {text!r}{hint}"
        ) from None
    if count < 1:
        raise SweepError(f"grid: {name}: COUNT must be a positive integer, got {parts[2]!r} in {text!r}{hint}")
    if count > MAX_COUNT:
        raise SweepError(f"grid: {name}: COUNT must be at most {MAX_COUNT:,}, got {parts[2]!r} in {text!r}")
    if not call and count == 1 and values[0] != values[1]:
        raise SweepError(f"grid: {name}: COUNT = 1 gives START only, and STOP differs, in {text!r} ({_COLON_FORM}; "
                         f"one value: {name}={parts[0]}:{parts[0]}:1)")
    return GridAxis(name, values[0], values[1], count)


def as_axes(grid) -> list[GridAxis]:
    """The grid axes of `grid` (strings, GridAxis objects or `{name: (start, stop, count)}`),
    checked: at least one, no name twice."""
    if isinstance(grid, (str, GridAxis)):
        grid = [grid]
    if isinstance(grid, Mapping):
        items = []
        for name, value in grid.items():
            try:
                start, stop, count = value
            except (TypeError, ValueError):
                raise SweepError(f"grid: {name}: expected (start, stop, count), got {value!r}") from None
            items.append(GridAxis(str(name), start, stop, count))
        grid = items
    if not isinstance(grid, Sequence):
        raise SweepError(
            f"grid: expected a sequence of NAME=START:STOP:COUNT strings or GridAxis, got {grid!r}"
        )
    axes = [g if isinstance(g, GridAxis) else parse_grid(g) for g in grid]
    if not axes:
        raise SweepError("grid: give at least one grid axis NAME=START:STOP:COUNT")
    seen = {}
    for a in axes:
        if a.name in seen:
            raise SweepError(f"grid: {a.name!r} is given twice")
        if a.dim in seen.values():
            other = next(k for k, d in seen.items() if d == a.dim)
            raise SweepError(f"grid: {a.name!r} and {other!r} would both be the store's dimension {a.dim!r}")
        seen[a.name] = a.dim
    return axes


def axes_of(spec: Mapping[str, Any]) -> list[GridAxis]:
    """The grid axes of a sweep's specification (its `grid` entry)."""
    return [GridAxis(**g) for g in spec["grid"]]


def grid_columns(axes, members: np.ndarray) -> dict[str, np.ndarray]:
    """Each axis's value for the members `members` (flat indices, C order): name -> array."""
    unravelled = np.unravel_index(members, tuple(a.count for a in axes))
    return {a.name: a.values[i] for a, i in zip(axes, unravelled)}


def describe_member(columns, i) -> str:
    """`m=1.5, q0.x=-1`: the grid values of the member at row `i` of `columns`."""
    return ", ".join(f"{k}={float(v[i]):.6g}" for k, v in columns.items())


def describe_members(axes, a: int, b: int) -> str:
    """`member 6 (m=1.5, q0.x=-1)` or `members 6..7 (m=1.5, q0.x=-1 .. m=1.5, q0.x=1)`."""
    cols = grid_columns(axes, np.array([a, b - 1]))
    first, last = describe_member(cols, 0), describe_member(cols, 1)
    if b - a == 1:
        return f"member {a} ({first})"
    return f"members {a}..{b - 1} ({first} .. {last})"


@dataclasses.dataclass(frozen=True)
class ChunkLayout:
    """How a grid of shape `shape` is cut into chunks, blocks of shape `block`.

    The block takes the last axes whole as long as `chunk_size` allows, then as many values of
    the next axis as fit, and one value of each earlier axis (:meth:`of`): e.g. a 6 × 8 grid in
    chunks of at most 20 members has blocks of 2 × 8, and in chunks of at most 3 blocks of
    1 × 3 (the last of each row holding 2). The members of a chunk are thus consecutive in C
    order, `[a, b)` (:meth:`member_range`); the chunks are numbered in C order over the grid of
    blocks.
    """

    shape: tuple[int, ...]
    block: tuple[int, ...]

    @classmethod
    def of(cls, shape, chunk_size: int) -> ChunkLayout:
        """The layout of at most `chunk_size` members per chunk."""
        block, budget = [], max(1, int(chunk_size))
        for n in reversed(tuple(shape)):
            c = min(n, budget)
            block.append(c)
            budget = budget // n if c == n else 1
        return cls(tuple(int(n) for n in shape), tuple(reversed(block)))

    @property
    def size(self) -> int:
        """Members per (full) chunk."""
        return math.prod(self.block)

    @property
    def members(self) -> int:
        """Members of the grid."""
        return math.prod(self.shape)

    @property
    def counts(self) -> tuple[int, ...]:
        """Chunks along each axis."""
        return tuple(-(-n // b) for n, b in zip(self.shape, self.block))

    @property
    def chunks(self) -> int:
        """The number of chunks."""
        return math.prod(self.counts)

    def _bounds(self, index: int) -> tuple[list[int], list[int]]:
        if not 0 <= index < self.chunks:
            raise IndexError(f"chunk {index} out of range for {self.chunks} chunks")
        start, rest = [], index
        for c, b in zip(reversed(self.counts), reversed(self.block)):
            rest, k = divmod(rest, c)
            start.append(k * b)
        start.reverse()
        return start, [min(s + b, n) for s, b, n in zip(start, self.block, self.shape)]

    def slices(self, index: int) -> tuple[slice, ...]:
        """The chunk's block of the grid, one slice per axis."""
        start, stop = self._bounds(index)
        return tuple(slice(a, b) for a, b in zip(start, stop))

    def region(self, first: int, last: int) -> tuple[slice, ...]:
        """The block of the chunks `first..last` (consecutive, and in one :meth:`row`)."""
        a, b = self.slices(first), self.slices(last)
        return tuple(slice(s.start, t.stop) for s, t in zip(a, b))

    def row(self, index: int) -> int:
        """Chunks with the same row make one block when consecutive (:meth:`region`)."""
        split = [i for i, c in enumerate(self.counts) if c > 1]
        return index // self.counts[split[-1]] if split else 0

    def member_range(self, index: int) -> tuple[int, int]:
        """`(a, b)`: the chunk holds the members a, ..., b - 1 (C order)."""
        start, stop = self._bounds(index)
        a, stride = 0, 1
        for s, n in zip(reversed(start), reversed(self.shape)):
            a += s * stride
            stride *= n
        return a, a + math.prod(e - s for s, e in zip(start, stop))

    def member_mask(self, done: np.ndarray) -> np.ndarray:
        """The per-chunk flags `done` (chunks,) as per-member flags of the grid's shape."""
        m = np.asarray(done, dtype=bool).reshape(self.counts)
        for axis, b in enumerate(self.block):
            m = np.repeat(m, b, axis=axis)
        return m[tuple(slice(0, n) for n in self.shape)]
