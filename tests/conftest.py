"""Shared test configuration: float64 JAX (gnipy enables it on import)."""

import gnipy  # noqa: F401
