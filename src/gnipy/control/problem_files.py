"""Reading gnipy's TOML problem files (`gni control`, `gni fit`) and checking their entries.

A file is read as bytes, at most :data:`MAX_PROBLEM_BYTES`, and decoded as UTF-8; every value is
checked for its type before it is used (TOML's strings and booleans are never taken as numbers,
NaN and infinities are refused where a finite number is needed), and every error is an
:class:`~gnipy.errors.InputError` whose message starts with the key (`horizon.steps: ...`,
`system.params.m: ...`). The checks (`entry_number`, `entry_numbers`, `entry_table`, ...) are shared by
:mod:`gnipy.control.problems` and :mod:`gnipy.control.fit_problems`.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..system import System

__all__ = ["MAX_PROBLEM_BYTES", "problem_text", "read_problem"]

#: A problem file larger than this is refused before it is read (problem files are a few lines; a
#: large one is a mistake, e.g. a result file given as the problem).
MAX_PROBLEM_BYTES = 16 * 2**20


def problem_text(path) -> str:
    """The text of the problem file `path` as gnipy reads it to solve it (UTF-8, at most
    :data:`MAX_PROBLEM_BYTES`). Raises :class:`~gnipy.InputError` otherwise."""
    return read_problem(Path(path), "problem")[1]


def read_problem(source, name: str, also: str = "") -> tuple[dict, str, Path, str]:
    """`(data, text, directory, name)` of a problem given as a path (a string without a newline),
    TOML text or a parsed mapping; the directory is the file's (relative paths in it), else the
    working directory."""
    base, text = Path("."), ""
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source):
        path = Path(source)
        try:
            if path.is_file() and path.stat().st_size > MAX_PROBLEM_BYTES:
                raise InputError(f"problem: {str(path)!r} is {path.stat().st_size:,} bytes, larger than any problem "
                                 f"file ({MAX_PROBLEM_BYTES // 2**20} MiB): is it the problem file?")
            raw = path.read_bytes()
        except OSError as e:
            raise InputError(f"problem: cannot read {str(path)!r}: {e.strerror or e}") from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise InputError(f"problem: {str(path)!r} is not UTF-8 text (TOML files are): byte {raw[e.start]:#04x} "
                             f"at offset {e.start}") from None
        base, name, source = path.parent, path.stem, text
    if isinstance(source, str):
        try:
            return tomllib.loads(source), source, base, name
        except tomllib.TOMLDecodeError as e:
            raise InputError(f"problem: not valid TOML: {e}") from None
    if isinstance(source, Mapping):
        return dict(source), text, base, name
    raise InputError(f"problem: expected a path, TOML text, a mapping{' or ' + also if also else ''}, "
                     f"got {type(source).__name__}")


# ----------------------------------------------------------------------------------------------
# The entries, checked: a TOML value of the wrong type is refused naming its key (no coercion:
# "1" and true are not numbers), as are NaN, infinities and values out of range.
# ----------------------------------------------------------------------------------------------
def describe_entry(value) -> str:
    """What a TOML value is, for messages: `the string '1'`, `true (a boolean)`, `a table`..."""
    if value is None:
        return "nothing (the key is missing)"
    if isinstance(value, bool):
        return f"{str(value).lower()} (a boolean)"
    if isinstance(value, str):
        text = f"the string {value!r}"
    elif isinstance(value, Mapping):
        text = f"a table {dict(value)!r}"
    elif isinstance(value, list):
        text = f"a list {value!r}"
    elif isinstance(value, (int, float)):
        text = repr(value)
    else:
        text = f"{type(value).__name__} {value!r}"
    return text if len(text) <= 100 else text[:97] + "..."


def quoted_names(names) -> str:
    """The names, sorted and quoted, for a message: `'a', 'b'`."""
    return ", ".join(repr(n) for n in sorted(names, key=str))


def is_entry_number(value) -> bool:
    """Whether a TOML value is a number (an int or a float; a boolean is not)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def entry_table(data, key: str, *, required: bool = True) -> Mapping:
    """The section `[key]`: a table; when `required`, present and not empty."""
    sec = data.get(key)
    if sec is None:
        if required:
            raise InputError(f"{key}: missing section [{key}]")
        return {}
    if not isinstance(sec, Mapping):
        raise InputError(f"{key}: expected a table [{key}], got {describe_entry(sec)}")
    if required and not sec:
        raise InputError(f"{key}: the section [{key}] is empty")
    return sec


def refuse_unknown_keys(sec: Mapping, where: str, keys: set[str]) -> None:
    """Refuse keys a section does not have (a misspelt key would otherwise be a default)."""
    unknown = set(sec) - keys
    if unknown:
        raise InputError(f"{where}: unknown key(s) {quoted_names(unknown)}; expected {', '.join(sorted(keys))}")


def entry_text(where: str, value) -> str:
    """A TOML string; :class:`InputError` naming `where` otherwise."""
    if not isinstance(value, str):
        raise InputError(f"{where}: expected a string, got {describe_entry(value)}")
    return value


def entry_flag(where: str, value) -> bool:
    """A TOML boolean; :class:`InputError` naming `where` otherwise."""
    if not isinstance(value, bool):
        raise InputError(f"{where}: expected true or false, got {describe_entry(value)}")
    return value


def entry_number(where: str, value, *, positive: bool = False, nonnegative: bool = False) -> float:
    """A finite TOML number as a float, positive or >= 0 when asked; :class:`InputError` naming `where` otherwise."""
    if not is_entry_number(value):
        raise InputError(f"{where}: expected a {'positive ' if positive else ''}number, got {describe_entry(value)}")
    if not math.isfinite(value):
        raise InputError(f"{where}: must be finite, got {value!r}")
    if positive and value <= 0:
        raise InputError(f"{where}: must be positive, got {value!r}")
    if nonnegative and value < 0:
        raise InputError(f"{where}: must be >= 0, got {value!r}")
    return float(value)


def entry_integer(where: str, value, low: int, high: int, high_key: str = "") -> int:
    """A TOML integer from `low` to `high` (`high_key`: the key that sets `high`, named in the message)."""
    bound = f"{high:,}" + (f" ({high_key})" if high_key else "")
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"{where}: expected an integer from {low:,} to {bound}, got {describe_entry(value)}")
    if not low <= value <= high:
        raise InputError(f"{where}: must be an integer from {low:,} to {bound}, got {value:,}")
    return value


def entry_numbers(where: str, value, names: tuple[str, ...] | None = None) -> list[float]:
    """A list of finite numbers; with `names`, one per name."""
    if not isinstance(value, list) or not all(is_entry_number(x) for x in value):
        bad = next((x for x in value if not is_entry_number(x)), None) if isinstance(value, list) else None
        raise InputError(f"{where}: expected a list of numbers, got {describe_entry(value)}"
                         + (f" (holding {describe_entry(bad)})" if isinstance(value, list) and value else ""))
    if not all(math.isfinite(x) for x in value):
        raise InputError(f"{where}: contains NaN or infinite values")
    if names is not None and len(value) != len(names):
        raise InputError(f"{where}: expected {len(names)} number{'s' if len(names) != 1 else ''} (one per "
                         f"component: {', '.join(names)}), got {len(value)}")
    return [float(x) for x in value]


def _matrix(where: str, value, k: int | None = None) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise InputError(f"{where}: expected a matrix as a list of rows, got {describe_entry(value)}")
    rows = [entry_numbers(where, r) for r in value]
    if len({len(r) for r in rows}) != 1:
        raise InputError(f"{where}: rows of different lengths")
    R = np.asarray(rows)
    if k is not None and R.shape != (k, k):
        raise InputError(f"{where}: expected a {k}x{k} matrix, got {R.shape[0]}x{R.shape[1]}")
    return R


def entry_rotation(where: str, value, system: System) -> np.ndarray:
    """A k x k element of the system's group (e.g. a rotation on SO(3): RᵀR = I, det R > 0), by the
    group's own membership test (:meth:`gnipy.lie_groups.MatrixLieGroup.is_element`)."""
    if system.group is None:
        raise InputError(f"{where}: the model {system.name!r} has no orientation (no group part)")
    R = _matrix(where, value, system.group.matrix_size)
    if not np.all(np.isfinite(R)) or not system.group.is_element(R):
        why = "not finite" if not np.all(np.isfinite(R)) else system.group.why_not_element(R)
        raise InputError(f"{where}: {why}; give its entries to full precision")
    return R


def entry_method(where: str, value) -> str:
    """A method's name, known and differentiable (the solvers differentiate through its steps)."""
    from ..methods import get_method
    from ..reference import ContinuousReference

    name = entry_text(where, value)
    try:
        method = get_method(name)
    except InputError as e:
        head, sep, rest = str(e).partition(": ")
        raise InputError(f"{where}: {rest if sep and head == 'method' else e}") from None
    if isinstance(method, ContinuousReference):
        raise InputError(f"{where}: the continuous reference cannot be differentiated or traced; use an integrator")
    return name


def entry_params(spec, table, where: str) -> dict[str, float]:
    """A table of a model's parameters: known names, finite numbers."""
    if table is None:
        return {}
    if not isinstance(table, Mapping):
        raise InputError(f"{where}: expected a table {{name = value}}, got {describe_entry(table)}")
    unknown = set(table) - set(spec.params)
    if unknown:
        raise InputError(f"{where}: unknown parameter(s) {quoted_names(unknown)} of model {spec.name!r} (known: "
                         f"{', '.join(spec.params) or 'none'})")
    return {k: entry_number(f"{where}.{k}", v) for k, v in table.items()}


def entry_model(data, base: Path | None = None):
    """`(spec, params)` of `[system]`: the model (a zoo model's name, or a reference to the user's
    function `FILE.py:NAME` with FILE in `base`, the problem file's folder, or below it:
    :func:`gnipy.user_systems.data_file_reference`) and its parameters (the defaults updated)."""
    from ..registry import get_model
    from ..user_systems import data_file_reference, is_reference

    system_sec = entry_table(data, "system")
    refuse_unknown_keys(system_sec, "system", {"model", "params"})
    model = system_sec.get("model")
    if not isinstance(model, str):
        raise InputError(f"system.model: expected a model name (see `gni models`) or FILE.py:NAME, got "
                         f"{describe_entry(model)}")
    try:
        if is_reference(model):  # only a .py file beside the problem file (gnipy.user_systems)
            model = data_file_reference(model, Path(".") if base is None else base, "system.model")
        spec = get_model(model)
    except (KeyError, ValueError, InputError) as e:
        raise InputError(f"system.model: {str(e).strip(chr(39))}") from None
    params = spec.resolve_params(entry_params(spec, system_sec.get("params"), "system.params"))
    return spec, params


def build_model_system(spec, params, where: str) -> System:
    """The model's System for `params`; a failure names `where` (the parameters' key)."""
    try:
        return spec.build(params)
    except InputError as e:
        raise InputError(f"{where}: the model {spec.name!r} cannot be built with these parameters: {e}") from None
    except (ArithmeticError, ValueError, TypeError) as e:  # the model's own code, on values it cannot take
        raise InputError(f"{where}: the model {spec.name!r} cannot be built with these parameters: "
                         f"{type(e).__name__}: {e}") from None


def entry_start(start: Mapping, system: System, spec, params, where: str = "start"):
    """`(q0, v0, R0)` of `[start]`, checked against the model (the model's defaults where absent)."""
    q0 = tuple(entry_numbers(f"{where}.q0", start["q0"], system.coordinates)) if "q0" in start else None
    v0 = tuple(entry_numbers(f"{where}.v0", start["v0"], system.velocities)) if "v0" in start else None
    R0 = entry_rotation(f"{where}.R0", start["R0"], system) if "R0" in start else None
    if q0 is None or v0 is None:
        try:
            dq, dv = spec.initial_condition(params)
        except (InputError, ArithmeticError, ValueError, TypeError) as e:
            raise InputError(f"{where}: the model's default start cannot be computed for these parameters ({e}); "
                             f"give {where}.q0 and {where}.v0") from None
        q0 = dq if q0 is None else q0
        v0 = dv if v0 is None else v0
    return q0, v0, R0
