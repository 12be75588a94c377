"""Checks and conversions of the values users pass in: real arrays and vectors (an
:class:`~gnipy.errors.InputError` naming the argument otherwise), float64 computation, and the
concrete value of a possibly traced number.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from .errors import InputError


def concrete_value(x):
    """The value of `x` when it is known now (a Python/NumPy value, or a tracer of `jax.grad` or
    `jax.jacfwd` called outside `jit`), else None (an abstract tracer of `jax.jit`)."""
    if not isinstance(x, jax.core.Tracer):
        return x
    try:
        from jax._src.core import to_concrete_value  # private: absent in some versions, then None

        return to_concrete_value(x)
    except Exception:  # pragma: no cover
        return None


def _number(x) -> float:
    """A provenance number: `float(x)`, or for a value traced by JAX (a parameter being
    differentiated) its value where known now, else NaN (the arrays of the functions carry it)."""
    c = concrete_value(x)
    return float("nan") if c is None else float(c)


def finite_number(name: str, x) -> float:
    """`float(x)`; :class:`InputError` naming `name` when `x` is not a number or not finite."""
    try:
        value = float(x)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name}: expected a number, got {x!r}") from e
    if not math.isfinite(value):
        raise InputError(f"{name}: must be finite, got {x!r}")
    return value


def _fmt(x: float) -> str:
    return f"{float(x):.3e}"


def real_array(name: str, x, what: str = "real numbers") -> np.ndarray:
    """`x` as a float64 array; :class:`InputError` naming `name` if it is not numbers, or is
    complex (an imaginary part would otherwise be dropped with only a NumPy warning)."""
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name}: expected {what}, got {x!r}") from e
    if a.dtype.kind == "c":
        raise InputError(f"{name}: expected {what}, got complex values (gnipy integrates real systems)")
    try:
        return np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as e:
        raise InputError(f"{name}: expected {what}, got {x!r}") from e


def require_float64() -> None:
    """:class:`InputError` unless JAX computes in float64 (`jax_enable_x64`, which importing
    gnipy turns on): in float32 nothing gnipy computes reaches its stated accuracy."""
    if not jax.config.jax_enable_x64:
        raise InputError(
            "jax_enable_x64: gnipy computes in float64, but JAX's jax_enable_x64 is off (something turned it "
            "off after importing gnipy); turn it back on with jax.config.update('jax_enable_x64', True)"
        )


def _as_vector(name: str, x, n: int) -> np.ndarray:
    a = real_array(name, x, f"{n} real numbers")
    if a.ndim != 1 or a.shape[0] != n:
        raise InputError(f"{name}: expected a vector of length {n}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or infinite values: {a.tolist()}")
    return a
