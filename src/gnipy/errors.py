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
- :class:`QualitativeFailureWarning` (a `UserWarning`): a run converged but its motion went
  qualitatively wrong (a verdict of :mod:`gnipy.diagnostics` out of band, checked at every node);
  :class:`QualitativeFailure` (a `RuntimeError`) is the same raised, with `simulate(...,
  throw="strict")` or `warnings.simplefilter("error", gnipy.QualitativeFailureWarning)`.
"""

from __future__ import annotations

import contextlib
import warnings

__all__ = ["InputError", "MethodError", "SolverFailure", "OutputError", "OutputBusy", "QualitativeFailureWarning",
           "QualitativeFailure", "verdicts_reported_by_caller"]


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


class QualitativeFailureWarning(UserWarning):
    """A run whose steps converged but whose motion went qualitatively wrong: a verdict (the GNI's
    hidden momentum, a conserved energy) left its band at some node (:attr:`gnipy.Solution.health`).
    The message names the time, the quantity and what to use instead. Filter it like any warning
    (`warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)`), or make it an error."""


class QualitativeFailure(RuntimeError):
    """A run went qualitatively wrong, raised (`simulate(..., throw="strict")`).

    Attributes: `time` (when the first verdict left its band) and `solution` (the whole run).
    """

    def __init__(self, message: str, *, time: float | None, solution=None):
        super().__init__(message)
        self.time = time
        self.solution = solution


@contextlib.contextmanager
def verdicts_reported_by_caller():
    """Within this block :class:`QualitativeFailureWarning` is not shown: for code that runs
    failing cases on purpose and reports their verdicts itself (the atlas, the figures of the
    paper's failures, convergence studies, the `gni` commands)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QualitativeFailureWarning)
        yield
