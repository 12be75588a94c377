"""Where a simulation saves: the :class:`SaveAt` policy and the schedule it makes of a run.

Modelled on diffrax's `SaveAt`. A fixed-step geometric method has values only at its nodes
$t_k = t_0 + k h$: gnipy saves nodes and never interpolates between them (an interpolant leaves
the constraint manifold and breaks the structure the methods preserve). Times asked for must
therefore lie on the grid; to save at arbitrary times, choose h dividing them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .errors import InputError
from .inputs import positive_integer, real_array

__all__ = ["SaveAt", "Schedule", "schedule"]

#: Relative tolerance with which a requested time counts as a node of the grid.
GRID_RTOL = 1e-9


@dataclasses.dataclass(frozen=True)
class SaveAt:
    """Which nodes a simulation saves.

    Give one of `every`, `steps`, `ts`, or only `t0`/`t1`:

    - `SaveAt(every=K)`: nodes 0, K, 2K, ... and always the last one (the default, K = 1);
    - `SaveAt(steps=True)`: every node (the same as `every=1`);
    - `SaveAt(ts=[...])`: the nodes at these times (each on the grid $t_0 + k h$, or the final
      time); add `t0=True`/`t1=True` to save the first/last node too;
    - `SaveAt(t1=True)`: the last node only; `SaveAt(t0=True, t1=True)`: first and last.

    `states=True` also saves the integrator's state at the saved nodes (`Solution.states`, e.g.
    the GNI's post-momentum $p^+_k$); the state after the last step is always returned
    (`Solution.final_state`), to continue the run with `simulate(..., state0=sol.final_state)`.

    Examples:
        >>> import gnipy
        >>> gnipy.SaveAt(every=10)
        SaveAt(every=10)
        >>> gnipy.SaveAt(ts=[0.5, 1.0])
        SaveAt(ts=(0.5, 1.0))
    """

    t0: bool = False
    t1: bool = False
    ts: tuple[float, ...] | None = None
    every: int | None = None
    steps: bool = False
    states: bool = False

    def __post_init__(self):
        for name in ("t0", "t1", "steps", "states"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f"saveat.{name}: expected True or False, got {getattr(self, name)!r}")
        if self.every is not None:
            object.__setattr__(self, "every", positive_integer("saveat.every", self.every))
        if self.ts is not None:
            ts = real_array("saveat.ts", self.ts, "a sequence of times").reshape(-1)
            try:
                ts = np.asarray(ts, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError) as e:
                raise InputError(f"saveat.ts: expected a sequence of times, got {self.ts!r}") from e
            if ts.size == 0:
                raise InputError("saveat.ts: no times given")
            if not np.all(np.isfinite(ts)):
                raise InputError("saveat.ts: contains NaN or infinite values")
            if not (np.all(np.diff(ts) > 0) or np.all(np.diff(ts) < 0)):
                raise InputError("saveat.ts: the times must be strictly increasing (or, for a run backward "
                                 "in time, strictly decreasing)")
            object.__setattr__(self, "ts", tuple(float(t) for t in ts))
        chosen = [n for n in ("every", "ts") if getattr(self, n) is not None] + (["steps"] if self.steps else [])
        if len(chosen) > 1:
            raise InputError(f"saveat: give one of every, steps and ts, not {' and '.join(chosen)}")
        if not chosen and not (self.t0 or self.t1):
            raise InputError("saveat: nothing to save; give every=K, steps=True, ts=[...], t0=True or t1=True")

    def __repr__(self) -> str:
        fields = [f"{f.name}={getattr(self, f.name)!r}" for f in dataclasses.fields(self)
                  if getattr(self, f.name) != f.default]
        return f"SaveAt({', '.join(fields)})"


@dataclasses.dataclass(frozen=True)
class Schedule:
    """What a run does, worked out on the host before anything is compiled.

    Attributes:
        steps: the number of full steps of size h.
        partial: the size of a shortened last step as a fraction of h (0: none).
        nodes: the saved nodes' step indices k, sorted (the shortened last step's node is
            `steps + 1`).
        lengths: the steps between consecutive saved nodes on the grid (the first: from node 0
            to the first saved node), one per saved grid node.
        tail: steps after the last saved grid node, up to node `steps`.
        save_final: whether the node after the shortened last step is saved.
    """

    steps: int
    partial: float
    nodes: tuple[int, ...]
    lengths: tuple[int, ...]
    tail: int
    save_final: bool

    @property
    def grid_nodes(self) -> np.ndarray:
        """The saved nodes on the grid of full steps."""
        return np.asarray(self.nodes[: len(self.lengths)], dtype=np.int64)

    def times(self, t0, h):
        """The times of the saved nodes (`t0 + k h`; the shortened step's node at the final time)."""
        k = np.asarray(self.nodes, dtype=np.float64)
        if self.save_final:
            k[-1] = self.steps + self.partial
        return t0 + h * k


def _nodes_of_times(ts, steps: int, partial: float, h: float | None, t0: float) -> set[int]:
    """The step indices of the times `ts` (:attr:`SaveAt.ts`) on the grid `t0 + k h` of a run of
    `steps` steps (and a shortened one of `partial` h, whose node is `steps + 1`); InputError for a
    time off the grid or outside the run, or times in the other order than the run's."""
    last = steps + (1 if partial > 0 else 0)
    if h is None:
        raise InputError("saveat.ts: needs a concrete h to place the times on the grid")
    if len(ts) > 1 and (ts[1] > ts[0]) != (h > 0):
        # the rows of the solution follow the run: ts in the other order would not match them
        raise InputError(
            f"saveat.ts: the times are {'increasing' if ts[1] > ts[0] else 'decreasing'}, but "
            f"h = {h!r} runs {'forward' if h > 0 else 'backward'} in time; give them in the order the run "
            f"reaches them ({'increasing' if h > 0 else 'decreasing'}), so that row i of the solution is ts[i]"
        )
    nodes = set()
    t_end = t0 + h * (steps + partial)
    for t in ts:
        k = (t - t0) / h
        kr = round(k)
        tol = GRID_RTOL * max(1.0, abs(k))
        if partial > 0 and abs(t - t_end) <= GRID_RTOL * max(abs(t_end), abs(h)):
            nodes.add(last)
        elif abs(k - kr) <= tol and 0 <= kr <= steps:
            nodes.add(int(kr))
        elif k < -tol or k > steps + partial + tol:
            raise InputError(f"saveat.ts: {t!r} lies outside the run [{min(t0, t_end)!r}, {max(t0, t_end)!r}]")
        else:
            raise InputError(
                f"saveat.ts: {t!r} is not a node t0 + k h (h = {h!r}: it lies between k = {math.floor(k)} and "
                f"{math.floor(k) + 1}); gnipy saves nodes and does not interpolate (an interpolant leaves the "
                "constraints): choose h dividing the times"
            )
    return nodes


def schedule(saveat: SaveAt, steps: int, partial: float = 0.0, *, h: float | None = None, t0: float = 0.0) -> Schedule:
    """The :class:`Schedule` of a run of `steps` full steps (and a shortened last one of `partial`
    h when `partial > 0`), saving as `saveat` says. `h` and `t0` place `saveat.ts` on the grid."""
    last = steps + (1 if partial > 0 else 0)
    if saveat.every is not None or saveat.steps:
        every = 1 if saveat.steps else saveat.every
        nodes = set(range(0, steps + 1, every)) | {last}
    elif saveat.ts is not None:
        nodes = _nodes_of_times(saveat.ts, steps, partial, h, t0)
    else:
        nodes = set()
    if saveat.t0:
        nodes.add(0)
    if saveat.t1:
        nodes.add(last)
    nodes = sorted(nodes)
    save_final = partial > 0 and nodes[-1] == last
    grid = nodes[:-1] if save_final else nodes
    lengths = tuple(int(b - a) for a, b in zip([0] + grid[:-1], grid))
    tail = steps - (grid[-1] if grid else 0)
    return Schedule(steps, float(partial), tuple(nodes), lengths, int(tail), bool(save_final))
