"""The arguments of :func:`gnipy.fit`, checked and resolved before anything is compiled: the step
grid and the parameter tables, the system and how it is built from the parameters
(:func:`fit_model`), the initial condition and its estimated components (:func:`fit_start`), and
the observations on the step grid with their weights (:func:`fit_data`). Every refusal is an
:class:`~gnipy.errors.InputError` (a :class:`~gnipy.errors.MethodError` for the method) naming
the argument."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..extras import require
from ..errors import InputError
from ..inputs import finite_number, real_array
from ..registry import get_model
from ..saveat import GRID_RTOL
from ..simulate import MIN_STEP_SIZE
from ..system import System
from .memory import check_fit_memory
from .observations import Observations, UnnamedObservations, as_observations, sigma_array

__all__ = ["ArgsBuild", "ModelBuild", "FitModel", "FitStart", "FitData", "step_grid", "parameter_tables", "progress_reporter",
           "check_fit_method", "fit_model", "fit_start", "fit_data", "initial_vector", "initial_selection",
           "observed_columns", "grid_steps"]


# ----------------------------------------------------------------------------------------------
# The numbers, the parameter tables, the progress report and the method
# ----------------------------------------------------------------------------------------------
def step_grid(h, t0) -> tuple[float, float]:
    """`(h, t0)` checked: finite numbers, `h` nonzero and not below `MIN_STEP_SIZE` in size."""
    h = finite_number("h", h)
    if h == 0:
        raise InputError("h: must be nonzero")
    if abs(h) < MIN_STEP_SIZE:
        raise InputError(f"h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision")
    return h, finite_number("t0", t0)


def parameter_tables(params, fixed) -> tuple[tuple[str, ...], list[float], dict]:
    """`(names, guesses, fixed)`: the estimated parameters' names and initial guesses, and the
    fixed parameters as a dict; checked: mappings with string keys, numbers for values (checked
    before a model reads them: its own check would take `"1"` or True; traced fixed values are
    left to the model), no parameter both estimated and fixed."""
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        raise InputError(f"params: expected a dict name -> initial guess, got {type(params).__name__}")
    if fixed is not None and not isinstance(fixed, Mapping):
        raise InputError(f"fixed: expected a dict name -> value, got {type(fixed).__name__}")
    fixed = dict(fixed or {})
    for arg, table in (("params", params), ("fixed", fixed)):
        bad = [k for k in table if not isinstance(k, str)]
        if bad:
            raise InputError(f"{arg}: parameter names must be strings, got {bad[0]!r}")
    param_names = tuple(params)
    guesses = [finite_number(f"params: {k!r}", v) for k, v in params.items()]
    for k, v in fixed.items():  # before a model reads them (its own check would take "1" or True)
        if not isinstance(v, jax.core.Tracer):
            finite_number(f"fixed: {k!r}", v)
    both = sorted(set(param_names) & set(fixed))
    if both:
        raise InputError(f"fixed: {both} also in params (a parameter is either estimated or fixed)")
    return param_names, guesses, fixed


def progress_reporter(progress):
    """The `(iteration, chi2)` callable of `progress=`, or None."""
    if progress is None or progress is False:
        return None
    if progress is True:
        require("rich", extra="cli", what="progress display")
        from rich.console import Console

        console = Console(stderr=True)

        def report(k, chi2):
            console.print(f"fit: iteration {k}, chi2 = {chi2:.6g}")

        return report
    if callable(progress):
        return progress
    raise InputError(f"progress: expected True, False or a callable(iteration, chi2), got {progress!r}")


def check_fit_method(method) -> None:
    """A method's name (known), an integrator or None; `MethodError` otherwise, before the method
    is put in the compiled problem (where another object fails obscurely)."""
    from ..errors import MethodError
    from ..integrators.base import Integrator
    from ..methods import get_method
    from ..reference import ContinuousReference

    if method is None or isinstance(method, Integrator):
        return
    if isinstance(method, str):
        method = get_method(method)
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference cannot be differentiated or traced; use an integrator")
    if not isinstance(method, Integrator):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")


# ----------------------------------------------------------------------------------------------
# The system, and how it is built from the parameters
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ModelBuild:
    """Build a zoo model from its estimated and fixed parameters (hashable: compiled fits are
    shared between calls of one model)."""

    name: str

    def __call__(self, params):
        """The model's System at `params` (name -> value; the others at the model's defaults)."""
        spec = get_model(self.name)
        return spec.build(spec.resolve_params(params))

    def initial(self, params):
        """The model's default initial condition at `params`."""
        return get_model(self.name).default_ic(dict(get_model(self.name).resolve_params(params)))


@dataclasses.dataclass(frozen=True, eq=False)
class ArgsBuild:
    """The System with some of its named parameters (:attr:`gnipy.System.args`) replaced: how
    :func:`gnipy.fit` estimates them without rebuilding it. Hashed by identity (a System holds
    arrays): each :func:`gnipy.fit` call makes its own, and so compiles its fit once."""

    system: System

    def __call__(self, params):
        """The System with `params` (name -> value) as its args."""
        return self.system.with_args(**params)


@dataclasses.dataclass(frozen=True)
class FitModel:
    """The system of a fit (:func:`fit_model`).

    Attributes:
        build: `build(params) -> System` (a :class:`ModelBuild` for a zoo model), or None for a
            given System.
        system: the System at the initial guess.
        given: the given System (whose parameters are not estimated), else None.
        follow_ic: whether the model's default initial condition can follow the estimated
            parameters (it can be evaluated on JAX values).
        positive: the parameters that are positive by their meaning (a zoo model's
            :attr:`~gnipy.registry.ModelSpec.positive`; none for a user's System or build).
    """

    build: Any
    system: System
    given: System | None
    follow_ic: bool
    positive: tuple[str, ...] = ()


def fit_model(system, param_names, guesses, fixed, q0, v0) -> FitModel:
    """The system of :func:`gnipy.fit`'s `system` (a zoo model's name, a `build(params)` function or
    a System), built at the initial guess; InputError for unknown parameters, bad values, a build
    that fails or does not return a System, or parameters to estimate in a System."""
    if isinstance(system, str):
        return _zoo_model(system, param_names, guesses, fixed, q0, v0)
    if isinstance(system, System):
        if (param_names or fixed) and system.args is not None:
            # its named parameters (System(args=...)) are estimated in place: no rebuilding
            unknown = [k for k in (*param_names, *fixed) if k not in system.args]
            if unknown:
                raise InputError(f"params: unknown parameter {unknown[0]!r} of the System (its args: "
                                 f"{', '.join(system.args)})")
            build = ArgsBuild(system)
            return FitModel(build=build, system=_built(build, param_names, guesses, fixed), given=None,
                            follow_ic=False)
        if param_names or fixed:
            raise InputError("params: a System's parameters cannot be estimated here unless they are its args "
                             "(System(..., args={...})); pass a model name, FILE.py:NAME or a build(params) function")
        return FitModel(build=None, system=system, given=system, follow_ic=False)
    if callable(system):
        return FitModel(build=system, system=_built(system, param_names, guesses, fixed), given=None, follow_ic=False)
    raise InputError(f"system: expected a model name, a build(params) function or a gnipy.System, "
                     f"got {type(system).__name__}")


def _zoo_model(name: str, param_names, guesses, fixed, q0, v0) -> FitModel:
    spec = get_model(name)
    build = ModelBuild(spec.name)
    spec.resolve_params({**fixed, **dict(zip(param_names, guesses))})  # unknown names, bad values
    concrete = build({**fixed, **dict(zip(param_names, guesses))})
    follow_ic = False
    if spec.default_ic is not None and (q0 is None or v0 is None) and param_names:
        try:
            jax.eval_shape(build.initial, {**fixed, **{k: jnp.float64(g) for k, g in zip(param_names, guesses)}})
            follow_ic = True
        except Exception:  # e.g. float() of a traced value: the default at the initial guess
            follow_ic = False
    return FitModel(build=build, system=concrete, given=None, follow_ic=follow_ic, positive=tuple(spec.positive))


def _built(build, param_names, guesses, fixed) -> System:
    try:
        concrete = build({**{k: jnp.float64(v) for k, v in fixed.items()},
                          **{k: jnp.float64(g) for k, g in zip(param_names, guesses)}})
    except InputError:
        raise
    except Exception as e:
        raise InputError(f"system: build(params) failed at the initial guess: {type(e).__name__}: {e}") from e
    if not isinstance(concrete, System):
        raise InputError(f"system: build(params) must return a gnipy.System, got {type(concrete).__name__}")
    return concrete


# ----------------------------------------------------------------------------------------------
# The initial condition, and what is estimated
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class FitStart:
    """The initial condition of a fit and the estimated quantities (:func:`fit_start`).

    Attributes:
        q0, v0: the full initial coordinates and velocity (guesses where estimated), (n,), (N,).
        R0: the initial orientation (a matrix), or None without a group part.
        q_idx, v_idx: the estimated components of q0 and of v0.
        names: the estimated quantities: the parameters, then `q0.<coordinate>` and
            `v0.<velocity>`.
        y0: their initial guesses, (P,).
        follow_ic: whether the default initial condition follows the estimated parameters (a
            model's, when neither q0 nor v0 is given).
    """

    q0: np.ndarray
    v0: np.ndarray
    R0: np.ndarray | None
    q_idx: tuple[int, ...]
    v_idx: tuple[int, ...]
    names: tuple[str, ...]
    y0: np.ndarray
    follow_ic: bool


def fit_start(model: FitModel, q0, v0, R0, initial, param_names, guesses) -> FitStart:
    """The initial condition (given, or the system's defaults) and the estimated quantities
    (`initial`: which components of q0 and v0 beside the parameters); InputError when there are
    no defaults to take, a vector of the wrong size, or nothing to estimate."""
    concrete = model.system
    coords, vels = concrete.coordinates, concrete.velocities
    defaults = concrete.defaults
    if (q0 is None or v0 is None) and defaults is None:
        raise InputError(f"q0/v0: the system {concrete.name!r} has no default initial condition; give q0 and v0")
    q0v = initial_vector("q0", defaults[0] if q0 is None else q0, concrete.n)
    v0v = initial_vector("v0", defaults[1] if v0 is None else v0, concrete.dim)
    if R0 is None and defaults is not None and len(defaults) > 2 and defaults[2] is not None:
        R0 = defaults[2]
    b0 = concrete.initial_point(q0v, R0)
    R0a = None if concrete.group is None else np.asarray(b0.R)
    follow_ic = model.follow_ic and q0 is None and v0 is None
    q_idx, v_idx = initial_selection(initial, coords, vels)
    names = (param_names + tuple(f"q0.{coords[i]}" for i in q_idx) + tuple(f"v0.{vels[i]}" for i in v_idx))
    if not names:
        raise InputError("params/initial: nothing to estimate; name parameters (params=) and/or parts of the "
                         "initial condition (initial=)")
    y0 = np.concatenate([np.asarray(guesses, dtype=np.float64), q0v[list(q_idx)], v0v[list(v_idx)]])
    return FitStart(q0=q0v, v0=v0v, R0=R0a, q_idx=q_idx, v_idx=v_idx, names=names, y0=y0, follow_ic=follow_ic)


def initial_vector(name, x, n):
    """`x` as a finite vector of `n` numbers; InputError naming `name` otherwise."""
    a = real_array(name, x, f"{n} real numbers").reshape(-1)
    if a.shape != (n,):
        raise InputError(f"{name}: expected {n} numbers, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or infinite values")
    return a


def _components(name: str, which, names: tuple[str, ...]) -> tuple[int, ...]:
    """The indices of the components `which` (names or indices, or all for True/"all") of `names`."""
    if which is True or (isinstance(which, str) and which == "all"):
        return tuple(range(len(names)))
    if isinstance(which, (str, int, np.integer)):
        which = (which,)
    idx = []
    for w in which:
        if isinstance(w, str):
            if w not in names:
                raise InputError(f"initial: unknown component {w!r} of {name} (known: {', '.join(names)})")
            idx.append(names.index(w))
        elif isinstance(w, (int, np.integer)) and not isinstance(w, bool) and -len(names) <= w < len(names):
            idx.append(int(w) % len(names))
        else:
            raise InputError(f"initial: {w!r} is not a component of {name} ({len(names)} components: "
                             f"{', '.join(names)})")
    if len(set(idx)) != len(idx):
        raise InputError(f"initial: a component of {name} is named twice")
    return tuple(sorted(idx))


def initial_selection(initial, coordinates, velocities):
    """`(q_idx, v_idx)`: the components of q0 and of v0 that :func:`gnipy.fit`'s `initial`
    estimates (`"q0"`/`"v0"` for every component, or a mapping to some by name or index)."""
    if initial is None:
        initial = ()
    if isinstance(initial, str):
        initial = (initial,)
    if isinstance(initial, Mapping):
        items = dict(initial)
    else:
        try:
            items = {k: True for k in initial}
        except TypeError:
            raise InputError(f"initial: expected a subset of ('q0', 'v0') or a mapping, got {initial!r}") from None
    bad = [k for k in items if k not in ("q0", "v0")]
    if bad:
        raise InputError(f"initial: unknown entries {bad} (estimate 'q0' and/or 'v0', or e.g. {{'q0': ['x', 'y']}})")
    q_idx = _components("q0", items["q0"], coordinates) if "q0" in items else ()
    v_idx = _components("v0", items["v0"], velocities) if "v0" in items else ()
    return q_idx, v_idx


# ----------------------------------------------------------------------------------------------
# The observations, on the step grid
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class FitData:
    """The observations of a fit on the step grid, with their weights (:func:`fit_data`).

    Attributes:
        observations: the :class:`~gnipy.control.Observations` (named).
        columns: `("q" or "v", index)` of each observed variable.
        steps: the step index of each observation time.
        mask: where a value is observed, (T, k).
        n_obs: the number of observed values.
        sigma_known: whether the measurement errors were given.
        arrays: `(values, weights)`, JAX arrays (T, k), zero at missing values: the data of the
            weighted residuals.
    """

    observations: Observations
    columns: tuple
    steps: tuple[int, ...]
    mask: np.ndarray
    n_obs: int
    sigma_known: bool
    arrays: tuple


def fit_data(observations, system: System, t0: float, h: float, sigma, n_estimated: int, bound) -> FitData:
    """:func:`gnipy.fit`'s `observations` on the step grid of `t0` and `h`, with the weights of
    `sigma` (or of the observations' own); the fit's memory checked against `bound` (the fitted run
    holds every node of the span) before anything is compiled; InputError for a time off the grid,
    unknown variables, sigma given twice, or fewer observed values than `n_estimated`."""
    obs = as_observations(observations)
    if isinstance(obs, UnnamedObservations):
        obs = obs.named(system.coordinates)
    columns = observed_columns(obs.variables, system.coordinates, system.velocities)
    ks = grid_steps(obs.times, t0, h)
    # before anything is compiled: the fitted run holds every node of the span
    check_fit_memory(system, ks[-1], obs.values.size, n_estimated, t0=t0, t_last=float(obs.times[-1]), h=h,
                     max_bytes=bound)
    if sigma is not None and obs.sigma is not None:
        raise InputError("sigma: given both here and in the observations; give one")
    sig = obs.sigma if sigma is None else sigma_array(sigma, obs.values.shape, "sigma")
    mask = np.isfinite(obs.values)
    n_obs = int(mask.sum())
    if n_obs < n_estimated:
        raise InputError(f"observations: {n_obs} observed values cannot determine {n_estimated} estimated quantities")
    weights = np.where(mask, 1.0 if sig is None else 1.0 / np.where(mask, sig, 1.0), 0.0)
    arrays = (jnp.asarray(np.where(mask, obs.values, 0.0)), jnp.asarray(weights))
    return FitData(observations=obs, columns=columns, steps=ks, mask=mask, n_obs=n_obs, sigma_known=sig is not None,
                   arrays=arrays)


def observed_columns(variables, coordinates, velocities):
    """`("q" or "v", index)` of each observed variable; InputError naming `observations` for an
    unknown one."""
    cols = []
    for name in variables:
        if name in coordinates:
            cols.append(("q", coordinates.index(name)))
        elif name in velocities:
            cols.append(("v", velocities.index(name)))
        else:
            raise InputError(f"observations: unknown variable {name!r} (coordinates: {', '.join(coordinates)}; "
                             f"velocities: {', '.join(velocities)})")
    return tuple(cols)


def grid_steps(times, t0: float, h: float) -> tuple[int, ...]:
    """The step index of each observation time; InputError naming `observations` and the time
    for a time off the grid, before t0, or out of order."""
    ks = []
    for t in times:
        k = (float(t) - t0) / h
        kr = round(k)
        if abs(k - kr) > GRID_RTOL * max(1.0, abs(k)):
            raise InputError(
                f"observations: time {float(t)!r} is not a node t0 + k h of the step grid (t0 = {t0!r}, h = {h!r}: "
                f"it lies between k = {math.floor(k)} and {math.floor(k) + 1}); gnipy compares nodes and does not "
                "interpolate: choose h dividing the observation times"
            )
        if kr < 0:
            raise InputError(f"observations: time {float(t)!r} lies before t0 = {t0!r}")
        ks.append(int(kr))
    if any(b <= a for a, b in zip(ks, ks[1:])):
        i = next(i for i, (a, b) in enumerate(zip(ks, ks[1:])) if b <= a)
        raise InputError(f"observations: the times must be strictly increasing along the run; time "
                         f"{float(times[i + 1])!r} follows {float(times[i])!r}")
    if ks[-1] < 1:
        raise InputError("observations: every observation is at t0; observe at least one later node")
    return tuple(ks)
