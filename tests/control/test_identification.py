"""Parameter identification (`gnipy.control.fit`) on synthetic data of the Chaplygin sleigh.

The reference numbers are the true parameters and initial conditions that made the data, the
noise level used to perturb them, and central differences of the residuals computed by ordinary
(untransformed) simulations; none is taken from an earlier run of `fit`.

The sleigh's positions determine the contact distance `a` and the ratio I/m of its moment of
inertia to its mass (the motion depends on m and I only through it): the fits hold m = 1 and
estimate I and a. The compiled programs are shared: every fit of one problem structure (model,
estimated quantities, observed variables, observation times) reuses one compilation, and the
data are made by runs that save as many nodes as the fitted runs.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.control import FitResult, Observations, fit

MODEL = "chaplygin-sleigh"
METHOD = "gni-trapezoid"
H, STEPS = 0.05, 60
TRUE = {"I": 1.5, "a": 0.4}
GUESS = {"I": 1.2, "a": 0.5}
Q0, V0 = (0.0, 0.0, 0.0), (1.0, 0.4, 1.0)  # on the constraint ẏ cosθ − ẋ sinθ = a θ̇ for a = 0.4
TS = H * np.arange(2, STEPS + 1, 2)  # every other node: a subset of the grid
K = np.arange(2, STEPS + 1, 2)
SIGMA = 1e-3


def noisy(values, seed):
    return values + SIGMA * np.random.default_rng(seed).standard_normal(values.shape)


@pytest.fixture(scope="module")
def truth():
    """The true run, every node (the fitted runs save as many and share its compilation)."""
    return gnipy.simulate(gnipy.make_system(MODEL, **TRUE), METHOD, Q0, V0, h=H, steps=STEPS)


@pytest.fixture(scope="module")
def xy(truth):
    """The true x and y at the observation times."""
    return np.asarray(truth.q)[K][:, :2]


def fit_xy(values, **kw):
    kw = dict(params=GUESS, method=METHOD, h=H, q0=Q0, v0=V0) | kw
    return fit(MODEL, Observations(TS, values, ("x", "y")), **kw)


@pytest.fixture(scope="module")
def noisy_fit(xy):
    return fit_xy(noisy(xy, 0), sigma=SIGMA)


def test_recovers_parameters_from_noisy_partial_observations_within_the_stated_uncertainty(noisy_fit, xy):
    r = noisy_fit
    assert isinstance(r, FitResult) and r.success, r.message
    assert r.names == ("I", "a") and r.n_obs == xy.size and r.rank == 2 and r.dof == xy.size - 2
    assert r.sigma_known and r.identifiable.all()
    for i, name in enumerate(r.names):
        assert abs(r.values[i] - TRUE[name]) <= 4 * r.stderr[i], (name, r.values[i], r.stderr[i])
        assert 0 < r.stderr[i] < 1e-2 * TRUE[name]
    assert r.params == {"I": r.values[0], "a": r.values[1]}
    assert 0.5 < r.reduced_chi2 < 1.6  # chi² with 58 degrees of freedom: 1 ± 0.19
    np.testing.assert_allclose(r.correlation, r.correlation.T)
    np.testing.assert_allclose(np.diag(r.covariance), r.stderr**2)
    # the fitted Solution: every node from t0, the model values behind the residuals
    sol = r.solution
    assert sol.success and len(sol.t) == STEPS + 1
    np.testing.assert_allclose(np.asarray(sol.q)[K][:, :2] - r.observations.values, r.residuals, rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.sum((r.residuals / SIGMA) ** 2), r.chi2, rtol=1e-9)
    assert "I" in r.summary() and "std error" in r.summary()
    # without sigma, the errors are scaled by the residuals' own scatter (s² = chi²/dof in the weights' units)
    unknown = fit_xy(r.observations.values)
    np.testing.assert_allclose(unknown.values, r.values, rtol=1e-7)
    np.testing.assert_allclose(unknown.stderr, r.stderr * np.sqrt(r.reduced_chi2), rtol=1e-5)
    assert not unknown.sigma_known


def test_the_stated_uncertainty_matches_the_scatter_of_repeated_fits(xy):
    """24 noise realizations: the spread of the estimates is the stated standard error (the
    sample standard deviation of 24 draws is within about ±15% of the true one)."""
    fits = [fit_xy(noisy(xy, seed), sigma=SIGMA) for seed in range(100, 124)]
    assert all(f.success for f in fits)
    values = np.array([f.values for f in fits])
    stated = np.mean([f.stderr for f in fits], axis=0)
    ratio = values.std(axis=0, ddof=1) / stated
    assert np.all((0.6 < ratio) & (ratio < 1.5)), ratio
    assert np.all(np.abs(values.mean(axis=0) - [TRUE["I"], TRUE["a"]]) < 4 * stated / np.sqrt(len(fits)))


def test_noise_free_data_give_the_true_parameters(truth, xy, tmp_path):
    """From arrays, from a Solution, from an xarray Dataset and from a netCDF file written by
    gnipy (partial: x and y only): the true parameters to 1e-8."""
    at_ts = gnipy.simulate(gnipy.make_system(MODEL, **TRUE), METHOD, Q0, V0, h=H, steps=STEPS,
                           saveat=gnipy.SaveAt(ts=TS))
    path = gnipy.write_netcdf(at_ts, tmp_path / "sleigh.nc")
    sources = {
        "arrays": Observations(TS, xy, ("x", "y")),
        "solution": Observations.from_solution(at_ts, ("x", "y")),
        "dataset": Observations.from_dataset(at_ts.to_xarray(), ("x", "y")),
        "netcdf": Observations.from_dataset(path, ("x", "y")),
    }
    for source, obs in sources.items():
        r = fit(MODEL, obs, params=GUESS, method=METHOD, h=H, q0=Q0, v0=V0)
        assert r.success, (source, r.message)
        np.testing.assert_allclose(r.values, [TRUE["I"], TRUE["a"]], rtol=1e-8, err_msg=source)
        assert r.chi2 < 1e-20


def test_missing_values_are_left_out(xy):
    """NaN marks a missing value: it is not fitted, not counted, and its residual is NaN."""
    values = xy.copy()
    values[3, 0] = values[10, 1] = np.nan
    values[20] = np.nan
    r = fit_xy(values)
    assert r.success and r.n_obs == xy.size - 4 and r.dof == xy.size - 6
    np.testing.assert_allclose(r.values, [TRUE["I"], TRUE["a"]], rtol=1e-8)
    assert np.array_equal(np.isnan(r.residuals), np.isnan(values))


def central(f, x, rel=1e-6):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = rel * max(abs(x[i]), 1.0)
        cols.append((f(x + e) - f(x - e)) / (2 * e[i]))
    return np.stack(cols, axis=1)


def test_the_jacobian_of_the_uncertainties_matches_central_differences(noisy_fit):
    """The Jacobian behind the covariance (forward mode through the simulation, the implicit steps
    by the implicit function theorem) against central differences of the weighted residuals
    computed by ordinary simulations; and the covariance is (JᵀJ)⁻¹ of it."""
    r = noisy_fit
    np.testing.assert_array_equal(r.raw, r.values)  # no v0 estimated: the solver's point is the estimate
    J = central(r.weighted_residuals, r.raw)
    np.testing.assert_allclose(r.jacobian, J, rtol=0, atol=1e-6 * np.abs(J).max())
    np.testing.assert_allclose(r.weighted_residuals(), np.where(np.isnan(r.residuals), 0, r.residuals).ravel() / SIGMA,
                               rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(r.covariance, np.linalg.inv(r.jacobian.T @ r.jacobian), rtol=1e-8)


@pytest.fixture(scope="module")
def start():
    """A start off the default one: q0, and v0 on the constraint (ẏ = (a θ̇ + ẋ sinθ)/cosθ)."""
    q0 = np.array([0.3, -0.2, 0.5])
    dx, dth = 0.8, 0.7
    v0 = np.array([dx, (TRUE["a"] * dth + dx * np.sin(q0[2])) / np.cos(q0[2]), dth])
    return q0, v0


@pytest.fixture(scope="module")
def initial_fit(start, tmp_path_factory):
    """q0 and v0 estimated from a netCDF file of every coordinate at every node (noise-free), from
    a guess whose v0 violates the constraint."""
    q0, v0 = start
    system = gnipy.make_system(MODEL, **TRUE)
    sol = gnipy.simulate(system, METHOD, q0, v0, h=H, steps=STEPS)
    path = gnipy.write_netcdf(sol, tmp_path_factory.mktemp("fit") / "start.nc")
    guess_q0, guess_v0 = q0 + [0.05, 0.05, -0.1], v0 + [0.2, -0.1, 0.3]
    r = fit(system, path, initial=("q0", "v0"), method=METHOD, h=H, q0=guess_q0, v0=guess_v0)
    return r, sol, (system, guess_q0, guess_v0)


def constraint(q0, v0):
    th = q0[2]
    return -v0[0] * np.sin(th) + v0[1] * np.cos(th) - TRUE["a"] * v0[2]


def test_estimates_the_initial_condition_with_a_velocity_on_the_constraints(initial_fit, start):
    r, sol, (system, guess_q0, guess_v0) = initial_fit
    q0, v0 = start
    assert abs(constraint(guess_q0, guess_v0)) > 0.1  # the guess is off the constraint
    assert r.success, r.message
    assert r.names == ("q0.x", "q0.y", "q0.theta", "v0.dx", "v0.dy", "v0.dtheta")
    np.testing.assert_allclose(r.values, np.r_[q0, v0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(r.q0, q0, atol=1e-9)
    np.testing.assert_allclose(r.v0, v0, atol=1e-9)
    assert abs(constraint(r.q0, r.v0)) < 1e-13  # the reported v0 is the projected one
    # six estimated numbers, one removed by the projection: rank 5, every reported quantity determined
    assert r.rank == 5 and r.dof == r.n_obs - 5 and r.identifiable.all() and np.all(np.isfinite(r.stderr))
    # noisy data (as a (times, values) tuple of every coordinate), sigma known: within the stated error
    values = noisy(np.asarray(sol.q), 7)
    n = fit(system, (np.asarray(sol.t), values), initial=("q0", "v0"), method=METHOD, h=H, q0=guess_q0,
            v0=guess_v0, sigma=SIGMA)
    assert n.success, n.message
    assert np.all(np.abs(n.values - np.r_[q0, v0]) <= 4 * n.stderr), (n.values - np.r_[q0, v0]) / n.stderr
    assert np.all(n.stderr < 2e-3) and abs(constraint(n.q0, n.v0)) < 1e-13


def test_the_jacobian_with_a_projected_velocity_matches_central_differences(initial_fit):
    """At the solver's final point, where v0 is a raw vector projected inside the residuals."""
    r = initial_fit[0]
    J = central(r.weighted_residuals, r.raw)
    np.testing.assert_allclose(r.jacobian, J, rtol=0, atol=1e-6 * np.abs(J).max())


def test_quantities_the_data_cannot_determine_are_reported(xy):
    """m and I together: only I/m enters the motion, so neither is determined (infinite error);
    a still is, and the fit still finds the true ratio."""
    r = fit(MODEL, Observations(TS, xy, ("x", "y")), params={"m": 1.3, "I": 1.2, "a": 0.5}, method=METHOD, h=H,
            q0=Q0, v0=V0)
    assert r.success and r.rank == 2
    assert r.identifiable.tolist() == [False, False, True]
    assert np.isinf(r.stderr[:2]).all() and np.isfinite(r.stderr[2])
    assert "do not determine m, I" in r.message
    np.testing.assert_allclose(r.values[1] / r.values[0], TRUE["I"], rtol=1e-8)
    np.testing.assert_allclose(r.values[2], TRUE["a"], rtol=1e-8)


def test_progress_reports_each_iteration(xy, capsys):
    calls = []
    r = fit_xy(xy, progress=lambda k, chi2: calls.append((k, chi2)))
    assert [k for k, _ in calls] == list(range(r.iterations))
    assert calls[-1][1] <= calls[0][1] and calls[-1][1] < 1e-16
    fit_xy(xy, progress=True)
    assert "fit: iteration 0, chi2 =" in capsys.readouterr().err


def test_bad_input_is_refused_naming_the_argument(xy, truth):
    obs = Observations(TS, xy, ("x", "y"))
    bad = [
        ("observations: time 0.11", lambda: fit(MODEL, Observations(TS + 0.01, xy, ("x", "y")), params=GUESS, h=H)),
        ("observations: unknown variable 'z'", lambda: fit(
            MODEL, Observations(TS, xy, ("x", "z")), params=GUESS, method=METHOD, h=H, q0=Q0, v0=V0)),
        ("observations: values have shape", lambda: Observations(TS, xy[:, :1], ("x", "y"))),
        ("observations: values have shape", lambda: Observations(TS[:-1], xy, ("x", "y"))),
        ("observations: values of shape", lambda: fit(MODEL, (TS, xy), params=GUESS, h=H, q0=Q0, v0=V0)),
        ("observations: repeated", lambda: Observations(TS, xy, ("x", "x"))),
        ("observations: unknown variable 'w'", lambda: Observations.from_solution(truth, ("x", "w"))),
        ("observations: time -0.1 lies before", lambda: fit(
            MODEL, Observations(np.r_[-0.1, TS[1:]], xy, ("x", "y")), params=GUESS, h=H, q0=Q0, v0=V0)),
        ("observations: the times must be strictly increasing", lambda: fit(
            MODEL, Observations(TS[::-1], xy, ("x", "y")), params=GUESS, h=H, q0=Q0, v0=V0)),
        ("observations: expected", lambda: fit(MODEL, 3.0, params=GUESS, h=H)),
        ("sigma: sigma has shape", lambda: fit(MODEL, obs, params=GUESS, h=H, q0=Q0, v0=V0, sigma=np.ones(3))),
        ("sigma: sigma must be positive", lambda: fit(MODEL, obs, params=GUESS, h=H, q0=Q0, v0=V0, sigma=-1.0)),
        ("sigma: given both", lambda: fit(MODEL, Observations(TS, xy, ("x", "y"), sigma=SIGMA), params=GUESS, h=H,
                                          q0=Q0, v0=V0, sigma=SIGMA)),
        ("params: unknown parameter 'b'", lambda: fit(MODEL, obs, params={"b": 1.0}, h=H, q0=Q0, v0=V0)),
        ("fixed: ['a'] also in params", lambda: fit(MODEL, obs, params=GUESS, fixed={"a": 1.0}, h=H)),
        # a System estimates only its named parameters (args; the zoo's sleigh: test_user_systems.py)
        ("params: a System's parameters cannot be estimated here unless they are its args", lambda: fit(
            gnipy.System(lambda q, v: 0.5 * v @ v, lambda q: jnp.array([[0.0, 0.0, 1.0]]), coordinates=("x", "y", "t")),
            obs, params=GUESS, h=H)),
        ("params: unknown parameter 'b' of the System", lambda: fit(gnipy.make_system(MODEL), obs, params={"b": 1.0},
                                                                    h=H)),
        ("initial: unknown entries", lambda: fit(MODEL, obs, initial=("R0",), h=H, q0=Q0, v0=V0)),
        ("initial: unknown component 'z'", lambda: fit(MODEL, obs, initial={"q0": ["z"]}, h=H, q0=Q0, v0=V0)),
        ("params/initial: nothing to estimate", lambda: fit(MODEL, obs, h=H, q0=Q0, v0=V0)),
        ("q0: expected 3 numbers", lambda: fit(MODEL, obs, params=GUESS, h=H, q0=(0.0, 0.0), v0=V0)),
        ("h: must be nonzero", lambda: fit(MODEL, obs, params=GUESS, h=0.0, q0=Q0, v0=V0)),
        ("system: expected a model name", lambda: fit(3, obs, params=GUESS, h=H)),
        ("progress: expected", lambda: fit(MODEL, obs, params=GUESS, h=H, q0=Q0, v0=V0, progress="yes")),
    ]
    for match, call in bad:
        with pytest.raises(gnipy.InputError, match=match.replace("(", r"\(").replace("[", r"\[")):
            call()


def test_a_failed_simulation_during_the_fit_raises_a_solver_failure(initial_fit):
    """A moment of inertia 0: the metric is singular and the first simulation fails (the problem of
    the initial-condition fit otherwise, which shares its compilation)."""
    _, sol, (_, guess_q0, guess_v0) = initial_fit
    with pytest.raises(gnipy.SolverFailure, match="fit: a simulation failed at some trial values of q0.x"):
        fit(gnipy.make_system(MODEL, I=0.0, a=TRUE["a"]), (np.asarray(sol.t), np.asarray(sol.q)), initial=("q0", "v0"),
            method=METHOD, h=H, q0=guess_q0, v0=guess_v0)


class ReachedComputation(Exception):
    """A refusal came too late: a simulation or the solver was reached."""


def _tripwire(*args, **kwargs):
    raise ReachedComputation("reached a computation")


def test_strings_and_booleans_are_not_numbers_and_the_span_is_bounded(monkeypatch):
    """Issue 28 (D6, D9): every number fit takes refuses strings and booleans (naming the
    argument); a span of observations whose fitted run would not fit in memory is refused before
    anything is compiled, max_bytes=None lifts the bound."""
    import optimistix

    import gnipy.control.identification as identification

    monkeypatch.setattr(identification, "simulate", _tripwire)
    monkeypatch.setattr(optimistix, "least_squares", _tripwire)
    obs = Observations(TS, np.zeros((TS.size, 2)), ("x", "y"))
    base = dict(params=GUESS, method=METHOD, h=H, q0=Q0, v0=V0)
    cases = [
        (dict(params={"I": "1.2"}), "params: 'I': expected a number"), (dict(params={"I": True}), "params: 'I'"),
        (dict(params={1: 1.0}), "params: parameter names must be strings"),
        (dict(params={"I": 1.2}, fixed={"m": True}), "fixed: 'm': expected a number"),
        (dict(params={"I": 1.2}, fixed={"m": "1"}), "fixed: 'm'"),
        (dict(h=True), "h: expected a number"), (dict(h="0.05"), "h:"), (dict(h=1e-320), "h:"), (dict(t0=True), "t0:"),
        (dict(sigma="0.1"), "sigma:"), (dict(sigma=True), "sigma:"), (dict(sigma=1e-320), "sigma: sigma must lie in"),
        (dict(q0=("0", 0.0, 0.0)), "q0:"), (dict(v0=(True, 0.4, 1.0)), "v0:"),
        (dict(max_steps=True), "max_steps:"), (dict(max_steps=10**7), "max_steps:"), (dict(rtol="1e-10"), "rtol:"),
        (dict(max_bytes="x"), "max_bytes:"),
    ]
    for kw, words in cases:
        with pytest.raises(gnipy.InputError) as info:
            fit(MODEL, obs, **(base | kw))
        assert str(info.value).startswith(words), (kw, str(info.value))
    for bad in (np.zeros((TS.size, 2)).astype(str), np.zeros((TS.size, 2), dtype=bool)):
        with pytest.raises(gnipy.InputError, match="observations: expected"):
            Observations(TS, bad, ("x", "y"))
    with pytest.raises(gnipy.InputError, match="observations: expected"):
        Observations([True, False], [1.0, 2.0], "x")
    far = Observations([0.05, 3e6], np.zeros((2, 2)), ("x", "y"))  # 6·10⁷ steps of 0.05
    with pytest.raises(gnipy.InputError, match=r"observations/h: .*60,000,001 nodes.* max_bytes=None"):
        fit(MODEL, far, **base)
    with pytest.raises(ReachedComputation):
        fit(MODEL, far, **base, max_bytes=None)
