"""The outputs a running `gni` command holds: a lock on each (:class:`gnipy.files.output_lock`),
taken after the output's checks and released when the command ends, so that two commands never
write the same file or folder at once."""

from __future__ import annotations

import contextlib
import contextvars

__all__ = ["hold", "holding"]

# the output locks the running command holds (gnipy.files.output_lock), released when it ends
_HELD: contextvars.ContextVar[contextlib.ExitStack | None] = contextvars.ContextVar("gnipy_cli_held", default=None)


@contextlib.contextmanager
def holding():
    """The scope of one command's output locks: every :func:`hold` inside it is released at its end,
    however the command ends (:func:`gnipy.cli.errors.guarded` opens one around each command)."""
    with contextlib.ExitStack() as stack:
        token = _HELD.set(stack)
        try:
            yield stack
        finally:
            _HELD.reset(token)


def hold(option: str, path) -> None:
    """Lock the output `path` of `option` until the command ends (:func:`gnipy.files.output_lock`):
    a second `gni` process writing the same file or directory is refused at once
    (:class:`gnipy.OutputBusy`, naming `option`; exit code 2 through
    :func:`gnipy.cli.errors.guarded`) instead of racing this one. Call it after the path's own
    checks."""
    from gnipy.files import output_lock

    if path is None:
        return
    stack = _HELD.get()
    if stack is None:
        raise RuntimeError("gnipy.cli.held.hold: called outside holding() (a command not run by guarded)")
    stack.enter_context(output_lock(path, argument=option))
