"""Optimal-control problems as data: the TOML problem files of `gni control`, the worked control
problems, and the result files.

A control problem file (:func:`load_problem`) has the sections

- `[system]`: `model` (a zoo model's name) and `params` (a table of parameter values);
- `[inputs]`: one entry per input, `name = { velocity name = gain }`: the force $F = Bu$ of
  actuators along those velocity components (:func:`gnipy.forcing.input_force`);
- `[start]`: `q0`, `v0` and, on $\\mathbb{R}^n\\times G$, `R0` (default: the model's), and
  `project_v0 = true` to project a `v0` that violates the constraints onto them;
- `[horizon]`: `h` and `steps`;
- `[target]`: coordinate and velocity names with their values, and `R` (a matrix);
- `[solver]` (optional): `method`, `bounds = [lower, upper]`, `effort`, `smoothness`,
  `max_iterations`, `segments`, `starts`, `optimizer` (`"slsqp"` or `"ipopt"`) (the arguments of
  :func:`gnipy.control.solve_optimal_control`);
- `[warm_start]` (optional): $u_j(t) = a_j\\sin(2\\pi\\,\\mathrm{periods}\\,t/T + \\phi_j)$ from
  `amplitude`, `phase` and `periods`, or `file = "earlier.nc"`, the inputs of an earlier `gni
  control` result (a path relative to the problem file; the inputs' names must match, and on
  another grid the earlier inputs, held over their steps, are read at the middle of each new step,
  the last one held past the earlier horizon) (default: zero inputs);
- `name`, `description` (optional).

Every entry is checked when the file is read, before anything is compiled: a value of the wrong
type (a string or a boolean is not a number), out of range, NaN or infinite, or of the wrong size
for the model is an :class:`~gnipy.errors.InputError` naming its key (`horizon.steps: ...`,
`inputs.torque: ...`), as is a problem whose memory is estimated beyond the bound (`max_bytes`).

:data:`WORKED_PROBLEMS` holds the two worked problems of the control guide as such files.

The reading of the files and the checks of their entries are :mod:`gnipy.control.problem_files`;
fit problem files are :mod:`gnipy.control.fit_problems`.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..extras import require
from ..errors import InputError
from ..system import System
from .problem_files import (
    build_model_system,
    describe_entry,
    entry_flag,
    entry_integer,
    entry_method,
    entry_model,
    entry_number,
    entry_numbers,
    entry_rotation,
    entry_start,
    entry_table,
    entry_text,
    is_entry_number,
    quoted_names,
    read_problem,
    refuse_unknown_keys,
)

__all__ = ["ControlProblem", "WORKED_PROBLEMS", "worked_problem", "load_problem", "write_control_result"]

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


def worked_problem(name: str, steps: int | None = None) -> str:
    """The problem file of the worked problem `name` (:data:`WORKED_PROBLEMS`); with `steps`, at
    that many steps over its own horizon (h scaled to keep `steps` x h): the same problem at
    another resolution (the control benchmark's, BENCHMARKS.md section 11).

    Raises:
        InputError: an unknown `name`, or `steps` not a whole number >= 1.
    """
    import re

    if name not in WORKED_PROBLEMS:
        raise InputError(f"name: expected one of {', '.join(map(repr, WORKED_PROBLEMS))}, got {name!r}")
    text = WORKED_PROBLEMS[name]
    if steps is None:
        return text
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"steps: expected a whole number of steps >= 1, got {steps!r}")
    k = int(re.search(r"^steps = (\d+)$", text, re.M).group(1))
    h = float(re.search(r"^h = ([0-9.eE+-]+)$", text, re.M).group(1))
    text = re.sub(r"^steps = \d+$", f"steps = {int(steps)}", text, flags=re.M)
    return re.sub(r"^h = [0-9.eE+-]+$", f"h = {h * k / int(steps)!r}", text, flags=re.M)

_SECTIONS = {"name", "description", "system", "inputs", "start", "horizon", "target", "solver", "warm_start"}

@dataclasses.dataclass(frozen=True)
class ControlProblem:
    """An optimal-control problem read from a problem file (module docstring).

    Attributes:
        name, description: from the file.
        system: the forced System (the model with the input force).
        input_names: the inputs' names, in order.
        target: the target mapping (:func:`gnipy.control.terminal_residual`).
        q0, v0, R0: the start; `project_v0`: project v0 onto the constraints.
        h, steps: the horizon.
        method, bounds, effort, smoothness, max_iterations, segments, starts, optimizer: the
            solver's options.
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
    project_v0: bool = False
    starts: int = 1
    optimizer: str = "slsqp"

    def solve(self, progress=False, check_continuous: bool = True, max_bytes="auto"):
        """:func:`gnipy.control.solve_optimal_control` on this problem (`max_bytes` as there)."""
        from .optimal_control import solve_optimal_control

        return solve_optimal_control(
            self.system, self.target, h=self.h, steps=self.steps, q0=self.q0, v0=self.v0, R0=self.R0,
            method=self.method, controls0=self.controls0, bounds=self.bounds, effort=self.effort,
            smoothness=self.smoothness, segments=self.segments,
            max_iterations=self.max_iterations, progress=progress, input_names=self.input_names,
            check_continuous=check_continuous, project_v0=self.project_v0, max_bytes=max_bytes,
            starts=self.starts, optimizer=self.optimizer)


def load_problem(source, *, name: str = "problem", max_bytes="auto") -> ControlProblem:
    """Read a problem: a path to a TOML file, TOML text (a string holding a newline), a parsed
    mapping, or the name of a worked problem (:data:`WORKED_PROBLEMS`).

    Every entry is checked here, before anything is compiled: its type (a string or a boolean is
    not a number, NaN and infinities are refused), its range, and its size against the model (the
    lengths of `q0`, `v0`, the names of the target, `R0` and `R` rotations).

    Arguments:
        source: the problem (see above).
        name: the problem's name when the file has none and is not a path (a path's stem is).
        max_bytes: the memory bound of :func:`gnipy.control.solve_optimal_control`, checked here
            (before the warm start is built): `"auto"`, a number of bytes or None.

    Raises:
        InputError: a missing or malformed entry, named by its section and key (`horizon.steps:
            ...`), or a problem estimated beyond `max_bytes` (naming `horizon.steps`).
    """
    from ..forcing import input_force
    from ..simulate import MAX_TOTAL_STEPS, MIN_STEP_SIZE
    from .memory import check_control_memory
    from .control_arguments import OPTIMIZERS
    from .optimal_control import MAX_ITERATIONS, MAX_STARTS

    if isinstance(source, str) and source in WORKED_PROBLEMS:
        source = WORKED_PROBLEMS[source]
    data, text, folder, name = read_problem(source, name, f"a worked problem's name ({', '.join(WORKED_PROBLEMS)})")
    unknown = set(data) - _SECTIONS
    if unknown:
        raise InputError(f"problem: unknown section(s) {quoted_names(unknown)}; expected {', '.join(sorted(_SECTIONS))}")
    title = entry_text("name", data.get("name", name))
    description = entry_text("description", data.get("description", "")).strip()
    spec, params = entry_model(data, folder)
    base = build_model_system(spec, params, "system.params")
    F, m, input_names = input_force(base, entry_table(data, "inputs"))
    system = base.with_force(F, inputs=m)
    start = entry_table(data, "start", required=False)
    refuse_unknown_keys(start, "start", {"q0", "v0", "R0", "project_v0"})
    q0, v0, R0 = entry_start(start, system, spec, params)
    project_v0 = entry_flag("start.project_v0", start.get("project_v0", False))
    horizon = entry_table(data, "horizon")
    refuse_unknown_keys(horizon, "horizon", {"h", "steps"})
    h = entry_number("horizon.h", horizon.get("h"), positive=True)
    if h < MIN_STEP_SIZE:
        raise InputError(f"horizon.h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision")
    steps = entry_integer("horizon.steps", horizon.get("steps"), 1, MAX_TOTAL_STEPS)
    if not math.isfinite(h * steps):
        raise InputError(f"horizon: the horizon h x steps = {h!r} x {steps} is not a finite time")
    target = _target(entry_table(data, "target"), system)
    solver = entry_table(data, "solver", required=False)
    refuse_unknown_keys(solver, "solver", {"method", "bounds", "effort", "smoothness", "max_iterations", "segments",
                                           "starts", "optimizer"})
    method = entry_method("solver.method", solver.get("method", "gni-trapezoid"))
    bounds = _bounds(solver.get("bounds"), m)
    effort = entry_number("solver.effort", solver.get("effort", 1.0), nonnegative=True)
    smoothness = entry_number("solver.smoothness", solver.get("smoothness", 0.0), nonnegative=True)
    max_iterations = entry_integer("solver.max_iterations", solver.get("max_iterations", 500), 1, MAX_ITERATIONS)
    segments = entry_integer("solver.segments", solver.get("segments", 1), 1, steps, "horizon.steps")
    starts = entry_integer("solver.starts", solver.get("starts", 1), 1, MAX_STARTS)
    if starts > 1 and segments > 1:
        raise InputError("solver.starts: a multistart is for single shooting (solver.segments = 1)")
    optimizer = entry_text("solver.optimizer", solver.get("optimizer", "slsqp"))
    if optimizer not in OPTIMIZERS:
        raise InputError(f"solver.optimizer: expected one of {', '.join(map(repr, OPTIMIZERS))}, got {optimizer!r}")
    size = sum(system.group.dim if k == "R" else 1 for k in target)
    if size > steps * m:
        raise InputError(f"horizon.steps: the target's {size} conditions need at least as many controls; "
                         f"{steps} steps x {m} inputs are {steps * m}")
    # refused before the warm start (K x m numbers) is built or anything is compiled
    check_control_memory(system, steps, size, segments, max_bytes, key="horizon.steps", optimizer=optimizer)
    warm = entry_table(data, "warm_start", required=False)
    controls0 = _warm_start(warm, steps, m, h, folder, input_names)
    return ControlProblem(
        name=title, description=description, system=system, input_names=input_names, target=target, q0=q0, v0=v0,
        R0=R0, h=h, steps=steps, method=method, bounds=bounds, effort=effort, smoothness=smoothness,
        max_iterations=max_iterations, segments=segments, controls0=controls0, source=text, project_v0=project_v0,
        starts=starts, optimizer=optimizer)


def _target(table: Mapping, system: System) -> dict:
    """The `[target]` table: coordinate and velocity names with numbers, `R` a rotation."""
    names = (*system.coordinates, *system.velocities) + (("R",) if system.group is not None else ())
    target = {}
    for key, value in table.items():
        if key == "R" and system.group is not None:
            target[key] = entry_rotation("target.R", value, system)
        elif key in names:
            target[key] = entry_number(f"target.{key}", value)
        else:
            raise InputError(f"target: unknown name {key!r}; expected one of {', '.join(names)}")
    return target


def _bounds(value, m: int):
    """`[lower, upper]`, each a number or one per input; lower < upper (-inf and inf: no bound)."""
    if value is None:
        return None
    if not isinstance(value, list) or len(value) != 2:
        raise InputError(f"solver.bounds: expected [lower, upper], got {describe_entry(value)}")
    sides = []
    for side, b in zip(("lower", "upper"), value):
        if isinstance(b, list):
            if len(b) != m or not all(is_entry_number(x) for x in b):
                raise InputError(f"solver.bounds: the {side} bound must be a number or a list of {m} numbers (one per "
                                 f"input), got {describe_entry(b)}")
        elif not is_entry_number(b):
            raise InputError(f"solver.bounds: the {side} bound must be a number, got {describe_entry(b)}")
        arr = np.broadcast_to(np.asarray(b, dtype=np.float64), (m,))
        if np.any(np.isnan(arr)):
            raise InputError(f"solver.bounds: the {side} bound is NaN")
        sides.append(arr)
    lo, hi = sides
    if np.any(lo >= hi):
        raise InputError(f"solver.bounds: need lower < upper for every input, got {value[0]!r} and {value[1]!r}")
    return value[0], value[1]


#: The most inputs a warm-start file may hold (steps x inputs), checked before they are read.
MAX_WARM_START_VALUES = 10_000_000


def _warm_start(warm, steps: int, m: int, h: float, folder=None, input_names=()) -> np.ndarray:
    if not warm:
        return np.zeros((steps, m))
    if "file" in warm:
        refuse_unknown_keys(warm, "warm_start", {"file"})
        return _warm_start_file(warm["file"], steps, m, h, folder, input_names)
    refuse_unknown_keys(warm, "warm_start", {"amplitude", "phase", "periods"})
    names = tuple(f"input {j + 1}" for j in range(m))
    amp = np.asarray(entry_numbers("warm_start.amplitude", warm.get("amplitude", [0.0] * m), names))
    phase = np.asarray(entry_numbers("warm_start.phase", warm.get("phase", [0.0] * m), names))
    periods = entry_number("warm_start.periods", warm.get("periods", 1.0))
    T = steps * h
    t = (np.arange(steps) + 0.5) * h  # the middle of each step
    with np.errstate(invalid="ignore", over="ignore"):  # checked below
        u = amp[None, :] * np.sin(2 * np.pi * periods * t[:, None] / T + phase[None, :])
    if not np.all(np.isfinite(u)):
        raise InputError(f"warm_start: the inputs it makes are not finite (the phase 2 pi periods t / T + phase "
                         f"overflows for periods = {periods!r}, phase = {phase.tolist()!r}); choose smaller values")
    return u


def _warm_start_file(file, steps: int, m: int, h: float, folder, input_names) -> np.ndarray:
    """The inputs of an earlier `gni control` result file as the warm start (module docstring): read
    as data only (numbers; nothing in the file is executed), its size checked before they are read."""
    from pathlib import Path

    xr = require("xarray", extra="files")
    if not isinstance(file, str) or not file or "\x00" in file:
        raise InputError(f"warm_start.file: expected the path of a gni control result file (netCDF), got "
                         f"{describe_entry(file)}")
    path = Path(file) if Path(file).is_absolute() else Path(".") / file if folder is None else Path(folder) / file
    if not path.is_file():
        raise InputError(f"warm_start.file: {path}: no such file")
    try:
        with xr.open_dataset(path) as ds:
            if "u" not in ds or ds["u"].dims != ("control_step", "input") or "control_time" not in ds:
                raise InputError(f"warm_start.file: {path} holds no inputs u(control_step, input) with their "
                                 "control_time: not a gni control result")
            if ds["u"].size > MAX_WARM_START_VALUES:
                raise InputError(f"warm_start.file: {path} holds {ds['u'].size} inputs, more than "
                                 f"{MAX_WARM_START_VALUES:,}")
            names = [str(x) for x in np.asarray(ds["input"].values)] if "input" in ds.coords else []
            u = np.asarray(ds["u"].values, dtype=np.float64)
            t = np.asarray(ds["control_time"].values, dtype=np.float64)
    except (OSError, ValueError) as e:
        raise InputError(f"warm_start.file: cannot read {path}: {e}") from None
    expected = [str(x) for x in input_names] if input_names else names
    if u.shape[1] != m or (input_names and names != expected):
        raise InputError(f"warm_start.file: {path} holds the inputs {', '.join(names) or u.shape[1]}; this problem's "
                         f"are {', '.join(expected)}")
    if u.shape[0] == 0 or not (np.all(np.isfinite(u)) and np.all(np.isfinite(t))):
        raise InputError(f"warm_start.file: {path}: its inputs are empty or not finite")
    if u.shape[0] == steps and (steps == 1 or np.allclose(np.diff(t), h, rtol=1e-12, atol=0.0)):
        return u
    # another grid: the earlier inputs, held over their steps, read at the middle of each new step
    rel = t - t[0]
    mid = (np.arange(steps) + 0.5) * h
    k = np.clip(np.searchsorted(rel, mid, side="right") - 1, 0, u.shape[0] - 1)
    return u[k]


def write_control_result(result, problem: ControlProblem | None, path, *, overwrite: bool = False) -> None:
    """Write a :class:`~gnipy.control.ControlResult` to netCDF, whole or not at all: the controlled
    run's nodes (as `gni run` writes them), the controls `u(step, input)` with the step's start
    time `t_step(step)`, and the solver's figures as attributes (cost, target and KKT residuals,
    iterations, wall time, the problem file's text)."""
    xr = require("xarray", extra="files")

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
        "control_redundant_components": ",".join(result.redundant_components),
        "control_starts": int(result.starts),
        "control_optimizer": str(result.optimizer),
        "control_local_optima": ", ".join(f"{c!r} ({n})" for c, n in result.local_optima),
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
