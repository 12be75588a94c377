"""Checks and conversions of the values users pass in: real arrays and vectors (an
:class:`~gnipy.errors.InputError` naming the argument otherwise), float64 computation, and the
concrete value of a possibly traced number.
"""

from __future__ import annotations

import math
import numbers

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


def is_traced(*trees) -> bool:
    """Whether any leaf of the pytrees `trees` is a JAX tracer (the call is under a transformation)."""
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(trees))


def provenance_number(x) -> float:
    """A provenance number: `float(x)`, or for a value traced by JAX (a parameter being
    differentiated) its value where known now, else NaN (the arrays of the functions carry it)."""
    c = concrete_value(x)
    return float("nan") if c is None else float(c)


def is_text_or_bool(x) -> bool:
    """Whether `x` is a string, bytes or a boolean (scalar or array): values that `float()` and
    NumPy would turn into numbers (`"0.01"`, `True`) but that gnipy never takes as one."""
    if isinstance(x, (str, bytes, bool, np.bool_)):
        return True
    dtype = getattr(x, "dtype", None)
    return dtype is not None and getattr(dtype, "kind", "") in ("U", "S", "b")


def is_real_scalar(x) -> bool:
    """Whether `x` is a real scalar (Python, NumPy or JAX): a bool is not, though Python counts it
    as an int, nor a string, though `float()` converts it, nor a complex number."""
    kind = getattr(getattr(x, "dtype", None), "kind", None)
    if kind is not None:
        return kind in ("i", "u", "f") and np.ndim(x) == 0
    return isinstance(x, numbers.Real) and not isinstance(x, bool)


def _leaves(x):
    """The entries of nested lists and tuples."""
    if isinstance(x, (list, tuple)):
        for e in x:
            yield from _leaves(e)
    else:
        yield x


def refuse_text_or_bool(name: str, x, what: str = "a number") -> None:
    """:class:`InputError` naming `name` when `x` is a string, bytes or a boolean (scalars, or
    arrays/sequences holding them): `"1"` and `True` are not numbers, whatever `float()` says."""
    for v in _leaves(x):
        if is_text_or_bool(v):
            where = "" if v is x else f" in {_short(x)}"
            raise InputError(f"{name}: expected {what}, got {type(v).__name__} {_short(v)}{where}")
    dtype = getattr(x, "dtype", None)
    if getattr(dtype, "kind", "") == "O" and any(is_text_or_bool(e) for e in np.asarray(x).ravel()):
        raise InputError(f"{name}: expected {what}, got strings or booleans in {_short(x)}")


def flag(name: str, x) -> bool:
    """`x` as a bool; :class:`InputError` naming `name` unless it is `True` or `False` (a NumPy
    boolean too): `"no"`, `0` and `None` are not flags (`"no"` would be true)."""
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    raise InputError(f"{name}: expected True or False, got {x!r}")


def real_number(name: str, x, *, lower: float | None = None, strict: bool = False) -> float:
    """`x` as a finite float; :class:`InputError` naming `name` for what is not a real number (a
    string, a boolean or a complex number is not one), not finite, or below `lower` (at or below
    it when `strict`)."""
    if not is_real_scalar(x):
        raise InputError(f"{name}: expected a number, got {type(x).__name__} {_short(x)}")
    value = float(x)
    if not math.isfinite(value):
        raise InputError(f"{name}: must be finite, got {x!r}")
    if lower is not None and (value <= lower if strict else value < lower):
        raise InputError(f"{name}: must be {'>' if strict else '>='} {lower:g}, got {x!r}")
    return value


def finite_number(name: str, x) -> float:
    """`x` as a finite float (:func:`real_number` without bounds)."""
    return real_number(name, x)


def positive_integer(name: str, x, error: type[InputError] = InputError) -> int:
    """`x` as an int of at least 1; `error` (:class:`InputError` or a subclass) naming `name` otherwise:
    a bool, a float (even a whole one) or a string is not an integer here."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, np.integer)) or x < 1:
        raise error(f"{name}: must be a positive integer, got {x!r}")
    return int(x)


def whole_number(name: str, x, low: int, high: int) -> int:
    """`x` as an int from `low` to `high`; :class:`InputError` naming `name` otherwise (a bool, a
    float or a string is not an integer here)."""
    kind = getattr(getattr(x, "dtype", None), "kind", None)
    if isinstance(x, bool) or not (isinstance(x, numbers.Integral) or kind in ("i", "u")) or np.ndim(x) != 0:
        raise InputError(f"{name}: must be an integer from {low:,} to {high:,}, got {type(x).__name__} {_short(x)}")
    if not low <= int(x) <= high:
        raise InputError(f"{name}: must be an integer from {low:,} to {high:,}, got {int(x):,}")
    return int(x)


def _short(x, limit: int = 80) -> str:
    text = repr(x)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def format_scientific(x: float) -> str:
    """`x` in scientific notation with 4 significant digits (`1.234e-05`), as error messages quote values."""
    return f"{float(x):.3e}"


def real_array(name: str, x, what: str = "real numbers") -> np.ndarray:
    """`x` as a float64 array; :class:`InputError` naming `name` if it holds anything but real
    numbers: strings, booleans and `None` are not numbers, though NumPy would convert them
    (`"1"` to 1, `True` to 1, `None` to NaN), and complex values are refused (an imaginary part
    would otherwise be dropped with only a NumPy warning)."""
    for v in _leaves(x) if isinstance(x, (list, tuple)) else ():
        if not (is_real_scalar(v) or getattr(getattr(v, "dtype", None), "kind", None) in ("i", "u", "f")):
            complex_ = isinstance(v, complex) or getattr(getattr(v, "dtype", None), "kind", None) == "c"
            raise InputError(f"{name}: expected {what}, got "
                             + ("complex values (gnipy integrates real systems)" if complex_ else
                                f"{type(v).__name__} {_short(v)} in {_short(x)}"))
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name}: expected {what}, got {_short(x)}") from e
    if a.dtype.kind in ("U", "S", "b"):
        raise InputError(f"{name}: expected {what}, got {'booleans' if a.dtype.kind == 'b' else 'strings'}"
                         f" ({_short(x)})")
    if a.dtype.kind == "O":  # None, or objects NumPy could not make numbers of
        if a.size == 0 or not all(is_real_scalar(e) for e in a.ravel()):
            raise InputError(f"{name}: expected {what}, got {_short(x)}")
    if a.dtype.kind == "c":
        raise InputError(f"{name}: expected {what}, got complex values (gnipy integrates real systems)")
    try:
        return np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as e:
        raise InputError(f"{name}: expected {what}, got {_short(x)}") from e


def require_float64() -> None:
    """:class:`InputError` unless JAX computes in float64 (`jax_enable_x64`, which importing
    gnipy turns on): in float32 nothing gnipy computes reaches its stated accuracy."""
    if not jax.config.jax_enable_x64:
        raise InputError(
            "jax_enable_x64: gnipy computes in float64, but JAX's jax_enable_x64 is off (something turned it "
            "off after importing gnipy); turn it back on with jax.config.update('jax_enable_x64', True)"
        )


def finite_vector(name: str, x, n: int) -> np.ndarray:
    """`x` as a float64 vector of length `n` with finite entries; :class:`InputError` naming `name` otherwise."""
    a = real_array(name, x, f"{n} real numbers")
    if a.ndim != 1 or a.shape[0] != n:
        raise InputError(f"{name}: expected a vector of length {n}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or infinite values: {a.tolist()}")
    return a
