"""Discrete optimal control with the GNI as the dynamics (the paper's open question on optimal
control, §10; discrete mechanics and optimal control: Ober-Blöbaum, Junge & Marsden, *Discrete
mechanics and optimal control: an analysis*, ESAIM: COCV 2011; for nonholonomic systems
Kobilarov, Marsden & Sukhatme, DCDS-S 2010, and Jiménez, Kobilarov & Martín de Diego, *Discrete
variational optimal control*, J. Nonlinear Sci. 2013).

**The problem.** Given a forced system with inputs u (:mod:`gnipy.forcing`), a start
$(q_0, v_0, R_0)$, a step h and K steps, find per-step inputs $u_0, \\dots, u_{K-1}$ (held over each
step) that minimize

$$J(u) = \\sum_{k<K} h\\Big(\\tfrac{w}{2}|u_k|^2 + c(q_k, v_k, u_k, t_k)\\Big)
  + \\frac s2\\sum_{k<K-1}\\frac{|u_{k+1} - u_k|^2}{h}$$

subject to the discrete dynamics (the forced discrete Lagrange–d'Alembert steps of the chosen
method, by default the GNI with the trapezoid $l_d$), a terminal target $g(q_K, v_K, R_K) = 0$ and
bounds $u_{lo} \\le u_k \\le u_{hi}$.

**Transcription: direct shooting, single by default, multiple on request.** With one segment
(`segments=1`, the default) the unknowns are the controls only; the states are
eliminated by the steps themselves (:func:`gnipy.simulate`), and the derivatives of $J$ and $g$
with respect to all K·m controls come from reverse mode through the steps (the implicit steps
differentiated by the implicit function theorem). Why this choice: every iterate is then a
trajectory of the discrete dynamics that satisfies the nonholonomic constraints exactly (in a
simultaneous transcription the step equations and constraints hold only at convergence), the
problem has K·m unknowns and as many equality constraints as the target has components (instead
of adding K states and multipliers), and the GNI's step is already the solver of its own implicit
equations. Its limit: the sensitivity of the end state to early controls grows with the horizon
for unstable dynamics. Multiple shooting (`segments=S`) is the remedy there: the method's state
$(b, p^+)$ at the starts of segments 2..S becomes an unknown (the orientation as
$\\bar R\\exp(\\hat\\eta)$ about the warm start's), and the defects at the boundaries become
constraints; each segment is still a run of the GNI's steps. Measured on the worked problems
(2-core machine), single shooting was the better default: sleigh-steering 24 SQP iterations and
13 s with one segment, 67 iterations and 41 s with four (the same optimum); ball-plate 41
iterations and 27 s with one, and with four SLSQP reached its 500-iteration cap (the states'
unknowns, of other scales than the controls, slow its quasi-Newton updates).

**Solver.** Sequential quadratic programming with bounds (SciPy's SLSQP, Kraft 1988) on the exact
gradients, the cost scaled so that its Hessian starts near the identity (SLSQP's first guess of
it). Where SLSQP does not reach a KKT point (its active set can stall: measured on the sleigh at
h = 0.1 with the torque bound, every control at a bound and a miss of 0.9), a trust-region
interior-point method (SciPy's trust-constr) from the warm start, then SLSQP from its result. Last a
polish: Gauss–Newton steps on the free controls (those not at a bound),
$\\Delta u = -J_g^T(J_gJ_g^T)^{-1}g$, until the target is met to round-off. The result reports the
target's residual, the KKT residual $\\max|\\nabla J + J_g^T\\lambda|$ over the free controls (λ by
least squares) and the sign of the bound multipliers of the active controls; `success` asks for
all three. Written on SciPy's solvers because neither optimistix nor another JAX library offers
nonlinear equality constraints with bounds.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..extras import require
from ..errors import InputError
from ..inputs import real_array, real_number, whole_number
from ..resources import MAX_MEMORY_BYTES
from ..saveat import SaveAt
from ..simulate import MAX_TOTAL_STEPS, MIN_STEP_SIZE, default_initial_condition, simulate
from ..solution import Solution
from ..system import System
from .memory import check_control_memory

__all__ = ["solve_optimal_control", "ControlResult", "terminal_residual", "MAX_MEMORY_BYTES", "MAX_ITERATIONS"]


#: The largest `max_iterations` accepted: SciPy's solvers count iterations in 32-bit integers, and an
#: SQP that has not converged after a million iterations on these problems will not.
MAX_ITERATIONS = 10**6


@dataclasses.dataclass(frozen=True)
class ControlResult:
    """The solution of a discrete optimal-control problem (:func:`solve_optimal_control`).

    Attributes:
        controls: the optimal per-step inputs, shape (K, m).
        solution: the :class:`~gnipy.Solution` of the controlled run (every node).
        cost: $J(u)$ at the solution.
        target_residual: $\\max|g|$, the miss of the terminal target.
        kkt_residual: $\\max|\\nabla J + J_g^T\\lambda|$ over the controls not at a bound,
            relative to the larger of $\\max|\\nabla J|$ and $\\max|J_g^T\\lambda|$.
        bound_multipliers_ok: whether the multipliers of the controls at a bound have the sign
            of a minimum (pushing outward).
        multipliers: λ, one per component of the target.
        active_bounds: the number of controls at a bound.
        iterations: SQP iterations (and `polish_iterations` Gauss–Newton steps after them).
        polish_iterations: Gauss–Newton steps of the polish.
        success: the target is met to `target_tol`, the KKT residual is below `kkt_tol` and the
            bound multipliers have the right sign (checked here, whatever the SQP's own message).
        message: the SQP's message and what the polish did.
        wall_time: seconds, compilation included.
        method: the method of the dynamics.
        input_names: the inputs' names (`u0, u1, ...` unless given).
        target_jacobian: $\\partial g/\\partial u$ at the returned controls, (d, K·m) (reverse mode
            through the steps: the derivative the solver used; None after multiple shooting, whose
            Jacobian is that of the defects and the target with respect to controls and states).
        continuous_miss: $\\max|g|$ when the same held controls drive the continuous system (the
            reference, :class:`~gnipy.ContinuousReference`): how far the physical system ends from
            the target, the discretization's error (NaN when not checked).
    """

    controls: np.ndarray
    solution: Solution
    cost: float
    target_residual: float
    kkt_residual: float
    bound_multipliers_ok: bool
    multipliers: np.ndarray
    active_bounds: int
    iterations: int
    polish_iterations: int
    success: bool
    message: str
    wall_time: float
    method: str
    input_names: tuple[str, ...] = ()
    continuous_miss: float = float("nan")
    target_jacobian: np.ndarray | None = None

    def summary(self) -> str:
        """A few lines: success, cost, residuals, iterations and time."""
        K, m = self.controls.shape
        return "\n".join([
            f"optimal control with {self.method}: {K} steps x {m} input{'s' if m > 1 else ''}, "
            f"{'converged' if self.success else 'NOT converged'} ({self.message})",
            f"  cost J = {self.cost:.12g}",
            f"  target residual max|g| = {self.target_residual:.3e}",
            f"  KKT residual (free controls) = {self.kkt_residual:.3e}; {self.active_bounds} controls at a bound"
            + ("" if self.active_bounds == 0 else
               f" (multipliers {'of the right sign' if self.bound_multipliers_ok else 'of the WRONG sign'})"),
            f"  iterations: {self.iterations} SQP + {self.polish_iterations} polish; {self.wall_time:.2f} s",
        ] + ([] if math.isnan(self.continuous_miss) else [
            f"  the continuous system (reference) with these inputs misses the target by {self.continuous_miss:.3e}"
            + (" (the discretization's error: a smaller h reduces it)" if self.success
               else " (the discrete problem is not solved either)")]))


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
            err = np.max(np.abs(R_target.T @ R_target - np.eye(k)))
            if err > 1e-10 or np.linalg.det(R_target) <= 0:
                raise InputError(f"target: 'R' is not a group element (|RᵀR − I| = {err:.3e}, det = "
                                 f"{np.linalg.det(R_target):.3g})")
        elif name in coords:
            q_idx.append(coords[name])
            q_val.append(_finite("target", name, value))
        elif name in vels:
            v_idx.append(vels[name])
            v_val.append(_finite("target", name, value))
        else:
            raise InputError(f"target: unknown name {name!r}; expected one of {', '.join([*coords, *vels])}"
                             + (", R" if system.group is not None else ""))
    q_idx, q_val = np.asarray(q_idx, int), np.asarray(q_val)
    v_idx, v_val = np.asarray(v_idx, int), np.asarray(v_val)
    space = system.space

    def g(b, v):
        parts = []
        if len(q_idx):
            parts.append(space.coordinates(b)[q_idx] - q_val)
        if len(v_idx):
            parts.append(v[v_idx] - v_val)
        if R_target is not None:
            parts.append(system.group.log(jnp.asarray(R_target).T @ space.orientation(b)))
        return jnp.concatenate(parts)

    return g


def _finite(arg, name, value) -> float:
    return real_number(f"{arg}: {name!r}", value)


def _bounds(bounds, m: int):
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


def solve_optimal_control(
    system: System,
    target,
    *,
    h: float,
    steps: int,
    q0=None,
    v0=None,
    R0=None,
    method=None,
    controls0=None,
    bounds=None,
    effort: float = 1.0,
    smoothness: float = 0.0,
    running_cost: Callable | None = None,
    t0: float = 0.0,
    max_iterations: int = 500,
    target_tol: float = 1e-10,
    kkt_tol: float = 1e-6,
    progress=False,
    input_names=None,
    check_continuous: bool = True,
    segments: int = 1,
    project_v0: bool = False,
    max_bytes="auto",
) -> ControlResult:
    """Solve a discrete optimal-control problem by direct shooting on the GNI's steps (see
    the module docstring for the formulation and the choice of transcription).

    Arguments:
        system: a forced System with inputs (`System(..., force=F, inputs=m)` or
            `system.with_force(F, inputs=m)`).
        target: the terminal target, a mapping of coordinate/velocity names (and `"R"`) to values,
            or a callable `g(b, v)` (:func:`terminal_residual`).
        h, steps: the step and the number K of steps (the horizon is K h).
        q0, v0, R0: the start (default: the system's).
        method: the dynamics' method (default `"gni-trapezoid"`: the GNI, RATTLE's steps).
        controls0: the warm start, (K, m) (default zeros; a problem whose target does not depend
            on the controls to first order at zero needs a nonzero warm start, e.g. the sleigh at
            rest).
        bounds: `(lower, upper)` for the inputs, numbers or one per input (default none).
        effort: the weight w of $\\tfrac w2|u|^2$ in the running cost.
        smoothness: the weight s of $\\tfrac s2\\sum_k|u_{k+1} - u_k|^2/h$, a penalty on the
            inputs' rate of change (against controls that alternate from step to step: the
            discrete dynamics can reach a target more cheaply with them than the continuous
            system does, see the control guide).
        running_cost: an optional `c(q, v, u, t)` added to the running cost (q the coordinates x).
        t0: the start time.
        max_iterations: the SQP's iteration cap.
        target_tol: the miss of the target below which the problem counts as solved.
        kkt_tol: the relative KKT residual below which it counts as optimal (an SQP that stops
            with a larger one, or with bound multipliers of the wrong sign, reports no success).
        progress: `True` prints one line per SQP iteration (cost and miss), or a callable
            `progress(iteration, cost, miss)` or `progress(iteration, cost, miss, total)`. The
            iterations count on across the solver's stages (SLSQP; where it fails, trust-constr
            and SLSQP again, each up to `max_iterations`); `total` is the most the solve can now
            take: `max_iterations` during the first SLSQP, raised when the fallback starts.
        input_names: names of the inputs, for files and figures (default `u0, u1, ...`).
        segments: the number of shooting segments: 1 (the default) is single shooting; with
            S > 1, multiple shooting: the method's state $(b, p^+)$ at the starts of segments
            2..S are unknowns too, and the steps' defects at the segment boundaries are
            constraints (GNI-family methods; see the module docstring).
        check_continuous: drive the continuous system (the reference) with the optimal inputs and
            report how far it ends from the target (`continuous_miss`): the discrete problem's
            target is met to round-off by the discrete dynamics, the physical system's only to the
            method's accuracy at h.
        project_v0: project `v0` onto the constraints ($\\mathbb{G}$-orthogonally) instead of
            refusing a `v0` that violates them.
        max_bytes: the most memory the solve may need, estimated before anything is compiled
            (:func:`gnipy.control.memory.control_memory`: the SQP's dense matrices grow as
            (K·m)²): `"auto"` (the default) the smaller of :data:`MAX_MEMORY_BYTES` and half the
            physical memory, a number of bytes, or None for no bound.

    Returns:
        A :class:`ControlResult`.

    Raises:
        InputError: bad arguments (named; a string or a boolean is not a number), or a problem
            estimated beyond `max_bytes` (naming `steps`).
    """
    start = time.perf_counter()
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
    lo, hi = _bounds(bounds, m)
    report = _reporter(progress)
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
    method = "gni-trapezoid" if method is None else method
    g = terminal_residual(system, target)
    if callable(target):
        d = 1  # not known before it is evaluated (by a simulation): at least one component
    else:
        d = sum(system.group.dim if name == "R" else 1 for name in target)
    if d > K * m:
        raise InputError(f"target: {d} conditions on {K * m} controls; use more steps")
    # refused before anything is compiled or allocated (the SQP's matrices grow as (K·m)²)
    check_control_memory(system, K, d, segments, max_bytes)
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    if controls0 is None:
        U0 = np.zeros((K, m))
    else:
        U0 = real_array("controls0", controls0, f"a ({K}, {m}) array of numbers")
        if U0.ndim == 1 and m == 1:
            U0 = U0[:, None]
        if U0.shape != (K, m) or not np.all(np.isfinite(U0)):
            raise InputError(f"controls0: expected a finite array of shape ({K}, {m}), got {np.shape(controls0)}")
    U0 = np.clip(U0, lo, hi)
    if project_v0:
        _, v0 = system.check(q0, v0, R0=R0, project_v0=True)
    # check the problem once, eagerly: the start, the method, the target's shape (clear errors
    # before anything is compiled)
    first = simulate(system, method, q0, v0, R0=R0, h=h, steps=K, controls=U0, t0=t0, saveat=SaveAt(t1=True))
    name = first.method
    g0 = np.asarray(g(_final_point(system, first), first.v[-1]))
    if g0.ndim != 1 or g0.size == 0:
        raise InputError(f"target: the residual g(b, v) must be a non-empty vector, got shape {g0.shape}")
    if g0.size > K * m:
        raise InputError(f"target: {g0.size} conditions on {K * m} controls; use more steps")
    ts = t0 + h * np.arange(K)

    def run(U):
        return simulate(system, method, q0, v0, R0=R0, h=h, steps=K, controls=U, t0=t0)

    def effort_cost(U):
        J = 0.5 * effort * h * jnp.sum(U**2)
        if smoothness:
            J = J + 0.5 * smoothness / h * jnp.sum(jnp.diff(U, axis=0) ** 2)
        return J

    def cost_of(U):
        J = effort_cost(U)
        if running_cost is not None:
            sol = run(U)
            J = J + h * jnp.sum(jax.vmap(running_cost)(sol.q[:K], sol.v[:K], U, jnp.asarray(ts)))
        return J

    def constraint(U):
        sol = run(U)
        return g(_final_point(system, sol), sol.v[-1])

    shape = (K, m)
    # the single-shooting functions of the controls: the polish, the KKT check and (one segment)
    # the SQP itself
    f_val = jax.jit(lambda u: cost_of(u.reshape(shape)))
    f_grad = jax.jit(jax.grad(lambda u: cost_of(u.reshape(shape))))
    c_val = jax.jit(lambda u: constraint(u.reshape(shape)))
    c_jac = jax.jit(jax.jacrev(lambda u: constraint(u.reshape(shape))))
    if segments == 1:
        x0, x_lo, x_hi = U0.ravel(), np.tile(lo, K), np.tile(hi, K)
        F_val, F_grad, C_val, C_jac = f_val, f_grad, c_val, c_jac
    else:
        shooting = _MultipleShooting(system, method, g, q0, v0, R0, h, K, m, t0, segments, U0, running_cost,
                                     effort_cost, ts)
        x0 = np.concatenate([U0.ravel(), shooting.s0])
        x_lo = np.concatenate([np.tile(lo, K), np.full(shooting.s0.size, -np.inf)])
        x_hi = np.concatenate([np.tile(hi, K), np.full(shooting.s0.size, np.inf)])
        F_val = jax.jit(shooting.cost)
        F_grad = jax.jit(jax.grad(shooting.cost))
        C_val = jax.jit(shooting.constraints)
        C_jac = jax.jit(jax.jacrev(shooting.constraints))

    it = [0]
    cap = [max_iterations]  # the most iterations the solve can take, as known now (progress's total)

    def callback(x):
        it[0] += 1
        if report is not None:
            report(it[0], float(F_val(x)), float(np.max(np.abs(C_val(x)))), max(cap[0], it[0]))

    # SLSQP starts its quasi-Newton Hessian at the identity; the effort's Hessian is h w I, so the
    # cost is divided by h w (its first steps are otherwise 1/(h w) too long)
    scale = 1.0 / (h * effort) if effort > 0 else 1.0 / h
    lo_x, hi_x = np.tile(lo, K), np.tile(hi, K)
    objective = (lambda x: scale * float(F_val(x)), lambda x: scale * np.asarray(F_grad(x)))
    constraint_fns = (lambda x: np.asarray(C_val(x)), lambda x: np.asarray(C_jac(x)))

    def finish(res, polished_from):
        # the controls, checked and polished by single shooting (what a re-simulation gives)
        full = np.clip(res.x, x_lo, x_hi)
        x = full[: K * m]
        x, polish, miss = _polish(x, c_val, c_jac, lo_x, hi_x, target_tol)
        jac = None
        if segments == 1 or polish:
            jac = np.asarray(c_jac(x))
            kkt, lam, active, signs_ok = _kkt(np.asarray(f_grad(x)), jac, x, lo_x, hi_x)
        else:  # the KKT conditions of the multiple-shooting problem (equivalent; no other compile)
            kkt, lam, active, signs_ok = _kkt(np.asarray(F_grad(full)), np.asarray(C_jac(full)), full, x_lo, x_hi)
            lam = lam[-len(g0):]  # the target's multipliers (after the defects')
        # success is checked here, not taken from the SQP's word: the target met, a KKT point, the
        # bound multipliers of the right sign (SLSQP can stop at its iteration cap on a point that
        # is all three, and say it converged on one that is not)
        ok = miss <= target_tol and kkt <= kkt_tol and signs_ok
        return dict(x=x, polish=polish, miss=miss, kkt=kkt, lam=lam, active=active, signs_ok=signs_ok, ok=ok,
                    res=res, stages=polished_from, jac=jac)

    res = _slsqp(objective, constraint_fns, x0, x_lo, x_hi, max_iterations, callback)
    out = finish(res, "SLSQP")
    iterations = int(res.nit)
    if not out["ok"]:
        # SLSQP's active set can stall (measured: the sleigh at h = 0.1 with |tau| <= 1.5, all 40
        # controls at a bound and a miss of 0.9); an interior-point method (trust-constr) from the
        # warm start finds the region, and SLSQP from there the active set and the last digits
        effort_only = running_cost is None and not smoothness and segments == 1
        cap[0] = it[0] + 2 * max_iterations  # trust-constr, then SLSQP again
        first = _trust_constr(objective, constraint_fns, x0, x_lo, x_hi, max_iterations, callback,
                              hessian=scale * h * effort if effort_only else None)
        cap[0] = it[0] + max_iterations
        res = _slsqp(objective, constraint_fns, np.clip(first.x, x_lo, x_hi), x_lo, x_hi, max_iterations, callback)
        retry = finish(res, f"SLSQP failed ({out['res'].message}); trust-constr ({first.nit} iterations), then SLSQP")
        iterations += int(first.nit) + int(res.nit)
        if (retry["ok"], -retry["kkt"] - retry["miss"]) > (out["ok"], -out["kkt"] - out["miss"]):
            out = retry
    x, polish, miss, kkt, lam = out["x"], out["polish"], out["miss"], out["kkt"], out["lam"]
    active, signs_ok, res = out["active"], out["signs_ok"], out["res"]
    U = x.reshape(shape)
    solution = run(U)
    continuous_miss = float("nan")
    if check_continuous:
        from ..errors import SolverFailure

        try:
            ref = simulate(system, "reference", q0, v0, R0=R0, h=h, steps=K, controls=U, t0=t0, saveat=SaveAt(t1=True))
            continuous_miss = float(np.max(np.abs(np.asarray(g(_final_point(system, ref), ref.v[-1])))))
        except SolverFailure:
            continuous_miss = float("inf")
    success = out["ok"]
    message = f"{out['stages']}: {res.message}" + (f"; polished in {polish} Gauss-Newton steps" if polish else "")
    if res.success and miss > target_tol:
        message += f"; the target is missed by {miss:.3e} > target_tol = {target_tol:g}"
    if res.success and (kkt > kkt_tol or not signs_ok):
        message += (f"; not a KKT point (residual {kkt:.3e}"
                    + ("" if signs_ok else ", bound multipliers of the wrong sign") + ")")
    return ControlResult(
        controls=U, solution=solution, cost=float(f_val(x)), target_residual=miss, kkt_residual=kkt,
        bound_multipliers_ok=signs_ok, multipliers=lam, active_bounds=active, iterations=iterations,
        polish_iterations=polish, success=success, message=message, wall_time=time.perf_counter() - start,
        method=name, input_names=tuple(str(n) for n in input_names) if input_names is not None
        else tuple(f"u{j}" for j in range(m)), continuous_miss=continuous_miss, target_jacobian=out["jac"],
    )


class _MultipleShooting:
    """The functions of multiple shooting: the unknowns are the controls and, for segments 2..S,
    the method's state at the segment's start, $s_j = (x_j, \\eta_j, p^+_j)$ with the orientation
    $R_j = \\bar R_j\\exp(\\hat\\eta_j)$ about the warm start's $\\bar R_j$; the constraints are the
    defects at the boundaries (the end of segment j − 1 minus $s_j$; $\\log(R_j^{-1}R_{end})$ for
    the orientation) and the target at the end of the last segment."""

    def __init__(self, system, method, g, q0, v0, R0, h, K, m, t0, S, U0, running_cost, effort_cost, ts):
        from ..integrators.gni import GNIState

        self.system, self.method, self.g, self.q0, self.v0, self.R0 = system, method, g, q0, v0, R0
        self.h, self.K, self.m, self.t0 = h, K, m, t0
        self.cuts = np.linspace(0, K, S + 1).round().astype(int)
        self.running_cost, self.effort_cost, self.ts = running_cost, effort_cost, ts
        # the warm start's states at the boundaries: the first guesses and the orientations R̄_j
        guess = simulate(system, method, q0, v0, R0=R0, h=h, steps=K, controls=U0, t0=t0,
                         saveat=SaveAt(ts=t0 + h * self.cuts[1:-1], states=True))
        states = guess.states
        if not isinstance(states, GNIState):
            raise InputError(f"segments: multiple shooting needs a method whose state is (b, p+) (the GNI family), "
                             f"not {guess.method}")
        self.GNIState = GNIState
        space = system.space
        self.n, self.N = system.n, system.dim
        self.d = 0 if system.group is None else system.group.dim
        x = np.asarray(space.coordinates(states.b)).reshape(S - 1, self.n)
        self.Rbar = None if system.group is None else np.asarray(space.orientation(states.b))
        p = np.asarray(states.p_plus).reshape(S - 1, self.N)
        self.s0 = np.concatenate([x, np.zeros((S - 1, self.d)), p], axis=1).ravel()

    def _state(self, j, s):
        from ..spaces import Point

        x, eta, p = s[: self.n], s[self.n : self.n + self.d], s[self.n + self.d :]
        if self.system.group is None:
            b = x
        else:
            b = Point(x, jnp.asarray(self.Rbar[j]) @ self.system.group.exp(eta))
        return self.GNIState(b, p, jnp.zeros_like(x))

    def _runs(self, x):
        K, m, S = self.K, self.m, len(self.cuts) - 1
        U = x[: K * m].reshape(K, m)
        svars = x[K * m :].reshape(S - 1, self.n + self.d + self.N)
        save = SaveAt(steps=True, states=True) if self.running_cost is not None else SaveAt(t1=True, states=True)
        sols = []
        for j in range(S):
            k0, k1 = int(self.cuts[j]), int(self.cuts[j + 1])
            common = dict(h=self.h, steps=k1 - k0, controls=U[k0:k1], t0=self.t0 + k0 * self.h, saveat=save)
            if j == 0:
                sols.append(simulate(self.system, self.method, self.q0, self.v0, R0=self.R0, **common))
            else:
                sols.append(simulate(self.system, self.method, state0=self._state(j - 1, svars[j - 1]), **common))
        return U, svars, sols

    def constraints(self, x):
        U, svars, sols = self._runs(x)
        space = self.system.space
        parts = []
        for j in range(1, len(sols)):
            end = sols[j - 1].final_state
            start = self._state(j - 1, svars[j - 1])
            parts.append(space.coordinates(end.b) - space.coordinates(start.b))
            if self.system.group is not None:
                parts.append(self.system.group.log(space.orientation(start.b).T @ space.orientation(end.b)))
            parts.append(end.p_plus - start.p_plus)
        last = sols[-1]
        parts.append(self.g(_final_point(self.system, last), last.v[-1]))
        return jnp.concatenate(parts)

    def cost(self, x):
        U = x[: self.K * self.m].reshape(self.K, self.m)
        J = self.effort_cost(U)
        if self.running_cost is not None:
            _, _, sols = self._runs(x)
            q = jnp.concatenate([s.q[:-1] for s in sols])
            v = jnp.concatenate([s.v[:-1] for s in sols])
            J = J + self.h * jnp.sum(jax.vmap(self.running_cost)(q, v, U, jnp.asarray(self.ts)))
        return J


def _slsqp(objective, constraint, x0, lo, hi, max_iterations, callback):
    from scipy.optimize import minimize

    return minimize(objective[0], x0, jac=objective[1], method="SLSQP", bounds=list(zip(lo, hi)),
                    constraints=[dict(type="eq", fun=constraint[0], jac=constraint[1])],
                    options=dict(maxiter=int(max_iterations), ftol=1e-15), callback=callback)


def _trust_constr(objective, constraint, x0, lo, hi, max_iterations, callback, hessian):
    """SciPy's trust-region interior-point method, with the effort's Hessian when the cost is the
    effort alone (`hessian` = its diagonal value) and BFGS for the constraints' curvature."""
    import warnings

    from scipy.optimize import BFGS, Bounds, NonlinearConstraint, minimize

    hess = BFGS() if hessian is None else (lambda x: hessian * np.eye(x.size))
    finite = np.isfinite(lo) | np.isfinite(hi)
    with warnings.catch_warnings():  # "delta_grad == 0.0" notes of the BFGS update near convergence
        warnings.simplefilter("ignore", UserWarning)
        return minimize(objective[0], x0, jac=objective[1], hess=hess, method="trust-constr",
                        bounds=Bounds(lo, hi) if np.any(finite) else None,
                        constraints=[NonlinearConstraint(constraint[0], 0.0, 0.0, jac=constraint[1], hess=BFGS())],
                        options=dict(maxiter=int(max_iterations), gtol=1e-12, xtol=1e-14),
                        callback=lambda x, *_: callback(x))


def _final_point(system, sol):
    """The base point at the solution's last node."""
    from ..spaces import Point

    if system.group is None:
        return sol.q[-1]
    return Point(sol.q[-1], sol.R[-1])


def _at_bounds(x, lo, hi):
    """`(at_lo, at_hi)`: the controls at their bounds, within 1e-8 of the bounds' range (SLSQP
    stops a few ulps inside a bound); unbounded entries never."""
    width = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
    tol_x = np.where(np.isfinite(width), 1e-8 * width, 0.0)
    return x <= lo + tol_x, x >= hi - tol_x


def _polish(x, c_val, c_jac, lo, hi, tol, max_steps: int = 8):
    """Gauss–Newton steps on the free controls until the target is met to `tol` (or no progress)."""
    c = np.asarray(c_val(x))
    miss = float(np.max(np.abs(c)))
    steps = 0
    while miss > 0.01 * tol and steps < max_steps:
        at_lo, at_hi = _at_bounds(x, lo, hi)
        free = ~(at_lo | at_hi)
        J = np.asarray(c_jac(x))[:, free]
        if J.shape[1] < J.shape[0] or not np.all(np.isfinite(J)):
            break
        dx = np.zeros_like(x)
        try:
            dx[free] = -J.T @ np.linalg.solve(J @ J.T, c)
        except np.linalg.LinAlgError:  # J has dependent rows: the target is not reachable to first order here
            break
        x_new = np.clip(x + dx, lo, hi)
        c_new = np.asarray(c_val(x_new))
        miss_new = float(np.max(np.abs(c_new)))
        if not miss_new < miss:
            break
        x, c, miss = x_new, c_new, miss_new
        steps += 1
    return x, steps, miss


def _kkt(grad, Jg, x, lo, hi):
    """KKT residual over the free controls, the multipliers, the active bounds and their signs."""
    at_lo, at_hi = _at_bounds(x, lo, hi)
    free = ~(at_lo | at_hi)
    if not (np.all(np.isfinite(grad)) and np.all(np.isfinite(Jg))):  # a run that blew up: no KKT point
        return float("inf"), np.full(Jg.shape[0], np.nan), int(np.sum(~free)), False
    lam = np.linalg.lstsq(Jg[:, free].T, -grad[free], rcond=None)[0] if np.any(free) else np.zeros(Jg.shape[0])
    r = grad + Jg.T @ lam
    # relative to the size of the terms that must cancel, ∇J and J_gᵀλ (a fixed scale would pass
    # any point of a problem whose cost is small)
    size = max(float(np.max(np.abs(grad), initial=0.0)), float(np.max(np.abs(Jg.T @ lam), initial=0.0)))
    size = size if size > 0 else 1.0
    kkt = float(np.max(np.abs(r[free]), initial=0.0) / size)
    # at a lower bound the objective must not decrease inward (r ≥ 0), at an upper bound r ≤ 0
    tol = 1e-6 * size
    signs_ok = bool(np.all(r[at_lo] >= -tol) and np.all(r[at_hi] <= tol))
    return kkt, lam, int(np.sum(~free)), signs_ok


def _reporter(progress):
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
