"""The rolling ball's GNI step in C (issue 35): the same algorithm as :mod:`benchmarks.numba_gni`'s.

`benchmarks/c_gni.c` is a line-by-line port of numba_gni's kernel for the rolling ball, example 2
(gni-trapezoid; its solver `EX2_SOLVER`, "predicted-newton"): the same formulas and the same
operations in the same order. It answers "is Numba leaving speed on the table?": compiled with
IEEE arithmetic (`-O3 -fno-fast-math -ffp-contract=off`: no reassociation, no FMA contraction, as
Numba's `fastmath=False`), it computes the same numbers as the Numba kernel, bit for bit, and its
µs/step is the compiled-C price of the same work.

It is compiled when first used (by the benchmark), never shipped as a binary:

- the compiler is `cc`, else `gcc`, else `clang` (the first found on PATH), or `$GNIPY_BENCH_CC`;
  if none is found, :class:`CompilerNotFoundError` (a RuntimeError) says so, for the benchmark to
  catch and report;
- flags: `-O3 -fno-fast-math -ffp-contract=off -shared -fPIC`, plus `-march=native` by default
  (the host's instruction set, as Numba compiles for the host CPU; `march_native=False` leaves it
  out). GCC's and Clang's defaults contract a*b + c into an FMA where the target has one
  (`-ffp-contract=fast`/`on`); `-ffp-contract=off` keeps the arithmetic identical to Numba's;
- the library is written to a fresh private directory from :func:`tempfile.mkdtemp` (mode 0700,
  owned by this user: no other user can replace the file between the build and the load), loaded
  with ctypes, and the directory is removed right after loading (the mapping stays valid). Nothing
  is cached on disk; the loaded library is kept for the life of the process.

API: :func:`run_rolling_ball_ex2_c` (final state, as `numba_gni.run_rolling_ball_ex2`),
:func:`count_iterations_c`, :func:`time_rolling_ball_ex2_c` (the loop timed inside C, without the
ctypes call's overhead), :func:`compiler_info`.
"""

from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

__all__ = [
    "SOURCE",
    "CompilerNotFoundError",
    "build",
    "compiler_info",
    "count_iterations_c",
    "find_compiler",
    "load",
    "run_rolling_ball_ex2_c",
    "time_rolling_ball_ex2_c",
]

#: the C source, next to this file
SOURCE = Path(__file__).resolve().with_name("c_gni.c")
#: the compiler flags (plus -march=native unless march_native=False)
CFLAGS = ("-O3", "-fno-fast-math", "-ffp-contract=off", "-shared", "-fPIC")
_COMPILERS = ("cc", "gcc", "clang")

_lib = None  # the loaded library (ctypes.CDLL) and how it was built
_lib_info = None


class CompilerNotFoundError(RuntimeError):
    """No C compiler was found: the C baseline cannot be built on this machine."""


def find_compiler():
    """The C compiler to use: `$GNIPY_BENCH_CC`, else the first of cc, gcc, clang on PATH.

    Raises :class:`CompilerNotFoundError` if there is none."""
    env = os.environ.get("GNIPY_BENCH_CC")
    candidates = (env,) if env else _COMPILERS
    for name in candidates:
        path = shutil.which(name)
        if path:
            return path
    raise CompilerNotFoundError(
        f"no C compiler found (looked for {', '.join(candidates)} on PATH): the C baseline of the "
        "rolling ball (benchmarks/c_gni.c) cannot be built; install one (e.g. gcc) or set GNIPY_BENCH_CC"
    )


def build(compiler=None, march_native=True):
    """Compile c_gni.c and load it: `(ctypes.CDLL, info)`, info = dict(compiler, flags).

    The shared library is written to a new private directory (:func:`tempfile.mkdtemp`), loaded,
    and the directory removed. Raises :class:`CompilerNotFoundError` without a compiler, and
    RuntimeError (with the compiler's output) if the compilation fails.
    """
    cc = compiler or find_compiler()
    flags = list(CFLAGS) + (["-march=native"] if march_native else [])
    tmp = tempfile.mkdtemp(prefix="gnipy-c-gni-")
    try:
        so = os.path.join(tmp, "c_gni.so")
        cmd = [cc, *flags, "-o", so, str(SOURCE), "-lm"]
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"compiling the C baseline failed ({' '.join(cmd)}):\n{proc.stdout}{proc.stderr}")
        lib = ctypes.CDLL(so)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    dp = ctypes.POINTER(ctypes.c_double)
    lib.gni_ex2_run.argtypes = [dp, ctypes.c_double, ctypes.c_long, dp]
    lib.gni_ex2_run.restype = ctypes.c_long
    lib.gni_ex2_time.argtypes = [dp, ctypes.c_double, ctypes.c_long, ctypes.c_long, dp]
    lib.gni_ex2_time.restype = ctypes.c_double
    return lib, {"compiler": cc, "flags": flags}


def load():
    """The compiled library, built on first use (see :func:`build`) and kept for the process."""
    global _lib, _lib_info
    if _lib is None:
        _lib, _lib_info = build()
    return _lib


def compiler_info():
    """`dict(compiler, flags)` of the loaded library (builds it if needed)."""
    load()
    return dict(_lib_info)


def _state(state0):
    s = np.ascontiguousarray(state0, dtype=np.float64)
    if s.shape != (16,):
        raise ValueError(f"state0: expected shape (16,), got {s.shape}")
    return s


def _ptr(a):
    return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))


def count_iterations_c(state0, h, steps):
    """`(mean Newton iterations per step, final state (16,))` of the C loop."""
    lib = load()
    s = _state(state0)
    out = np.empty(16)
    n = lib.gni_ex2_run(_ptr(s), float(h), int(steps), _ptr(out))
    return n / max(int(steps), 1), out


def run_rolling_ball_ex2_c(state0, h, steps):
    """The rolling ball, example 2, in C: the final state (16,) after `steps` steps of size h.

    The same state layout and numbers as `numba_gni.run_rolling_ball_ex2`."""
    return count_iterations_c(state0, h, steps)[1]


def time_rolling_ball_ex2_c(state0, h, steps, repeats=20):
    """The minimum wall time (s) over `repeats` runs of `steps` steps, timed inside C."""
    lib = load()
    s = _state(state0)
    out = np.empty(16)
    return float(lib.gni_ex2_time(_ptr(s), float(h), int(steps), int(repeats), _ptr(out)))
