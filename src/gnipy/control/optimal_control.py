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
Every step a segment (`segments = steps`) is a transcription of its own
(:mod:`gnipy.control.step_shooting`): all steps evaluated at once, the derivatives sparse, for
IPOPT; it reaches single shooting's optimum, but is not faster here (the control guide).

**Compiled once per structure.** The shooting problems are equinox Modules whose numbers are
arrays, and the SQP's functions are two module-level compiled programs that take them as an
argument (:meth:`gnipy.control.sqp.Functions.of`; the transcriptions are in
:mod:`gnipy.control.shooting`): solves, warm starts and multistarts of one structure share them.

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
nonlinear equality constraints with bounds. `optimizer="ipopt"` solves with IPOPT and the exact
Hessian of the Lagrangian instead (:mod:`gnipy.control.ipopt`, which says when each is faster),
with the same polish and checks.
"""


from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from ..errors import InputError
from ..resources import MAX_MEMORY_BYTES
from ..simulate import default_initial_condition
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
from .shooting import SingleShooting, final_point, sqp_problem
from .sqp import SQPProblem, solve_sqp
from .ipopt import solve_ipopt

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
    optimizer: str = "slsqp",
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
            constraints (GNI-family methods; see the module docstring). `segments = steps`,
            every step a segment, is one vectorized program with sparse derivatives
            (:mod:`gnipy.control.step_shooting`; no running cost), which IPOPT takes as sparse.
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
        optimizer: `"slsqp"` (the default: SciPy's SLSQP, with trust-constr as its fallback) or
            `"ipopt"` (IPOPT with the exact Hessian of the Lagrangian, the SLSQP chain as its
            fallback; needs the `ipopt` extra). Measured on the control guide's worked problems,
            IPOPT is the faster on the ball-plate problem and finds its lower optimum, SLSQP on
            the sleigh (:mod:`gnipy.control.ipopt`).

    Returns:
        A :class:`ControlResult`.

    Raises:
        InputError: bad arguments (named; a string or a boolean is not a number), or a problem
            estimated beyond `max_bytes` (naming `steps`).
        MissingExtra: `optimizer="ipopt"` without the `ipopt` extra (cyipopt).
    """
    start = time.perf_counter()
    a = control_arguments(system, steps=steps, h=h, effort=effort, smoothness=smoothness, t0=t0,
                          target_tol=target_tol, kkt_tol=kkt_tol, running_cost=running_cost, segments=segments,
                          max_iterations=max_iterations, check_continuous=check_continuous, project_v0=project_v0,
                          bounds=bounds, progress=progress, input_names=input_names, optimizer=optimizer)
    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or not 1 <= starts <= MAX_STARTS:
        raise InputError(f"starts: expected a whole number of starts from 1 to {MAX_STARTS}, got {starts!r}")
    if starts > 1 and a.segments > 1:
        raise InputError("starts: a multistart is for single shooting (segments = 1): its random starts are controls")
    method = "gni-trapezoid" if method is None else method
    g = terminal_residual(system, target)
    d = target_size(system, target, a.K * a.m)
    # refused before anything is compiled or allocated (the SQP's matrices grow as (K·m)²)
    check_control_memory(system, a.K, d, a.segments, max_bytes, optimizer=a.optimizer,
                         running_cost=running_cost is not None)
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    U0 = np.clip(warm_start(controls0, a.K, a.m), a.lo, a.hi)
    if project_v0:
        _, v0 = system.check(q0, v0, R0=R0, project_v0=True)
    single = SingleShooting.make(system, method, g, q0, v0, R0, a, running_cost)
    name, n_target = single.check(U0, a.K * a.m)
    # a redundant target (components that the others fix through the dynamics or the constraints, e.g.
    # "at rest" as every velocity of a constrained system) makes the SQP's constraint Jacobian singular
    # everywhere (SLSQP: "Singular matrix C"): the SQP solves for an independent subset, and the whole
    # target is checked at the end
    problem = sqp_problem(single, a, U0, running_cost, n_target)
    full_g, dropped = g, _redundant_components(problem, U0, a)
    if dropped:  # rebuilt (and compiled again) only then: the probe uses the functions the SQP uses
        keep = np.setdiff1d(np.arange(n_target), dropped)
        single = SingleShooting.make(system, method, TargetSubset(full_g, tuple(int(k) for k in keep)), q0, v0, R0, a,
                                      running_cost)
        n_target = keep.size
        problem = sqp_problem(single, a, U0, running_cost, n_target)
    out, iterations, optima = _multistart(problem, a, starts)
    U = out.x.reshape(a.K, a.m)
    solution = single.run(U, concrete=True)
    rank = target_rank(out.jac)
    names = _component_names(system, target, len(dropped) + n_target)
    redundant = tuple(names[k] for k in dropped)
    if dropped:  # the whole target, at the end of the run: what success means
        single = dataclasses.replace(single, g=full_g)
        miss = float(np.max(np.abs(np.asarray(full_g(final_point(system, solution), solution.v[-1])))))
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
        local_optima=optima, starts=int(starts), optimizer=a.optimizer, target_tol=a.target_tol, kkt_tol=a.kkt_tol, target_rank=rank, redundant_components=redundant,
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
        solve = solve_ipopt if a.optimizer == "ipopt" else solve_sqp
        out, iterations = solve(trial, max_iterations=a.max_iterations, target_tol=a.target_tol,
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
