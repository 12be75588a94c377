"""The one stepping loop of gnipy: every simulation, streamed run, sweep and experiment steps here
(through :func:`gnipy.simulate`).

Two compiled forms of the same loop over one method's `step`:

- :func:`run_nodes` (the default): between saved nodes a `fori_loop` whose trip count is traced,
  so runs that save as many nodes share one compilation whatever their step counts and h (and
  :mod:`gnipy.preparation` pads the node count to a bucket, so that nearby counts share it too);
- :func:`run_nodes_checkpointed` (under a JAX transformation: `jax.grad`, `jax.jacrev`,
  `jax.jacfwd`, `jax.jit` of a simulation): static trip counts (reverse mode cannot differentiate
  a loop of unknown length) in blocks of at most L steps. When reverse mode would keep more than
  :data:`GRADIENT_MEMORY_BYTES` of per-step residuals (:func:`residual_bytes` × steps), each block
  is rematerialized on the backward pass (`jax.checkpoint`), so it keeps about (steps/L + L)
  states instead of one step's residuals per step, at the price of one more forward run (measured
  on the rolling ball, 10⁴ steps: the gradient costs 3.0× the forward run without checkpoints,
  7.4× with them; its residuals are 1.9 kB per step). The implicit steps' solves are
  differentiated by the implicit function theorem (:func:`gnipy.integrators.base.implicit_solve`),
  not through their iterations.

Both keep the same bookkeeping: the first failed step (a solve that did not converge or a
non-finite state) is recorded with its residual, and the state stays at the last good node.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .compilation import split_arrays
from .extras import require
from .inputs import is_traced
from . import monitor

__all__ = ["run_nodes", "run_nodes_checkpointed", "finish_native", "checkpoint_blocks", "progress_reporter", "Progress",
           "residual_bytes", "loop_step", "initial_carry", "report_progress", "split_arrays", "GRADIENT_MEMORY_BYTES"]

_INT = jnp.int32

#: The memory reverse mode may keep for the residuals of a run's steps before the loop is
#: checkpointed (blocks recomputed on the backward pass).
GRADIENT_MEMORY_BYTES = 256 * 2**20


def _tree_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(x)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


# The progress callback: compiled code calls `report_progress(steps_done)` through `jax.debug.callback`;
# it forwards to the reporter of the `simulate` call in progress (one Python function, so that the
# compiled program does not depend on which reporter it is).
_REPORTER: list[Callable[[int], None]] = []


def report_progress(k) -> None:
    """Report `k` steps done (the largest of them, for a batch) to the active
    :class:`progress_reporter`, if any: what the compiled XLA loop calls back, and the native
    loop after each piece of a run (:mod:`gnipy.native.backend`)."""
    if _REPORTER:
        _REPORTER[-1](int(np.max(np.asarray(k))))


class progress_reporter:
    """Context manager: while active, compiled runs with progress call `fn(steps_done)`."""

    def __init__(self, fn: Callable[[int], None]):
        self.fn = fn

    def __enter__(self):
        _REPORTER.append(self.fn)
        return self

    def __exit__(self, *exc):
        _REPORTER.pop()
        return False


def loop_step(method, system):
    """One step of the loop on the carry of :func:`initial_carry`; with a monitor in the carry (its 7th
    entry), the node the step starts from is checked first (:func:`gnipy.monitor.update`), and
    the iteration k = k_end (the monitor's) only checks: the loop's one extra iteration checks the
    last node, so that the check is compiled once."""
    def one_step(carry, h):
        state, k, fail_k, fail_res, it_tot, it_max = carry[:6]
        sys_k = system.at_step(k)  # a forced system's input and time at step k
        watched, go = (), True
        if len(carry) > 6:
            watched = (monitor.update(method, sys_k, carry[6], state, h, k, fail_k < 0),)
            go = monitor.stepping(carry[6], k)
        new, info = method.step(sys_k, state, h)
        ok = info.ok & _tree_finite(new) & (fail_k < 0) & go
        newly_failed = (~ok) & (fail_k < 0) & go
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, state)
        res = jnp.where(jnp.isfinite(info.residual), info.residual, jnp.inf)
        fail_k = jnp.where(newly_failed, k, fail_k)
        fail_res = jnp.where(newly_failed, res, fail_res)
        it = jnp.where(ok, info.iterations, 0).astype(_INT)
        k_next = k + jnp.asarray(go, _INT)
        return (state, k_next, fail_k, fail_res, it_tot + it, jnp.maximum(it_max, it)) + watched

    return one_step


def _observer(method, system, save_states: bool):
    def observe(state, h):
        b, v, p = method.observe(system, state, h)
        return b, v, p, method.hidden_momentum(system, state, h), (state if save_states else None)

    return observe


def initial_carry(state0, monitor0=None):
    """The loop's carry: the state, the step index, the first failed step and its residual, the
    Newton iterations (total, max), and the monitor (:mod:`gnipy.monitor`) when given."""
    carry = (state0, jnp.asarray(0, _INT), jnp.asarray(-1, _INT), jnp.asarray(0.0), jnp.asarray(0, _INT),
             jnp.asarray(0, _INT))
    return carry if monitor0 is None else carry + (jnp.asarray(monitor0, jnp.float64),)


def _final_step(method, system, carry, h, h_last):
    """The shortened last step: the state rescaled to the new step size, then one step of it."""
    state = method.change_step(system, carry[0], h, h_last)
    return loop_step(method, system)((state,) + carry[1:], h_last)


def watched_run(monitor0, lengths, tail, partial: bool):
    """`(monitor0, tail)` for a loop that checks every node: the monitor told how many steps the
    loop takes, and the tail one iteration longer (the check of the last node) unless the run
    ends with a shortened step (whose node :func:`_finish` checks)."""
    if not is_traced(monitor0, lengths, tail):  # on the host: no dispatch
        total = int(np.sum(np.asarray(lengths, np.int64))) + int(tail)
        return monitor.with_end(np.asarray(monitor0, np.float64), total + (1 if partial else 0)), \
            int(tail) + (0 if partial else 1)
    total = jnp.sum(jnp.asarray(lengths, _INT)) + jnp.asarray(tail, _INT)
    return monitor.with_end(monitor0, total + (1 if partial else 0)), tail + (0 if partial else 1)


def _finish(method, system, carry, obs, h, h_last, partial: bool):
    b, v, p, hidden, states = obs
    energy = jax.vmap(system.energy)(b, v)
    residual = jax.vmap(system.constraint_residual)(b, v)
    _, _, fail_k, fail_res, it_tot, it_max = carry[:6]
    out = dict(b=b, v=v, p=p, hidden=hidden, states=states, energy=energy, residual=residual, fail_k=fail_k,
               fail_res=fail_res, iterations=jnp.stack([it_tot, it_max]), final_state=carry[0],
               monitor=None if len(carry) == 6 else carry[6])
    if len(carry) > 6 and partial:  # the node after the shortened step, which no iteration starts from
        out["monitor"] = _watch_last(method, system, carry, h, h_last)
    return out


def _watch_last(method, system, carry, h, h_last):
    """The monitor after the node that ends the shortened last step (at t0 + (k-1) h + h_last)."""
    state, k, fail_k, mon = carry[0], carry[1], carry[2], carry[6]
    shifted = mon.at[monitor.SLOTS.index("t0")].add(h_last - h)
    out = monitor.update(method, system.at_step(k), shifted, state, h_last, k, fail_k < 0)
    return out.at[monitor.SLOTS.index("t0")].set(mon[monitor.SLOTS.index("t0")])


def _concat(obs, last):
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b[None]]), obs, last)


def run_nodes(method, system, state0, h, lengths, tail, h_last, *, partial: bool, save_final: bool,
              save_states: bool = False, progress: bool = False, progress_stride=1, monitor0=None, nodes=None):
    """Run from `state0`, observing after each `lengths[i]` steps, then `tail` steps more and (with
    `partial`) one shortened step of `h_last`, observed if `save_final`.

    `lengths`, `tail`, `h` and `h_last` are traced: only the number of saved nodes fixes the
    compiled program. With `progress` (static: one more program), every `progress_stride` steps
    (traced) the steps done are reported to the active :class:`progress_reporter`.

    With `monitor0` (:func:`gnipy.monitor.initial`), every node is checked as the loop runs and
    the result's `monitor` holds the verdicts of the whole run (:mod:`gnipy.monitor`).

    With `nodes` (traced), only the first `nodes` entries of `lengths` are the run's; the others
    are zeros (steps of no length, whose nodes repeat the last one), so that runs saving
    different numbers of nodes share a program (:func:`gnipy.preparation.node_bucket`). The
    shortened last step's node, when saved, is then the entry `nodes` rather than the last.

    Returns:
        A dict: `b, v, p` (saved nodes), `hidden` (the GNI family's p⁺ − p̄, else None), `states`
        (if `save_states`), `energy`, `residual`, `fail_k` (first failed step, -1 if none),
        `fail_res`, `iterations` (total, max), `final_state`, `monitor` (None without `monitor0`).
    """
    step = loop_step(method, system)
    observe = _observer(method, system, save_states)

    def one_step(c, h):
        c = step(c, h)
        if progress:
            jax.lax.cond(c[1] % progress_stride == 0, lambda k: jax.debug.callback(report_progress, k), lambda k: None, c[1])
        return c

    def steps(carry, n):
        return jax.lax.fori_loop(0, n, lambda _, c: one_step(c, h), carry)

    def block(carry, n):
        carry = steps(carry, n)
        return carry, observe(carry[0], h)

    # the tail runs as one more block, its observation dropped: the step is traced (and compiled)
    # once, not once for the blocks and again for the tail
    if monitor0 is not None:
        monitor0, tail = watched_run(monitor0, lengths, tail, partial)
    carry = initial_carry(state0, monitor0)
    blocks = jnp.concatenate([jnp.asarray(lengths, _INT).reshape(-1), jnp.asarray(tail, _INT).reshape(1)])
    carry, obs = jax.lax.scan(block, carry, blocks)
    obs = jax.tree_util.tree_map(lambda a: a[:-1], obs)
    if partial:
        carry = _final_step(method, system, carry, h, h_last)
        if save_final:
            last = observe(carry[0], h_last)
            obs = _concat(obs, last)
            if nodes is not None:  # the node after the run's own blocks, not after the zeros
                obs = jax.tree_util.tree_map(lambda a, x: jax.lax.dynamic_update_index_in_dim(a, x, nodes, 0),
                                             obs, last)
    return _finish(method, system, carry, obs, h, h_last, partial)


def finish_native(method, system, states, carry, h, h_last, *, partial: bool, save_final: bool,
                  save_states: bool = False):
    """The result of :func:`run_nodes` from the native loop's output (:mod:`gnipy.native`): the
    state after each block of steps (`states`, a leading block axis; the last is the tail's) and
    the loop's final carry. The nodes are observed here as `run_nodes` observes them, and a
    shortened last step (`partial`) runs here."""
    observe = _observer(method, system, save_states)
    obs = jax.vmap(lambda st: observe(st, h))(states)
    obs = jax.tree_util.tree_map(lambda a: a[:-1], obs)
    if partial:
        carry = _final_step(method, system, carry, h, h_last)
        if save_final:
            obs = _concat(obs, observe(carry[0], h_last))
    return _finish(method, system, carry, obs, h, h_last, partial)


def checkpoint_blocks(lengths, tail: int, block: int | None = None):
    """Split the segments between saved nodes (`lengths`, then the unsaved `tail`) into blocks of at
    most `block` steps (default about the square root of the steps, balanced over each segment).

    Returns `(L, block_lengths, saved)`: the block size, each block's steps, and the indices of the
    blocks after which a node is saved (in order).
    """
    segs = [int(n) for n in lengths] + ([int(tail)] if tail else [])
    total = sum(segs)
    if block is None:
        block = max(1, math.isqrt(max(total, 1)))
        longest = max(segs, default=1)
        if longest and longest <= block:
            block = longest
    block = max(1, int(block))
    out, saved = [], []
    for i, n in enumerate(segs):
        pieces = max(1, -(-n // block))
        base, extra = divmod(n, pieces)
        out.extend(base + (1 if j < extra else 0) for j in range(pieces))
        if i < len(lengths):
            saved.append(len(out) - 1)
    L = max(out, default=1) or 1
    return L, tuple(out), tuple(saved)


def residual_bytes(method, system, state0, h) -> int:
    """The bytes reverse mode keeps per step of `method` (the residuals of one step's VJP, from its
    shapes: nothing is computed)."""
    def vjp_of_step(s):
        return jax.vjp(lambda s: method.step(system, s, h)[0], s)[1]

    res = jax.eval_shape(vjp_of_step, state0)
    return int(sum(np.prod(x.shape, dtype=np.int64) * np.dtype(x.dtype).itemsize
                   for x in jax.tree_util.tree_leaves(res)))


def run_nodes_checkpointed(method, system, state0, h, lengths: tuple, tail: int, h_last, *, partial: bool,
                           save_final: bool, save_states: bool = False, block: int | None = None,
                           checkpoint: bool | None = None):
    """The loop of :func:`run_nodes` with static trip counts, for JAX transformations (reverse mode
    included): blocks of at most L steps (:func:`checkpoint_blocks`), each a `lax.scan` of L steps
    (those past the block's length masked when blocks differ in length), rematerialized on the
    backward pass (`jax.checkpoint`) when `checkpoint` (default: when the steps' residuals would
    exceed :data:`GRADIENT_MEMORY_BYTES`). Same arguments and result as :func:`run_nodes`
    (`lengths`, `tail` static)."""
    one_step = loop_step(method, system)
    observe = _observer(method, system, save_states)
    first_saved = len(lengths) > 0 and lengths[0] == 0
    seg = lengths[1:] if first_saved else lengths
    L, blocks, saved = checkpoint_blocks(seg, tail, block)
    if checkpoint is None:
        checkpoint = sum(blocks) * residual_bytes(method, system, state0, h) > GRADIENT_MEMORY_BYTES
    uniform = all(n == L for n in blocks)

    def run_block(carry, n):
        def masked(c, i):
            new = one_step(c, h)
            if uniform:
                return new, None
            return jax.tree_util.tree_map(lambda a, b: jnp.where(i < n, a, b), new, c), None

        return jax.lax.scan(masked, carry, jnp.arange(L, dtype=_INT))[0]

    if checkpoint:
        run_block = jax.checkpoint(run_block)

    def body(carry, n):
        carry = run_block(carry, n)
        return carry, observe(carry[0], h)

    carry = initial_carry(state0)
    obs0 = observe(state0, h)
    if any(blocks):
        carry, obs = jax.lax.scan(body, carry, jnp.asarray(blocks, dtype=_INT))
        idx = np.asarray(saved, dtype=np.int64)
        obs = jax.tree_util.tree_map(lambda a: a[idx], obs)
    else:
        obs = jax.tree_util.tree_map(lambda a: jnp.zeros((0,) + a.shape, a.dtype), obs0)
    if first_saved:
        obs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), obs0, obs)
    if partial:
        carry = _final_step(method, system, carry, h, h_last)
        if save_final:
            obs = _concat(obs, observe(carry[0], h_last))
    return _finish(method, system, carry, obs, h, h_last, partial)


class Progress:
    """The `progress=` of a :func:`gnipy.simulate` call: a rich bar, a callable, or nothing; a context
    manager around the run that forwards the steps done (:class:`progress_reporter`)."""

    def __init__(self, progress, total: int):
        self.total = max(1, int(total))
        self.active = bool(progress)
        self.stride = max(1, self.total // 200)
        self.fn = progress if callable(progress) else None
        self.bar = None

    def __enter__(self):
        if not self.active:
            return self
        if self.fn is None:
            require("rich", extra="cli", what="progress bar")
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

            self.bar = Progress("simulate", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                                TimeRemainingColumn(), transient=False)
            task = self.bar.add_task("steps", total=self.total)
            self.bar.start()
            self.fn = lambda done, total: self.bar.update(task, completed=done)
        self._done = 0

        def advance(done):  # monotone: the chunks of a batch split across devices report on their own
            done = min(int(done), self.total)
            if done > self._done:
                self._done = done
                self.fn(done, self.total)

        self._ctx = progress_reporter(advance)
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc):
        if not self.active:
            return False
        if exc[0] is None and self._done < self.total:
            self._done = self.total
            self.fn(self.total, self.total)
        self._ctx.__exit__(*exc)
        if self.bar is not None:
            self.bar.stop()
        return False
