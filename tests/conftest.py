"""Shared test configuration: float64 JAX (gnipy enables it on import), and XLA's programs compiled
for compile time rather than run time (:data:`SUITE_XLA_FLAGS`)."""

import os

#: The XLA flags of the test processes (this one, pytest-xdist's workers and every process a test
#: starts: the doc pages, the CLI's subprocesses, dask's workers). Most of the suite's time is XLA
#: compiling programs that then run a few hundred steps, so the flags trade run time for compile
#: time; none changes what a program computes except the first (measured on the 2-core machine):
#:
#: - LLVM's optimization passes off: programs compile about a quarter faster and run about twice
#:   slower (the first call of the rolling ball 3.06 → 2.22 s, of the Chaplygin top 6.03 → 4.27 s;
#:   the suite 16 min 46 s → 12 min 34 s). The programs users run keep XLA's default (-O2), which
#:   rounds some operations differently (fused multiply-adds: runs of 200 steps agree to ≤ 4e-15):
#:   tests/test_compiled_as_shipped.py runs one model of each structure with each family of solves
#:   compiled both ways and holds them equal to round-off, and `GNIPY_TEST_SHIPPED_XLA=1 pytest`
#:   runs the whole suite as shipped;
#: - LLVM's code generation in one piece rather than split into parallel parts (the split costs
#:   CPU that the two workers already use): a process running the rolling ball's and the Chaplygin
#:   top's first calls 5.5 → 5.05 s of CPU;
#: - two HLO passes off that only move computations (no arithmetic changes): hoisting what a loop
#:   does not change out of the loop, and moving reshapes across elementwise operations. The
#:   bicycle's gni-trapezoid program (36,000 HLO instructions) compiles in 16 s instead of 25 s;
#:   the two first calls above, 4.1 s of CPU instead of 4.7 s.
SUITE_XLA_FLAGS = (
    "--xla_backend_optimization_level=0",
    "--xla_cpu_parallel_codegen_split_count=1",
    "--xla_disable_hlo_passes=while-loop-invariant-code-motion,reshape-mover",
)
if os.environ.get("GNIPY_TEST_SHIPPED_XLA", "").strip() in ("", "0"):
    # before the first computation: XLA reads the flags when JAX starts its backend (importing gnipy
    # starts none: tests/test_compiled_as_shipped.py checks it)
    _flags = os.environ.get("XLA_FLAGS", "").split()
    os.environ["XLA_FLAGS"] = " ".join([*_flags, *(f for f in SUITE_XLA_FLAGS if f not in _flags)])

#: JAX's persistent compilation cache, shared by every process of the session: the pytest-xdist
#: workers, the doc pages' processes and the `gni` commands tests start. The suite compiles the
#: same programs in several processes (two workers; the pages and commands each start afresh; a
#: worker that releases its compiled programs, :func:`_release_compiled_programs`, compiles them
#: again), and a program found in the cache is loaded instead. It changes how long a test takes,
#: not what it computes: the cache is keyed by the program and the compiler's flags. The folder is
#: made by the first process (pytest's, or the only one without xdist), private (mkdtemp: 0700,
#: what gnipy.compilation requires), and removed when that process exits;
#: `GNIPY_TEST_NO_COMPILATION_CACHE=1` turns it off.
SESSION_CACHE = "GNIPY_TEST_SESSION_CACHE"
if os.environ.get("GNIPY_TEST_NO_COMPILATION_CACHE", "").strip() in ("", "0"):
    if not os.environ.get(SESSION_CACHE):
        import atexit
        import shutil
        import tempfile

        os.environ[SESSION_CACHE] = tempfile.mkdtemp(prefix="gnipy-test-session-")
        atexit.register(shutil.rmtree, os.environ[SESSION_CACHE], True)
    from gnipy.compilation import enable_compilation_cache  # noqa: E402

    enable_compilation_cache(os.environ[SESSION_CACHE], min_compile_seconds=0.1)

import gnipy  # noqa: E402


import pathlib  # noqa: E402

import pytest  # noqa: E402

from gnipy.compilation import release_compiled_programs_if_needed  # noqa: E402


#: The files left out of the contributors' inner loop, `pytest -m "not slow"` (README, "What is
#: checked"): the exhaustive sweeps over models x methods, the docs and examples run as written,
#: the experiments, the CLI end to end, control and the native backend's equalities, each more
#: than about 12 s of CPU (measured with `--durations=0` on the 2-core machine). What stays is the
#: core's unit level (the Problem, the driver, the GNI, groups, retractions, systems, files,
#: inputs, the layers), about 1 min 40 s. The whole suite, `pytest`, is the CI command and runs
#: them all; a test is also `slow` by its own `@pytest.mark.slow`.
SLOW_FILES = frozenset({
    "analysis", "test_doc_examples.py", "test_examples.py", "test_gradients.py", "test_monitor.py",
    "test_forcing.py", "test_ensembles.py", "test_diagnostics.py", "test_sweep.py", "test_streaming.py",
    "test_streaming_integrity.py", "test_sweep_integrity.py", "test_cli.py", "test_cli_fuzz.py", "test_sharding.py",
    "test_spaces.py", "test_group_maps.py", "test_api_fuzz.py", "test_properties.py", "test_benchmark_numba.py",
    "test_benchmark_baselines.py", "test_convergence_orders.py", "test_lie_groups.py",
    "integrators/test_no_false_failures.py", "integrators/test_discrete_gradient.py",
    "integrators/test_gni_variants.py", "integrators/test_reversal.py", "integrators/test_composition.py",
    "integrators/test_roundoff.py", "integrators/test_paper_schemes.py", "integrators/test_comparators.py",
    "integrators/test_reduced_rattle.py", "integrators/test_energy_theorem.py",
    "native/test_backend.py", "native/test_primitives.py",
    "control/test_optimal_control.py", "control/test_identification.py", "control/test_step_shooting.py",
    "models/test_group_models.py", "models/test_rolling_ball.py", "models/test_default_methods.py",
    "models/test_decisive_models.py", "models/test_whipple_bicycle.py", "models/test_rattleback.py",
    "models/test_rolling_disk.py", "models/test_differential_drive.py",
    "test_symbolic.py", "test_holonomic.py",
    "experiments", "cli",
})


def pytest_collection_modifyitems(config, items):
    """Mark the tests of :data:`SLOW_FILES` (files, or folders of tests/) `slow`."""
    root = pathlib.Path(__file__).parent
    for item in items:
        rel = pathlib.Path(str(item.fspath)).relative_to(root).as_posix()
        if rel in SLOW_FILES or rel.split("/")[0] in SLOW_FILES:
            item.add_marker(pytest.mark.slow)


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """After each test module, drop the compiled programs if the process holds many memory maps:
    the suite compiles hundreds of programs in one process, and XLA's CPU backend maps every
    kernel's code separately (vm.max_map_count would be exceeded; see gnipy.compilation)."""
    yield
    release_compiled_programs_if_needed(fraction=0.25)


@pytest.fixture(autouse=True, scope="module")
def _verdicts_at_saved_nodes(request):
    """A test module that sets `CHECK_EVERY_NODE = False` runs `gnipy.simulate` with
    `check_every_node=False` by default: modules that test the numerics (orders, equalities with
    the paper's schemes, round-off, reversibility, backends) and not the verdicts, whose hundreds
    of programs then compile without the every-node check (about 1-3 s each for the GNI family,
    which put the suite over its time budget). The check itself is tested in test_monitor.py,
    test_diagnostics.py and wherever verdicts are asserted; streamed runs and sweeps always check."""
    defaults = gnipy.simulate.__kwdefaults__
    if getattr(request.module, "CHECK_EVERY_NODE", True):
        yield
        return
    defaults["check_every_node"] = False
    try:
        yield
    finally:
        defaults["check_every_node"] = True


@pytest.fixture
def lock_holder():
    """`hold(path)`: another process holding the output lock of `path` (as a running gnipy writer
    does, gnipy.files.output_lock) until the test ends; returns the process (its `pid`)."""
    import subprocess
    import sys
    import textwrap

    started = []

    def hold(path):
        script = textwrap.dedent(f"""
            import sys
            from gnipy.files import output_lock
            with output_lock({str(path)!r}):
                print("held", flush=True)
                sys.stdin.read()
        """)
        p = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             text=True)
        started.append(p)
        assert p.stdout.readline().strip() == "held"
        return p

    yield hold
    for p in started:
        if p.poll() is None:
            p.stdin.close()
            p.wait(timeout=60)
