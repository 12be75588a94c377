"""Parameter identification: :func:`fit` estimates a model's parameters and/or its initial
condition from observed trajectories, by nonlinear least squares through the simulation.

The model is simulated with :func:`gnipy.simulate` at the observation times (nodes
$t_0 + kh$ of the step grid: gnipy never interpolates between nodes), and the weighted residuals

$$r_{ij} = \\big(\\text{model}_j(t_i; \\theta) - y_{ij}\\big) / \\sigma_{ij}$$

of the observed variables (any coordinates and velocities; missing values as NaN) are minimized
over the estimated quantities $\\theta$ with optimistix's Levenberg–Marquardt method. The
simulation is differentiated by JAX (forward mode; the implicit steps by the implicit function
theorem), so the Jacobian is exact up to the steps' solver tolerance, not a finite difference.

**Uncertainties** come from the Jacobian $J$ of the weighted residuals at the estimate: the
covariance is $s^2 (J^TJ)^{-1}$, with $s^2 = \\chi^2/(n_{obs} - p)$ ($p$ the rank of $J$) when
the measurement errors are unknown (`sigma=None`: the residuals' own scatter estimates them) and
$s^2 = 1$ when `sigma` is given (then the reduced $\\chi^2$ tests the fit: about 1 for a model
that explains the data).
This is the usual linearization: valid when the errors are small enough for the model to be
nearly linear in $\\theta$ over a few standard errors.

**Initial velocities** must satisfy the constraints. An estimated `v0` is therefore a free
vector that is projected $\\mathbb{G}$-orthogonally onto the constraints (for the current
parameters and `q0`, :func:`gnipy.system.project_velocity`) at every evaluation; the reported
`v0` is the projected one. The directions the projection removes do not change the residuals
(they are null directions of $J$), so the covariance is formed with the pseudo-inverse of
$J^TJ$ (singular values below $10^{-10}$ of the largest dropped) and mapped to the reported
quantities (the parameters, `q0` and the projected `v0`) by the derivative of that map; it is the
same for every generalized inverse, because the dropped directions change none of them. A
quantity that the data cannot determine (e.g. the mass and the moment of inertia of the Chaplygin
sleigh separately: only their ratio enters the motion) has a reported direction in the null space
of $J$: its standard error is infinite and the result says so.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..extras import require
from ..errors import InputError, SolverFailure
from ..inputs import finite_number, real_array, real_number, require_float64, whole_number
from ..registry import get_model
from ..saveat import GRID_RTOL, SaveAt
from ..simulate import MIN_STEP_SIZE, simulate
from ..solution import Solution
from ..system import System, project_velocity
from .memory import check_fit_memory, memory_limit
from .observations import Observations, UnnamedObservations, as_observations, sigma_array
from .optimal_control import MAX_ITERATIONS

__all__ = ["fit", "FitResult", "Observations", "RCOND", "MAX_STEPS"]

#: Singular values of the scaled Jacobian below this fraction of the largest count as zero: the
#: directions the projection of `v0` removes (about 1e-16 of the largest), and quantities the
#: data cannot tell apart.
RCOND = 1e-10

#: The default of :func:`fit`'s `max_steps`: the most iterations of the solver.
MAX_STEPS = 200

#: A reported quantity is identifiable when its derivative lies in the row space of the Jacobian
#: to this relative tolerance.
IDENTIFIABLE_TOL = 1e-6


# ----------------------------------------------------------------------------------------------
# The least-squares problem
# ----------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _ModelBuild:
    """Build a zoo model from its estimated and fixed parameters (hashable: compiled fits are
    shared between calls of one model)."""

    name: str

    def __call__(self, params):
        spec = get_model(self.name)
        return spec.build(spec.resolve_params(params))

    def initial(self, params):
        return get_model(self.name).default_ic(dict(get_model(self.name).resolve_params(params)))


def _point(system: System, q0, R0):
    from ..spaces import Point

    x = jnp.asarray(q0, jnp.float64).reshape(system.n)
    if system.group is None:
        return x
    k = system.group.matrix_size
    return Point(x, jnp.eye(k) if R0 is None else jnp.asarray(R0, jnp.float64).reshape(k, k))


class _Problem(eqx.Module):
    """The weighted residuals of a fit as a function of the scaled estimated quantities `z`
    (`y = scale * z`: the parameters, then the estimated components of q0 and of the raw v0)."""

    system: Any  # a System whose parameters are not estimated, else None
    fixed: dict  # fixed parameters passed to the build (arrays)
    q0: jax.Array
    v0: jax.Array
    R0: Any
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
        system, q0, v0 = self.unpack(y)
        npar, nq = len(self.param_names), len(self.q_idx)
        out = [jnp.asarray(y[:npar + nq], jnp.float64)]
        if self.v_idx:
            vp = project_velocity(system.without_metadata(), _point(system, q0, self.R0), v0)
            out.append(vp[jnp.asarray(self.v_idx)])
        return jnp.concatenate(out)

    def initial_velocity(self, y):
        """The full projected v0 at `y`."""
        system, q0, v0 = self.unpack(y)
        return project_velocity(system.without_metadata(), _point(system, q0, self.R0), v0)

    def predict(self, y):
        """The model's values of the observed variables at the observation times, (T, k)."""
        system, q0, v0 = self.unpack(y)
        kw = {} if self.controls is None else {"controls": self.controls}
        sol = simulate(system, self.method, q0, v0, R0=self.R0, h=self.h, steps=self.steps,
                       saveat=SaveAt(ts=self.ts), t0=self.t0, project_v0=True, **kw)
        return jnp.stack([(sol.q if kind == "q" else sol.v)[:, i] for kind, i in self.columns], axis=1)

    def residuals(self, y, data):
        """The weighted residuals at the unscaled `y`, flattened (zero at missing values)."""
        values, weights = data
        return ((self.predict(y) - values) * weights).reshape(-1)

    def __call__(self, z, data):
        return self.residuals(self.scale * z, data)


@eqx.filter_jit
def _linearization(problem: _Problem, y, data):
    """The weighted residuals at `y` and their Jacobian (compiled once per problem structure):
    for solvers whose final state does not hold them."""
    jac, r = jax.jacfwd(lambda u: (problem.residuals(u, data),) * 2, has_aux=True)(y)
    return r, jac


@eqx.filter_jit
def _as_matrix(operator):
    """A lineax operator's matrix (the solver's Jacobian at its final point)."""
    return operator.as_matrix()


@eqx.filter_jit
def _reported(problem: _Problem, y):
    """The reported quantities at `y`, their derivative, and the projected v0."""
    return problem.outputs(y), jax.jacfwd(problem.outputs)(y), problem.initial_velocity(y)


def _final_linearization(out, problem: _Problem, y, data):
    """The weighted residuals and their Jacobian (in the unscaled quantities) at the solver's
    final point: from the Gauss–Newton family's final state when it holds them (its last
    accepted point is the returned one), else computed anew."""
    import lineax as lx

    info = getattr(out.state, "f_info", None)
    jac = getattr(info, "jac", None)
    if isinstance(jac, lx.AbstractLinearOperator) and getattr(info, "residual", None) is not None:
        return np.asarray(info.residual), np.asarray(_as_matrix(jac)) / np.asarray(problem.scale)[None, :]
    return tuple(np.asarray(a) for a in _linearization(problem, jnp.asarray(y), data))


#: The progress report of the fit running now (a callable `(iteration, chi2)`, or None): the
#: compiled solver always calls :func:`_verbose`, which forwards here, so that fits with and
#: without progress share one compiled program (one process reports one fit's progress at a time:
#: fits run in parallel threads would share it).
_REPORT: list = [None]


def _report(k, loss):
    fn = _REPORT[0]
    if fn is not None:
        fn(int(k), float(2 * loss))


def _verbose(**kw):
    """optimistix's `verbose` hook: the iteration and the loss, sent to the host."""
    jax.debug.callback(_report, kw["num_steps"][1], kw["loss_this_step"][1])


def _progress_reporter(progress):
    """The `(iteration, chi2)` callable of `progress=`, or None."""
    if progress is None or progress is False:
        return None
    if progress is True:
        require("rich", extra="cli", what="progress display")
        from rich.console import Console

        console = Console(stderr=True)

        def report(k, chi2):
            console.print(f"fit: iteration {k}, chi2 = {chi2:.6g}")

        return report
    if callable(progress):
        return progress
    raise InputError(f"progress: expected True, False or a callable(iteration, chi2), got {progress!r}")


# ----------------------------------------------------------------------------------------------
# The result
# ----------------------------------------------------------------------------------------------
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
# fit
# ----------------------------------------------------------------------------------------------
def _vector(name, x, n):
    a = real_array(name, x, f"{n} real numbers").reshape(-1)
    if a.shape != (n,):
        raise InputError(f"{name}: expected {n} numbers, got {a.size}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: contains NaN or infinite values")
    return a


def _components(name: str, which, names: tuple[str, ...]) -> tuple[int, ...]:
    """The indices of the components `which` (names or indices, or all for True/"all") of `names`."""
    if which is True or (isinstance(which, str) and which == "all"):
        return tuple(range(len(names)))
    if isinstance(which, (str, int, np.integer)):
        which = (which,)
    idx = []
    for w in which:
        if isinstance(w, str):
            if w not in names:
                raise InputError(f"initial: unknown component {w!r} of {name} (known: {', '.join(names)})")
            idx.append(names.index(w))
        elif isinstance(w, (int, np.integer)) and not isinstance(w, bool) and -len(names) <= w < len(names):
            idx.append(int(w) % len(names))
        else:
            raise InputError(f"initial: {w!r} is not a component of {name} ({len(names)} components: "
                             f"{', '.join(names)})")
    if len(set(idx)) != len(idx):
        raise InputError(f"initial: a component of {name} is named twice")
    return tuple(sorted(idx))


def _initial_selection(initial, coordinates, velocities):
    if initial is None:
        initial = ()
    if isinstance(initial, str):
        initial = (initial,)
    if isinstance(initial, Mapping):
        items = dict(initial)
    else:
        try:
            items = {k: True for k in initial}
        except TypeError:
            raise InputError(f"initial: expected a subset of ('q0', 'v0') or a mapping, got {initial!r}") from None
    bad = [k for k in items if k not in ("q0", "v0")]
    if bad:
        raise InputError(f"initial: unknown entries {bad} (estimate 'q0' and/or 'v0', or e.g. {{'q0': ['x', 'y']}})")
    q_idx = _components("q0", items["q0"], coordinates) if "q0" in items else ()
    v_idx = _components("v0", items["v0"], velocities) if "v0" in items else ()
    return q_idx, v_idx


def _columns(variables, coordinates, velocities):
    cols = []
    for name in variables:
        if name in coordinates:
            cols.append(("q", coordinates.index(name)))
        elif name in velocities:
            cols.append(("v", velocities.index(name)))
        else:
            raise InputError(f"observations: unknown variable {name!r} (coordinates: {', '.join(coordinates)}; "
                             f"velocities: {', '.join(velocities)})")
    return tuple(cols)


def _grid(times, t0: float, h: float) -> tuple[int, ...]:
    """The step index of each observation time; InputError naming `observations` and the time
    for a time off the grid, before t0, or out of order."""
    ks = []
    for t in times:
        k = (float(t) - t0) / h
        kr = round(k)
        if abs(k - kr) > GRID_RTOL * max(1.0, abs(k)):
            raise InputError(
                f"observations: time {float(t)!r} is not a node t0 + k h of the step grid (t0 = {t0!r}, h = {h!r}: "
                f"it lies between k = {math.floor(k)} and {math.floor(k) + 1}); gnipy compares nodes and does not "
                "interpolate: choose h dividing the observation times"
            )
        if kr < 0:
            raise InputError(f"observations: time {float(t)!r} lies before t0 = {t0!r}")
        ks.append(int(kr))
    if any(b <= a for a, b in zip(ks, ks[1:])):
        i = next(i for i, (a, b) in enumerate(zip(ks, ks[1:])) if b <= a)
        raise InputError(f"observations: the times must be strictly increasing along the run; time "
                         f"{float(times[i + 1])!r} follows {float(times[i])!r}")
    if ks[-1] < 1:
        raise InputError("observations: every observation is at t0; observe at least one later node")
    return tuple(ks)


def _check_method(method) -> None:
    """A method's name (known), an integrator or None; `MethodError` otherwise, before the method
    is put in the compiled problem (where another object fails obscurely)."""
    from ..errors import MethodError
    from ..integrators.base import Integrator
    from ..methods import get_method
    from ..reference import ContinuousReference

    if method is None or isinstance(method, Integrator):
        return
    if isinstance(method, str):
        method = get_method(method)
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference cannot be differentiated or traced; use an integrator")
    if not isinstance(method, Integrator):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")


_TRACE_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                 jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError)


def fit(
    system,
    observations,
    *,
    params: Mapping[str, float] | None = None,
    fixed: Mapping[str, float] | None = None,
    initial=(),
    method=None,
    h: float,
    t0: float = 0.0,
    q0=None,
    v0=None,
    R0=None,
    sigma=None,
    controls=None,
    solver=None,
    max_steps: int = MAX_STEPS,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    progress=False,
    max_bytes="auto",
) -> FitResult:
    """Estimate model parameters and/or the initial condition from observed trajectories.

    Minimizes the sum of squared weighted residuals between the observations and a simulation
    (:func:`gnipy.simulate` with `method` and step `h`, from `t0`) over the estimated quantities,
    with optimistix's Levenberg–Marquardt method; the standard errors come from the Jacobian at
    the estimate (see the module docstring for the formulas and the treatment of `v0`).

    Arguments:
        system: a zoo model's name (built with the estimated `params` and the `fixed` ones, the
            others at their defaults); or a function `build(params) -> System` of a dict of the
            parameters (estimated and fixed, as JAX scalars: the System's functions must use them
            as arrays, e.g. `jax.tree_util.Partial` arguments); or a :class:`~gnipy.System`
            when only the initial condition is estimated.
        observations: an :class:`Observations` (any coordinates and velocities, missing values
            as NaN, optional `sigma`); a tuple `(times, values, variables)`, or `(times, values)`
            with one column per coordinate; a :class:`~gnipy.Solution` or an `xarray.Dataset`
            or the path of a netCDF file written by gnipy (every coordinate at the saved times;
            :meth:`Observations.from_solution` / :meth:`Observations.from_dataset` take some
            variables only). Every time must be a node $t_0 + kh$ after `t0`, in increasing order.
        params: the parameters to estimate, name -> initial guess.
        fixed: parameters held at given values (default: a model's defaults; for a `build`
            function, these are passed to it beside the estimated ones).
        initial: which parts of the initial condition to estimate: `"q0"` and/or `"v0"` (every
            component), or a mapping to some components by name or index, e.g.
            `{"q0": ["x", "y"], "v0": "all"}`. `q0`/`v0` give the initial guesses.
        method: the integrator (object or name; default: the model's default method).
        h: the step size.
        t0: the time of the initial condition.
        q0, v0: the initial condition (guesses where estimated, else held). Default: for a model,
            its documented initial condition, following the parameters where it depends on them
            (`ModelSpec.default_ic`, when that function can be evaluated on JAX values; else its
            value at the initial guess); for a `build` function or a System, the System's
            `defaults` at the initial guess. `v0` is projected onto the constraints at every
            evaluation (the constraints may depend on the estimated quantities).
        R0: the initial orientation on $\\mathbb{R}^n \\times G$ (held; default the system's).
        sigma: the standard deviations of the measurement errors: a number, one per observed
            variable, or one per value (T, k); not together with `Observations.sigma`. With
            `sigma`, the covariance is $(J^TJ)^{-1}$ and the reduced chi² tests the fit; without,
            the residuals are unweighted and the covariance is scaled by the reduced chi².
        controls: passed on to :func:`gnipy.simulate` (`controls=`) when given.
        solver: an optimistix least-squares solver (default
            `optimistix.LevenbergMarquardt(rtol, atol)`). The estimated quantities are scaled
            by their initial guesses (by 1 where a guess is 0) before the solver sees them.
        max_steps: the most solver iterations.
        rtol, atol: the default solver's tolerances (on the scaled quantities and on the
            residuals).
        progress: `True` prints the iteration and chi² as the solver advances; a callable is
            called as `progress(iteration, chi2)` instead (rejected trial steps included).
        max_bytes: the most memory the fit may need, estimated before anything is compiled
            (:func:`gnipy.control.memory.fit_memory`: the fitted run holds every node from `t0` to
            the last observation): `"auto"` (the default) the smaller of 8 GiB and half the
            physical memory, a number of bytes, or None for no bound.

    Returns:
        A :class:`FitResult`: the estimates, standard errors, covariance and correlation, chi²
        and degrees of freedom, the fitted Solution, and whether the solver converged
        (`success`, `message`, `iterations`; a fit that did not converge is returned, not
        raised, so that it can be inspected).

    Raises:
        InputError: bad arguments (the message names the argument): unknown parameters or
            variables, observation times off the step grid, shapes that do not match, too few
            observations, a model that cannot be built from traced parameter values, values that
            are not numbers (a string or a boolean is not one), or a fit estimated beyond
            `max_bytes` (naming `observations/h`).
        SolverFailure: a simulation failed during the fit (a step did not converge at some
            trial values of the estimated quantities; `step`, `time` and `residual` are then
            unknown: -1 and NaN). Better initial guesses or a smaller `h` help.
    """
    import optimistix as optx

    start = time.perf_counter()
    require_float64()
    h = finite_number("h", h)
    if h == 0:
        raise InputError("h: must be nonzero")
    if abs(h) < MIN_STEP_SIZE:
        raise InputError(f"h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision")
    t0 = finite_number("t0", t0)
    if params is None:
        params = {}
    if not isinstance(params, Mapping):
        raise InputError(f"params: expected a dict name -> initial guess, got {type(params).__name__}")
    if fixed is not None and not isinstance(fixed, Mapping):
        raise InputError(f"fixed: expected a dict name -> value, got {type(fixed).__name__}")
    fixed = dict(fixed or {})
    for arg, table in (("params", params), ("fixed", fixed)):
        bad = [k for k in table if not isinstance(k, str)]
        if bad:
            raise InputError(f"{arg}: parameter names must be strings, got {bad[0]!r}")
    param_names = tuple(params)
    guesses = [finite_number(f"params: {k!r}", v) for k, v in params.items()]
    for k, v in fixed.items():  # before a model reads them (its own check would take "1" or True)
        if not isinstance(v, jax.core.Tracer):
            finite_number(f"fixed: {k!r}", v)
    both = sorted(set(param_names) & set(fixed))
    if both:
        raise InputError(f"fixed: {both} also in params (a parameter is either estimated or fixed)")
    max_steps = whole_number("max_steps", max_steps, 1, MAX_ITERATIONS)
    rtol, atol = real_number("rtol", rtol, lower=0.0), real_number("atol", atol, lower=0.0)
    bound = memory_limit(max_bytes)
    reporter = _progress_reporter(progress)
    _check_method(method)

    # the system, and how it is built from the parameters
    follow_ic = False
    given_system = None
    if isinstance(system, str):
        spec = get_model(system)
        build = _ModelBuild(spec.name)
        spec.resolve_params({**fixed, **dict(zip(param_names, guesses))})  # unknown names, bad values
        concrete = build({**fixed, **dict(zip(param_names, guesses))})
        if spec.default_ic is not None and (q0 is None or v0 is None) and param_names:
            try:
                jax.eval_shape(build.initial, {**fixed, **{k: jnp.float64(g) for k, g in zip(param_names, guesses)}})
                follow_ic = True
            except Exception:  # e.g. float() of a traced value: the default at the initial guess
                follow_ic = False
    elif isinstance(system, System):
        if param_names or fixed:
            raise InputError("params: a System's parameters cannot be estimated here; pass a model name or a "
                             "build(params) function")
        build, concrete, given_system = None, system, system
    elif callable(system):
        build = system
        try:
            concrete = build({**{k: jnp.float64(v) for k, v in fixed.items()},
                              **{k: jnp.float64(g) for k, g in zip(param_names, guesses)}})
        except InputError:
            raise
        except Exception as e:
            raise InputError(f"system: build(params) failed at the initial guess: {type(e).__name__}: {e}") from e
        if not isinstance(concrete, System):
            raise InputError(f"system: build(params) must return a gnipy.System, got {type(concrete).__name__}")
    else:
        raise InputError(f"system: expected a model name, a build(params) function or a gnipy.System, "
                         f"got {type(system).__name__}")
    coords, vels = concrete.coordinates, concrete.velocities

    # the initial condition: given, or the defaults
    defaults = concrete.defaults
    if (q0 is None or v0 is None) and defaults is None:
        raise InputError(f"q0/v0: the system {concrete.name!r} has no default initial condition; give q0 and v0")
    q0v = _vector("q0", defaults[0] if q0 is None else q0, concrete.n)
    v0v = _vector("v0", defaults[1] if v0 is None else v0, concrete.dim)
    if R0 is None and defaults is not None and len(defaults) > 2 and defaults[2] is not None:
        R0 = defaults[2]
    b0 = concrete.initial_point(q0v, R0)
    R0a = None if concrete.group is None else np.asarray(b0.R)
    if follow_ic and (q0 is not None or v0 is not None):
        follow_ic = False
    q_idx, v_idx = _initial_selection(initial, coords, vels)
    names = (param_names + tuple(f"q0.{coords[i]}" for i in q_idx) + tuple(f"v0.{vels[i]}" for i in v_idx))
    if not names:
        raise InputError("params/initial: nothing to estimate; name parameters (params=) and/or parts of the "
                         "initial condition (initial=)")
    y0 = np.concatenate([np.asarray(guesses, dtype=np.float64), q0v[list(q_idx)], v0v[list(v_idx)]])

    # the observations, on the grid
    obs = as_observations(observations)
    if isinstance(obs, UnnamedObservations):
        obs = obs.named(coords)
    columns = _columns(obs.variables, coords, vels)
    ks = _grid(obs.times, t0, h)
    # before anything is compiled: the fitted run holds every node of the span
    check_fit_memory(concrete, ks[-1], obs.values.size, len(names), t0=t0, t_last=float(obs.times[-1]), h=h,
                     max_bytes=bound)
    if sigma is not None and obs.sigma is not None:
        raise InputError("sigma: given both here and in the observations; give one")
    sig = obs.sigma if sigma is None else sigma_array(sigma, obs.values.shape, "sigma")
    sigma_known = sig is not None
    mask = np.isfinite(obs.values)
    n_obs = int(mask.sum())
    if n_obs < len(names):
        raise InputError(f"observations: {n_obs} observed values cannot determine {len(names)} estimated quantities")
    weights = np.where(mask, 1.0 if sig is None else 1.0 / np.where(mask, sig, 1.0), 0.0)
    data = (jnp.asarray(np.where(mask, obs.values, 0.0)), jnp.asarray(weights))

    scale = np.where(y0 != 0, np.abs(y0), 1.0)
    problem = _Problem(
        system=None if given_system is None else given_system.without_metadata(),
        fixed={k: jnp.asarray(finite_number(f"fixed: {k!r}", v), jnp.float64) for k, v in fixed.items()},
        q0=jnp.asarray(q0v), v0=jnp.asarray(v0v), R0=None if R0a is None else jnp.asarray(R0a),
        scale=jnp.asarray(scale), controls=controls, build=build, method=method, param_names=param_names,
        q_idx=q_idx, v_idx=v_idx, follow_ic=follow_ic, h=h, steps=ks[-1], t0=t0,
        ts=tuple(float(t0 + k * h) for k in ks), columns=columns,
    )
    if solver is None:
        solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, verbose=_verbose)
    elif reporter is not None:
        if not hasattr(solver, "verbose"):
            raise InputError("progress: this solver has no `verbose` hook to report progress through")
        solver = eqx.tree_at(lambda s: s.verbose, solver, _verbose)

    _REPORT[0] = reporter
    try:
        out = optx.least_squares(problem, solver, jnp.asarray(y0 / scale), data, max_steps=int(max_steps),
                                 throw=False)
        z = np.asarray(out.value)
    except InputError:
        raise
    except _TRACE_ERRORS as e:
        raise InputError(
            f"params: the system cannot be built and simulated from traced parameter values (the model's functions "
            f"convert a parameter to a Python number); {type(e).__name__}: {str(e).splitlines()[0]}"
        ) from e
    except Exception as e:  # a failed step raises from the compiled solve (eqx.error_if)
        if "step failed" not in str(e):
            raise
        cause = next((line.strip() for line in str(e).splitlines() if "step failed" in line), "")
        cause = cause.split("Error: ", 1)[-1]
        raise SolverFailure(
            f"fit: a simulation failed at some trial values of {', '.join(names)} ({cause}); start from better "
            "initial guesses or use a smaller h", step=-1, time=float("nan"), residual=float("nan")) from e
    finally:
        _REPORT[0] = None
    y = z * scale
    iterations = int(out.stats["num_steps"])
    success = bool(out.result == optx.RESULTS.successful)
    solver_message = "the solver converged" if success else str(optx.RESULTS[out.result])

    # the linearization at the estimate: residuals, Jacobian, the reported quantities
    try:
        r, J = _final_linearization(out, problem, y, data)
    except Exception as e:
        if "step failed" not in str(e):
            raise
        raise SolverFailure("fit: the simulation at the estimate failed", step=-1, time=float("nan"),
                            residual=float("nan")) from e
    outputs, phi, v0p = (np.asarray(a) for a in _reported(problem, jnp.asarray(y)))
    chi2 = float(np.sum(r**2))
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

    if not finite:
        success = False
        solver_message += "; the Jacobian at the estimate is not finite (no uncertainties)"
    notes = [solver_message if success else f"the solver did not converge: {solver_message}"]
    if not identifiable.all():
        bad = [n for n, ok in zip(names, identifiable) if not ok]
        notes.append(f"the data do not determine {', '.join(bad)} (a null direction of the Jacobian: infinite "
                     "standard error)")
    if dof <= 0:
        notes.append("no degrees of freedom are left: the standard errors cannot be estimated (give sigma or more "
                     "observations)")

    # the fitted run: every node, at the estimate
    system_fit, q0_fit, _ = problem.unpack(jnp.asarray(y))
    if given_system is None:
        npar = len(param_names)
        estimated = {k: float(v) for k, v in zip(param_names, y[:npar])}
        system_fit = build({**fixed, **estimated}) if isinstance(build, _ModelBuild) else build(
            {**{k: jnp.float64(v) for k, v in fixed.items()}, **{k: jnp.float64(v) for k, v in estimated.items()}})
    q0_fit = np.asarray(q0_fit)
    kw = {} if controls is None else {"controls": controls}
    try:
        solution = simulate(system_fit, method, q0_fit, v0p, R0=R0a, h=h, steps=ks[-1], t0=t0, project_v0=True,
                            throw=False, **kw)
    except InputError as e:
        at = ", ".join(f"{n} = {x:.6g}" for n, x in zip(names, outputs))
        raise InputError(f"params: the fitted system is not valid at the estimate ({at}): {e}") from e
    model = np.full(obs.values.shape, np.nan)
    got = np.asarray(solution.q), np.asarray(solution.v)
    for j, (kind, i) in enumerate(columns):
        rows = [k for k in ks if k < got[0].shape[0]]
        model[: len(rows), j] = got[0 if kind == "q" else 1][rows, i]
    residuals = np.where(mask, model - obs.values, np.nan)
    if not solution.success:
        notes.append(f"the fitted run failed: {solution.message}")

    return FitResult(
        names=names, values=outputs, stderr=stderr, covariance=cov, correlation=corr, identifiable=identifiable,
        params={k: float(v) for k, v in zip(param_names, outputs)}, q0=q0_fit, v0=v0p, solution=solution,
        observations=obs, residuals=residuals, raw=y, jacobian=J, chi2=chi2, n_obs=n_obs, rank=rank, dof=dof,
        reduced_chi2=reduced, sigma_known=sigma_known, success=bool(success), message="; ".join(notes),
        iterations=iterations, initial_guess=y0, method=solution.method, h=h, t0=t0,
        wall_time=time.perf_counter() - start, _problem=problem, _data=data,
    )
