"""Problems as data: the TOML problem files of `gni control` (optimal control) and `gni fit`
(identification), the worked control problems, and the result files.

A control problem file (:func:`load_problem`) has the sections

- `[system]`: `model` (a zoo model's name) and `params` (a table of parameter values);
- `[inputs]`: one entry per input, `name = { velocity name = gain }`: the force $F = Bu$ of
  actuators along those velocity components (:func:`gnipy.forcing.input_force`);
- `[start]`: `q0`, `v0` and, on $\\mathbb{R}^n\\times G$, `R0` (default: the model's);
- `[horizon]`: `h` and `steps`;
- `[target]`: coordinate and velocity names with their values, and `R` (a matrix);
- `[solver]` (optional): `method`, `bounds = [lower, upper]`, `effort`, `smoothness`,
  `max_iterations`, `segments` (the arguments of :func:`gnipy.control.solve_optimal_control`);
- `[warm_start]` (optional): $u_j(t) = a_j\\sin(2\\pi\\,\\mathrm{periods}\\,t/T + \\phi_j)$ from
  `amplitude`, `phase` and `periods` (default: zero inputs);
- `name`, `description` (optional).

:data:`WORKED_PROBLEMS` holds the two worked problems of the control guide as such files.

A fit problem file (`gni fit`, :func:`load_fit_problem`) names the model, the parameters to
estimate with their guesses, the observations (a gnipy result file) and the integration::

    [system]
    model = "chaplygin-sleigh"
    params = { m = 1.0 }           # fixed parameters (default: the model's)
    [estimate]
    params = { I = 1.2, a = 0.5 }  # estimated, with initial guesses
    initial = ["q0"]               # optional: also q0 and/or v0
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
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..system import System

__all__ = ["ControlProblem", "WORKED_PROBLEMS", "load_problem", "write_control_result", "FitProblem",
           "load_fit_problem", "write_fit_result"]

#: The worked problems of the control guide, as problem files (`gni control --example NAME`).
WORKED_PROBLEMS: dict[str, str] = {
    "sleigh-steering": '''\
name = "sleigh-steering"
description = """Steer the Chaplygin sleigh from rest at the origin to the pose (x, y, theta) = (1, 0.5, 0)
in T = 4 with a torque |tau| <= 1.5 about its centre of mass (no other actuation: the knife edge turns
rotation into forward motion), minimizing the effort (1/2) sum h tau_k^2."""

[system]
model = "chaplygin-sleigh"
params = { m = 1.0, I = 1.0, a = 0.5 }

[inputs]
torque = { dtheta = 1.0 }

[start]
q0 = [0.0, 0.0, 0.0]
v0 = [0.0, 0.0, 0.0]

[horizon]
h = 0.05
steps = 80

[target]
x = 1.0
y = 0.5
theta = 0.0

[solver]
method = "gni-trapezoid"
bounds = [-1.5, 1.5]
effort = 1.0

[warm_start]
amplitude = [1.0]
phase = [0.0]
periods = 1.0
''',
    "ball-plate": '''\
name = "ball-plate"
description = """The ball-plate problem: a homogeneous ball (m = r = 1, I = 2/5) rests on a plate at the
origin; move the plate (input: its acceleration (ax, ay), which acts on the ball as the inertial force
-m a in the plate's frame) so that after T = 6 the ball is back at the origin, at rest, turned by 90
degrees about the vertical: a rotation that rolling without slipping reaches only along a loop (the
classic nonholonomic motion-planning problem). Minimizes the effort (1/2) sum h |a_k|^2 plus a small
penalty on the rate of change (0.01/2) sum |a_(k+1) - a_k|^2 / h (without it the optimum alternates from
step to step, reaching the target more cheaply in the discrete dynamics than in the continuous ones)."""

[system]
model = "rolling-ball"
params = { Omega = 0.0, I1 = 0.4, I2 = 0.4, I3 = 0.4, m = 1.0, r = 1.0 }

[inputs]
ax = { dx = -1.0 }
ay = { dy = -1.0 }

[start]
q0 = [0.0, 0.0]
v0 = [0.0, 0.0, 0.0, 0.0, 0.0]

[horizon]
h = 0.1
steps = 60

[target]
x = 0.0
y = 0.0
dx = 0.0
dy = 0.0
R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]

[solver]
method = "gni-trapezoid"
effort = 1.0
smoothness = 0.01

[warm_start]
amplitude = [0.5, 0.5]
phase = [1.5707963267948966, 0.0]
periods = 1.0
''',
}

_SECTIONS = {"name", "description", "system", "inputs", "start", "horizon", "target", "solver", "warm_start"}


@dataclasses.dataclass(frozen=True)
class ControlProblem:
    """An optimal-control problem read from a problem file (module docstring).

    Attributes:
        name, description: from the file.
        system: the forced System (the model with the input force).
        input_names: the inputs' names, in order.
        target: the target mapping (:func:`gnipy.control.terminal_residual`).
        q0, v0, R0: the start.
        h, steps: the horizon.
        method, bounds, effort, smoothness, max_iterations, segments: the solver's options.
        controls0: the warm start (K, m).
        source: the file's text (kept in the result file's attributes).
    """

    name: str
    description: str
    system: System
    input_names: tuple[str, ...]
    target: dict
    q0: tuple
    v0: tuple
    R0: Any
    h: float
    steps: int
    method: str
    bounds: Any
    effort: float
    smoothness: float
    max_iterations: int
    segments: int
    controls0: np.ndarray
    source: str

    def solve(self, progress=False, check_continuous: bool = True):
        """:func:`gnipy.control.solve_optimal_control` on this problem."""
        from .optimal_control import solve_optimal_control

        return solve_optimal_control(
            self.system, self.target, h=self.h, steps=self.steps, q0=self.q0, v0=self.v0, R0=self.R0,
            method=self.method, controls0=self.controls0, bounds=self.bounds, effort=self.effort,
            smoothness=self.smoothness, segments=self.segments,
            max_iterations=self.max_iterations, progress=progress, input_names=self.input_names,
            check_continuous=check_continuous)


def load_problem(source, *, name: str = "problem") -> ControlProblem:
    """Read a problem: a path to a TOML file, TOML text (a string holding a newline), a parsed
    mapping, or the name of a worked problem (:data:`WORKED_PROBLEMS`).

    Raises:
        InputError: a missing or malformed entry, named by its section and key.
    """
    if isinstance(source, str) and source in WORKED_PROBLEMS:
        source = WORKED_PROBLEMS[source]
    data, text, _, name = _read(source, name, f"a worked problem's name ({', '.join(WORKED_PROBLEMS)})")
    unknown = set(data) - _SECTIONS
    if unknown:
        raise InputError(f"problem: unknown section(s) {', '.join(sorted(unknown))}; expected {', '.join(sorted(_SECTIONS))}")
    from ..forcing import input_force
    from ..registry import get_model

    system_sec = _section(data, "system")
    _known_keys(data, {"system": {"model", "params"}, "start": {"q0", "v0", "R0"}, "horizon": {"h", "steps"}})
    model = system_sec.get("model")
    if not isinstance(model, str):
        raise InputError("system.model: expected a model name (see `gni models`)")
    try:
        spec = get_model(model)
    except (KeyError, ValueError, InputError) as e:
        raise InputError(f"system.model: {e}") from None
    params = spec.resolve_params(system_sec.get("params") or {})
    base = spec.build(params)
    F, m, input_names = input_force(base, _section(data, "inputs"))
    system = base.with_force(F, inputs=m)
    start = data.get("start", {})
    q0 = tuple(_numbers("start.q0", start["q0"])) if "q0" in start else None
    v0 = tuple(_numbers("start.v0", start["v0"])) if "v0" in start else None
    R0 = np.asarray(_matrix("start.R0", start["R0"])) if "R0" in start else None
    if q0 is None or v0 is None:
        dq, dv = spec.initial_condition(params)
        q0 = dq if q0 is None else q0
        v0 = dv if v0 is None else v0
    horizon = _section(data, "horizon")
    h = _positive("horizon.h", horizon.get("h"))
    steps = horizon.get("steps")
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise InputError(f"horizon.steps: expected a positive integer, got {steps!r}")
    target = dict(_section(data, "target"))
    if "R" in target:
        target["R"] = _matrix("target.R", target["R"])
    solver = data.get("solver", {})
    method = str(solver.get("method", "gni-trapezoid"))
    bounds = solver.get("bounds")
    if bounds is not None:
        if not isinstance(bounds, list) or len(bounds) != 2:
            raise InputError(f"solver.bounds: expected [lower, upper], got {bounds!r}")
        bounds = (bounds[0], bounds[1])
    effort = solver.get("effort", 1.0)
    smoothness = solver.get("smoothness", 0.0)
    segments = solver.get("segments", 1)
    unknown = set(solver) - {"method", "bounds", "effort", "smoothness", "max_iterations", "segments"}
    if unknown:
        raise InputError(f"solver: unknown key(s) {', '.join(sorted(unknown))}; expected method, bounds, effort, "
                         "smoothness, max_iterations, segments")
    max_iterations = solver.get("max_iterations", 500)
    warm = data.get("warm_start", {})
    controls0 = _warm_start(warm, steps, m, h)
    return ControlProblem(
        name=str(data.get("name", name)), description=str(data.get("description", "")).strip(), system=system,
        input_names=input_names, target=target, q0=q0, v0=v0, R0=R0, h=h, steps=steps, method=method,
        bounds=bounds, effort=effort, smoothness=smoothness, max_iterations=max_iterations, segments=segments, controls0=controls0, source=text)


def _read(source, name: str, also: str = "") -> tuple[dict, str, Path, str]:
    """`(data, text, directory, name)` of a problem given as a path (a string without a newline),
    TOML text or a parsed mapping; the directory is the file's (relative paths in it), else the
    working directory."""
    base, text = Path("."), ""
    if isinstance(source, Path) or (isinstance(source, str) and "\n" not in source):
        path = Path(source)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as e:
            raise InputError(f"problem: cannot read {str(path)!r}: {e.strerror or e}") from None
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


def _known_keys(data, known: dict[str, set[str]]) -> None:
    """Refuse keys a section does not have (a misspelt key would otherwise be a default)."""
    for section, keys in known.items():
        unknown = set(data.get(section) or {}) - keys
        if unknown:
            raise InputError(f"{section}: unknown key(s) {', '.join(sorted(unknown))}; expected "
                             f"{', '.join(sorted(keys))}")


def _section(data, key) -> Mapping:
    sec = data.get(key)
    if not isinstance(sec, Mapping) or not sec:
        raise InputError(f"{key}: missing or empty section [{key}]")
    return sec


def _numbers(where, value) -> list[float]:
    if not isinstance(value, list) or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        raise InputError(f"{where}: expected a list of numbers, got {value!r}")
    if not all(math.isfinite(x) for x in value):
        raise InputError(f"{where}: contains NaN or infinite values")
    return [float(x) for x in value]


def _matrix(where, value) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise InputError(f"{where}: expected a matrix as a list of rows, got {value!r}")
    rows = [_numbers(where, r) for r in value]
    if len({len(r) for r in rows}) != 1:
        raise InputError(f"{where}: rows of different lengths")
    return np.asarray(rows)


def _positive(where, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InputError(f"{where}: expected a positive number, got {value!r}")
    return float(value)


def _warm_start(warm, steps: int, m: int, h: float) -> np.ndarray:
    if not warm:
        return np.zeros((steps, m))
    unknown = set(warm) - {"amplitude", "phase", "periods"}
    if unknown:
        raise InputError(f"warm_start: unknown key(s) {', '.join(sorted(unknown))}; expected amplitude, phase, periods")
    amp = np.asarray(_numbers("warm_start.amplitude", warm.get("amplitude", [0.0] * m)))
    phase = np.asarray(_numbers("warm_start.phase", warm.get("phase", [0.0] * m)))
    if amp.shape != (m,) or phase.shape != (m,):
        raise InputError(f"warm_start: amplitude and phase need one value per input ({m})")
    periods = warm.get("periods", 1.0)
    if isinstance(periods, bool) or not isinstance(periods, (int, float)) or not math.isfinite(periods):
        raise InputError(f"warm_start.periods: expected a number, got {periods!r}")
    T = steps * h
    t = (np.arange(steps) + 0.5) * h  # the middle of each step
    return amp[None, :] * np.sin(2 * np.pi * float(periods) * t[:, None] / T + phase[None, :])


def write_control_result(result, problem: ControlProblem | None, path, *, overwrite: bool = False) -> None:
    """Write a :class:`~gnipy.control.ControlResult` to netCDF, whole or not at all: the controlled
    run's nodes (as `gni run` writes them), the controls `u(step, input)` with the step's start
    time `t_step(step)`, and the solver's figures as attributes (cost, target and KKT residuals,
    iterations, wall time, the problem file's text)."""
    import xarray as xr

    from .. import schema
    from ..io import write_netcdf

    K, m = result.controls.shape
    names = list(problem.input_names) if problem is not None else list(result.input_names)
    attrs = {
        "command": "gni control",
        "control_problem": problem.name if problem is not None else "",
        "control_cost": float(result.cost),
        "control_target_residual": float(result.target_residual),
        "control_kkt_residual": float(result.kkt_residual),
        "control_active_bounds": int(result.active_bounds),
        "control_iterations": int(result.iterations),
        "control_polish_iterations": int(result.polish_iterations),
        "control_success": int(result.success),
        "control_message": str(result.message),
        "control_wall_time_s": float(result.wall_time),
        "control_continuous_miss": float(result.continuous_miss),
        "control_transcription": "direct shooting on the method's steps (gnipy.control)",
    }
    if problem is not None and problem.source:
        attrs["control_problem_file"] = problem.source
    ds = result.solution.to_xarray(attrs=attrs)
    t = np.asarray(result.solution.t)
    ds["u"] = xr.DataArray(np.asarray(result.controls, dtype=np.float64), dims=schema.dims("u"),
                           attrs={**schema.variable_attrs("u"), "components": ",".join(names)})
    ds = ds.assign_coords(control_step=np.arange(K), input=names, control_time=("control_step", t[:K]))
    for name in ("control_step", "control_time", "input"):
        ds[name].attrs.update(schema.variable_attrs(name))
    write_netcdf(ds, path, overwrite=overwrite)


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

    def solve(self, progress=False):
        """:func:`gnipy.fit` on this problem."""
        from .identification import fit

        return fit(self.model, self.observations, params=self.params or None, fixed=self.fixed or None,
                   initial=self.initial, method=self.method, h=self.h, t0=self.t0, q0=self.q0, v0=self.v0,
                   R0=self.R0, progress=progress)


def load_fit_problem(source, *, name: str = "fit") -> FitProblem:
    """Read a fit problem: a path to a TOML file (its observation file is relative to it), TOML
    text, or a parsed mapping (paths then relative to the working directory).

    Raises:
        InputError: a missing or malformed entry, named by its section and key.
    """
    from .identification import Observations

    data, text, base, name = _read(source, name)
    unknown = set(data) - _FIT_SECTIONS
    if unknown:
        raise InputError(f"problem: unknown section(s) {', '.join(sorted(unknown))}; expected "
                         f"{', '.join(sorted(_FIT_SECTIONS))}")
    from ..registry import get_model

    system_sec = _section(data, "system")
    _known_keys(data, {"system": {"model", "params"}, "start": {"q0", "v0", "R0"}})
    model = system_sec.get("model")
    if not isinstance(model, str):
        raise InputError("system.model: expected a model name (see `gni models`)")
    try:
        get_model(model)
    except (KeyError, ValueError, InputError) as e:
        raise InputError(f"system.model: {e}") from None
    fixed = dict(system_sec.get("params") or {})
    estimate = _section(data, "estimate")
    unknown = set(estimate) - {"params", "initial"}
    if unknown:
        raise InputError(f"estimate: unknown key(s) {', '.join(sorted(unknown))}; expected params, initial")
    params = dict(estimate.get("params") or {})
    initial = estimate.get("initial", [])
    if isinstance(initial, str):
        initial = [initial]
    if not isinstance(initial, list) or not set(initial) <= {"q0", "v0"}:
        raise InputError(f"estimate.initial: expected a list of 'q0' and/or 'v0', got {initial!r}")
    if not params and not initial:
        raise InputError("estimate: nothing to estimate: give params = {...} and/or initial = [...]")
    obs_sec = _section(data, "observations")
    unknown = set(obs_sec) - {"file", "variables", "sigma"}
    if unknown:
        raise InputError(f"observations: unknown key(s) {', '.join(sorted(unknown))}; expected file, variables, sigma")
    file = obs_sec.get("file")
    if not isinstance(file, str) or not file:
        raise InputError("observations.file: expected the path of a gnipy result file (netCDF)")
    obs_path = Path(file) if Path(file).is_absolute() else base / file
    if not obs_path.is_file():
        raise InputError(f"observations.file: cannot read {str(obs_path)!r}: no such file")
    variables = obs_sec.get("variables")
    if variables is not None and (not isinstance(variables, list) or not all(isinstance(v, str) for v in variables)):
        raise InputError(f"observations.variables: expected a list of names, got {variables!r}")
    sigma = obs_sec.get("sigma")
    if sigma is not None:
        sigma = _positive("observations.sigma", sigma)
    observations = Observations.from_dataset(str(obs_path), variables, sigma=sigma)
    start = data.get("start", {})
    q0 = tuple(_numbers("start.q0", start["q0"])) if "q0" in start else None
    v0 = tuple(_numbers("start.v0", start["v0"])) if "v0" in start else None
    R0 = np.asarray(_matrix("start.R0", start["R0"])) if "R0" in start else None
    integ = data.get("integration", {})
    unknown = set(integ) - {"method", "h", "t0"}
    if unknown:
        raise InputError(f"integration: unknown key(s) {', '.join(sorted(unknown))}; expected method, h, t0")
    h = integ.get("h")
    if h is None:
        import xarray as xr

        with xr.open_dataset(obs_path) as ds:
            h = ds.attrs.get("h")
        if h is None:
            raise InputError("integration.h: missing, and the observation file does not record its h")
    h = _positive("integration.h", float(h))
    t0 = integ.get("t0", 0.0)
    if isinstance(t0, bool) or not isinstance(t0, (int, float)) or not math.isfinite(t0):
        raise InputError(f"integration.t0: expected a number, got {t0!r}")
    return FitProblem(name=str(data.get("name", name)), description=str(data.get("description", "")).strip(),
                      model=model, fixed=fixed, params=params, initial=tuple(initial), observations=observations,
                      q0=q0, v0=v0, R0=R0, method=integ.get("method"), h=h, t0=float(t0), source=text)


def write_fit_result(result, problem: FitProblem | None, path, *, overwrite: bool = False) -> None:
    """Write a :class:`~gnipy.control.FitResult` to netCDF, whole or not at all: the fitted run's
    nodes (as `gni run` writes them), the estimates `estimate(quantity)`, their standard errors
    `standard_error(quantity)` and covariance `covariance(quantity, quantity_)`, and the fit's
    figures (chi², degrees of freedom, iterations) as attributes."""
    import xarray as xr

    from .. import schema
    from ..io import write_netcdf

    attrs = {
        "command": "gni fit",
        "fit_chi2": float(result.chi2),
        "fit_dof": int(result.dof),
        "fit_reduced_chi2": float(result.reduced_chi2),
        "fit_n_obs": int(result.n_obs),
        "fit_rank": int(result.rank),
        "fit_sigma_known": int(result.sigma_known),
        "fit_success": int(result.success),
        "fit_message": str(result.message),
        "fit_iterations": int(result.iterations),
        "fit_wall_time_s": float(result.wall_time),
        "fit_observed_variables": ",".join(result.observations.variables),
    }
    if problem is not None and problem.source:
        attrs["fit_problem_file"] = problem.source
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
