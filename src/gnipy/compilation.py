"""Compiled programs: the persistent compilation cache (on disk, between processes), and the
release of compiled programs held in memory when a process holds too many of them.

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
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = [
    "enable_compilation_cache",
    "default_cache_dir",
    "cache_requested",
    "memory_map_count",
    "release_compiled_programs_if_needed",
]


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

    Arguments:
        path: the cache directory (default :func:`default_cache_dir`).
        min_compile_seconds: programs that compile faster than this are not stored.

    Returns:
        The directory used, or None when the directory cannot be created (the cache is an
        optimisation: nothing fails without it).
    """
    import jax

    directory = Path(path) if path is not None else default_cache_dir()
    try:
        directory.mkdir(parents=True, exist_ok=True)
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

    Returns:
        True if the caches were cleared.
    """
    count = memory_map_count()
    if count is None or count < fraction * _max_map_count():
        return False
    import gc

    import jax

    jax.clear_caches()
    gc.collect()
    return True
