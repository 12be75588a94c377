"""`gni sweep` and gnipy.sweep: grids of runs in vmapped chunks on dask.distributed,
written to zarr, resumable.

Most tests share one in-process (threaded) dask cluster; the interruption test runs the
CLI in a subprocess on its default local *process* cluster and kills it (SIGKILL)
part-way.
"""

import json
import os
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest
import xarray as xr
import zarr
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app
from gnipy.sweep import ChunkLayout, GridAxis, SweepError, open_sweep, parse_grid, run_sweep

runner = CliRunner()

# The rolling ball (R² × SO(3)): q, v and R per member; a 2 x 3 grid in chunks (blocks) of
# 1 x 2, so that the last chunk of each row (1 member) is padded on input.
BALL = dict(
    model="rolling-ball",
    grid=["Omega=0.5:1:2", "q0.x=-1:1:3"],
    method="gni-midpoint",
    h=0.05,
    steps=20,
    save_every=10,
    chunk_size=2,
)

# The contact oscillator with members that fail (large initial velocity at a large
# step): 48 members in 24 chunks, for the resumption tests.
OSC_GRID = ["epsilon=0.1:0.5:6", "v0.dx=-1:3000:8"]
OSC = dict(
    model="contact-oscillator",
    grid=OSC_GRID,
    h=0.5,
    steps=2000,
    save_every=500,
    chunk_size=2,
)
OSC_ARGS = (
    "sweep contact-oscillator --grid epsilon=0.1:0.5:6 --grid v0.dx=-1:3000:8 "
    "--h 0.5 --steps 2000 --save-every 500 --chunk-size 2"
).split()
assert OSC_ARGS[3::2][:2] == OSC_GRID


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error")]


def _files_under(path):
    """(path, size, modification time) of every file under `path` (empty if none): changes whenever
    a file there is written."""
    found = []
    for d, _, names in os.walk(path):
        for name in names:
            try:
                st = os.stat(os.path.join(d, name))
            except FileNotFoundError:  # replaced while listed
                continue
            found.append((os.path.join(d, name), st.st_size, st.st_mtime_ns))
    return sorted(found)


def _assert_same_data(a: xr.Dataset, b: xr.Dataset):
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert json.loads(a.attrs["sweep_spec"]) == json.loads(b.attrs["sweep_spec"])


def _assert_same_bits(a, b):
    """Every array of the two stores, as stored (zarr, no decoding): the same bytes, NaN included."""
    a, b = (
        {name: np.asarray(x[...]) for name, x in zarr.open_group(str(p), mode="r").arrays()}
        for p in (a, b)
    )
    assert sorted(a) == sorted(b)
    for name in a:
        assert a[name].dtype == b[name].dtype and a[name].shape == b[name].shape, name
        if a[name].dtype.kind in "fiub":
            assert a[name].tobytes() == b[name].tobytes(), name
        else:  # the names of the coordinates and velocities
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        with Client(cluster, set_as_default=False) as c:
            yield c


@pytest.fixture(scope="module")
def ball_store(client, tmp_path_factory):
    out = tmp_path_factory.mktemp("ball") / "ball.zarr"
    report = run_sweep(**BALL, out=out, client=client, progress=False)
    return out, report


@pytest.fixture(scope="module")
def osc_reference(client, tmp_path_factory):
    """The oscillator sweep, uninterrupted."""
    out = tmp_path_factory.mktemp("osc") / "reference.zarr"
    report = run_sweep(**OSC, out=out, client=client, progress=False)
    assert report.complete and report.chunks_computed == 24
    assert report.chunks_skipped == 0
    return out, report


# --------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------
def test_every_member_equals_its_own_simulation(ball_store):
    out, report = ball_store
    assert report.members == 6 and report.chunks == 4 and report.complete
    assert report.chunks_computed == 4 and report.chunk_size == 2
    assert report.failed_members == 0
    ds = xr.open_zarr(out)
    assert (ds.sizes["Omega"], ds.sizes["q0_x"]) == (2, 3)  # no padding in the store
    spec = gnipy.get_model("rolling-ball")
    for Omega in (0.5, 1.0):
        for x in (-1.0, 0.0, 1.0):
            params = {**spec.params, "Omega": Omega}
            q0, v0 = spec.initial_condition(params)
            # v0 is then off the constraints: projected, as in the sweep
            q0 = (x, *q0[1:])
            one = gnipy.simulate(
                gnipy.make_system("rolling-ball", Omega=Omega),
                "gni-midpoint",
                q0,
                v0,
                R0=np.reshape(spec.R0, (3, 3)),
                h=0.05,
                steps=20,
                save_every=10,
                project_v0=True,
                check_every_node=False,  # the numbers only (the verdicts: test_every_member_has_its_own_...)
            )
            member = ds.sel({"Omega": Omega, "q0_x": x})
            for name in ("q", "v", "p", "R", "energy", "constraint_residual"):
                np.testing.assert_allclose(
                    member[name].values,
                    np.asarray(getattr(one, name)),
                    rtol=0,
                    atol=1e-13,
                    err_msg=f"{name}, member Omega={Omega}, q0.x={x}",
                )
    np.testing.assert_allclose(ds["time"].values, [0.0, 0.5, 1.0])
    assert (ds["result"].values == 0).all() and ds["valid"].values.all()
    assert ds["chunk_done"].values.all()


def test_open_sweep_gives_the_grid_as_dimensions(ball_store):
    out, _ = ball_store
    ds = open_sweep(out)
    assert ds["q"].dims == ("Omega", "q0_x", "time", "coordinate")
    assert ds["R"].dims == ("Omega", "q0_x", "time", "i", "j")
    assert ds["result"].dims == ("Omega", "q0_x")
    np.testing.assert_array_equal(ds["Omega"].values, [0.5, 1.0])
    np.testing.assert_array_equal(ds["q0_x"].values, [-1.0, 0.0, 1.0])
    assert ds["q0_x"].attrs["long_name"] == "grid axis q0.x"  # the dimension's name is an identifier
    assert list(ds["velocity"].values) == ["dx", "dy", "omega1", "omega2", "omega3"]
    raw = zarr.open_group(str(out), mode="r")  # the arrays as stored, the grid as their first axes
    np.testing.assert_array_equal(ds["q"].sel(Omega=1.0, q0_x=0.0).values, raw["q"][1, 1])  # as keywords
    np.testing.assert_array_equal(
        ds["q"].isel(time=0).values[..., 0], [[-1.0, 0.0, 1.0]] * 2
    )
    # `time` holds the times (h = 0.05, saved every 10 steps), `node` and `step` the indices
    assert ds["time"].dtype == np.float64 and ds["time"].attrs["units"] == "s"
    assert ds["time"].attrs["standard_name"] == "time" and "t" not in ds.variables
    np.testing.assert_array_equal(ds["node"].values, [0, 1, 2])
    np.testing.assert_array_equal(ds["step"].values, [0, 10, 20])
    np.testing.assert_array_equal(ds["q"].sel(time=1.0).values, raw["q"][:, :, 2])
    assert ds.attrs["Conventions"] == "CF-1.8" and ds.attrs["source"] == f"gnipy {gnipy.__version__}"
    assert "rolling-ball" in ds.attrs["title"] and ds.attrs["history"]
    assert "dR/dt = hat(xi) R" in ds.attrs["orientation"]
    assert all(ds[name].attrs["long_name"] for name in ds.data_vars)
    # the zarr chunks are the sweep's chunks (blocks of 1 x 2) along the grid axes
    assert ds["q"].encoding["chunks"][:2] == (1, 2) and raw["q"].chunks[:2] == (1, 2)
    spec = json.loads(ds.attrs["sweep_spec"])
    assert spec["model"] == "rolling-ball" and spec["method"] == "gni-midpoint"
    assert spec["h"] == 0.05
    assert spec["steps"] == 20 and spec["save_every"] == 10 and spec["chunk_size"] == 2
    assert spec["grid"] == [
        GridAxis("Omega", 0.5, 1.0, 2).to_dict(),
        GridAxis("q0.x", -1.0, 1.0, 3).to_dict(),
    ]
    assert spec["gnipy_version"] == gnipy.__version__ and "Omega" not in spec["params"]


def test_plain_xarray_open_zarr_gives_the_grid_without_warnings(ball_store):
    """The store is an ordinary zarr store with consolidated metadata: `xr.open_zarr(path)`
    opens it with the grid axes as dimensions, warns of nothing, and gives what open_sweep
    gives."""
    out, _ = ball_store
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ds = xr.open_zarr(out).load()
        # every entry of the store is a zarr node (no stray file to warn about when listed)
        listed = sorted(zarr.open_group(str(out), mode="r", use_consolidated=False).array_keys())
    assert zarr.open_group(str(out), mode="r").metadata.consolidated_metadata is not None
    assert listed == sorted(json.loads(ds.attrs["store_arrays"]))
    assert sorted(p.name for p in out.iterdir()) == sorted([*listed, "zarr.json"])
    for name, dims in {"q": ("time", "coordinate"), "R": ("time", "i", "j"), "valid": ("time",),
                       "result": (), "failed_time": ()}.items():
        assert ds[name].dims == ("Omega", "q0_x", *dims), name
    np.testing.assert_array_equal(ds["Omega"].values, np.linspace(0.5, 1.0, 2))
    np.testing.assert_array_equal(ds["q0_x"].values, np.linspace(-1.0, 1.0, 3))
    assert ds["Omega"].attrs["long_name"] == "grid axis Omega"
    assert ds["failed_time"].attrs["units"] == "s" and ds["time"].attrs["units"] == "s"
    assert "member" not in ds.dims and not any(str(k).startswith("grid_") for k in ds.variables)
    assert ds.attrs["gnipy_owned"] == "gnipy sweep store"
    opened = open_sweep(out)
    assert set(opened.variables) == set(ds.variables) and opened.attrs == ds.attrs
    for name in ds.variables:
        assert opened[name].dims == ds[name].dims and opened[name].attrs == ds[name].attrs, name
        np.testing.assert_array_equal(opened[name].values, ds[name].values, err_msg=name)


@pytest.mark.parametrize("shape, chunk_size", [((2, 3), 2), ((2, 3), 4), ((6, 8), 20), ((6, 8), 3),
                                               ((4, 5, 6), 12), ((4, 5, 6), 1), ((3,), 7), ((4, 5, 6), 500)])
def test_chunks_are_blocks_of_consecutive_members(shape, chunk_size):
    layout = ChunkLayout.of(shape, chunk_size)
    assert layout.size <= chunk_size
    index = np.arange(np.prod(shape)).reshape(shape)  # each member's number, C order
    seen = np.zeros(shape, dtype=int)
    previous_end = 0
    for i in range(layout.chunks):
        a, b = layout.member_range(i)
        assert a == previous_end and 0 < b - a <= layout.size  # consecutive, in order
        block = layout.slices(i)
        np.testing.assert_array_equal(index[block].ravel(), np.arange(a, b))
        seen[block] += 1
        previous_end = b
    assert previous_end == index.size and (seen == 1).all()  # every member in one chunk
    done = np.arange(layout.chunks) % 3 == 1
    expected = np.zeros(shape, dtype=bool)
    for i in np.flatnonzero(done):
        expected[layout.slices(i)] = True
    np.testing.assert_array_equal(layout.member_mask(done), expected)


def test_failed_members_are_recorded_not_raised(osc_reference):
    out, report = osc_reference
    ds = open_sweep(out)
    failed = ds["result"].values == 1
    assert 0 < failed.sum() < failed.size and report.failed_members == int(failed.sum())
    fs = ds["failed_step"].values
    assert (fs[failed] >= 0).all() and (fs[~failed] == -1).all()
    k = ds["step"].values
    np.testing.assert_array_equal(k, np.rint(ds["time"].values / 0.5))
    np.testing.assert_array_equal(
        ds["valid"].values, (fs[..., None] < 0) | (k <= fs[..., None])
    )
    valid = ds["valid"].values
    q = ds["q"].values
    assert np.isnan(q[~valid]).all()  # NaN after the failure, not held at the last good state
    assert np.isfinite(q[~failed]).all()
    np.testing.assert_array_equal(ds["failed_time"].values[failed], 0.5 * fs[failed])
    assert np.isnan(ds["failed_time"].values[~failed]).all()
    assert np.isnan(ds["failed_residual"].values[~failed]).all()


# --------------------------------------------------------------------------------------
# Resuming
# --------------------------------------------------------------------------------------
@pytest.mark.slow
def test_interrupted_cli_sweep_resumes_without_recomputing(
    osc_reference, client, tmp_path
):
    """`gni sweep` on its default local process cluster, killed (SIGKILL, with its
    workers) once some chunks are done; the same command again (here on an existing
    cluster, --scheduler) computes only the rest, and the store equals the uninterrupted
    sweep exactly."""
    out = tmp_path / "killed.zarr"
    args = [*OSC_ARGS, "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(
        [sys.executable, "-m", "gnipy.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )
    done = np.zeros(0, dtype=bool)
    seen = None
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None:
            # the flags are read (zarr, ~10 ms of CPU a read) only when a file of `chunk_done`
            # changed: the subprocess spends seconds compiling after it created the store, and reading
            # every 5 ms through that cost more CPU than the rest of the test
            now = _files_under(out / "chunk_done")
            if now != seen and (out / "zarr.json").exists():
                seen = now
                done = zarr.open_group(str(out), mode="r")["chunk_done"][:]
                if done.sum() >= 2:
                    break
            time.sleep(0.005)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # the driver and its cluster's workers
        except ProcessLookupError:  # it ended by itself: the assertions below say why
            pass
        output = proc.communicate()[0].decode()
    for _ in range(100):  # nothing of the killed sweep is left running
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        pytest.fail("processes of the killed sweep are still running")
    assert proc.returncode == -signal.SIGKILL, output
    done = zarr.open_group(str(out), mode="r")["chunk_done"][:]
    assert 2 <= done.sum() < done.size, output
    with pytest.raises(SweepError, match="incomplete"):
        open_sweep(out)

    res = invoke(*args[:-4], "--scheduler", client.scheduler.address, "--out", out)
    assert res.exit_code == 1, res.output  # members failed (written, and listed)
    assert "members failed" in _error_lines(res.output)[0], res.output
    n = int(done.sum())
    assert f"chunks: {24 - n} computed, {n} skipped" in res.output, res.output
    _assert_same_data(open_sweep(out), open_sweep(osc_reference[0]))
    _assert_same_bits(out, osc_reference[0])  # the interrupted-then-resumed store, bit for bit


@pytest.mark.slow
def test_resume_after_max_chunks_and_after_an_unflagged_chunk(
    osc_reference, client, tmp_path
):
    out = tmp_path / "partial.zarr"
    calls = []
    first = run_sweep(**OSC, out=out, client=client, progress=lambda *a: calls.append(a[:2]), max_chunks=5)
    counts = (first.chunks_computed, first.chunks_skipped, first.chunks_remaining)
    assert counts == (5, 0, 19)
    assert calls[0] == (0, 24) and calls[-1] == (5, 24)  # progress(chunks done, chunks)
    assert [c for c in calls if c[0] > 0] == [(k, 24) for k in range(1, 6)]
    assert not first.complete
    part = open_sweep(out, allow_incomplete=True)  # the chunks not done are marked
    not_done = part["result"].values == -1
    assert not_done.sum() == 38 and not part["valid"].values[not_done].any()
    second = run_sweep(**OSC, out=out, client=client, progress=False)
    counts = (second.chunks_computed, second.chunks_skipped, second.chunks_remaining)
    assert counts == (19, 5, 0)
    _assert_same_data(open_sweep(out), open_sweep(osc_reference[0]))

    # a chunk whose data were (partly) written but whose flag was not: recomputed
    group = zarr.open_group(str(out), mode="r+")
    group["q"][0, 6:8] = -7.0  # chunk 3: members 6, 7 = (epsilon 0.1, v0.dx[6:8])
    group["chunk_done"][3] = False
    third = run_sweep(**OSC, out=out, client=client, progress=False)
    assert (third.chunks_computed, third.chunks_skipped) == (1, 23)
    _assert_same_data(open_sweep(out), open_sweep(osc_reference[0]))
    _assert_same_bits(out, osc_reference[0])
    # done: nothing to compute (and no cluster is needed)
    again = run_sweep(**OSC, out=out, progress=False)
    assert (again.chunks_computed, again.chunks_skipped) == (0, 24)


def test_a_different_sweep_on_the_store_is_refused(osc_reference, client, tmp_path):
    out, _ = osc_reference
    before = open_sweep(out)
    with pytest.raises(
        SweepError,
        match=r"out: .*holds a different sweep: h is 0\.5 there and 0\.25 here",
    ):
        run_sweep(**{**OSC, "h": 0.25}, out=out, client=client, progress=False)
    with pytest.raises(
        SweepError, match="grid is epsilon=0.1:0.5:6 v0.dx=-1.0:3000.0:8 there"
    ):
        run_sweep(
            **{**OSC, "grid": ["epsilon=0.1:0.5:6", "v0.dx=-1:3000:9"]},
            out=out,
            client=client,
            progress=False,
        )
    res = invoke(*OSC_ARGS[:-2], "--chunk-size", "3", "--out", out)
    assert res.exit_code == 2 and "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and "--out" in errors[0]
    assert "chunk_size is 2 there and 3 here" in errors[0]
    assert "--overwrite" in errors[0]
    _assert_same_data(open_sweep(out), before)  # untouched
    # --overwrite starts afresh (on the shared cluster: --scheduler)
    copy = tmp_path / "copy.zarr"
    run_sweep(
        **{**OSC, "h": 0.25}, out=copy, client=client, progress=False, max_chunks=1
    )
    address = client.scheduler.address
    res = invoke(*OSC_ARGS, "--scheduler", address, "--overwrite", "--max-chunks", "2",
                 "--out", copy)
    assert res.exit_code == 1, res.output  # members 1 to 3 failed
    assert "3 of 48 members failed" in _error_lines(res.output)[0], res.output
    assert "chunks: 2 computed, 0 skipped" in res.output
    assert "22 remaining" in res.output
    attrs = xr.open_zarr(copy).attrs
    assert json.loads(attrs["sweep_spec"])["h"] == 0.5
    # no temporary directories left
    assert [p.name for p in tmp_path.iterdir()] == ["copy.zarr"]


# --------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------
def test_parse_grid():
    axis = parse_grid("q0.x=-1:1:5")
    assert axis == GridAxis("q0.x", -1.0, 1.0, 5) and str(axis) == "q0.x=-1.0:1.0:5"
    np.testing.assert_array_equal(axis.values, np.linspace(-1, 1, 5))
    np.testing.assert_array_equal(parse_grid("m = 2 : 2 : 1").values, [2.0])
    # the unambiguous form: the same axis
    assert parse_grid("q0.x=linspace(-1, 1, 5)") == axis and parse_grid("q0.x = linspace(-1,1,5)") == axis
    np.testing.assert_array_equal(parse_grid("m=linspace(2, 3, 1)").values, [2.0])  # numpy's own reading
    bad = ["m=1:2", "m=a:b:3", "m=1:2:0", "m=nan:1:2", "m=1:inf:2", "m=1:2:2.5", "m=linspace(1, 2)",
           "m=linspace(1, 2, 2.5)", "m=linspace(1, 2, 3", "m=lin(1, 2, 3)"]
    for text in [*bad, "=1:2:3", "m1:2:3"]:
        with pytest.raises(SweepError, match="^grid: "):
            parse_grid(text)
    # the short form read as START:STEP:STOP or a slice: refused, saying what it means
    for text in ("m=0:0.1:1", "m=2:3:1", "m=0:1:0.25"):
        with pytest.raises(SweepError, match=r"is numpy\.linspace\(START, STOP, COUNT\), not a slice or START:STEP:STOP"):
            parse_grid(text)


def test_a_bad_member_in_a_chunk_is_named():
    """A worker names a member that the driver's check of the grid corners missed."""
    from gnipy.sweep import run_chunk
    from gnipy.sweep.plan import make_plan

    plan = make_plan("vertical-disk", ["q0.phi=0:0:2"], method="gni-trapezoid", h=0.1,
                 steps=10, t_final=None, save_every=None, set_params={},
                 project_v0=False, chunk_size=2)
    columns = {"q0.phi": np.array([0.0, 1.5])}  # v0 is off the constraints at phi = 1.5
    with pytest.raises(SweepError, match=r"^grid: member 11 \(q0.phi=1.5\): v0: "):
        run_chunk(plan.spec, 10, columns, 2)


DISK = ["sweep", "vertical-disk", "--h", "0.1", "--steps", "10"]
M = [*DISK, "--grid", "m=1:2:2"]  # a good grid
VD = ["sweep", "vertical-disk", "--grid", "m=1:2:2"]  # without --h and --steps
BAD = [
    ([*DISK, "--grid", "m=1:2"], "--grid"),
    ([*DISK, "--grid", "m=a:b:3"], "--grid"),
    ([*DISK, "--grid", "m=1:2:0"], "--grid"),
    ([*DISK, "--grid", "m=1:2:-3"], "--grid"),
    ([*DISK, "--grid", "nope=1:2:3"], "--grid"),
    ([*DISK, "--grid", "q0.nope=1:2:3"], "--grid"),
    ([*DISK, "--grid", "m=nan:1:2"], "--grid"),
    ([*DISK, "--grid", "m=1:inf:2"], "--grid"),
    ([*M, "--grid", "m=1:3:2"], "--grid"),
    ([*M, "--set", "m=3"], "--grid"),
    ([*DISK, "--grid", "m=-1:1:3"], "--grid"),  # a member with a negative mass
    ([*DISK], "--grid"),
    ([*M, "--set", "nope=1"], "--set"),
    ([*M, "--set", "r=nan"], "--set"),
    ([*M, "--chunk-size", "0"], "--chunk-size"),
    ([*M, "--workers", "0"], "--workers"),
    ([*M, "--save-every", "0"], "--save-every"),
    ([*M, "--max-chunks", "0"], "--max-chunks"),
    ([*M, "--method", "nope"], "--method"),
    ([*M, "--method", "reference"], "--method"),
    ([*M, "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers"),
    (["sweep", "no-such-model", *M[2:]], "MODEL"),
    ([*VD, "--h", "0", "--steps", "10"], "--h"),
    ([*VD, "--h", "nan", "--steps", "10"], "--h"),
    ([*VD, "--steps", "10"], "--h"),
    ([*VD, "--h", "0.1"], "--steps/--t-final"),
    ([*VD, "--h", "0.1", "--steps", "10", "--t-final", "1"], "--steps/--t-final"),
    ([*VD, "--h", "0.3", "--t-final", "1"], "--t-final"),
    ([*VD, "--h", "0.1", "--steps", "0"], "--steps"),
    ([*DISK, "--grid", "v0.dx=0:1:2", "--no-project-v0"], "--project-v0"),
]


@pytest.mark.parametrize("args, option", BAD, ids=[" ".join(a[1:]) for a, _ in BAD])
def test_bad_input(args, option, tmp_path):
    res = invoke(*args, "--out", tmp_path / "bad.zarr")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and option in errors[0], res.output
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    "where", ["missing-dir", "is-file", "parent-is-file", "not-a-store", "unwritable"]
)
def test_unwritable_output_is_rejected_before_running(where, tmp_path, monkeypatch):
    out = tmp_path / "s.zarr"
    if where == "missing-dir":
        out = tmp_path / "nope" / "s.zarr"
    elif where == "is-file":
        out.write_text("")
    elif where == "parent-is-file":
        (tmp_path / "f").write_text("")
        out = tmp_path / "f" / "s.zarr"
    elif where == "not-a-store":
        out.mkdir()
        (out / "precious.txt").write_text("keep me")
    else:
        # root ignores chmod: simulate it
        monkeypatch.setattr(os, "access", lambda *a, **k: False)
    for extra in ([], ["--overwrite"]):
        res = invoke(*DISK, "--grid", "m=1:2:2", "--out", out, *extra)
        assert res.exit_code == 2 and "Traceback" not in res.output
        errors = _error_lines(res.output)
        assert len(errors) == 1, res.output
        assert "--out" in errors[0] and str(out) in errors[0], res.output
    if where == "not-a-store":
        assert (out / "precious.txt").read_text() == "keep me"


def test_help_lists_every_option():
    res = invoke("sweep", "--help")
    assert res.exit_code == 0
    options = "--grid --method --h --steps --t-final --save-every --set --project-v0 "
    options += "--no-project-v0 --chunk-size --scheduler --workers --overwrite "
    options += "--max-chunks --yes --connect-timeout"
    for option in [*options.split(), "--out"]:
        assert option in res.output, option


@pytest.mark.slow
def test_every_member_has_its_own_verdicts_and_labels(client, tmp_path):
    """A sleigh sweep saving only its first and last nodes: each member's verdicts are those of
    its own in-memory run (every node checked), the report counts the members that went wrong,
    one QualitativeFailureWarning says so, and the store says how the runs started."""
    out = tmp_path / "sleigh.zarr"
    with pytest.warns(gnipy.QualitativeFailureWarning, match="2 of 2 members"):
        report = run_sweep("chaplygin-sleigh", ["q0.x=0:1:2"], out=out, h=0.01, steps=4000, save_every=4000,
                           method="gni-trapezoid", client=client, progress=False)
    assert report.unhealthy_members == 2 and report.failed_members == 0
    ds = open_sweep(out)
    with pytest.warns(gnipy.QualitativeFailureWarning):
        one = gnipy.simulate(gnipy.make_system("chaplygin-sleigh"), "gni-trapezoid", h=0.01, steps=4000,
                             save_every=4000)
    assert not ds["healthy"].values.any()
    np.testing.assert_allclose(ds["hidden_momentum_first_time"].values, one.hidden_verdict.first_time, atol=1e-9)
    # the ratio (~3.5e5) measures round-off grown along the sleigh's expanding direction, so two programs
    # that round differently (the sweep's batch and the single run; -O0 and XLA's default) agree to
    # what that growth leaves of round-off: 6e-5 relative measured, both programs at -O0
    np.testing.assert_allclose(ds["hidden_momentum_max_band_ratio"].values, one.hidden_verdict.max_band_ratio,
                               rtol=1e-3)
    assert ds.attrs["start"].startswith("consistent") and "Trapezoid" in ds.attrs["method_settings"]
    assert ds["native"].dtype == bool
    # a healthy sweep: no warning, every member healthy (the ball store above)


def test_a_healthy_sweep_is_healthy(ball_store):
    out, report = ball_store
    ds = open_sweep(out)
    assert report.unhealthy_members == 0 and ds["healthy"].values.all()
    assert np.isnan(ds["energy_drift_first_time"].values).all()
