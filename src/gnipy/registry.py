"""The model registry: each model is a :class:`ModelSpec` with parameters, defaults, and its exact
solution or invariants where known.

The zoo (:mod:`gnipy.models`) registers its models here; the driver (:func:`gnipy.simulate`, the
streamed runs, the sweeps) looks up a system's default method and registered invariants by its
`model` (:attr:`gnipy.System.model`: set on the systems the zoo builds, None on a System written
by hand whatever its `name`), so it depends on this table and not on the models above it."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax

from .errors import InputError
from .system import System
from .system_checks import default_point
from .text import safe
from .user_systems import is_reference, load, user_code_error

__all__ = ["ModelSpec", "FALLBACK_METHOD", "FALLBACK_METHODS", "set_default_methods", "set_method_lookup", "method_table",
           "register", "get_model", "model_from_function", "model_names", "make_system", "registered_invariants",
           "default_method_for"]


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
        origin: for a user's system (:func:`model_from_function`), `(reference, digest)`: how to
            load it again and the SHA-256 of its source; None for the zoo's models.
        positive: the parameters that are positive by their meaning (masses, moments of inertia,
            lengths): :func:`gnipy.fit` bounds their estimates below by 0 unless told otherwise.
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
    origin: tuple[str, str | None] | None = None
    positive: tuple[str, ...] = ()

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
        return _DEFAULT_METHODS.get(self.name, ("", f"not measured: the default of systems the atlas has not measured "
                                                     f"({FALLBACK_METHOD}, qualified on 16 of the 17 zoo models)"))[1]

    def system(self, **overrides) -> System:
        """Build the System for the defaults updated with `overrides`."""
        params = self.resolve_params(overrides)
        return self.build(params)


_REGISTRY: dict[str, ModelSpec] = {}

#: The default for systems the atlas has not measured (a user's own System, a zoo model without a
#: record): a method qualified on all but one of the zoo models by the atlas's rule
#: (:attr:`gnipy.experiments.method_choice.MethodMeasurement.qualifies`: the long run completes,
#: raises no run-time warning and keeps the energy and every registered invariant to 1e-2). Measured
#: on 2026-11-26 (commit d0204c7) with the atlas's own measurement
#: (:func:`gnipy.experiments.atlas.measure_model`, the full plans: h = 0.01, 10⁵ steps, 10⁶ on three
#: models, error over t <= 200; reversibility not measured, it is not part of the rule) for
#: gni-trapezoid, sgni-trapezoid, sgni-midpoint, dla and discrete-gradient on all 15 zoo models:
#: sgni-trapezoid, sgni-midpoint and dla qualify on all 15; gni-trapezoid fails on chaplygin-sleigh,
#: chaplygin-sleigh-se2 and suslov (its hidden momentum leaves its O(h) band at t = 19-28: position
#: errors 280, 294, 2.0), discrete-gradient does not apply to the three orientation-dependent models
#: and drifts on nonholonomic-particle-gauge (1.05e-2). Among the three, the rule
#: (:func:`~gnipy.experiments.method_choice.choose`) picks sgni-trapezoid on 9 models, dla on 4 and
#: sgni-midpoint on 2; the sgni keep the constraints to round-off (the rule's first tie-break; dla's
#: reported velocities miss them by up to 4.7e-2), and the trapezoid is symmetric on every system
#: (the midpoint is not where l depends on R, with Cayley's retraction). The table is in the atlas
#: guide (docs/user-guide/atlas.md, "Systems the atlas has not measured").
#:
#: Measured again on 2026-11-28 for the two models added since (`gni atlas --models
#: rolling-disk,differential-drive`, the full plans): on rolling-disk the three qualify (errors 8.8e-4,
#: 8.8e-4, 7.8e-4; the rule picks sgni-trapezoid); on differential-drive only dla does. There the two
#: sgni keep the energy (7.5e-6, 3.8e-6) and follow the reference as closely as dla (1.0e-2 and 5.2e-3
#: against 1.9e-2 over t <= 200), but φ − r(θ_R − θ_L)/2b, which the difference of the two rolling
#: rows makes a constant of the motion (its coefficients are constant), drifts by 11.6 and 5.8 rad
#: over the 10⁵ steps, in which the wheels turn through about 10⁴ rad: a velocity constraint held at
#: the nodes does not make the position increments keep its integral, where dla's discrete constraint
#: on q_{k+1} − q_k does (2.9e-7). sgni-trapezoid stays the fallback (16 of 17, and the reasons
#: above); dla, next in FALLBACK_METHODS, is the one method that qualifies on all 17.
FALLBACK_METHOD = "sgni-trapezoid"

#: The methods qualified on all the zoo models or all but one (the measurements above), in the order the default tries
#: them: a system that the first cannot run (its :meth:`~gnipy.integrators.base.Integrator.check`
#: raises :class:`~gnipy.MethodError`) gets the next that can (:func:`default_method_for`).
FALLBACK_METHODS = ("sgni-trapezoid", "sgni-midpoint", "dla")

#: model name -> (method, why): filled by :mod:`gnipy.models.default_methods` (the measurements).
_DEFAULT_METHODS: dict[str, tuple[str, str]] = {}


def set_default_methods(table: Mapping[str, tuple[str, str]]) -> None:
    """Record the models' measured default methods, `name -> (method, why)`."""
    _DEFAULT_METHODS.update(table)


#: method name -> a fresh integrator object (:func:`gnipy.methods.get_method`, a layer above this
#: table, which sets it): how :func:`default_method_for` asks a method whether it can run a system.
_METHOD_LOOKUP: Callable[[str], Any] | None = None

#: The names of the registered methods (:func:`gnipy.methods.method_names`, set with the lookup).
_METHOD_NAMES: Callable[[], list[str]] | None = None


def set_method_lookup(lookup: Callable[[str], Any], names: Callable[[], list[str]] | None = None) -> None:
    """Record how a method name becomes an integrator object and, with `names`, which names the
    registered methods have (set by :mod:`gnipy.methods`)."""
    global _METHOD_LOOKUP, _METHOD_NAMES
    _METHOD_LOOKUP = lookup
    _METHOD_NAMES = names


def method_table() -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """`(get_method, method_names)` of :mod:`gnipy.methods` (a layer above the integrators, which
    ask it which registered methods there are), as :func:`set_method_lookup` recorded them."""
    if _METHOD_LOOKUP is None or _METHOD_NAMES is None:
        from .errors import MethodError

        raise MethodError("the method table (gnipy.methods) is not loaded; import gnipy")
    return _METHOD_LOOKUP, _METHOD_NAMES


def register(spec: ModelSpec) -> ModelSpec:
    """Add a model to the registry (names are unique); returns the registered spec, whose `build`
    returns its systems recorded as the model (:meth:`gnipy.System.as_model`): the model's
    invariants and measured default method apply to them, and to no System that only shares its
    name."""
    if spec.name in _REGISTRY:
        raise ValueError(f"model {spec.name!r} registered twice")
    build, model, names = spec.build, spec.name, tuple(spec.params)

    def rebuild(values):
        if not set(values) <= set(names):  # a named parameter the model does not take
            return None
        return build(dict(spec.params) | values)

    def build_as_model(params):
        return build(params).as_model(model, rebuild)

    spec = dataclasses.replace(spec, build=build_as_model)
    _REGISTRY[spec.name] = spec
    return spec


def get_model(name: str) -> ModelSpec:
    """The model called `name`: a zoo model's name (:func:`model_names`), or a reference to the
    user's own system, `path/to/file.py:NAME` or `package.module:NAME` (NAME a function that returns
    a :class:`~gnipy.System`, or a System), loaded as :mod:`gnipy.user_systems` says (a file that
    another user could have written is refused before it runs) and made a model by
    :func:`model_from_function`. Unknown names raise InputError listing the known ones."""
    if is_reference(name):
        loaded = load(name)
        key = (loaded.reference, loaded.digest, id(loaded.obj))
        spec = _USER_MODELS.get(key)
        if spec is None:
            spec = _USER_MODELS[key] = model_from_function(loaded.obj, reference=loaded.reference,
                                                           digest=loaded.digest)
        return spec
    if not isinstance(name, str):
        raise InputError(f"model: expected a model name or a reference FILE.py:NAME, got {type(name).__name__}")
    if name not in _REGISTRY:
        raise InputError(f"model: unknown model {name!r} (known: {', '.join(sorted(_REGISTRY))})")
    return _REGISTRY[name]


#: The user's models made in this process: (reference, digest, id of the function) -> spec (one spec,
#: and so one build function, per source: their runs share compilations).
_USER_MODELS: dict[tuple, ModelSpec] = {}


def model_from_function(function, *, reference: str | None = None, digest: str | None = None) -> ModelSpec:
    """A model (:class:`ModelSpec`) of the user's function that builds a System.

    Arguments:
        function: `function(**params) -> System`; its parameters that have a number as default
            are the model's parameters, with those defaults (what `--set`, sweeps and `fit`
            reach); parameters with other defaults are left to theirs; a parameter without a
            default is refused. A :class:`~gnipy.System` itself is a model without parameters.
        reference: how to load it again (`FILE.py:NAME` or `module:NAME`); default the function's
            `module:qualname`.
        digest: the SHA-256 of its source (:mod:`gnipy.user_systems`), recorded with the runs.

    The initial condition is the System's `defaults` (for the parameters asked), else the origin at
    rest (and the identity orientation); the coordinates are the System's.

    Raises:
        InputError: a parameter without a default, a function that does not return a System.
    """
    import inspect

    if isinstance(function, System):
        system_value = function
        params: dict[str, float] = {}

        def make(p):
            return system_value
        label = reference or system_value.name
    elif callable(function):
        label = reference or f"{getattr(function, '__module__', '?')}:{getattr(function, '__qualname__', '?')}"
        params = _model_parameters(function, label)

        def make(p):
            return function(**p)
    else:
        raise InputError(f"model: {safe(reference or repr(function))!r} is a {type(function).__name__}, "
                         "not a function that returns a gnipy.System")

    def built(p):
        try:
            system = make(dict(p))
        except InputError:
            raise
        except Exception as e:  # the user's code: the error names the model and its line
            if any(isinstance(v, jax.core.Tracer) for v in p.values()):
                raise  # under a transformation (gnipy.fit): its caller says what it needs
            source = getattr(getattr(function, "__code__", None), "co_filename", None)
            raise user_code_error(label, e, source) from e
        if not isinstance(system, System):
            raise InputError(f"model: {safe(label)!r} returned a {type(system).__name__}, expected a gnipy.System")
        return system

    def build(p):
        base = dict(p)

        def rebuild(values):  # the System of these values for the named parameters, the rest as built
            if not set(values) <= set(params):  # a named parameter the function does not take
                return None
            return built(base | values)
        return built(p).as_user_model(label, digest, rebuild)

    first = build(params)

    def initial(p):
        return _initial_condition(build(p))

    q0, v0 = initial(params)
    R0 = first.defaults[2] if first.defaults and len(first.defaults) > 2 else None
    doc = (inspect.getdoc(function) or "").strip() if not isinstance(function, System) else ""
    return ModelSpec(
        name=label, description=doc.splitlines()[0] if doc else f"the user's system {first.name!r}", build=build,
        params=params, coordinates=tuple(first.coordinates), q0=q0, v0=v0,
        R0=None if R0 is None else tuple(float(x) for x in R0), default_ic=initial if params else None,
        notes=doc, origin=(label, digest),
    )


def _model_parameters(function, label: str) -> dict[str, float]:
    """The model parameters of the user's `function` (:func:`model_from_function`): its parameters
    with a finite number as default, by name; InputError for a parameter without a default, or a
    positional-only model parameter."""
    import inspect
    import math

    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError) as e:
        raise InputError(f"model: cannot read the parameters of {safe(label)!r}: {e}") from None
    params = {}
    for p in signature.parameters.values():
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            continue
        if p.default is p.empty:
            raise InputError(f"model: {safe(label)!r}: parameter {p.name!r} has no default; give each "
                             "parameter of the function a default (a number makes it a model parameter)")
        d = p.default
        if isinstance(d, (int, float)) and not isinstance(d, bool) and math.isfinite(d):
            if p.kind is p.POSITIONAL_ONLY:
                raise InputError(f"model: {safe(label)!r}: parameter {p.name!r} is positional-only; "
                                 "model parameters are passed by name")
            params[p.name] = float(d)
    return params


def _initial_condition(system: System) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """`(q0, v0)` of a user's model: the System's `defaults`, else the origin at rest."""
    defaults = system.defaults or ()
    q0 = defaults[0] if len(defaults) > 0 else None
    v0 = defaults[1] if len(defaults) > 1 else None
    return ((0.0,) * system.n if q0 is None else tuple(float(x) for x in q0),
            (0.0,) * system.dim if v0 is None else tuple(float(x) for x in v0))


def model_names() -> list[str]:
    """Names of all registered models."""
    return sorted(_REGISTRY)


def make_system(name: str, **params) -> System:
    """Build the System of model `name` with parameters overriding the defaults."""
    return get_model(name).system(**params)


def registered_invariants(name: str | None) -> tuple[str, ...]:
    """The names of the invariants registered for the model called `name`: a system's are those
    of its `model` (none for a System written by hand, whatever its name)."""
    spec = _REGISTRY.get(name)
    return tuple(spec.invariants) if spec is not None else ()


def default_method_for(system_name: str | None, system: System | None = None, b0=None) -> str:
    """The method that runs `system` when none is named: the zoo model `system_name`'s measured
    default (:attr:`ModelSpec.default_method`), or for other systems :data:`FALLBACK_METHOD`. For a
    System, `system_name` is its `model` (None for a System written by hand, whatever its name).

    With `system` (the System to run; `b0` its base point, default the system's documented initial
    condition or the origin), the first of these candidates that can run it, then of
    :data:`FALLBACK_METHODS`: a method whose `check` refuses the system (e.g. a zoo model given a
    metric that is not constant, where its default needs one) is passed over. When none can, the first
    candidate (running it raises the method's own error).
    """
    spec = _REGISTRY.get(system_name)
    first = spec.default_method if spec is not None else FALLBACK_METHOD
    if system is None:
        return first
    candidates = list(dict.fromkeys((first, *FALLBACK_METHODS)))
    for name in candidates:
        if _can_run(name, system, b0):
            return name
    return first


def _can_run(name: str, system: System, b0=None) -> bool:
    """Whether the method called `name` accepts `system`: its `check` raises no MethodError (anything
    else it raises, e.g. on parameters traced by `jax.grad`, is left to the run, which checks again;
    without the method table, :func:`set_method_lookup`, every method is taken to run it)."""
    from .errors import MethodError

    if _METHOD_LOOKUP is None:
        return True
    method = _METHOD_LOOKUP(name)
    try:
        method.validate(system, default_point(system) if b0 is None else b0)
    except MethodError:
        return False
    except Exception:
        return True
    return True
