"""Shared test configuration: float64 JAX (gnipy enables it on import)."""

import gnipy  # noqa: F401


import pytest  # noqa: E402

from gnipy.compilation import release_compiled_programs_if_needed  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """After each test module, drop the compiled programs if the process holds many memory maps:
    the suite compiles hundreds of programs in one process, and XLA's CPU backend maps every
    kernel's code separately (vm.max_map_count would be exceeded; see gnipy.compilation)."""
    yield
    release_compiled_programs_if_needed(fraction=0.25)
