"""The result of :func:`~gnipy.control.optimal_control.solve_optimal_control`:
:class:`ControlResult`."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..solution import Solution

__all__ = ["ControlResult"]


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
