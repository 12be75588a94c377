"""Compiled programs: the XLA options of every program gnipy compiles (:func:`jit`), the persistent
compilation cache (on disk, between processes), and the release of compiled programs held in
memory when a process holds too many of them.

**Compiler options.** :data:`COMPILER_OPTIONS` turns off XLA's newer CPU "fusion emitters" for
gnipy's programs. Measured on the 2-core machine, interleaved A/B runs in fresh processes: the
first `simulate` call of the rolling ball falls from 3.7–4.0 s to 2.1–2.5 s (XLA's own compile
time from 2.0–2.7 s to 1.0–1.1 s) and of a 1000-member batch from 5.4–6.2 s to 3.8–4.2 s, while the
compiled code runs as fast (per step, and batched, within the machine's noise). Where the
installed JAX/XLA does not know the option (older or newer versions), :func:`compiler_options`
finds out once, by compiling a trivial program, and gnipy compiles without it.

A first `gnipy.simulate` call in a fresh process spends most of its few seconds compiling. JAX can
keep compiled programs on disk and load them in later processes (measured for the rolling ball
on 2 cores: first call 5.1 s without the cache, 1.7 s with it; the rest is tracing).

**Opt-in.** The cache is off by default. In the test suite we saw a segmentation fault inside JAX's
cache writer (`compilation_cache.put_executable_and_time`); it was most likely the process running
out of memory maps (see :func:`release_compiled_programs_if_needed`: the same test then aborted
inside XLA's compiler with the cache off), but until the cache has been checked on its own it stays
opt-in. Turn it on by setting `GNIPY_COMPILATION_CACHE=1` (the command line and the workers of
`gni sweep` then call :func:`enable_compilation_cache` at start-up, before compiling anything), or
call it yourself at the start of a Python session.

The directory is `$GNIPY_CACHE_DIR` if set, else `~/.cache/gnipy/jax`.

**Trust.** JAX loads the executables it finds there and runs them, and gnipy cannot authenticate
JAX's entries (JAX reads and writes them itself, by path). So the directory is used only if it is
private (:func:`gnipy.private_folder.private_directory`): a directory, not a link, owned by the
current user and writable by no one else (a missing one is created with mode 0700). Another
directory is refused with a :class:`~gnipy.private_folder.CacheWarning`, and the cache stays off.
What remains trusted is that no one but the user (or root) writes into a directory only the user
can write, and that its path keeps naming it while JAX uses it.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

from .private_folder import CacheRefused, private_directory, warn_refused

__all__ = [
    "COMPILER_OPTIONS",
    "compiler_options",
    "jit",
    "bind",
    "split_arrays",
    "traced_once",
    "enable_compilation_cache",
    "default_cache_dir",
    "cache_requested",
    "memory_map_count",
    "release_compiled_programs_if_needed",
]


#: XLA options passed to every program gnipy compiles (see the module docstring for the measurements).
COMPILER_OPTIONS: dict[str, object] = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def compiler_options() -> dict[str, object]:
    """:data:`COMPILER_OPTIONS` when JAX's default backend is the CPU and this JAX/XLA accepts them
    (checked once per process by compiling a trivial program), else `{}` (on a GPU, XLA's defaults).
    Setting `GNIPY_XLA_DEFAULTS=1` also returns `{}`."""
    if os.environ.get("GNIPY_XLA_DEFAULTS", "").strip() not in ("", "0"):
        return {}
    import jax

    if jax.default_backend() != "cpu":
        return {}
    try:
        jax.jit(lambda x: x + 1, compiler_options=dict(COMPILER_OPTIONS)).lower(1.0).compile()
    except Exception:  # TypeError (no compiler_options argument) or XLA's "No such compile option"
        return {}
    return dict(COMPILER_OPTIONS)


def _traced(tree) -> bool:
    """Whether a leaf of `tree` is a JAX tracer (the call is being traced, or transformed)."""
    import jax

    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def jit(fun=None, **jitkwargs):
    """`equinox.filter_jit` with :func:`compiler_options`: the decorator of gnipy's compiled programs.

    The options are looked up at the first call (so importing gnipy compiles nothing). Usable as
    `@jit` or `jit(fun, donate=...)`. Called with traced arguments (under `jax.jit`, `jax.grad`,
    `jax.vmap`, ...), where JAX accepts compiler options only on the outermost program, it is
    `equinox.filter_jit` without them (the outer program's options apply).
    """
    if fun is None:
        return functools.partial(jit, **jitkwargs)
    import equinox as eqx

    jitted = nested = None

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        nonlocal jitted, nested
        if _traced((args, kwargs)):
            if nested is None:
                nested = eqx.filter_jit(fun, **jitkwargs)
            return nested(*args, **kwargs)
        if jitted is None:
            jitted = eqx.filter_jit(fun, compiler_options=compiler_options(), **jitkwargs)
        return jitted(*args, **kwargs)

    return wrapper


def split_arrays(tree):
    """`(leaves, structure_key, rebuild)`: the array leaves of `tree` (a method, a system, or a
    tuple of them; as jax arrays), a hashable key of everything else (None when a static part
    cannot be hashed), and `rebuild(leaves)`. The form in which compiled loops take a method and
    a system: their programs are keyed by the structure and called with the leaves
    (:mod:`gnipy.preparation`; the native backend's loops, :mod:`gnipy.native.backend`; the
    optimizers' callbacks, :func:`bind`)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    dyn, static = eqx.partition(tree, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    static_leaves, static_def = jax.tree_util.tree_flatten(static)
    key = (treedef, static_def, tuple(static_leaves))
    try:
        hash(key)
    except TypeError:
        key = None

    def rebuild(ls):
        return eqx.combine(jax.tree_util.tree_unflatten(treedef, ls), static)

    return [jnp.asarray(a) for a in leaves], key, rebuild


class _Structure:
    """The static part of a pytree argument of :func:`bind` (the function and :func:`split_arrays`'s
    key of the tree) as a static argument of `jax.jit`: hashed once, compared by identity first."""

    __slots__ = ("fun", "key", "tree", "_hash")

    def __init__(self, fun, key, rebuild):
        self.fun, self.key, self.tree = fun, key, rebuild
        self._hash = hash((fun, key))

    def __hash__(self):
        return self._hash

    def __eq__(self, other):
        return self is other or (isinstance(other, _Structure) and self._hash == other._hash
                                 and self.fun is other.fun and self.key == other.key)


@functools.cache
def _bound_program():
    """The one `jax.jit` program of :func:`bind` (made at the first call: its compiler options)."""
    import jax

    def call(structure, leaves, *args):
        return structure.fun(structure.tree(leaves), *args)

    return jax.jit(call, static_argnums=(0,), compiler_options=compiler_options() or None)


def bind(fun, tree):
    """`fun(tree, *args)` as a compiled program of the remaining arguments, with `tree`'s partition
    into arrays and the rest done once, here, instead of at every call: what
    `equinox.filter_jit(fun)(tree, *args)` computes, compiled once per structure of `tree` in the
    same way (trees of one structure whose arrays differ share the program), for functions called
    many times with the same tree, such as the optimizers' callbacks on a control problem
    (:mod:`gnipy.control.sqp`). Measured on the sleigh-steering problem's constraints and their
    Jacobian (80 steps; a 17-array problem): 0.79 ms a call through `filter_jit`, of which 0.30 ms
    were its partition and hashing of the problem; 0.50 ms this way. The `args` are arrays (NumPy
    or JAX).

    Raises:
        TypeError: a part of `tree` that is not an array cannot be hashed.
    """
    leaves, key, rebuild = split_arrays(tree)
    if key is None:
        raise TypeError(f"tree: its parts that are not arrays must be hashable (they key the compiled program, as "
                        f"for equinox.filter_jit); {type(tree).__name__} has one that is not")
    structure = _Structure(fun, key, rebuild)
    program = _bound_program()

    def call(*args):
        return program(structure, leaves, *args)

    return call


def traced_once(fun):
    """Trace `fun` once per argument structure inside a traced program: the decorator of the
    functions gnipy's steps call many times (a system's Lagrangian and metric, the groups' maps).

    Called with traced arguments (inside `jax.jit`, `jax.grad`, `jax.vmap`, ...), `fun` is an
    `equinox.filter_jit` call: JAX traces it once for each structure and shapes of its arguments
    and reuses that trace (and its derivatives) at every later call, where a plain Python function
    is traced again at each call. XLA inlines the call, so the compiled program computes the same
    numbers. Measured on the 2-core machine, tracing the native backend's step of every model × method
    pair (tests/native/test_primitives.py): the first 40 pairs 26.7 s → 14.3 s. Called with concrete
    values, `fun` runs as written, op by op, and compiles no program of its own.

    Takes positional arguments only (a method's `self` included: it is part of the structure).
    """
    import equinox as eqx

    nested = None

    @functools.wraps(fun)
    def wrapper(*args):
        nonlocal nested
        if _traced(args):
            if nested is None:
                nested = eqx.filter_jit(fun)
            return nested(*args)
        return fun(*args)

    return wrapper


def cache_requested() -> bool:
    """Whether `GNIPY_COMPILATION_CACHE` asks for the cache (set and not `0`/empty)."""
    return os.environ.get("GNIPY_COMPILATION_CACHE", "").strip() not in ("", "0")


def default_cache_dir() -> Path:
    """`$GNIPY_CACHE_DIR`, else `~/.cache/gnipy/jax` (`$XDG_CACHE_HOME` is respected)."""
    if os.environ.get("GNIPY_CACHE_DIR"):
        return Path(os.environ["GNIPY_CACHE_DIR"])
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "gnipy" / "jax"


def enable_compilation_cache(path=None, *, min_compile_seconds: float = 0.2) -> Path | None:
    """Turn on JAX's persistent compilation cache (takes effect for programs compiled afterwards;
    JAX reads the setting at its first compilation, so call this before simulating).

    JAX's entries are executables that JAX loads and runs; gnipy cannot authenticate them (JAX
    reads and writes them itself), so the only protection is that the directory is the user's
    alone: it is checked as :func:`gnipy.private_folder.private_directory` does, and a missing one
    is created with mode 0700.

    Arguments:
        path: the cache directory (default :func:`default_cache_dir`).
        min_compile_seconds: programs that compile faster than this are not stored.

    Returns:
        The directory used, or None when the directory cannot be created, or is refused because it
        is not private: a symbolic link, another user's, or writable by its group or others (with a
        :class:`~gnipy.private_folder.CacheWarning`). The cache is an optimisation: nothing fails
        without it.
    """
    import jax

    directory = Path(path) if path is not None else default_cache_dir()
    try:
        os.close(private_directory(directory))
    except CacheRefused as e:
        warn_refused(directory, str(e), what="JAX's compilation cache", instead="the cache stays off",
                     remedy="Set GNIPY_CACHE_DIR to a folder that only you can write (gnipy creates a missing one "
                            "with mode 0700), or pass such a folder, or leave GNIPY_COMPILATION_CACHE unset.")
        return None
    except OSError:
        return None
    if not os.access(directory, os.W_OK | os.X_OK):
        return None
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_seconds))
    return directory


def memory_map_count() -> int | None:
    """The number of memory mappings of this process (Linux), or None where it cannot be read."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return None


@functools.cache
def _max_map_count() -> int:
    try:
        with open("/proc/sys/vm/max_map_count") as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return 65530


def release_compiled_programs_if_needed(fraction: float = 0.5) -> bool:
    """Drop JAX's in-memory caches of compiled programs when this process holds too many memory maps.

    XLA's CPU backend maps the machine code of every compiled kernel separately: a compiled
    simulation of a model on R² × SO(3) adds about 500 memory mappings (measured), and they stay
    while the program is cached. Linux limits a process to `vm.max_map_count` mappings (65530 by
    default) and XLA aborts the process beyond it, after about a hundred distinct compiled
    simulations. :func:`gnipy.simulate` calls this before compiling: above `fraction` of the limit,
    the caches are cleared (`jax.clear_caches()`; programs are compiled again when next needed),
    which releases the mappings.

    Reading `/proc/self/maps` costs about 1 ms, so the count is read again only after JAX has
    compiled something since the last reading (counted through `jax.monitoring`); otherwise the
    last count is used.

    Returns:
        True if the caches were cleared.
    """
    global _last_count
    compiles = _compile_count()
    if _last_count is None or _last_count[0] != compiles:
        _last_count = (compiles, memory_map_count())
    count = _last_count[1]
    if count is None or count < fraction * _max_map_count():
        return False
    import gc

    import jax

    jax.clear_caches()
    gc.collect()
    _last_count = None
    return True


_BACKEND_COMPILE_EVENT = "/jax/core/compile/backend_compile_duration"
_compiles = [0]
_last_count: tuple[int, int | None] | None = None


def _on_event_duration(event: str, duration: float, **kwargs) -> None:
    if event == _BACKEND_COMPILE_EVENT:
        _compiles[0] += 1


@functools.cache
def _listening() -> bool:
    import jax.monitoring

    try:
        jax.monitoring.register_event_duration_secs_listener(_on_event_duration)
    except Exception:  # no monitoring API: read the maps every time
        return False
    return True


def _compile_count() -> int:
    """The number of backend compilations seen since the listener was registered; where it cannot be
    registered, a counter that changes at every call (so that the maps are read every time)."""
    if not _listening():
        _compiles[0] += 1
    return _compiles[0]
