"""What a run of :func:`gnipy.simulate` needs that depends only on its system, method and initial
condition, computed once per call signature and kept: the checked start, the prepared method,
the diagnostics' sentences, and the compiled programs with their inputs already split.

A repeated call with the same system object, method (the same object, or the same name:
:func:`gnipy.methods.shared_method`) and initial condition (compared by value) checks nothing
again (:meth:`gnipy.System.check`, `method.check`, `method.prepare` ran once) and calls its
compiled programs directly: the arrays of the method and system are
flattened once, and the programs are `jax.jit` functions shared by every run whose method and
system have the same structure (the non-array parts, compared as equinox's `filter_jit` compares
them) and whose numbers of saved nodes fall in one bucket (:func:`node_bucket`).
`equinox.filter_jit` would partition and hash the whole method and system on every call (about
0.3 ms each time, measured), which is why this module dispatches by hand.
"""

from __future__ import annotations

import functools
import threading

import jax
import jax.numpy as jnp
import numpy as np

from .compilation import compiler_options
from .errors import InputError
from .stepping import run_nodes, split_arrays

__all__ = ["Prepared", "prepare", "state_point", "node_padding", "node_bucket"]

_CACHE: dict = {}
#: held while the caches below change (runs may come from several threads)
_LOCK = threading.Lock()
_CACHE_MAX = 64
_PROGRAMS: dict = {}
_READINGS: dict = {}
_PROGRAMS_MAX = 256


def node_padding(T: int) -> int:
    """The number of nodes the diagnostics program is compiled for when `T` are saved: a power of
    two (at least 16), so that runs saving different numbers of nodes share it."""
    return max(16, 1 << (int(T) - 1).bit_length())


def node_bucket(n: int) -> int:
    """The number of nodes a run's program is compiled for when `n` are saved: 16 up to 16, else
    `n` rounded up to a quarter of an octave (a multiple of 2^(k-3) for 2^(k-1) <= n < 2^k), so at
    most a quarter more than `n`. Runs of one system and method whose node counts fall in one
    bucket share one program; the first call of a new count would otherwise compile the whole
    loop again (measured on the sleigh with gni-midpoint: 1.0 s, against 1.8 s for the first call).
    The extra nodes are blocks of no steps (:func:`gnipy.stepping.run_nodes`), cut from the result."""
    n = int(n)
    if n <= 16:
        return 16
    step = 1 << (n.bit_length() - 3)
    return -(-n // step) * step


def _key_part(x):
    if x is None:
        return None
    a = np.asarray(x)
    if a.dtype == object:
        raise TypeError
    return a.dtype.str, a.shape, a.tobytes()


def _program(key, make):
    """The compiled program under `key` (made by `make()` the first time; uncached when key is None)."""
    if key is not None and key in _PROGRAMS:
        return _PROGRAMS[key]
    program = jax.jit(make(), compiler_options=compiler_options())
    if key is not None:
        with _LOCK:
            if len(_PROGRAMS) >= _PROGRAMS_MAX:
                _PROGRAMS.pop(next(iter(_PROGRAMS), None), None)
            _PROGRAMS[key] = program
    return program


@functools.partial(jax.jit, static_argnums=1)
def _first(arrays, T: int):
    """The first `T` rows of each array of a pytree, in one dispatch (three `x[:T]` cost about 0.1 ms)."""
    return jax.tree_util.tree_map(lambda x: x[:T], arrays)


#: The entries of a run's result with one row per saved node (cut to the run's own nodes).
_NODE_KEYS = ("b", "v", "p", "hidden", "states", "energy", "residual", "q", "R", "t")


class Prepared:
    """A checked start `(b0, v0)`, the prepared method, the system without metadata (`core`), the
    diagnostics' host-side answers (`cache`) and the compiled programs of runs from this start."""

    __slots__ = ("b0", "v0", "method", "core", "cache", "refs", "_leaves", "_key", "_rebuild", "_sys_leaves",
                 "_sys_key", "_sys_rebuild", "_start", "_runs", "_states")

    def __init__(self, b0, v0, method, core, refs):
        self.b0, self.v0, self.method, self.core, self.refs = b0, v0, method, core, refs
        self.cache = {}
        self._leaves = None
        self._runs = {}
        self._states = {}  # h -> `method.init` at the checked start (host arrays), for native runs

    def _split(self):
        if self._leaves is None:
            # `_leaves` set last: a thread that finds it set finds the rest set too (calls from threads
            # that name one method share one Prepared: gnipy.methods.shared_method)
            leaves, self._key, self._rebuild = split_arrays((self.method, self.core))
            self._sys_leaves, self._sys_key, self._sys_rebuild = split_arrays(self.core)
            self._start = None if self.v0 is None else (
                jax.tree_util.tree_map(jnp.asarray, self.b0), jnp.asarray(self.v0, jnp.float64))
            self._leaves = leaves

    def run(self, state0, h: float, lengths, tail: int, h_last: float, times, *, partial: bool, save_final: bool,
            save_states: bool, progress: bool, progress_stride: int, monitor0):
        """:func:`gnipy.stepping.run_nodes` from `state0` (None: `method.init` at the checked start,
        in the same program); also the saved nodes' coordinates `q`, orientations `R`, their
        `times` as a device array `t`, and for the GNI family the saved nodes padded for
        :meth:`node_diagnostics` (`out["padded"]`). Every node is checked from `monitor0`
        (:mod:`gnipy.monitor`; None: no check in the loop)."""
        self._split()
        from_state = state0 is not None
        n, bucket = len(lengths), node_bucket(len(lengths))
        saved = n + (1 if partial and save_final else 0)  # the rows of the result
        config = (bucket, bool(partial), bool(save_final), bool(save_states), bool(progress), from_state)
        program = self._runs.get(config)
        if program is None:
            rebuild = self._rebuild

            def make():
                def run(leaves, start, h, lengths, tail, h_last, stride, times, monitor0, nodes):
                    method, system = rebuild(leaves)
                    state = start if from_state else method.init(system, start[0], start[1], h)
                    out = run_nodes(method, system, state, h, lengths, tail, h_last, partial=config[1],
                                    save_final=config[2], save_states=config[3], progress=config[4],
                                    progress_stride=stride, monitor0=monitor0, nodes=nodes)
                    return _complete(system, out, times)

                return run

            program = _program(None if self._key is None else ("run", self._key, config), make)
            self._runs[config] = program
        start = state0 if from_state else self._start
        padded_lengths = np.zeros(bucket, np.int32)
        padded_lengths[:n] = np.asarray(lengths, np.int32).reshape(-1)
        rows = bucket + saved - n
        times = np.asarray(times, np.float64).reshape(-1)
        padded_times = np.pad(times, (0, rows - len(times)), mode="edge") if len(times) else np.zeros(rows)
        out = program(self._leaves, start, np.float64(h), padded_lengths, np.int32(tail), np.float64(h_last),
                      np.int32(progress_stride), padded_times,
                      None if monitor0 is None else np.asarray(monitor0, np.float64), np.int32(n))
        if rows != saved:  # the rows of the bucket's extra nodes cut (`padded` keeps them: it is padded anyway)
            out |= _first({k: out[k] for k in _NODE_KEYS if k in out}, saved)
        return out

    def run_native(self, state0, h: float, lengths, tail: int, h_last: float, times, *, partial: bool,
                   save_final: bool, save_states: bool, monitor0, progress_stride: int | None = None):
        """:meth:`run` on the native backend (:mod:`gnipy.native`): the same result, or None when
        the method's step does not lower (then `self.cache["native"]` holds the reason)."""
        from .native.backend import native_loop, run_native

        if state0 is None and float(h) in self._states:  # `method.init` at this start and h, computed once
            state0 = self._states[float(h)]
        elif state0 is None:
            program = self._runs.get("init")
            if program is None:
                self._split()
                rebuild = self._rebuild

                def make():
                    def init(leaves, start, h):
                        method, system = rebuild(leaves)
                        return method.init(system, start[0], start[1], h)
                    return init

                program = _program(None if self._key is None else ("init", self._key), make)
                self._runs["init"] = program
            self._split()
            state0 = jax.tree_util.tree_map(np.asarray, program(self._leaves, self._start, np.float64(h)))
            if len(self._states) < 8:
                self._states[float(h)] = state0
        loop = self._runs.get("native")
        if loop is None:  # the states of one start have one structure: one loop (and one lookup)
            loop = self._runs["native"] = native_loop(self.method, self.core, state0)
        if not hasattr(loop, "run"):
            self.cache["native"] = str(loop)
            return None
        return run_native(loop, self.method, self.core, state0, h, lengths, tail, h_last, partial=partial,
                          save_final=save_final, save_states=save_states, monitor0=monitor0, times=times,
                          complete=_complete, progress_stride=progress_stride,
                          post=self._native_post(partial, save_final, save_states))

    def _native_post(self, partial: bool, save_final: bool, save_states: bool):
        """The compiled :func:`gnipy.native.backend.post_body` of runs from this start with these
        flags, called with the method's and system's leaves split once (:meth:`run`'s dispatch)."""
        config = ("native-post", bool(partial), bool(save_final), bool(save_states))
        program = self._runs.get(config)
        if program is None:
            from .native.backend import post_body

            self._split()
            rebuild = self._rebuild

            def make(layout):
                def post(leaves, saved, carry, h, h_last, times):
                    method, system = rebuild(leaves)
                    return post_body(method, system, layout, saved, carry, h, h_last, times, *config[1:],
                                     False, False, functools.partial(_complete_with_diagnostics, h=h))
                return post

            jitted = {}

            def program(layout, saved, carry, h, h_last, times):
                # the layout (the state's tree structure and shapes) is static: one program each
                run = jitted.get(layout)
                if run is None:
                    run = jitted[layout] = _program(None if self._key is None else (config, self._key, layout),
                                                    lambda: make(layout))
                return run(self._leaves, saved, carry, h, h_last, times)

            self._runs[config] = program
        return program

    def node_diagnostics(self, padded, h: float, T: int, times=None):
        """:func:`gnipy.diagnostics.node_diagnostics` at the first `T` of the padded saved
        nodes: `(hidden_ratio, expected_ratio, energy_plus)` as arrays (T,). One program per
        system structure and padded length, shared by every method."""
        program = self._runs.get("diagnostics")
        if program is None:
            from .diagnostics import node_diagnostics

            self._split()
            rebuild = self._sys_rebuild

            def make():
                def diagnose(leaves, b, v, p, hidden, h, t):
                    system = rebuild(leaves)
                    if system.force is None:
                        return jax.vmap(lambda bb, vv, pp, xx: node_diagnostics(system, bb, vv, pp, xx, h))(
                            b, v, p, hidden)
                    # a forced system: λ at each node's time and input
                    return jax.vmap(lambda bb, vv, pp, xx, tt: node_diagnostics(system, bb, vv, pp, xx, h, tt))(
                        b, v, p, hidden, t)

                return diagnose

            program = _program(None if self._sys_key is None else ("diagnostics", self._sys_key), make)
            self._runs["diagnostics"] = program
        n_pad = int(np.shape(padded[1])[0])
        t = np.zeros(n_pad) if times is None else np.pad(np.asarray(times, np.float64)[:n_pad],
                                                          (0, max(0, n_pad - len(times))), mode="edge")
        out = program(self._sys_leaves, *padded, np.float64(h), t)
        # device arrays, not waited for: the run's caller goes on while they are computed
        return out if out[0].shape[0] == T else _first(out, T)


def _observed(system, out, times):
    """The nodes' coordinates `q`, orientations `R` and times `t`, added to a run's result."""
    out["q"] = system.space.coordinates(out["b"])
    out["R"] = system.space.orientation(out["b"])
    out["t"] = times
    return out


def _complete(system, out, times):
    """A run's result completed inside its program: :func:`_observed`, and for the GNI family the
    nodes padded for :meth:`Prepared.node_diagnostics`."""
    out = _observed(system, out, times)
    if out["hidden"] is not None:
        T = out["v"].shape[0]
        pad = node_padding(T) - T

        def edge(a):
            return jnp.concatenate([a, jnp.repeat(a[-1:], pad, axis=0)]) if pad else a

        out["padded"] = jax.tree_util.tree_map(edge, (out["b"], out["v"], out["p"], out["hidden"]))
    return out


def _complete_with_diagnostics(system, out, times, *, h):
    """:func:`_complete` for a native run (an unforced system): the GNI family's node diagnostics
    computed in the same program (`out["diagnostics"]`, :meth:`Prepared.node_diagnostics`'s
    arrays) rather than by a program of their own, a dispatch fewer per call."""
    out = _observed(system, out, times)
    if out["hidden"] is not None:
        from .diagnostics import node_diagnostics

        out["diagnostics"] = jax.vmap(lambda bb, vv, pp, xx: node_diagnostics(system, bb, vv, pp, xx, h))(
            out["b"], out["v"], out["p"], out["hidden"])
    return out


def _state_reading(system, method):
    """`(structure, shapes, point)` for states of `method` on `system`: the pytree structure and
    leaf shapes `method.init` builds, and `point(state)`, the state's base point (a compiled
    program shared by methods and systems of one structure). Kept per structure: runs continued
    from a state (streamed runs, the figures' starts) then trace nothing again."""
    core = system.without_metadata()
    leaves, key, rebuild = split_arrays((method, core))
    hit = _READINGS.get(key) if key is not None else None
    if hit is None:
        b_ref = system.initial_point(np.zeros(system.n)) if system.defaults is None else system.initial_point(
            system.defaults[0], system.defaults[2] if len(system.defaults) > 2 else None)
        ref = jax.eval_shape(lambda: method.init(core, b_ref, jnp.zeros(system.dim), 1.0))
        ref_leaves, ref_def = jax.tree_util.tree_flatten(ref)

        def point(leaves, state):
            m, s = rebuild(leaves)
            return m.observe(s, state, 1.0)[0]

        hit = (ref_def, [r.shape for r in ref_leaves], jax.jit(point))  # also called under transformations
        if key is not None:
            with _LOCK:
                if len(_READINGS) >= _CACHE_MAX:
                    _READINGS.pop(next(iter(_READINGS), None), None)
                _READINGS[key] = hit
    ref_def, shapes, point = hit
    return ref_def, shapes, lambda state: point(leaves, state)


def state_point(system, method, state0):
    """The base point of a given integrator state (checked against the state `method.init` builds)."""
    ref_def, shapes, point = _state_reading(system, method)
    leaves, treedef = jax.tree_util.tree_flatten(state0)
    if treedef != ref_def or any(np.shape(a) != r for a, r in zip(leaves, shapes)):
        raise InputError(
            f"state0: not a state of {method.name} for {system.name!r} (expected {ref_def} with shapes "
            f"{shapes}); pass the final_state of a run of the same method and system"
        )
    if not all(np.all(np.isfinite(np.asarray(a))) for a in leaves if np.issubdtype(np.asarray(a).dtype, np.inexact)):
        raise InputError("state0: contains NaN or infinite values")
    return point(state0), None


def prepare(system, method, q0, v0, R0, project_v0: bool, state0) -> Prepared:
    """The checked start and prepared method (:meth:`System.check`, `method.check`,
    `method.prepare`), from a cache keyed by the system and method objects (held, so their ids stay
    theirs) and the bytes of the initial condition: a repeated call checks nothing again. With
    `state0` the state is checked (its structure, finite values) and nothing is cached."""
    key = None
    if state0 is None:
        try:
            key = (id(system), id(method), _key_part(q0), _key_part(v0), _key_part(R0), bool(project_v0))
        except (TypeError, ValueError):
            key = None
        hit = _CACHE.get(key) if key is not None else None
        if hit is not None:
            return hit
        b0, v0c = system.check(q0, v0, R0=R0, project_v0=project_v0)
        v0c = np.asarray(v0c, dtype=np.float64)
    else:
        b0, v0c = state_point(system, method, state0)
    method.validate(system, b0)
    prepared = Prepared(b0, v0c, method.prepare(system, b0), system.without_metadata(), (system, method))
    if key is not None:
        with _LOCK:
            if len(_CACHE) >= _CACHE_MAX:
                _CACHE.pop(next(iter(_CACHE), None), None)
            _CACHE[key] = prepared
    return prepared
