"""Compiled programs: releasing them when the process holds many memory maps; the opt-in cache."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp

from gnipy.compilation import memory_map_count, release_compiled_programs_if_needed


def test_release_drops_compiled_programs_and_their_maps():
    for i in range(20):  # twenty distinct programs, each with its own mapped machine code
        jax.jit(lambda x, i=i: jnp.sin(x) * i + jnp.cumsum(jnp.cos(x) ** (i % 3 + 1)))(jnp.ones(50)).block_until_ready()
    before = memory_map_count()
    assert before is not None and before > 0
    assert not release_compiled_programs_if_needed(fraction=1e9)  # far below the limit: nothing done
    assert release_compiled_programs_if_needed(fraction=0.0)
    assert memory_map_count() <= before


def test_cache_is_opt_in_and_goes_where_asked(tmp_path):
    code = (
        "from gnipy.compilation import cache_requested, enable_compilation_cache;"
        "print(cache_requested()); print(enable_compilation_cache())"
    )
    env = {k: v for k, v in os.environ.items() if k != "GNIPY_COMPILATION_CACHE"}
    env["GNIPY_CACHE_DIR"] = str(tmp_path / "cache")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", str(tmp_path / "cache")]
    assert (tmp_path / "cache").is_dir()
