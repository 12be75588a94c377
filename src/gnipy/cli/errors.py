"""Errors of the `gni` commands: bad input names its option (exit code 2); a solver failure or a
file that cannot be written gives exit code 1; neither prints a Python traceback.

gnipy's own errors name the *argument* at fault (`h: ...`, `params: ...`, `chunk_steps: ...`,
see :mod:`gnipy.errors`); :data:`ARGUMENT_OPTIONS` maps each argument to the option that sets it,
and :func:`option_message` rewrites a message for the command line.
"""

from __future__ import annotations

import contextlib
import re

from .output import EXIT_FAILURE, EXIT_USAGE, fail

__all__ = ["ARGUMENT_OPTIONS", "UsageError", "WriteFailure", "guarded", "option_message", "relabel", "writing"]

#: The argument names of gnipy's error messages (`name: ...`) and the option each stands for.
ARGUMENT_OPTIONS = {
    "h": "--h",
    "steps": "--steps",
    "t_final": "--t-final",
    "steps/t_final": "--steps/--t-final",
    "save_every": "--save-every",
    "q0": "--q0",
    "v0": "--v0",
    "q0/v0": "--q0/--v0",
    "R0": "--R0",
    "t0": "--t0",
    "params": "--set",
    "model": "MODEL",
    "method": "--method",
    "lagrangian": "--set/--q0",
    "constraints": "--set/--q0",
    "affine": "--set/--q0",
    "chunk_steps": "--checkpoint-every",
    "resume": "--resume",
}

#: Keyword arguments that gnipy's messages suggest (`pass overwrite=True`), as the flags.
_KEYWORD_FLAGS = {"project_v0=True": "--project-v0", "overwrite=True": "--overwrite", "resume=True": "--resume",
                  "rerun with resume=False": "rerun without --resume", "max_bytes=None": "--yes",
                  "a larger save_every": "a larger --save-every"}


class UsageError(Exception):
    """Bad command-line input: `option` is named in the message."""

    def __init__(self, option: str, message: str):
        super().__init__(f"{option}: {message}")
        self.option = option


class WriteFailure(Exception):
    """A file could not be written after the run (the message names the option and the path)."""


def _flags(text: str, keywords: dict[str, str] | None = None) -> str:
    for keyword, flag in (_KEYWORD_FLAGS if keywords is None else keywords).items():
        text = text.replace(f"{keyword} ({flag})", flag).replace(keyword, flag)
    return text


def option_message(message, options: dict[str, str] = ARGUMENT_OPTIONS,
                   keywords: dict[str, str] | None = None) -> str:
    """A gnipy error message (`argument: what was wrong`) as one about the command-line option of
    that argument (:data:`ARGUMENT_OPTIONS`, or the command's own `options`); the keyword arguments
    it suggests written as flags (`keywords`: the command's own, default those of `gni run`)."""
    head, sep, rest = str(message).partition(":")
    if sep and head.strip() in options:
        return f"{options[head.strip()]}:{_flags(rest, keywords)}"
    return str(message) if keywords is None else _flags(str(message), keywords)


def relabel(option: str, message) -> str:
    """An error message of gnipy.files / gnipy.io as one about the CLI `option`: its own argument
    prefix (`path:`, `out:`, ...) replaced by the option, `overwrite=True` written as the flag."""
    text = _flags(str(message))
    head, sep, rest = text.partition(": ")
    if sep and head in ("path", "out", "out_dir", "plot", option):
        text = rest
    elif sep and head in ARGUMENT_OPTIONS:  # about another argument (resume: ...)
        return f"{ARGUMENT_OPTIONS[head]}: {rest}"
    elif sep and re.fullmatch(r"--[\w-]+(/--[\w-]+)*", head):  # already about an option (e.g. --resume)
        return text
    return f"{option}: {text}"


@contextlib.contextmanager
def writing(option: str, path):
    """Turn a failure to write `path` (an `OSError`, the netCDF library's `HDF error`) into a
    one-line error about `option` (exit code 1); other errors pass."""
    from gnipy.files import as_output_error

    try:
        yield
    except (OSError, RuntimeError) as e:
        err = as_output_error(e, path)
        if err is None:
            raise
        raise WriteFailure(relabel(option, err)) from None


def guarded(fn, origins: dict[str, str] | None = None, method_option: str = "--method",
            options: dict[str, str] | None = None, keywords: dict[str, str] | None = None,
            out_of_memory: str | None = None):
    """Run `fn()` turning gnipy's errors into one-line messages and exit codes; the output locks
    it takes (:func:`gnipy.cli.held.hold`) are released when it ends; an output another process
    is writing (:class:`gnipy.OutputBusy`) is refused with exit code 2.

    `origins` maps an option to where its value came from (e.g. `"--h"` → `"key 'h' in run.toml"`):
    a message about that option says so. A command other than `gni run` passes its own vocabulary,
    so that every message names something it has: `options` maps gnipy's argument names to its
    options or to the keys of its input file (instead of :data:`ARGUMENT_OPTIONS`, e.g. `"steps"` →
    `"horizon.steps"`), `keywords` the keyword arguments gnipy's messages suggest to what it takes
    instead (e.g. `"max_bytes=None"` → `"--yes"`), `out_of_memory` the advice when memory runs out."""
    import gnipy
    from gnipy.io import OutputError

    from .held import holding

    def usage(message: str):
        fail(_with_origin(message, origins), EXIT_USAGE)

    vocabulary = ARGUMENT_OPTIONS if options is None else options
    try:
        with holding():  # the outputs the command locks (held.hold), released however it ends
            return fn()
    except UsageError as e:
        usage(str(e))
    except gnipy.MethodError as e:
        message = option_message(e, {**vocabulary, "method": method_option, "methods": method_option}, keywords)
        usage(message if message.startswith(method_option) else f"{method_option}: {message}")
    except gnipy.InputError as e:
        usage(option_message(e, vocabulary, keywords))
    except gnipy.OutputBusy as e:  # another process writes this output (held.hold): refused, as bad input is
        usage(str(e))
    except gnipy.SolverFailure as e:
        fail(f"solver failure: {e}", EXIT_FAILURE)
    except gnipy.MissingExtra as e:  # e.g. gni sweep without dask: the message names the pip line
        fail(str(e), EXIT_FAILURE)
    except WriteFailure as e:
        fail(str(e), EXIT_FAILURE)
    except OutputError as e:
        fail(relabel("--out", e), EXIT_FAILURE)
    except OSError as e:
        where = f": {e.filename}" if getattr(e, "filename", None) else ""
        fail(f"--out: {e.strerror or e}{where}", EXIT_FAILURE)
    except RuntimeError as e:  # the netCDF library's failed write ("NetCDF: HDF error"), else a bug
        from gnipy.files import as_output_error

        err = as_output_error(e, "the output")
        if err is None:
            raise
        fail(relabel("--out", err), EXIT_FAILURE)
    except MemoryError:
        fail(out_of_memory or "out of memory: save fewer nodes (--save-every) or stream the run (--checkpoint-every K)",
             EXIT_FAILURE)


def _with_origin(message: str, origins: dict[str, str] | None) -> str:
    """A message about an option (`--h: ...`) saying where the option's value came from, when
    `origins` (option -> where, e.g. `"key 'h' in run.toml"`) has it: `--h (from key 'h' in
    run.toml): ...`. A message about several options (`--steps/--t-final: ...`) names the first
    one found."""
    head, sep, rest = message.partition(":")
    if sep and origins:
        for option in head.split("/"):
            if option in origins:
                return f"{head} (from {origins[option]}):{rest}"
    return message
