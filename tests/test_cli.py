"""The `gni` command line, in process (typer's CliRunner).

Runs share one compilation: the same model, h and number of steps wherever possible.
"""

import json
import os

import numpy as np
import pytest
import xarray as xr
import typer
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app

runner = CliRunner()

MODEL = "vertical-disk"
BASE = ["run", MODEL, "--method", "gni-trapezoid", "--h", "0.1", "--steps", "10"]


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
    assert ds["time"].dtype == np.float64 and ds["q"].dims == ("time", "coordinate")
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
    qe, _ = spec.exact(dict(spec.params), q0, v0, ds["time"].values)
    err = np.max(np.abs(ds["q"].values - qe))
    assert err == pytest.approx(a["max_error_q_vs_exact"], rel=1e-12)
    assert 1e-6 < err < 0.1**2


def test_run_with_overrides_initial_condition_and_save_stride(tmp_path):
    out = tmp_path / "o.nc"
    x0, v0 = "1,-2,0.5,0", "0,0,0.3,1.5"  # (ẋ, ẏ) off the constraints: projected
    res = invoke(*BASE, "--set", "r=2", "--set", "I_rot=3,m=0.5", "--q0", x0, "--v0", v0, "--project-v0",
                 "--save-every", "4", "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    assert ds.attrs["param_r"] == 2.0 and ds.attrs["param_I_rot"] == 3.0 and ds.attrs["param_m"] == 0.5
    np.testing.assert_allclose(ds["time"].values, [0.0, 0.4, 0.8, 1.0])  # steps 0, 4, 8 and the last
    np.testing.assert_array_equal(ds["node"].values, [0, 1, 2, 3])
    np.testing.assert_array_equal(ds["step"].values, [0, 4, 8, 10])
    np.testing.assert_array_equal(ds["q"].sel(time=0.8).values, ds["q"].values[2])
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
    qe, ve = spec.exact(dict(spec.params), *spec.initial_condition(spec.params), ds["time"].values)
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
    # each model's measured default and why (gnipy.models.default_methods)
    for name in gnipy.model_names():
        spec = gnipy.get_model(name)
        assert f"default method: {spec.default_method} (best error against the reference" in " ".join(res.output.split()), name
        # the velocity names a problem file's [inputs] and targets use (issue 34)
        system = gnipy.make_system(name)
        assert f"v = ({', '.join(system.velocities)})" in " ".join(res.output.split()), name
    res = invoke("methods")
    assert res.exit_code == 0
    for name in gnipy.method_names():
        assert name in res.output
    res = invoke("--version")
    assert res.exit_code == 0 and gnipy.__version__ in res.output
    for cmd in [[], ["run"], ["demo"], ["models"], ["methods"], ["convergence"], ["info"]]:
        res = invoke(*cmd, "--help")
        assert res.exit_code == 0 and "Usage" in res.output, cmd
    assert "--t-final" in invoke("run", "--help").output
    assert "--config" in invoke("run", "--help").output and "--plot" in invoke("run", "--help").output
    assert "--h-max" in invoke("convergence", "--help").output


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
    ([*BASE, "--q0", "1,2,3"], "--q0"),
    ([*BASE, "--q0", "1,2,3,4,5"], "--q0"),
    ([*BASE, "--q0", "1,a,3,4"], "--q0"),
    ([*BASE, "--q0", "1,nan,3,4"], "--q0"),
    ([*BASE, "--v0", "1,0,1"], "--v0"),
    ([*BASE, "--v0", "1,0,x,1"], "--v0"),
    ([*BASE, "--v0", "0,1,1,1"], "--v0"),  # off the constraints (without --project-v0)
    ([*BASE, "--q0", "0,0,1.5,0"], "--v0"),  # default v0 is off the constraints at this heading
    ([*BASE, "--save-every", "0"], "--save-every"),
    ([*BASE, "--plot", "{tmp}/figure.unknown-format"], "--plot"),
    ([*BASE, "--plot", "{tmp}/no-such-dir/figure.png"], "--plot"),
    ([*BASE, "--config", "{tmp}/no-such-config.toml"], "--config"),
    (["run", "--h", "0.1", "--steps", "10"], "MODEL"),
    (["run", MODEL, "--steps", "10"], "--h"),
]


@pytest.mark.parametrize("args, option", BAD, ids=[" ".join(a[1:]) for a, _ in BAD])
def test_bad_input(args, option, tmp_path):
    args = [str(a).replace("{tmp}", str(tmp_path)) for a in args]
    res = invoke(*args, "--out", tmp_path / "bad.nc")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and option in errors[0], res.output
    assert not (tmp_path / "bad.nc").exists() and os.listdir(tmp_path) == []


def test_v0_off_constraints_hints_at_projection(tmp_path):
    res = invoke(*BASE, "--v0", "0,1,1,1", "--out", tmp_path / "x.nc")
    assert "--project-v0" in _error_lines(res.output)[0]


def test_run_without_out_prints_the_summary_and_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = invoke(*BASE)
    assert res.exit_code == 0, res.output
    assert "vertical-disk" in res.output and "error vs exact" in res.output and "written" not in res.output
    assert os.listdir(tmp_path) == []
    # a figure alone is written, and said
    res = invoke(*BASE, "--plot", "run.png")
    assert res.exit_code == 0 and "written: run.png" in res.output and os.listdir(tmp_path) == ["run.png"]


@pytest.mark.parametrize("extra", [["--checkpoint-every", "5"], ["--checkpoint-every", "5", "--resume"],
                                   ["--save-every", "1", "--steps", "1000001"]])
def test_a_streamed_run_needs_out(extra, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = invoke(*BASE, *extra)
    errors = _error_lines(res.output)
    assert res.exit_code == 2 and len(errors) == 1 and "--out" in errors[0] and "Traceback" not in res.output
    assert os.listdir(tmp_path) == []


def test_the_model_is_checked_before_the_output_path(tmp_path):
    for out in (["--out", tmp_path / "missing" / "x.nc"], []):  # a bad --out, or none (once "--out missing")
        res = invoke("run", "no-such-model", "--h", "0.1", "--steps", "10", *out)
        errors = _error_lines(res.output)
        assert res.exit_code == 2 and len(errors) == 1 and "MODEL" in errors[0] and "--out" not in errors[0], res.output


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


# --------------------------------------------------------------------------------------------
# gni run --plot and --config
# --------------------------------------------------------------------------------------------
def _same_run(a: xr.Dataset, b: xr.Dataset):
    """The same data and the same run attributes (not the creation time, in `created` and `history`,
    or the config file)."""
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    skip = {"created", "history", "config_file"}
    assert {k for k in a.attrs if k not in skip} == {k for k in b.attrs if k not in skip}
    for k in a.attrs:
        if k not in skip:
            np.testing.assert_array_equal(a.attrs[k], b.attrs[k], err_msg=k)


def test_run_plot_writes_png(tmp_path):
    out, png = tmp_path / "run.nc", tmp_path / "run.png"
    res = invoke(*BASE, "--out", out, "--plot", png)
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert f"written: {out}, {png}" in res.output


def test_config_file_gives_the_same_run_as_options(tmp_path):
    x0, v0 = "0.5,-1,0,0", "1,0,0,1"
    res = invoke(*BASE, "--method", "gni-trapezoid", "--set", "r=1", "--q0", x0, "--v0", v0, "--save-every", "2",
                 "--out", tmp_path / "options.nc")
    assert res.exit_code == 0, res.output
    (tmp_path / "run.toml").write_text(
        '# a run of the vertical disk\n'
        'model = "vertical-disk"\nmethod = "gni-trapezoid"\nh = 0.1\nsteps = 10\n'
        'set = { r = 1 }\nx0 = [0.5, -1, 0, 0]\nv0 = "1,0,0,1"\nsave-every = 2\n'
        'out = "config.nc"\nplot = "config.png"\n'
    )
    res = invoke("run", "--config", tmp_path / "run.toml")
    assert res.exit_code == 0, res.output
    # relative paths in the file are relative to the file's directory
    assert (tmp_path / "config.png").is_file()
    a, b = xr.load_dataset(tmp_path / "options.nc"), xr.load_dataset(tmp_path / "config.nc")
    _same_run(a, b)
    assert b.attrs["config_file"] == str(tmp_path / "run.toml")
    # keys with underscores and `set` as a list of strings work the same
    (tmp_path / "run2.toml").write_text(
        'model = "vertical-disk"\nmethod = "gni-trapezoid"\nh = 0.1\nt_final = 1.0\nset = ["r=1"]\nx0 = [0.5, -1, 0, 0]\n'
        'v0 = [1, 0, 0, 1]\nsave_every = 2\nproject_v0 = false\nout = "config2.nc"\n'
    )
    res = invoke("run", "--config", tmp_path / "run2.toml")
    assert res.exit_code == 0, res.output
    _same_run(a, xr.load_dataset(tmp_path / "config2.nc"))


def test_x0_is_the_older_name_of_q0(tmp_path):
    """`--x0` and the config key `x0` still give q0 (the library's name); both keys in one file are refused."""
    runs = {}
    for name, args in {"q0": ["--q0", "1,2,0,0"], "x0": ["--x0", "1,2,0,0"], "key": ["--config", tmp_path / "run.toml"]}.items():
        (tmp_path / "run.toml").write_text('x0 = [1, 2, 0, 0]\n')
        res = invoke(*BASE, *args, "--out", tmp_path / f"{name}.nc")
        assert res.exit_code == 0, res.output
        runs[name] = xr.load_dataset(tmp_path / f"{name}.nc")["q"].values
        np.testing.assert_array_equal(runs[name][0], [1.0, 2.0, 0.0, 0.0])
    np.testing.assert_array_equal(runs["x0"], runs["q0"])
    np.testing.assert_array_equal(runs["key"], runs["q0"])
    (tmp_path / "both.toml").write_text('x0 = [1, 2, 0, 0]\nq0 = [1, 2, 0, 0]\n')
    res = invoke(*BASE, "--config", tmp_path / "both.toml")
    assert res.exit_code == 2 and "'x0' and 'q0'" in _error_lines(res.output)[0], res.output
    res = invoke(*BASE, "--x0", "1,2,3")
    assert res.exit_code == 2 and "--q0" in _error_lines(res.output)[0], res.output


def test_command_line_overrides_config(tmp_path):
    (tmp_path / "run.toml").write_text(
        'model = "vertical-disk"\nmethod = "no-such-method"\nh = 0.1\nsteps = 3\n'
        'x0 = [9, 9, 0, 0]\nset = { r = 1, m = 2 }\nout = "from-config.nc"\n'
    )
    out = tmp_path / "from-cli.nc"
    res = invoke("run", "--config", tmp_path / "run.toml", "--method", "gni-trapezoid", "--t-final", "1",
                 "--q0", "1,2,0,0", "--set", "m=1", "--out", out)
    assert res.exit_code == 0, res.output
    assert out.is_file() and not (tmp_path / "from-config.nc").exists()
    ds = xr.load_dataset(out)
    assert ds.attrs["method"] == "gni-trapezoid" and ds.attrs["steps"] == 10  # --t-final beats steps
    np.testing.assert_array_equal(ds.attrs["q0"], [1.0, 2.0, 0.0, 0.0])
    assert ds.attrs["param_m"] == 1.0 and ds.attrs["param_r"] == 1.0  # --set wins per name


CONFIG_ERRORS = [
    ('model = "vertical-disk"\nh = [0.1\n', ["run.toml", "not valid TOML"]),
    ('model = "vertical-disk"\nh = 0.1 0.2\n', ["run.toml", "not valid TOML", "line 2"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10\nstep-size = 0.1\n', ["run.toml", "'step-size'", "unknown key"]),
    ('model = "vertical-disk"\nh = "fast"\nsteps = 10\n', ["run.toml", "'h'", "must be a number"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10.5\n', ["run.toml", "'steps'", "must be an integer"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10\nproject-v0 = 1\n', ["'project-v0'", "true or false"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10\nx0 = [1, "a", 0, 0]\n', ["'x0'", "list of numbers"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10\nset = { r = "big" }\n', ["'set.r'", "must be a number"]),
    ('model = "vertical-disk"\nh = 0.1\nsteps = 10\nx0 = [1, 2]\n', ["--q0", "'x0' in", "run.toml"]),
    ('model = "vertical-disk"\nh = -1\nsteps = 10\n', ["--h", "'h' in", "run.toml"]),
    ('model = "no-such-model"\nh = 0.1\nsteps = 10\n', ["MODEL", "'model' in", "run.toml"]),
    ('[model]\nname = "vertical-disk"\n', ["'model'", "must be a string"]),
    (b'model = "\xff"\n', ["run.toml", "not valid TOML"]),
]


@pytest.mark.parametrize("text, words", CONFIG_ERRORS, ids=[f"config-{i}" for i in range(len(CONFIG_ERRORS))])
def test_bad_config_file(text, words, tmp_path):
    path = tmp_path / "run.toml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    res = invoke("run", "--config", path, "--out", tmp_path / "x.nc")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1, res.output
    for word in words:
        assert word in errors[0], errors[0]
    assert sorted(os.listdir(tmp_path)) == ["run.toml"]


def test_config_keys_are_the_options_of_gni_run():
    """The keys of --config are read from `gni run`'s own declarations: checked here against the
    command as click builds it (its parameters, their long names and types), so that an option
    added to `gni run` is a key (or named command-line only) without a second list."""
    from gnipy.cli.run import CONFIG_KEYS

    command = typer.main.get_command(app).commands["run"]
    only = {"--config", "--resume", "--overwrite", "--yes", "--accept-out-of-band"}
    expected = {}
    for param in command.params:
        longs = [o for o in param.opts if o.startswith("--")]
        if not longs:
            expected[param.name] = "MODEL"
        elif longs[0] not in only:
            expected.update({o[2:].replace("-", "_"): longs[0] for o in longs})
    assert {key: option for key, (option, _) in CONFIG_KEYS.items()} == expected
    # what each key must hold: the types of the options (the values' checks: CONFIG_ERRORS below)
    kinds = {"h": "number", "t_final": "number", "steps": "integer", "save_every": "integer",
             "checkpoint_every": "integer", "project_v0": "boolean", "out": "path", "plot": "path"}
    assert {key: CONFIG_KEYS[key][1] for key in kinds} == kinds
    assert {k for k, (_, kind) in CONFIG_KEYS.items() if kind == "vector"} == {"q0", "x0", "v0", "R0"}
    assert CONFIG_KEYS["set"][1] == "set" and CONFIG_KEYS["model"][1] == CONFIG_KEYS["method"][1] == "string"


# --------------------------------------------------------------------------------------------
# gni info
# --------------------------------------------------------------------------------------------
def test_info_summarizes_a_run_file(tmp_path):
    out = tmp_path / "run.nc"
    assert invoke(*BASE, "--out", out).exit_code == 0
    res = invoke("info", out)
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    for word in ["vertical-disk", "I_rot=1", "gni-trapezoid", "h = 0.1", "10 steps", "t = 0 .. 1", "11 saved nodes",
                 "variable q", "time=11, coordinate=4", "x, y, phi, theta", "max |E - E0|",
                 "max |mu(q)(v - Y)|", gnipy.__version__, "created", "gni run", "p+ = G v0"]:
        assert word in text, word
    ds = xr.load_dataset(out)
    drift = np.max(np.abs(ds["energy"].values - ds["energy"].values[0]))
    assert f"{drift:.3e}" in text


def test_info_reads_files_of_the_earlier_layout(tmp_path):
    """A file from before the times moved into `time` (`time` the node index, the times in `t`)."""
    out = tmp_path / "run.nc"
    assert invoke(*BASE, "--out", out).exit_code == 0
    ds = xr.load_dataset(out)
    old = ds.drop_vars(["time", "node", "step"]).assign(t=(("time",), ds["time"].values, {"units": "time units"}))
    old.assign_coords(time=np.arange(ds.sizes["time"])).to_netcdf(tmp_path / "old.nc")
    res = invoke("info", tmp_path / "old.nc")
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "t = 0 .. 1 time units, 11 saved nodes" in text and "variable q" in text


@pytest.mark.parametrize("what", ["missing", "junk", "directory"])
def test_info_on_unreadable_file(what, tmp_path):
    path = tmp_path / "f.nc"
    if what == "junk":
        path.write_text("not a netCDF file")
    elif what == "directory":
        path.mkdir()
    res = invoke("info", path)
    assert res.exit_code == 2 and "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and str(path) in errors[0]


def test_files_carry_units_and_plot_from_the_file(tmp_path):
    from gnipy import plots

    out = tmp_path / "run.nc"
    assert invoke(*BASE, "--out", out).exit_code == 0
    with xr.open_dataset(out) as ds:
        assert ds["time"].attrs["units"] == "s" and ds["time"].attrs["standard_name"] == "time"
        assert "units" not in ds["energy"].attrs  # no model states an energy unit: none is invented
        assert "time in s" in ds.attrs["units_convention"] and ds.attrs["jax_version"]
        assert ds.attrs["Conventions"] == "CF-1.8" and ds.attrs["source"] == f"gnipy {gnipy.__version__}"
        assert ds.attrs["title"] and ds.attrs["history"]
        plots.plot_solution(ds, tmp_path / "again.png")
    assert (tmp_path / "again.png").stat().st_size > 10_000


# --------------------------------------------------------------------------------------------
# gni convergence
# --------------------------------------------------------------------------------------------
def _orders(output):
    """`{method: order}` from the lines `order METHOD: VALUE`."""
    out = {}
    for line in output.splitlines():
        if line.startswith("order ") and ":" in line:
            name, _, value = line[len("order "):].partition(":")
            out[name.strip()] = float(value) if value.strip() != "n/a" else float("nan")
    return out


def test_convergence_against_the_exact_solution(tmp_path):
    """Vertical disk (V = 0, constant metric): every discrete Lagrangian family gives the same
    discrete Lagrangian ½ΔᵀMΔ, so the GNI with Euler A is the GNI with the trapezoid: order 2."""
    res = invoke("convergence", MODEL, "--methods", "gni-trapezoid,gni-euler-a", "--h-max", "0.1",
                 "--h-min", "0.0125", "--count", "4", "--t-final", "1", "--out", tmp_path / "study")
    assert res.exit_code == 0, res.output
    assert "exact solution" in res.output
    orders = _orders(res.output)
    assert set(orders) == {"gni-trapezoid", "gni-euler-a"}
    for name, order in orders.items():
        assert abs(order - 2.0) < 0.15, (name, order)
    import csv

    with open(tmp_path / "study" / "convergence.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 and {r["yardstick"] for r in rows} == {"exact"}
    assert sorted({int(r["steps"]) for r in rows}) == [10, 20, 40, 80]
    for r in rows:  # h adjusted to a whole number of steps
        assert float(r["h"]) * int(r["steps"]) == pytest.approx(1.0, rel=1e-14)
    assert (tmp_path / "study" / "convergence.png").read_bytes()[:4] == b"\x89PNG"
    # the study's error at h = 0.1 is the error of `gni run` at h = 0.1
    out = tmp_path / "run.nc"
    assert invoke(*BASE, "--out", out).exit_code == 0
    ds = xr.load_dataset(out)
    spec = gnipy.get_model(MODEL)
    qe, _ = spec.exact(dict(spec.params), ds.attrs["q0"], ds.attrs["v0"], ds["time"].values)
    err = np.max(np.abs(ds["q"].values[-1] - qe[-1]))
    row = next(r for r in rows if r["method"] == "gni-trapezoid" and r["steps"] == "10")
    assert float(row["error"]) == pytest.approx(err, rel=1e-10, abs=1e-15)


def test_convergence_against_the_reference(tmp_path):
    res = invoke("convergence", "nonholonomic-particle", "--methods", "gni-euler-b", "--h-max", "0.1",
                 "--h-min", "0.025", "--count", "3", "--t-final", "1", "--out", tmp_path)
    assert res.exit_code == 0, res.output
    assert "continuous reference" in res.output
    order = _orders(res.output)["gni-euler-b"]
    assert abs(order - 1.0) < 0.15, order
    assert (tmp_path / "convergence.csv").is_file() and (tmp_path / "convergence.png").is_file()


CONVERGENCE_BAD = [
    (["--count", "1"], "--count"),
    (["--h-min", "0.2", "--h-max", "0.1"], "--h-min"),
    (["--h-max", "0"], "--h-max"),
    (["--h-max", "nan"], "--h-max"),
    (["--h-max", "2", "--t-final", "1"], "--h-max"),
    (["--h-max", "0.1", "--h-min", "0.099", "--count", "3"], "--count"),
    (["--t-final", "-1"], "--t-final"),
    (["--methods", "gni-trapezoid,nope"], "--methods"),
    (["--methods", "reference"], "--methods"),
    (["--methods", ","], "--methods"),
    (["--methods", "rat"], "--methods"),  # needs a group part
    (["--error", "energy"], "--error"),
    (["--set", "r=abc"], "--set"),
    (["--q0", "1,2"], "--q0"),
]


@pytest.mark.parametrize("args, option", CONVERGENCE_BAD, ids=[" ".join(a) for a, _ in CONVERGENCE_BAD])
def test_convergence_bad_input(args, option, tmp_path):
    res = invoke("convergence", MODEL, *args, "--out", tmp_path / "study")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and option in errors[0], res.output
    assert not (tmp_path / "study").exists()


def test_convergence_out_is_a_file(tmp_path):
    (tmp_path / "f").write_text("")
    res = invoke("convergence", MODEL, "--out", tmp_path / "f")
    assert res.exit_code == 2 and "--out" in _error_lines(res.output)[0]


def test_run_without_method_uses_the_models_measured_default(tmp_path):
    out = tmp_path / "default.nc"
    res = invoke("run", MODEL, "--h", "0.1", "--steps", "10", "--out", out)
    assert res.exit_code == 0, res.output
    assert xr.load_dataset(out).attrs["method"] == gnipy.get_model(MODEL).default_method
