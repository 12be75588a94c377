"""The arguments of :func:`~gnipy.control.optimal_control.solve_optimal_control`, checked before
anything is compiled: the numbers and flags (:func:`control_arguments`), the inputs' bounds and
names, the progress report, the warm start, and the terminal target (:func:`terminal_residual`).
Every refusal is an :class:`~gnipy.errors.InputError` naming the argument (a string or a boolean is
not a number)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..extras import require
from ..errors import InputError
from ..inputs import real_array, real_number, whole_number
from ..simulate import MAX_TOTAL_STEPS, MIN_STEP_SIZE
from ..system import System

__all__ = ["ControlArguments", "control_arguments", "terminal_residual", "TerminalResidual", "TargetSubset",
           "target_size", "warm_start", "control_bounds", "control_reporter", "MAX_ITERATIONS", "OPTIMIZERS"]


#: The largest `max_iterations` accepted: SciPy's solvers count iterations in 32-bit integers, and an
#: SQP that has not converged after a million iterations on these problems will not.
MAX_ITERATIONS = 10**6

#: The optimizers of a solve: SciPy's SLSQP (:mod:`gnipy.control.sqp`, the default) and IPOPT with
#: the exact Hessian (:mod:`gnipy.control.ipopt`, the `ipopt` extra).
OPTIMIZERS = ("slsqp", "ipopt")


@dataclasses.dataclass(frozen=True)
class ControlArguments:
    """The checked arguments of a solve (:func:`control_arguments`): the number K of `steps` and m
    of inputs, and `h`, `effort`, `smoothness`, `t0`, `target_tol`, `kkt_tol`, `segments`,
    `max_iterations` and `input_names` (None or a tuple of m names) as given; `lo`, `hi`: the
    inputs' bounds, (m,) each; `report`: the `(iteration, cost, miss, total)` callable of
    `progress`, or None; `optimizer`: one of :data:`OPTIMIZERS`."""

    K: int
    m: int
    h: float
    effort: float
    smoothness: float
    t0: float
    target_tol: float
    kkt_tol: float
    segments: int
    max_iterations: int
    lo: np.ndarray
    hi: np.ndarray
    report: Callable | None
    input_names: tuple[str, ...] | None
    optimizer: str = "slsqp"


def control_arguments(system, *, steps, h, effort, smoothness, t0, target_tol, kkt_tol, running_cost, segments,
                      max_iterations, check_continuous, project_v0, bounds, progress, input_names,
                      optimizer="slsqp") -> ControlArguments:
    """The arguments of a solve (by the names of
    :func:`~gnipy.control.optimal_control.solve_optimal_control`), checked in this order: a forced
    System with inputs, the numbers, `running_cost`, the flags, `bounds`, `progress`,
    `input_names` and `optimizer` (IPOPT's package installed)."""
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if not system.is_forced or system.inputs == 0:
        raise InputError("system: an optimal-control problem needs inputs: System(..., force=F, inputs=m) "
                         "or system.with_force(F, inputs=m)")
    K, m = whole_number("steps", steps, 1, MAX_TOTAL_STEPS), system.inputs
    h = real_number("h", h, lower=0.0, strict=True)
    if h < MIN_STEP_SIZE:
        raise InputError(f"h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision")
    effort = real_number("effort", effort, lower=0.0)
    smoothness = real_number("smoothness", smoothness, lower=0.0)
    t0 = real_number("t0", t0)
    target_tol = real_number("target_tol", target_tol, lower=0.0, strict=True)
    kkt_tol = real_number("kkt_tol", kkt_tol, lower=0.0, strict=True)
    if running_cost is not None and not callable(running_cost):
        raise InputError(f"running_cost: expected a callable c(q, v, u, t), got {type(running_cost).__name__}")
    segments = whole_number("segments", segments, 1, K)
    max_iterations = whole_number("max_iterations", max_iterations, 1, MAX_ITERATIONS)
    for flag_name, value in (("check_continuous", check_continuous), ("project_v0", project_v0)):
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(f"{flag_name}: expected True or False, got {value!r}")
    lo, hi = control_bounds(bounds, m)
    report = control_reporter(progress)
    names = _input_names(input_names, m)
    if not isinstance(optimizer, str) or optimizer not in OPTIMIZERS:
        raise InputError(f"optimizer: expected one of {', '.join(map(repr, OPTIMIZERS))}, got {optimizer!r}")
    if optimizer == "ipopt":  # before anything is compiled: the missing package named with its extra
        require("cyipopt", extra="ipopt", what="IPOPT optimizer (optimizer='ipopt')")
    return ControlArguments(K=K, m=m, h=h, effort=effort, smoothness=smoothness, t0=t0, target_tol=target_tol,
                            kkt_tol=kkt_tol, segments=segments, max_iterations=max_iterations, lo=lo, hi=hi,
                            report=report, input_names=names, optimizer=optimizer)


def _input_names(input_names, m: int):
    if input_names is not None:
        try:
            if isinstance(input_names, (str, bytes)):
                raise TypeError
            input_names = tuple(input_names)
        except TypeError:
            raise InputError(f"input_names: expected a sequence of {m} names, got {input_names!r}") from None
        if len(input_names) != m or not all(isinstance(n, str) for n in input_names):
            raise InputError(f"input_names: expected {m} names (strings), got {input_names!r}")
        if len(set(input_names)) != m:
            raise InputError(f"input_names: repeated names in {list(input_names)}")
    return input_names


def target_size(system: System, target, controls: int) -> int:
    """The number of components of the target (at least one for a callable, whose size is known
    only once it is evaluated); InputError when they outnumber the `controls`."""
    if callable(target):
        d = 1  # not known before it is evaluated (by a simulation): at least one component
    else:
        d = sum(system.group.dim if name == "R" else 1 for name in target)
    if d > controls:
        raise InputError(f"target: {d} conditions on {controls} controls; use more steps")
    return d


def warm_start(controls0, K: int, m: int) -> np.ndarray:
    """The warm start `controls0` as a finite (K, m) array (zeros for None)."""
    if controls0 is None:
        return np.zeros((K, m))
    U0 = real_array("controls0", controls0, f"a ({K}, {m}) array of numbers")
    if U0.ndim == 1 and m == 1:
        U0 = U0[:, None]
    if U0.shape != (K, m) or not np.all(np.isfinite(U0)):
        raise InputError(f"controls0: expected a finite array of shape ({K}, {m}), got {np.shape(controls0)}")
    return U0


def terminal_residual(system: System, target) -> Callable:
    """The terminal constraint $g(b, v)$ of a target, as a function of the final base point and
    velocity.

    Arguments:
        system: the System (its coordinate and velocity names).
        target: a mapping from names to values: coordinate names (`system.coordinates`),
            velocity names (`system.velocities`), and `"R"` for the orientation on
            $\\mathbb{R}^n\\times G$ (a matrix; the residual is $\\log(R_{target}^{-1}R)$, three
            components on SO(3)); or a callable `g(b, v) -> (d,)`.

    Raises:
        InputError: unknown names, or no component.
    """
    if callable(target):
        return target
    if not isinstance(target, Mapping) or not target:
        raise InputError("target: expected a mapping of names to values (coordinates, velocities, 'R') "
                         "or a callable g(b, v)")
    coords = {c: i for i, c in enumerate(system.coordinates)}
    vels = {c: i for i, c in enumerate(system.velocities)}
    q_idx, q_val, v_idx, v_val, R_target = [], [], [], [], None
    for name, value in target.items():
        if name == "R":
            if system.group is None:
                raise InputError("target: 'R' is for systems with a group part")
            k = system.group.matrix_size
            R_target = real_array("target: 'R'", value, f"a {k}x{k} matrix")
            if R_target.shape != (k, k) or not np.all(np.isfinite(R_target)):
                raise InputError(f"target: 'R' must be a finite {k}x{k} matrix, got shape {R_target.shape}")
            if not system.group.is_element(R_target):  # the group's own test (e.g. a rotation on SO(3))
                raise InputError(f"target: 'R' is not a group element: {system.group.why_not_element(R_target)}")
        elif name in coords:
            q_idx.append(coords[name])
            q_val.append(_finite("target", name, value))
        elif name in vels:
            v_idx.append(vels[name])
            v_val.append(_finite("target", name, value))
        else:
            raise InputError(f"target: unknown name {name!r}; expected one of {', '.join([*coords, *vels])}"
                             + (", R" if system.group is not None else ""))
    return TerminalResidual(space=system.space, group=system.group, q_idx=tuple(q_idx),
                            q_val=jnp.asarray(q_val, jnp.float64), v_idx=tuple(v_idx),
                            v_val=jnp.asarray(v_val, jnp.float64),
                            R_target=None if R_target is None else jnp.asarray(R_target, jnp.float64))


class TerminalResidual(eqx.Module):
    """$g(b, v)$ of a target given by names (:func:`terminal_residual`): the targeted coordinates
    and velocities minus their values, then $\\log(R_{target}^{-1}R)$. A pytree whose values are
    arrays: targets of one shape share one compiled program whatever their values."""

    space: Any
    group: Any
    q_idx: tuple = eqx.field(static=True)
    q_val: jax.Array
    v_idx: tuple = eqx.field(static=True)
    v_val: jax.Array
    R_target: Any

    def __call__(self, b, v):
        parts = []
        if self.q_idx:
            parts.append(self.space.coordinates(b)[jnp.asarray(self.q_idx)] - self.q_val)
        if self.v_idx:
            parts.append(v[jnp.asarray(self.v_idx)] - self.v_val)
        if self.R_target is not None:
            parts.append(self.group.log(self.R_target.T @ self.space.orientation(b)))
        return jnp.concatenate(parts)


class TargetSubset(eqx.Module):
    """The components `keep` of a terminal residual `g` (a redundant target's independent ones)."""

    g: Any
    keep: tuple = eqx.field(static=True)

    def __call__(self, b, v):
        return self.g(b, v)[jnp.asarray(self.keep)]


def _finite(arg, name, value) -> float:
    return real_number(f"{arg}: {name!r}", value)


def control_bounds(bounds, m: int):
    """`(lower, upper)`: the bounds of the m inputs, (m,) each (infinite on an unbounded side):
    `bounds` is None or a pair of numbers or of one number per input, lower < upper."""
    if bounds is None:
        return np.full(m, -np.inf), np.full(m, np.inf)
    what = f"(lower, upper), each a number or {m} numbers"
    try:
        pair = not isinstance(bounds, (str, bytes, Mapping)) and len(bounds) == 2
    except TypeError:  # no length (a number, a 0-d array)
        pair = False
    if not pair:
        raise InputError(f"bounds: expected {what}, got {bounds!r}")
    try:
        lo, hi = (np.broadcast_to(real_array(f"bounds: {side}", b, "a number or one per input"), (m,)).copy()
                  for side, b in zip(("lower", "upper"), bounds))
    except ValueError as e:  # an InputError, or a shape that does not broadcast
        if isinstance(e, InputError):
            raise
        raise InputError(f"bounds: expected {what}, got {bounds!r}") from None
    # an infinite bound is no bound on that side; lower = +inf or upper = -inf fail lower < upper
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo >= hi):
        raise InputError(f"bounds: need lower < upper for every input, got {lo} and {hi}")
    return lo, hi


def control_reporter(progress):
    """The `(iteration, cost, miss, total)` callable of `progress=`, or None."""
    import inspect

    if progress is False or progress is None:
        return None
    if progress is True:
        require("rich", extra="cli", what="progress display")
        from rich.console import Console

        console = Console(stderr=True, markup=False, highlight=False)
        return lambda i, J, miss, total: console.print(f"iteration {i:4d}: cost {J:.10g}, target miss {miss:.3e}")
    if callable(progress) and not isinstance(progress, (bool, np.bool_)):
        try:
            inspect.signature(progress).bind(0, 0.0, 0.0, 0)
            takes_total = True
        except TypeError:
            takes_total = False
        except ValueError:  # no signature to inspect (some builtins): the documented three arguments
            takes_total = False
        return progress if takes_total else (lambda i, J, miss, total: progress(i, J, miss))
    raise InputError(f"progress: expected True, False or a callable(iteration, cost, miss[, total]), got {progress!r}")
