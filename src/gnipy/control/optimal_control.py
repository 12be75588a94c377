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
(2-core machine, 2026-11-28), single shooting was the better default: sleigh-steering 23 SQP
iterations and 5.4 s with one segment, 37 iterations and 13.6 s with four (the same optimum);
ball-plate 108 iterations and 12.8 s with one, and with four SLSQP reached its 500-iteration cap
(the states' unknowns, of other scales than the controls, slow its quasi-Newton updates).

**Compiled once per structure.** The shooting problems are equinox Modules whose numbers are
arrays, and the SQP's functions are two module-level compiled programs that take them as an
argument (:meth:`gnipy.control.sqp.Functions.of`): solves, warm starts and multistarts of one
structure share them.

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
import functools
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..resources import MAX_MEMORY_BYTES
from ..saveat import SaveAt
from ..simulate import default_initial_condition, simulate
from ..system import System
from .control_arguments import (
    MAX_ITERATIONS,
    ControlArguments,
    TargetSubset,
    control_arguments,
    target_size,
    terminal_residual,
    warm_start,
)
from .control_result import ControlResult, target_rank
from .memory import check_control_memory
from .sqp import Functions, SQPProblem, solve_sqp

__all__ = ["solve_optimal_control", "ControlResult", "terminal_residual", "MAX_MEMORY_BYTES", "MAX_ITERATIONS"]


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
    starts: int = 1,
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

        starts: the number of starts of a multistart (≥ 1; single shooting): the warm start, then
            `starts - 1` random ones (:func:`_random_start`, seeded by their index: reproducible),
            each solved by the same compiled functions (no recompilation: a start costs its SQP
            iterations). The best successful outcome is returned, and
            :attr:`ControlResult.local_optima` lists the distinct optima found (costs equal to a
            relative 1e-8 are one optimum) with how many starts reached each.

    Returns:
        A :class:`ControlResult`.

    Raises:
        InputError: bad arguments (named; a string or a boolean is not a number), or a problem
            estimated beyond `max_bytes` (naming `steps`).
    """
    start = time.perf_counter()
    a = control_arguments(system, steps=steps, h=h, effort=effort, smoothness=smoothness, t0=t0,
                          target_tol=target_tol, kkt_tol=kkt_tol, running_cost=running_cost, segments=segments,
                          max_iterations=max_iterations, check_continuous=check_continuous, project_v0=project_v0,
                          bounds=bounds, progress=progress, input_names=input_names)
    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or not 1 <= starts <= MAX_STARTS:
        raise InputError(f"starts: expected a whole number of starts from 1 to {MAX_STARTS}, got {starts!r}")
    if starts > 1 and a.segments > 1:
        raise InputError("starts: a multistart is for single shooting (segments = 1): its random starts are controls")
    method = "gni-trapezoid" if method is None else method
    g = terminal_residual(system, target)
    d = target_size(system, target, a.K * a.m)
    # refused before anything is compiled or allocated (the SQP's matrices grow as (K·m)²)
    check_control_memory(system, a.K, d, a.segments, max_bytes)
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    U0 = np.clip(warm_start(controls0, a.K, a.m), a.lo, a.hi)
    if project_v0:
        _, v0 = system.check(q0, v0, R0=R0, project_v0=True)
    single = _SingleShooting.make(system, method, g, q0, v0, R0, a, running_cost)
    name, n_target = single.check(U0, a.K * a.m)
    # a redundant target (components that the others fix through the dynamics or the constraints, e.g.
    # "at rest" as every velocity of a constrained system) makes the SQP's constraint Jacobian singular
    # everywhere (SLSQP: "Singular matrix C"): the SQP solves for an independent subset, and the whole
    # target is checked at the end
    problem = _sqp_problem(single, a, U0, running_cost, n_target)
    full_g, dropped = g, _redundant_components(problem, U0, a)
    if dropped:  # rebuilt (and compiled again) only then: the probe uses the functions the SQP uses
        keep = np.setdiff1d(np.arange(n_target), dropped)
        single = _SingleShooting.make(system, method, TargetSubset(full_g, tuple(int(k) for k in keep)), q0, v0, R0, a,
                                      running_cost)
        n_target = keep.size
        problem = _sqp_problem(single, a, U0, running_cost, n_target)
    out, iterations, optima = _multistart(problem, a, starts)
    U = out.x.reshape(a.K, a.m)
    solution = single.run(U, concrete=True)
    rank = target_rank(out.jac)
    names = _component_names(system, target, len(dropped) + n_target)
    redundant = tuple(names[k] for k in dropped)
    if dropped:  # the whole target, at the end of the run: what success means
        single = dataclasses.replace(single, g=full_g)
        miss = float(np.max(np.abs(np.asarray(full_g(_final_point(system, solution), solution.v[-1])))))
        out = dataclasses.replace(out, miss=miss, ok=out.ok and miss <= a.target_tol)
        message = (out.message(a.target_tol, a.kkt_tol) + f"; redundant target: {', '.join(redundant)} "
                   f"fixed by the other components (solved for {n_target} independent ones; the whole target "
                   f"checked at the end: max|g| = {miss:.3e})")
    else:
        message = out.message(a.target_tol, a.kkt_tol)
        if rank is not None and rank < out.jac.shape[0]:
            message += f"; the target's Jacobian has rank {rank} of {out.jac.shape[0]} at the returned controls"
    continuous_miss = single.continuous_miss(U) if check_continuous else float("nan")
    return ControlResult(
        controls=U, solution=solution, cost=float(problem.controls.cost(out.x)), target_residual=out.miss,
        kkt_residual=out.kkt, bound_multipliers_ok=out.signs_ok, multipliers=out.lam, active_bounds=out.active,
        iterations=iterations, polish_iterations=out.polish, success=out.ok, message=message,
        wall_time=time.perf_counter() - start, method=name,
        input_names=tuple(str(n) for n in a.input_names) if a.input_names is not None
        else tuple(f"u{j}" for j in range(a.m)), continuous_miss=continuous_miss, target_jacobian=out.jac,
        local_optima=optima, starts=int(starts), target_tol=a.target_tol, kkt_tol=a.kkt_tol, target_rank=rank, redundant_components=redundant,
    )


#: The most starts of a multistart.
MAX_STARTS = 1000


def _random_start(problem: SQPProblem, j: int) -> np.ndarray:
    """Start j > 0 of a multistart (reproducible: seeded by j): the warm start plus Gaussian
    controls of standard deviation a quarter of the bounds' width (or max(1, |warm start|) where
    unbounded), clipped to the bounds."""
    rng = np.random.default_rng(j)
    lo, hi, x0 = problem.x_lo, problem.x_hi, problem.x0
    finite = np.isfinite(lo) & np.isfinite(hi)
    spread = np.where(finite, 0.25 * np.where(finite, hi - lo, 0.0), max(1.0, float(np.max(np.abs(x0), initial=0.0))))
    return np.clip(x0 + spread * rng.standard_normal(x0.shape), lo, hi)


def _multistart(problem: SQPProblem, a: ControlArguments, starts: int):
    """`(best outcome, total iterations, distinct optima)`: the SQP from the warm start and from
    `starts - 1` random starts, on the same compiled functions; the best is the successful outcome
    of least cost (else the least miss). The optima: `((cost, starts that reached it), ...)` of the
    successful outcomes, costs within a relative 1e-8 counted as one, by increasing cost (empty for
    one start)."""
    outcomes, total = [], 0
    for j in range(starts):
        offset, remaining = total, (starts - j - 1) * a.max_iterations

        def report(i, cost, miss, cap, offset=offset, remaining=remaining):
            if a.report is not None:  # one count across the starts: never past its total
                a.report(offset + i, cost, miss, offset + cap + remaining)

        trial = problem if j == 0 else dataclasses.replace(problem, x0=_random_start(problem, j))
        out, iterations = solve_sqp(trial, max_iterations=a.max_iterations, target_tol=a.target_tol,
                                    kkt_tol=a.kkt_tol, report=report if a.report is not None else None)
        total += iterations
        outcomes.append((out, float(problem.controls.cost(out.x))))
    best = min(outcomes, key=lambda oc: (not oc[0].ok, oc[1] if oc[0].ok else oc[0].miss))[0]
    optima: list[list] = []
    for out, cost in sorted((oc for oc in outcomes if oc[0].ok), key=lambda oc: oc[1]):
        if optima and abs(cost - optima[-1][0]) <= 1e-8 * max(abs(cost), abs(optima[-1][0]), 1e-300):
            optima[-1][1] += 1
        else:
            optima.append([cost, 1])
    return best, total, tuple((c, n) for c, n in optima) if starts > 1 else ()


def _redundant_components(problem: SQPProblem, U0, a: ControlArguments) -> list[int]:
    """The target's components that the others fix: the rows of $\\partial g/\\partial u$ outside an
    independent set (pivoted QR), at controls near the warm start (a random perturbation of 5 per cent
    of the bounds' width, or 0.1: a warm start such as zero, where the target may be degenerate to
    first order without being redundant, does not count); [] when the rank is full or not measurable."""
    from scipy.linalg import qr

    rng = np.random.default_rng(0)
    width = np.where(np.isfinite(a.hi - a.lo), a.hi - a.lo, 2.0)
    probe = np.clip(U0 + 0.05 * width * rng.standard_normal(U0.shape), a.lo, a.hi)
    J = np.asarray(problem.controls.constraints_jacobian(probe.ravel()))  # compiled once: the SQP's own
    rank = target_rank(J)
    if rank is None or rank >= J.shape[0]:
        return []
    pivots = qr(J.T, mode="r", pivoting=True)[1]
    return sorted(int(k) for k in pivots[rank:])


def _component_names(system, target, d: int) -> list[str]:
    """Names of the target's d components, in the order of :func:`terminal_residual` (coordinates,
    velocities, then the orientation's log); `g[k]` for a callable target."""
    if callable(target):
        return [f"g[{k}]" for k in range(d)]
    names = [n for n in target if n in system.coordinates] + [n for n in target if n in system.velocities]
    names += [f"R[{k}]" for k in range(d - len(names))]
    return names


class _SingleShooting(eqx.Module):
    """The functions of single shooting: the unknowns are the controls (K, m); the states are
    eliminated by the steps themselves (a run from the start). A pytree whose numbers are arrays:
    problems of one structure (system, method, target's shape, K, m) share the compiled programs
    whatever their numbers (start, step, weights, target values, warm start)."""

    system: Any
    method: Any
    g: Any
    q0: Any
    v0: Any
    R0: Any
    h: jax.Array
    t0: jax.Array
    effort: jax.Array
    smoothness: jax.Array
    ts: jax.Array
    K: int = eqx.field(static=True)
    m: int = eqx.field(static=True)
    smooth: bool = eqx.field(static=True)
    running_cost: Any = eqx.field(static=True)

    @classmethod
    def make(cls, system, method, g, q0, v0, R0, a: ControlArguments, running_cost) -> "_SingleShooting":
        """The single-shooting functions of a problem."""
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        return cls(system=system, method=method, g=g, q0=f64(q0), v0=f64(v0), R0=None if R0 is None else f64(R0),
                   h=f64(a.h), t0=f64(a.t0), effort=f64(a.effort), smoothness=f64(a.smoothness),
                   ts=f64(a.t0 + a.h * np.arange(a.K)), K=int(a.K), m=int(a.m), smooth=bool(a.smoothness),
                   running_cost=running_cost)

    def run(self, U, concrete: bool = False):
        """The run driven by the controls `U` (every node); `concrete`: outside a compiled program
        (the step and start time as numbers, as a run the user makes)."""
        h, t0 = (float(self.h), float(self.t0)) if concrete else (self.h, self.t0)
        return simulate(self.system, self.method, self.q0, self.v0, R0=self.R0, h=h, steps=self.K, controls=U, t0=t0)

    def check(self, U0, controls: int) -> tuple[str, int]:
        """`(the method's name, the number of the target's components)`: the problem checked once,
        eagerly, by a run from the warm start `U0`: the start, the method, the target's shape (clear
        errors before anything is compiled; no more components than `controls`)."""
        # the same run as the result's (every node): one compiled program for both
        first = self.run(U0, concrete=True)
        g0 = np.asarray(self.g(_final_point(self.system, first), first.v[-1]))
        if g0.ndim != 1 or g0.size == 0:
            raise InputError(f"target: the residual g(b, v) must be a non-empty vector, got shape {g0.shape}")
        if g0.size > controls:
            raise InputError(f"target: {g0.size} conditions on {controls} controls; use more steps")
        return first.method, len(g0)

    def effort_cost(self, U):
        """The effort and smoothness terms of the cost."""
        J = 0.5 * self.effort * self.h * jnp.sum(U**2)
        if self.smooth:
            J = J + 0.5 * self.smoothness / self.h * jnp.sum(jnp.diff(U, axis=0) ** 2)
        return J

    def cost(self, U):
        """The cost J(U)."""
        J = self.effort_cost(U)
        if self.running_cost is not None:
            sol = self.run(U)
            K = self.K
            J = J + self.h * jnp.sum(jax.vmap(self.running_cost)(sol.q[:K], sol.v[:K], U, self.ts))
        return J

    def constraint(self, U):
        """The target's residual g at the end of the run."""
        sol = self.run(U)
        return self.g(_final_point(self.system, sol), sol.v[-1])

    def continuous_miss(self, U) -> float:
        """$\\max|g|$ when the held controls `U` drive the continuous system (the reference); inf
        when that run fails."""
        from ..errors import SolverFailure

        try:
            ref = simulate(self.system, "reference", self.q0, self.v0, R0=self.R0, h=float(self.h), steps=self.K,
                           controls=U, t0=float(self.t0), saveat=SaveAt(t1=True))
            return float(np.max(np.abs(np.asarray(self.g(_final_point(self.system, ref), ref.v[-1])))))
        except SolverFailure:
            return float("inf")


class _Controls(eqx.Module):
    """Single shooting as a function of the flattened controls (K·m,)."""

    single: _SingleShooting
    shape: tuple = eqx.field(static=True)

    def cost(self, u):
        return self.single.cost(u.reshape(self.shape))

    def constraints(self, u):
        return self.single.constraint(u.reshape(self.shape))


def _sqp_problem(single: _SingleShooting, a: ControlArguments, U0, running_cost, n_target: int) -> SQPProblem:
    """The problem the SQP solves: single shooting on the controls with one segment, else multiple
    shooting on the controls and the segments' states; the cost scaled for SLSQP."""
    shape = (a.K, a.m)
    # the single-shooting functions of the controls: the polish, the KKT check and (one segment)
    # the SQP itself
    controls = Functions.of(_Controls(single, shape))
    lo_x, hi_x = np.tile(a.lo, a.K), np.tile(a.hi, a.K)
    if a.segments == 1:
        x0, x_lo, x_hi, unknowns = U0.ravel(), np.tile(a.lo, a.K), np.tile(a.hi, a.K), controls
    else:
        shooting = _MultipleShooting.make(single, a.segments, U0)
        s0 = np.asarray(shooting.s0)
        x0 = np.concatenate([U0.ravel(), s0])
        x_lo = np.concatenate([lo_x, np.full(s0.size, -np.inf)])
        x_hi = np.concatenate([hi_x, np.full(s0.size, np.inf)])
        unknowns = Functions.of(shooting)
    # SLSQP starts its quasi-Newton Hessian at the identity; the effort's Hessian is h w I, so the
    # cost is divided by h w (its first steps are otherwise 1/(h w) too long)
    scale = 1.0 / (a.h * a.effort) if a.effort > 0 else 1.0 / a.h
    effort_only = running_cost is None and not a.smoothness and a.segments == 1
    return SQPProblem(controls=controls, unknowns=unknowns, single=a.segments == 1, x0=x0, x_lo=x_lo, x_hi=x_hi,
                      lo=lo_x, hi=hi_x, n_target=n_target, scale=scale,
                      hessian=scale * a.h * a.effort if effort_only else None)


class _MultipleShooting(eqx.Module):
    """The functions of multiple shooting: the unknowns are the controls and, for segments 2..S,
    the method's state at the segment's start, $s_j = (x_j, \\eta_j, p^+_j)$ with the orientation
    $R_j = \\bar R_j\\exp(\\hat\\eta_j)$ about the warm start's $\\bar R_j$; the constraints are the
    defects at the boundaries (the end of segment j − 1 minus $s_j$; $\\log(R_j^{-1}R_{end})$ for
    the orientation) and the target at the end of the last segment. A pytree like
    :class:`_SingleShooting`: compiled once per structure."""

    single: _SingleShooting
    Rbar: Any  # the warm start's orientations at the boundaries, or None
    s0: jax.Array  # the warm start's states at the boundaries (the unknowns' first guess)
    cuts: tuple = eqx.field(static=True)
    n: int = eqx.field(static=True)
    N: int = eqx.field(static=True)
    d: int = eqx.field(static=True)

    @classmethod
    def make(cls, single: _SingleShooting, S: int, U0) -> "_MultipleShooting":
        """The multiple-shooting functions of `single`'s problem with S segments, about the run
        of the warm start `U0`."""
        from ..integrators.gni import GNIState

        system, K, h, t0 = single.system, single.K, float(single.h), float(single.t0)
        cuts = tuple(int(c) for c in np.linspace(0, K, S + 1).round().astype(int))
        # the warm start's states at the boundaries: the first guesses and the orientations R̄_j
        guess = simulate(system, single.method, single.q0, single.v0, R0=single.R0, h=h, steps=K, controls=U0, t0=t0,
                         saveat=SaveAt(ts=t0 + h * np.asarray(cuts[1:-1]), states=True))
        states = guess.states
        if not isinstance(states, GNIState):
            raise InputError(f"segments: multiple shooting needs a method whose state is (b, p+) (the GNI family), "
                             f"not {guess.method}")
        space = system.space
        n, N = system.n, system.dim
        d = 0 if system.group is None else system.group.dim
        x = np.asarray(space.coordinates(states.b)).reshape(S - 1, n)
        Rbar = None if system.group is None else jnp.asarray(space.orientation(states.b))
        p = np.asarray(states.p_plus).reshape(S - 1, N)
        s0 = np.concatenate([x, np.zeros((S - 1, d)), p], axis=1).ravel()
        return cls(single=single, Rbar=Rbar, s0=jnp.asarray(s0), cuts=cuts, n=n, N=N, d=d)

    def _state(self, j, s):
        from ..integrators.gni import GNIState
        from ..spaces import Point

        x, eta, p = s[: self.n], s[self.n : self.n + self.d], s[self.n + self.d :]
        system = self.single.system
        b = x if system.group is None else Point(x, self.Rbar[j] @ system.group.exp(eta))
        return GNIState(b, p, jnp.zeros_like(x))

    def _runs(self, x):
        one = self.single
        K, m, S = one.K, one.m, len(self.cuts) - 1
        U = x[: K * m].reshape(K, m)
        svars = x[K * m :].reshape(S - 1, self.n + self.d + self.N)
        save = SaveAt(steps=True, states=True) if one.running_cost is not None else SaveAt(t1=True, states=True)
        sols = []
        for j in range(S):
            k0, k1 = int(self.cuts[j]), int(self.cuts[j + 1])
            common = dict(h=one.h, steps=k1 - k0, controls=U[k0:k1], t0=one.t0 + k0 * one.h, saveat=save)
            if j == 0:
                sols.append(simulate(one.system, one.method, one.q0, one.v0, R0=one.R0, **common))
            else:
                sols.append(simulate(one.system, one.method, state0=self._state(j - 1, svars[j - 1]), **common))
        return U, svars, sols

    def constraints(self, x):
        U, svars, sols = self._runs(x)
        system = self.single.system
        space = system.space
        parts = []
        for j in range(1, len(sols)):
            end = sols[j - 1].final_state
            start = self._state(j - 1, svars[j - 1])
            parts.append(space.coordinates(end.b) - space.coordinates(start.b))
            if system.group is not None:
                parts.append(system.group.log(space.orientation(start.b).T @ space.orientation(end.b)))
            parts.append(end.p_plus - start.p_plus)
        last = sols[-1]
        parts.append(self.single.g(_final_point(system, last), last.v[-1]))
        return jnp.concatenate(parts)

    def cost(self, x):
        one = self.single
        U = x[: one.K * one.m].reshape(one.K, one.m)
        J = one.effort_cost(U)
        if one.running_cost is not None:
            _, _, sols = self._runs(x)
            q = jnp.concatenate([s.q[:-1] for s in sols])
            v = jnp.concatenate([s.v[:-1] for s in sols])
            J = J + one.h * jnp.sum(jax.vmap(one.running_cost)(q, v, U, one.ts))
        return J



def _final_point(system, sol):
    """The base point at the solution's last node."""
    from ..spaces import Point

    if system.group is None:
        return sol.q[-1]
    return Point(sol.q[-1], sol.R[-1])
