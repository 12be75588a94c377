"""Issue 28 at the command line: one writer per output, and nothing left behind by a killed writer.

- D10: two `gni run --checkpoint-every` on the same --out at once: the second is refused at once
  (exit 2, naming the first one's PID), and the first finishes with a file that verifies; the same
  for a sweep store and the output folders of `gni atlas`, `gni convergence` and `gni reproduce`.
- D4: a `gni run --out` killed between writing its temporary and renaming it leaves the temporary
  (nothing runs in a killed process); the next run of that --out removes it.

Killed and concurrent writers are real processes: the lock is the kernel's, dropped when its
process dies.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from typer.testing import CliRunner

from gnipy.cli import app
from gnipy.files import lock_path
from gnipy.io import verify_netcdf

runner = CliRunner()

BASE = ["run", "vertical-disk", "--method", "gni-trapezoid", "--h", "0.1", "--steps", "10"]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def refused_as_busy(res, option, pid):
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and errors[0].startswith(f"Error: {option}:"), res.output
    assert f"being written by another gnipy process (PID {pid})" in errors[0], errors[0]


def gnipy_leftovers(directory):
    return sorted(str(p.relative_to(directory)) for p in directory.rglob("*") if ".gnipy-" in p.name
                  or p.name.endswith((".tmp", ".partial", ".parts")))


def test_two_streamed_runs_on_one_out(tmp_path):
    """The defect: the second run deleted the first's checkpoints and one of them failed with a
    misleading message. Now the second (and a --resume of it) is refused before touching anything."""
    out = tmp_path / "long.nc"
    args = ["run", "knife-edge", "--method", "gni-trapezoid", "--h", "0.0001", "--steps", "2000000",
            "--save-every", "20000", "--checkpoint-every", "200000", "--out", str(out)]
    first = subprocess.Popen([sys.executable, "-m", "gnipy.cli", *args], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not lock_path(out).exists():  # the first run has its lock (before it compiles anything)
            assert first.poll() is None and time.monotonic() < deadline, first.communicate()
            time.sleep(0.05)
        refused_as_busy(invoke(*args), "--out", first.pid)
        refused_as_busy(invoke(*args, "--resume"), "--out", first.pid)
        stdout, stderr = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert first.returncode == 0, stdout + stderr
    ok, message = verify_netcdf(out)
    assert ok, message
    assert gnipy_leftovers(tmp_path) == []


def test_a_run_killed_before_its_rename_is_cleaned_by_the_next(tmp_path):
    out = tmp_path / "r.nc"
    script = textwrap.dedent(f"""
        import os, signal, sys
        real = os.replace
        def replace(src, dst, *a, **k):  # killed just before the final rename
            if str(dst) == {str(out)!r}:
                os.kill(os.getpid(), signal.SIGKILL)
            return real(src, dst, *a, **k)
        os.replace = replace
        from gnipy.cli import app
        sys.argv = ["gni", *{[*BASE, "--out", str(out)]!r}]
        app()
    """)
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                       stdin=subprocess.DEVNULL)
    assert p.returncode == -signal.SIGKILL, p.stdout + p.stderr
    assert not out.exists()
    assert any(name.endswith(".tmp") for name in gnipy_leftovers(tmp_path)), gnipy_leftovers(tmp_path)
    res = invoke(*BASE, "--out", out)
    assert res.exit_code == 0, res.output
    assert verify_netcdf(out)[0]
    assert sorted(os.listdir(tmp_path)) == ["r.nc"]


@pytest.mark.parametrize("command", [
    ["sweep", "rolling-ball", "--method", "gni-midpoint", "--grid", "Omega=0:1:2", "--h", "0.1", "--steps", "2",
     "--workers", "1", "--out", "{out}"],
    ["atlas", "--quick", "--models", "knife-edge", "--methods", "gni-trapezoid", "--out", "{out}"],
    ["convergence", "vertical-disk", "--methods", "gni-trapezoid", "--h-max", "0.1", "--h-min", "0.05",
     "--count", "2", "--out", "{out}"],
    ["reproduce", "--quick", "--out", "{out}"],
    ["demo", "--out", "{out}"],
    [*BASE, "--out", "{out}"],
    ["control", "--example", "sleigh-steering", "--out", "{out}"],
    ["fit", "{problem}", "--out", "{out}"],
], ids=["sweep", "atlas", "convergence", "reproduce", "demo", "run", "control", "fit"])
def test_every_command_refuses_an_output_another_process_writes(tmp_path, command, lock_holder):
    """Each command checks the lock before it computes anything (so these are fast: nothing runs)."""
    out, problem = tmp_path / "out", tmp_path / "fit.toml"
    problem.write_text("# the lock is checked before the problem is read\n")
    p = lock_holder(out)
    refused_as_busy(invoke(*[a.format(out=out, problem=problem) for a in command]), "--out", p.pid)
    p.stdin.close()
    p.wait(timeout=60)
    assert not out.exists()
    assert gnipy_leftovers(tmp_path) == []


def test_a_qualitatively_wrong_run_is_written_and_exits_3(tmp_path):
    """gni-trapezoid on the sleigh to t = 30, a node every 1100 steps (none near t = 21.3, where
    the hidden momentum leaves its band): the file is written with health 'qualitatively wrong',
    the warning is printed, the exit code is 3; --accept-out-of-band exits 0; a healthy run 0."""
    import gnipy

    base = ("run", "chaplygin-sleigh", "--method", "gni-trapezoid", "--h", "0.01", "--t-final", "30",
            "--save-every", "1100")
    res = invoke(*base, "--out", tmp_path / "a.nc")
    assert res.exit_code == 3, res.output
    assert "QUALITATIVELY" in res.output and "left its O(h) band at t = 21.3 " in res.output
    assert "exit code 3" in res.output
    assert gnipy.read_netcdf(tmp_path / "a.nc").attrs["health"] == "qualitatively wrong"
    res = invoke(*base, "--out", tmp_path / "b.nc", "--accept-out-of-band")
    assert res.exit_code == 0, res.output
    assert verify_netcdf(tmp_path / "b.nc")[0]
    res = invoke("run", "chaplygin-sleigh", "--method", "sgni-trapezoid", "--h", "0.01", "--t-final", "30",
                 "--save-every", "1100", "--out", tmp_path / "c.nc")
    assert res.exit_code == 0, res.output
    assert gnipy.read_netcdf(tmp_path / "c.nc").attrs["health"] == "healthy"
