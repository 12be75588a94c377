"""Memory bounds of optimal control and identification: what :func:`gnipy.solve_optimal_control`
and :func:`gnipy.fit` are estimated to need, from measurements, checked before anything is
compiled (their `max_bytes`; `gni control` / `gni fit` lift it with `--yes`)."""

from __future__ import annotations

import math

from ..errors import InputError
from ..files import format_bytes
from ..inputs import is_real_scalar
from ..resources import memory_bound, node_bytes
from ..system import System

__all__ = ["memory_limit", "control_memory", "check_control_memory", "fit_memory", "check_fit_memory"]

#: Bytes of the dense matrices of the SQP solvers per squared unknown, measured with tracemalloc
#: (SciPy 1.17, n = 1000 and 1500 unknowns, bounds on each): SLSQP's workspace holds about 12 n² numbers,
#: the trust-constr fallback about 45 n² (its BFGS approximations and the interior point's
#: factorizations); the two run one after the other, so the larger counts.
_SQP_BYTES_PER_UNKNOWN2 = 8 * 46

#: Bytes per step that reverse mode keeps, per squared state size s = n + k² + N (the coordinates,
#: the orientation's k x k matrix, the velocity): the implicit steps' linearizations for the adjoint
#: solves. Measured (peak RSS of jax.jacrev of the target through 10³ .. 10⁶ steps) at about 1.4 s²
#: numbers a step on the sleigh (s = 6) and 1.0 s² on the rolling ball (s = 16); 2 s² is the estimate.
_REVERSE_NUMBERS_PER_STATE2 = 2

#: Numbers per unknown and step, per state size s, that IPOPT's exact Hessian may keep: with a running
#: cost it is forward mode over reverse mode through the run (a tangent per unknown through every step),
#: measured (peak RSS of the ball-plate problem with IPOPT through that path against SLSQP, 120 and 240
#: steps, 240 and 480 unknowns) to grow by 20 MB, about 29 numbers per unknown and step on the ball
#: (s = 16): 2 s is the estimate. Without one, the second-order adjoint (gnipy.control.second_order)
#: keeps O(n²) (its rows of the Hessian, counted with the Hessian's copies) and O(K s²).
_HESSIAN_NUMBERS_PER_UNKNOWN_STEP_STATE = 2

#: The copies of the controlled run's nodes held at once: the device arrays, their host copies, the
#: dataset written.
_NODE_COPIES = 3


def memory_limit(max_bytes, name: str = "max_bytes") -> int | None:
    """The memory bound that `max_bytes` stands for: `"auto"` the smaller of
    :data:`MAX_MEMORY_BYTES` and half the physical memory, `None` no bound, else a number of
    bytes (`InputError` naming `name` for anything else)."""
    if max_bytes is None:
        return None
    if isinstance(max_bytes, str) and max_bytes == "auto":
        return memory_bound()
    if not is_real_scalar(max_bytes) or not float(max_bytes) >= 0 or math.isnan(float(max_bytes)):
        raise InputError(f"{name}: expected a number of bytes >= 0, 'auto' or None, got {max_bytes!r}")
    return int(min(float(max_bytes), 2.0**62))


def control_memory(system: System, steps: int, *, target_size: int = 1, segments: int = 1,
                   optimizer: str = "slsqp", running_cost: bool = False) -> dict[str, int]:
    """The memory :func:`solve_optimal_control` is estimated to need, in bytes, by part (before
    anything is compiled; what `max_bytes` bounds).

    Arguments:
        system: the forced System (its inputs m, its state's size).
        steps: the number K of steps.
        target_size: the number d of the target's components.
        segments: the number S of shooting segments.
        optimizer: `"slsqp"` or `"ipopt"` (whose exact Hessian adds the `"hessian"` part).
        running_cost: whether the cost has a running cost (IPOPT's Hessian is then forward mode
            over reverse mode through the run, as with several segments).

    Returns:
        `{"sqp": ..., "jacobian": ..., "reverse": ..., "hessian": ..., "nodes": ..., "total": ...}`:
        the SQP's dense matrices, O(n²) in the n = K·m (+ the multiple-shooting states) unknowns
        (SciPy's SLSQP and trust-constr hold dense n x n matrices; IPOPT's fallback runs them
        too); the constraints' Jacobian (d + the defects) x n, in a few copies; what reverse mode
        keeps per step to differentiate through the steps, O(K s²) for the state size s; with
        IPOPT, the Hessian of the Lagrangian: the dense Hessian in five copies (the second-order
        adjoint's rows, JAX's, NumPy's, its lower triangle, IPOPT's factorization) and, where
        forward mode over reverse mode computes it (a running cost, several segments), a tangent
        per unknown through the steps, O(K s n); with every step a segment (`segments = steps`,
        :mod:`gnipy.control.step_shooting`) its sparse blocks, O(K (s + m)²); 0 with SLSQP; the
        controlled run's nodes, O(K).
    """
    k = system.group.matrix_size if system.group is not None else 0
    group_dim = system.group.dim if system.group is not None else 0
    state = system.n + k * k + system.dim
    every_step = segments == steps > 1  # gnipy.control.step_shooting: every state after a step, R's nine entries
    shooting = steps * state if every_step else (segments - 1) * (system.n + group_dim + system.dim)
    unknowns = steps * system.inputs + shooting
    if every_step:  # sparse: the blocks over (s_k, u_k), in five copies
        hessian = 8 * 5 * (steps * (state + system.inputs) ** 2 + 3 * steps * system.inputs)
    else:
        hessian = 8 * (_HESSIAN_NUMBERS_PER_UNKNOWN_STEP_STATE * state * steps * unknowns
                       * (running_cost or segments > 1) + 5 * unknowns**2)
    parts = {
        "sqp": _SQP_BYTES_PER_UNKNOWN2 * unknowns**2,
        "jacobian": 3 * 8 * (target_size + shooting) * unknowns,  # JAX's, its NumPy copy, SciPy's
        "reverse": 8 * _REVERSE_NUMBERS_PER_STATE2 * state**2 * steps,
        "hessian": hessian if optimizer == "ipopt" else 0,
        "nodes": _NODE_COPIES * (steps + 1) * node_bytes(system),
    }
    parts["total"] = sum(parts.values())
    return parts


def check_control_memory(system: System, steps: int, target_size: int, segments: int, max_bytes,
                         key: str = "steps", optimizer: str = "slsqp", running_cost: bool = False) -> None:
    """Refuse (`InputError` naming `key`) a problem whose :func:`control_memory` exceeds the bound
    of `max_bytes` (:func:`memory_limit`)."""
    bound = memory_limit(max_bytes)
    if bound is None:
        return
    need = control_memory(system, steps, target_size=target_size, segments=segments, optimizer=optimizer,
                          running_cost=running_cost)
    if need["total"] > bound:
        n = steps * system.inputs
        raise InputError(
            f"{key}: {steps:,} steps x {system.inputs} input{'s' if system.inputs > 1 else ''} = {n:,} controls "
            f"would need about {format_bytes(need['total'])} of memory (the SQP's dense matrices, which grow as the "
            f"square of the unknowns, {format_bytes(need['sqp'])}; differentiating through the steps "
            f"{format_bytes(need['reverse'])}"
            + (f"; IPOPT's exact Hessian {format_bytes(need['hessian'])}" if need["hessian"] else "")
            + f"; the run's nodes {format_bytes(need['nodes'])}): more than the bound of "
            f"{format_bytes(bound)}; use fewer steps (a larger h over the same horizon) or fewer inputs, or pass "
            "max_bytes=None to solve it anyway")




def fit_memory(system: System, span_steps: int, values: int, estimated: int) -> dict[str, int]:
    """The memory :func:`fit` is estimated to need, in bytes, by part (before anything is compiled;
    what `max_bytes` bounds).

    Arguments:
        system: the System (the size of its nodes).
        span_steps: the steps from `t0` to the last observation time.
        values: the observed values (times x variables, missing ones included).
        estimated: the number of estimated quantities.

    Returns:
        `{"nodes": ..., "jacobian": ..., "data": ..., "total": ...}`: the fitted run, which holds every
        node of the span, in a few copies (the device's, the host's, the dataset written); the
        Jacobian of the residuals, values x quantities (the solver's, its linear solve's
        factorization, the NumPy copies and the SVD of the uncertainties); the observations, weights
        and residuals. Forward mode differentiates through the steps without keeping them: its
        memory does not grow with the span (measured: the same peak for 10³ and 10⁶ steps), its
        time does (span x quantities per iteration).
    """
    parts = {
        "nodes": 3 * (span_steps + 1) * node_bytes(system),
        "jacobian": 6 * 8 * values * estimated,
        "data": 4 * 8 * values,
    }
    parts["total"] = sum(parts.values())
    return parts


def check_fit_memory(system: System, span_steps: int, values: int, estimated: int, *, t0: float, t_last: float,
                     h: float, max_bytes, key: str = "observations/h") -> None:
    """Refuse (`InputError` naming `key`) a fit whose :func:`fit_memory` exceeds the bound of
    `max_bytes` (:func:`memory_limit`); `t0`, `t_last` and `h` are
    for the message."""
    bound = memory_limit(max_bytes)
    if bound is None:
        return
    need = fit_memory(system, span_steps, values, estimated)
    if need["total"] > bound:
        raise InputError(
            f"{key}: the fit would need about {format_bytes(need['total'])} of memory (the fitted run holds every node "
            f"from t0 = {t0:g} to the last observation time {t_last:g} in steps of h = {h:g}: {span_steps + 1:,} "
            f"nodes, {format_bytes(need['nodes'])}; the Jacobian of {values:,} values x {estimated} quantities, "
            f"{format_bytes(need['jacobian'])}): more than the bound of {format_bytes(bound)}; observe a shorter span "
            "or use a larger h, or pass max_bytes=None to fit anyway")
