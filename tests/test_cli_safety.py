"""Issue 12 at the command line: nothing lost, nothing silently wrong, no traceback on any path.

Each test reproduces one defect that `gni` had, through the command line (typer's CliRunner, in
process; real write failures in a subprocess with a file-size limit):

1. ownership: an existing --out/--plot file is refused without --overwrite (also when the path
   comes from a config file); links, FIFOs and directories always; output directories gnipy
   creates carry a marker and are rewritten on a rerun, other directories need --overwrite;
2. a full disk: a one-line message and exit code 1, no temporary left, an existing file untouched;
3. a step size or final time that overflows the step count: a clean usage error;
4. terminal safety: text from files and paths is printed literally, control characters escaped;
5. `set = { "m=2,g" = 1 }` in a config file is refused;
6. runs beyond the memory/file bounds are refused before anything is compiled (`--yes` runs them);
7. the recorded save stride is the one used;
8. `gni verify`, and `gni info`'s checksum line.

The runs share one compilation with tests/test_cli.py where they can (vertical disk, h = 0.1, 10 steps).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
import gnipy.resources
from gnipy.cli import app, resources
from gnipy.cli.output import safe

runner = CliRunner()

MODEL = "vertical-disk"
BASE = ["run", MODEL, "--method", "gni-trapezoid", "--h", "0.1", "--steps", "10"]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def errors_of(res):
    return [line for line in res.output.splitlines() if line.startswith("Error")]


def assert_usage_error(res, *words, code=2):
    """Exit `code`, no traceback, exactly one error line holding every word."""
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    errors = errors_of(res)
    assert len(errors) == 1, res.output
    for word in words:
        assert word in errors[0], (word, errors[0])
    return errors[0]


def temporaries(directory):
    return sorted(p.name for p in directory.rglob("*") if p.name.endswith((".tmp", ".partial")))


# --------------------------------------------------------------------------------------------------
# 1. Ownership: --overwrite, links and special files, config paths, owned directories
# --------------------------------------------------------------------------------------------------
def test_run_refuses_existing_out_and_plot_without_overwrite(tmp_path):
    out, png = tmp_path / "run.nc", tmp_path / "run.png"
    assert invoke(*BASE, "--out", out, "--plot", png).exit_code == 0
    nc_bytes, png_bytes = out.read_bytes(), png.read_bytes()

    res = invoke(*BASE, "--q0", "1,0,0,0", "--out", out)
    assert_usage_error(res, "--out", str(out), "--overwrite")
    res = invoke(*BASE, "--q0", "1,0,0,0", "--out", tmp_path / "other.nc", "--plot", png)
    assert_usage_error(res, "--plot", str(png), "--overwrite")
    assert out.read_bytes() == nc_bytes and png.read_bytes() == png_bytes  # untouched
    assert sorted(os.listdir(tmp_path)) == ["run.nc", "run.png"]  # refused before the run

    res = invoke(*BASE, "--q0", "1,0,0,0", "--out", out, "--plot", png, "--overwrite")
    assert res.exit_code == 0, res.output
    assert xr.load_dataset(out)["q"].values[0, 0] == 1.0 and png.read_bytes() != png_bytes
    # --out and --plot naming one file: refused (the figure would replace the result)
    res = invoke(*BASE, "--out", tmp_path / "same.png", "--plot", tmp_path / "same.png")
    assert_usage_error(res, "--plot", "also --out")
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("option", ["--out", "--plot"])
@pytest.mark.parametrize("kind", ["symlink", "fifo", "directory"])
def test_links_fifos_and_directories_are_refused_even_with_overwrite(tmp_path, option, kind):
    target = tmp_path / "victim.txt"
    target.write_text("precious")
    path = tmp_path / ("x.nc" if option == "--out" else "x.png")
    if kind == "symlink":
        path.symlink_to(target)
    elif kind == "fifo":
        os.mkfifo(path)  # writing it would block (or feed whoever reads it)
    else:
        path.mkdir()
    args = ["--out", path] if option == "--out" else ["--out", tmp_path / "r.nc", "--plot", path]
    for extra in ([], ["--overwrite"]):
        res = invoke(*BASE, *args, *extra)
        assert_usage_error(res, option, str(path))
    assert target.read_text() == "precious" and os.path.lexists(path)
    assert not (tmp_path / "r.nc").exists()


def test_config_out_does_not_overwrite_what_it_points_at(tmp_path):
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "important.txt").write_text("precious")
    (victim / "link.nc").symlink_to(victim / "important.txt")
    conf = tmp_path / "conf"
    conf.mkdir()
    for out in ("../victim/important.txt", "../victim/link.nc"):
        (conf / "run.toml").write_text(f'model = "{MODEL}"\nh = 0.1\nsteps = 10\nout = "{out}"\n')
        res = invoke("run", "--config", conf / "run.toml")
        assert_usage_error(res, "--out", "run.toml", "victim")
        # a config file cannot grant --overwrite: only the command line does
        (conf / "run.toml").write_text(f'model = "{MODEL}"\nh = 0.1\nsteps = 10\nout = "{out}"\noverwrite = true\n')
        assert_usage_error(invoke("run", "--config", conf / "run.toml"), "--config", "'overwrite'", "unknown key")
    assert (victim / "important.txt").read_text() == "precious"
    assert sorted(os.listdir(victim)) == ["important.txt", "link.nc"]


def test_demo_refuses_an_existing_out(tmp_path, monkeypatch):
    out = tmp_path / "demo.nc"
    out.write_text("precious")
    monkeypatch.setattr(gnipy, "simulate", lambda *a, **k: pytest.fail("ran before checking --out"))
    assert_usage_error(invoke("demo", "--out", out), "--out", "--overwrite")
    assert out.read_text() == "precious"
    os.remove(out)
    out.symlink_to(tmp_path / "elsewhere")
    assert_usage_error(invoke("demo", "--out", out, "--overwrite"), "--out", "symbolic link")


STUDY = ["convergence", MODEL, "--methods", "gni-trapezoid", "--h-max", "0.1", "--h-min", "0.05", "--count", "2",
         "--t-final", "0.2"]


def test_convergence_owns_the_directory_it_creates(tmp_path):
    study = tmp_path / "a" / "study"  # parents created too; the study directory gets the marker
    assert invoke(*STUDY, "--out", study).exit_code == 0
    assert (study / ".gnipy-owned").is_file() and not (tmp_path / "a" / ".gnipy-owned").exists()
    inode = (study / "convergence.csv").stat().st_ino
    res = invoke(*STUDY, "--out", study)  # a rerun into its own directory replaces its files
    assert res.exit_code == 0, res.output
    assert (study / "convergence.csv").stat().st_ino != inode  # a new file, renamed into place
    # a file someone put at one of its names as a link is never written through
    os.remove(study / "convergence.png")
    (study / "convergence.png").symlink_to(tmp_path / "target.png")
    assert_usage_error(invoke(*STUDY, "--out", study, "--overwrite"), "--out", "symbolic link")
    assert not (tmp_path / "target.png").exists()

    foreign = tmp_path / "mine"  # a directory gnipy did not create, holding a file of the same name
    foreign.mkdir()
    (foreign / "convergence.csv").write_text("my notes")
    (foreign / "other.txt").write_text("mine too")
    res = invoke(*STUDY, "--out", foreign)
    assert_usage_error(res, "--out", "convergence.csv", "--overwrite")
    assert (foreign / "convergence.csv").read_text() == "my notes"
    res = invoke(*STUDY, "--out", foreign, "--overwrite")
    assert res.exit_code == 0, res.output
    assert (foreign / "convergence.csv").read_text().startswith("method,steps")
    assert (foreign / "other.txt").read_text() == "mine too" and not (foreign / ".gnipy-owned").exists()
    assert temporaries(tmp_path) == []


def _stub_reproduction(monkeypatch):
    """gni reproduce with stages that are instant but write through the real figure writers."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    import gnipy.experiments.struggles as st
    import gnipy.experiments.theorems as th
    from gnipy.experiments import figures as F
    from gnipy.experiments import reproduce as rp
    from gnipy.experiments.figure_tools import write_figure

    def figure(name):
        def make(out_dir, quick, progress=None):
            fig = Figure(figsize=(1.0, 0.8))
            FigureCanvasAgg(fig)
            fig.subplots().plot([0, 1], [1, 0])
            files = write_figure(fig, out_dir, name)  # the real writer: atomic, ownership rules
            return F.FigureResult(name, name, "stub", files, {}, [], [])

        return make

    monkeypatch.setattr(rp, "_figure_functions",
                        lambda: {f"figure_{k}": figure(f"figure{k}") for k in (1, 2, 3)})
    monkeypatch.setattr(th, "theorem_table", lambda quick, progress=None: [])
    monkeypatch.setattr(th, "errata_rows", lambda quick, progress=None: [])
    monkeypatch.setattr(st, "struggle_figures", lambda out_dir, quick, progress=None: [])


def test_reproduce_reruns_into_its_own_folder_and_asks_elsewhere(tmp_path, monkeypatch):
    _stub_reproduction(monkeypatch)
    out = tmp_path / "gnipy-reproduction"
    assert invoke("reproduce", "--out", out, "--quick").exit_code == 0
    assert (out / ".gnipy-owned").is_file() and (out / "report.html").is_file()
    inode = (out / "figure1.png").stat().st_ino
    res = invoke("reproduce", "--out", out, "--quick")  # the README's command stays re-runnable
    assert res.exit_code == 0, res.output
    assert (out / "figure1.png").stat().st_ino != inode

    foreign = tmp_path / "papers"
    foreign.mkdir()
    (foreign / "report.md").write_text("my report")
    res = invoke("reproduce", "--out", foreign, "--quick")
    assert_usage_error(res, "--out", "report.md", "--overwrite")
    assert sorted(os.listdir(foreign)) == ["report.md"]  # refused before any stage ran
    res = invoke("reproduce", "--out", foreign, "--quick", "--overwrite")
    assert res.exit_code == 0, res.output
    assert "my report" not in (foreign / "report.md").read_text() and not (foreign / ".gnipy-owned").exists()
    (foreign / "figure2.pdf").unlink()
    os.mkfifo(foreign / "figure2.pdf")
    assert_usage_error(invoke("reproduce", "--out", foreign, "--quick", "--overwrite"), "--out", "FIFO")
    assert temporaries(tmp_path) == []


def test_streamed_run_refuses_an_existing_out_without_overwrite(tmp_path):
    out = tmp_path / "s.nc"
    streamed = [*BASE, "--checkpoint-every", "5", "--out", out]
    assert invoke(*streamed).exit_code == 0
    before = out.read_bytes()
    assert_usage_error(invoke(*streamed), "--out", "--overwrite")
    assert out.read_bytes() == before
    res = invoke(*streamed, "--q0", "1,0,0,0", "--overwrite")  # simulate_to_file(overwrite=True)
    assert res.exit_code == 0, res.output
    assert xr.load_dataset(out)["q"].values[0, 0] == 1.0
    assert sorted(os.listdir(tmp_path)) == ["s.nc"]


# --------------------------------------------------------------------------------------------------
# 2. A full disk: real write failures (a file-size limit: writes past it fail with EFBIG)
# --------------------------------------------------------------------------------------------------
FULL_DISK_SCRIPT = textwrap.dedent(r'''
    import hashlib, json, os, resource, signal, sys
    from pathlib import Path
    from typer.testing import CliRunner
    from gnipy.cli import app

    runner = CliRunner()
    here = Path.cwd()
    BASE = ["run", "vertical-disk", "--method", "gni-trapezoid", "--h", "0.1", "--steps", "10"]
    STUDY = ["convergence", "vertical-disk", "--methods", "gni-trapezoid", "--h-max", "0.1", "--h-min", "0.05",
             "--count", "2", "--t-final", "0.2"]

    def digest(p):
        return hashlib.sha256(p.read_bytes()).hexdigest() if p.exists() else None

    def invoke(args):
        res = runner.invoke(app, [str(a) for a in args])
        exc = res.exception
        return {"args": [str(a) for a in args], "code": res.exit_code, "output": res.output,
                "exception": None if exc is None or isinstance(exc, SystemExit) else repr(exc)}

    def limit(n):
        hard = resource.getrlimit(resource.RLIMIT_FSIZE)[1]
        resource.setrlimit(resource.RLIMIT_FSIZE, (n, hard))

    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails (EFBIG), no signal
    setup = [invoke([*BASE, "--out", "good.nc", "--plot", "good.png"]), invoke([*STUDY, "--out", "study"])]
    files = ["good.nc", "good.png", "study/convergence.csv", "study/convergence.png"]
    before = {f: digest(here / f) for f in files}
    sizes = {f: (here / f).stat().st_size for f in files}
    cases = []
    limit(sizes["good.nc"] // 4)  # below every file written here
    cases.append(("--out", invoke([*BASE, "--q0", "1,0,0,0", "--out", "good.nc", "--overwrite"])))
    cases.append(("--out", invoke([*BASE, "--out", "new.nc"])))
    cases.append(("--out", invoke([*BASE, "--out", "streamed.nc", "--checkpoint-every", "5"])))
    limit(sizes["study/convergence.csv"] // 2)
    cases.append(("--out", invoke([*STUDY, "--out", "study"])))
    cases.append(("--out", invoke([*STUDY, "--out", "study2"])))
    limit((sizes["good.nc"] + sizes["good.png"]) // 2)  # the result fits, the figure does not
    cases.append(("--plot", invoke([*BASE, "--out", "other.nc", "--plot", "good.png", "--overwrite"])))
    limit(resource.RLIM_INFINITY)
    after = {f: digest(here / f) for f in files}
    left = sorted(str(p.relative_to(here)) for p in here.rglob("*") if p.name.endswith((".tmp", ".partial")))
    print("RESULT " + json.dumps({"setup": setup, "cases": cases, "before": before, "after": after, "left": left,
                                  "exists": {f: (here / f).exists() for f in ["new.nc", "study2", "other.nc"]}}))
''')


def test_a_full_disk_gives_a_clean_error_and_keeps_the_old_files(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("GNIPY_")}
    proc = subprocess.run([sys.executable, "-c", FULL_DISK_SCRIPT], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=300, stdin=subprocess.DEVNULL)
    line = next((x for x in proc.stdout.splitlines() if x.startswith("RESULT ")), None)
    assert line is not None, proc.stdout[-3000:] + proc.stderr[-3000:]
    r = json.loads(line[len("RESULT "):])
    assert [c["code"] for c in r["setup"]] == [0, 0], r["setup"]
    for option, case in r["cases"]:
        where = f"{' '.join(case['args'])}:\n{case['output']}"
        assert case["exception"] is None, where + case["exception"]
        assert case["code"] == 1 and "Traceback" not in case["output"], where
        errors = [x for x in case["output"].splitlines() if x.startswith("Error")]
        assert len(errors) == 1 and errors[0].startswith(f"Error: {option}:"), where
        assert "File too large" in errors[0] or "HDF error" in errors[0] or "disk" in errors[0], where
    assert r["after"] == r["before"]  # the earlier result, figure and study are untouched
    assert r["left"] == []  # no temporary file left
    assert r["exists"] == {"new.nc": False, "study2": False, "other.nc": True}
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]


# --------------------------------------------------------------------------------------------------
# 3. Step counts that overflow; 6. bounds checked before anything is compiled
# --------------------------------------------------------------------------------------------------
@pytest.fixture
def no_computation(monkeypatch):
    """Any simulation fails the test: the refusals below must come first."""
    import gnipy.streaming

    def tripwire(*a, **k):
        pytest.fail("reached a computation")

    monkeypatch.setattr(gnipy, "simulate", tripwire)
    monkeypatch.setattr(gnipy.streaming, "simulate_to_file", tripwire)


OVERFLOW = [
    (["knife-edge", "--h", "1e-320", "--t-final", "10"], "--h"),
    (["knife-edge", "--h", "1e-300", "--t-final", "1e300"], "--t-final"),
    ([MODEL, "--h", "5e-324", "--steps", "10"], "--h"),
    ([MODEL, "--h", "0.1", "--steps", str(10**20)], "--steps"),
    ([MODEL, "--h", "0.1", "--steps", str(10**12)], "--steps/--save-every"),
    ([MODEL, "--h", "1e-3", "--t-final", "1e9"], "--t-final/--save-every"),
    ([MODEL, "--h", "0.1", "--steps", str(10**12), "--save-every", str(10**11)], "--save-every"),
]


@pytest.mark.parametrize("args, option", OVERFLOW, ids=[" ".join(a) for a, _ in OVERFLOW])
def test_overflowing_and_huge_step_counts_are_refused_at_once(tmp_path, no_computation, args, option):
    # CPU time of this process: "at once" means nothing is computed, whatever else loads the
    # machine (the suite's other worker may hold both cores, e.g. with a native batch)
    start = time.process_time()
    res = invoke("run", *args, "--out", tmp_path / "x.nc")
    seconds = time.process_time() - start
    assert_usage_error(res, f"Error: {option}:")
    assert seconds < 1.0 and os.listdir(tmp_path) == []


@pytest.mark.parametrize("steps, words", [(10**20, ["--steps (from key 'steps'", "more than any run"]),
                                          (10**12, ["--steps/--save-every (from key", "TiB", "--yes"])])
def test_config_with_a_huge_step_count_is_refused_at_once(tmp_path, no_computation, steps, words):
    (tmp_path / "run.toml").write_text(f'model = "{MODEL}"\nh = 0.1\nsteps = {steps}\nout = "x.nc"\n')
    start = time.process_time()  # CPU time: nothing computed, whatever the machine's load
    res = invoke("run", "--config", tmp_path / "run.toml")
    assert time.process_time() - start < 1.0
    assert_usage_error(res, *words)
    (tmp_path / "tiny.toml").write_text('model = "knife-edge"\nh = 1e-320\nt-final = 10\nout = "x.nc"\n')
    assert_usage_error(invoke("run", "--config", tmp_path / "tiny.toml"), "--h (from key 'h'", "below")
    assert sorted(os.listdir(tmp_path)) == ["run.toml", "tiny.toml"]


def test_memory_and_file_bounds_and_yes(tmp_path, monkeypatch):
    out = tmp_path / "x.nc"
    monkeypatch.setattr(gnipy.resources, "MAX_MEMORY_BYTES", 1000)
    err = assert_usage_error(invoke(*BASE, "--out", out), "--steps/--save-every", "in memory", "--checkpoint-every",
                             "--yes")
    assert "bytes" in err or "KiB" in err
    monkeypatch.setattr(gnipy.resources, "MAX_MEMORY_BYTES", 2**33)
    monkeypatch.setattr(resources, "MAX_OUTPUT_BYTES", 100)
    assert_usage_error(invoke(*BASE, "--out", out), "--steps/--save-every", "the file would hold 11 saved nodes",
                       "--yes")
    monkeypatch.setattr(resources, "MAX_OUTPUT_BYTES", 2**36)
    import shutil

    class Usage:
        free = 10

    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage)
    assert_usage_error(invoke(*BASE, "--out", out), "free", "--yes")
    assert not out.exists()
    monkeypatch.setattr(gnipy.resources, "MAX_MEMORY_BYTES", 1000)
    res = invoke(*BASE, "--out", out, "--yes")  # the user says so: it runs
    assert res.exit_code == 0, res.output
    assert out.is_file()


def test_memory_bound_is_at_most_half_the_ram():
    pages = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    assert resources.memory_bound() == min(gnipy.resources.MAX_MEMORY_BYTES, pages // 2)


# --------------------------------------------------------------------------------------------------
# 4. Terminal safety
# --------------------------------------------------------------------------------------------------
NASTY = {"note_close": "[/bold]", "note_bare": "[/]", "note_link": "[link=http://x]y[/link]",
         "note_ansi": "\x1b[31mred", "note_bell": "ring\x07", "note_c1": "a\x9bb", "note_del": "x\x7fy",
         "note_emoji": ":warning:", "model": "[bold]m[/bold]", "params": '{"[red]": 1.0}'}


def _nasty_file(path):
    ds = xr.Dataset({"energy": (("time",), np.array([1.0, 1.0]))}, coords={"time": [0.0, 1.0]})
    gnipy.io.write_netcdf(ds, path, attrs=NASTY)
    return path


def assert_shown_literally(output):
    assert "\x1b" not in output and "\x07" not in output and "\x9b" not in output and "\x7f" not in output
    for text in ("[/bold]", "[/]", "[link=http://x]y[/link]", "\\x1b[31mred", "ring\\x07", "a\\x9bb", "x\\x7fy",
                 ":warning:", "[bold]m[/bold]", "[red]=1"):
        assert text in output, (text, output)


def test_info_prints_attributes_literally(tmp_path):
    directory = tmp_path / "a["
    directory.mkdir()
    path = _nasty_file(directory / "]b.nc")  # the path holds "[/]"
    assert "[/]" in str(path)
    res = invoke("info", path)
    assert res.exit_code == 0 and res.exception is None, res.output
    assert_shown_literally(res.output)
    assert f"gni info: {path}" in res.output and "checksum" in res.output


@pytest.mark.parametrize("name", ["x\x1b[31m.nc", "[/]", "a\x07\x9b.nc", "[link=http://x]y"])
def test_paths_with_markup_and_control_characters(tmp_path, name, no_computation):
    path = tmp_path / name.replace("/", "_") if name != "[/]" else tmp_path / "[" / "]"
    path.parent.mkdir(exist_ok=True)
    path.write_text("taken")
    shown = safe(path)
    for args in (["info", path], ["verify", path], [*BASE, "--out", path], ["demo", "--out", path]):
        res = invoke(*args)
        assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
        assert shown in errors_of(res)[0], (shown, res.output)
        assert "\x1b" not in res.output and "\x07" not in res.output
    assert path.read_text() == "taken"


def test_a_run_whose_path_holds_markup(tmp_path):
    directory = tmp_path / "[bold]x["
    directory.mkdir()
    out = directory / "]y.nc"
    res = invoke(*BASE, "--out", out)
    assert res.exit_code == 0 and res.exception is None, res.output
    assert f"written: {out}" in res.output


def test_safe_escapes_every_control_character():
    for code in [*range(0x20), 0x7F, *range(0x80, 0xA0), 0x202E, 0x2028]:
        shown = safe(f"a{chr(code)}b")
        assert shown.startswith("a\\") and shown.endswith("b") and shown.isprintable(), (code, shown)
    assert safe("plain [text] é ü 🚀") == "plain [text] é ü 🚀"
    assert safe("\udcff") == "\\udcff"  # an undecodable byte of a path


# --------------------------------------------------------------------------------------------------
# 5. `set` tables in config files; 7. the save stride recorded
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("table", ['{ "m=2,r" = 1 }', '{ "m=2" = 1 }', '{ "m " = 1 }', '{ "" = 1 }',
                                   '{ "r,m" = 2 }', '{ "1m" = 1 }'])
def test_config_set_table_keys_must_be_parameter_names(tmp_path, table, no_computation):
    (tmp_path / "run.toml").write_text(f'model = "{MODEL}"\nh = 0.1\nsteps = 10\nset = {table}\n')
    assert_usage_error(invoke("run", "--config", tmp_path / "run.toml", "--out", tmp_path / "x.nc"),
                       "--config", "key 'set'", "not a parameter name")


def test_save_stride_recorded_is_the_one_used(tmp_path):
    out = tmp_path / "x.nc"
    res = invoke(*BASE, "--save-every", "100", "--out", out)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out)
    assert ds.attrs["save_every"] == 10 and ds.sizes["time"] == 2  # min(100, 10 steps): the ends only
    np.testing.assert_array_equal(ds["step"].values, [0, 10])


# --------------------------------------------------------------------------------------------------
# 8. gni verify, and gni info's checksum line
# --------------------------------------------------------------------------------------------------
def test_verify_result_files(tmp_path):
    import netCDF4

    out = tmp_path / "run.nc"
    assert invoke(*BASE, "--out", out).exit_code == 0
    res = invoke("verify", out)
    assert res.exit_code == 0 and "ok" in res.output, res.output
    assert "checksum verified: " in " ".join(invoke("info", out).output.split())
    with netCDF4.Dataset(out, "a") as nc:  # one value edited after the run
        nc.variables["energy"][3] = 0.0
    assert_usage_error(invoke("verify", out), "PATH:", "DAMAGED", code=1)
    info = invoke("info", out)
    assert info.exit_code == 0 and "NOT verified" in info.output and "DAMAGED" in info.output
    # a file without a checksum: cannot be verified (exit 1, saying so)
    plain = xr.load_dataset(out)
    plain.attrs = {}
    plain.to_netcdf(tmp_path / "plain.nc")
    assert_usage_error(invoke("verify", tmp_path / "plain.nc"), "gnipy_checksum", code=1)


def test_verify_unreadable_paths_and_unfinished_runs(tmp_path):
    assert_usage_error(invoke("verify", tmp_path / "missing.nc"), "PATH", "no such file")
    (tmp_path / "junk.nc").write_text("not netCDF")
    assert_usage_error(invoke("verify", tmp_path / "junk.nc"), "PATH", "junk.nc")
    os.mkfifo(tmp_path / "fifo.nc")  # never opened: reading it would block
    assert_usage_error(invoke("verify", tmp_path / "fifo.nc"), "PATH", "not a regular file")
    assert_usage_error(invoke("info", tmp_path / "fifo.nc"), "FILE", "not a regular file")
    parts = tmp_path / "long.nc.parts"  # the checkpoints of an interrupted streamed run
    parts.mkdir()
    (parts / "spec.json").write_text("{}")
    for path in (parts, tmp_path / "long.nc"):
        assert_usage_error(invoke("verify", path), "unfinished streamed run", "--resume", code=1)


def test_verify_dispatches_sweep_stores(tmp_path, monkeypatch):
    import gnipy.sweep as sweep

    store = tmp_path / "s.zarr"
    store.mkdir()
    monkeypatch.setattr(sweep, "verify_sweep", lambda p: (True, f"{p}: ok, 4 chunks verified", []), raising=False)
    res = invoke("verify", store)
    assert res.exit_code == 0 and "ok, 4 chunks verified" in res.output
    monkeypatch.setattr(sweep, "verify_sweep", lambda p: (False, "chunk 3 is damaged", [3]), raising=False)
    assert_usage_error(invoke("verify", store), "PATH", "chunk 3", code=1)

    def not_a_store(p):
        raise sweep.SweepError(f"path: {str(p)!r} is not a gnipy sweep store")

    monkeypatch.setattr(sweep, "verify_sweep", not_a_store, raising=False)
    assert_usage_error(invoke("verify", store), "PATH", "not a gnipy sweep store")
    monkeypatch.delattr(sweep, "verify_sweep", raising=False)  # a gnipy without it: a clean message
    assert_usage_error(invoke("verify", store), "PATH", "cannot verify sweep stores")
