"""The persistent compilation cache: compiled programs kept on disk between processes.

A first `gnipy.simulate` call in a fresh process spends most of its few seconds compiling. JAX can
keep compiled programs on disk and load them in later processes (measured for the rolling ball
on 2 cores: first call 5.1 s without the cache, 1.7 s with it; the rest is tracing). The
command line (`gni ...`) and the workers of `gni sweep` turn the cache on; in a Python session call
:func:`enable_compilation_cache` before the first simulation.

The directory is `$GNIPY_CACHE_DIR` if set, else `~/.cache/gnipy/jax`. Setting
`GNIPY_NO_COMPILATION_CACHE=1` disables it (for the command line as well).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["enable_compilation_cache", "default_cache_dir"]


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
        The directory used, or None when `GNIPY_NO_COMPILATION_CACHE` is set or the directory
        cannot be created (the cache is an optimisation: nothing fails without it).
    """
    if os.environ.get("GNIPY_NO_COMPILATION_CACHE", "").strip() not in ("", "0"):
        return None
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
