"""Identification problems as data: the TOML problem files of `gni fit` and the result files.

A fit problem file (`gni fit`, :func:`load_fit_problem`) names the model, the parameters to
estimate with their guesses, the observations (a gnipy result file) and the integration::

    [system]
    model = "chaplygin-sleigh"
    params = { m = 1.0 }           # fixed parameters (default: the model's)
    [estimate]
    params = { I = 1.2, a = 0.5 }  # estimated, with initial guesses
    initial = ["q0"]               # optional: also q0 and/or v0
    bounds = { a = [0.0, 1.0] }    # optional (default: masses, inertias, lengths positive)
    [observations]
    file = "observed.nc"           # relative to the problem file
    variables = ["x", "y"]         # optional (default: every coordinate)
    sigma = 1e-3                   # optional (default: estimated from the scatter)
    [start]                        # optional (default: the model's)
    q0 = [0.0, 0.0, 0.0]
    v0 = [1.0, 0.4, 1.0]
    [integration]
    method = "gni-trapezoid"       # optional (default: the model's)
    h = 0.05                       # optional when the file records its h

The entries are checked as :mod:`gnipy.control.problem_files` checks a control problem's: a value
of the wrong type, out of range or of the wrong size is an :class:`~gnipy.errors.InputError` naming
its key; an observation file that cannot be read names `observations.file`.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..extras import require
from ..errors import InputError
from .problem_files import (
    build_model_system,
    describe_entry,
    entry_method,
    entry_model,
    entry_number,
    entry_numbers,
    entry_params,
    entry_rotation,
    entry_table,
    entry_text,
    is_entry_number,
    quoted_names,
    read_problem,
    refuse_unknown_keys,
)

__all__ = ["FitProblem", "load_fit_problem", "write_fit_result"]


_FIT_SECTIONS = {"name", "description", "system", "estimate", "observations", "start", "integration"}


@dataclasses.dataclass(frozen=True)
class FitProblem:
    """An identification problem read from a fit problem file (module docstring).

    Attributes:
        name, description: from the file.
        model: the zoo model's name.
        fixed: the fixed parameters.
        params: the estimated parameters' initial guesses.
        initial: which parts of the initial condition are estimated (`"q0"`, `"v0"`).
        bounds: the bounds of `[estimate] bounds`, name -> `(lower, upper)` (over the model's
            defaults: :mod:`gnipy.control.bounds`; `[-inf, inf]` lifts one).
        observations: the :class:`~gnipy.control.Observations`.
        q0, v0, R0: the start (guesses where estimated).
        method, h, t0: the integration.
        source: the file's text.
    """

    name: str
    description: str
    model: str
    fixed: dict
    params: dict
    initial: tuple
    observations: Any
    q0: Any
    v0: Any
    R0: Any
    method: Any
    h: float
    t0: float
    source: str
    bounds: dict = dataclasses.field(default_factory=dict)

    def solve(self, progress=False, max_bytes="auto"):
        """:func:`gnipy.fit` on this problem (`max_bytes` as there)."""
        from .identification import fit

        return fit(self.model, self.observations, params=self.params or None, fixed=self.fixed or None,
                   initial=self.initial, method=self.method, h=self.h, t0=self.t0, q0=self.q0, v0=self.v0,
                   R0=self.R0, bounds=self._bounds(), progress=progress, max_bytes=max_bytes)

    def _bounds(self):
        """The bounds for :func:`gnipy.fit` (an infinite pair lifts a default), None without any."""
        if not self.bounds:
            return None
        return {k: None if (a, b) == (-math.inf, math.inf) else (a, b) for k, (a, b) in self.bounds.items()}


def load_fit_problem(source, *, name: str = "fit", max_bytes="auto") -> FitProblem:
    """Read a fit problem: a path to a TOML file (its observation file is relative to it), TOML
    text, or a parsed mapping (paths then relative to the working directory).

    Every entry is checked here, before anything is compiled (types: a string or a boolean is not
    a number; ranges; the names and sizes against the model), and the observation file too: a
    gnipy result file whose `q(time, coordinate)` / `v(time, velocity)` hold numbers.

    Arguments:
        source: the problem (see above).
        name: the problem's name when the file has none and is not a path (a path's stem is).
        max_bytes: the memory bound (as :func:`gnipy.fit`'s): the observed variables of the file
            are refused before they are read when they alone exceed it.

    Raises:
        InputError: a missing or malformed entry, named by its section and key
            (`observations.sigma: ...`); an observation file that cannot be read or holds no
            usable observations (`observations.file: ...`).
    """
    from .memory import memory_limit

    data, text, base, name = read_problem(source, name)
    unknown = set(data) - _FIT_SECTIONS
    if unknown:
        raise InputError(f"problem: unknown section(s) {quoted_names(unknown)}; expected {', '.join(sorted(_FIT_SECTIONS))}")
    title = entry_text("name", data.get("name", name))
    description = entry_text("description", data.get("description", "")).strip()
    spec, fixed_all = entry_model(data, base)
    fixed = entry_params(spec, data["system"].get("params"), "system.params")
    params, initial, bounds = _estimate_section(data, spec, fixed)
    # the system at the initial guess: the names and sizes below are checked against it
    system = build_model_system(spec, {**fixed_all, **params}, "system.params/estimate.params")
    obs_path, variables, sigma = _observations_section(data, base, spec, system)
    q0, v0, R0 = _start_section(data, system)
    method, h, t0 = _integration_section(data)
    observations, file_h = _read_observations(obs_path, variables, sigma, memory_limit(max_bytes))
    h = _step_size(h, file_h)
    _check_memory(system, observations, params, initial, t0, h, max_bytes)
    return FitProblem(name=title, description=description, model=spec.name, fixed=fixed, params=params,
                      initial=tuple(initial), observations=observations, q0=q0, v0=v0, R0=R0, method=method, h=h,
                      t0=t0, source=text, bounds=bounds)


def _estimate_section(data, spec, fixed) -> tuple[dict, list, dict]:
    """`(params, initial, bounds)` of `[estimate]`: the estimated parameters' guesses (none also
    fixed), the estimated parts of the initial condition (something to estimate) and the bounds
    of estimated parameters (pairs of numbers, lower below upper)."""
    estimate = entry_table(data, "estimate")
    refuse_unknown_keys(estimate, "estimate", {"params", "initial", "bounds"})
    params = entry_params(spec, estimate.get("params"), "estimate.params")
    both = set(params) & set(fixed)
    if both:
        raise InputError(f"estimate.params: {quoted_names(both)} also in system.params (a parameter is either estimated or "
                         "fixed)")
    initial = estimate.get("initial", [])
    if isinstance(initial, str):
        initial = [initial]
    if (not isinstance(initial, list) or not all(isinstance(k, str) for k in initial)
            or not set(initial) <= {"q0", "v0"} or len(set(initial)) != len(initial)):
        raise InputError(f"estimate.initial: expected a list of 'q0' and/or 'v0' (each once), got {describe_entry(initial)}")
    if not params and not initial:
        raise InputError("estimate: nothing to estimate: give params = {...} and/or initial = [...]")
    return params, initial, _bounds_entry(estimate.get("bounds", {}), params, spec.positive)


def _bounds_entry(table, params, positive) -> dict:
    """`[estimate] bounds`: estimated parameter -> `[lower, upper]` (numbers, ±inf for an open
    side), each holding its guess strictly inside, as the model's positive parameters' guesses
    must be unless a bound is given."""
    if not isinstance(table, dict):
        raise InputError(f"estimate.bounds: expected a table {{name = [lower, upper]}}, got {describe_entry(table)}")
    out = {}
    for name, pair in table.items():
        key = f"estimate.bounds.{name}"
        if name not in params:
            raise InputError(f"{key}: not an estimated parameter (estimate.params: {', '.join(params) or 'none'})")
        if not isinstance(pair, list) or len(pair) != 2 or not all(is_entry_number(x) for x in pair):
            raise InputError(f"{key}: expected [lower, upper] (numbers; inf and -inf for an open side), got "
                             f"{describe_entry(pair)}")
        a, b = (float(x) for x in pair)
        if not a < b:
            raise InputError(f"{key}: the lower bound must be below the upper bound, got [{a!r}, {b!r}]")
        if not a < params[name] < b:
            raise InputError(f"{key}: the guess {params[name]!r} (estimate.params.{name}) is not strictly inside "
                             f"[{a!r}, {b!r}]")
        out[name] = (a, b)
    for name in positive:
        if name in params and name not in out and not params[name] > 0:
            raise InputError(f"estimate.params.{name}: the guess {params[name]!r} must be positive ({name} is a mass, "
                             f"moment of inertia or length of this model); [estimate] bounds = {{ {name} = [-inf, inf] "
                             "} lifts the bound")
    return out


def _observations_section(data, base: Path, spec, system) -> tuple[Path, Any, Any]:
    """`(path, variables, sigma)` of `[observations]`: the observation file (relative to `base`),
    the observed variables (names of the system's, or None) and sigma (or None)."""
    from .observations import SIGMA_RANGE

    obs_sec = entry_table(data, "observations")
    refuse_unknown_keys(obs_sec, "observations", {"file", "variables", "sigma"})
    file = obs_sec.get("file")
    if not isinstance(file, str) or not file:
        raise InputError(f"observations.file: expected the path of a gnipy result file (netCDF), got {describe_entry(file)}")
    if "\x00" in file:
        raise InputError(f"observations.file: {file!r}: a path cannot contain a NUL character")
    obs_path = Path(file) if Path(file).is_absolute() else base / file
    variables = obs_sec.get("variables")
    if variables is not None:
        _check_variables(variables, spec, system)
    sigma = obs_sec.get("sigma")
    if sigma is not None:
        sigma = entry_number("observations.sigma", sigma, positive=True)
        if not SIGMA_RANGE[0] <= sigma <= SIGMA_RANGE[1]:
            raise InputError(f"observations.sigma: {sigma!r} is outside {SIGMA_RANGE[0]:g} .. {SIGMA_RANGE[1]:g}: the "
                             "weights 1/sigma or the squared weighted residuals would not be finite in float64")
    return obs_path, variables, sigma


def _check_variables(variables, spec, system) -> None:
    """`observations.variables`: a list of distinct names of the system's coordinates and velocities."""
    known = (*system.coordinates, *system.velocities)
    if not isinstance(variables, list) or not variables or not all(isinstance(v, str) for v in variables):
        raise InputError(f"observations.variables: expected a list of names, got {describe_entry(variables)}")
    if len(set(variables)) != len(variables):
        raise InputError(f"observations.variables: a name is repeated in {variables!r}")
    unknown = [v for v in variables if v not in known]
    if unknown:
        raise InputError(f"observations.variables: unknown variable {unknown[0]!r} of model {spec.name!r} "
                         f"(coordinates: {', '.join(system.coordinates)}; velocities: "
                         f"{', '.join(system.velocities)})")


def _start_section(data, system) -> tuple[Any, Any, Any]:
    """`(q0, v0, R0)` of the optional `[start]` (None where not given)."""
    start = entry_table(data, "start", required=False)
    refuse_unknown_keys(start, "start", {"q0", "v0", "R0"})
    q0 = tuple(entry_numbers("start.q0", start["q0"], system.coordinates)) if "q0" in start else None
    v0 = tuple(entry_numbers("start.v0", start["v0"], system.velocities)) if "v0" in start else None
    R0 = entry_rotation("start.R0", start["R0"], system) if "R0" in start else None
    return q0, v0, R0


def _integration_section(data) -> tuple[Any, float | None, float]:
    """`(method, h, t0)` of the optional `[integration]` (method and h None where not given)."""
    integ = entry_table(data, "integration", required=False)
    refuse_unknown_keys(integ, "integration", {"method", "h", "t0"})
    method = integ.get("method")
    if method is not None:
        method = entry_method("integration.method", method)
    h = integ.get("h")
    if h is not None:
        h = entry_number("integration.h", h, positive=True)
    t0 = entry_number("integration.t0", integ.get("t0", 0.0))
    return method, h, t0


def _step_size(h, file_h) -> float:
    """The step: `[integration] h`, else the observation file's attribute h; not below
    `MIN_STEP_SIZE`."""
    from ..simulate import MIN_STEP_SIZE

    if h is None:
        if file_h is None:
            raise InputError("integration.h: missing, and the observation file does not record its h; give "
                             "[integration] h")
        if not (is_entry_number(file_h) and math.isfinite(file_h) and file_h > 0):
            raise InputError(f"integration.h: missing, and the observation file's attribute h ({file_h!r}) is not a "
                             "positive number; give [integration] h")
        h = float(file_h)
    if h < MIN_STEP_SIZE:
        raise InputError(f"integration.h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision")
    return h


def _check_memory(system, observations, params, initial, t0: float, h: float, max_bytes) -> None:
    """The fit's memory, before anything is compiled (gnipy.fit checks it again, with the step grid)."""
    from .memory import check_fit_memory

    t_last = float(observations.times[-1])
    span = (t_last - t0) / h
    if math.isfinite(span) and span >= 0:
        estimated = len(params) + ("q0" in initial) * system.n + ("v0" in initial) * system.dim
        check_fit_memory(system, round(span), observations.values.size, estimated, t0=t0, t_last=t_last, h=h,
                         max_bytes=max_bytes, key="observations.file/integration.h")


def _read_observations(path: Path, variables, sigma, bound: int | None):
    """`(Observations, the file's h attribute or None)` from a gnipy result file: opened lazily, its
    observed variables checked (dimensions, numbers) and their size bounded before they are read.
    Every failure is an InputError naming `observations.file`."""
    xr = require("xarray", extra="files")

    from ..io import upgrade_layout

    where = f"observations.file: {str(path)!r}"
    _check_file(path, where)
    try:
        ds = xr.open_dataset(path)  # lazily: the header now, the observed variables below
    except MemoryError:
        raise
    except Exception as e:  # a damaged file fails in many ways (OSError, ValueError, HDF errors, ...)
        raise _unreadable(where, e) from None
    with ds:
        try:
            ds = upgrade_layout(ds)
        except Exception as e:
            raise _unreadable(where, e) from None
        _check_size(ds, where, bound)
        file_h = _file_step(ds)
        observations = _dataset_observations(ds, variables, sigma, where)
    return observations, file_h


def _check_file(path: Path, where: str) -> None:
    """The observation file exists, is a regular file and is not empty."""
    try:
        st = path.stat()
    except OSError as e:
        raise InputError(f"{where}: cannot read it: {e.strerror or e}") from None
    if not path.is_file():
        raise InputError(f"{where}: not a regular file")
    if st.st_size == 0:
        raise InputError(f"{where}: the file is empty (not a gnipy result file)")


def _unreadable(where: str, e) -> InputError:
    """The error of a file that cannot be read as a gnipy result file, saying why (`e`)."""
    why = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
    if isinstance(e, ValueError) and "backend" in why:
        why = "not a netCDF file that xarray can open"
    return InputError(f"{where}: cannot read it as a gnipy result file ({why})")


def _check_size(ds, where: str, bound: int | None) -> None:
    """The observed variables of the opened dataset `ds` within the memory bound, before they are read."""
    from ..files import format_bytes

    loaded = sum(int(ds[v].nbytes) for v in ("q", "v", "t", "time") if v in ds.variables)
    if bound is not None and loaded > bound:
        raise InputError(f"{where}: its observed variables are {format_bytes(loaded)}, more than the memory bound "
                         f"of {format_bytes(bound)}; observe fewer times, or pass max_bytes=None to read it anyway")


def _file_step(ds):
    """The dataset's attribute h as a Python number (a one-element numeric array or a NumPy
    scalar unwrapped), as it is otherwise, or None."""
    file_h = ds.attrs.get("h")
    if isinstance(file_h, np.ndarray) and file_h.size == 1 and file_h.dtype.kind in "iuf":
        file_h = file_h.reshape(-1)[0]
    if isinstance(file_h, (np.integer, np.floating)):
        file_h = file_h.item()
    return file_h


def _dataset_observations(ds, variables, sigma, where: str):
    """The observations of the dataset; its errors named by `where` (the file)."""
    from .identification import Observations

    try:
        return Observations.from_dataset(ds, variables, sigma=sigma)
    except InputError as e:
        head, sep, rest = str(e).partition(": ")
        raise InputError(f"{where}: {rest if sep and head == 'observations' else e}") from None
    except MemoryError:
        raise
    except Exception as e:  # the data of a damaged file fail when read
        raise _unreadable(where, e) from None


def write_fit_result(result, problem: FitProblem | None, path, *, overwrite: bool = False) -> None:
    """Write a :class:`~gnipy.control.FitResult` to netCDF, whole or not at all: the fitted run's
    nodes (as `gni run` writes them), the estimates `estimate(quantity)`, their standard errors
    `standard_error(quantity)` and covariance `covariance(quantity, quantity_)`, and the fit's
    figures (chi², degrees of freedom, iterations) as attributes."""
    xr = require("xarray", extra="files")

    from .. import schema
    from ..io import write_netcdf

    attrs = {
        "command": "gni fit",
        "fit_chi2": float(result.chi2),
        "fit_dof": int(result.dof),
        "fit_reduced_chi2": float(result.reduced_chi2),
        "fit_n_obs": int(result.n_obs),
        "fit_rank": int(result.rank),
        "fit_determined": int(result.determined),
        "fit_discretization": float(result.discretization),
        "fit_combinations": "; ".join(str(c) for c in result.combinations),
        "fit_at_bound": ", ".join(f"{n} = {b!r}" for n, b in result.at_bound.items()),
        "fit_sigma_known": int(result.sigma_known),
        "fit_success": int(result.success),
        "fit_message": str(result.message),
        "fit_iterations": int(result.iterations),
        "fit_wall_time_s": float(result.wall_time),
        "fit_observed_variables": ",".join(result.observations.variables),
    }
    if problem is not None and problem.source:
        attrs["fit_problem_file"] = problem.source
    if result.solution is None:
        raise InputError(f"--out: the fit has no fitted run to write ({result.message})")
    ds = result.solution.to_xarray(attrs=attrs)
    names = [str(n) for n in result.names]
    for var, values, dims in (("estimate", result.values, ("quantity",)),
                              ("standard_error", result.stderr, ("quantity",)),
                              ("covariance", result.covariance, ("quantity", "quantity_"))):
        ds[var] = xr.DataArray(np.asarray(values, dtype=np.float64), dims=dims, attrs=schema.variable_attrs(var))
    ds = ds.assign_coords(quantity=names, quantity_=names)
    for name in ("quantity", "quantity_"):
        ds[name].attrs.update(schema.variable_attrs(name))
    write_netcdf(ds, path, overwrite=overwrite)
