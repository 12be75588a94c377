"""Problem files (gnipy.control.problems) and `gni fit`: a fit problem file read and solved from
the command line recovers the parameters that made its observation file; malformed files are
refused naming the entry."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app
from gnipy.control.fit_problems import load_fit_problem

PROBLEM = """\
[system]
model = "chaplygin-sleigh"
params = { m = 1.0 }
[estimate]
params = { I = 1.2, a = 0.5 }
bounds = { a = [0.0, 1.0] }
[observations]
file = "observed.nc"
variables = ["x", "y"]
[start]
q0 = [0.0, 0.0, 0.0]
v0 = [1.0, 0.4, 1.0]
[integration]
method = "gni-trapezoid"
"""


@pytest.fixture(scope="module")
def observed(tmp_path_factory):
    """An observation file made by `gni run` with I = 1.5, a = 0.4 (the truth the fit must find)."""
    d = tmp_path_factory.mktemp("fit")
    res = CliRunner().invoke(app, ["run", "chaplygin-sleigh", "--method", "gni-trapezoid", "--set", "I=1.5,a=0.4",
                                   "--h", "0.05", "--steps", "60", "--q0", "0,0,0", "--v0", "1,0.4,1",
                                   "--out", str(d / "observed.nc")])
    assert res.exit_code == 0, res.output
    (d / "sleigh-fit.toml").write_text(PROBLEM)
    return d


def test_gni_fit_recovers_the_parameters_of_the_observed_run(observed):
    out, fig = observed / "fit.nc", observed / "fit.png"
    res = CliRunner().invoke(app, ["fit", str(observed / "sleigh-fit.toml"), "--out", str(out), "--plot", str(fig)])
    assert res.exit_code == 0, res.output
    assert "converged" in res.output and fig.stat().st_size > 0
    ok, _ = gnipy.verify_netcdf(out)
    assert ok
    with xr.open_dataset(out) as ds:
        est = dict(zip(ds["quantity"].values.tolist(), ds["estimate"].values))
        assert abs(est["I"] - 1.5) <= 1e-8 and abs(est["a"] - 0.4) <= 1e-8
        assert ds.attrs["fit_success"] == 1 and ds.attrs["fit_observed_variables"] == "x,y"
        assert ds.attrs["fit_determined"] == 2 and ds.attrs["fit_at_bound"] == "" and ds.attrs["fit_combinations"] == ""
        assert ds["covariance"].shape == (2, 2)
        # the file holds the fitted run: it is the run of the estimated parameters
        truth = gnipy.simulate(gnipy.make_system("chaplygin-sleigh", I=1.5, a=0.4), "gni-trapezoid", (0, 0, 0),
                               (1.0, 0.4, 1.0), h=0.05, steps=60)
        assert np.max(np.abs(ds["q"].values - np.asarray(truth.q))) <= 1e-8
    # h came from the observation file (h = 0.05, not in the problem file); a's bounds are read
    prob = load_fit_problem(observed / "sleigh-fit.toml")
    assert prob.h == 0.05 and prob.bounds == {"a": (0.0, 1.0)}


def test_fit_problem_errors_name_the_entry(observed):
    cases = [
        (PROBLEM.replace('file = "observed.nc"', 'file = "missing.nc"'), "observations.file"),
        (PROBLEM.replace("params = { I = 1.2, a = 0.5 }", "params = {}"), "estimate"),
        (PROBLEM.replace('model = "chaplygin-sleigh"', 'model = "no-such"'), "system.model"),
        (PROBLEM.replace('variables = ["x", "y"]', 'variables = "x"'), "observations.variables"),
        (PROBLEM + "[extra]\na = 1\n", "unknown section"),
        (PROBLEM.replace('method = "gni-trapezoid"', 'method = "gni-trapezoid"\nstep = 1'), "integration: unknown key"),
    ]
    for text, words in cases:
        path = observed / "bad.toml"
        path.write_text(text)
        with pytest.raises(gnipy.InputError) as info:
            load_fit_problem(path)
        assert words in str(info.value), (words, str(info.value))
    res = CliRunner().invoke(app, ["fit", str(observed / "bad.toml"), "--out", str(observed / "bad.nc")])
    assert res.exit_code == 2 and "integration" in res.output


# --------------------------------------------------------------------------------------------------
# Issue 28 (D6, D7, D9): every entry of both file formats is checked before anything is compiled;
# a value of the wrong type is refused naming its key, never coerced, never another exception
# --------------------------------------------------------------------------------------------------
import copy  # noqa: E402
import json  # noqa: E402
import tomllib  # noqa: E402

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from gnipy.control.problems import WORKED_PROBLEMS, load_problem  # noqa: E402

SLEIGH = tomllib.loads(WORKED_PROBLEMS["sleigh-steering"])


class ReachedComputation(Exception):
    """A refusal came too late: a simulation or the solver was reached."""


def _tripwire(*args, **kwargs):
    raise ReachedComputation("reached a computation")


@pytest.fixture(scope="module")
def tripwire():
    """Nothing here may simulate or solve: the checks come first."""
    import optimistix

    import gnipy.control.identification as identification
    import gnipy.control.least_squares as least_squares
    import gnipy.control.shooting as shooting

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(shooting, "simulate", _tripwire)
        mp.setattr(identification, "simulate", _tripwire)
        mp.setattr(least_squares, "simulate", _tripwire)
        mp.setattr(optimistix, "least_squares", _tripwire)
        yield


def _with(data, path, value):
    data = copy.deepcopy(data)
    node = data
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value
    return data


#: The numeric entries of the control problem file: the path of each, and the key its error names.
CONTROL_NUMBERS = {
    ("horizon", "h"): "horizon.h", ("horizon", "steps"): "horizon.steps", ("solver", "effort"): "solver.effort",
    ("solver", "smoothness"): "solver.smoothness", ("solver", "max_iterations"): "solver.max_iterations",
    ("solver", "segments"): "solver.segments", ("target", "x"): "target.x", ("target", "theta"): "target.theta",
    ("system", "params", "m"): "system.params.m", ("system", "params", "a"): "system.params.a",
    ("inputs", "torque", "dtheta"): "inputs.torque", ("warm_start", "periods"): "warm_start.periods",
}
CONTROL_LISTS = {("start", "q0"): "start.q0", ("start", "v0"): "start.v0", ("solver", "bounds"): "solver.bounds",
                 ("warm_start", "amplitude"): "warm_start.amplitude", ("warm_start", "phase"): "warm_start.phase"}

# what TOML can hold that is not a number: strings (numbers written as strings too), booleans,
# dates and times, arrays, tables
not_a_number = st.one_of(
    st.text(max_size=5), st.floats(allow_nan=False).map(repr), st.booleans(), st.datetimes(), st.dates(), st.times(),
    st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3),
    st.dictionaries(st.text(max_size=3), st.floats(allow_nan=False), max_size=2),
)
# what is not a list of numbers: the above but lists, and lists holding one of them
not_numbers = st.one_of(
    st.text(max_size=5), st.booleans(), st.floats(), st.integers(), st.dates(),
    st.dictionaries(st.text(max_size=3), st.floats(), max_size=2),
    st.tuples(st.lists(st.floats(allow_nan=False), max_size=2),
              st.one_of(st.text(max_size=3), st.booleans(), st.dates())).map(lambda p: p[0] + [p[1]]),
)
toml_value = st.recursive(
    st.one_of(st.text(max_size=5), st.booleans(), st.integers(), st.floats(), st.dates()),
    lambda inner: st.one_of(st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=6,
)
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
                derandomize=True)


@FAST
@given(path=st.sampled_from(list(CONTROL_NUMBERS)), value=not_a_number)
def test_control_numbers_of_the_wrong_type_are_refused_naming_the_key(tripwire, path, value):
    with pytest.raises(gnipy.InputError) as info:
        load_problem(_with(SLEIGH, path, value))
    assert str(info.value).startswith(CONTROL_NUMBERS[path] + ":"), (path, value, str(info.value))


@FAST
@given(path=st.sampled_from(list(CONTROL_LISTS)), value=not_numbers)
def test_control_lists_of_the_wrong_type_are_refused_naming_the_key(tripwire, path, value):
    with pytest.raises(gnipy.InputError) as info:
        load_problem(_with(SLEIGH, path, value))
    assert str(info.value).startswith(CONTROL_LISTS[path] + ":"), (path, value, str(info.value))


@FAST
@given(path=st.sampled_from(list(CONTROL_NUMBERS)),
       value=st.one_of(st.integers(-10**20, 10**20), st.floats(), st.sampled_from([0, -1, 0.0, 1e308, 1e-320])))
def test_control_numbers_are_taken_as_they_are_or_refused_naming_the_key(tripwire, path, value):
    """Any number: accepted as it is (no clipping; a real entry is the float64 nearest to it, as TOML
    means it), or refused naming the key (its range; NaN and infinities; a horizon that needs too
    much memory; a model that cannot be built). Integer entries (steps, iterations) are exact."""
    try:
        problem = load_problem(_with(SLEIGH, path, value))
    except gnipy.InputError as e:
        head = str(e).split(":")[0]
        assert head.startswith(CONTROL_NUMBERS[path].rsplit(".", 1)[0]), (path, value, str(e))
        return
    taken = {("horizon", "h"): problem.h, ("horizon", "steps"): problem.steps, ("solver", "effort"): problem.effort,
             ("solver", "smoothness"): problem.smoothness, ("solver", "max_iterations"): problem.max_iterations,
             ("solver", "segments"): problem.segments}
    exact = value if isinstance(taken.get(path), int) else float(value)
    if path in taken:
        assert taken[path] == exact and not isinstance(taken[path], bool)
    if path[0] == "target":
        assert problem.target[path[1]] == float(value)


@FAST
@given(path=st.sampled_from([p for p in [("name",), ("description",), ("system",), ("system", "model"),
                                         ("system", "params"), ("inputs",), ("inputs", "torque"), ("start",),
                                         ("horizon",), ("target",), ("target", "R"), ("solver",),
                                         ("solver", "method"), ("solver", "bounds"), ("warm_start",), ("extra",)]]
                            + list(CONTROL_NUMBERS) + list(CONTROL_LISTS)),
       value=toml_value)
def test_any_value_at_any_key_is_accepted_or_refused_with_an_input_error(tripwire, path, value):
    try:
        load_problem(_with(SLEIGH, path, value))
    except gnipy.InputError as e:
        assert str(e).split(":")[0].split(".")[0] in (path[0], "problem"), (path, value, str(e))


@settings(max_examples=100, deadline=None, derandomize=True)
@given(data=st.binary(max_size=300))
def test_random_bytes_as_a_problem_file_are_an_input_error(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("bytes") / "p.toml"
    path.write_bytes(data)
    for loader in (load_problem, load_fit_problem):
        with pytest.raises(gnipy.InputError):  # never another exception (a UnicodeDecodeError, ...)
            loader(path)


def test_refusals_name_the_key_and_say_why(tripwire):
    cases = [
        (("inputs", "torque", "dtheta"), 0.0, "inputs.torque: every gain is zero"),
        (("system", "params"), 5, "system.params: expected a table"),
        (("target", "x"), True, "target.x: expected a number, got true (a boolean)"),
        (("solver", "effort"), True, "solver.effort: expected a number, got true (a boolean)"),
        (("system", "params", "m"), "1", "system.params.m: expected a number, got the string '1'"),
        (("inputs", "torque", "dtheta"), "1", "inputs.torque: the gain of 'dtheta' must be a number"),
        (("start", "R0"), [[1.0]], "start.R0: the model 'chaplygin-sleigh' has no orientation"),
        (("solver", "segments"), 81, "solver.segments: must be an integer from 1 to 80 (horizon.steps)"),
        (("horizon", "steps"), 3_000_000_000, "horizon.steps: 3,000,000,000 steps x 1 input"),
    ]
    for path, value, words in cases:
        with pytest.raises(gnipy.InputError) as info:
            load_problem(_with(SLEIGH, path, value))
        assert str(info.value).startswith(words), (words, str(info.value))


def test_the_memory_bound_is_checked_before_the_warm_start_is_built(tripwire, monkeypatch):
    """3·10⁹ steps: the warm start alone would be 24 GB; refused first (numpy never asked), and
    max_bytes=None lifts the bound (then the warm start is built: a small case shows it)."""
    import gnipy.control.problems as problems

    built = []
    monkeypatch.setattr(problems, "_warm_start", lambda *a: built.append(a) or np.zeros((a[1], a[2])))
    with pytest.raises(gnipy.InputError, match=r"horizon.steps: .* pass max_bytes=None"):
        load_problem(_with(SLEIGH, ("horizon", "steps"), 3_000_000_000))
    assert built == []
    with pytest.raises(gnipy.InputError, match="horizon.steps"):
        load_problem(SLEIGH, max_bytes=1000)  # the worked problem needs about 2.5 MB
    assert load_problem(SLEIGH, max_bytes=None).steps == 80 and len(built) == 1


# --------------------------------------------------------------------------------------------------
# Fit problem files and observation files
# --------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fit_dir(tmp_path_factory):
    """A fit problem (as a mapping) with an observation file written without computing anything."""
    d = tmp_path_factory.mktemp("fit-files")
    t = 0.05 * np.arange(11)
    xr.Dataset({"q": (("time", "coordinate"), np.stack([t, 0.4 * t, 0.1 * t], axis=1))},
               coords={"time": t, "coordinate": ["x", "y", "theta"]}, attrs={"h": 0.05}).to_netcdf(d / "obs.nc")
    data = tomllib.loads(PROBLEM.replace('file = "observed.nc"', f"file = {json.dumps(str(d / 'obs.nc'))}"))
    return d, data


FIT_NUMBERS = {("estimate", "params", "I"): "estimate.params.I", ("system", "params", "m"): "system.params.m",
               ("observations", "sigma"): "observations.sigma", ("integration", "h"): "integration.h",
               ("integration", "t0"): "integration.t0"}
FIT_LISTS = {("start", "q0"): "start.q0", ("start", "v0"): "start.v0"}


@FAST
@given(path=st.sampled_from(list(FIT_NUMBERS)), value=not_a_number)
def test_fit_numbers_of_the_wrong_type_are_refused_naming_the_key(tripwire, fit_dir, path, value):
    with pytest.raises(gnipy.InputError) as info:
        load_fit_problem(_with(fit_dir[1], path, value))
    assert str(info.value).startswith(FIT_NUMBERS[path] + ":"), (path, value, str(info.value))


@FAST
@given(path=st.sampled_from(list(FIT_LISTS)), value=not_numbers)
def test_fit_lists_of_the_wrong_type_are_refused_naming_the_key(tripwire, fit_dir, path, value):
    with pytest.raises(gnipy.InputError) as info:
        load_fit_problem(_with(fit_dir[1], path, value))
    assert str(info.value).startswith(FIT_LISTS[path] + ":"), (path, value, str(info.value))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
          derandomize=True)
@given(data=st.binary(max_size=2000), keep=st.integers(0, 4000))
def test_random_or_damaged_observation_files_name_observations_file(tripwire, fit_dir, tmp_path_factory, data, keep):
    """Random bytes, and a real result file cut short (then random bytes after it): an InputError
    naming observations.file (or a good file), never another exception. (Bytes overwritten inside
    the HDF5 structure are left out: the HDF5 library is not hardened against every such file.)"""
    d, problem = fit_dir
    good = (d / "obs.nc").read_bytes()
    damaged = good[:keep] + data if keep % 2 else data
    path = tmp_path_factory.mktemp("obs") / "obs.nc"
    path.write_bytes(damaged)
    try:
        load_fit_problem(_with(problem, ("observations", "file"), str(path)))
    except gnipy.InputError as e:
        assert str(e).startswith(("observations.file:", "integration.h:")), str(e)


def test_observation_files_are_checked(tripwire, fit_dir, tmp_path):
    d, problem = fit_dir
    t = 0.05 * np.arange(11)
    cases = {
        "strings": (xr.Dataset({"q": (("time", "coordinate"), np.zeros((11, 3)).astype(str))},
                               coords={"time": t, "coordinate": ["x", "y", "theta"]}), "q holds <U"),
        "booleans": (xr.Dataset({"q": (("time", "coordinate"), np.zeros((11, 3), dtype=bool))},
                                coords={"time": t, "coordinate": ["x", "y", "theta"]}), "not numbers"),
        "extra": (xr.Dataset({"q": (("time", "coordinate", "e"), np.zeros((11, 3, 2)))},
                             coords={"time": t, "coordinate": ["x", "y", "theta"]}), "dimensions"),
        "no-time": (xr.Dataset({"q": (("k", "coordinate"), np.zeros((11, 3)))},
                               coords={"coordinate": ["x", "y", "theta"]}), "dimensions"),
    }
    for name, (ds, words) in cases.items():
        ds.attrs["h"] = 0.05
        ds.to_netcdf(tmp_path / f"{name}.nc")
        with pytest.raises(gnipy.InputError) as info:
            load_fit_problem(_with(problem, ("observations", "file"), str(tmp_path / f"{name}.nc")))
        assert str(info.value).startswith("observations.file:") and words in str(info.value), (name, str(info.value))
    # the observed variables are sized before they are read
    with pytest.raises(gnipy.InputError, match=r"observations.file: .* more than the memory bound .* max_bytes=None"):
        load_fit_problem(problem, max_bytes=100)
    assert load_fit_problem(problem, max_bytes=None).h == 0.05


def test_a_worked_problem_at_another_resolution_keeps_its_horizon():
    """`worked_problem(name, steps)`: the same problem file with `steps` steps over the same horizon
    (the control benchmark's cases); without steps the file itself; wrong names and counts refused."""
    from gnipy.control.problems import WORKED_PROBLEMS, worked_problem

    for name, text in WORKED_PROBLEMS.items():
        assert worked_problem(name) == text
        base = load_problem(text)
        for steps in (7, 2 * base.steps):
            other = load_problem(worked_problem(name, steps))
            assert other.steps == steps and abs(other.steps * other.h - base.steps * base.h) <= 1e-12
            assert other.target.keys() == base.target.keys()
            assert all(np.array_equal(np.asarray(other.target[k]), np.asarray(base.target[k])) for k in base.target)
            np.testing.assert_array_equal(np.asarray(other.bounds, dtype=float), np.asarray(base.bounds, dtype=float))
    with pytest.raises(gnipy.InputError, match="name: expected one of 'sleigh-steering', 'ball-plate'"):
        worked_problem("sleigh")
    with pytest.raises(gnipy.InputError, match="steps: expected a whole number"):
        worked_problem("ball-plate", 2.5)
