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

__all__ = ["FitResult", "Uncertainties", "Combination", "uncertainties", "fit_notes", "observed_residuals", "RCOND",
           "IDENTIFIABLE_TOL"]

#: Singular values of the scaled Jacobian below this fraction of the largest count as exact zeros:
#: the directions the projection of `v0` removes (about 1e-16 of the largest), and quantities that
#: do not enter the model at all. They set the rank (and so the degrees of freedom).
RCOND = 1e-10

#: A reported quantity with a part along an exact null direction (below :data:`RCOND`) larger than
#: this fraction of its derivative is not identifiable.
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
            observation time, at the estimate), or None when the system is not valid at the
            estimate (a user's model without bounds that drifted out of its valid region: the
            result is then flagged, `success` False, and says why in `message`).
        observations: the :class:`Observations` fitted.
        residuals: model minus observation, (T, k) (NaN where a value is missing).
        raw: the solver's final point: the estimated quantities with the `v0` components before
            their projection onto the constraints, (P,) (equal to `values` where no `v0`
            component is estimated).
        jacobian: the Jacobian of the weighted residuals (flattened row by row, zero rows for
            missing values) with respect to the estimated quantities at `raw`, (T·k, P).
        chi2: the sum of the squared weighted residuals.
        n_obs: the number of observed values used.
        rank: the number of independent directions in the Jacobian (singular values above
            :data:`RCOND` of the largest: the effective number of estimated quantities; the
            projection of `v0` removes one per constraint when all of `v0` is estimated).
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
        determined: how many directions of the Jacobian the data determine (the rule of
            :func:`uncertainties`: the continuous model's part of the Jacobian along them exceeds
            the noise and the discretization's part); below `rank` when some combinations are lost
            in the noise or are seen only through the discretization error.
        threshold: $s$, the noise scale of one weighted residual (1 when `sigma` is given, else
            the root of the reduced chi²).
        discretization: $d$, the size (norm over the observed values, weighted) of the fitted
            predictions' discretization error, estimated by Richardson extrapolation from reruns
            at h/2 (NaN when they failed: then the rule weighs the noise alone).
        combinations: the combinations of quantities that are not identifiable one by one but
            that the data determine (:class:`Combination`), e.g. $m r^2 + I$ linearized.
        bounds: the bounded quantities, name -> `(lower, upper)` (:mod:`gnipy.control.bounds`).
        at_bound: the quantities whose estimate is at one of its bounds, name -> the bound (the
            fit is then flagged: the data push it out of the valid region).
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
    determined: int = 0
    threshold: float = float("nan")
    discretization: float = float("nan")
    combinations: tuple = ()
    bounds: dict = dataclasses.field(default_factory=dict)
    at_bound: dict = dataclasses.field(default_factory=dict)
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
        system = "the model" if self.solution is None else self.solution.system
        head = [
            f"gnipy.fit: {system} with {self.method}, h = {self.h:g}; {self.n_obs} observed values "
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
            bound = f"  at its bound {self.at_bound[name]:g}" if name in self.at_bound else ""
            rows.append(f"{name:<{width}}  {x:16.9g}  {s:10.3g}  {rel}{bound}")
        if self.combinations:
            rows.append("determined combinations (linearized at the estimate):")
            rows.extend(f"  {c}" for c in self.combinations)
        return "\n".join(head + rows)

    def __repr__(self) -> str:
        parts = ", ".join(f"{n}={x:.6g}±{s:.2g}" for n, x, s in zip(self.names, self.values, self.stderr))
        return f"FitResult({parts}; success={self.success}, iterations={self.iterations})"


# ----------------------------------------------------------------------------------------------
# The statistics
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Combination:
    """A linear combination of estimated quantities that the data determine although the
    quantities in it are not determined one by one (e.g. $m r^2 + I$ of a rolling disk whose
    motion depends on that sum only, linearized at the estimate).

    Attributes:
        coefficients: name -> coefficient (the largest in size is 1).
        value: the combination $\\sum_i c_i y_i$ at the estimate.
        stderr: its standard error.
    """

    coefficients: dict
    value: float
    stderr: float

    def __str__(self) -> str:
        terms = []
        for name, c in self.coefficients.items():
            sign = "-" if c < 0 else "+"
            coef = "" if abs(abs(c) - 1.0) < 5e-7 else f"{abs(c):.6g}·"
            terms.append(f"{sign} {coef}{name}")
        text = " ".join(terms)
        return (text[2:] if text.startswith("+ ") else "-" + text[2:]) + f" = {self.value:.9g} ± {self.stderr:.3g}"


@dataclasses.dataclass(frozen=True)
class Uncertainties:
    """The statistics of a fit at its estimate (:func:`uncertainties`): `stderr`, `covariance`,
    `correlation`, `identifiable`, `rank`, `determined`, `dof`, `reduced_chi2`, `threshold` and
    `combinations` as in :class:`FitResult`, and `finite`: whether the Jacobian is finite (else
    they are those of a zero Jacobian)."""

    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    identifiable: np.ndarray
    rank: int
    determined: int
    dof: int
    reduced_chi2: float
    threshold: float
    combinations: tuple
    finite: bool


def uncertainties(J, phi, scale, chi2: float, n_obs: int, sigma_known: bool, discrete_part=None,
                  names=(), values=None) -> Uncertainties:
    """The uncertainties of the reported quantities from the Jacobian `J` of the weighted residuals
    (T·k, P) and the reported quantities' derivative `phi` (P, P), both with respect to the unscaled
    estimated quantities, their `scale` (the estimates' sizes), chi², the number of observed
    values, and `discrete_part`: a function of a matrix of directions $V$ in the scaled quantities
    (P, r) that returns $J_d V$, the part of $J_s V$ that is the derivative of the discretization
    error (:func:`gnipy.control.identification.fit` estimates it by Richardson extrapolation
    from a rerun at h/2; None: no part).

    The rule (:mod:`gnipy.control.identification`'s docstring): with $J_s$ the Jacobian in the
    scaled quantities, its singular values $S_j$ and right singular vectors $v_j$, and $s$ the
    noise scale of one weighted residual (1 when `sigma_known`, else the reduced chi²'s root), the
    direction $v_j$ is *determined* when the part of $J_s v_j$ that the continuous model makes,
    $c_j = \\|J_s v_j - J_d v_j\\|$, exceeds both the noise and the discretization's part:
    $c_j > \\max(s, \\|J_d v_j\\|)$. A reported quantity is identifiable when it has no part along
    an exact null direction (below :data:`RCOND`, to :data:`IDENTIFIABLE_TOL`) and its part along
    the other undetermined directions, each weighted by its uncertainty
    $\\max(s, \\|J_d v_j\\|)/c_j$, is below its own size. The covariance is
    $s^2 \\phi_s (J_s^TJ_s)^+ \\phi_s^T$ over the determined directions; a quantity that is not
    identifiable has an infinite standard error and NaN covariance with the others, and the
    combinations of such quantities that the determined directions fix are returned
    (:class:`Combination`)."""
    Js = J * scale[None, :]
    finite = bool(np.all(np.isfinite(Js)))
    if not finite:  # a run that blew up at the estimate, or weights that overflow: no SVD to take
        Js = np.zeros_like(Js)
    U, S, Vt = np.linalg.svd(Js, full_matrices=False)
    rank = int(np.sum(S > RCOND * S[0])) if S.size and S[0] > 0 else 0
    dof = n_obs - rank
    reduced = chi2 / dof if dof > 0 else float("nan")
    s2 = 1.0 if sigma_known else reduced
    noise = math.sqrt(s2) if math.isfinite(s2) else 0.0
    Vr = Vt[:rank].T
    JdV = np.zeros((Js.shape[0], rank)) if discrete_part is None or not finite or not rank else np.asarray(
        discrete_part(Vr))
    if not np.all(np.isfinite(JdV)):
        JdV = np.zeros_like(JdV)
    dpart = np.linalg.norm(JdV, axis=0)
    cpart = np.linalg.norm(U[:, :rank] * S[None, :rank] - JdV, axis=0)
    limit = np.maximum(noise, dpart)
    keep = cpart > limit
    V = Vr[:, keep]
    pinv = (V / S[:rank][keep] ** 2) @ V.T
    phis = phi * scale[None, :]  # the reported quantities' derivatives with respect to z
    values = np.zeros(phi.shape[0]) if values is None else np.asarray(values, dtype=np.float64)
    out_scale = np.where(values != 0, np.abs(values), 1.0)
    norms = np.linalg.norm(phis, axis=1)
    exact = np.linalg.norm(phis @ Vt[rank:].T, axis=1) <= IDENTIFIABLE_TOL * np.maximum(norms, 1e-300)
    with np.errstate(divide="ignore"):
        weight = np.where(cpart[~keep] > 0, limit[~keep] / cpart[~keep], np.inf)
    along = np.abs(phis @ Vr[:, ~keep])
    spread = np.sqrt(np.sum(np.where(along > 0, (along * weight[None, :]) ** 2, 0.0), axis=1)) / out_scale
    identifiable = exact & (spread < 1.0)
    cov = s2 * phis @ pinv @ phis.T
    undetermined = np.concatenate([Vr[:, ~keep].T, Vt[rank:]], axis=0)
    combos = _combinations(phi, scale, undetermined, cov, identifiable, tuple(names), values) if finite else ()
    stderr, corr = _undetermined(cov, identifiable)
    return Uncertainties(stderr=stderr, covariance=cov, correlation=corr, identifiable=identifiable, rank=rank,
                         determined=int(keep.sum()), dof=dof, reduced_chi2=reduced, threshold=noise,
                         combinations=combos, finite=finite)


def _combinations(phi, scale, undetermined_vt, cov, identifiable, names, values) -> tuple:
    """The combinations of the quantities that are not identifiable which the determined
    directions fix: the coefficient vectors $c$ on those quantities with $c \\cdot w_j = 0$ for
    every undetermined direction $w_j = \\phi\\,(s \\odot v_j)$ (the change of the reported
    quantities along it), each scaled so that its largest coefficient is 1."""
    bad = np.flatnonzero(~identifiable)
    if bad.size < 2 or not names or not np.all(np.isfinite(cov)):
        return ()
    W = (phi @ (scale[:, None] * undetermined_vt.T))[bad]  # (|B|, undetermined)
    if W.shape[1] == 0 or not np.all(np.isfinite(W)):
        return ()
    _, sw, vt = np.linalg.svd(W.T, full_matrices=True)
    r = int(np.sum(sw > 1e-8 * max(sw[0], 1e-300))) if sw.size else 0
    out = []
    for c in vt[r:]:
        c = c / c[np.argmax(np.abs(c))]
        c[np.abs(c) < 1e-12] = 0.0
        full = np.zeros(phi.shape[0])
        full[bad] = c
        var = float(full @ cov @ full)
        out.append(Combination(coefficients={names[i]: float(x) for i, x in zip(bad, c) if x != 0.0},
                               value=float(full @ values), stderr=math.sqrt(max(var, 0.0))))
    return tuple(out)


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


def fit_notes(success: bool, solver_message: str, stats: Uncertainties, names, at_bound=None,
              discretization: float = 0.0) -> tuple[bool, list[str]]:
    """`(success, notes)`: whether the fit succeeded (the solver converged, the Jacobian at the
    estimate is finite and no estimate is at a bound) and how it ended, in words: the solver's
    message, the estimates at a bound, the quantities the data do not determine (and the
    combinations they do), no degrees of freedom left."""
    if not stats.finite:
        success = False
        solver_message += "; the Jacobian at the estimate is not finite (no uncertainties)"
    notes = [solver_message if success else f"the solver did not converge: {solver_message}"]
    if at_bound:
        success = False
        notes.append("at a bound: " + ", ".join(f"{n} = {b:g}" for n, b in at_bound.items())
                     + " (the data push the estimate out of the valid region: a quantity they do not determine, "
                     "or a model that does not fit them; the standard error there is not that of a minimum)")
    if not stats.identifiable.all():
        bad = [n for n, ok in zip(names, stats.identifiable) if not ok]
        why = "the noise" if not discretization or not math.isfinite(discretization) else (
            "the noise and the discretization error")
        text = (f"the data do not determine {', '.join(bad)} (infinite standard error: along some combination "
                f"of them the fit changes by less than {why})")
        if stats.combinations:
            text += "; they determine " + "; ".join(str(c) for c in stats.combinations)
        notes.append(text)
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
