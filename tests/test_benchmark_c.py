"""The C port of the rolling ball's GNI step (benchmarks/c_gni.c, issue 35) computes what Numba computes.

benchmarks/c_gni.py compiles c_gni.c at first use with the machine's C compiler. Where there is a
compiler, the C loop must reproduce numba_gni's kernel bit for bit (the same operations in the
same order, IEEE arithmetic on both sides: -fno-fast-math -ffp-contract=off, Numba's
fastmath=False). Where there is none, the loader must say so with CompilerNotFoundError (which the
benchmark catches and reports): that is asserted instead, never skipped. Not timed here.
"""

import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ is not installed

from benchmarks import c_gni, numba_gni  # noqa: E402

H = 0.01


def _compiler():
    try:
        return c_gni.find_compiler()
    except c_gni.CompilerNotFoundError:
        return None


COMPILER = _compiler()


def test_c_matches_numba_bit_for_bit():
    s0 = numba_gni.CASES["rolling-ball-ex2"].initial_state()
    if COMPILER is None:
        with pytest.raises(c_gni.CompilerNotFoundError, match="no C compiler found"):
            c_gni.run_rolling_ball_ex2_c(s0, H, 10)
        return
    for steps in (1, 1000, 2000):
        ours = c_gni.run_rolling_ball_ex2_c(s0, H, steps)
        np.testing.assert_array_equal(ours, numba_gni.run_rolling_ball_ex2(s0, H, steps))
    its, _ = c_gni.count_iterations_c(s0, H, 2000)
    assert its == numba_gni.count_iterations("rolling-ball-ex2", H, 2000)[0]
    # another start (perturbed momenta): still the same numbers
    s1 = s0.copy()
    s1[11:] += 0.05 * np.random.default_rng(35).standard_normal(5)
    np.testing.assert_array_equal(c_gni.run_rolling_ball_ex2_c(s1, H, 500), numba_gni.run_rolling_ball_ex2(s1, H, 500))
    assert c_gni.time_rolling_ball_ex2_c(s0, H, 100, repeats=2) > 0.0
    info = c_gni.compiler_info()
    assert "-ffp-contract=off" in info["flags"] and "-fno-fast-math" in info["flags"]


def test_c_failed_newton_gives_nan():
    if COMPILER is None:
        with pytest.raises(c_gni.CompilerNotFoundError):
            c_gni.run_rolling_ball_ex2_c(np.full(16, np.nan), H, 3)
        return
    assert np.all(np.isnan(c_gni.run_rolling_ball_ex2_c(np.full(16, np.nan), H, 3)))
    with pytest.raises(ValueError, match="shape"):
        c_gni.run_rolling_ball_ex2_c(np.zeros(6), H, 3)


def test_missing_compiler_is_reported(monkeypatch):
    # whatever the machine has: a compiler that is not there gives the clear error, before any
    # temporary directory is made
    made = []
    monkeypatch.setattr(tempfile, "mkdtemp", lambda *a, **k: made.append(1))
    monkeypatch.setenv("GNIPY_BENCH_CC", "gnipy-no-such-compiler")
    with pytest.raises(c_gni.CompilerNotFoundError, match="gnipy-no-such-compiler"):
        c_gni.build()
    assert made == []


def test_build_uses_a_private_temporary_directory(monkeypatch):
    # the library is compiled into a fresh mkdtemp() directory (mode 0700) and nothing is left behind
    if COMPILER is None:
        with pytest.raises(c_gni.CompilerNotFoundError):
            c_gni.build()
        return
    made = []
    real = tempfile.mkdtemp

    def mkdtemp(*args, **kwargs):
        path = real(*args, **kwargs)
        made.append((path, Path(path).stat().st_mode & 0o777))
        return path

    monkeypatch.setattr(tempfile, "mkdtemp", mkdtemp)
    lib, info = c_gni.build(march_native=False)
    assert "-march=native" not in info["flags"]
    assert len(made) == 1 and made[0][1] == 0o700
    assert not Path(made[0][0]).exists()  # removed after loading
    out = np.empty(16)
    s0 = numba_gni.CASES["rolling-ball-ex2"].initial_state()
    P = c_gni.ctypes.POINTER(c_gni.ctypes.c_double)
    n = lib.gni_ex2_run(s0.ctypes.data_as(P), H, 200, out.ctypes.data_as(P))
    assert n == 200  # one Newton iteration per step here
    np.testing.assert_array_equal(out, numba_gni.run_rolling_ball_ex2(s0, H, 200))
