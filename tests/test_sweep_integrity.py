"""Sweep stores gnipy can trust and own: ownership of the store (its attribute gnipy_owned,
--overwrite, stale temporaries, stores of earlier formats), chunk checksums (damaged chunks recomputed on resume, damaged metadata a clear
error, gnipy.sweep.verify_sweep), size bounds checked before anything is allocated, the
scheduler checked and connected before the store is created, and failed members visible
(NaN after their failure, failed_step/failed_time/failed_residual, exit code 1).

One in-process (threaded) dask cluster and one small sweep of the contact oscillator are
shared by the module: 6 members in 3 chunks of 2, half of which fail at step 4 (a large
initial velocity at a large step). Every damaged store is a copy of that reference, and a
resume recomputes only the damaged chunk (the program is compiled once).
"""

import json
import os
import re
import shutil
import subprocess
import sys
import time
import tracemalloc
import urllib.error
import urllib.request
import uuid
import warnings

import numpy as np
import pytest
import zarr
from typer.testing import CliRunner

import gnipy.sweep as sweep_module
import gnipy.sweep.plan as sweep_plan
from gnipy.cli import app
from gnipy.files import MARKER, make_owned_dir
from gnipy.solution import Solution
from gnipy.sweep import SweepError, SweepWarning, open_sweep, run_sweep, verify_sweep

runner = CliRunner()

# the method is named (not the model's default, which the atlas may change): rattle's explicit steps
# overflow at step 4 for the members with v0.dx = 3000
SMALL = dict(
    model="contact-oscillator",
    method="rattle",
    grid=["epsilon=0.1:0.5:3", "v0.dx=-1:3000:2"],
    h=0.5,
    steps=20,
    save_every=2,
    chunk_size=2,
)
SMALL_ARGS = (
    "sweep contact-oscillator --method rattle --grid epsilon=0.1:0.5:3 --grid v0.dx=-1:3000:2 --h 0.5 "
    "--steps 20 --save-every 2 --chunk-size 2"
).split()
FAILED = [1, 3, 5]  # the members with v0.dx = 3000: step 4 fails


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def _error_lines(output):
    return [line for line in output.splitlines() if line.startswith("Error")]


def _arrays(path) -> dict:
    """Every array of the store, as stored (zarr, no decoding)."""
    group = zarr.open_group(str(path), mode="r")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing in the store that zarr does not know
        return {name: np.asarray(a[...]) for name, a in group.arrays()}


def _owned(path) -> bool:
    """Whether `path` is a store that records gnipy created it (and holds no marker file)."""
    attrs = zarr.open_group(str(path), mode="r").attrs
    return attrs.get("gnipy_owned") == "gnipy sweep store" and not (path / MARKER).exists()


def _flat(group, name):
    """A per-member array of the 3 x 2 store, its members along one axis (C order)."""
    a = np.asarray(group[name][...])
    return a.reshape(6, *a.shape[2:])


def _assert_same_arrays(a, b):
    a, b = _arrays(a), _arrays(b)
    assert sorted(a) == sorted(b)
    for name in a:
        assert a[name].dtype == b[name].dtype, name
        if a[name].dtype.kind == "f":  # bit for bit, NaN included
            assert a[name].tobytes() == b[name].tobytes(), name
        else:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait(timeout=60)
    return proc.pid


@pytest.fixture(scope="module")
def client():
    from distributed import Client, LocalCluster

    with LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cluster:
        with Client(cluster, set_as_default=False) as c:
            yield c


@pytest.fixture(scope="module")
def reference(client, tmp_path_factory):
    """The small sweep, uninterrupted and undamaged."""
    out = tmp_path_factory.mktemp("reference") / "ref.zarr"
    report = run_sweep(**SMALL, out=out, client=client, progress=False)
    assert report.complete and report.chunks_computed == 3
    return out, report


@pytest.fixture
def copy(reference, tmp_path):
    out = tmp_path / "copy.zarr"
    shutil.copytree(reference[0], out)
    return out


# --------------------------------------------------------------------------------------
# 5. Failed members: NaN after their failure, recorded, reported, exit code 1
# --------------------------------------------------------------------------------------
def test_failed_members_are_nan_after_their_failure_and_recorded(reference):
    out, report = reference
    assert report.failed_members == 3
    first = report.failures[0]
    assert first["member"] == 1 and first["grid"] == {"epsilon": 0.1, "v0.dx": 3000.0}
    assert (first["step"], first["time"]) == (4, 2.0)
    assert [f["member"] for f in report.failures] == FAILED
    g = zarr.open_group(str(out), mode="r")
    failed = np.zeros(6, dtype=bool)
    failed[FAILED] = True
    np.testing.assert_array_equal(_flat(g, "result"), failed.astype(np.int32))
    np.testing.assert_array_equal(_flat(g, "failed_step"), np.where(failed, 4, -1))
    np.testing.assert_array_equal(_flat(g, "failed_time")[failed], 2.0)
    assert np.isnan(_flat(g, "failed_time")[~failed]).all()
    assert np.isnan(_flat(g, "failed_residual")[~failed]).all()
    if "failed_residuals" in Solution.__dataclass_fields__:  # gnipy.simulate reports it
        assert np.isfinite(_flat(g, "failed_residual")[failed]).all()
    valid = _flat(g, "valid")
    steps = g["step"][:]
    np.testing.assert_array_equal(valid, ~failed[:, None] | (steps[None, :] <= 4))
    for name in ("q", "v", "p", "energy", "constraint_residual"):
        x = _flat(g, name)
        mask = np.broadcast_to(valid.reshape(valid.shape + (1,) * (x.ndim - 2)), x.shape)
        assert np.isnan(x[~mask]).all(), name  # not held at the last good state
        assert np.isfinite(x[~failed]).all(), name


def test_cli_exits_1_and_lists_the_failed_members(copy):
    res = invoke(*SMALL_ARGS, "--out", copy)  # resumed: every chunk done, nothing computed
    assert res.exit_code == 1, res.output
    assert "chunks: 0 computed, 3 skipped" in res.output and "failed members: 3" in res.output
    errors = _error_lines(res.output)
    assert len(errors) == 1 and "Traceback" not in res.output
    assert "3 of 6 members failed" in errors[0]
    assert "member 1 (epsilon=0.1, v0.dx=3000): step 4, t = 2," in errors[0]
    assert "member 5 (epsilon=0.5, v0.dx=3000)" in errors[0]


def test_gni_info_summarizes_a_sweep_store(reference, copy, tmp_path):
    """`gni info` on a store (issue 31): the run, the grid, the chunks, the members that failed (the
    three with v0.dx = 3000, by the design of SMALL) and the checksums; a damaged chunk is named."""
    res = invoke("info", reference[0])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    for expected in ("sweep store", "contact-oscillator", "rattle", "grid epsilon 3 values, 0.1 .. 0.5",
                     "grid v0.dx 2 values, -1 .. 3000", "6 in 3 chunk(s): 3 done", "failed members 3",
                     "verified: the 3 done chunk(s) match"):
        assert expected in text, (expected, res.output)
    _truncate(copy / "q/c/1/0/0/0")
    res = invoke("info", copy)
    text = " ".join(res.output.split())
    assert res.exit_code == 0 and "NOT verified" in text and "chunk 1" in text, res.output
    assert "6 in 3 chunk(s): 2 done, incomplete" in text, res.output  # the damaged chunk is not done
    assert "failed members 2" in text, res.output  # member 3 (chunk 1) is not counted: not done
    (tmp_path / "empty").mkdir()
    res = invoke("info", tmp_path / "empty")
    errors = _error_lines(res.output)
    assert res.exit_code == 2 and len(errors) == 1 and "not a gnipy sweep store" in errors[0], res.output


def test_gni_info_on_the_checkpoints_of_a_streamed_run(tmp_path):
    parts = tmp_path / "x.nc.parts"
    parts.mkdir()
    (parts / "spec.json").write_text("{}")
    res = invoke("info", parts)
    assert res.exit_code == 0 and "unfinished streamed run" in res.output and "--resume" in res.output, res.output


# --------------------------------------------------------------------------------------
# 2. Integrity: damaged chunks recomputed, damaged metadata a clear error
# --------------------------------------------------------------------------------------
def _truncate(f):
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])


def _flip(f):
    data = bytearray(f.read_bytes())
    for i in range(len(data) // 3, len(data) // 3 + 8):
        data[i] ^= 0xFF
    f.write_bytes(bytes(data))


def _replace_by_chunk_0(f):
    shutil.copyfile(f.parent / "0", f)  # readable, and wrong


# the chunks are blocks of 1 x 2 of the 3 x 2 grid (epsilon, v0.dx): zarr chunk (k, 0, ...) is chunk k
DAMAGE = {
    # name: (file of the chunk, what to do, the chunk)
    "truncated q": ("q/c/1/0/0/0", _truncate, 1),
    "deleted energy": ("energy/c/2/0/0", os.unlink, 2),
    "flipped v": ("v/c/0/0/0/0", _flip, 0),
    "q of another chunk": ("q/c/2/0/0/0", lambda f: shutil.copyfile(f.parents[3] / "0/0/0/0", f), 2),
    "deleted checksum": ("chunk_checksum/c/1/0", os.unlink, 1),
    "truncated failed_step": ("failed_step/c/2/0", _truncate, 2),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_chunk_is_recomputed_on_resume(damage, reference, copy, client):
    name, do, chunk = DAMAGE[damage]
    f = copy / name
    assert f.is_file()
    do(f)
    ok, message, bad = verify_sweep(copy)
    assert not ok and bad == [chunk], message
    assert f"chunk {chunk}, members {2 * chunk}..{2 * chunk + 1} (" in message
    with pytest.raises(SweepError, match=rf"^path: .*is damaged: .*chunk {chunk}, members"):
        open_sweep(copy)
    with pytest.warns(SweepWarning, match=rf"chunk {chunk} of .*, members {2 * chunk}\.\.{2 * chunk + 1} \(epsilon="):
        report = run_sweep(**SMALL, out=copy, client=client, progress=False)
    assert (report.chunks_computed, report.chunks_skipped, report.chunks_repaired) == (1, 2, 1)
    assert report.complete and report.failed_members == 3
    _assert_same_arrays(copy, reference[0])  # bit for bit
    assert verify_sweep(copy)[0]


def test_the_cli_warns_of_a_damaged_chunk_and_recomputes_it(reference, copy, client):
    _truncate(copy / "p/c/1/0/0/0")
    res = invoke(*SMALL_ARGS, "--scheduler", client.scheduler.address, "--out", copy)
    assert res.exit_code == 1, res.output  # the failed members
    assert "Traceback" not in res.output
    warnings_ = [line for line in res.output.splitlines() if line.startswith("warning:")]
    assert len(warnings_) == 1 and "--out: chunk 1 of" in warnings_[0], res.output
    assert "members 2..3 (epsilon=0.3, v0.dx=-1 .. epsilon=0.3, v0.dx=3000)" in warnings_[0]
    assert "chunks: 1 computed, 2 skipped" in res.output
    assert "damaged chunks found and computed again: 1" in res.output
    _assert_same_arrays(copy, reference[0])


def _garbage(f):
    f.write_text("{ this is not JSON")


def _wrong_grid_value(p):
    zarr.open_array(str(p / "epsilon"), mode="r+")[1] = 0.25


# the store's own metadata (zarr.json) damaged: it no longer shows that gnipy created it, so gnipy
# does not replace it (remove it); the rest damaged: --overwrite starts afresh
REMOVE, AFRESH = "remove it yourself", "start afresh with overwrite=True"
STRUCTURE = {
    # name: (damage, what the message says, what to do)
    "garbage root zarr.json": (lambda p: _garbage(p / "zarr.json"), r"its metadata \(zarr\.json\) cannot be read",
                               REMOVE),
    "deleted root zarr.json": (lambda p: os.unlink(p / "zarr.json"), "its metadata file zarr.json is missing",
                               REMOVE),
    "garbage q/zarr.json": (
        lambda p: _garbage(p / "q" / "zarr.json"), r"the metadata of its array 'q' \(q/zarr\.json\)", AFRESH
    ),
    "deleted energy array": (lambda p: shutil.rmtree(p / "energy"), "its array 'energy' is missing", AFRESH),
    "wrong time coordinate": (
        lambda p: shutil.copyfile(p / "node" / "c" / "0", p / "time" / "c" / "0"),
        "its coordinate 'time' does not hold the sweep's values", AFRESH,
    ),
    "wrong grid value": (_wrong_grid_value, "its coordinate 'epsilon' does not hold the sweep's values", AFRESH),
}


def test_damaged_metadata_is_a_clear_error(reference, tmp_path, client):
    for i, (case, (do, what, hint)) in enumerate(STRUCTURE.items()):
        out = tmp_path / f"s{i}.zarr"
        shutil.copytree(reference[0], out)
        do(out)
        pattern = rf"^out: the sweep store '{out}' is damaged: {what}.*{hint}"
        with pytest.raises(SweepError, match=pattern):
            run_sweep(**SMALL, out=out, client=client, progress=False)
        res = invoke(*SMALL_ARGS, "--out", out)
        assert res.exit_code == 2 and "Traceback" not in res.output, (case, res.output)
        errors = _error_lines(res.output)
        assert len(errors) == 1 and errors[0].startswith("Error: --out: the sweep store"), (case, res.output)
        assert str(out) in errors[0] and (hint == REMOVE or "--overwrite" in errors[0]), (case, res.output)
        ok, message, bad = verify_sweep(out)
        assert not ok and bad == [] and "is damaged" in message, (case, message)
        with pytest.raises(SweepError, match="^path: .*is damaged"):
            open_sweep(out)
    # --overwrite replaces a damaged store that shows gnipy created it, and only that
    before = sorted(p.relative_to(tmp_path / "s0.zarr") for p in (tmp_path / "s0.zarr").rglob("*"))
    with pytest.raises(SweepError, match=f"^out: .*is damaged: .*{REMOVE}"):
        run_sweep(**SMALL, out=tmp_path / "s0.zarr", client=client, progress=False, overwrite=True)
    assert sorted(p.relative_to(tmp_path / "s0.zarr") for p in (tmp_path / "s0.zarr").rglob("*")) == before
    out = tmp_path / "s2.zarr"
    report = run_sweep(**SMALL, out=out, client=client, progress=False, overwrite=True)
    assert report.chunks_computed == 3
    _assert_same_arrays(out, reference[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"s{i}.zarr" for i in range(len(STRUCTURE))]


# --------------------------------------------------------------------------------------
# 1. Ownership: the marker, --overwrite only over gnipy's stores, stale temporaries
# --------------------------------------------------------------------------------------
def test_overwrite_replaces_only_a_store_gnipy_created(reference, tmp_path, client):
    ref = reference[0]
    assert _owned(ref)  # its attribute gnipy_owned, and no marker file
    before = _arrays(ref)
    foreign = tmp_path / "foreign.zarr"
    foreign.mkdir()
    (foreign / "precious.txt").write_text("keep me")
    link = tmp_path / "link.zarr"
    link.symlink_to(ref)
    file = tmp_path / "file.zarr"
    file.write_text("a file")
    other = make_owned_dir(tmp_path / "parts", "checkpoint parts of a streamed run")
    mixed = tmp_path / "mixed.zarr"
    shutil.copytree(ref, mixed)
    (mixed / "notes.txt").write_text("mine")
    cases = [
        (foreign, "a directory gnipy did not create"),
        (link, "is a symbolic link"),
        (file, "is a regular file"),
        (other, "created for something else"),
        (mixed, "holds 'notes.txt', which gnipy did not write"),
    ]
    for out, what in cases:
        with pytest.raises(SweepError, match=f"^out: .*{what}"):
            run_sweep(**SMALL, out=out, client=client, progress=False, overwrite=True)
        res = invoke(*SMALL_ARGS, "--overwrite", "--out", out)
        assert res.exit_code == 2 and "Traceback" not in res.output, res.output
        assert _error_lines(res.output)[0].startswith("Error: --out:"), res.output
    assert (foreign / "precious.txt").read_text() == "keep me"
    assert link.is_symlink() and os.readlink(link) == str(ref)
    assert file.read_text() == "a file" and (other / MARKER).is_file()
    assert (mixed / "notes.txt").read_text() == "mine" and (mixed / "q").is_dir()
    after = _arrays(ref)
    assert all(np.array_equal(before[k], after[k], equal_nan=before[k].dtype.kind == "f") for k in before)
    # an empty directory is taken (and becomes gnipy's)
    empty = tmp_path / "empty.zarr"
    empty.mkdir()
    report = run_sweep(**SMALL, out=empty, client=client, progress=False, max_chunks=1)
    assert report.chunks_computed == 1 and _owned(empty)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries left


def _old_store(reference, path, fmt: str, marker: bool):
    """A store in the layout of an earlier gnipy: members along a flat `member` axis, the grid
    values in grid_NAME, the specification of format `fmt`; with gnipy's marker file (format 2)
    or without (format 1)."""
    import xarray as xr

    ds = xr.open_zarr(reference).load()
    grid = {"epsilon": "epsilon", "v0_dx": "v0.dx"}  # dimension: grid name
    flat = ds.drop_vars(list(grid)).stack(member=list(grid)).reset_index("member", drop=True)
    flat = flat.transpose("member", ...).assign_coords(member=np.arange(6))
    for dim, name in grid.items():
        flat[f"grid_{name}"] = ("member", np.repeat(ds[dim].values, 2) if dim == "epsilon"
                                else np.tile(ds[dim].values, 3))
    spec = json.loads(ds.attrs["sweep_spec"])
    flat.attrs = {"sweep_spec": json.dumps({**spec, "format": fmt})}
    flat.to_zarr(str(path), mode="w-", consolidated=False)
    if marker:
        (path / MARKER).write_text(json.dumps({"created_by": "gnipy", "purpose": "gnipy sweep store"}) + "\n")
    return path


@pytest.mark.parametrize("fmt, marker", [("gnipy-sweep/2", True), ("gnipy-sweep/1", False)])
def test_a_store_of_an_earlier_format_is_a_clear_error_and_gnipy_s(reference, client, tmp_path, fmt, marker):
    """A store of an earlier gnipy (a flat member axis) is not resumed, verified or read: the
    error names it and what to do; it counts as gnipy's, so overwrite=True replaces it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # zarr: consolidated metadata, and the marker file
        old = _old_store(reference[0], tmp_path / "old.zarr", fmt, marker)
    what = rf"'{old}' was written by an earlier gnipy \(format {fmt}, with a flat member axis"
    with pytest.raises(SweepError, match=rf"^out: the sweep store {what}.* cannot be resumed .*overwrite=True"):
        run_sweep(**SMALL, out=old, client=client, progress=False)
    ok, message, bad = verify_sweep(old)
    assert not ok and bad == [] and re.search(what, message) and "cannot be read" in message, message
    with pytest.raises(SweepError, match=rf"^path: the sweep store {what}.*xarray.open_zarr"):
        open_sweep(old)
    res = invoke(*SMALL_ARGS, "--out", old)
    assert res.exit_code == 2 and "Traceback" not in res.output, res.output
    assert "earlier gnipy" in _error_lines(res.output)[0] and "--overwrite" in _error_lines(res.output)[0]
    report = run_sweep(**SMALL, out=old, client=client, progress=False, overwrite=True, max_chunks=1)
    assert report.chunks_computed == 1 and _owned(old)
    assert json.loads(zarr.open_group(str(old)).attrs["sweep_spec"])["format"] == sweep_module.FORMAT
    assert [p.name for p in tmp_path.iterdir()] == ["old.zarr"]  # the old store is gone


def test_a_store_of_the_previous_format_names_the_dimensions_change(reference, copy):
    """Format gnipy-sweep/4 named the dimensions as the grid (`v0.dx`); this version names them
    `v0_dx` and neither reads nor resumes the older stores: the error says why."""
    group = zarr.open_group(str(copy), mode="r+")
    spec = json.loads(group.attrs["sweep_spec"])
    group.attrs["sweep_spec"] = json.dumps({**spec, "format": "gnipy-sweep/4"})
    with pytest.raises(SweepError, match=r"earlier gnipy \(format gnipy-sweep/4, its dimensions named as the grid, "
                                         r"q0\.x where they are now q0_x\)"):
        open_sweep(copy)


def test_stale_temporaries_of_dead_processes_are_removed(client, tmp_path):
    """A run killed (SIGKILL) while creating or replacing a store leaves its temporary
    directory; the next run at that path removes those of dead processes, old-style names
    (`.NAME.HEX.partial`, no process id) included, and keeps those of a live process."""
    dead = _dead_pid()
    hex12 = uuid.uuid4().hex[:12]
    stale = [
        f".s.zarr.gnipy-{dead}-{hex12}.partial",
        f".s.zarr.gnipy-{dead}-{hex12}.old",
        f".s.zarr.{uuid.uuid4().hex}.partial",  # the name the previous version used
    ]
    kept = [f".s.zarr.gnipy-{os.getppid()}-{hex12}.partial", f".t.zarr.{uuid.uuid4().hex}.partial"]
    for name in stale + kept:
        (tmp_path / name).mkdir()
        (tmp_path / name / "zarr.json").write_text("{}")
    # on the shared cluster through a scheduler file (as `dask scheduler --scheduler-file` writes)
    scheduler_file = tmp_path / "scheduler.json"
    scheduler_file.write_text(json.dumps({"address": client.scheduler.address}))
    report = run_sweep(**SMALL, out=tmp_path / "s.zarr", scheduler=str(scheduler_file),
                       progress=False, max_chunks=1)
    assert report.chunks_computed == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*kept, "s.zarr", "scheduler.json"])


# --------------------------------------------------------------------------------------
# 3. Size: checked before anything is allocated
# --------------------------------------------------------------------------------------
def test_a_huge_grid_is_refused_at_once(tmp_path):
    tracemalloc.start()
    t = time.perf_counter()
    try:
        with pytest.raises(SweepError, match=r"^grid: Omega=0\.0:1\.0:100000 m=1\.0:2\.0:100000 gives "
                                             r"10,000,000,000 member.* TiB .*max_bytes"):
            run_sweep("rolling-ball", ["Omega=0:1:100000", "m=1:2:100000"], h=0.1, steps=10,
                      out=tmp_path / "huge.zarr", progress=False)
        with pytest.raises(SweepError, match="^grid: .*members: reading their results back alone"):
            run_sweep("rolling-ball", ["Omega=0:1:100000", "m=1:2:100000"], h=0.1, steps=10,
                      out=tmp_path / "huge.zarr", progress=False, max_bytes=None)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert time.perf_counter() - t < 10 and peak < 50 * 2**20
    huge = ["sweep", "rolling-ball", "--h", "0.1", "--steps", "10", "--out", tmp_path / "huge.zarr"]
    for grid, extra, words in [
        # 10¹⁰ members x (2 saved nodes x 217 bytes (q, v, p, energy, residual, R, valid) + 58 bytes
        # (result, failed step, time and residual, backend, the verdicts))
        (["Omega=0:1:100000", "m=1:2:100000"], [], ["4.48 TiB", "pass --yes"]),
        (["Omega=0:1:100000", "m=1:2:100000"], ["--yes"], ["memory"]),
        (["Omega=0:1:99999999999999999999"], [], ["COUNT must be at most 1,000,000,000"]),
    ]:
        res = invoke(*huge, *[a for g in grid for a in ("--grid", g)], *extra)
        assert res.exit_code == 2 and "Traceback" not in res.output, res.output
        errors = _error_lines(res.output)
        assert len(errors) == 1 and errors[0].startswith("Error: --grid:"), res.output
        assert all(w in errors[0] for w in words), res.output
    assert list(tmp_path.iterdir()) == []


def test_the_size_bound_the_free_space_and_the_chunk_memory(client, tmp_path, monkeypatch):
    out = tmp_path / "s.zarr"
    with pytest.raises(SweepError, match=r"^grid: .*6 member\(s\) x 11 saved node\(s\).*max_bytes = 1000 bytes"):
        run_sweep(**SMALL, out=out, client=client, progress=False, max_bytes=1000)
    with monkeypatch.context() as m:  # a full disk: refused whatever max_bytes
        m.setattr(shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(10**6, 10**6 - 10, 10))
        with pytest.raises(SweepError, match=r"^out: .*only 10 bytes are free"):
            run_sweep(**SMALL, out=out, client=client, progress=False, max_bytes=None)
    with monkeypatch.context() as m:  # a chunk larger than a quarter of the memory
        m.setattr(sweep_plan, "_memory_total", lambda: 8_000)
        with pytest.raises(SweepError, match="^chunk_size: a chunk of 2 member"):
            run_sweep(**SMALL, out=out, client=client, progress=False)
    assert list(tmp_path.iterdir()) == []
    # the command line's bound is DEFAULT_MAX_BYTES; --yes lifts it
    monkeypatch.setattr(sweep_module, "DEFAULT_MAX_BYTES", 1000)
    args = [*SMALL_ARGS, "--scheduler", client.scheduler.address, "--max-chunks", "1", "--out", out]
    res = invoke(*args)
    assert res.exit_code == 2 and "pass --yes to go ahead" in _error_lines(res.output)[0], res.output
    assert list(tmp_path.iterdir()) == []
    res = invoke(*args, "--yes")
    assert res.exit_code == 1 and "chunks: 1 computed" in res.output, res.output  # member 1 failed
    assert _owned(out)


# --------------------------------------------------------------------------------------
# 4. The scheduler: checked and connected before the store; no dashboard
# --------------------------------------------------------------------------------------
def test_a_bad_scheduler_fails_fast_and_creates_nothing(tmp_path):
    out = tmp_path / "s.zarr"
    bad_file = tmp_path / "bad.json"
    bad_file.write_text(json.dumps({"address": "not an address"}))
    for scheduler, what in [
        ("not an address", "is neither a valid address nor a scheduler file that exists"),
        ("tcp://host", "is not a valid address"),
        ("tcp://a b:8786", "is not a valid address"),
        ("tcp://host:99999", "is not a valid address"),
        (str(bad_file), "in the scheduler file"),
    ]:
        t = time.perf_counter()
        with pytest.raises(SweepError, match=f"^scheduler: .*{what}"):
            run_sweep(**SMALL, out=out, scheduler=scheduler, progress=False)
        assert time.perf_counter() - t < 5
    # a valid address where no scheduler listens: within the connection timeout
    t = time.perf_counter()
    with pytest.raises(SweepError, match=r"^scheduler: cannot connect to 'tcp://127\.0\.0\.1:1' within 1 s"):
        run_sweep(**SMALL, out=out, scheduler="tcp://127.0.0.1:1", connect_timeout=1, progress=False)
    assert time.perf_counter() - t < 10
    for scheduler in ("not an address", "tcp://127.0.0.1:1"):
        t = time.perf_counter()
        res = invoke(*SMALL_ARGS, "--scheduler", scheduler, "--connect-timeout", "1", "--out", out)
        assert res.exit_code == 2 and "Traceback" not in res.output, res.output
        errors = _error_lines(res.output)
        assert len(errors) == 1 and errors[0].startswith("Error: --scheduler:"), res.output
        assert time.perf_counter() - t < 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]  # no store


def test_the_local_cluster_serves_no_dashboard():
    from gnipy.sweep.cluster import Cluster

    with Cluster(None, None, 1, 10) as c:
        server = c.cluster.scheduler.http_server
        assert server.port != 8787 and server.address == "127.0.0.1"
        for page in ("/status", "/info/main/workers.html", "/health"):
            with pytest.raises(urllib.error.HTTPError, match="404"):
                urllib.request.urlopen(f"http://127.0.0.1:{server.port}{page}", timeout=10)
