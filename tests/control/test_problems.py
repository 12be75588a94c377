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
from gnipy.control.problems import load_fit_problem

PROBLEM = """\
[system]
model = "chaplygin-sleigh"
params = { m = 1.0 }
[estimate]
params = { I = 1.2, a = 0.5 }
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
                                   "--h", "0.05", "--steps", "60", "--x0", "0,0,0", "--v0", "1,0.4,1",
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
        assert ds["covariance"].shape == (2, 2)
        # the file holds the fitted run: it is the run of the estimated parameters
        truth = gnipy.simulate(gnipy.make_system("chaplygin-sleigh", I=1.5, a=0.4), "gni-trapezoid", (0, 0, 0),
                               (1.0, 0.4, 1.0), h=0.05, steps=60)
        assert np.max(np.abs(ds["q"].values - np.asarray(truth.q))) <= 1e-8
    # h came from the observation file (h = 0.05, not in the problem file)
    assert load_fit_problem(observed / "sleigh-fit.toml").h == 0.05


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
