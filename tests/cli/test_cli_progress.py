"""Progress of the long `gni` commands when not on a terminal (gnipy.cli.progress): plain lines,
every tenth of the work or every 10 s; and the CLI's reading of the library (method orders,
messages that name arguments).

typer's CliRunner is not a terminal: the commands run there as in a batch job or a pipe.
"""

import re

import pytest
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app
from gnipy.cli.progress import LINE_EVERY_SECONDS, Progress
from gnipy.cli.run import PROGRESS_STEPS

runner = CliRunner()


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def plain(total=None, unit="runs"):
    lines, clock = [], Clock()
    return Progress("study", total, unit, terminal=False, write=lines.append, clock=clock), lines, clock


def test_a_line_per_tenth_of_the_work_and_at_the_end():
    progress, lines, clock = plain(1000, "steps")
    with progress:
        for done in range(0, 1001, 20):
            clock.now += 0.01
            progress.update(done)
    shown = [int(re.match(r"study: ([\d,]+)/1,000 steps, \d+ s$", line)[1].replace(",", "")) for line in lines]
    assert shown == list(range(0, 1001, 100)), lines


def test_a_line_every_10_s_when_the_work_is_slow():
    progress, lines, clock = plain(10**6, "steps")
    with progress:
        progress.update(0)
        for done in (1, 2, 3):
            clock.now += LINE_EVERY_SECONDS + 1
            progress.update(done)
        clock.now += 1
        progress.update(4)  # a second later, far from the next tenth: no line
    assert lines == ["study: 0/1,000,000 steps, 0 s", "study: 1/1,000,000 steps, 11 s", "study: 2/1,000,000 steps, 22 s",
                     "study: 3/1,000,000 steps, 33 s", "study: 4/1,000,000 steps, 34 s"], lines
    # (the last line is the one at the end of the work: what was done when it stopped)


def test_the_callback_form_and_a_total_given_late():
    progress, lines, _ = plain()
    with progress:
        for k in range(4):
            progress(k, 3, f"run {k}")  # as gnipy.analysis.convergence_study calls it
    assert lines == [f"study: {k}/3 runs, 0 s: run {k}" for k in range(4)]  # the plain lines name the stage
    progress, lines, _ = plain()
    with progress:
        pass
    assert lines == []  # nothing to say: no total, nothing done


def _progress_lines(output, command, unit):
    return [line for line in output.splitlines()
            if re.fullmatch(rf"{command}: [\d,]+/[\d,]+ {unit}, \d+ s(: .+)?", line)]


def test_gni_convergence_reports_its_runs(tmp_path):
    res = runner.invoke(app, ["convergence", "vertical-disk", "--methods", "gni-trapezoid,gni-euler-a", "--h-max",
                              "0.1", "--h-min", "0.05", "--count", "2", "--out", str(tmp_path / "study")])
    assert res.exit_code == 0, res.output
    lines = _progress_lines(res.output, "convergence", "runs")
    assert [line.split(",")[0] for line in lines] == [f"convergence: {k}/4 runs" for k in range(5)], res.output


def test_gni_run_reports_the_steps_of_a_long_run(tmp_path):
    n = PROGRESS_STEPS
    res = runner.invoke(app, ["run", "vertical-disk", "--method", "gni-trapezoid", "--h", "0.0001", "--steps", str(n),
                              "--save-every", str(n), "--out", str(tmp_path / "long.nc")])
    assert res.exit_code == 0, res.output
    lines = _progress_lines(res.output, "run", "steps")
    assert len(lines) >= 3 and lines[-1].startswith(f"run: {n:,}/{n:,} steps"), res.output
    done = [int(line.split("/")[0].split()[-1].replace(",", "")) for line in lines]
    assert done == sorted(done)


def test_gni_run_says_nothing_of_progress_for_a_short_run(tmp_path):
    res = runner.invoke(app, ["run", "vertical-disk", "--method", "gni-trapezoid", "--h", "0.1", "--steps", "10",
                              "--out", str(tmp_path / "short.nc")])
    assert res.exit_code == 0, res.output
    assert not _progress_lines(res.output, "run", "steps")


def test_gni_methods_shows_the_order_each_method_states():
    res = runner.invoke(app, ["methods"])
    assert res.exit_code == 0
    holonomic = "; keeps holonomic constraints"
    for name in gnipy.method_names():
        line = next(line for line in res.output.splitlines() if line.startswith(name + " "))
        method = gnipy.get_method(name)
        assert line.endswith(holonomic) == method.holonomic, line  # stated once, on the method
        line = line.removesuffix(holonomic)
        order = method.order
        assert line.endswith(f"(order {order})") if order is not None else "(order" not in line, line


def test_library_messages_name_arguments_and_the_cli_names_options(tmp_path):
    spec = gnipy.get_model("vertical-disk")
    with pytest.raises(gnipy.InputError, match=r"^params: unknown parameter 'nope'"):
        spec.resolve_params({"nope": 1.0})
    res = runner.invoke(app, ["run", "vertical-disk", "--h", "0.1", "--steps", "10", "--set", "nope=1",
                              "--out", str(tmp_path / "x.nc")])
    assert res.exit_code == 2
    assert [line for line in res.output.splitlines() if line.startswith("Error")] == [
        "Error: --set: unknown parameter 'nope' of model 'vertical-disk' (known: "
        + ", ".join(spec.params) + ")"]


def test_a_heartbeat_for_work_that_does_not_count(monkeypatch):
    import time

    import gnipy.cli.progress as progress_module

    monkeypatch.setattr(progress_module, "LINE_EVERY_SECONDS", 0.05)
    lines = []
    with Progress("reproduce", terminal=False, write=lines.append, heartbeat=True):
        time.sleep(0.5)
    assert len(lines) >= 3 and all(re.fullmatch(r"reproduce: \d+ s", line) for line in lines[:-1]), lines
    assert re.fullmatch(r"reproduce: finished, \d+ s", lines[-1]), lines


def test_gni_reproduce_passes_its_progress_to_the_stages(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import gnipy.experiments.reproduce as reproduction

    def run_reproduction(out_dir, quick, *, console=None, overwrite=False, progress=None):
        for k in range(6):  # six stages, as the reproduction runs them
            progress(k, 6, f"stage {k}")
        progress(6, 6, "")
        return SimpleNamespace(ok=True)

    monkeypatch.setattr(reproduction, "run_reproduction", run_reproduction)
    res = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "r"), "--quick"])
    assert res.exit_code == 0, res.output
    lines = _progress_lines(res.output, "reproduce", "stages")
    assert [line.split(",")[0] for line in lines] == [f"reproduce: {k}/6 stages" for k in range(7)], res.output
    assert [line.partition(" s:")[2] for line in lines] == [f" stage {k}" for k in range(6)] + [""], res.output


def test_gni_sweep_reports_its_chunks(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import gnipy.sweep

    def run_sweep(model, grid, *, out, progress=True, **kwargs):
        if callable(progress):
            for k in range(5):
                progress(k, 4)
        spec = {"model": model, "params": {}, "method": "mp", "h": 0.1, "steps": 10, "save_every": 10,
                "grid": [{"name": "m", "start": 1.0, "stop": 2.0, "count": 8}]}
        return SimpleNamespace(path=out, members=8, chunks=4, chunk_size=2, chunks_computed=4, chunks_skipped=0,
                               chunks_remaining=0, chunks_repaired=0, failed_members=0, failures=[], wall_time=1.0,
                               members_computed=8, member_steps_per_second=80.0, complete=True, spec=spec)

    monkeypatch.setattr(gnipy.sweep, "run_sweep", run_sweep)
    res = runner.invoke(app, ["sweep", "vertical-disk", "--grid", "m=1:2:8", "--h", "0.1", "--steps", "10",
                              "--out", str(tmp_path / "s.zarr")])
    assert res.exit_code == 0, res.output
    lines = _progress_lines(res.output, "sweep", "chunks")
    assert [line.split(",")[0] for line in lines] == [f"sweep: {k}/4 chunks" for k in range(5)], res.output


# ------------------------------------------------------------------------------------------------
# The bar on a terminal shows names literally (issue 28, D5)
# ------------------------------------------------------------------------------------------------
NASTY_NAMES = ["[/bold]x[red", "[link=http://x]y[/link]", "\x1b]0;pwned\x07title", "a\x1b[2Jb\x9bc"]


@pytest.mark.parametrize("name", NASTY_NAMES)
def test_the_bar_shows_a_name_literally(name, monkeypatch):
    """A problem's name in the description: rich markup crashed the bar (MarkupError), escape
    sequences reached the terminal (window title, clear screen). The bar, rendered to a string,
    holds the name with its control characters as visible escapes and nothing interpreted."""
    import io

    import rich.console

    from gnipy.text import safe

    screen, real = io.StringIO(), rich.console.Console
    monkeypatch.setattr(rich.console, "Console", lambda **kwargs: real(file=screen, force_terminal=True, width=400,
                                                                        color_system=None))
    with Progress("control", 60, "iterations", description=f"{name}: compiling", terminal=True) as progress:
        progress.update(70, description=f"{name}: cost 1.5")
        progress._bar.refresh()
        shown = screen.getvalue()
    assert f"{safe(name)}: cost 1.5" in shown
    assert "\x1b]" not in shown and "\x07" not in shown and "\x9b" not in shown and "\x1b[2J" not in shown
    assert "70/70" in shown  # more iterations than announced: the total follows, never "70/60"


def test_plain_lines_never_count_past_the_total():
    progress, lines, clock = plain(60, "iterations")
    with progress:
        for done in (30, 60, 70):
            clock.now += 11
            progress.update(done)
    assert lines[-1].startswith("study: 70/70 iterations")
    assert all(not re.match(r"study: (\d+)/(\d+)", x) or int(re.match(r"study: (\d+)/(\d+)", x)[1])
               <= int(re.match(r"study: (\d+)/(\d+)", x)[2]) for x in lines)
