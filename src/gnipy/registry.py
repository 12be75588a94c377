"""The model registry: each model is a :class:`ModelSpec` with parameters, defaults, and its exact
solution or invariants where known.

The zoo (:mod:`gnipy.models`) registers its models here; the driver (:func:`gnipy.simulate`, the
streamed runs, the sweeps) looks up a system's default method and registered invariants by its
name, so it depends on this table and not on the models above it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax

from .errors import InputError
from .system import System

__all__ = ["ModelSpec", "FALLBACK_METHOD", "set_default_methods", "register", "get_model", "model_names", "make_system",
           "registered_invariants", "default_method_for"]


@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """A model of the zoo.

    Attributes:
        name: the CLI name (e.g. `"nonholonomic-particle"`).
        description: one line.
        build: `build(params: dict[str, float]) -> System`.
        params: parameter names and default values.
        coordinates: the names of q.
        q0, v0: the documented initial condition for the default parameters (on R^n × G, `q0`
            holds x and `v0` the velocity (ẋ, ξ) with ξ in the group's vee coordinates).
        R0: the documented initial orientation on R^n × G, flattened row-major (None: identity).
        default_ic: optional `default_ic(params) -> (q0, v0)` when the default initial condition
            depends on the parameters (it must satisfy the constraints).
        exact: optional `exact(params, q0, v0, t) -> (q, v)` (t an array; returns arrays (T, n)
            and (T, N)); it may return None for parameters without a closed form.
        invariants: conserved quantities by name: `f(params, q, v) -> scalar`, or
            `f(params, q, v, R) -> scalar` for models whose functions depend on the orientation.
        notes: longer documentation.
    """

    name: str
    description: str
    build: Callable[[dict[str, float]], System]
    params: Mapping[str, float]
    coordinates: tuple[str, ...]
    q0: tuple[float, ...]
    v0: tuple[float, ...]
    R0: tuple[float, ...] | None = None
    default_ic: Callable[[dict[str, float]], tuple[Any, Any]] | None = None
    exact: Callable[..., Any] | None = None
    invariants: Mapping[str, Callable[..., Any]] = dataclasses.field(default_factory=dict)
    notes: str = ""

    def resolve_params(self, overrides: Mapping[str, Any] | None = None) -> dict[str, float]:
        """Defaults updated with `overrides`; unknown names, values that are not numbers (a string or
        a boolean is not one) and non-finite values raise InputError."""
        import math

        from .inputs import is_text_or_bool

        if overrides is not None and not isinstance(overrides, Mapping):
            raise InputError(f"params: expected a mapping of parameter names to numbers, got {overrides!r}")
        params = dict(self.params)
        for k, v in (overrides or {}).items():
            if k not in params:
                known = ", ".join(params) or "none"
                raise InputError(f"params: unknown parameter {k!r} of model {self.name!r} (known: {known})")
            if isinstance(v, jax.core.Tracer):  # differentiated with respect to it (jax.grad): kept traced
                params[k] = v
                continue
            if is_text_or_bool(v):
                raise InputError(f"params: parameter {k!r} must be a number, got {type(v).__name__} {v!r}")
            try:
                v = float(v)
            except (TypeError, ValueError) as e:
                raise InputError(f"params: parameter {k!r} must be a number, got {v!r}") from e
            if not math.isfinite(v):
                raise InputError(f"params: parameter {k!r} must be finite, got {v!r}")
            params[k] = v
        return params

    def initial_condition(self, params: Mapping[str, float]) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The documented initial condition for these parameters."""
        if self.default_ic is not None:
            q0, v0 = self.default_ic(dict(params))
            return tuple(float(x) for x in q0), tuple(float(x) for x in v0)
        return self.q0, self.v0

    @property
    def default_method(self) -> str:
        """The method that runs when none is named, chosen from measurements
        (:mod:`gnipy.models.default_methods`)."""
        return _DEFAULT_METHODS.get(self.name, (FALLBACK_METHOD, ""))[0]

    @property
    def default_reason(self) -> str:
        """Why :attr:`default_method` (the measurements that chose it)."""
        return _DEFAULT_METHODS.get(self.name, ("", "not measured: the library-wide default"))[1]

    def system(self, **overrides) -> System:
        """Build the System for the defaults updated with `overrides`."""
        params = self.resolve_params(overrides)
        return self.build(params)


_REGISTRY: dict[str, ModelSpec] = {}

#: The default for systems that are not zoo models (symmetric, order 2, diagnosed; explicit for a
#: constant metric on R^n).
FALLBACK_METHOD = "gni-trapezoid"

#: model name -> (method, why): filled by :mod:`gnipy.models.default_methods` (the measurements).
_DEFAULT_METHODS: dict[str, tuple[str, str]] = {}


def set_default_methods(table: Mapping[str, tuple[str, str]]) -> None:
    """Record the models' measured default methods, `name -> (method, why)`."""
    _DEFAULT_METHODS.update(table)


def register(spec: ModelSpec) -> ModelSpec:
    """Add a model to the registry (names are unique)."""
    if spec.name in _REGISTRY:
        raise ValueError(f"model {spec.name!r} registered twice")
    _REGISTRY[spec.name] = spec
    return spec


def get_model(name: str) -> ModelSpec:
    """The model called `name`; unknown names raise InputError listing the known ones."""
    if name not in _REGISTRY:
        raise InputError(f"model: unknown model {name!r} (known: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


def model_names() -> list[str]:
    """Names of all registered models."""
    return sorted(_REGISTRY)


def make_system(name: str, **params) -> System:
    """Build the System of model `name` with parameters overriding the defaults."""
    return get_model(name).system(**params)


def registered_invariants(name: str) -> tuple[str, ...]:
    """The names of the invariants registered for the model called `name` (none for other systems)."""
    spec = _REGISTRY.get(name)
    return tuple(spec.invariants) if spec is not None else ()


def default_method_for(system_name: str) -> str:
    """The default method of the zoo model `system_name`, or the library-wide default for other systems."""
    spec = _REGISTRY.get(system_name)
    return spec.default_method if spec is not None else FALLBACK_METHOD
