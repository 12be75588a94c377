"""The user's own system at the command line (issue 31, point 1): `gni run`, `gni sweep`, `gni fit`,
`gni control`, `gni convergence` and `gni atlas` take `FILE.py:NAME` wherever they take a zoo
model's name, `--set` reaches the function's parameters, and streamed runs and sweeps record the
source's digest and refuse to resume when the file changed.

The systems are files of the tests' own (tests/user_system_files.py): the Chaplygin sleigh written
as a user would. Reference values: the zoo's sleigh (gnipy.models.chaplygin_sleigh, written
separately) run with the same method, parameters and start; the digests against hashlib.
"""

from __future__ import annotations

import hashlib
import os

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app
from gnipy.sweep.errors import SweepError
from gnipy.sweep.task import member_inputs
from user_system_files import SLEIGH_ARGS, SLEIGH_CLOSURE, write_source

CHECK_EVERY_NODE = False
runner = CliRunner()
RUN = ["--method", "gni-midpoint", "--h", "0.02", "--steps", "50"]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture
def folder(tmp_path):
    os.chmod(tmp_path, 0o755)
    write_source(tmp_path / "sleigh.py", SLEIGH_ARGS)
    write_source(tmp_path / "closed.py", SLEIGH_CLOSURE)
    return tmp_path


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None) as cluster:
        with Client(cluster, set_as_default=False) as c:
            yield c


def zoo(I, a, steps=50, h=0.02):
    return gnipy.simulate(gnipy.make_system("chaplygin-sleigh", m=1.0, I=I, a=a), "gni-midpoint", (0.0, 0.0, 0.0),
                          (1.0, a, 1.0), h=h, steps=steps)


def digest(text):
    return "sha256:" + hashlib.sha256(text.encode()).hexdigest()


def test_run_a_file_with_set(folder):
    out = folder / "r.nc"
    res = invoke("run", folder / "sleigh.py:make_sleigh", *RUN, "--set", "I=0.8,a=0.45", "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    ref = zoo(0.8, 0.45)
    np.testing.assert_allclose(ds["q"].values, np.asarray(ref.q), rtol=0, atol=1e-13)
    assert ds.attrs["model_reference"] == f"{folder / 'sleigh.py'}:make_sleigh"
    assert ds.attrs["model_source_sha256"] == digest(SLEIGH_ARGS)
    assert "I=0.8" in res.output and "a=0.45" in res.output
    # a relative reference, from the file's folder; without --out, the summary only
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        res = invoke("run", "sleigh.py:make_sleigh", *RUN)
    finally:
        os.chdir(cwd)
    assert res.exit_code == 0 and "writes nothing" not in res.output.lower(), res.output
    assert "final q" in res.output


@pytest.mark.parametrize("ref, set_, message", [
    ("sleigh.py:make_sled", [], "MODEL: .* has no 'make_sled'"),
    ("sleigh.py:make_sleigh", ["--set", "b=1"], r"--set: unknown parameter 'b' of model .*sleigh.py:make_sleigh' \(known: m, I, a\)"),
    ("nothing.py:f", [], "MODEL: no file"),
])
def test_run_refuses_with_the_option_named(folder, ref, set_, message):
    import re

    res = invoke("run", folder / ref, *RUN, *set_)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert re.search(message, " ".join(res.output.split())), res.output


def test_run_refuses_a_file_others_may_write_before_it_runs(folder, monkeypatch):
    monkeypatch.setattr("gnipy.user_systems.private_group", lambda gid: False)  # whoever runs the tests
    marker = folder / "ran"
    path = write_source(folder / "shared.py", f"open({str(marker)!r}, 'w').close()\n" + SLEIGH_ARGS, mode=0o666)
    res = invoke("run", f"{path}:make_sleigh", *RUN)
    assert res.exit_code == 2, res.output
    assert "refusing to run" in res.output and "writable by its group and others" in " ".join(res.output.split())
    assert not marker.exists()


def test_a_streamed_run_refuses_to_resume_a_changed_file(folder):
    out = folder / "long.nc"
    spec = gnipy.get_model(f"{folder / 'sleigh.py'}:make_sleigh")
    from gnipy.streaming import simulate_to_file

    # interrupted after one chunk: the parts record the system's reference and digest
    first = simulate_to_file(spec.system(), "gni-midpoint", spec.q0, spec.v0, path=out, h=0.02, steps=50,
                             chunk_steps=10, stop_after_chunks=1)
    assert not first.complete
    write_source(folder / "sleigh.py", SLEIGH_ARGS + "\n# edited\n")
    res = invoke("run", folder / "sleigh.py:make_sleigh", *RUN, "--checkpoint-every", "10", "--resume", "--out", out)
    assert res.exit_code != 0, res.output
    text = " ".join(res.output.split())
    assert "has a different origin" in text and digest(SLEIGH_ARGS) in text, res.output
    # the unchanged file resumes
    write_source(folder / "sleigh.py", SLEIGH_ARGS)
    res = invoke("run", folder / "sleigh.py:make_sleigh", *RUN, "--checkpoint-every", "10", "--resume", "--out", out)
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(xr.load_dataset(out)["q"].values, np.asarray(zoo(0.5, 0.3).q), rtol=0, atol=1e-13)


def test_sweep_a_users_parameters(folder, client):
    out = folder / "s.zarr"
    args = ["sweep", folder / "sleigh.py:make_sleigh", *RUN, "--grid", "I=linspace(0.5, 0.8, 2)",
            "--scheduler", client.scheduler.address, "--save-every", "1"]
    res = invoke(*args, "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.open_zarr(out)
    for I in (0.5, 0.8):
        np.testing.assert_allclose(ds["q"].sel(I=I).values, np.asarray(zoo(I, 0.3).q), rtol=0, atol=1e-13)
    import json

    assert json.loads(ds.attrs["sweep_spec"])["model_source"] == digest(SLEIGH_ARGS)
    # the file changed: the store holds another sweep
    write_source(folder / "sleigh.py", SLEIGH_ARGS + "\n# edited\n")
    res = invoke(*args, "--out", out)
    assert res.exit_code == 2 and "model_source" in res.output and "different sweep" in res.output, res.output


def test_sweep_refuses_closed_over_parameters_with_how_to(folder, client):
    res = invoke("sweep", folder / "closed.py:make_sleigh", *RUN, "--grid", "I=linspace(0.5, 0.8, 2)",
                 "--scheduler", client.scheduler.address, "--out", folder / "c.zarr")
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "cannot run as one batch" in text and "args=dict(" in text, res.output
    # an initial condition can be swept all the same: one System
    res = invoke("sweep", folder / "closed.py:make_sleigh", *RUN, "--grid", "q0.x=linspace(0, 1, 2)",
                 "--scheduler", client.scheduler.address, "--out", folder / "c.zarr")
    assert res.exit_code == 0, res.output


def test_a_worker_refuses_a_file_changed_since_the_plan(folder):
    ref = f"{folder / 'sleigh.py'}:make_sleigh"
    job = {"model": ref, "model_source": digest(SLEIGH_ARGS), "params": {"m": 1.0, "I": 0.5, "a": 0.3}}
    member_inputs(job, {}, 1)  # the planned file
    write_source(folder / "sleigh.py", SLEIGH_ARGS + "\n# edited\n")
    with pytest.raises(SweepError, match="changed since the sweep was planned"):
        member_inputs(job, {}, 1)


def test_fit_and_control_problem_files_name_a_file_beside_them(folder):
    observed = folder / "observed.nc"
    res = invoke("run", folder / "sleigh.py:make_sleigh", "--method", "gni-trapezoid", "--h", "0.05", "--steps", "20",
                 "--set", "I=0.8,a=0.4", "--v0", "1,0.4,1", "--out", observed)
    assert res.exit_code == 0, res.output
    (folder / "fit.toml").write_text(
        '[system]\nmodel = "sleigh.py:make_sleigh"\nparams = { a = 0.4 }\n[estimate]\nparams = { I = 0.6 }\n'
        '[observations]\nfile = "observed.nc"\nsigma = 1e-3\n[start]\nq0 = [0.0, 0.0, 0.0]\nv0 = [1.0, 0.4, 1.0]\n'
        '[integration]\nmethod = "gni-trapezoid"\nh = 0.05\n')
    res = invoke("fit", folder / "fit.toml", "--out", folder / "fit.nc")
    assert res.exit_code == 0, res.output
    est = xr.load_dataset(folder / "fit.nc")["estimate"].values
    assert abs(est[0] - 0.8) < 1e-8, res.output  # noise-free data of I = 0.8
    # control: the sleigh steered to a pose by a torque, its model named the same way
    (folder / "steer.toml").write_text(
        '[system]\nmodel = "sleigh.py:make_sleigh"\nparams = { I = 1.0, a = 0.5 }\n[inputs]\ntorque = { dtheta = 1.0 }\n'
        '[start]\nq0 = [0.0, 0.0, 0.0]\nv0 = [0.0, 0.0, 0.0]\n[horizon]\nh = 0.1\nsteps = 10\n'
        '[target]\nx = 0.05\ny = 0.0\ntheta = 0.1\n[solver]\nmethod = "gni-trapezoid"\n')
    res = invoke("control", folder / "steer.toml", "--out", folder / "steer.nc")
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(folder / "steer.nc")
    q_end = ds["q"].values[-1]
    np.testing.assert_allclose(q_end, [0.05, 0.0, 0.1], rtol=0, atol=1e-8)


def test_convergence_and_atlas_of_a_users_system(folder):
    res = invoke("convergence", folder / "sleigh.py:make_sleigh", "--methods", "gni-trapezoid", "--t-final", "1",
                 "--h-max", "0.1", "--h-min", "0.025", "--count", "3", "--out", folder / "conv")
    assert res.exit_code == 0, res.output
    assert "order gni-trapezoid: 2.0" in res.output or "order gni-trapezoid: 1.9" in res.output, res.output
    res = invoke("atlas", "--quick", "--models", folder / "sleigh.py:make_sleigh", "--methods", "sgni-trapezoid",
                 "--out", folder / "atlas")
    assert res.exit_code == 0, res.output
    assert "make_sleigh" in (folder / "atlas" / "atlas.md").read_text()
    # the zoo's record of defaults is not given the user's system
    assert "make_sleigh" not in (folder / "atlas" / "default_methods.py").read_text()


def test_data_files_name_only_a_file_beside_them(folder, tmp_path_factory):
    """A problem or config file received from someone else cannot run a module or a script elsewhere;
    a file beside it is found from any working directory."""
    for model in ("os:abort", "../sleigh.py:make_sleigh", "/tmp/x.py:f"):
        (folder / "bad.toml").write_text(f'[system]\nmodel = "{model}"\n[inputs]\ntorque = {{ dtheta = 1.0 }}\n')
        res = invoke("control", folder / "bad.toml", "--out", folder / "bad.nc")
        assert res.exit_code == 2, res.output
        assert "in a file of data, a model of your own must be a .py file beside it" in " ".join(res.output.split())
    (folder / "run.toml").write_text('model = "sleigh.py:make_sleigh"\nmethod = "gni-midpoint"\nh = 0.02\nsteps = 50\n'
                                     'set = { I = 0.8, a = 0.45 }\n')
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    cwd = os.getcwd()
    os.chdir(elsewhere)
    try:
        res = invoke("run", "--config", folder / "run.toml", "--out", "r.nc")
    finally:
        os.chdir(cwd)
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(xr.load_dataset(elsewhere / "r.nc")["q"].values, np.asarray(zoo(0.8, 0.45).q), rtol=0,
                               atol=1e-13)
