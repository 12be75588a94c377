"""Parsing and checking the options of the `gni` commands (numbers, vectors, `--set`, models,
methods, step sizes); each check raises :class:`~gnipy.cli.errors.UsageError` naming the option."""

from __future__ import annotations

import math

from .errors import UsageError

__all__ = ["MAX_CONVERGENCE_COUNT", "MAX_STEPS", "check_positive", "model_spec", "parse_R0", "parse_methods",
           "parse_set", "parse_vector", "prepare", "prepare_model", "step_counts"]

#: Bounds of `gni convergence`: step sizes per study, and steps per run (int32 step counters).
MAX_CONVERGENCE_COUNT = 1000
MAX_STEPS = 2**31 - 1


def parse_vector(option: str, text: str | None, n: int, names) -> tuple[float, ...] | None:
    """`a,b,...` (commas or spaces) as `n` finite numbers named `names`; None for None."""
    if text is None:
        return None
    parts = [s for s in text.replace(" ", ",").split(",") if s != ""]
    try:
        values = tuple(float(s) for s in parts)
    except ValueError:
        raise UsageError(option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {text!r}") from None
    if len(values) != n:
        raise UsageError(
            option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {len(values)} in {text!r}"
        )
    if not all(math.isfinite(x) for x in values):
        raise UsageError(option, f"contains NaN or infinite values: {text!r}")
    return values


def parse_set(items: list[str] | None) -> dict[str, float]:
    """`--set NAME=VALUE` (repeatable, or comma-separated) as `{name: value}`."""
    out: dict[str, float] = {}
    for item in items or []:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            name, eq, value = part.partition("=")
            name, value = name.strip(), value.strip()
            if not eq or not name or not value:
                raise UsageError("--set", f"expected NAME=VALUE, got {part!r}")
            try:
                x = float(value)
            except ValueError:
                raise UsageError("--set", f"parameter {name!r} must be a number, got {value!r}") from None
            if not math.isfinite(x):
                raise UsageError("--set", f"parameter {name!r} must be finite, got {value!r}")
            out[name] = x
    return out


def check_positive(option: str, value, kind: str = "number") -> None:
    """`value` (when given) is a positive finite `kind`."""
    if value is None:
        return
    if isinstance(value, float) and not math.isfinite(value):
        raise UsageError(option, f"must be a positive finite {kind}, got {value!r}")
    if value <= 0:
        raise UsageError(option, f"must be a positive {kind}, got {value!r}")


def model_spec(name: str):
    """The model MODEL names (a zoo name or a reference to the user's function), or a UsageError."""
    import gnipy

    try:
        return gnipy.get_model(name)
    except gnipy.InputError as e:
        raise UsageError("MODEL", str(e).partition(":")[2].strip()) from None


def prepare_model(model: str, set_items, q0_text, v0_text):
    """The model, its parameters and the initial condition (`--set`, `--q0`, `--v0` or the
    model's defaults); returns `(spec, params, q0, v0)`."""
    import gnipy

    spec = model_spec(model)
    try:
        params = spec.resolve_params(parse_set(set_items))
    except gnipy.InputError as e:
        raise UsageError("--set", str(e).partition(":")[2].strip()) from None
    names = spec.coordinates
    q0 = parse_vector("--q0", q0_text, len(names), names)
    vnames = spec.build(params).velocities  # (ẋ, ξ) on R^n × G: longer than x
    v0 = parse_vector("--v0", v0_text, len(vnames), vnames)
    dq, dv = spec.initial_condition(params)
    return spec, params, tuple(dq if q0 is None else q0), tuple(dv if v0 is None else v0)


def prepare(model: str, method: str, h, steps, t_final, set_items, q0_text, v0_text, save_every):
    """Check the options of a run (`gni run`, `gni demo`); returns `(spec, params, q0, v0)`."""
    import gnipy

    model_spec(model)
    if not gnipy.methods.is_method_name(method):
        raise UsageError("--method", f"unknown method {method!r} (known: {', '.join(gnipy.method_names())})")
    check_positive("--h", h)
    if (steps is None) == (t_final is None):
        raise UsageError("--steps/--t-final", "give exactly one of --steps and --t-final")
    check_positive("--steps", steps, "integer")
    check_positive("--t-final", t_final)
    check_positive("--save-every", save_every, "integer")
    # the step count now, not at the run: h below the normal range, t_final / h that overflows or is
    # more steps than any run can take, t_final not a whole number of steps (messages name the option)
    from gnipy.simulate import resolve_steps

    resolve_steps(h, steps, t_final)
    return prepare_model(model, set_items, q0_text, v0_text)


def parse_R0(spec, params, text: str | None):
    """The initial orientation (flattened row-major) for a model on R^n × G: `--R0`, else the
    model's documented one (None: the identity); None for models without a group part."""
    group = spec.build(params).group
    if group is None:
        if text is not None:
            raise UsageError("--R0", f"model {spec.name!r} has no orientation (no group part)")
        return None
    k = group.matrix_size
    if text is None:
        return tuple(spec.R0) if spec.R0 is not None else tuple(float(x) for x in group.identity().reshape(-1))
    return parse_vector("--R0", text, k * k, [f"r{i + 1}{j + 1}" for i in range(k) for j in range(k)])


def parse_methods(text: str) -> list[str]:
    """`--methods M1,M2` of `gni convergence`: known names, not the reference, without repeats."""
    import gnipy

    names = []
    for part in text.split(","):
        name = part.strip()
        if not name:
            continue
        if not gnipy.methods.is_method_name(name):
            raise UsageError("--methods", f"unknown method {name!r} (known: {', '.join(gnipy.method_names())})")
        if name == "reference":
            raise UsageError("--methods", "'reference' is the yardstick of the study, not a method to study")
        if name not in names:
            names.append(name)
    if not names:
        raise UsageError("--methods", f"give at least one method name, got {text!r}")
    return names


def step_counts(h_max: float, h_min: float, count: int, t_final: float) -> list[int]:
    """Whole numbers of steps for `count` log-spaced h from h_max down to h_min (distinct)."""
    import numpy as np

    for option, value in (("--h-max", h_max), ("--h-min", h_min), ("--t-final", t_final)):
        check_positive(option, value)
    if isinstance(count, bool) or count < 2:
        raise UsageError("--count", f"need at least 2 step sizes to fit an order, got {count!r}")
    if count > MAX_CONVERGENCE_COUNT:
        raise UsageError("--count", f"at most {MAX_CONVERGENCE_COUNT} step sizes, got {count!r}")
    if t_final / h_min > MAX_STEPS:
        raise UsageError("--t-final/--h-min", f"{t_final!r} / {h_min!r} is more than {MAX_STEPS:.0e} steps per run")
    if h_min >= h_max:
        raise UsageError("--h-min/--h-max", f"need h-min < h-max, got {h_min!r} and {h_max!r}")
    if h_max > t_final:
        raise UsageError("--h-max", f"larger than the final time {t_final!r}")
    counts = sorted({max(1, round(t_final / h)) for h in np.geomspace(h_max, h_min, count)})
    if len(counts) < 2:
        raise UsageError(
            "--count", f"the step sizes give only {len(counts)} distinct step count(s) on [0, {t_final:g}]; "
            "widen --h-max/--h-min"
        )
    return counts
