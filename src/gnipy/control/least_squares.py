"""The least-squares problem of a fit (:func:`gnipy.fit`): the weighted residuals as a function of
the solver's internal variables (:class:`LeastSquares`), the moves of `v0` onto the constraints
(:func:`admissible_velocity`), the linearization at the estimate, and the estimate of the
discretization error that the identifiability rule weighs (:func:`discretization`). The
formulas are in :mod:`gnipy.control.identification`'s docstring."""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..saveat import SaveAt
from ..simulate import simulate
from ..system import System
from .bounds import bounded_quantities
from .fit_result import RCOND

__all__ = ["LeastSquares", "initial_point", "admissible_velocity", "linearization", "operator_matrix", "reported",
           "final_linearization", "gauss_newton_step", "residuals_at", "discretization", "DIFFERENCE_STEP"]


def initial_point(system: System, q0, R0):
    from ..spaces import Point

    x = jnp.asarray(q0, jnp.float64).reshape(system.n)
    if system.group is None:
        return x
    k = system.group.matrix_size
    return Point(x, jnp.eye(k) if R0 is None else jnp.asarray(R0, jnp.float64).reshape(k, k))


class LeastSquares(eqx.Module):
    """The weighted residuals of a fit as a function of the solver's internal variables `z`,
    mapped onto the estimated quantities `y` inside their bounds (:mod:`gnipy.control.bounds`;
    `y = scale * z` for an unbounded one): the parameters, then the estimated components of q0
    and of the raw v0."""

    system: Any  # a System whose parameters are not estimated, else None
    fixed: dict  # fixed parameters passed to the build (arrays)
    q0: jax.Array
    v0: jax.Array
    R0: Any
    lower: jax.Array  # the bounds and scales of the estimated quantities (gnipy.control.bounds)
    upper: jax.Array
    scale: jax.Array
    controls: Any
    build: Any = eqx.field(static=True)
    method: Any
    param_names: tuple = eqx.field(static=True)
    q_idx: tuple = eqx.field(static=True)
    v_idx: tuple = eqx.field(static=True)
    follow_ic: bool = eqx.field(static=True)
    h: float = eqx.field(static=True)
    steps: int = eqx.field(static=True)
    t0: float = eqx.field(static=True)
    ts: tuple = eqx.field(static=True)
    columns: tuple = eqx.field(static=True)
    kinds: tuple = eqx.field(static=True)  # which transform onto its bounds each quantity takes

    def unpack(self, y):
        """`(system, q0, v0 before projection)` at the unscaled estimate `y`."""
        y = jnp.asarray(y, jnp.float64)
        npar, nq = len(self.param_names), len(self.q_idx)
        params = {**self.fixed, **{name: y[i] for i, name in enumerate(self.param_names)}}
        system = self.system if self.system is not None else self.build(params)
        q0, v0 = self.q0, self.v0
        if self.follow_ic:
            q0, v0 = (jnp.asarray(a, jnp.float64).reshape(-1) for a in self.build.initial(params))
        if nq:
            q0 = q0.at[jnp.asarray(self.q_idx)].set(y[npar:npar + nq])
        if self.v_idx:
            v0 = v0.at[jnp.asarray(self.v_idx)].set(y[npar + nq:])
        return system, q0, v0

    def outputs(self, y):
        """The reported quantities at `y`: the parameters, the estimated components of q0 and
        those of the projected v0."""
        npar, nq = len(self.param_names), len(self.q_idx)
        out = [jnp.asarray(y[:npar + nq], jnp.float64)]
        if self.v_idx:
            out.append(self.initial_velocity(y)[jnp.asarray(self.v_idx)])
        return jnp.concatenate(out)

    def initial_velocity(self, y):
        """The full v0 at `y`, on the constraints of the system at `y` (:func:`admissible_velocity`)."""
        system, q0, v0 = self.unpack(y)
        return admissible_velocity(system.without_metadata(), initial_point(system, q0, self.R0), v0)

    def predict(self, y):
        """The model's values of the observed variables at the observation times, (T, k)."""
        system, q0, _ = self.unpack(y)
        v0 = self.initial_velocity(y)
        kw = {} if self.controls is None else {"controls": self.controls}
        sol = simulate(system, self.method, q0, v0, R0=self.R0, h=self.h, steps=self.steps,
                       saveat=SaveAt(ts=self.ts), t0=self.t0, project_v0=True, **kw)
        return jnp.stack([(sol.q if kind == "q" else sol.v)[:, i] for kind, i in self.columns], axis=1)

    def residuals(self, y, data):
        """The weighted residuals at the unscaled `y`, flattened (zero at missing values)."""
        values, weights = data
        return ((self.predict(y) - values) * weights).reshape(-1)

    def quantities(self, z):
        """The estimated quantities `y` at the solver's internal variables `z`."""
        return bounded_quantities(self.kinds, self.lower, self.upper, self.scale, z)

    def __call__(self, z, data):
        return self.residuals(self.quantities(z), data)


def admissible_velocity(system: System, b, v):
    """`v` moved onto the velocity constraints $\\mu(b)(v - Y(b)) = 0$ by the smallest change of its
    components, $v - \\mu^T(\\mu\\mu^T)^{-1}\\mu(v - Y)$: the identity on a velocity that satisfies
    them. Unlike the $\\mathbb{G}$-orthogonal projection, it does not depend on the masses and
    moments of inertia, so a held `v0` does not make the fit depend on them where the motion does
    not (it depends on the constraints' parameters, as the constraints do)."""
    mu = system.mu(b)
    if mu.shape[0] == 0:
        return v
    return v - mu.T @ jnp.linalg.solve(mu @ mu.T, mu @ (v - system.Y(b)))


@jit
def linearization(problem: LeastSquares, y, data):
    """The weighted residuals at `y` and their Jacobian (compiled once per problem structure):
    for solvers whose final state does not hold them."""
    jac, r = jax.jacfwd(lambda u: (problem.residuals(u, data),) * 2, has_aux=True)(y)
    return r, jac


@jit
def operator_matrix(operator):
    """A lineax operator's matrix (the solver's Jacobian at its final point)."""
    return operator.as_matrix()


@jit
def reported(problem: LeastSquares, y):
    """The reported quantities at `y`, their derivative, and the projected v0."""
    return problem.outputs(y), jax.jacfwd(problem.outputs)(y), problem.initial_velocity(y)


def final_linearization(out, problem: LeastSquares, y, dydz, data):
    """The weighted residuals and their Jacobian (in the estimated quantities `y`) at the solver's
    final point: from the Gauss–Newton family's final state when it holds them (its last
    accepted point is the returned one; the Jacobian in the internal variables divided by
    `dydz`), else, and for a quantity at a bound (`dydz` about 0), computed anew."""
    import lineax as lx

    info = getattr(out.state, "f_info", None)
    jac = getattr(info, "jac", None)
    usable = np.all(np.abs(dydz) > 1e-8 * np.asarray(problem.scale))
    if usable and isinstance(jac, lx.AbstractLinearOperator) and getattr(info, "residual", None) is not None:
        return np.asarray(info.residual), np.asarray(operator_matrix(jac)) / dydz[None, :]
    return tuple(np.asarray(a) for a in linearization(problem, jnp.asarray(y), data))


def gauss_newton_step(r, J, scale):
    """The unconstrained Gauss–Newton step from the estimate (minimum norm in the scaled
    quantities, singular values below RCOND dropped): where it crosses a bound, the data push the
    estimate beyond it. Zero where the Jacobian is not finite."""
    Js = J * scale[None, :]
    if not (np.all(np.isfinite(Js)) and np.all(np.isfinite(r))):
        return np.zeros_like(scale)
    return -scale * np.linalg.lstsq(Js, r, rcond=RCOND)[0]


#: The step of the central differences along the Jacobian's directions at h/2, in the scaled
#: quantities (errors about 1e-10 of the derivative from truncation and round-off together).
DIFFERENCE_STEP = 1e-5


@jit
def residuals_at(problem: LeastSquares, y, data):
    """The weighted residuals at `y` (compiled once per problem structure)."""
    return problem.residuals(y, data)


def discretization(problem: LeastSquares, y, r, Js, scale, method: str, data):
    """`(d, discrete_part)`: the size of the weighted discretization error of the predictions at
    the estimate `y`, and the function $V \\mapsto J_d V$ (the discretization error's part of the
    scaled Jacobian `Js` along the directions $V$), both by Richardson extrapolation against the
    problem rerun at h/2 (controls given per step held over both half steps):
    $e = (r_h - r_{h/2})\\,2^p/(2^p - 1)$ with $p$ the method's order and `r` the residuals at h,
    and $J_d v = (J_s v - J_{h/2} v)\\,2^p/(2^p - 1)$ with $J_{h/2} v$ by central differences.
    `(NaN, None)` when the rerun fails."""
    from ..methods import get_method

    try:
        order = int(getattr(get_method(method), "order", 1) or 1)
    except Exception:  # a method object that is not in the table: the most cautious factor
        order = 1
    factor = 2.0**order / (2.0**order - 1.0)
    controls = problem.controls
    if controls is not None and not (callable(controls) and not hasattr(controls, "shape")):
        controls = jnp.repeat(jnp.asarray(controls), 2, axis=0)
    half = dataclasses.replace(problem, h=problem.h / 2, steps=2 * problem.steps, controls=controls)

    def residuals(u):
        return np.asarray(residuals_at(half, jnp.asarray(u), data))

    try:
        r_half = residuals(y)
    except Exception:  # a failed step at h/2 (eqx.error_if), or a model that refuses it
        return float("nan"), None
    if not np.all(np.isfinite(r_half)):
        return float("nan"), None

    def discrete_part(V):
        cols = []
        for v in np.asarray(V).T:
            dy = DIFFERENCE_STEP * scale * v
            jv_half = (residuals(y + dy) - residuals(y - dy)) / (2 * DIFFERENCE_STEP)
            cols.append((Js @ v - jv_half) * factor)
        return np.stack(cols, axis=1) if cols else np.zeros((Js.shape[0], 0))

    return float(np.linalg.norm((np.asarray(r) - r_half) * factor)), discrete_part
