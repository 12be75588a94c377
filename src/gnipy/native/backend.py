"""Which backend runs a simulation's step loop, and the native run itself.

`gnipy.simulate(..., backend=)`:

- `"xla"`: the loop of :func:`gnipy.stepping.run_nodes`, compiled by XLA (JAX's compiler);
- `"native"`: the same loop with the method's step compiled to scalar machine code
  (:mod:`gnipy.native.program`), the observation of the saved nodes on XLA;
- `"auto"` (the default): native when it can run and the run is long enough to pay for building
  it (:data:`NATIVE_MIN_STEPS` trajectory-steps), else XLA. The choice depends only on the run's
  arguments, never on what ran before in the process.

A batch of initial conditions runs on every core (one chunk of members per core), several
members at a time in vector lanes (:func:`gnipy.native.program.default_lanes`), each member with
the bits of its own single run.

A batch of parameter values (a list of systems) runs the same way, with the systems' array
leaves as inputs of one program instead of constants in it (:func:`native_loop`'s `params`).

The native loop runs when JAX's default device is the CPU (or `"native"` was asked for), llvmlite
is installed, the system is unforced (a forced system's drive stays on XLA), the run is not traced
by a JAX transformation (gradients stay on XLA), and every primitive of the step lowers. When it cannot, XLA runs and
`Solution.backend` says so (with `"native"` asked for, a warning gives the reason).
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..errors import InputError
from ..monitor import SIZE, initial
from ..stepping import finish_native, initial_carry, loop_step, report_progress, split_arrays, watched_run
from .lowering import Unsupported
from .engine import available
from .program import build_loop, default_lanes

__all__ = ["BACKENDS", "NATIVE_MIN_STEPS", "check_backend", "choose", "run_native", "native_loop", "system_params"]

#: The values of `simulate(..., backend=)`.
BACKENDS = ("auto", "xla", "native")

#: The trajectory-steps (steps × members) from which `backend="auto"` builds a native program.
#: Building one costs 0.1–1.5 s the first time (0.1–0.4 s from the disk cache: tracing and
#: lowering), about what XLA's compilation of the same loop costs; a native step is 8–10× faster
#: (BENCHMARKS.md), so from about 10⁴ steps a run gains even when both were to be built. Shorter
#: runs stay on XLA, whose programs are shared across initial conditions and parameter values.
NATIVE_MIN_STEPS = 20_000

_LOOPS: dict = {}
_LOOPS_MAX = 64


def check_backend(backend) -> str:
    """`backend` checked: one of :data:`BACKENDS`."""
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise InputError(f"backend: expected one of {', '.join(map(repr, BACKENDS))}, got {backend!r}")
    return backend


def _loop_key(method, system, params: bool = False):
    """The key of a built loop: the structure of `(method, system)` and the values of its array
    leaves (with `params`, the system's values are inputs of the program: only their shapes)."""
    leaves, key, _ = split_arrays((method, system))
    if key is None:
        return None
    n_method = len(split_arrays(method)[0])
    try:
        return key, params, tuple((np.asarray(a).dtype.str, np.shape(a),
                                   None if params and i >= n_method else np.asarray(a).tobytes())
                                  for i, a in enumerate(leaves))
    except Exception:
        return None


def _why_not(system, *, traced: bool = False) -> str | None:
    if traced:
        return "the run is traced by a JAX transformation (gradients stay on XLA)"
    if getattr(system, "force", None) is not None:
        return "forced systems (their drive) run on XLA"
    if not available():
        return "llvmlite is not installed (pip install 'gnipy[native]')"
    return None


def choose(backend: str, system, method, *, trajectory_steps: int, traced: bool = False,
           stacklevel: int = 4) -> tuple[str, str]:
    """`(backend, why)`: `"native"` or `"xla"` for this run, and a sentence when XLA runs although
    native was possible or asked for (also warned when native was asked for, `stacklevel` frames up:
    by default the caller of :func:`gnipy.simulate` or :func:`gnipy.integrate`). The choice depends
    on the run's arguments only (not on what ran before in the process), so that a run gives the
    same bits in any process."""
    from ..reference import ContinuousReference

    if backend == "xla" or isinstance(method, ContinuousReference):
        return "xla", ""
    reason = _why_not(system, traced=traced)
    if reason is None and backend == "auto":
        if jax.default_backend() != "cpu":
            reason = f"JAX's default device is {jax.default_backend()}"
        elif trajectory_steps < NATIVE_MIN_STEPS:
            return "xla", f"a short run ({trajectory_steps} < {NATIVE_MIN_STEPS} trajectory-steps)"
    if reason is not None:
        if backend == "native":
            warnings.warn(f"backend='native': running on XLA, because {reason}", RuntimeWarning, stacklevel=stacklevel)
        return "xla", reason
    return "native", ""


def system_params(system) -> tuple[list, object]:
    """`(values, rebuild)`: the array leaves of `system` (its parameter values) and
    `rebuild(values)`, the system with other values."""
    arrays, static = eqx.partition(system, eqx.is_array)
    values, treedef = jax.tree_util.tree_flatten(arrays)
    return values, lambda vs: eqx.combine(jax.tree_util.tree_unflatten(treedef, list(vs)), static)


def native_loop(method, system, state0, *, batch: bool = False, params: bool = False):
    """The compiled loop of `method` on `system` (built once per method and system values; for a
    `batch`, with the version that runs several trajectories in vector lanes), or the
    :class:`Unsupported` reason. With `params`, the system's array leaves (its parameter values,
    :func:`system_params`) are inputs of the loop, so one program runs every value: `system` is
    then an example (one member of a parameter batch)."""
    lanes = default_lanes() if batch else 1
    key = _loop_key(method, system, params)
    key = None if key is None else (key, lanes)
    hit = _LOOPS.get(key) if key is not None else None
    if hit is not None:
        return hit
    carry0 = initial_carry(state0, initial(0.01, 1.0, 0.0))  # every native run checks every node (gnipy.monitor)
    try:
        if params:
            values, rebuild = system_params(system)
            loop = build_loop(lambda c, hh, vs: loop_step(method, rebuild(vs))(c, hh), carry0, 0.01,
                              lanes=lanes, params=values)
        else:
            loop = build_loop(loop_step(method, system), carry0, 0.01, lanes=lanes)
    except Unsupported as e:
        loop = e
    if key is not None:
        if len(_LOOPS) >= _LOOPS_MAX:
            _LOOPS.pop(next(iter(_LOOPS)))
        _LOOPS[key] = loop
    return loop


def _flat_state(treedef, shapes, flat):
    leaves, i = [], 0
    for s in shapes:
        n = int(np.prod(s, dtype=np.int64))
        leaves.append(flat[..., i:i + n].reshape(flat.shape[:-1] + tuple(s)))
        i += n
    return jax.tree_util.tree_unflatten(treedef, leaves)


def post_body(method, system, layout, saved, carry, h, h_last, times, partial: bool, save_final: bool,
              save_states: bool, batched: bool, system_batched: bool, complete):
    """What :func:`run_native` computes on XLA after the loop (traced): the saved nodes and the
    final carry read back as :func:`gnipy.stepping.run_nodes`'s result, completed by `complete`.
    `layout` is `(treedef, shapes, S)` of the flat state."""
    treedef, shapes, S = layout

    def one(system, sv, c):
        states = _flat_state(treedef, shapes, sv)
        i32 = jnp.int32
        cy = (_flat_state(treedef, shapes, c[:S]), c[S].astype(i32), c[S + 1].astype(i32), c[S + 2],
              c[S + 3].astype(i32), c[S + 4].astype(i32), c[S + 5:S + 5 + SIZE])
        out = finish_native(method, system, states, cy, h, h_last, partial=partial, save_final=save_final,
                            save_states=save_states)
        return out if complete is None else complete(system, out, times)

    if not batched:
        return one(system, saved, carry)
    return eqx.filter_vmap(one, in_axes=(eqx.if_array(0) if system_batched else None, 0, 0))(system, saved, carry)


_post = jit(post_body)


@jit
def _flatten_states(state):
    leaves = jax.tree_util.tree_leaves(state)
    return jnp.concatenate([jnp.reshape(x, (x.shape[0], -1)) for x in leaves], axis=1)


def _run_reporting(loop, carry, h, blocks, stride: int):
    """`loop.run` in pieces of about `stride` steps, the steps done reported after each
    (:class:`gnipy.stepping.progress_reporter`); the same result as one call."""
    pieces, ends = [], []  # sub-blocks, and whether each ends a block
    for n in blocks:
        n = int(n)
        cuts = list(range(0, n, stride)) + [n]
        parts = [b - a for a, b in zip(cuts[:-1], cuts[1:])] or [0]
        pieces += parts
        ends += [False] * (len(parts) - 1) + [True]
    rows, done, i = [], 0, 0
    while i < len(pieces):
        j, steps = i, 0
        while j < len(pieces) and (steps < stride or j == i):  # about `stride` steps per call
            steps += pieces[j]
            j += 1
        chunk = pieces[i:j]
        carry, saved = loop.run(carry, h, chunk)
        rows.append(saved)
        done += sum(chunk)
        i += len(chunk)
        report_progress(done)
    saved = np.concatenate(rows, axis=-2)
    return carry, saved[..., np.asarray(ends), :]


#: The loop's counters at the start of a run (gnipy.stepping.initial_carry: step, failed step, its
#: residual, the Newton iterations' total and largest).
_COUNTERS = np.array([0.0, -1.0, 0.0, 0.0, 0.0])


def run_native(loop, method, system, state0, h, lengths, tail, h_last, *, partial: bool, save_final: bool,
               save_states: bool, monitor0, batched: bool = False, system_batched: bool = False, times=None,
               complete=None, progress_stride: int | None = None, post=None) -> dict:
    """The run of :func:`gnipy.stepping.run_nodes` (same arguments and result; `state0` with a
    leading member axis when `batched`) on the compiled `loop`; `complete(system, out, times)`
    adds fields inside the same XLA program. With `system_batched`, `system` is a stack of
    systems (:func:`gnipy.stack_systems`), one per member, and `loop` was built with `params`.
    With `progress_stride`, the steps done are reported every `progress_stride` steps or so (the
    loop then runs in pieces). `monitor0` is the monitor at the start (:func:`gnipy.monitor.initial`:
    (SIZE,), or (B, SIZE) for a batch). `post(layout, saved, carry, h, h_last, times)`, when given,
    is a compiled :func:`post_body` for this method, system and flags (a repeated run's caller
    keeps one: :class:`gnipy.preparation.Prepared`), called instead of partitioning the method and
    system again."""
    leaves, treedef = jax.tree_util.tree_flatten(state0)
    shapes = tuple(tuple(np.shape(x))[1 if batched else 0:] for x in leaves)
    S = sum(math.prod(s) for s in shapes)
    # the loop's last iteration only checks the last node (gnipy.stepping.watched_run)
    monitor0, tail = watched_run(monitor0, lengths, tail, bool(partial))
    if batched:
        flat = np.asarray(_flatten_states(state0), dtype=np.float64)
        watch = np.broadcast_to(np.asarray(monitor0, np.float64), flat.shape[:-1] + (SIZE,))
        carry0 = np.concatenate([flat, np.broadcast_to(_COUNTERS, flat.shape[:-1] + (5,)), watch], axis=-1)
    else:
        carry0 = np.concatenate([np.ravel(np.asarray(x, dtype=np.float64)) for x in leaves]
                                + [_COUNTERS, np.asarray(monitor0, np.float64)])
    if system_batched:  # each member's parameter values after its counters (build_loop's params)
        values, _ = system_params(system)
        carry0 = np.concatenate([carry0] + [np.reshape(np.asarray(v, np.float64), (carry0.shape[0], -1))
                                            for v in values], axis=-1)
    if carry0.shape[-1] != loop.n_carry:
        raise ValueError(f"run_native: a carry of {carry0.shape[-1]} values for a loop of {loop.n_carry}")
    blocks = np.concatenate([np.asarray(lengths, np.int32).reshape(-1), np.asarray([tail], np.int32)])
    if progress_stride:
        carry, saved = _run_reporting(loop, carry0, float(h), blocks, int(progress_stride))
    else:
        carry, saved = loop.run(carry0, float(h), blocks)
    times = None if times is None else np.asarray(times, np.float64)
    if post is not None:
        return post((treedef, shapes, S), saved, carry, np.float64(h), np.float64(h_last), times)
    return _post(method, system, (treedef, shapes, S), saved, carry, np.float64(h), np.float64(h_last),
                 times, bool(partial), bool(save_final),
                 bool(save_states), bool(batched), bool(system_batched), complete)
