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

import time
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..errors import InputError, SolverFailure
from ..inputs import finite_number, real_number, require_float64, whole_number
from ..saveat import SaveAt
from ..simulate import simulate
from ..system import System, project_velocity
from .control_arguments import MAX_ITERATIONS
from .fit_arguments import (
    FitData,
    FitModel,
    FitStart,
    ModelBuild,
    check_fit_method,
    fit_data,
    fit_model,
    fit_start,
    parameter_tables,
    progress_reporter,
    step_grid,
)
from .fit_result import IDENTIFIABLE_TOL, RCOND, FitResult, fit_notes, observed_residuals, uncertainties  # noqa: F401
from .memory import memory_limit
from .observations import Observations

__all__ = ["fit", "FitResult", "Observations", "RCOND", "MAX_STEPS"]

#: The default of :func:`fit`'s `max_steps`: the most iterations of the solver.
MAX_STEPS = 200


# ----------------------------------------------------------------------------------------------
# The least-squares problem
# ----------------------------------------------------------------------------------------------
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


@jit
def _linearization(problem: _Problem, y, data):
    """The weighted residuals at `y` and their Jacobian (compiled once per problem structure):
    for solvers whose final state does not hold them."""
    jac, r = jax.jacfwd(lambda u: (problem.residuals(u, data),) * 2, has_aux=True)(y)
    return r, jac


@jit
def _as_matrix(operator):
    """A lineax operator's matrix (the solver's Jacobian at its final point)."""
    return operator.as_matrix()


@jit
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
        system: a zoo model's name, or the user's system as `"FILE.py:NAME"` / `"module:NAME"`
            (:func:`gnipy.get_model`), built with the estimated `params` and the `fixed` ones, the
            others at their defaults; or a function `build(params) -> System` of a dict of the
            parameters (estimated and fixed, as JAX scalars: the System's functions must use them
            as arrays, e.g. as its `args`); or a :class:`~gnipy.System`: its named parameters
            (`args`) are estimated in place (`system.with_args`, no rebuilding), else only the
            initial condition is.
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
    start = time.perf_counter()
    require_float64()
    h, t0 = step_grid(h, t0)
    param_names, guesses, fixed = parameter_tables(params, fixed)
    max_steps = whole_number("max_steps", max_steps, 1, MAX_ITERATIONS)
    rtol, atol = real_number("rtol", rtol, lower=0.0), real_number("atol", atol, lower=0.0)
    bound = memory_limit(max_bytes)
    reporter = progress_reporter(progress)
    check_fit_method(method)
    model = fit_model(system, param_names, guesses, fixed, q0, v0)
    begin = fit_start(model, q0, v0, R0, initial, param_names, guesses)
    data = fit_data(observations, model.system, t0, h, sigma, len(begin.names), bound)

    # the least-squares problem in the scaled quantities, solved
    scale = np.where(begin.y0 != 0, np.abs(begin.y0), 1.0)
    problem = _problem(model, begin, data, fixed, param_names, scale, controls, method, h, t0)
    solver = _least_squares_solver(solver, rtol, atol, reporter)
    out, z = _solve(problem, solver, begin.y0 / scale, data.arrays, max_steps, reporter, begin.names)
    y = z * scale
    iterations, success, solver_message = _solver_outcome(out)

    # the linearization at the estimate: residuals, Jacobian, the reported quantities
    r, J = _linearization_at_estimate(out, problem, y, data.arrays)
    outputs, phi, v0p = (np.asarray(a) for a in _reported(problem, jnp.asarray(y)))
    chi2 = float(np.sum(r**2))
    stats = uncertainties(J, phi, scale, chi2, data.n_obs, data.sigma_known)
    success, notes = fit_notes(success, solver_message, stats, begin.names)

    # the fitted run: every node, at the estimate
    q0_fit, solution = _fitted_run(problem, model, begin, y, fixed, v0p, outputs)
    residuals = observed_residuals(solution, data.columns, data.steps, data.observations, data.mask)
    if not solution.success:
        notes.append(f"the fitted run failed: {solution.message}")

    return FitResult(
        names=begin.names, values=outputs, stderr=stats.stderr, covariance=stats.covariance,
        correlation=stats.correlation, identifiable=stats.identifiable,
        params={k: float(v) for k, v in zip(param_names, outputs)}, q0=q0_fit, v0=v0p, solution=solution,
        observations=data.observations, residuals=residuals, raw=y, jacobian=J, chi2=chi2, n_obs=data.n_obs,
        rank=stats.rank, dof=stats.dof, reduced_chi2=stats.reduced_chi2, sigma_known=data.sigma_known,
        success=bool(success), message="; ".join(notes), iterations=iterations, initial_guess=begin.y0,
        method=solution.method, h=h, t0=t0, wall_time=time.perf_counter() - start, _problem=problem,
        _data=data.arrays,
    )


# ----------------------------------------------------------------------------------------------
# The steps of fit
# ----------------------------------------------------------------------------------------------
def _problem(model: FitModel, begin: FitStart, data: FitData, fixed, param_names, scale, controls, method, h,
             t0) -> _Problem:
    """The least-squares problem of a fit (in the quantities scaled by `scale`)."""
    ks = data.steps
    return _Problem(
        system=None if model.given is None else model.given.without_metadata(),
        fixed={k: jnp.asarray(finite_number(f"fixed: {k!r}", v), jnp.float64) for k, v in fixed.items()},
        q0=jnp.asarray(begin.q0), v0=jnp.asarray(begin.v0), R0=None if begin.R0 is None else jnp.asarray(begin.R0),
        scale=jnp.asarray(scale), controls=controls, build=model.build, method=method, param_names=param_names,
        q_idx=begin.q_idx, v_idx=begin.v_idx, follow_ic=begin.follow_ic, h=h, steps=ks[-1], t0=t0,
        ts=tuple(float(t0 + k * h) for k in ks), columns=data.columns,
    )


def _least_squares_solver(solver, rtol, atol, reporter):
    """The solver: `solver`, with the progress hook when progress is reported, or the default
    Levenberg–Marquardt."""
    import optimistix as optx

    if solver is None:
        return optx.LevenbergMarquardt(rtol=rtol, atol=atol, verbose=_verbose)
    if reporter is not None:
        if not hasattr(solver, "verbose"):
            raise InputError("progress: this solver has no `verbose` hook to report progress through")
        return eqx.tree_at(lambda s: s.verbose, solver, _verbose)
    return solver


@jit
def _least_squares(problem: _Problem, solver, z0, data, max_steps: int):
    """optimistix's least squares, compiled with gnipy's compiler options (gnipy.compilation.jit)."""
    import optimistix as optx

    return optx.least_squares(problem, solver, z0, data, max_steps=max_steps, throw=False)


def _solve(problem: _Problem, solver, z0, data, max_steps, reporter, names):
    """`(optimistix's solution, its final point)` from the scaled guess `z0`, progress reported
    through `reporter`; InputError for a model that cannot be traced, SolverFailure for a
    simulation that failed at some trial values."""
    _REPORT[0] = reporter
    try:
        out = _least_squares(problem, solver, jnp.asarray(z0), data, int(max_steps))
        return out, np.asarray(out.value)
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


def _solver_outcome(out) -> tuple[int, bool, str]:
    """`(iterations, success, message)` of optimistix's solution."""
    import optimistix as optx

    success = bool(out.result == optx.RESULTS.successful)
    solver_message = "the solver converged" if success else str(optx.RESULTS[out.result])
    return int(out.stats["num_steps"]), success, solver_message


def _linearization_at_estimate(out, problem: _Problem, y, data):
    """:func:`_final_linearization`, a failed step a SolverFailure."""
    try:
        return _final_linearization(out, problem, y, data)
    except Exception as e:
        if "step failed" not in str(e):
            raise
        raise SolverFailure("fit: the simulation at the estimate failed", step=-1, time=float("nan"),
                            residual=float("nan")) from e


def _fitted_run(problem: _Problem, model: FitModel, begin: FitStart, y, fixed, v0p, outputs):
    """`(q0, Solution)` of the fitted run: every node from t0 to the last observation, at the
    estimate `y` (the system rebuilt from the estimated parameters as plain numbers, the projected
    `v0p`); InputError when the system is not valid there."""
    system_fit, q0_fit, _ = problem.unpack(jnp.asarray(y))
    if model.given is None:
        param_names, build = problem.param_names, model.build
        estimated = {k: float(v) for k, v in zip(param_names, y[:len(param_names)])}
        system_fit = build({**fixed, **estimated}) if isinstance(build, ModelBuild) else build(
            {**{k: jnp.float64(v) for k, v in fixed.items()}, **{k: jnp.float64(v) for k, v in estimated.items()}})
    q0_fit = np.asarray(q0_fit)
    kw = {} if problem.controls is None else {"controls": problem.controls}
    try:
        solution = simulate(system_fit, problem.method, q0_fit, v0p, R0=begin.R0, h=problem.h, steps=problem.steps,
                            t0=problem.t0, project_v0=True, throw=False, **kw)
    except InputError as e:
        at = ", ".join(f"{n} = {x:.6g}" for n, x in zip(begin.names, outputs))
        raise InputError(f"params: the fitted system is not valid at the estimate ({at}): {e}") from e
    return q0_fit, solution
