"""Streamed runs (gnipy.simulate_to_file) when things go wrong: a parts directory gnipy does not
own, damaged or missing checkpoints, a step failing at the start of a chunk, SIGINT during the
merge, a full disk, a finished run resumed, stale temporaries, outputs too large to write.

One small model (knife-edge, gni-trapezoid, 10 chunks of 40 steps) compiled once for the module;
every recomputed run must equal the uninterrupted one bit for bit."""

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import netCDF4
import numpy as np
import pytest

import gnipy
import gnipy.streaming as streaming
from gnipy.files import MARKER, OutputError
from gnipy.io import stamp_checksum, verify_netcdf
from gnipy.streaming import parts_directory, simulate_to_file

MODEL, METHOD = "knife-edge", "gni-trapezoid"
H, STEPS, SAVE, CHUNK = 0.01, 400, 4, 40  # 10 chunks of the same shape: one compilation
RUN = dict(h=H, steps=STEPS, save_every=SAVE, chunk_steps=CHUNK)
SUBPROCESS_TIMEOUT = 180


@pytest.fixture(scope="module")
def knife():
    spec = gnipy.get_model(MODEL)
    q0, v0 = spec.initial_condition(dict(spec.params))
    return spec.system(), q0, v0


def _run(knife, path, **kw):
    system, q0, v0 = knife
    return simulate_to_file(system, METHOD, q0, v0, path=path, **{**RUN, **kw})


@pytest.fixture(scope="module")
def reference(knife, tmp_path_factory):
    """The uninterrupted run: (its file, its StreamResult)."""
    path = tmp_path_factory.mktemp("reference") / "ref.nc"
    return path, _run(knife, path)


def _contents(path):
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        return ({k: np.asarray(v[...]) for k, v in nc.variables.items()}, nc.getncattr("gnipy_checksum"),
                nc.getncattr("stream_spec"))


def assert_same_file(a, b):
    """The data of two result files, bit for bit (and their checksums and specs)."""
    da, ca, sa = _contents(a)
    db, cb, sb = _contents(b)
    assert list(da) == list(db)
    for name in da:
        if da[name].dtype.kind == "O":
            assert da[name].tolist() == db[name].tolist(), name
        else:
            assert da[name].dtype == db[name].dtype and da[name].tobytes() == db[name].tobytes(), name
    assert ca == cb and sa == sb
    assert verify_netcdf(a)[0] and verify_netcdf(b)[0]


def _temporaries(*directories):
    return sorted(p.name for d in directories if Path(d).is_dir() for p in Path(d).iterdir()
                  if p.name.endswith((".tmp", ".partial")))


def _script(body: str) -> str:
    return textwrap.dedent(f"""
        import os, signal, sys
        import gnipy
        import gnipy.streaming as streaming
        spec = gnipy.get_model({MODEL!r})
        q0, v0 = spec.initial_condition(dict(spec.params))
        system = spec.system()
        def run(path, **kw):
            return streaming.simulate_to_file(system, {METHOD!r}, q0, v0, path=path, **{{**{RUN!r}, **kw}})
    """) + textwrap.dedent(body)


def _python(script: str, *args) -> subprocess.CompletedProcess:
    try:
        return subprocess.run([sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True,
                              timeout=SUBPROCESS_TIMEOUT)
    except subprocess.TimeoutExpired as e:  # the process is killed by subprocess.run
        pytest.fail(f"the process did not end within {SUBPROCESS_TIMEOUT} s: {e.stderr!r}")


# ---------------------------------------------------------------------------------------------
# 1. What gnipy owns: the parts directory, the destination
# ---------------------------------------------------------------------------------------------
def test_a_parts_directory_gnipy_did_not_create_is_never_deleted(knife, reference, tmp_path):
    path = tmp_path / "d.nc"
    parts = parts_directory(path)
    parts.mkdir()
    (parts / "notes.txt").write_text("x")
    with pytest.raises(OutputError, match=r"d\.nc\.parts is a directory gnipy did not create .* move it away"):
        _run(knife, path)
    assert (parts / "notes.txt").read_text() == "x" and sorted(os.listdir(parts)) == ["notes.txt"]
    assert not path.exists()

    link = tmp_path / "l.nc"
    parts_directory(link).symlink_to(parts)  # a link is not gnipy's either
    with pytest.raises(OutputError, match=r"l\.nc\.parts is a symbolic link; .* move it away"):
        _run(knife, link)

    # gnipy's own directory: a file someone put there survives starting afresh and the end of the run
    own = tmp_path / "own.nc"
    _run(knife, own, stop_after_chunks=2)
    assert (parts_directory(own) / MARKER).is_file()
    (parts_directory(own) / "notes.txt").write_text("mine")
    result = _run(knife, own)  # afresh: removes only gnipy's files
    assert result.complete and result.chunks_resumed == 0
    assert sorted(os.listdir(parts_directory(own))) == [MARKER, "notes.txt"]
    assert any("kept: it holds files gnipy did not write" in w for w in result.warnings)
    assert_same_file(own, reference[0])

    empty = tmp_path / "e.nc"  # an empty directory is taken over, then removed with the parts
    parts_directory(empty).mkdir()
    assert _run(knife, empty).complete and not parts_directory(empty).exists()


def test_the_destination_is_checked_up_front(knife, reference, tmp_path):
    path = tmp_path / "x.nc"
    path.write_text("old")
    with pytest.raises(OutputError, match=r"x\.nc exists; pass overwrite=True"):
        _run(knife, path)
    assert path.read_text() == "old" and not parts_directory(path).exists()
    assert _run(knife, path, overwrite=True).complete
    assert_same_file(path, reference[0])

    link = tmp_path / "link.nc"
    link.symlink_to(path)
    with pytest.raises(OutputError, match=r"link\.nc is a symbolic link"):
        _run(knife, link, overwrite=True)
    with pytest.raises(OutputError, match=r"is a directory"):
        _run(knife, tmp_path, overwrite=True)


# ---------------------------------------------------------------------------------------------
# 2. Damaged checkpoints are verified and recomputed on resume
# ---------------------------------------------------------------------------------------------
def _edit(file, fn, restamp=False):
    with netCDF4.Dataset(file, "a") as nc:
        nc.set_auto_maskandscale(False)
        fn(nc)
    if restamp:  # a consistent checksum over wrong data: the other checks must catch it
        stamp_checksum(file)


def _nudge(name, row=0):
    def fn(nc):
        a = nc[name][...]
        a.flat[row] = np.nextafter(a.flat[row], np.inf)
        nc[name][...] = a
    return fn


def _set(name, value, index=0):
    def fn(nc):
        a = nc[name][...]
        a.flat[index] = value
        nc[name][...] = a
    return fn


def _random_bytes(file):
    file.write_bytes(np.random.default_rng(0).bytes(file.stat().st_size))


def _truncate(file):
    with open(file, "r+b") as fh:
        fh.truncate(file.stat().st_size // 2)


FAULTS = {  # name: (the part damaged, how, what the warning says)
    "random-bytes-last": (3, _random_bytes, r"cannot be read"),
    "truncated": (2, _truncate, r"cannot be read"),
    "state-perturbed": (3, lambda f: _edit(f, _nudge("state_0")), r"do not match its checksum"),
    "q-perturbed": (1, lambda f: _edit(f, _nudge("q", 4)), r"do not match its checksum"),
    "missing-middle": (1, lambda f: f.unlink(), r"it is missing"),
    "state-not-finite": (2, lambda f: _edit(f, _set("state_1", np.nan), restamp=True), r"state_1 is not finite"),
    "steps-discontinuous": (2, lambda f: _edit(f, _set("step", 81), restamp=True),
                            r"time and step do not continue"),
    "other-run": (0, lambda f: _edit(f, lambda nc: nc.setncattr("stream_spec_sha256", "sha256:0")),
                  r"belongs to a different run"),
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_damaged_checkpoint_is_recomputed_on_resume(knife, reference, tmp_path, fault):
    index, damage, why = FAULTS[fault]
    path = tmp_path / "run.nc"
    _run(knife, path, stop_after_chunks=4)
    part = parts_directory(path) / f"part_{index:06d}.nc"
    damage(part)
    notices = []
    result = _run(knife, path, resume=True, notice=notices.append)
    assert result.complete and result.chunks_resumed == index
    assert notices and notices[0] in result.warnings
    later = 3 - index
    pattern = (rf"checkpoint part_{index:06d}\.nc in .*run\.nc\.parts does not verify: .*{why}.*"
               + (rf"and the {later} later part\(s\) are computed again" if later else "is computed again")
               + (rf" from part_{index - 1:06d}\.nc" if index else " from the start"))
    assert any(__import__("re").search(pattern, n) for n in notices), notices
    assert_same_file(path, reference[0])  # bit for bit
    assert not parts_directory(path).exists()


def test_a_damaged_spec_is_named(knife, reference, tmp_path):
    path = tmp_path / "run.nc"
    _run(knife, path, stop_after_chunks=2)
    assert verify_netcdf(parts_directory(path) / "part_000001.nc")[0]  # a part's checksum is gni verify's
    (parts_directory(path) / "spec.json").write_bytes(b"\x00garbage{")
    with pytest.raises(OutputError, match=r"cannot read .*spec\.json .*damaged; rerun with resume=False"):
        _run(knife, path, resume=True)
    assert _run(knife, path).complete  # afresh, as the message says
    assert_same_file(path, reference[0])


# ---------------------------------------------------------------------------------------------
# 3. A step failing in the first save block of a later chunk (the chunk keeps no node)
# ---------------------------------------------------------------------------------------------
def test_a_failure_at_the_start_of_a_chunk_raises_the_solver_failure(tmp_path, monkeypatch):
    # the sleigh on SE(2) (a group, an implicit step; cheaper to compile than the top it replaced):
    # at h = 5 the GNI's step 3 does not converge, the first step of chunk 1
    spec = gnipy.get_model("chaplygin-sleigh-se2")
    q0, v0 = spec.q0, spec.v0
    path = tmp_path / "sleigh.nc"
    kw = dict(path=path, h=5.0, steps=6, chunk_steps=3)
    with pytest.raises(gnipy.SolverFailure, match=r"step 3 \(t = 15 -> 20\) failed.* holds the run up to the last"):
        simulate_to_file(spec.system(), "gni-midpoint", q0, v0, **kw)
    with netCDF4.Dataset(path) as nc:
        assert nc.result == 1 and nc.failed_step == 3 and nc.streamed_chunks == 2
        np.testing.assert_array_equal(nc["step"][:], np.arange(4))
        for name in ("v", "R"):  # (its q is empty: the sleigh is on SE(2) alone)
            values = np.ma.getdata(nc[name][:])
            assert values.shape[0] == 4 and np.all(np.isfinite(values)), name
    assert verify_netcdf(path)[0] and not parts_directory(path).exists()
    # resumed, the finished failed run is read, not recomputed
    monkeypatch.setattr(streaming.run, "solve", None)  # (simulate_to_file looks it up in gnipy.streaming.run)
    result = simulate_to_file(spec.system(), "gni-midpoint", q0, v0, resume=True, throw=False, **kw)
    assert (result.complete, result.result, result.failed_step, result.nodes, result.steps) == (True, 1, 3, 4, 3)


# ---------------------------------------------------------------------------------------------
# 4. SIGINT during the merge: bounded, no temporary, resume finishes the run
# ---------------------------------------------------------------------------------------------
def test_sigint_during_the_merge_stops_cleanly_and_resume_finishes(knife, reference, tmp_path):
    path = tmp_path / "int.nc"
    proc = _python(_script("""
        def hook(i):
            if i == 3:  # in the middle of the merge; raise_signal delivers it to this (the main)
                # thread at once: os.kill may land on another of JAX's threads and reach the
                # handler only after the merge has finished when the machine is loaded
                signal.raise_signal(signal.SIGINT)
        streaming.merge._merge_hook = hook  # (looked up in gnipy.streaming.merge, where the merge runs)
        # Python's own SIGINT handler, whatever this process inherited: a child of a pytest-xdist
        # worker can start with SIGINT ignored, and gnipy leaves an ignored SIGINT alone
        signal.signal(signal.SIGINT, signal.default_int_handler)
        try:
            run(sys.argv[1])
        except KeyboardInterrupt:
            print("interrupted")
            sys.exit(130)
        print("completed")
    """), path)
    assert proc.returncode == 130 and "interrupted" in proc.stdout, proc.stdout + proc.stderr
    assert not path.exists()
    assert _temporaries(tmp_path, parts_directory(path)) == []
    assert len(list(parts_directory(path).glob("part_*.nc"))) == 10  # every chunk was computed
    result = _run(knife, path, resume=True)
    assert result.complete and result.chunks_resumed == 10 and result.warnings == []
    assert_same_file(path, reference[0])


# ---------------------------------------------------------------------------------------------
# 5. A full disk (a real write failure: RLIMIT_FSIZE) is an OutputError naming the file
# ---------------------------------------------------------------------------------------------
def test_a_full_disk_is_an_output_error_and_the_old_file_is_untouched(knife, reference, tmp_path):
    sizes = tmp_path / "sizes.nc"
    _run(knife, sizes, stop_after_chunks=9)
    largest_part = max(p.stat().st_size for p in parts_directory(sizes).glob("part_*.nc"))
    whole = reference[0].stat().st_size
    part_limit, merge_limit = 4096, (largest_part + whole) // 2
    assert largest_part + 2048 < merge_limit < whole - 2048, (largest_part, whole)

    path = tmp_path / "full.nc"
    path.write_bytes(b"an older result")
    before = path.stat()
    proc = _python(_script("""
        import resource
        from gnipy.files import OutputError
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail with EFBIG
        _, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
        for label, limit, resume in (("PART", int(sys.argv[2]), False), ("MERGE", int(sys.argv[3]), True)):
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
            try:
                run(sys.argv[1], overwrite=True, resume=resume)
                print(label, "no error")
            except OutputError as e:
                print(label, e)
    """), path, part_limit, merge_limit)
    out = proc.stdout
    assert proc.returncode == 0 and "Traceback" not in proc.stderr + out, out + proc.stderr
    part = parts_directory(path) / "part_000000.nc"
    assert f"PART cannot write {part}" in out and "MERGE no error" not in out, out
    assert f"MERGE cannot write {path}" in out, out
    assert "disk" in out
    assert _temporaries(tmp_path, parts_directory(path)) == []
    assert path.read_bytes() == b"an older result" and path.stat().st_mtime_ns == before.st_mtime_ns
    # the parts survived the failed merge: resume finishes the run
    result = _run(knife, path, overwrite=True, resume=True)
    assert result.complete and result.chunks_resumed == 10
    assert_same_file(path, reference[0])


# ---------------------------------------------------------------------------------------------
# 6. A finished run, resumed: read from the file, not recomputed (unless damaged)
# ---------------------------------------------------------------------------------------------
def test_resuming_a_finished_run_reads_it(knife, reference, tmp_path, monkeypatch):
    path = tmp_path / "done.nc"
    shutil.copyfile(reference[0], path)
    before = path.stat().st_mtime_ns
    with monkeypatch.context() as m:
        m.setattr(streaming.run, "solve", None)  # nothing may be computed (looked up in gnipy.streaming.run)
        result = _run(knife, path, resume=True)
    ref = reference[1]
    assert result.complete and result.chunks == result.chunks_resumed == ref.chunks == 10
    for field in ("nodes", "steps", "result", "failed_step", "energy_error", "constraint_residual", "iterations"):
        assert getattr(result, field) == getattr(ref, field), field
    np.testing.assert_array_equal(result.final_q, ref.final_q)
    assert path.stat().st_mtime_ns == before

    # another run's file is not this run's result: replacing it needs overwrite
    with pytest.raises(OutputError, match=r"exists; pass overwrite=True"):
        _run(knife, path, resume=True, steps=STEPS - CHUNK)

    _edit(path, _nudge("q", 7))  # damaged after it was written
    with pytest.raises(OutputError, match=r"done\.nc is the finished result of this run but it is DAMAGED.*overwrite"):
        _run(knife, path, resume=True)
    result = _run(knife, path, resume=True, overwrite=True)
    assert any("damaged" in w for w in result.warnings)
    assert_same_file(path, reference[0])


# ---------------------------------------------------------------------------------------------
# 7. Temporaries of dead processes are removed, those of live ones kept
# ---------------------------------------------------------------------------------------------
def test_stale_temporaries_are_removed(knife, reference, tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait(timeout=SUBPROCESS_TIMEOUT)
    path = tmp_path / "X.nc"
    _run(knife, path, stop_after_chunks=2)
    parts = parts_directory(path)
    stale = [tmp_path / f".X.nc.gnipy-{dead.pid}-0123456789ab.tmp", tmp_path / ".X.nc.0123456789ab.tmp",
             parts / f".part_000002.nc.gnipy-{dead.pid}-0123456789ab.tmp", parts / ".part_000003.nc.0123456789ab.tmp"]
    live = tmp_path / f".X.nc.gnipy-{os.getpid()}-abcdefabcdef.tmp"
    for f in (*stale, live):
        f.write_bytes(b"partial")
    assert _run(knife, path, resume=True).complete
    assert not any(f.exists() for f in stale) and live.exists()
    assert not parts.exists()
    assert_same_file(path, reference[0])


# ---------------------------------------------------------------------------------------------
# 8., 9. The stride recorded; the size of the output bounded up front
# ---------------------------------------------------------------------------------------------
def test_the_recorded_stride_is_the_one_used(knife, tmp_path):
    path = tmp_path / "s.nc"
    _run(knife, path, save_every=10**6, chunk_steps=None, attrs={"save_every": 10**6}, stop_after_chunks=0)
    import json

    assert json.loads((parts_directory(path) / "spec.json").read_text())["save_every"] == STEPS


def test_the_output_size_is_bounded_up_front(knife, reference, tmp_path, monkeypatch):
    path = tmp_path / "big.nc"
    with pytest.raises(OutputError, match=r"would hold 1,000,000,000,000,001 saved nodes .* more than max_bytes = "
                                          r"64 GiB.*max_bytes=None to write it anyway"):
        _run(knife, path, steps=10**15, save_every=1, chunk_steps=10**6, stop_after_chunks=0)  # (no endless run)
    with pytest.raises(gnipy.InputError, match=r"steps: .* more than any run can take"):
        _run(knife, path, steps=10**20)
    with pytest.raises(OutputError, match=r"about \d+\.\d KiB, more than max_bytes = 1000 bytes"):
        _run(knife, path, max_bytes=1000, stop_after_chunks=0)
    monkeypatch.setattr(shutil, "disk_usage", lambda d: shutil._ntuple_diskusage(10**9, 10**9 - 100, 100))
    with pytest.raises(OutputError, match=r"needs about .* of disk space .* has 100 bytes free"):
        _run(knife, path)
    assert not path.exists() and not parts_directory(path).exists()  # refused before anything was written
    assert _run(knife, path, max_bytes=None).complete  # the bound lifted (as gni run --yes)
    assert_same_file(path, reference[0])
