"""The persistent compilation cache: compiled programs kept on disk between processes.

A first `gnipy.simulate` call in a fresh process spends most of its few seconds compiling. JAX can
keep compiled programs on disk and load them in later processes (measured for the rolling ball
on 2 cores: first call 5.1 s without the cache, 1.7 s with it; the rest is tracing).

**Opt-in.** The cache is off by default: with jax 0.10.2 on CPU we saw a segmentation fault inside
JAX's cache write (`compilation_cache.put_executable_and_time`) when the cache had been turned on
in a process that had already compiled other programs. Turn it on by setting
`GNIPY_COMPILATION_CACHE=1` (the command line and the workers of `gni sweep` then call
:func:`enable_compilation_cache` at start-up, before compiling anything), or call it yourself at
the start of a Python session.

The directory is `$GNIPY_CACHE_DIR` if set, else `~/.cache/gnipy/jax`.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["enable_compilation_cache", "default_cache_dir", "cache_requested"]


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
