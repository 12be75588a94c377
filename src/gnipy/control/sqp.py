"""The solver of :func:`~gnipy.control.optimal_control.solve_optimal_control` (see that module's
docstring): SciPy's SLSQP on the exact gradients; where it does not reach a KKT point,
trust-constr from the warm start and SLSQP from its result (the better of the two outcomes kept).
Each stage's result is polished by Gauss–Newton steps on the target over the free controls and
checked for a KKT point by single shooting (:func:`solve_sqp`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import bind
from ..errors import SolverFailure

__all__ = ["Functions", "AtPoint", "cost_and_gradient", "constraints_and_jacobian", "lagrangian_hessian", "finite_hessian", "SQPProblem", "StageResult", "solve_sqp", "finish_stage"]


@dataclasses.dataclass(frozen=True)
class Functions:
    """A shooting problem's functions of its unknowns (flattened), compiled: the cost's value and
    gradient, the constraints' value and Jacobian (reverse mode through the steps), and the
    Hessian of the Lagrangian `hessian(x, lam, sigma)` of $\\sigma J + \\lambda\\cdot g$
    (:func:`_lagrangian_hessian`; compiled on its first call: only IPOPT asks for it,
    :mod:`gnipy.control.ipopt`)."""

    cost: Callable
    cost_gradient: Callable
    constraints: Callable
    constraints_jacobian: Callable
    hessian: Callable

    #: Whether the derivatives also come as sparse values at fixed places (IPOPT's form;
    #: :class:`gnipy.control.step_shooting.SparseFunctions`); these are dense.
    sparse = False

    @classmethod
    def of(cls, problem) -> "Functions":
        """The functions of `problem.cost(x)` and `problem.constraints(x)`: two compiled programs,
        the cost with its gradient and the constraints with their Jacobian, each computed once per
        point (SciPy asks for a value and then its derivative at the same point). The programs are
        module-level functions of `problem`, bound to it (:func:`gnipy.compilation.bind`: the
        problem's partition into arrays and the rest done once, not at every call): a problem that
        is a pytree (an equinox Module whose numbers are arrays) compiles once per structure, and
        every solve, warm start and start of a multistart of that structure reuses the programs
        (with gnipy's compiler options; measured on the sleigh-steering problem: XLA's compile time
        6.3 s -> 4.2 s with them, the same optimum to the last digit)."""
        cost = AtPoint(bind(cost_and_gradient, problem), "cost and its gradient")
        constraints = AtPoint(bind(constraints_and_jacobian, problem), "constraints and their Jacobian")
        return cls(cost=cost.first, cost_gradient=cost.second, constraints=constraints.first,
                   constraints_jacobian=constraints.second, hessian=_Hessian(problem))


class AtPoint:
    """A pair of arrays computed together at a point and kept for the last point asked. A value
    that is not finite stops the solve with a :class:`~gnipy.SolverFailure`: the compiled runs
    leave NaN nodes after a failed step (`simulate(..., throw=False)` under a transformation, so
    that the programs have no host callback and JAX's persistent cache keeps them)."""

    def __init__(self, fn, what: str):
        self.fn, self.what, self.key, self.value = fn, what, None, None

    def _at(self, x):
        x = np.ascontiguousarray(x, dtype=np.float64)
        key = x.tobytes()
        if key != self.key:
            a, b = self.fn(x)  # a NumPy array, passed to bind's program without a device_put of its own
            a, b = np.asarray(a), np.asarray(b)
            if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
                raise SolverFailure(
                    f"control: the {self.what} are not finite at an iterate of the optimizer (largest unknown "
                    f"{np.max(np.abs(x), initial=0.0):.3g}): a step of the run failed (its solve did not converge) or "
                    "the cost or target gave a non-finite value; bound the controls, start from a better warm start "
                    "or use a smaller h", step=-1, time=float("nan"), residual=float("nan"))
            self.key, self.value = key, (a, b)
        return self.value

    def first(self, x):
        return self._at(x)[0]

    def second(self, x):
        return self._at(x)[1]


class _Hessian:
    """The Hessian of the Lagrangian of `problem` at a point, a NumPy array; a value that is not
    finite stops the solve with a :class:`~gnipy.SolverFailure` (as :class:`AtPoint`)."""

    def __init__(self, problem):
        self.program = bind(lagrangian_hessian, problem)

    def __call__(self, x, lam, sigma):
        return finite_hessian(self.program(np.asarray(x, np.float64), np.asarray(lam, np.float64),
                                           np.asarray(sigma, np.float64)))


def finite_hessian(values) -> np.ndarray:
    """`values` of the Lagrangian's Hessian (all of it, or its nonzeros) as a NumPy array; values
    that are not finite stop the solve with a :class:`~gnipy.SolverFailure` (as :class:`AtPoint`)."""
    H = np.asarray(values)
    if not np.all(np.isfinite(H)):
        raise SolverFailure("control: the Hessian of the Lagrangian is not finite at an iterate of the optimizer: "
                            "a step of the run failed or the cost or target is not twice differentiable there",
                            step=-1, time=float("nan"), residual=float("nan"))
    return H


def lagrangian_hessian(problem, x, lam, sigma):
    """$\\nabla^2(\\sigma J + \\lambda\\cdot g)$ at `x` (compiled once per problem structure): the
    problem's own (`lagrangian_hessian`: single shooting's second-order adjoint,
    :mod:`gnipy.control.second_order`) where it has one, else forward mode over the reverse-mode
    gradient, one tangent per unknown."""
    own = getattr(problem, "lagrangian_hessian", None)
    H = None if own is None else own(x, lam, sigma)
    if H is None:
        H = jax.hessian(lambda y: sigma * problem.cost(y) + lam @ problem.constraints(y))(x)
    return H


def cost_and_gradient(problem, x):
    """The cost and its gradient at `x` (compiled once per problem structure: :func:`gnipy.compilation.bind`)."""
    return jax.value_and_grad(problem.cost)(x)


def constraints_and_jacobian(problem, x):
    """The constraints and their Jacobian at `x`, by reverse mode: one pass through the steps and
    one adjoint per constraint (compiled once per problem structure)."""
    g, pullback = jax.vjp(problem.constraints, x)
    (J,) = jax.vmap(pullback)(jnp.eye(g.size, dtype=g.dtype))
    return g, J


@dataclasses.dataclass(frozen=True)
class SQPProblem:
    """A shooting problem as the SQP sees it.

    Attributes:
        controls: the functions of the controls alone, (K·m,), by single shooting (the target is
            the constraint): the polish and the KKT check use them.
        unknowns: the functions of the SQP's unknowns: `controls` for single shooting; for
            multiple shooting those of the controls and the segments' states (the defects, then
            the target, are the constraints).
        single: whether the transcription is single shooting.
        x0, x_lo, x_hi: the unknowns' warm start and bounds.
        lo, hi: the controls' bounds, (K·m,).
        n_target: the number of components of the target (the last constraints).
        scale: the factor of the cost (SLSQP's quasi-Newton Hessian starts at the identity).
        hessian: the scaled cost's Hessian's diagonal value when the cost is the effort alone (for
            trust-constr), else None (BFGS).
    """

    controls: Functions
    unknowns: Functions
    single: bool
    x0: np.ndarray
    x_lo: np.ndarray
    x_hi: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    n_target: int
    scale: float
    hessian: float | None


@dataclasses.dataclass(frozen=True)
class StageResult:
    """The outcome of a stage of the SQP, polished and checked by single shooting.

    Attributes:
        x: the controls, flattened (K·m,).
        polish: the Gauss–Newton steps of the polish.
        miss: $\\max|g|$ after the polish.
        kkt, lam, active, signs_ok: the relative KKT residual, the target's multipliers, the number
            of controls at a bound and whether their multipliers have the sign of a minimum.
        ok: success: the target met to `target_tol`, a KKT point to `kkt_tol`, the signs right.
        res: SciPy's result of the stage's last solver.
        stages: the stages run, in words.
        jac: $\\partial g/\\partial u$ at `x`, or None where the KKT conditions of the
            multiple-shooting problem were checked.
    """

    x: np.ndarray
    polish: int
    miss: float
    kkt: float
    lam: np.ndarray
    active: int
    signs_ok: bool
    ok: bool
    res: object
    stages: str
    jac: np.ndarray | None

    def message(self, target_tol: float, kkt_tol: float) -> str:
        """How the solve ended, in words: the stages and the solver's message, the polish, and
        where the solver's word is not borne out, the miss or the KKT residual."""
        res = self.res
        message = f"{self.stages}: {res.message}" + (f"; polished in {self.polish} Gauss-Newton steps"
                                                     if self.polish else "")
        if res.success and self.miss > target_tol:
            message += f"; the target is missed by {self.miss:.3e} > target_tol = {target_tol:g}"
        if res.success and (self.kkt > kkt_tol or not self.signs_ok):
            message += (f"; not a KKT point (residual {self.kkt:.3e}"
                        + ("" if self.signs_ok else ", bound multipliers of the wrong sign") + ")")
        return message


class _Iterations:
    """SciPy's callback: counts the iterations across the stages and reports them (`report`:
    `(iteration, cost, miss, total)`, total the most the solve can take as known now)."""

    def __init__(self, functions: Functions, report, cap: int):
        self.functions, self.report, self.cap, self.count = functions, report, cap, 0

    def __call__(self, x):
        self.count += 1
        if self.report is not None:
            f = self.functions
            self.report(self.count, float(f.cost(x)), float(np.max(np.abs(f.constraints(x)))),
                        max(self.cap, self.count))


def solve_sqp(problem: SQPProblem, *, max_iterations: int, target_tol: float, kkt_tol: float,
              report) -> tuple[StageResult, int]:
    """`(the outcome, the SQP's iterations)`: SLSQP from the warm start; where it does not reach a
    KKT point, trust-constr from the warm start, then SLSQP from its result, and the better outcome
    kept. Each stage runs up to `max_iterations`; `report` is called once per iteration."""
    F = problem.unknowns
    x_lo, x_hi = problem.x_lo, problem.x_hi
    counter = _Iterations(F, report, max_iterations)
    # SLSQP starts its quasi-Newton Hessian at the identity: the cost is scaled to start near it
    objective = (lambda x: problem.scale * float(F.cost(x)), lambda x: problem.scale * np.asarray(F.cost_gradient(x)))
    constraint_fns = (lambda x: np.asarray(F.constraints(x)), lambda x: np.asarray(F.constraints_jacobian(x)))

    res = _slsqp(objective, constraint_fns, problem.x0, x_lo, x_hi, max_iterations, counter)
    out = finish_stage(problem, res, "SLSQP", target_tol, kkt_tol)
    if not out.ok:
        # SLSQP's active set can stall (measured: the sleigh at h = 0.1 with |tau| <= 1.5, all 40
        # controls at a bound and a miss of 0.9); an interior-point method (trust-constr) from the
        # warm start finds the region, and SLSQP from there the active set and the last digits
        counter.cap = counter.count + 2 * max_iterations  # trust-constr, then SLSQP again
        first = _trust_constr(objective, constraint_fns, problem.x0, x_lo, x_hi, max_iterations, counter,
                              hessian=problem.hessian)
        counter.cap = counter.count + max_iterations
        res = _slsqp(objective, constraint_fns, np.clip(first.x, x_lo, x_hi), x_lo, x_hi, max_iterations, counter)
        retry = finish_stage(problem, res, f"SLSQP failed ({out.res.message}); trust-constr ({first.nit} iterations), "
                        "then SLSQP", target_tol, kkt_tol)
        if (retry.ok, -retry.kkt - retry.miss) > (out.ok, -out.kkt - out.miss):
            out = retry
    # the iterations as reported (SciPy's callback, once per iteration of each stage): trust-constr's
    # own count (`nit`) can exceed its callbacks, and the progress report must count what it shows
    return out, counter.count


def finish_stage(problem: SQPProblem, res, stages: str, target_tol: float, kkt_tol: float) -> StageResult:
    """A stage's result: the controls, checked and polished by single shooting (what a
    re-simulation gives)."""
    f = problem.controls
    full = np.clip(res.x, problem.x_lo, problem.x_hi)
    x = full[: problem.lo.size]
    x, polish, miss = _polish(x, f.constraints, f.constraints_jacobian, problem.lo, problem.hi, target_tol)
    jac = None
    # by single shooting after a polish, and where the unknowns are every step's state (their dense
    # Jacobian, K states by K states, is what IPOPT's sparse one avoids)
    if problem.single or polish or problem.unknowns.sparse:
        jac = np.asarray(f.constraints_jacobian(x))
        kkt, lam, active, signs_ok = _kkt(np.asarray(f.cost_gradient(x)), jac, x, problem.lo, problem.hi)
    else:  # the KKT conditions of the multiple-shooting problem (equivalent; no other compile)
        F = problem.unknowns
        kkt, lam, active, signs_ok = _kkt(np.asarray(F.cost_gradient(full)), np.asarray(F.constraints_jacobian(full)),
                                          full, problem.x_lo, problem.x_hi)
        lam = lam[-problem.n_target:]  # the target's multipliers (after the defects')
    # success is checked here, not taken from the SQP's word: the target met, a KKT point, the
    # bound multipliers of the right sign (SLSQP can stop at its iteration cap on a point that
    # is all three, and say it converged on one that is not)
    ok = miss <= target_tol and kkt <= kkt_tol and signs_ok
    return StageResult(x=x, polish=polish, miss=miss, kkt=kkt, lam=lam, active=active, signs_ok=signs_ok, ok=ok,
                       res=res, stages=stages, jac=jac)


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
        if J.shape[1] < J.shape[0]:  # (values that are not finite stop the solve earlier: AtPoint)
            break
        dx = np.zeros_like(x)
        # the least-norm Gauss–Newton step by SVD: defined also when the target's rows are dependent
        # (a redundant target: ControlResult.redundant_components), where J Jᵀ is singular
        dx[free] = -np.linalg.lstsq(J, c, rcond=None)[0]
        x_new = np.clip(x + dx, lo, hi)
        c_new = np.asarray(c_val(x_new))
        miss_new = float(np.max(np.abs(c_new)))
        if not miss_new < miss:
            break
        x, c, miss = x_new, c_new, miss_new
        steps += 1
    return x, steps, miss


def _kkt(grad, Jg, x, lo, hi):
    """KKT residual over the free controls, the multipliers, the active bounds and their signs
    (`grad` and `Jg` are finite: :class:`AtPoint` stops the solve at a value that is not)."""
    at_lo, at_hi = _at_bounds(x, lo, hi)
    free = ~(at_lo | at_hi)
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
