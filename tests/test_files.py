"""gnipy.files: one writer per output (output_lock), no temporaries left behind (atomic writes
clean those of writers that died before their rename), and strict flags (issue 28: D4, D10).

Processes that hold a lock, or die before their rename, are real subprocesses: a lock is the
kernel's (flock), released when its process dies, and a SIGKILL leaves exactly what a power cut
leaves."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest

from gnipy.errors import InputError
from gnipy.files import (
    OutputBusy,
    OutputError,
    atomic_savefig,
    atomic_write,
    atomic_write_text,
    check_destination,
    clean_stale_temporaries,
    lock_path,
    output_lock,
)


def temporaries(directory):
    return sorted(p.name for p in directory.iterdir() if ".gnipy-" in p.name)


def dead_pid():
    p = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                       check=True)
    return int(p.stdout)


# ----------------------------------------------------------------------------------------------
# One writer per output
# ----------------------------------------------------------------------------------------------
def test_a_second_writer_is_refused_at_once_naming_the_owner(tmp_path, lock_holder):
    out = tmp_path / "run.nc"
    p = lock_holder(out)
    try:
        with pytest.raises(OutputBusy, match=rf"--out: .*run\.nc is being written by another gnipy process "
                                             rf"\(PID {p.pid}\)"):
            with output_lock(out, argument="--out"):
                pass
        # an atomic write of the same destination is refused too, and writes nothing
        with pytest.raises(OutputBusy):
            atomic_write_text(out, "second writer")
        assert not out.exists()
    finally:
        p.stdin.close()
        p.wait()
    assert not lock_path(out).exists()  # released and removed by its owner
    atomic_write_text(out, "now")
    assert out.read_text() == "now"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["run.nc"]


def test_the_lock_of_a_killed_writer_is_taken_over_and_removed(tmp_path, lock_holder):
    out = tmp_path / "run.nc"
    p = lock_holder(out)
    p.kill()
    p.wait()
    assert lock_path(out).exists()  # left behind by the SIGKILL ...
    with output_lock(out):  # ... but not held: the kernel dropped the lock with the process
        assert lock_path(out).read_text().strip() == str(os.getpid())
    assert not lock_path(out).exists()


def test_the_lock_is_reentrant_within_a_process(tmp_path):
    out = tmp_path / "run.nc"
    with output_lock(out):
        with output_lock(out):  # e.g. a command holding --out, then the library writing it
            atomic_write_text(out, "inner")
        assert lock_path(out).exists()
    assert not lock_path(out).exists()
    assert out.read_text() == "inner"


def test_a_lock_file_that_is_a_link_is_never_followed(tmp_path):
    out = tmp_path / "run.nc"
    target = tmp_path / "precious"
    target.write_text("keep me")
    os.symlink(target, lock_path(out))
    with pytest.raises(OutputError, match="symbolic link"):
        with output_lock(out):
            pass
    assert target.read_text() == "keep me"


def test_without_flock_the_pid_in_the_lock_file_decides(tmp_path, monkeypatch, lock_holder):
    """Where the file system has no flock (some network file systems), a lock file naming a live
    process other than this one is busy; one naming a dead process is taken over."""
    import errno
    import fcntl

    def no_flock(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    out = tmp_path / "run.nc"
    p = lock_holder(tmp_path / "other.nc")  # a live process that is not this one
    monkeypatch.setattr(fcntl, "flock", no_flock)
    lock_path(out).write_text(f"{p.pid}\n")
    with pytest.raises(OutputBusy, match=rf"PID {p.pid}"):
        with output_lock(out):
            pass
    lock_path(out).write_text(f"{dead_pid()}\n")
    with output_lock(out):
        assert lock_path(out).read_text().strip() == str(os.getpid())
    assert not lock_path(out).exists()


def test_an_unlockable_destination_defers_to_the_writer_s_own_error(tmp_path):
    """Where the lock file cannot be created (here: its directory does not exist), locking does
    nothing and the write that follows reports the real problem."""
    gone = tmp_path / "no-such-directory" / "run.nc"
    with output_lock(gone):  # nothing to lock
        pass
    with pytest.raises(OutputError, match="does not exist"):
        atomic_write_text(gone, "x")


# ----------------------------------------------------------------------------------------------
# No leftovers
# ----------------------------------------------------------------------------------------------
def test_a_failed_write_leaves_no_temporary_and_the_old_file(tmp_path):
    out = tmp_path / "a.txt"
    out.write_text("old")

    def fails(tmp):
        tmp.write_text("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(OutputError, match="No space left"):
        atomic_write(out, fails, overwrite=True)
    assert out.read_text() == "old"
    assert temporaries(tmp_path) == []


def test_a_failed_figure_leaves_no_temporary(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])

    def half_then_full_disk(tmp, **kwargs):  # the figure's file is begun, then the disk is full
        with open(tmp, "wb") as f:
            f.write(b"\x89PNG half")
        raise OSError(28, "No space left on device")

    fig.savefig = half_then_full_disk
    with pytest.raises(OutputError, match="No space left"):
        atomic_savefig(fig, tmp_path / "f.png")
    plt.close(fig)
    assert list(tmp_path.iterdir()) == []


def test_a_writer_killed_before_its_rename_is_cleaned_by_the_next_write(tmp_path):
    """The writer gets SIGKILL between writing its temporary and renaming it: the temporary stays
    (nothing can run in a killed process), and the next write of the same destination removes it."""
    out = tmp_path / "result.txt"
    script = textwrap.dedent(f"""
        import os, signal
        import gnipy.files as files
        real = os.replace
        def die(src, dst, *a, **k):
            os.kill(os.getpid(), signal.SIGKILL)
        os.replace = die
        files.atomic_write_text({str(out)!r}, "never renamed")
    """)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert p.returncode == -signal.SIGKILL, p.stderr
    left = temporaries(tmp_path)
    assert len(left) == 2 and any(n.endswith(".tmp") for n in left), left  # the temporary and the lock
    assert not out.exists()
    atomic_write_text(out, "complete")
    assert out.read_text() == "complete"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["result.txt"]


def test_temporaries_of_live_processes_and_other_names_are_left(tmp_path):
    out = tmp_path / "r.nc"
    mine = tmp_path / f".r.nc.gnipy-{os.getpid()}-0123456789ab.tmp"
    stale = tmp_path / f".r.nc.gnipy-{dead_pid()}-0123456789ab.tmp"
    other = tmp_path / f".q.nc.gnipy-{dead_pid()}-0123456789ab.tmp"
    for f in (mine, stale, other):
        f.write_text("x")
    assert clean_stale_temporaries(out) == [stale]
    assert mine.exists() and other.exists() and not stale.exists()


# ----------------------------------------------------------------------------------------------
# Flags are booleans
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("value", ["no", "False", 0, 1, None, [True]])
def test_overwrite_must_be_a_bool(tmp_path, value):
    (tmp_path / "a.txt").write_text("old")
    with pytest.raises(InputError, match="overwrite: expected True or False"):
        check_destination(tmp_path / "a.txt", overwrite=value)
    assert (tmp_path / "a.txt").read_text() == "old"


def test_an_empty_variable_is_checksummed_as_the_file_reads_it():
    """A model on G alone has no coordinates: the streamed writer's checksum of its empty string
    variable `coordinate` once raised (an empty array could not be cut into entries), then differed
    from the one read back from the file, so that every streamed file of such a model was reported
    DAMAGED. Written whole, an empty variable is fed as netCDF reads it: float zeros of its trailing
    shape (gnipy.files.as_stored), whatever its type."""
    import numpy as np

    from gnipy.files import DataChecksum, as_stored

    names, read_back = DataChecksum(), DataChecksum()
    names.update("coordinate", as_stored(np.array([], dtype=object)))
    read_back.update("coordinate", np.zeros((0,)))
    assert names.hexdigest() == read_back.hexdigest()
    empty_strings = DataChecksum()
    empty_strings.update("coordinate", np.array([], dtype=object))  # no error
    assert empty_strings.hexdigest() != names.hexdigest()  # the type is part of the digest
    np.testing.assert_array_equal(as_stored(np.arange(3)), np.arange(3))
