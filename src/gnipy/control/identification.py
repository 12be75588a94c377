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

**Initial velocities** must satisfy the constraints, which may depend on the estimated
parameters. At every evaluation `v0` (held, or estimated as a free vector) is moved onto the
constraints of the system at the trial values by the smallest change of its components,
$v - \\mu^T(\\mu\\mu^T)^{-1}\\mu(v - Y)$
(:func:`gnipy.control.least_squares.admissible_velocity`): a held `v0` that satisfies them is
kept exactly; one that does not is corrected in a way that depends on the constraints'
parameters only, never on the masses and moments of inertia (a $\\mathbb{G}$-orthogonal projection
would make the fit depend on them where the motion does not). The reported `v0` is the moved one.
The directions the move removes from an estimated `v0` do not change the residuals (exact null
directions of $J$), so the covariance is formed with the pseudo-inverse of $J^TJ$ and mapped to
the reported quantities (the parameters, `q0` and the moved `v0`) by the derivative of that map;
it is the same for every generalized inverse, because the dropped directions change none of them.

**Bounds.** Every trial point stays inside the quantities' bounds (a zoo model's masses, moments
of inertia and lengths are positive by default; :mod:`gnipy.control.bounds` says how); an estimate
that ends at a bound, a system that is not valid at the estimate, a solver that does not converge:
each returns a flagged result (`success` False, `message` says why), never an exception.

**Identifiability: which quantities the data determine.** Let $J_s$ be the Jacobian scaled by
the estimates (columns multiplied by $|y_i|$, 1 where $y_i = 0$), with singular values $S_j$ and
right singular vectors $v_j$, and $s$ the noise scale of one weighted residual (1 with `sigma`,
else $\\sqrt{\\chi^2/\\text{dof}}$). The simulation at step $h$ differs from the continuous model by
the discretization error, and so does its Jacobian: $J_s = J_c + J_d$. A direction that the
continuous physics leaves undetermined (for a disk driven from rest and observed in its rolling
angle, any change of $m$, $r$, $I_{rot}$ that keeps $m r^2 + I_{rot}$) still has $S_j > 0$ at
finite $h$, made by $J_d$ alone, and an exact-null test would call it determined. So the fit
reruns the problem at h/2 at the estimate and estimates, by Richardson extrapolation with the
method's order $p$, the discretization error of the predictions, $e = (r_h - r_{h/2})\\,2^p/(2^p-1)$
(its size is `FitResult.discretization`), and its part of the Jacobian along each direction,
$J_d v_j = (J_s v_j - J_{s,h/2}\\,v_j)\\,2^p/(2^p-1)$ (central differences at h/2). **The rule:**
$v_j$ is determined when the continuous part $c_j = \\|J_s v_j - J_d v_j\\|$ exceeds both the
noise and the discretization's part, $c_j > \\max(s, \\|J_d v_j\\|)$. For a physical direction
$\\|J_d v_j\\|/c_j = O(h^p)$; for one seen only through the discretization error it is about 1 or
more: the two are far apart at any $h$ where the method is in its asymptotic range. A quantity is
identifiable when its part along the undetermined directions, each weighted by its uncertainty
$\\max(s, \\|J_d v_j\\|)/c_j$, is below its own size (and it has none along an exact null
direction); otherwise its standard error is infinite, and the result lists the combinations of
such quantities that the data do determine (`FitResult.combinations`: $m r^2 + I_{rot}$ appears
as its gradient at the estimate, $r^2\\,m + 2mr\\,r + I_{rot}$ normalized). The covariance is
$s^2 (J_s^TJ_s)^+$ over the determined directions, mapped to the reported quantities.
"""

from __future__ import annotations

import time
from collections.abc import Mapping

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..errors import InputError, SolverFailure
from ..inputs import finite_number, real_number, require_float64, whole_number
from ..simulate import simulate
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
from .bounds import Bounds, fit_bounds
from .fit_result import IDENTIFIABLE_TOL, RCOND, FitResult, fit_notes, observed_residuals, uncertainties  # noqa: F401
from .least_squares import LeastSquares, discretization, final_linearization, gauss_newton_step, reported
from .memory import memory_limit
from .observations import Observations

__all__ = ["fit", "FitResult", "Observations", "RCOND", "MAX_STEPS"]

#: The default of :func:`fit`'s `max_steps`: the most iterations of the solver.
MAX_STEPS = 200


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
    bounds=None,
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
        bounds: bounds on the estimated quantities, name -> `(lower, upper)` (None or ±inf for an
            open side) or None to lift a default bound (:mod:`gnipy.control.bounds`). Default: a
            zoo model's masses, moments of inertia and lengths are positive (its
            :attr:`~gnipy.registry.ModelSpec.positive`). Every trial point of the solver is inside
            them; an estimate that ends at a bound is flagged (`at_bound`, `success` False).
        solver: an optimistix least-squares solver (default
            `optimistix.LevenbergMarquardt(rtol, atol)`). The estimated quantities are scaled
            by their initial guesses (by 1 where a guess is 0) and mapped onto their bounds before
            the solver sees them.
        max_steps: the most solver iterations.
        rtol, atol: the default solver's tolerances (on the scaled quantities and on the
            residuals).
        progress: `True` prints the iteration and chi² as the solver advances; a callable is
            called as `progress(iteration, chi2)` instead (rejected trial steps included).
        max_bytes: the most memory the fit may need, estimated before anything is compiled
            (:func:`gnipy.control.memory.fit_memory`: the fitted run holds every node from `t0` to
            the last observation): `"auto"` (the default) the smaller of 8 GiB and half the
            physical memory, a number of bytes, or None for no bound.

    The fit simulates once more at h/2 at the estimate, to estimate the discretization error that
    the identifiability rule weighs (module docstring).

    Returns:
        A :class:`FitResult`: the estimates, standard errors, covariance and correlation, chi²
        and degrees of freedom, which quantities the data determine (and which combinations,
        when they do not determine the quantities one by one), the fitted Solution, and whether
        the fit succeeded (`success`, `message`, `iterations`; a fit that did not converge, that
        ends at a bound, or whose system is not valid at the estimate is returned flagged, not
        raised, so that it can be inspected).

    Raises:
        InputError: bad arguments (the message names the argument): unknown parameters or
            variables, observation times off the step grid, shapes that do not match, too few
            observations, a model that cannot be built from traced parameter values, values that
            are not numbers (a string or a boolean is not one), bounds that are not pairs of
            numbers or do not hold the initial guesses, or a fit estimated beyond `max_bytes`
            (naming `observations/h`).
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
    limits = fit_bounds(bounds, model.positive, begin.names, begin.y0)
    data = fit_data(observations, model.system, t0, h, sigma, len(begin.names), bound)

    # the least-squares problem in the solver's internal variables, solved
    problem = _problem(model, begin, data, fixed, param_names, limits, controls, method, h, t0)
    solver = _least_squares_solver(solver, rtol, atol, reporter)
    out, z = _solve(problem, solver, limits.internal(begin.y0), data.arrays, max_steps, reporter, begin.names)
    y = np.asarray(problem.quantities(jnp.asarray(z)))
    iterations, success, solver_message = _solver_outcome(out)

    # the linearization at the estimate: residuals, Jacobian, the reported quantities
    r, J = _linearization_at_estimate(out, problem, y, limits.derivative(z), data.arrays)
    outputs, phi, v0p = (np.asarray(a) for a in reported(problem, jnp.asarray(y)))
    chi2 = float(np.sum(r**2))

    # the fitted run (every node, at the estimate) and its discretization error
    q0_fit, solution, invalid = _fitted_run(problem, model, begin, y, fixed, v0p, outputs)
    scale = np.where(y != 0, np.abs(y), 1.0)
    d, discrete_part = (float("nan"), None) if solution is None else discretization(
        problem, y, r, J * scale[None, :], scale, solution.method, data.arrays)
    stats = uncertainties(J, phi, scale, chi2, data.n_obs, data.sigma_known, discrete_part=discrete_part,
                          names=begin.names, values=outputs)
    at_bound = limits.at_bound(y, gauss_newton_step(r, J, scale))
    success, notes = fit_notes(success, solver_message, stats, begin.names, at_bound, d)
    if solution is None:
        success = False
        notes.append(invalid)
        residuals = np.full(data.observations.values.shape, np.nan)
    else:
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
        method=solution.method if solution is not None else _method_name(method),
        h=h, t0=t0, wall_time=time.perf_counter() - start, determined=stats.determined,
        threshold=stats.threshold, discretization=d, combinations=stats.combinations, bounds=limits.bounded,
        at_bound=at_bound, _problem=problem, _data=data.arrays,
    )


# ----------------------------------------------------------------------------------------------
# The steps of fit
# ----------------------------------------------------------------------------------------------
def _problem(model: FitModel, begin: FitStart, data: FitData, fixed, param_names, limits: Bounds, controls,
             method, h, t0) -> LeastSquares:
    """The least-squares problem of a fit (in the internal variables of `limits`)."""
    ks = data.steps
    return LeastSquares(
        system=None if model.given is None else model.given.without_metadata(),
        fixed={k: jnp.asarray(finite_number(f"fixed: {k!r}", v), jnp.float64) for k, v in fixed.items()},
        q0=jnp.asarray(begin.q0), v0=jnp.asarray(begin.v0), R0=None if begin.R0 is None else jnp.asarray(begin.R0),
        lower=jnp.asarray(limits.lower), upper=jnp.asarray(limits.upper), scale=jnp.asarray(limits.scale),
        controls=controls, build=model.build, method=method, param_names=param_names,
        q_idx=begin.q_idx, v_idx=begin.v_idx, follow_ic=begin.follow_ic, h=h, steps=ks[-1], t0=t0,
        ts=tuple(float(t0 + k * h) for k in ks), columns=data.columns, kinds=limits.kinds,
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
def _least_squares(problem: LeastSquares, solver, z0, data, max_steps: int):
    """optimistix's least squares, compiled with gnipy's compiler options (gnipy.compilation.jit)."""
    import optimistix as optx

    return optx.least_squares(problem, solver, z0, data, max_steps=max_steps, throw=False)


def _solve(problem: LeastSquares, solver, z0, data, max_steps, reporter, names):
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


def _linearization_at_estimate(out, problem: LeastSquares, y, dydz, data):
    """:func:`_final_linearization`, a failed step a SolverFailure."""
    try:
        return final_linearization(out, problem, y, dydz, data)
    except Exception as e:
        if "step failed" not in str(e):
            raise
        raise SolverFailure("fit: the simulation at the estimate failed", step=-1, time=float("nan"),
                            residual=float("nan")) from e


def _fitted_system(problem: LeastSquares, model: FitModel, y, fixed):
    """`(System, q0)` at the estimate `y` (the System rebuilt from the estimated parameters as
    plain numbers)."""
    system_fit, q0_fit, _ = problem.unpack(jnp.asarray(y))
    q0_fit = np.asarray(q0_fit)
    if model.given is None:
        param_names, build = problem.param_names, model.build
        estimated = {k: float(v) for k, v in zip(param_names, y[:len(param_names)])}
        system_fit = build({**fixed, **estimated}) if isinstance(build, ModelBuild) else build(
            {**{k: jnp.float64(v) for k, v in fixed.items()}, **{k: jnp.float64(v) for k, v in estimated.items()}})
    return system_fit, q0_fit


def _fitted_run(problem: LeastSquares, model: FitModel, begin: FitStart, y, fixed, v0p, outputs):
    """`(q0, Solution, None)` of the fitted run: every node from t0 to the last observation, at
    the estimate `y` (the projected `v0p`); `(q0, None, why)` when the system is not valid there
    (the fit drifted out of the model's valid region: a flagged result, not an exception)."""
    kw = {} if problem.controls is None else {"controls": problem.controls}
    q0_fit = np.array(problem.q0)  # the estimated components from y, without building the system
    npar = len(problem.param_names)
    q0_fit[list(problem.q_idx)] = np.asarray(y)[npar:npar + len(problem.q_idx)]
    try:
        system_fit, q0_fit = _fitted_system(problem, model, y, fixed)
        solution = simulate(system_fit, problem.method, q0_fit, v0p, R0=begin.R0, h=problem.h, steps=problem.steps,
                            t0=problem.t0, project_v0=True, throw=False, **kw)
    except InputError as e:
        at = ", ".join(f"{n} = {x:.6g}" for n, x in zip(begin.names, outputs))
        return q0_fit, None, (f"the fitted system is not valid at the estimate ({at}): {e}; bound the quantities "
                              "(bounds=) to keep the fit inside the model's valid region")
    return q0_fit, solution, None


def _method_name(method) -> str:
    """The method's name for a result without a fitted run."""
    if isinstance(method, str):
        return method
    return getattr(method, "name", None) or "the default method"
