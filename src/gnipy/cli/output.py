"""Printing for the `gni` commands: text shown literally, tables, consoles, one-line errors.

Text from files and from the command line (paths, attributes, names) is printed literally (no
rich markup), with control characters shown as escapes (`\\x1b`).
"""

from __future__ import annotations

import typer

from ..text import safe

__all__ = ["EXIT_FAILURE", "EXIT_QUALITATIVE", "EXIT_USAGE", "exit_for_health", "cell", "console", "fail", "report_result", "safe", "table", "warn"]

#: Exit code of bad input (the message names the option).
EXIT_USAGE = 2
#: Exit code of a solver failure or a file that cannot be written.
EXIT_FAILURE = 1
#: Exit code of a run whose steps converged but whose motion went qualitatively wrong (a verdict
#: out of band at some node, :attr:`gnipy.Solution.healthy`); the files are written all the same.
#: `--accept-out-of-band` makes it 0.
EXIT_QUALITATIVE = 3

def cell(text):
    """A table cell that shows `text` literally (no rich markup, control characters escaped)."""
    from rich.text import Text

    return Text(safe(text))


def table(title=None, **kwargs):
    """A rich `Table` whose title, headers and text cells are shown literally (:func:`cell`)."""
    from rich.table import Table

    class SafeTable(Table):
        def add_row(self, *cells, **kw):
            return super().add_row(*(cell(c) if isinstance(c, str) else c for c in cells), **kw)

        def add_column(self, header="", *args, **kw):
            return super().add_column(cell(header) if isinstance(header, str) else header, *args, **kw)

    return SafeTable(title=None if title is None else cell(title), **kwargs)


def console(stderr: bool = False):
    """A rich console that interprets no markup or emoji codes in what it prints (text from files
    and from the command line is shown as it is; pass it through :func:`safe`)."""
    from rich.console import Console

    return Console(highlight=False, soft_wrap=True, stderr=stderr, markup=False, emoji=False)


def report_result(command: str, name: str, result, written: str, seconds: float) -> None:
    """Print the report of `gni control` / `gni fit`: the problem, the result's `summary()` and
    the files written; exit with :data:`EXIT_FAILURE` when the result did not succeed (the files
    are written all the same)."""
    con = console()
    con.print(safe(f"{command}: {name}"))
    for line in result.summary().splitlines():
        con.print(safe(line))
    con.print(safe(f"wrote {written} in {seconds:.1f} s"))
    if not result.success:
        raise typer.Exit(EXIT_FAILURE)


def exit_for_health(healthy: bool, accept: bool) -> None:
    """Exit with :data:`EXIT_QUALITATIVE` when a run converged but is not healthy, unless the
    user accepted it (`--accept-out-of-band`)."""
    if not healthy and not accept:
        console(stderr=True).print("exit code 3: the run is qualitatively wrong (see the warnings above; "
                                   "--accept-out-of-band exits 0)", markup=False)
        raise typer.Exit(EXIT_QUALITATIVE)


def warn(text: str) -> None:
    """Print a warning (a run-time diagnostic, a damaged chunk) on stderr, literally."""
    console(stderr=True).print(safe(text), style="bold yellow", markup=False)


def fail(message: str, code: int) -> None:
    """Print a one-line error on stderr and exit with `code` (no traceback). Runs of whitespace
    become one space; other control characters are shown as escapes."""
    typer.echo("Error: " + safe(" ".join(str(message).split())), err=True)
    raise typer.Exit(code)
