"""Streamed long runs: chunks committed to part files, atomic completion, resume after SIGKILL."""

import os
import signal
import subprocess
import sys
import time

import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy import GNI, Midpoint, System
from gnipy.cli import app
from gnipy.io import OutputError
from gnipy.models.rolling_ball import example_2
from gnipy.streaming import parts_directory, simulate_to_file

H, STEPS, STRIDE, CHUNK = 0.01, 1005, 10, 200  # the last chunk is short and ends off the stride


@pytest.fixture(scope="module")
def ball():
    return example_2()


@pytest.fixture(scope="module")
def plain(ball):
    system, q0, v0 = ball
    return gnipy.simulate(system, "gni-trapezoid", q0, v0, h=H, steps=STEPS, save_every=STRIDE)


def _run(ball, path, **kw):
    system, q0, v0 = ball
    return simulate_to_file(system, "gni-trapezoid", q0, v0, path=path, h=H, steps=STEPS, save_every=STRIDE,
                            chunk_steps=CHUNK, **kw)


@pytest.fixture(scope="module")
def streamed(ball, tmp_path_factory):
    path = tmp_path_factory.mktemp("stream") / "ball.nc"
    return _run(ball, path), xr.load_dataset(path)


def test_streamed_file_equals_the_in_memory_run(plain, streamed):
    result, ds = streamed
    assert result.complete and result.chunks == 6 and result.nodes == len(plain.t) == 102
    for name in ("t", "q", "v", "p", "R"):  # the state: bit for bit
        np.testing.assert_array_equal(ds["time" if name == "t" else name].values, np.asarray(getattr(plain, name)),
                                      err_msg=name)
    # the same time axis and labels as the in-memory file: `time` holds t, `node` and `step` the indices
    mem = plain.to_xarray()
    for name in ("time", "node", "step"):
        np.testing.assert_array_equal(ds[name].values, mem[name].values, err_msg=name)
        assert ds[name].attrs == mem[name].attrs, name
    np.testing.assert_array_equal(ds["node"].values, np.arange(102))
    assert ds["step"].values[-1] == STEPS and ds["time"].attrs["units"] == "s"
    np.testing.assert_array_equal(ds["q"].sel(time=5.0).values, np.asarray(plain.q)[50])  # t = 5.0: step 500
    for name in mem.data_vars:  # the GNI diagnostics too, with the same attributes
        assert ds[name].attrs == mem[name].attrs, name
    np.testing.assert_allclose(ds["hidden_momentum"].values, np.asarray(plain.hidden_momentum), rtol=1e-14)
    for key in ("Conventions", "source", "title", "orientation"):
        assert ds.attrs[key] == mem.attrs[key], key
    # diagnostics derived from it in differently shaped programs: to rounding
    np.testing.assert_allclose(ds["energy"].values, np.asarray(plain.energy), rtol=1e-15, atol=0)
    np.testing.assert_allclose(ds["constraint_residual"].values, np.asarray(plain.constraint_residual), rtol=0, atol=1e-15)
    assert ds.attrs["steps"] == STEPS and ds.attrs["result"] == 0 and ds.attrs["model"] == "rolling-ball"
    assert not any(v.startswith("state_") for v in ds.variables)
    assert not parts_directory(result.path).exists()  # the parts are removed once the file is complete
    e = np.asarray(plain.energy)
    assert result.energy_error == pytest.approx(np.max(np.abs(e - e[0])), rel=1e-12)


def test_resume_after_an_interruption_gives_the_same_file(ball, streamed, tmp_path):
    path = tmp_path / "ball.nc"
    first = _run(ball, path, stop_after_chunks=2)
    assert not first.complete and not path.exists()
    parts = sorted(p.name for p in parts_directory(path).iterdir())
    assert parts == [".gnipy-owned", "part_000000.nc", "part_000001.nc", "spec.json"]  # the marker: gnipy's
    second = _run(ball, path, resume=True)
    assert second.complete and second.chunks_resumed == 2
    ds = xr.load_dataset(path)
    for name in ("q", "v", "p", "R", "energy", "time", "node", "step"):
        np.testing.assert_array_equal(ds[name].values, streamed[1][name].values, err_msg=name)


def test_resume_refuses_a_different_run(ball, tmp_path):
    path = tmp_path / "ball.nc"
    _run(ball, path, stop_after_chunks=1)
    system, q0, v0 = ball
    with pytest.raises(OutputError, match=r"resume: the interrupted run .* has a different h"):
        simulate_to_file(system, "gni-trapezoid", q0, v0, path=path, h=0.02, steps=STEPS, save_every=STRIDE,
                         chunk_steps=CHUNK, resume=True)


def test_chunk_must_be_a_multiple_of_the_stride(ball, tmp_path):
    with pytest.raises(gnipy.InputError, match=r"not a multiple of the save stride 10"):
        simulate_to_file(ball[0], "gni-trapezoid", ball[1], ball[2], path=tmp_path / "x.nc", h=H, steps=100,
                         save_every=10, chunk_steps=25)


def test_failure_writes_the_good_part_and_raises(tmp_path):
    wall = System(lambda q, v: 0.5 * v @ v - jnp.log1p(-q[0]), lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3, name="wall")
    path = tmp_path / "wall.nc"
    with pytest.raises(gnipy.SolverFailure, match=r"step \d+ .* holds the run up to the last good node"):
        simulate_to_file(wall, GNI(Midpoint()), [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], path=path, h=0.1, steps=40,
                         chunk_steps=2)
    ds = xr.load_dataset(path)
    assert ds.attrs["result"] == 1
    assert np.all(np.isfinite(ds["q"].values)) and np.all(ds["q"].values[:, 0] < 1.0)
    single = gnipy.simulate(wall, GNI(Midpoint()), [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=40, throw=False)
    np.testing.assert_array_equal(ds["q"].values, np.asarray(single.q))  # same nodes, no padding


# ---------------------------------------------------------------------------------------------
# gni run --checkpoint-every K --resume, killed with SIGKILL part-way
# ---------------------------------------------------------------------------------------------
RUN = ["run", "nonholonomic-particle", "--method", "gni-trapezoid", "--h", "0.001", "--steps", "6000000",
       "--save-every", "1000", "--checkpoint-every", "300000"]


def test_sigkill_then_resume_equals_an_uninterrupted_run(tmp_path):
    killed = tmp_path / "killed.nc"
    parts = parts_directory(killed)
    gni = [sys.executable, "-c", "from gnipy.cli import app; app()"]
    proc = subprocess.Popen([*gni, *RUN, "--out", str(killed)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if parts.is_dir() and len(list(parts.glob("part_*.nc"))) >= 2:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not killed.exists()  # nothing half-written
    done_before = len(list(parts.glob("part_*.nc")))
    assert 2 <= done_before < 20

    runner = CliRunner()
    resumed = runner.invoke(app, [*RUN, "--out", str(killed), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    assert "from an earlier run" in resumed.output
    whole = tmp_path / "whole.nc"
    fresh = runner.invoke(app, [*RUN, "--out", str(whole)])
    assert fresh.exit_code == 0, fresh.output
    a, b = xr.load_dataset(killed), xr.load_dataset(whole)
    assert a.sizes["time"] == 6001
    for name in ("time", "node", "step", "q", "v", "p", "energy", "constraint_residual"):
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert a["time"].values[-1] == 6000.0 and a.sel(time=3000.0)["node"] == 3000


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["--checkpoint-every", "0"], r"--checkpoint-every: must be a positive integer"),
        (["--checkpoint-every", "15"], r"--checkpoint-every: 15 is not a multiple of the save stride 10"),
        (["--resume"], r"--resume: only streamed runs resume"),
        (["--checkpoint-every", "20", "--plot", "x.png"], r"--plot: not available for streamed runs"),
    ],
)
def test_checkpoint_options_bad_input(tmp_path, args, pattern):
    result = CliRunner().invoke(app, ["run", "nonholonomic-particle", "--h", "0.1", "--steps", "40", "--save-every",
                                      "10", "--out", str(tmp_path / "x.nc"), *args])
    assert result.exit_code != 0
    assert "Traceback" not in result.output
    import re

    assert re.search(pattern, " ".join(result.output.split())), result.output
