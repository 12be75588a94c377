"""Shared test configuration: float64 JAX (gnipy enables it on import)."""

import gnipy


import pytest  # noqa: E402

from gnipy.compilation import release_compiled_programs_if_needed  # noqa: E402


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
