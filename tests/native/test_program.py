"""The compiled native loop (gnipy.native.program): blocks and saved states, the failure
bookkeeping, batches split across threads, and the on-disk cache of compiled programs."""

import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.native.program import build_loop


def _toy_step(carry, h):
    """x ← x + h·(1, x₀): exact sums to compare with; fails (residual 7) once x₀ exceeds 2."""
    state, k, fail_k, fail_res, it_tot, it_max = carry
    new = state + h * jnp.array([1.0, state[0]])
    ok = (new[0] <= 2.0) & (fail_k < 0)
    newly = (~ok) & (fail_k < 0)
    state = jnp.where(ok, new, state)
    return (state, k + 1, jnp.where(newly, k, fail_k), jnp.where(newly, 7.0, fail_res), it_tot + ok.astype(jnp.int32),
            jnp.maximum(it_max, 1))


def _carry(x):
    i = jnp.int32
    return (jnp.asarray(x, jnp.float64), i(0), i(-1), jnp.asarray(0.0), i(0), i(0))


def test_blocks_save_the_state_after_each_block():
    loop = build_loop(_toy_step, _carry([0.0, 0.0]), 0.25)
    carry, saved = loop.run(np.array([0.0, 0.0, 0, -1, 0, 0, 0]), 0.25, [2, 0, 3])
    np.testing.assert_array_equal(saved[:, 0], [0.5, 0.5, 1.25])
    # x₁ = Σ h·x₀ over the steps: h²(0 + 1 + 2 + 3 + 4) = 0.625
    assert carry[1] == 0.625 and carry[2] == 5 and carry[3] == -1 and carry[5] == 5


def test_a_carry_of_another_width_is_refused():
    """The compiled code reads and writes n_carry values per trajectory: a shorter carry (e.g. one
    without the monitor that native_loop's programs carry) would have it run past the buffer."""
    loop = build_loop(_toy_step, _carry([0.0, 0.0]), 0.25)
    assert loop.n_carry == 7
    for carry in (np.zeros(6), np.zeros(8), np.zeros((2, 6)), np.zeros((1, 2, 7))):
        with pytest.raises(ValueError, match="n_carry = 7"):
            loop.run(carry, 0.25, [1])


def test_a_failed_step_is_recorded_and_the_state_kept():
    loop = build_loop(_toy_step, _carry([0.0, 0.0]), 0.5)
    carry, saved = loop.run(np.array([0.0, 0.0, 0, -1, 0, 0, 0]), 0.5, [3, 4, 2])
    # steps 0-3 take x₀ to 2.0; step 4 would pass 2: it fails, and the state stays
    assert carry[0] == 2.0 and carry[3] == 4 and carry[4] == 7.0
    assert carry[2] == 9  # the step index still counts every step, as the XLA loop's does
    np.testing.assert_array_equal(saved[:, 0], [1.5, 2.0, 2.0])
    assert carry[5] == 4  # iterations only of the good steps


@pytest.mark.parametrize("lanes", [1, 4])
def test_batch_equals_single_runs_bit_for_bit(lanes):
    """Batches run in threads and, with lanes, several trajectories per vector (37 = 9 × 4 + 1:
    the last member runs alone); every member gets the bits of its own single run, failures
    included (members starting near x₀ = 2 fail at different steps)."""
    loop = build_loop(_toy_step, _carry([0.0, 0.0]), 0.01, lanes=lanes)
    rng = np.random.default_rng(0)
    x0 = rng.uniform(-1, 2, (37, 2))
    carry0 = np.concatenate([x0, np.tile([0, -1, 0, 0, 0], (37, 1))], axis=1)
    carry, saved = loop.run(carry0, 0.01, [100, 50])
    assert 0 < np.sum(carry[:, 3] >= 0) < 37  # some members failed, some did not
    for j in range(37):
        c1, s1 = loop.run(carry0[j], 0.01, [100, 50])
        np.testing.assert_array_equal(carry[j], c1)
        np.testing.assert_array_equal(saved[j], s1)


def test_programs_are_kept_on_disk_and_loaded_by_a_fresh_process(tmp_path):
    script = textwrap.dedent(f"""
        import os, jax, jax.numpy as jnp
        os.environ["GNIPY_CACHE_DIR"] = {str(tmp_path)!r}
        jax.config.update("jax_enable_x64", True)
        import sys; sys.path.insert(0, {str(__file__.rsplit('/', 1)[0])!r})
        from test_program import _toy_step, _carry
        from gnipy.native.program import build_loop
        loop = build_loop(_toy_step, _carry([0.0, 0.0]), 0.1)
        print(loop.source)
    """)
    first = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    files = list((tmp_path / "native").glob("*.o"))
    assert len(files) == 1 and files[0].stat().st_size > 0
    assert not list((tmp_path / "native").glob("*.tmp"))  # written whole: no partial file left
    second = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert first.stdout.split()[-1] == "compiled" and second.stdout.split()[-1] == "disk"
    # a damaged cache file is not loaded: the program is compiled again and the file replaced
    data = files[0].read_bytes()
    files[0].write_bytes(data[:100] + bytes([data[100] ^ 0xFF]) + data[101:])
    third = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert third.stdout.split()[-1] == "compiled" and files[0].read_bytes() == data


def test_jaxpr_constants_are_embedded_exactly():
    c = np.array([0.1, 1 / 3, np.pi, 5e-324, -0.0, 1e308])

    def step(carry, h):
        return (jnp.asarray(c), *carry[1:])

    loop = build_loop(step, _carry(np.zeros(6)), 0.1)
    carry, _ = loop.run(np.concatenate([np.ones(6), [0, -1, 0, 0, 0]]), 0.1, [1])
    np.testing.assert_array_equal(carry[:6], c)
    assert np.signbit(carry[4])
