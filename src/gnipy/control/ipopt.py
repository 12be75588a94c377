"""The interior-point solver of :func:`~gnipy.control.optimal_control.solve_optimal_control`
(`optimizer="ipopt"`): IPOPT (Wächter & Biegler, *On the implementation of an interior-point
filter line-search algorithm for large-scale nonlinear programming*, Math. Program. 2006) through
cyipopt, on the exact derivatives of the shooting problem: the cost's gradient and the
constraints' Jacobian by reverse mode through the steps, and the exact Hessian of the Lagrangian
$\\nabla^2(\\sigma J + \\lambda\\cdot g)$ by single shooting's second-order adjoint
(:mod:`gnipy.control.second_order`; forward over reverse mode where that does not apply,
:class:`gnipy.control.sqp.Functions`), compiled once per problem structure like the rest. With every
step a segment (`segments = steps`, :mod:`gnipy.control.step_shooting`) IPOPT gets the constraints'
Jacobian and the Hessian as sparse triplets instead.

Why beside SLSQP: SLSQP builds its Hessian by quasi-Newton updates and solves a dense QP per
iteration; on the ball-plate problem it took 121 iterations (60 steps) and 372 (120 steps), and
at 60 steps stopped at a local optimum 41 % above the one IPOPT finds from the same warm start in
13. With the exact Hessian IPOPT's iterations are few, but each costs a dense Hessian, $O(K^2)$,
and IPOPT factors it: on the sleigh, a cheap step over a long horizon, SLSQP is faster. The
control guide's table has the times (BENCHMARKS.md section 11).

The bounds are kept exactly (`bound_relax_factor = 0`): a control at its bound is at it, as the
KKT check (:func:`gnipy.control.sqp._kkt`) reads it. A step that fails at a trial point (NaN nodes)
is an evaluation error to IPOPT, which shortens its step; at the warm start it ends the solve with
a :class:`~gnipy.SolverFailure`. IPOPT's result is polished and checked as SLSQP's is
(:func:`gnipy.control.sqp.finish_stage`); where it is not a KKT point meeting the target (or a run of
the polish from its point fails), the SLSQP chain runs from the warm start and the better outcome is
kept, the message saying so either way. An error in gnipy's functions (or Ctrl-C) inside a callback
stops IPOPT at its next iteration and is raised after the solve: cyipopt itself drops errors raised
in its Hessian callback.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import SolverFailure
from ..extras import require
from .sqp import SQPProblem, StageResult, finish_stage, solve_sqp

__all__ = ["solve_ipopt", "IPOPT_TOL"]

#: IPOPT's tolerance on its scaled KKT error (`tol`). Success is not taken from its word: the
#: result is polished and checked like SLSQP's (target miss and relative KKT residual).
IPOPT_TOL = 1e-12


class _NLP:
    """cyipopt's problem object: the shooting problem's functions at IPOPT's points (dense
    Jacobian, the Hessian's lower triangle), a failed evaluation signalled to IPOPT as such, and
    the iterations reported."""

    def __init__(self, cyipopt, functions, n: int, d: int, report, count):
        self.ipopt, self.F, self.report, self.count = cyipopt, functions, report, count
        # sparse derivatives where the transcription has them (every step a segment,
        # gnipy.control.step_shooting), else dense
        self.sparse = functions.sparse
        if self.sparse:
            self.jac_structure, (self.rows, self.cols) = functions.jacobian_structure, functions.hessian_structure
        else:
            self.rows, self.cols = np.tril_indices(n)
            self.jac_structure = np.nonzero(np.ones((d, n), dtype=bool))
        self.error = None  # an error of gnipy's functions in a callback, raised after the solve

    def _call(self, fn, *args):
        try:
            return fn(*args)
        except SolverFailure:  # a failed step at a trial point: IPOPT shortens its step
            raise self.ipopt.CyIpoptEvaluationError() from None
        except BaseException as e:  # noqa: BLE001 (a bug, or Ctrl-C: kept, IPOPT stopped, raised after the solve)
            # cyipopt drops an error raised in its Hessian callback (IPOPT then goes on with whatever
            # the values' buffer holds) and turns some others into an "unrecoverable error"
            self.error = e
            raise

    def objective(self, x):
        return float(self._call(self.F.cost, x))

    def gradient(self, x):
        return np.asarray(self._call(self.F.cost_gradient, x))

    def constraints(self, x):
        return np.asarray(self._call(self.F.constraints, x))

    def jacobianstructure(self):
        return self.jac_structure

    def jacobian(self, x):
        if self.sparse:
            return np.asarray(self._call(self.F.jacobian_values, x))
        return np.asarray(self._call(self.F.constraints_jacobian, x)).ravel()

    def hessianstructure(self):
        return self.rows, self.cols

    def hessian(self, x, lam, sigma):
        if self.sparse:
            return self._call(self.F.hessian_values, x, lam, sigma)
        return self._call(self.F.hessian, x, lam, sigma)[self.rows, self.cols]

    def intermediate(self, alg_mod, iter_count, obj_value, inf_pr, *rest):
        if self.error is not None:  # an error in a callback: IPOPT stops here (User_Requested_Stop)
            return False
        if iter_count > 0:  # IPOPT reports its starting point as iteration 0
            self.count[0] += 1
            if self.report is not None:
                self.report(self.count[0], float(obj_value), float(inf_pr))
        return True


class _Outcome:
    """IPOPT's result in the fields :func:`gnipy.control.sqp.finish_stage` reads of SciPy's."""

    def __init__(self, x, info):
        self.x = np.asarray(x)
        self.success = int(info["status"]) in (0, 1)  # solved, or solved to IPOPT's acceptable level
        message = info["status_msg"]
        self.message = message.decode() if isinstance(message, bytes) else str(message)


def solve_ipopt(problem: SQPProblem, *, max_iterations: int, target_tol: float, kkt_tol: float,
                report) -> tuple[StageResult, int]:
    """`(the outcome, the iterations)`: IPOPT from the warm start with the exact Hessian (see the
    module docstring); where its outcome is not a success, the SLSQP chain
    (:func:`gnipy.control.sqp.solve_sqp`) from the warm start, and the better outcome kept. `report`
    is called once per iteration with `(iteration, cost, miss, total)` (the miss is IPOPT's primal
    infeasibility, max|g| on these problems)."""
    cyipopt = require("cyipopt", extra="ipopt", what="IPOPT optimizer (optimizer='ipopt')")
    F = problem.unknowns
    x0 = np.asarray(problem.x0, dtype=np.float64)
    n, d = x0.size, np.asarray(F.constraints(x0)).size  # (a failed run at the warm start raises here)
    count = [0]
    nlp = _NLP(cyipopt, F, n, d, None if report is None else
               (lambda i, cost, miss: report(i, cost, miss, max(max_iterations, i))), count)
    # IPOPT's bounds: +-1e20 is "none" (its nlp_lower/upper_bound_inf)
    lo = np.where(np.isfinite(problem.x_lo), problem.x_lo, -1e20)
    hi = np.where(np.isfinite(problem.x_hi), problem.x_hi, 1e20)
    solver = cyipopt.Problem(n=n, m=d, problem_obj=nlp, lb=lo, ub=hi, cl=np.zeros(d), cu=np.zeros(d))
    for key, value in (("sb", "yes"), ("print_level", 0), ("tol", IPOPT_TOL), ("max_iter", int(max_iterations)),
                       ("bound_relax_factor", 0.0)):
        solver.add_option(key, value)
    x, info = solver.solve(x0)
    del solver  # IPOPT's memory, before the fallback
    if nlp.error is not None:
        raise nlp.error
    outcome = _Outcome(np.clip(x, problem.x_lo, problem.x_hi), info)
    try:
        out = finish_stage(problem, outcome, "IPOPT", target_tol, kkt_tol)
        failed = None if out.ok else out.message(target_tol, kkt_tol)
    except SolverFailure as e:  # a run of the polish from IPOPT's point failed: not an outcome
        out, failed = None, f"IPOPT: {outcome.message}; its point could not be polished: {e}"
    if failed is not None:
        # the SLSQP chain from the warm start (its own fallback included), counted on
        retry, more = solve_sqp(problem, max_iterations=max_iterations, target_tol=target_tol, kkt_tol=kkt_tol,
                                report=None if report is None else
                                (lambda i, cost, miss, total, k=count[0]: report(k + i, cost, miss, k + total)))
        count[0] += more
        if out is None or (retry.ok, -retry.kkt - retry.miss) > (out.ok, -out.kkt - out.miss):
            out = dataclasses.replace(retry, stages=f"IPOPT failed ({failed}); then {retry.stages}")
        else:  # the message says that the fallback ran (its iterations are counted)
            out = dataclasses.replace(out, stages=f"IPOPT; the SLSQP chain from the warm start did no better "
                                                  f"({retry.stages}: {retry.res.message})")
    return out, count[0]

