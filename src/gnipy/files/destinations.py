"""Destinations: where gnipy may write a file or a working directory (:mod:`gnipy.files`), and
sizes for messages."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import InputError, OutputError
from .owned import MARKER, is_owned_dir


__all__ = ["format_bytes", "free_bytes", "check_destination", "check_directory_destination"]


def format_bytes(n: float) -> str:
    """A size for messages: `512 bytes`, `1.5 GiB`, ... (three significant digits)."""
    n = float(n)
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024:
            return f"{n:.0f} bytes" if unit == "bytes" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"


def free_bytes(directory) -> int | None:
    """The free space of the file system holding `directory` (None when it cannot be asked)."""
    import shutil

    try:
        return shutil.disk_usage(directory).free
    except OSError:
        return None




def file_kind(st: os.stat_result) -> str:
    """What the `lstat` result `st` is, in words for a message (`"a regular file"`, `"a symbolic link"`, ...)."""
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return "a regular file"
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a special file"


def _as_path(path, argument: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise OutputError(f"{argument}: expected a path, got {type(path).__name__}")
    text = os.fspath(path)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    if not text:
        raise OutputError(f"{argument}: the path is empty")
    if "\x00" in text:
        raise OutputError(f"{argument}: {text!r}: a path cannot contain a NUL character")
    try:
        return Path(text).expanduser()
    except RuntimeError as e:  # "~nosuchuser/...": no home directory to expand to
        raise OutputError(f"{argument}: {text!r}: {e}") from None


def _check_parent(path: Path, argument: str) -> Path:
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise OutputError(f"{argument}: cannot write {path}: directory {directory} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise OutputError(f"{argument}: cannot write {path}: directory {directory} is not writable")
    return directory


def _flag(name: str, x) -> bool:
    """`x` if it is a bool (NumPy's too); else `InputError`: `overwrite="no"` must not replace a file."""
    if isinstance(x, bool) or (type(x).__name__ == "bool_" and getattr(x, "shape", None) == ()):
        return bool(x)
    raise InputError(f"{name}: expected True or False, got {x!r}")


def check_destination(path, *, overwrite: bool = False, argument: str = "out") -> Path:
    """`path` as a `Path`, if gnipy may write a regular file there; else :class:`OutputError`.

    Allowed: nothing at `path`, or a regular file when `overwrite` is true, in a writable
    directory. Refused always: a symbolic link (even to a regular file), a directory, a device,
    FIFO or socket. The message names `argument` (e.g. `--out`) and what is there.
    `overwrite` must be a bool (:class:`~gnipy.InputError` otherwise).
    """
    overwrite = _flag("overwrite", overwrite)
    path = _as_path(path, argument)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise OutputError(f"{argument}: cannot write {path}: {e.strerror or e}") from None
    if st is not None:
        kind = file_kind(st)
        if stat.S_ISLNK(st.st_mode) or not stat.S_ISREG(st.st_mode):
            raise OutputError(f"{argument}: {path} is {kind}; gnipy writes only regular files it may replace "
                              "(choose another path)")
        if not overwrite:
            raise OutputError(f"{argument}: {path} exists; pass overwrite=True to replace it, "
                              "or choose another path")
    _check_parent(path, argument)
    return path


def check_directory_destination(path, *, overwrite: bool = False, argument: str = "out",
                                 reuse: bool = False) -> Path:
    """`path` as a `Path`, if gnipy may create (or reuse) a working directory there.

    Allowed: nothing at `path`; a directory gnipy created (:func:`is_owned_dir`) when `reuse`
    (continuing it) or `overwrite` (replacing it); an empty directory. Refused: a symbolic link,
    a regular or special file, a directory gnipy did not create that is not empty.
    """
    overwrite, reuse = _flag("overwrite", overwrite), _flag("reuse", reuse)
    path = _as_path(path, argument)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise OutputError(f"{argument}: cannot use {path}: {e.strerror or e}") from None
    if st is not None:
        if not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{argument}: {path} is {file_kind(st)}, not a directory gnipy created "
                              "(choose another path)")
        if is_owned_dir(path):
            if not (reuse or overwrite):
                raise OutputError(f"{argument}: {path} exists; pass overwrite=True to replace it, "
                                  "or choose another path")
        elif any(path.iterdir()):
            raise OutputError(f"{argument}: {path} is a directory gnipy did not create (it has no {MARKER} "
                              "marker) and is not empty; gnipy will not write into or delete it "
                              "(choose another path)")
        if not os.access(path, os.W_OK | os.X_OK):
            raise OutputError(f"{argument}: {path} is not writable")
    _check_parent(path, argument)
    return path
