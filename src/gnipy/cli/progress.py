"""Progress of the long `gni` commands, on a terminal and in logs.

On a terminal (stderr is a tty) a rich bar shows the progress and disappears when done. Elsewhere
(a batch job, a pipe, a CI log) the same progress is written as plain lines on stderr,

    convergence: 3/8 runs, 12 s: gni-trapezoid, h = 0.025

(after the colon: what runs now, where the work names it), one each time another tenth of the
work is done or 10 s have passed since the last line with something new to say, and one at the
end. Work that reports seldom or not at all (a sweep's
chunks, the stages of the reproduction) gets a line every 10 s all the same
(`reproduce: 3/9 stages, 40 s: Figure 4`). `gni run` (long runs), `gni convergence`, `gni sweep`,
`gni atlas` and `gni reproduce` report through :class:`Progress`.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

__all__ = ["LINE_EVERY_FRACTION", "LINE_EVERY_SECONDS", "Progress", "busy", "on_terminal"]

#: A plain progress line each time this fraction of the work more is done ...
LINE_EVERY_FRACTION = 0.1
#: ... or this many seconds have passed since the last line (and something was done since).
LINE_EVERY_SECONDS = 10.0


def on_terminal() -> bool:
    """Whether stderr is a terminal (then progress is a rich bar, else plain lines)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced or closed
        return False


class Progress:
    """`with Progress("convergence", total=8, unit="runs") as p: ... p.update(3)`.

    Arguments:
        command: the name the plain lines start with (e.g. `"convergence"`).
        total: the amount of work (runs, steps, chunks); it may be given later, in :meth:`update`.
        unit: what is counted, in the plain lines (`"runs"`, `"steps"`).
        description: the text beside the bar on a terminal (default: `command`).
        terminal: a rich bar (True) or plain lines (False); default :func:`on_terminal`.
        write: where the plain lines go (default: a line on stderr).
        clock: the time in seconds (default `time.monotonic`).
        heartbeat: with plain lines, also write one when :data:`LINE_EVERY_SECONDS` pass without
            one (from a thread), for work that reports seldom or not at all
            (`reproduce: 3/9 stages, 40 s: Figure 4`).
    """

    def __init__(self, command: str, total: int | None = None, unit: str = "", *, description: str | None = None,
                 terminal: bool | None = None, write: Callable[[str], None] | None = None,
                 clock: Callable[[], float] = time.monotonic, heartbeat: bool = False):
        self.command, self.total, self.unit = command, total, unit
        self.description = _shown(description or command)
        self.terminal = on_terminal() if terminal is None else terminal
        self.write = write or _echo_stderr
        self.clock = clock
        self.done = 0
        self.stage = ""  # what runs now (the last description given), named in the plain lines
        self._bar = self._task = None
        self._start = self._last_time = 0.0
        self._last_done = -1
        self._next_mark = 0.0
        self._lock = threading.Lock()
        self._heartbeat = heartbeat and not self.terminal
        self._stop = threading.Event()
        self._thread = None

    def __enter__(self) -> Progress:
        self._start = self._last_time = self.clock()
        if self.terminal:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress as Bar, SpinnerColumn, TextColumn
            from rich.progress import TimeElapsedColumn, TimeRemainingColumn

            # markup=False: a description holds names from files and the command line (a problem's
            # name "[/bold]x[red" would otherwise be rich markup, and crash the bar)
            self._bar = Bar(SpinnerColumn(), TextColumn("{task.description}", markup=False), BarColumn(),
                            MofNCompleteColumn(),
                            TimeElapsedColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                            transient=True)
            self._bar.__enter__()
            self._task = self._bar.add_task(self.description, total=self.total)
        elif self.total is not None:  # the work and its size, before the first of it is done
            self._line()
        if self._heartbeat:
            self._thread = threading.Thread(target=self._beat, name=f"gni {self.command} progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> bool:
        if self._thread is not None:
            self._stop.set()
            self._thread.join()
        if self._bar is not None:
            self._bar.__exit__(*exc)
        elif exc[0] is None and self.total is not None and self.done != self._last_done:
            self._line()
        elif exc[0] is None and self.total is None and self._heartbeat:
            self._line(finished=True)
        return False

    def update(self, done: int, total: int | None = None, description: str | None = None) -> None:
        """`done` of `total` (units) are done; `description` says what runs now (on the bar)."""
        if total is not None:
            self.total = total
        if self.total is not None and done > self.total:  # more work than announced: never "70/60"
            self.total = done
        self.done = done
        if description is not None:
            self.stage = _shown(description)
        if self._bar is not None:
            self._bar.update(self._task, completed=done, total=self.total,
                             **({} if description is None else {"description": _shown(description)}))
            return
        if self.total is None or done == self._last_done:
            return
        with self._lock:
            now = self.clock()
            if done >= self.total or done >= self._next_mark or now - self._last_time >= LINE_EVERY_SECONDS:
                self._line(now)

    def advance(self, amount: int = 1, description: str | None = None) -> None:
        """`amount` more units are done."""
        self.update(self.done + amount, description=description)

    def __call__(self, done: int, total: int, *rest) -> None:
        """The callback form, `progress(done, total[, description])` (what `gnipy.simulate`,
        :func:`gnipy.analysis.convergence_study` and the sweeps call; an empty description clears
        the stage the plain lines name)."""
        self.update(done, total, str(rest[0]) if rest and rest[0] is not None else None)

    def _beat(self) -> None:
        while not self._stop.wait(min(1.0, LINE_EVERY_SECONDS)):
            with self._lock:
                if self.clock() - self._last_time >= LINE_EVERY_SECONDS:
                    self._line()

    def _line(self, now: float | None = None, finished: bool = False) -> None:
        now = self.clock() if now is None else now
        unit = f" {self.unit}" if self.unit else ""
        done = f"{_count(self.done)}/{_count(self.total)}{unit}, " if self.total is not None else ""
        done = "finished, " if finished else done
        stage = f": {self.stage}" if self.stage and not finished else ""
        self.write(f"{self.command}: {done}{now - self._start:.0f} s{stage}")
        self._last_done, self._last_time = self.done, now
        if self.total:
            step = max(LINE_EVERY_FRACTION * self.total, 1.0)
            self._next_mark = (int(self.done / step) + 1) * step


def _shown(text) -> str:
    """`text` as the bar shows it: control characters as visible escapes (no escape sequence from a
    name reaches the terminal); the bar's column prints it without markup."""
    from gnipy.text import safe

    return safe(text)


def _count(x) -> str:
    return f"{int(x):,}" if float(x).is_integer() else f"{x:,.1f}"


def _echo_stderr(line: str) -> None:
    import typer

    typer.echo(line, err=True)


class busy:
    """`with busy("what"):` a spinner with the elapsed time on a terminal while a long call runs
    (nothing elsewhere: the command's report follows)."""

    def __init__(self, text: str):
        self.text = text
        self.bar = None

    def __enter__(self):
        if on_terminal():
            from rich.console import Console
            from rich.progress import Progress as Bar, SpinnerColumn, TextColumn, TimeElapsedColumn

            self.bar = Bar(SpinnerColumn(), TextColumn("{task.description}", markup=False), TimeElapsedColumn(),
                           console=Console(stderr=True), transient=True)
            self.bar.__enter__()
            self.bar.add_task(_shown(self.text), total=None)
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            return self.bar.__exit__(*exc)
        return False
