"""The files and directories the `gni` commands read and write (:mod:`gnipy.files`).

An existing output file is replaced only with `--overwrite`; a symbolic link, a directory, a FIFO
or a device is never written to. An output directory that gnipy creates gets the marker
`.gnipy-owned`; in such a directory gnipy replaces its own files on a rerun, in any other only
with `--overwrite`.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from .errors import UsageError, WriteFailure, relabel

__all__ = ["check_output", "check_output_dir", "check_plot", "check_readable", "create_output_dir", "same_file"]

def check_output(path: Path, option: str = "--out", overwrite: bool = False) -> Path:
    """`path` may be written as a regular file (:func:`gnipy.files.check_destination`): its directory
    exists and is writable, and nothing is there, or a regular file and `overwrite`; a symbolic
    link, directory, FIFO or device never. Else `UsageError` naming `option` and the path."""
    from gnipy.files import OutputError, check_destination

    try:
        return check_destination(path, overwrite=overwrite, argument=option)
    except OutputError as e:
        raise UsageError(option, relabel(option, e).partition(": ")[2]) from None
    except RuntimeError as e:  # Path.expanduser: "~user" of no such user
        raise UsageError(option, f"cannot use {str(path)!r}: {e}") from None


def check_plot(path: Path, overwrite: bool = False) -> None:
    """`--plot`: a writable path whose suffix is an image format matplotlib writes."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in formats:
        raise UsageError(
            "--plot", f"cannot tell the image format of {str(path)!r}: use one of the suffixes "
            + ", ".join(f".{k}" for k in sorted(formats))
        )
    check_output(path, "--plot", overwrite)


def same_file(a: Path, b: Path) -> bool:
    """Whether `a` and `b` name the same file (or the same path)."""
    try:
        return os.path.abspath(a) == os.path.abspath(b) or (a.exists() and b.exists() and os.path.samefile(a, b))
    except (OSError, ValueError):
        return False


def check_out_and_plot(out: Path | None, plot: Path | None, overwrite: bool = False) -> None:
    """The checks of a command's `--out` file (required) and optional `--plot` figure: both
    writable (:func:`check_output`, :func:`check_plot`) and not the same file."""
    if out is None:
        raise UsageError("--out", "missing: give --out FILE.nc")
    check_output(out, "--out", overwrite)
    if plot is not None:
        check_plot(plot, overwrite)
        if same_file(out, plot):
            raise UsageError("--plot", f"{str(plot)!r} is also --out: choose another path for the figure")


def check_output_dir(path: Path, names=(), overwrite: bool = False) -> bool:
    """`--out DIR` (`gni convergence`): an existing directory, or one that can be created, in which
    the files `names` may be written. Returns whether gnipy may replace existing files of those names:
    in a directory gnipy created (it holds the marker :data:`gnipy.files.MARKER`), or with
    `--overwrite`; a symbolic link, directory or special file at one of the names is always refused."""
    from gnipy.files import MARKER, OutputError, check_destination, is_owned_dir

    text = str(path)
    if "\x00" in text:
        raise UsageError("--out", f"{text!r}: a path cannot contain a NUL character")
    try:
        st = os.stat(path)  # a link to a directory is that directory (not one gnipy owns)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise UsageError("--out", f"cannot use {text!r}: {e.strerror or e}") from None
    if st is None:
        if os.path.islink(path):
            raise UsageError("--out", f"{text!r} is a dangling symbolic link")
        parent = path.parent if str(path.parent) else Path(".")
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise UsageError("--out", f"cannot create directory {text!r}: {str(parent)!r} is not a directory")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise UsageError("--out", f"cannot create directory {text!r}: {str(parent)!r} is not writable")
        return True
    if not stat.S_ISDIR(st.st_mode):
        raise UsageError("--out", f"{text!r} exists and is not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise UsageError("--out", f"directory {text!r} is not writable")
    replace = overwrite or is_owned_dir(path)
    taken = []
    for name in names:
        try:
            check_destination(path / name, overwrite=True, argument="--out")
        except OutputError as e:  # a link, directory or special file: never
            raise UsageError("--out", relabel("--out", e).partition(": ")[2]) from None
        if (path / name).exists():
            taken.append(name)
    if taken and not replace:
        raise UsageError(
            "--out", f"{text!r} is a directory gnipy did not create (no {MARKER} marker) and already holds "
            f"{', '.join(taken)}; pass --overwrite to replace them, or choose another directory"
        )
    return replace


def create_output_dir(path: Path, purpose: str) -> bool:
    """Create the directory `path` (and missing parents) with gnipy's marker, unless it exists;
    returns whether it was created here."""
    from gnipy.files import make_owned_dir

    if os.path.isdir(path):
        return False
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise WriteFailure(f"--out: cannot create {parent}: {e.strerror or e}") from None
    make_owned_dir(path, purpose)
    return True


def check_readable(path: Path, option: str) -> None:
    """`path` is a regular file (or a link to one) to read; else `UsageError` (a FIFO or device
    is never opened: reading one could block)."""
    text = str(path)
    if "\x00" in text:
        raise UsageError(option, f"{text!r}: a path cannot contain a NUL character")
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise UsageError(option, f"cannot read {text!r}: no such file") from None
    except OSError as e:
        raise UsageError(option, f"cannot read {text!r}: {e.strerror or e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise UsageError(option, f"cannot read {text!r}: it is a directory")
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(option, f"cannot read {text!r}: not a regular file (a FIFO, socket or device)")
