"""Owned directories: the working directories gnipy creates, marked so that it never deletes
anything else (:mod:`gnipy.files`)."""

from __future__ import annotations

import json
import os
import shutil
import stat
from collections.abc import Iterable
from pathlib import Path

from ..errors import OutputError


__all__ = ["MARKER", "make_owned_dir", "is_owned_dir", "remove_owned_dir"]


#: The marker file of a directory gnipy created (holds JSON: what the directory is for).
MARKER = ".gnipy-owned"


def make_owned_dir(path, purpose: str) -> Path:
    """Create the directory `path` (its parent must exist) with gnipy's marker file, which
    records `purpose`. Raises :class:`OutputError` if it cannot."""
    path = Path(os.fspath(path))
    try:
        path.mkdir()
    except OSError as e:
        raise OutputError(f"cannot create {path}: {e.strerror or e}") from None
    try:
        (path / MARKER).write_text(json.dumps({"created_by": "gnipy", "purpose": purpose}) + "\n")
    except OSError as e:
        try:  # the directory is ours and empty but for a partial marker: leave nothing behind
            (path / MARKER).unlink(missing_ok=True)
            path.rmdir()
        except OSError:
            pass
        raise OutputError(f"cannot create {path}: {e.strerror or e}") from None
    return path


def is_owned_dir(path) -> bool:
    """Whether `path` is a real directory (not a link) holding gnipy's marker file."""
    path = Path(os.fspath(path))
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode) and os.path.isfile(path / MARKER) \
            and not os.path.islink(path / MARKER)
    except OSError:
        return False


def remove_owned_dir(path, patterns: Iterable[str] = ("*",)) -> bool:
    """Remove what gnipy wrote in the owned directory `path`: the entries matching the glob
    `patterns` (recursively for subdirectories), then the marker and the directory if nothing else
    is left. A directory without the marker is not touched. Returns whether `path` is gone."""
    path = Path(os.fspath(path))
    if not is_owned_dir(path):
        return not os.path.lexists(path)
    for pattern in patterns:
        for entry in path.glob(pattern):
            if entry.name == MARKER:
                continue
            try:
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry)
                else:
                    entry.unlink()
            except OSError:
                pass
    try:
        left = [e for e in path.iterdir() if e.name != MARKER]
    except OSError:
        return False
    if left:
        return False
    try:
        (path / MARKER).unlink()
        path.rmdir()
    except OSError:
        return False
    return True
