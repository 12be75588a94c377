"""The result of :func:`~gnipy.control.optimal_control.solve_optimal_control`:
:class:`ControlResult`."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..solution import Solution

__all__ = ["ControlResult", "RANK_TOLERANCE", "target_rank"]

#: Singular values of the target's Jacobian below this fraction of the largest count as zero
#: (:func:`target_rank`): far above the round-off of a Jacobian computed through the steps (about
#: 1e-13 relative) and far below the conditioning of a well-posed target.
RANK_TOLERANCE = 1e-9


def target_rank(jacobian) -> int | None:
    """The numerical rank of the target's Jacobian with respect to the controls (:data:`RANK_TOLERANCE`);
    None for no Jacobian or a non-finite one."""
    if jacobian is None:
        return None
    J = np.asarray(jacobian, dtype=np.float64)
    if J.size == 0 or not np.all(np.isfinite(J)):
        return None
    s = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(s > RANK_TOLERANCE * s[0])) if s[0] > 0 else 0


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
        target_tol, kkt_tol: the tolerances `success` was judged by (NaN: not recorded).
        target_rank: the rank of `target_jacobian` (singular values below :data:`RANK_TOLERANCE`
            times the largest count as zero; None where no Jacobian was kept). Below the target's
            number of components the target is redundant: some component is fixed by the others
            through the dynamics or the constraints (a velocity that the constraints determine, say),
            and the target's multipliers are not unique.
        redundant_components: the target's components found to be fixed by the others before the
            solve (a singular constraint Jacobian for any controls): the SQP solved for the rest, and
            `target_residual` and `success` are for the whole target.
        local_optima: after a multistart (`starts > 1`), the distinct optima the successful starts
            reached, `((cost, number of starts), ...)` by increasing cost (the first is returned);
            empty for one start.
        starts: the number of starts (1: no multistart).
        optimizer: the optimizer asked for, `"slsqp"` or `"ipopt"` (the message says which stages
            ran: a fallback's too).
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
    target_tol: float = float("nan")
    kkt_tol: float = float("nan")
    target_rank: int | None = None
    redundant_components: tuple[str, ...] = ()
    local_optima: tuple = ()
    starts: int = 1
    optimizer: str = "slsqp"

    @property
    def redundant_target(self) -> bool:
        """Whether the target's components are dependent (:attr:`target_rank` below their number)."""
        return self.target_rank is not None and self.target_rank < np.shape(self.target_jacobian)[0]

    def _multistart_lines(self) -> list[str]:
        if self.starts <= 1:
            return []
        found = sum(n for _, n in self.local_optima)
        listed = ", ".join(f"{c:.10g} ({n} start{'s' if n > 1 else ''})" for c, n in self.local_optima)
        return [f"  multistart: {len(self.local_optima)} distinct local optim{'a' if len(self.local_optima) > 1 else 'um'} "
                f"from {found} of {self.starts} starts that converged" + (f": {listed}" if listed else "")]

    def _rank_lines(self) -> list[str]:
        if self.redundant_components:
            return [f"  redundant target: {', '.join(self.redundant_components)} fixed by the other components "
                    "(through the dynamics or the constraints); solved for the rest, the whole target checked"]
        if not self.redundant_target:
            return []
        d = np.shape(self.target_jacobian)[0]
        return [f"  redundant target: its {d} components have a Jacobian of rank {self.target_rank} with respect to the "
                "controls (dependent: one is fixed by the others through the dynamics or the constraints; "
                "the multipliers are not unique, and a target of independent components is better posed)"]

    def _kkt_line(self) -> str:
        """The summary's KKT line. At a point that misses the target the KKT residual (stationarity
        over the free controls, with the target's multipliers fitted by least squares) says nothing
        of optimality, and neither do the bound multipliers' signs: the line says the point is not
        feasible instead of quoting them as a verdict."""
        if self.target_residual > self.target_tol:  # False when the tolerance was not recorded (NaN)
            return (f"  no KKT point: the target is missed by {self.target_residual:.3e} > target_tol = "
                    f"{self.target_tol:g} (the stationarity residual {self.kkt_residual:.3e} of an infeasible point "
                    f"is no test of optimality); {self.active_bounds} controls at a bound")
        above = "" if not self.kkt_residual > self.kkt_tol else f" > kkt_tol = {self.kkt_tol:g}: not a KKT point"
        return (f"  KKT residual (free controls) = {self.kkt_residual:.3e}{above}; {self.active_bounds} controls at a "
                "bound" + ("" if self.active_bounds == 0 else
                          f" (multipliers {'of the right sign' if self.bound_multipliers_ok else 'of the WRONG sign'})"))

    def summary(self) -> str:
        """A few lines: success, cost, residuals, iterations and time."""
        K, m = self.controls.shape
        return "\n".join([
            f"optimal control with {self.method}: {K} steps x {m} input{'s' if m > 1 else ''}, "
            f"{'converged' if self.success else 'NOT converged'} ({self.message})",
            f"  cost J = {self.cost:.12g}",
            f"  target residual max|g| = {self.target_residual:.3e}",
            self._kkt_line(),
            f"  iterations: {self.iterations} {'IPOPT' if self.optimizer == 'ipopt' else 'SQP'} + "
            f"{self.polish_iterations} polish; {self.wall_time:.2f} s",
        ] + self._rank_lines() + self._multistart_lines() + ([] if math.isnan(self.continuous_miss) else [
            f"  the continuous system (reference) with these inputs misses the target by {self.continuous_miss:.3e}"
            + (" (the discretization's error: a smaller h reduces it)" if self.success
               else " (the discrete problem is not solved either)")]))
