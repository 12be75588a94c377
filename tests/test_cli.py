"""The `gni` command line, in process (typer's CliRunner).

Runs share one compilation: the same model, h and number of steps wherever possible.
"""

import json
import os

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app

runner = CliRunner()

MODEL = "vertical-disk"
BASE = ["run", MODEL, "--h", "0.1", "--steps", "10"]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error")]


# --------------------------------------------------------------------------------------------
# Successful runs
# --------------------------------------------------------------------------------------------
def test_run_writes_netcdf_with_variables_and_provenance(tmp_path):
    out = tmp_path / "run.nc"
    res = invoke(*BASE, "--out", out)
    assert res.exit_code == 0, res.output
    assert "vertical-disk" in res.output and "gni-trapezoid" in res.output and "error vs exact" in res.output
    ds = xr.load_dataset(out)
    assert ds["t"].dims == ("time",) and ds["q"].dims == ("time", "coordinate")
    assert ds["v"].dims == ("time", "velocity") and ds["energy"].dims == ("time",)
    assert ds["constraint_residual"].dims == ("time", "constraint")
    assert ds.sizes["time"] == 11 and list(ds["coordinate"].values) == ["x", "y", "phi", "theta"]
    a = ds.attrs
    assert a["model"] == MODEL and a["method"] == "gni-trapezoid" and a["h"] == 0.1 and a["steps"] == 10
    assert a["gnipy_version"] == gnipy.__version__ and a["created"] and a["start"]
    assert json.loads(a["params"]) == dict(gnipy.get_model(MODEL).params)
    spec = gnipy.get_model(MODEL)
    q0, v0 = spec.initial_condition(spec.params)
    np.testing.assert_array_equal(a["q0"], q0)
    np.testing.assert_array_equal(a["v0"], v0)
    # the run is the GNI's: constraints to round-off, O(h²) from the exact solution
    assert np.max(np.abs(ds["constraint_residual"].values)) < 1e-12
    qe, _ = spec.exact(dict(spec.params), q0, v0, ds["t"].values)
    err = np.max(np.abs(ds["q"].values - qe))
    assert err == pytest.approx(a["max_error_q_vs_exact"], rel=1e-12)
    assert 1e-6 < err < 0.1**2


def test_run_with_overrides_initial_condition_and_save_stride(tmp_path):
    out = tmp_path / "o.nc"
    x0, v0 = "1,-2,0.5,0", "0,0,0.3,1.5"  # (ẋ, ẏ) off the constraints: projected
    res = invoke(*BASE, "--set", "r=2", "--set", "I_rot=3,m=0.5", "--x0", x0, "--v0", v0, "--project-v0",
                 "--save-every", "4", "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    assert ds.attrs["param_r"] == 2.0 and ds.attrs["param_I_rot"] == 3.0 and ds.attrs["param_m"] == 0.5
    np.testing.assert_allclose(ds["t"].values, [0.0, 0.4, 0.8, 1.0])  # nodes 0, 4, 8 and the last
    np.testing.assert_array_equal(ds["q"].values[0], [1.0, -2.0, 0.5, 0.0])
    vp = ds["v"].values[0]  # the projected v0 is on the constraints ẋ = r cosφ θ̇, ẏ = r sinφ θ̇
    assert vp[0] == pytest.approx(2 * np.cos(0.5) * vp[3]) and vp[1] == pytest.approx(2 * np.sin(0.5) * vp[3])
    np.testing.assert_allclose(ds.attrs["v0"], vp)
    assert ds.attrs["save_every"] == 4 and ds.attrs["project_v0"] == 1


def test_run_reference_method_and_t_final(tmp_path):
    out = tmp_path / "ref.nc"
    res = invoke("run", "rotating-table-ball", "--method", "reference", "--h", "0.25", "--t-final", "2",
                 "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    assert ds.attrs["method"] == "reference" and ds.sizes["time"] == 9
    assert ds.attrs["max_error_q_vs_exact"] < 1e-8 and ds.attrs["invariant_drift_jacobi"] < 1e-10


def test_demo_runs_and_writes(tmp_path):
    out = tmp_path / "demo.nc"
    res = invoke("demo", "--out", out)
    assert res.exit_code == 0, res.output
    assert "rotating-table-ball" in res.output and "error vs exact" in res.output
    ds = xr.load_dataset(out)
    assert ds.attrs["model"] == "rotating-table-ball" and ds.attrs["method"] == "gni-trapezoid"
    err = np.max(np.abs(ds["q"].values - ds["q_exact"].values))
    assert err == pytest.approx(ds.attrs["max_error_q_vs_exact"])
    assert err < 1e-3  # second order, h = 0.01, t = 10
    # the exact solution stored in the file is the model's
    spec = gnipy.get_model("rotating-table-ball")
    qe, ve = spec.exact(dict(spec.params), *spec.initial_condition(spec.params), ds["t"].values)
    np.testing.assert_allclose(ds["q_exact"].values, qe, rtol=0, atol=1e-14)


def test_demo_default_output_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = invoke("demo")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "gnipy-demo.nc").is_file()


def test_listings_version_and_help():
    res = invoke("models")
    assert res.exit_code == 0
    for name in gnipy.model_names():
        assert name in res.output
    assert "Omega=1" in res.output and "I_flip=1" in res.output
    res = invoke("methods")
    assert res.exit_code == 0
    for name in gnipy.method_names():
        assert name in res.output
    res = invoke("--version")
    assert res.exit_code == 0 and gnipy.__version__ in res.output
    for cmd in [[], ["run"], ["demo"], ["models"], ["methods"]]:
        res = invoke(*cmd, "--help")
        assert res.exit_code == 0 and "Usage" in res.output, cmd
    assert "--t-final" in invoke("run", "--help").output


# --------------------------------------------------------------------------------------------
# Bad input: a one-line message naming the option, exit code 2 (1 for failures), no traceback
# --------------------------------------------------------------------------------------------
OUT = "{tmp}/bad.nc"
BAD = [
    (["run", "no-such-model", "--h", "0.1", "--steps", "10"], "MODEL"),
    ([*BASE, "--method", "nope"], "--method"),
    (["run", MODEL, "--h", "0", "--steps", "10"], "--h"),
    (["run", MODEL, "--h", "-0.1", "--steps", "10"], "--h"),
    (["run", MODEL, "--h", "nan", "--steps", "10"], "--h"),
    (["run", MODEL, "--h", "inf", "--steps", "10"], "--h"),
    (["run", MODEL, "--h", "abc", "--steps", "10"], "--h"),
    (["run", MODEL, "--h", "0.1", "--steps", "0"], "--steps"),
    (["run", MODEL, "--h", "0.1", "--steps", "-3"], "--steps"),
    (["run", MODEL, "--h", "0.1", "--steps", "2.5"], "--steps"),
    (["run", MODEL, "--h", "0.1"], "--steps/--t-final"),
    (["run", MODEL, "--h", "0.1", "--steps", "10", "--t-final", "1"], "--steps/--t-final"),
    (["run", MODEL, "--h", "0.3", "--t-final", "1"], "--t-final"),
    (["run", MODEL, "--h", "0.1", "--t-final", "nan"], "--t-final"),
    ([*BASE, "--set", "nonsense=1"], "--set"),
    ([*BASE, "--set", "r"], "--set"),
    ([*BASE, "--set", "=1"], "--set"),
    ([*BASE, "--set", "r=abc"], "--set"),
    ([*BASE, "--set", "r=nan"], "--set"),
    ([*BASE, "--set", "m=-1"], "--set"),
    ([*BASE, "--x0", "1,2,3"], "--x0"),
    ([*BASE, "--x0", "1,2,3,4,5"], "--x0"),
    ([*BASE, "--x0", "1,a,3,4"], "--x0"),
    ([*BASE, "--x0", "1,nan,3,4"], "--x0"),
    ([*BASE, "--v0", "1,0,1"], "--v0"),
    ([*BASE, "--v0", "1,0,x,1"], "--v0"),
    ([*BASE, "--v0", "0,1,1,1"], "--v0"),  # off the constraints (without --project-v0)
    ([*BASE, "--x0", "0,0,1.5,0"], "--v0"),  # default v0 is off the constraints at this heading
    ([*BASE, "--save-every", "0"], "--save-every"),
]


@pytest.mark.parametrize("args, option", BAD, ids=[" ".join(a[1:]) for a, _ in BAD])
def test_bad_input(args, option, tmp_path):
    res = invoke(*args, "--out", tmp_path / "bad.nc")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and option in errors[0], res.output
    assert not (tmp_path / "bad.nc").exists() and os.listdir(tmp_path) == []


def test_v0_off_constraints_hints_at_projection(tmp_path):
    res = invoke(*BASE, "--v0", "0,1,1,1", "--out", tmp_path / "x.nc")
    assert "--project-v0" in _error_lines(res.output)[0]


def test_missing_out_option():
    res = invoke(*BASE)
    assert res.exit_code == 2 and "--out" in res.output and "Traceback" not in res.output


@pytest.mark.parametrize("where", ["missing-dir", "is-dir", "parent-is-file"])
def test_unwritable_output_is_rejected_before_running(where, tmp_path):
    if where == "missing-dir":
        out = tmp_path / "nope" / "x.nc"
    elif where == "is-dir":
        out = tmp_path
    else:
        (tmp_path / "f").write_text("")
        out = tmp_path / "f" / "x.nc"
    res = invoke(*BASE, "--out", out)
    assert res.exit_code == 2 and "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and "--out" in errors[0] and str(out) in errors[0]


def test_unwritable_directory(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "access", lambda *a, **k: False)  # root ignores chmod: simulate it
    res = invoke(*BASE, "--out", tmp_path / "x.nc")
    assert res.exit_code == 2 and "not writable" in _error_lines(res.output)[0]


def test_write_failure_after_the_run(tmp_path, monkeypatch):
    def refuse(self, path=None, *a, **k):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(xr.Dataset, "to_netcdf", refuse)
    res = invoke(*BASE, "--out", tmp_path / "x.nc")
    assert res.exit_code == 1 and "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and "--out" in errors[0] and "Permission denied" in errors[0]
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "exc, code, option",
    [
        (gnipy.SolverFailure("gni-midpoint: step 3 failed", step=3, time=0.3, residual=1.0), 1, "step 3"),
        (gnipy.MethodError("method 'shake' is written for a constant metric"), 2, "--method"),
    ],
)
def test_solver_and_method_errors(exc, code, option, tmp_path, monkeypatch):
    def fail(*a, **k):
        raise exc

    monkeypatch.setattr(gnipy, "simulate", fail)
    res = invoke(*BASE, "--out", tmp_path / "x.nc")
    assert res.exit_code == code and "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and option in errors[0]
    assert os.listdir(tmp_path) == []
