"""Issue 28, point 3, at the command line: `gni control` and `gni fit` are bounded and clean.

Each test folds in one defect the adversarial pass found (D5-D9), through the command line
(typer's CliRunner, in process):

- D5: a problem's name holding rich markup or escape sequences is shown literally (report lines,
  the progress bar, the figure's title);
- D6: a problem whose memory is estimated beyond gnipy's bound is refused before anything is
  compiled or allocated, naming `horizon.steps` / `observations.file/integration.h`; `--yes`
  lifts the bound;
- D7/D8: bad problem files and bad observation files are one-line errors naming the key, exit 2;
- D9: a string or a boolean is not a number anywhere in the files; every message names a key of
  the problem file or an option the command has; the progress count never passes its total.

A tripwire replaces every entry point of a computation (the simulations of gnipy.control and
optimistix's solver) with a function that raises: a refusal that came too late fails the test
instead of slowing it down.
"""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy.resources
from gnipy.cli import app, resources
from gnipy.control.problems import WORKED_PROBLEMS

runner = CliRunner()

SLEIGH = WORKED_PROBLEMS["sleigh-steering"]
FIT = """\
[system]
model = "chaplygin-sleigh"
params = { m = 1.0 }
[estimate]
params = { I = 1.2, a = 0.5 }
[observations]
file = "obs.nc"
variables = ["x", "y"]
[start]
q0 = [0.0, 0.0, 0.0]
v0 = [1.0, 0.4, 1.0]
[integration]
method = "gni-trapezoid"
"""

#: The options each command has: a message may name these and no other.
OPTIONS = {"control": {"--out", "--plot", "--overwrite", "--yes", "--example", "--print"},
           "fit": {"--out", "--plot", "--overwrite", "--yes"}}


class ReachedComputation(Exception):
    """A command got past its checks to a computation."""


def _tripwire(*args, **kwargs):
    raise ReachedComputation("reached a computation")


@pytest.fixture
def tripwire(monkeypatch):
    import optimistix

    import gnipy.control.identification as identification
    import gnipy.control.least_squares as least_squares
    import gnipy.control.shooting as shooting

    monkeypatch.setattr(shooting, "simulate", _tripwire)
    monkeypatch.setattr(identification, "simulate", _tripwire)
    monkeypatch.setattr(least_squares, "simulate", _tripwire)
    monkeypatch.setattr(optimistix, "least_squares", _tripwire)


def observation_file(path, *, h=0.05, times=None, q=None, attrs=None):
    """A small result file as `gni run` writes one (q, v on the time grid, h recorded), written
    without computing anything."""
    t = h * np.arange(11) if times is None else np.asarray(times, dtype=float)
    q = np.stack([t, 0.4 * t, 0.1 * t], axis=1) if q is None else q
    ds = xr.Dataset({"q": (("time", "coordinate"), q), "v": (("time", "velocity"), np.ones((len(t), 3)))},
                    coords={"time": t, "coordinate": ["x", "y", "theta"], "velocity": ["dx", "dy", "dtheta"]},
                    attrs={"h": h} if attrs is None else attrs)
    ds.to_netcdf(path)
    return path


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def assert_refused(res, *words, command: str, code: int = 2) -> str:
    """Exit `code`, no traceback, one error line holding every word and naming only the command's
    own options."""
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1, res.output
    for word in words:
        assert word in errors[0], (word, errors[0])
    assert set(re.findall(r"--[a-z][a-z0-9-]*", errors[0])) <= OPTIONS[command], errors[0]
    return errors[0]


def control(tmp_path, text, *extra):
    (tmp_path / "p.toml").write_bytes(text if isinstance(text, bytes) else text.encode())
    return invoke("control", tmp_path / "p.toml", "--out", tmp_path / "out.nc", *extra)


def fit(tmp_path, text, *extra, obs=True):
    if obs:
        observation_file(tmp_path / "obs.nc")
    (tmp_path / "p.toml").write_bytes(text if isinstance(text, bytes) else text.encode())
    return invoke("fit", tmp_path / "p.toml", "--out", tmp_path / "out.nc", *extra)


# --------------------------------------------------------------------------------------------------
# D5: names shown literally
# --------------------------------------------------------------------------------------------------
NASTY_NAME = "[/bold]x[red \x1b]0;owned\x07 \x1b[2J $x^"


class _FakeControlResult:
    success, method = True, "gni-trapezoid"

    def summary(self):
        return "optimal control: converged"


def test_a_problems_name_is_shown_literally_in_the_report_and_the_bar(tmp_path, monkeypatch):
    from gnipy.cli import control as control_cli
    from gnipy.cli import progress
    from gnipy.control import problems

    def solve(self, progress=False, check_continuous=True, max_bytes="auto"):
        progress(1, 1.0, 0.5, 60)
        return _FakeControlResult()

    monkeypatch.setattr(problems.ControlProblem, "solve", solve)
    monkeypatch.setattr(problems, "write_control_result", lambda *a, **k: None)
    monkeypatch.setattr(progress, "on_terminal", lambda: True)  # the rich bar, with the name beside it
    text = SLEIGH.replace('name = "sleigh-steering"', f"name = {json.dumps(NASTY_NAME)}")  # JSON's escapes are TOML's
    res = control(tmp_path, text)
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output and "\x1b" not in res.output and "\x07" not in res.output
    assert "gni control: [/bold]x[red \\x1b]0;owned\\x07 \\x1b[2J $x^" in res.output
    assert control_cli.plot_title("a $x^ \x1b") == "a \\$x^ \\x1b"


def test_a_name_with_markup_and_dollars_makes_a_figure(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gnipy.cli.control import plot_title

    fig = plt.figure()
    fig.suptitle(plot_title(NASTY_NAME + ": gni-trapezoid"))
    fig.savefig(tmp_path / "t.png")  # an unclosed $x^ read as mathematics would fail here
    plt.close(fig)
    assert (tmp_path / "t.png").stat().st_size > 0


# --------------------------------------------------------------------------------------------------
# D6: resource bounds, before anything is compiled or allocated; --yes lifts them
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("steps", [3_000_000_000, 100_000_000, 20_000])
def test_control_beyond_the_memory_bound_is_refused_at_once(tmp_path, tripwire, steps):
    start = time.process_time()  # CPU time: nothing allocated or computed, whatever the machine's load
    res = control(tmp_path, SLEIGH.replace("steps = 80", f"steps = {steps}"))
    assert time.process_time() - start < 1.0
    err = assert_refused(res, "horizon.steps:", f"{steps:,} steps", "--yes", command="control")
    assert "bound" in err and not (tmp_path / "out.nc").exists()


def test_control_yes_lifts_the_memory_bound(tmp_path, tripwire, monkeypatch):
    monkeypatch.setattr(gnipy.resources, "MAX_MEMORY_BYTES", 10_000)  # the worked problem needs more
    assert_refused(control(tmp_path, SLEIGH), "horizon.steps:", "--yes", command="control")
    res = control(tmp_path, SLEIGH, "--yes")
    assert isinstance(res.exception, ReachedComputation), res.output  # past the bound, to the solve


def test_control_result_file_beyond_the_free_space_is_refused(tmp_path, tripwire, monkeypatch):
    import shutil

    class Usage:
        free = 10

    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage)
    assert_refused(control(tmp_path, SLEIGH), "horizon.steps:", "free", "--yes", command="control")


def test_fit_whose_span_is_beyond_the_memory_bound_is_refused_at_once(tmp_path, tripwire):
    observation_file(tmp_path / "obs.nc", times=[0.05, 3e6], q=np.zeros((2, 3)))  # 6·10⁷ steps of 0.05
    (tmp_path / "p.toml").write_text(FIT)
    start = time.process_time()
    res = invoke("fit", tmp_path / "p.toml", "--out", tmp_path / "out.nc")
    assert time.process_time() - start < 1.0
    assert_refused(res, "observations.file/integration.h:", "60,000,001 nodes", "--yes", command="fit")
    res = invoke("fit", tmp_path / "p.toml", "--out", tmp_path / "out.nc", "--yes")
    assert isinstance(res.exception, ReachedComputation), res.output  # --yes: on to the fit


# --------------------------------------------------------------------------------------------------
# D7, D8, D9: bad problem files and observation files
# --------------------------------------------------------------------------------------------------
CONTROL_CASES = [
    # D7
    (b'name = "\xff\xfe"\n' + SLEIGH.encode(), ["problem:", "UTF-8"]),
    (SLEIGH.replace("torque = { dtheta = 1.0 }", "torque = { dtheta = 0.0 }"), ["inputs.torque:", "zero"]),
    (SLEIGH.replace("params = { m = 1.0, I = 1.0, a = 0.5 }", "params = 5"), ["system.params:"]),
    # D9: strings and booleans are not numbers
    (SLEIGH.replace("torque = { dtheta = 1.0 }", 'torque = { dtheta = "1" }'), ["inputs.torque:", "'1'"]),
    (SLEIGH.replace("m = 1.0,", 'm = "1",'), ["system.params.m:", "string"]),
    (SLEIGH.replace("x = 1.0", "x = true"), ["target.x:", "boolean"]),
    (SLEIGH.replace("effort = 1.0", "effort = true"), ["solver.effort:", "boolean"]),
    (SLEIGH.replace("h = 0.05", 'h = "0.05"'), ["horizon.h:"]),
    (SLEIGH.replace("steps = 80", "steps = 80.0"), ["horizon.steps:"]),
    (SLEIGH.replace("bounds = [-1.5, 1.5]", 'bounds = ["-1.5", 1.5]'), ["solver.bounds:"]),
    (SLEIGH.replace("periods = 1.0", "periods = false"), ["warm_start.periods:"]),
    (SLEIGH.replace('method = "gni-trapezoid"', "method = 5"), ["solver.method:"]),
    (SLEIGH.replace('name = "sleigh-steering"', "name = 5"), ["name:"]),
    # every other key: lists, ranges, NaN/inf, shapes, names, empty tables
    (SLEIGH.replace("h = 0.05", "h = [0.05]"), ["horizon.h:"]),
    (SLEIGH.replace("h = 0.05", "h = -0.05"), ["horizon.h:"]),
    (SLEIGH.replace("h = 0.05", "h = nan"), ["horizon.h:"]),
    (SLEIGH.replace("h = 0.05", "h = 1e-320"), ["horizon.h:", "below"]),
    (SLEIGH.replace("h = 0.05", "h = 1e308"), ["horizon:", "finite"]),
    (SLEIGH.replace("steps = 80", "steps = 0"), ["horizon.steps:"]),
    (SLEIGH.replace("steps = 80", "steps = 1"), ["horizon.steps:", "3 conditions"]),
    (SLEIGH.replace("x = 1.0", "x = inf"), ["target.x:", "finite"]),
    (SLEIGH.replace("x = 1.0", "z = 1.0"), ["target:", "'z'"]),
    (SLEIGH.replace("effort = 1.0", "effort = -1.0"), ["solver.effort:"]),
    (SLEIGH.replace("effort = 1.0", "effort = 1.0\nsmoothness = -inf"), ["solver.smoothness:"]),
    (SLEIGH.replace("effort = 1.0", "effort = 1.0\nmax_iterations = 0"), ["solver.max_iterations:"]),
    (SLEIGH.replace("effort = 1.0", "effort = 1.0\nmax_iterations = 9223372036854775807"),
     ["solver.max_iterations:"]),
    (SLEIGH.replace("effort = 1.0", "effort = 1.0\nsegments = 81"), ["solver.segments:", "horizon.steps"]),
    (SLEIGH.replace("bounds = [-1.5, 1.5]", "bounds = [1.5, -1.5]"), ["solver.bounds:", "lower < upper"]),
    (SLEIGH.replace("bounds = [-1.5, 1.5]", "bounds = [nan, 1.5]"), ["solver.bounds:"]),
    (SLEIGH.replace("bounds = [-1.5, 1.5]", "bounds = [[-1, -1], 1.5]"), ["solver.bounds:"]),
    (SLEIGH.replace("bounds = [-1.5, 1.5]", "bounds = [-1.5]"), ["solver.bounds:"]),
    (SLEIGH.replace("q0 = [0.0, 0.0, 0.0]", "q0 = [0.0, 0.0]"), ["start.q0:", "3 numbers"]),
    (SLEIGH.replace("v0 = [0.0, 0.0, 0.0]", 'v0 = [0.0, 0.0, "0"]'), ["start.v0:"]),
    (SLEIGH.replace("v0 = [0.0, 0.0, 0.0]", "v0 = [0.0, 0.0, 0.0]\nR0 = [[1.0]]"), ["start.R0:", "orientation"]),
    (SLEIGH.replace("amplitude = [1.0]", "amplitude = [1.0, 2.0]"), ["warm_start.amplitude:"]),
    (SLEIGH.replace("torque = { dtheta = 1.0 }", "torque = { dphi = 1.0 }"), ["inputs.torque:", "'dphi'"]),
    (SLEIGH.replace("torque = { dtheta = 1.0 }", "torque = {}"), ["inputs.torque:"]),
    ("inputs = 3\n" + SLEIGH.replace("[inputs]\ntorque = { dtheta = 1.0 }", ""), ["inputs:", "table"]),
    (SLEIGH.replace("x = 1.0\ny = 0.5\ntheta = 0.0", ""), ["target:", "empty"]),
    (SLEIGH.replace('model = "chaplygin-sleigh"', 'model = "no-such-model"'), ["system.model:"]),
    (SLEIGH.replace("m = 1.0,", "mass = 1.0,"), ["system.params:", "'mass'"]),
    (SLEIGH + "\n[extra]\na = 1\n", ["problem:", "extra"]),
    (SLEIGH.replace('method = "gni-trapezoid"', 'method = "no-such"'), ["solver.method:", "unknown method"]),
    (SLEIGH.replace('method = "gni-trapezoid"', 'method = "reference"'), ["solver.method:", "differentiated"]),
]


@pytest.mark.parametrize("text, words", CONTROL_CASES, ids=range(len(CONTROL_CASES)))
def test_bad_control_problem_files_name_the_key(tmp_path, tripwire, text, words):
    assert_refused(control(tmp_path, text), *words, command="control")
    assert not (tmp_path / "out.nc").exists()


def test_rolling_ball_target_must_be_a_rotation(tmp_path, tripwire):
    ball = WORKED_PROBLEMS["ball-plate"]
    bad = ball.replace("R = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]",
                       "R = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]")  # a reflection
    assert_refused(control(tmp_path, bad), "target.R:", "rotation", command="control")
    bad = ball.replace("v0 = [0.0, 0.0, 0.0, 0.0, 0.0]",
                       "v0 = [0.0, 0.0, 0.0, 0.0, 0.0]\nR0 = [[2.0, 0, 0], [0, 1, 0], [0, 0, 1]]")
    assert_refused(control(tmp_path, bad), "start.R0:", "rotation", command="control")


def test_a_velocity_off_the_constraints_names_the_key_and_what_the_file_can_say(tmp_path):
    """The library's message suggests project_v0=True (gnipy.simulate's keyword): the command line
    says which key of the file does that, never an option gni control does not have."""
    text = SLEIGH.replace("v0 = [0.0, 0.0, 0.0]", "v0 = [0.0, 1.0, 0.0]")  # sideways: the knife edge forbids it
    err = assert_refused(control(tmp_path, text), "start.v0:", "project_v0 = true in [start]", command="control")
    assert "--project-v0" not in err


def _dataset_variants(tmp_path):
    t = 0.05 * np.arange(11)
    base = xr.Dataset({"q": (("time", "coordinate"), np.zeros((11, 3)))},
                      coords={"time": t, "coordinate": ["x", "y", "theta"]}, attrs={"h": 0.05})
    extra = xr.Dataset({"q": (("time", "coordinate", "extra"), np.zeros((11, 3, 1)))},
                       coords={"time": t, "coordinate": ["x", "y", "theta"]})
    no_time = xr.Dataset({"q": (("step", "coordinate"), np.zeros((11, 3)))}, coords={"coordinate": ["x", "y", "theta"]})
    strings = base.copy()
    strings["q"] = (("time", "coordinate"), np.zeros((11, 3)).astype(str))
    dates = base.assign_coords(time=np.array(["2020-01-01"] * 11, dtype="datetime64[ns]"))
    variants = {"extra": extra, "no_time": no_time, "strings": strings, "dates": dates}
    for name, ds in variants.items():
        ds.to_netcdf(tmp_path / f"{name}.nc")
    (tmp_path / "empty.nc").write_bytes(b"")
    (tmp_path / "garbage.nc").write_bytes(b"CDF\x01" + bytes(range(256)) * 4)
    base.to_netcdf(tmp_path / "whole.nc")
    data = (tmp_path / "whole.nc").read_bytes()
    (tmp_path / "truncated.nc").write_bytes(data[: len(data) // 2])
    (tmp_path / "text.nc").write_text("not a netCDF file\n")


FILE_CASES = {"extra": "dimensions", "no_time": "dimensions", "strings": "not numbers", "dates": "not numbers",
              "empty": "empty", "garbage": "", "truncated": "", "text": "cannot read"}


@pytest.mark.parametrize("name", list(FILE_CASES))
def test_bad_observation_files_name_observations_file(tmp_path, tripwire, name):
    _dataset_variants(tmp_path)
    text = FIT.replace('file = "obs.nc"', f'file = "{name}.nc"')
    err = assert_refused(fit(tmp_path, text, obs=False), "observations.file:", f"{name}.nc", FILE_CASES[name],
                         command="fit")
    assert "--out" not in err


@pytest.mark.parametrize("h", ['"abc"', "[0.05, 0.1]", "-0.05", "missing"])
def test_an_unusable_h_attribute_names_integration_h(tmp_path, tripwire, h):
    import netCDF4

    observation_file(tmp_path / "obs.nc")
    with netCDF4.Dataset(tmp_path / "obs.nc", "a") as nc:
        if h == "missing":
            nc.delncattr("h")
        else:
            nc.setncattr("h", {'"abc"': "abc", "[0.05, 0.1]": np.array([0.05, 0.1]), "-0.05": -0.05}[h])
    text = FIT.replace('method = "gni-trapezoid"\n', "")
    assert_refused(fit(tmp_path, text, obs=False), "integration.h:", command="fit")


FIT_CASES = [
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = 3"), ["estimate.params:", "table"]),
    (FIT.replace("I = 1.2", 'I = "1.2"'), ["estimate.params.I:", "string"]),
    (FIT.replace("m = 1.0", "m = true"), ["system.params.m:", "boolean"]),
    (FIT.replace('variables = ["x", "y"]', 'variables = ["x", "y"]\nsigma = 1e-320'), ["observations.sigma:"]),
    (FIT.replace('variables = ["x", "y"]', 'variables = ["x", "y"]\nsigma = "0.1"'), ["observations.sigma:"]),
    (FIT.replace('variables = ["x", "y"]', 'variables = ["x", "y"]\nsigma = nan'), ["observations.sigma:"]),
    (FIT.replace('variables = ["x", "y"]', 'variables = ["x", "q"]'), ["observations.variables:", "'q'"]),
    (FIT.replace('variables = ["x", "y"]', 'variables = ["x", "x"]'), ["observations.variables:"]),
    (FIT.replace('variables = ["x", "y"]', "variables = [1]"), ["observations.variables:"]),
    (FIT.replace('file = "obs.nc"', "file = 5"), ["observations.file:"]),
    (FIT.replace('file = "obs.nc"', 'file = "missing.nc"'), ["observations.file:", "missing.nc"]),
    (FIT.replace("q0 = [0.0, 0.0, 0.0]", "q0 = [0.0, 0.0]"), ["start.q0:"]),
    (FIT.replace("v0 = [1.0, 0.4, 1.0]", "v0 = [1.0, 0.4, true]"), ["start.v0:"]),
    (FIT.replace('method = "gni-trapezoid"', 'method = "gni-trapezoid"\nh = "0.05"'), ["integration.h:"]),
    (FIT.replace('method = "gni-trapezoid"', 'method = "gni-trapezoid"\nt0 = inf'), ["integration.t0:"]),
    (FIT.replace('method = "gni-trapezoid"', "method = 1"), ["integration.method:"]),
    (FIT.replace('method = "gni-trapezoid"', 'method = "reference"'), ["integration.method:", "differentiated"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = 1.2, m = 0.5 }"), ["estimate.params:", "'m'"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { b = 1.0 }"), ["estimate.params:", "'b'"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "initial = ['q0', 'q0']"), ["estimate.initial:"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = {}"), ["estimate:", "nothing"]),
    (FIT.replace("[estimate]\nparams = { I = 1.2, a = 0.5 }\n", ""), ["estimate:", "missing"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = 1.2, a = 0.5 }\nbounds = { I = [1, 0] }"),
     ["estimate.bounds.I:", "lower bound"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = 1.2, a = 0.5 }\nbounds = { I = [2, 3] }"),
     ["estimate.bounds.I:", "not strictly inside"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = 1.2, a = 0.5 }\nbounds = { m = [0, 3] }"),
     ["estimate.bounds.m:", "not an estimated"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = 1.2, a = 0.5 }\nbounds = { a = [0, \"1\"] }"),
     ["estimate.bounds.a:", "[lower, upper]"]),
    (FIT.replace("params = { I = 1.2, a = 0.5 }", "params = { I = -1.2, a = 0.5 }"),
     ["estimate.params.I:", "must be positive", "[-inf, inf]"]),
]


@pytest.mark.parametrize("text, words", FIT_CASES, ids=range(len(FIT_CASES)))
def test_bad_fit_problem_files_name_the_key(tmp_path, tripwire, text, words):
    assert_refused(fit(tmp_path, text), *words, command="fit")
    assert not (tmp_path / "out.nc").exists()


def test_messages_from_gnipy_fit_name_keys_of_the_file(tmp_path, tripwire):
    """An error that gnipy.fit finds (an observation time off the step grid of h) names the
    problem file's keys, not gnipy's arguments."""
    text = FIT.replace('method = "gni-trapezoid"', 'method = "gni-trapezoid"\nh = 0.03')
    err = assert_refused(fit(tmp_path, text), "observations.file:", "not a node", command="fit")
    assert not err.startswith("Error: observations:")


# --------------------------------------------------------------------------------------------------
# D9: the progress count never passes its total
# --------------------------------------------------------------------------------------------------
def test_control_progress_total_grows_with_the_fallback(tmp_path, monkeypatch):
    from gnipy.control import problems

    def solve(self, progress=False, check_continuous=True, max_bytes="auto"):
        # what solve_optimal_control reports when SLSQP stops failing at 60 of 60 and the fallback runs
        for i in range(1, 61):
            progress(i, 1.0, 0.5, 60)
        for i in range(61, 71):
            progress(i, 1.0, 0.5, 60 + 120)
        return _FakeControlResult()

    monkeypatch.setattr(problems.ControlProblem, "solve", solve)
    monkeypatch.setattr(problems, "write_control_result", lambda *a, **k: None)
    res = control(tmp_path, SLEIGH.replace("effort = 1.0", "effort = 1.0\nmax_iterations = 60"))
    assert res.exit_code == 0, res.output
    counts = [tuple(map(int, m)) for m in re.findall(r"control: (\d+)/(\d+) iterations", res.output)]
    assert counts and counts[-1] == (70, 180)
    assert all(done <= total for done, total in counts), counts
