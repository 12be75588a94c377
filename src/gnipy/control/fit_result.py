"""The result of :func:`gnipy.fit` (:class:`FitResult`) and the statistics in it: the
uncertainties from the Jacobian of the weighted residuals at the estimate (:func:`uncertainties`;
the formulas are in :mod:`gnipy.control.identification`'s docstring), how the fit ended in words
(:func:`fit_notes`) and the residuals of the fitted run (:func:`observed_residuals`)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..solution import Solution
from .observations import Observations

__all__ = ["FitResult", "Uncertainties", "uncertainties", "fit_notes", "observed_residuals", "RCOND",
           "IDENTIFIABLE_TOL"]

#: Singular values of the scaled Jacobian below this fraction of the largest count as zero: the
#: directions the projection of `v0` removes (about 1e-16 of the largest), and quantities the
#: data cannot tell apart.
RCOND = 1e-10

#: A reported quantity is identifiable when its derivative lies in the row space of the Jacobian
#: to this relative tolerance.
IDENTIFIABLE_TOL = 1e-6


@dataclasses.dataclass(frozen=True, repr=False, eq=False)
class FitResult:
    """The outcome of :func:`fit`.

    Attributes:
        names: the estimated quantities: the parameters by name, then `q0.<coordinate>` and
            `v0.<velocity>` for estimated initial-condition components.
        values: their estimates, (P,) in the order of `names` (`v0` components projected onto
            the constraints).
        stderr: their standard errors, (P,) (`inf` for a quantity the data cannot determine,
            NaN when no degree of freedom is left to estimate the error scale).
        covariance: their covariance matrix, (P, P).
        correlation: their correlation matrix, (P, P) (NaN where a standard error is 0 or inf).
        identifiable: whether each quantity is determined by the data, (P,) bool.
        params: the estimated model parameters, name -> value.
        q0: the full initial coordinates of the fitted run, (n,).
        v0: the full initial velocity of the fitted run, projected onto the constraints, (N,).
        solution: the fitted :class:`~gnipy.Solution` (every node from `t0` to the last
            observation time, at the estimate).
        observations: the :class:`Observations` fitted.
        residuals: model minus observation, (T, k) (NaN where a value is missing).
        raw: the solver's final point: the estimated quantities with the `v0` components before
            their projection onto the constraints, (P,) (equal to `values` where no `v0`
            component is estimated).
        jacobian: the Jacobian of the weighted residuals (flattened row by row, zero rows for
            missing values) with respect to the estimated quantities at `raw`, (T·k, P).
        chi2: the sum of the squared weighted residuals.
        n_obs: the number of observed values used.
        rank: the number of independent directions in the Jacobian (the effective number of
            estimated quantities; the projection of `v0` removes one per constraint when all of
            `v0` is estimated).
        dof: the degrees of freedom, `n_obs - rank`.
        reduced_chi2: `chi2 / dof` (about 1 for a good fit when `sigma` is known).
        sigma_known: whether the measurement errors were given (`sigma`): the covariance is then
            $(J^TJ)^{-1}$; otherwise it is scaled by `reduced_chi2`.
        success: whether the least-squares solver converged.
        message: how the fit ended, in words (with warnings about undetermined quantities).
        iterations: the solver's iterations (steps of Levenberg–Marquardt, rejected ones included).
        initial_guess: the starting values, (P,).
        method: the integrator's name; `h`, `t0`: the step grid.
        wall_time: seconds spent in :func:`fit` (compilation included).
    """

    names: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    identifiable: np.ndarray
    params: dict[str, float]
    q0: np.ndarray
    v0: np.ndarray
    solution: Solution
    observations: Observations
    residuals: np.ndarray
    raw: np.ndarray
    jacobian: np.ndarray
    chi2: float
    n_obs: int
    rank: int
    dof: int
    reduced_chi2: float
    sigma_known: bool
    success: bool
    message: str
    iterations: int
    initial_guess: np.ndarray
    method: str
    h: float
    t0: float
    wall_time: float
    _problem: Any = dataclasses.field(default=None, compare=False)
    _data: Any = dataclasses.field(default=None, compare=False)

    @property
    def estimates(self) -> dict[str, float]:
        """The estimates by name."""
        return dict(zip(self.names, (float(x) for x in self.values)))

    @property
    def standard_errors(self) -> dict[str, float]:
        """The standard errors by name."""
        return dict(zip(self.names, (float(x) for x in self.stderr)))

    def weighted_residuals(self, raw=None) -> np.ndarray:
        """The weighted residuals (flattened, zero at missing values) of the fitted problem at
        `raw` (the estimated quantities in the order of :attr:`names`, `v0` components before
        their projection; default :attr:`raw`, the solver's final point), computed by an ordinary
        (untransformed) simulation: the function whose derivative is :attr:`jacobian`."""
        y = self.raw if raw is None else np.asarray(raw, dtype=np.float64).reshape(-1)
        if y.shape != self.raw.shape:
            raise InputError(f"raw: expected {self.raw.size} numbers (one per name), got shape {y.shape}")
        return np.asarray(self._problem.residuals(jnp.asarray(y), self._data))

    def summary(self) -> str:
        """A readable table of the estimates and their standard errors, and how the fit ended."""
        obs = self.observations
        head = [
            f"gnipy.fit: {self.solution.system} with {self.method}, h = {self.h:g}; {self.n_obs} observed values "
            f"of {', '.join(obs.variables)} at {len(obs.times)} times",
            f"{'converged' if self.success else 'NOT converged'} after {self.iterations} iterations: {self.message}",
            f"chi2 = {self.chi2:.6g}, dof = {self.dof}, reduced chi2 = {self.reduced_chi2:.4g} "
            f"({'sigma given' if self.sigma_known else 'sigma estimated from the residuals'})",
        ]
        width = max([9] + [len(n) for n in self.names])
        rows = [f"{'quantity':<{width}}  {'estimate':>16}  {'std error':>10}  {'relative':>9}"]
        for name, x, s in zip(self.names, self.values, self.stderr):
            # relative error only where the estimate is known to differ from zero
            rel = f"{abs(s / x):9.2e}" if abs(x) > s and math.isfinite(s) else f"{'':>9}"
            rows.append(f"{name:<{width}}  {x:16.9g}  {s:10.3g}  {rel}")
        return "\n".join(head + rows)

    def __repr__(self) -> str:
        parts = ", ".join(f"{n}={x:.6g}±{s:.2g}" for n, x, s in zip(self.names, self.values, self.stderr))
        return f"FitResult({parts}; success={self.success}, iterations={self.iterations})"


# ----------------------------------------------------------------------------------------------
# The statistics
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Uncertainties:
    """The statistics of a fit at its estimate (:func:`uncertainties`): `stderr`, `covariance`,
    `correlation`, `identifiable`, `rank`, `dof` and `reduced_chi2` as in :class:`FitResult`, and
    `finite`: whether the Jacobian is finite (else they are those of a zero Jacobian)."""

    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    identifiable: np.ndarray
    rank: int
    dof: int
    reduced_chi2: float
    finite: bool


def uncertainties(J, phi, scale, chi2: float, n_obs: int, sigma_known: bool) -> Uncertainties:
    """The uncertainties of the reported quantities from the Jacobian `J` of the weighted residuals
    (T·k, P) and the reported quantities' derivative `phi` (P, P), both with respect to the unscaled
    estimated quantities, their `scale`, chi² and the number of observed values: the covariance
    $s^2 \\phi_s (J_s^TJ_s)^+ \\phi_s^T$ with the derivatives taken in the scaled quantities
    (singular values below :data:`RCOND` of the largest dropped), $s^2$ the reduced chi² unless
    `sigma_known`. A quantity whose derivative is not in the row space of the Jacobian (to
    :data:`IDENTIFIABLE_TOL`) is not identifiable: infinite standard error, NaN covariance with the
    others."""
    Js = J * scale[None, :]
    finite = bool(np.all(np.isfinite(Js)))
    if not finite:  # a run that blew up at the estimate, or weights that overflow: no SVD to take
        Js = np.zeros_like(Js)
    _, S, Vt = np.linalg.svd(Js, full_matrices=False)
    rank = int(np.sum(S > RCOND * S[0])) if S.size and S[0] > 0 else 0
    V = Vt[:rank].T
    pinv = (V / S[:rank] ** 2) @ V.T
    phis = phi * scale[None, :]  # the reported quantities' derivatives with respect to z
    inrow = phis @ V @ V.T
    norms = np.linalg.norm(phis, axis=1)
    identifiable = np.linalg.norm(phis - inrow, axis=1) <= IDENTIFIABLE_TOL * np.maximum(norms, 1e-300)
    dof = n_obs - rank
    reduced = chi2 / dof if dof > 0 else float("nan")
    s2 = 1.0 if sigma_known else reduced
    cov = s2 * phis @ pinv @ phis.T
    stderr, corr = _undetermined(cov, identifiable)
    return Uncertainties(stderr=stderr, covariance=cov, correlation=corr, identifiable=identifiable, rank=rank,
                         dof=dof, reduced_chi2=reduced, finite=finite)


def _undetermined(cov, identifiable):
    """`(stderr, correlation)` of the covariance `cov`, which is marked in place where a quantity is
    not identifiable (inf on the diagonal, NaN beside it)."""
    stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    stderr[~identifiable] = np.inf
    cov[~identifiable, :] = np.nan
    cov[:, ~identifiable] = np.nan
    for i in np.flatnonzero(~identifiable):
        cov[i, i] = np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(stderr, stderr)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, np.where((stderr > 0) & np.isfinite(stderr), 1.0, np.nan))
    return stderr, corr


def fit_notes(success: bool, solver_message: str, stats: Uncertainties, names) -> tuple[bool, list[str]]:
    """`(success, notes)`: whether the fit succeeded (the solver converged and the Jacobian at the
    estimate is finite) and how it ended, in words: the solver's message, the quantities the data
    do not determine, no degrees of freedom left."""
    if not stats.finite:
        success = False
        solver_message += "; the Jacobian at the estimate is not finite (no uncertainties)"
    notes = [solver_message if success else f"the solver did not converge: {solver_message}"]
    if not stats.identifiable.all():
        bad = [n for n, ok in zip(names, stats.identifiable) if not ok]
        notes.append(f"the data do not determine {', '.join(bad)} (a null direction of the Jacobian: infinite "
                     "standard error)")
    if stats.dof <= 0:
        notes.append("no degrees of freedom are left: the standard errors cannot be estimated (give sigma or more "
                     "observations)")
    return success, notes


def observed_residuals(solution: Solution, columns, steps, observations: Observations, mask) -> np.ndarray:
    """Model minus observation, (T, k): the fitted run's values of the observed variables (`columns`:
    `("q" or "v", index)`) at the observations' `steps`; NaN where a value is missing (`mask`
    false) or the run ended before the time."""
    model = np.full(observations.values.shape, np.nan)
    got = np.asarray(solution.q), np.asarray(solution.v)
    for j, (kind, i) in enumerate(columns):
        rows = [k for k in steps if k < got[0].shape[0]]
        model[: len(rows), j] = got[0 if kind == "q" else 1][rows, i]
    return np.where(mask, model - observations.values, np.nan)
