"""The exceptions and warnings of sweeps, and the wording of a damaged store."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError

__all__ = ["SweepError", "SweepFailure", "SweepWarning"]


class SweepError(InputError):
    """Bad sweep input, or a store that does not hold the requested sweep.

    The message starts with the argument it is about (`grid: ...`, `out: ...`,
    `chunk_size: ...`). A subclass of :class:`gnipy.InputError`.
    """


class SweepFailure(RuntimeError):
    """A chunk of a sweep failed on the cluster for a reason other than bad input (a
    worker died, a store write failed, ...). The chunks already done stay done: run the
    sweep again to resume."""


class SweepWarning(UserWarning):
    """A chunk of a store that was flagged done is damaged (unreadable, or its data differ from
    their checksum) and is computed again; the message names the chunk and its members."""


#: What to do with a damaged store gnipy created.
START_AFRESH = "start afresh with overwrite=True (its data cannot be trusted)"
#: ... and with one whose metadata no longer show that gnipy created it.
REMOVE_IT = ("gnipy cannot tell that it created this directory, so it will not replace it: remove it "
             "yourself and run the sweep again (its data cannot be trusted)")


def why(e: BaseException) -> str:
    """`TypeName: message` of an exception, on one line and at most 160 characters."""
    text = " ".join(str(e).split())
    if len(text) > 160:
        text = text[:157] + "..."
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def damaged(argument: str, path: Path, what: str, hint: str = START_AFRESH) -> SweepError:
    """The SweepError for the store at `path` whose `what` is damaged, saying what to do."""
    return SweepError(f"{argument}: the sweep store {str(path)!r} is damaged: {what}; {hint}")
