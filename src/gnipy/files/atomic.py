"""Temporaries and atomic writes: a file is written whole or not at all (:mod:`gnipy.files`)."""

from __future__ import annotations

import errno
import os
import re
import shutil
import uuid
from collections.abc import Callable
from pathlib import Path

from ..errors import OutputError
from .destinations import check_destination
from .locks import output_lock, pid_alive


__all__ = ["temporary_name", "clean_stale_temporaries", "as_output_error", "atomic_write", "atomic_write_text",
           "atomic_savefig"]


_TEMP = re.compile(r"^\.(?P<name>.+)\.(?:gnipy-(?P<pid>\d+)-)?[0-9a-f]{8,32}\.(?:tmp|partial|old)$")


def temporary_name(path: Path, suffix: str = "tmp") -> Path:
    """A fresh temporary path beside `path`: `.NAME.gnipy-PID-HEX.SUFFIX`."""
    return path.with_name(f".{path.name}.gnipy-{os.getpid()}-{uuid.uuid4().hex[:12]}.{suffix}")



def clean_stale_temporaries(path) -> list[Path]:
    """Remove the temporaries gnipy left beside `path` when a process writing it died.

    Only names of gnipy's own pattern for this destination are touched
    (`.NAME.gnipy-PID-HEX.tmp|partial|old`, and the older `.NAME.HEX.tmp|partial|old`), and of
    those only the ones whose process is no longer running. Returns what was removed."""
    path = Path(os.fspath(path))
    directory = path.parent if str(path.parent) else Path(".")
    removed = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return removed
    for entry in entries:
        m = _TEMP.match(entry.name)
        if m is None or m.group("name") != path.name:
            continue
        pid = m.group("pid")
        if pid is not None and pid_alive(int(pid)):
            continue
        target = Path(entry.path)
        try:
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(target)
            else:
                target.unlink()
            removed.append(target)
        except OSError:
            pass
    return removed



def as_output_error(e: BaseException, path, action: str = "write") -> OutputError | None:
    """The :class:`OutputError` for a failure to `action` `path`, or None if `e` is not a failure
    of the file system or the netCDF/HDF5 library (a bug, an interrupt)."""
    if isinstance(e, OutputError):
        return e
    if isinstance(e, OSError):
        why = e.strerror or str(e)
        if e.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
            why += " (the disk or your quota is full, or the file is over a size limit)"
        return OutputError(e.errno, f"cannot {action} {path}: {why}") if e.errno else \
            OutputError(f"cannot {action} {path}: {why}")
    text = str(e)
    if isinstance(e, RuntimeError) and ("NetCDF" in text or "HDF" in text):
        # the netCDF library reports a failed write (e.g. a full disk) as "NetCDF: HDF error"
        return OutputError(f"cannot {action} {path}: {text} (the disk may be full)")
    return None


def atomic_write(path, write: Callable[[Path], object], *, overwrite: bool = False,
                 argument: str = "out", checked: bool = False) -> Path:
    """Write a file atomically: `write(tmp)` creates the file `tmp` beside `path`; it is flushed
    to disk and renamed to `path`.

    Arguments:
        path: the destination (checked with :func:`check_destination` unless `checked`).
        write: called with the temporary path; writes the whole file there.
        overwrite: replace an existing regular file at `path`.
        argument: the name of the argument in messages.
        checked: the caller has already checked the destination (e.g. a file gnipy owns).

    Unless `checked`, the write holds the destination's :class:`output_lock` and first removes the
    temporaries of earlier writers of `path` that died before their rename
    (:func:`clean_stale_temporaries`).

    Raises:
        OutputError: the destination is refused, or writing failed (the temporary is removed and
            an old file at `path` is untouched).
        OutputBusy: another process is writing `path`.
    """
    if checked:  # a file inside an output gnipy owns, whose run holds the output's lock
        return _atomic_write(Path(os.fspath(path)), write, overwrite, argument, checked)
    path = check_destination(path, overwrite=overwrite, argument=argument)
    with output_lock(path, argument=argument):
        clean_stale_temporaries(path)  # of an earlier writer of `path` that was killed before its rename
        return _atomic_write(path, write, overwrite, argument, checked)


def _atomic_write(path: Path, write, overwrite: bool, argument: str, checked: bool) -> Path:
    tmp = temporary_name(path)
    try:
        write(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)  # on disk before it counts as done
        finally:
            os.close(fd)
        if not checked:  # refuse a link or special file put there while we wrote
            check_destination(path, overwrite=overwrite, argument=argument)
        os.replace(tmp, path)
    except BaseException as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        err = as_output_error(e, path)
        if err is not None and err is not e:
            raise err from e
        raise
    return path


def atomic_write_text(path, text: str, **kwargs) -> Path:
    """:func:`atomic_write` of a UTF-8 text file."""
    def write(tmp: Path) -> None:
        with open(tmp, "x", encoding="utf-8") as fh:
            fh.write(text)
    return atomic_write(path, write, **kwargs)


def atomic_savefig(fig, path, **kwargs) -> Path:
    """:func:`atomic_write` of a matplotlib figure (the format from `path`'s suffix);
    `kwargs` other than those of :func:`atomic_write` go to `fig.savefig`."""
    own = {k: kwargs.pop(k) for k in ("overwrite", "argument", "checked") if k in kwargs}
    fmt = Path(os.fspath(path)).suffix.lstrip(".").lower() or None
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, **kwargs), **own)
