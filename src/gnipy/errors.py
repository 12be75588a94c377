"""The exceptions gnipy raises, in one place.

- :class:`InputError` (a `ValueError`): an argument is not acceptable; the message starts with
  the argument's name (`h: ...`, `q0: ...`, `params: ...`) and says what was wrong. Every error
  about bad input derives from it, so `except gnipy.InputError` catches them all.
- :class:`MethodError` (an :class:`InputError`): a method cannot integrate a system.
- :class:`SolverFailure` (a `RuntimeError`): a step did not converge or gave a non-finite value;
  it carries the step, time, residual and the solution up to the failure.
- :class:`OutputError` (an `OSError`): a file could not be written or read (the path and why).
- :class:`OutputBusy` (an :class:`OutputError`): another process is writing the same output
  (:class:`gnipy.files.output_lock`).
"""

from __future__ import annotations

__all__ = ["InputError", "MethodError", "SolverFailure", "OutputError", "OutputBusy"]


class InputError(ValueError):
    """An argument is not acceptable (the message names the argument and says why)."""


class MethodError(InputError):
    """A method cannot be applied to a system (the message says why)."""


class SolverFailure(RuntimeError):
    """An implicit step did not converge or produced a non-finite value.

    Attributes: `step` (index of the failed step), `time`, `residual`, and `solution` (the
    solution up to the last good saved node).
    """

    def __init__(self, message: str, *, step: int, time: float, residual: float, solution=None):
        super().__init__(message)
        self.step = step
        self.time = time
        self.residual = residual
        self.solution = solution


class OutputError(OSError):
    """A file could not be written or read (the message names the path and why)."""


class OutputBusy(OutputError):
    """Another process is writing the same output (the message names it, with its process id)."""
