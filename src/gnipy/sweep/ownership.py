"""Which directories are gnipy's sweep stores, and where a sweep may write one.

A store gnipy creates records it in its own metadata: the root attribute `gnipy_owned` (its
purpose, `"gnipy sweep store"`, :data:`OWNER_ATTR`), beside the sweep's specification
`sweep_spec`. Stores of earlier versions are recognised too: format `gnipy-sweep/2` by gnipy's
marker file (:data:`gnipy.files.MARKER`), format `gnipy-sweep/1` by a readable `sweep_spec`.
gnipy writes a store only where nothing is, into an empty directory, or over such a store; it
replaces one (`overwrite=True`) only when everything at its top level is gnipy's, and never
touches a directory it cannot tell it created.
"""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path
from typing import Any

from ..extras import require
from .. import files
from .errors import REMOVE_IT, START_AFRESH, SweepError, damaged, why
from .plan import FORMAT, MEMBER_VARS, OLD_FORMATS

__all__ = ["PURPOSE", "OWNER_ATTR", "check_out", "is_store", "open_group"]

#: The purpose gnipy records in a sweep store (in its attribute :data:`OWNER_ATTR`).
PURPOSE = "gnipy sweep store"
#: The root attribute of a store that records that gnipy created it.
OWNER_ATTR = "gnipy_owned"

# the store's other arrays (coordinates and per-chunk flags), and its metadata files (v3 and v2)
COORDS = ("time", "node", "step", "coordinate", "velocity", "constraint", "chunk")
CHUNK_VARS = ("chunk_done", "chunk_checksum")
META_FILES = ("zarr.json", ".zgroup", ".zattrs", ".zmetadata")


def read_attrs(path: Path) -> dict[str, Any] | None:
    """The attributes of the zarr group at `path`, or None if it is not a readable zarr group."""
    zarr = require("zarr", extra="sweeps")

    if not (path / "zarr.json").is_file() and not (path / ".zgroup").is_file():
        return None
    try:
        return dict(zarr.open_group(str(path), mode="r", use_consolidated=False).attrs)
    except Exception:  # noqa: BLE001 - unreadable: not a store we know
        return None


def parse_spec(text) -> dict[str, Any] | None:
    """A sweep specification (JSON) of this or an earlier format, or None."""
    try:
        spec = json.loads(text)
    except (TypeError, ValueError):
        return None
    ok = isinstance(spec, dict) and spec.get("format") in (FORMAT, *OLD_FORMATS)
    return spec if ok else None


def marker_purpose(path: Path) -> str | None:
    """The purpose recorded in gnipy's marker file in `path` (None if unreadable)."""
    try:
        purpose = json.loads((path / files.MARKER).read_text()).get("purpose")
    except (OSError, ValueError, AttributeError):
        return None
    return purpose if isinstance(purpose, str) else None


def _is_dir(path: Path) -> bool:
    try:
        return stat.S_ISDIR(os.lstat(path).st_mode)
    except OSError:
        return False


def is_ours(path: Path) -> bool:
    """Whether `path` is a sweep store gnipy created (this version's, by its attribute
    :data:`OWNER_ATTR`; an earlier one's, by its marker file or its `sweep_spec`)."""
    if not _is_dir(path):
        return False
    if files.is_owned_dir(path):  # format gnipy-sweep/2
        return marker_purpose(path) in (None, PURPOSE)
    attrs = read_attrs(path)
    if attrs is None:
        return False
    if attrs.get(OWNER_ATTR) == PURPOSE:
        return True
    spec = parse_spec(attrs.get("sweep_spec"))  # format gnipy-sweep/1: no marker
    return spec is not None and spec["format"] in OLD_FORMATS


def looks_like_store(path: Path) -> bool:
    """Whether the directory `path` looks like a sweep store whose metadata are damaged (a root
    `zarr.json`, or the array `chunk_done`)."""
    return _is_dir(path) and ((path / "zarr.json").is_file() or (path / "chunk_done").is_dir())


def is_store(path: Path) -> bool:
    """Whether `path` is a sweep store (gnipy's, or one that looks like one with damaged
    metadata): the readers say what is damaged rather than "not a store"."""
    if files.is_owned_dir(path) and marker_purpose(path) not in (None, PURPOSE):
        return False
    return is_ours(path) or looks_like_store(path)


def foreign_entries(path: Path) -> list[str]:
    """The entries at the top of the store `path` that gnipy does not write there."""
    foreign = []
    try:
        entries = sorted(os.scandir(path), key=lambda e: e.name)
    except OSError:
        return foreign
    for e in entries:
        if e.is_symlink():
            foreign.append(e.name)
        elif e.is_dir():
            ours = (e.name in MEMBER_VARS or e.name in COORDS or e.name in CHUNK_VARS
                    or e.name.startswith("grid_") or e.name == "member"
                    or any(os.path.isfile(os.path.join(e.path, m)) for m in ("zarr.json", ".zarray")))
            if not ours:
                foreign.append(e.name + "/")
        elif e.name not in (*META_FILES, files.MARKER):
            foreign.append(e.name)
    return foreign


def remove_store(path: Path) -> None:
    """Delete a store gnipy wrote (what :func:`foreign_entries` does not list)."""
    foreign = set(foreign_entries(path))
    try:
        entries = list(os.scandir(path))
    except OSError:
        return
    for e in entries:
        if e.name in foreign or e.name + "/" in foreign:
            continue
        try:
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path)
            else:
                os.unlink(e.path)
        except OSError:
            pass
    try:
        os.rmdir(path)
    except OSError:
        pass


def open_group(path: Path, argument: str, mode: str = "r"):
    """`(group, spec)` of the store at `path` (its own metadata, not the consolidated copy), or
    a SweepError saying what is damaged."""
    zarr = require("zarr", extra="sweeps")

    hint = START_AFRESH if is_ours(path) else REMOVE_IT
    if not (path / "zarr.json").is_file() and not (path / ".zgroup").is_file():
        raise damaged(argument, path, "its metadata file zarr.json is missing", hint)
    try:
        group = zarr.open_group(str(path), mode=mode, use_consolidated=False)
        attrs = dict(group.attrs)
    except Exception as e:  # noqa: BLE001 - any failure to parse the metadata
        raise damaged(argument, path, f"its metadata (zarr.json) cannot be read ({why(e)})", hint) from None
    spec = parse_spec(attrs.get("sweep_spec"))
    if spec is None:
        raise damaged(argument, path, "its attribute sweep_spec (the sweep's specification) is missing or "
                      "unreadable", hint)
    return group, spec


def check_out(out, overwrite: bool) -> tuple[Path, str]:
    """The store's path and what to do there: `"create"` (nothing there, or an empty
    directory), `"replace"` (a store gnipy wrote, with overwrite) or `"resume"`. Changes
    nothing; SweepError (`out: ...`) for a destination gnipy must not write."""
    if not isinstance(out, (str, os.PathLike)) or not os.fspath(out):
        raise SweepError(f"out: expected a path to a directory DIR.zarr, got {out!r}")
    path = Path(os.fspath(out)).expanduser()
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise SweepError(f"out: cannot use {str(path)!r}: {e.strerror or e}") from None
    is_dir = st is not None and stat.S_ISDIR(st.st_mode)
    purpose = marker_purpose(path) if is_dir and files.is_owned_dir(path) else None
    if purpose not in (None, PURPOSE):
        raise SweepError(f"out: {str(path)!r} is a directory gnipy created for something else "
                         f"({purpose}), not a sweep store; choose another path")
    ours = is_dir and is_ours(path)
    try:
        _check_destination(path, is_dir, ours, overwrite)
    except (files.OutputError, OSError) as e:
        raise SweepError(str(e) if isinstance(e, files.OutputError) else
                         f"out: cannot use {str(path)!r}: {e.strerror or e}") from None
    if not ours:
        return path, "create"
    if not overwrite:
        return path, "resume"
    _check_all_ours(path)
    return path, "replace"


def _check_destination(path: Path, is_dir: bool, ours: bool, overwrite: bool) -> None:
    """Refuse (OutputError, OSError or SweepError) a destination gnipy must not write: a store of
    its own (`ours`) it cannot write, a directory it did not create that is not empty, or
    what :func:`gnipy.files.check_directory_destination` refuses."""
    if ours:
        parent = path.parent if str(path.parent) else Path(".")
        for where in (path, parent):
            if not os.access(where, os.W_OK | os.X_OK):
                raise files.OutputError(f"out: {where} is not writable")
    elif is_dir and any(path.iterdir()):
        if looks_like_store(path):
            open_group(path, "out")  # says what is damaged
            raise damaged("out", path, f"it has no attribute {OWNER_ATTR}", REMOVE_IT)
        raise SweepError(f"out: {str(path)!r} is a directory gnipy did not create and is not "
                         "empty; gnipy will not write into or delete it (choose another path)")
    else:  # nothing there, an empty directory, or what gnipy never writes into
        files.check_directory_destination(path, overwrite=overwrite, reuse=True, argument="out")


def _check_all_ours(path: Path) -> None:
    """Refuse to replace the store at `path` when it holds what gnipy did not write."""
    foreign = foreign_entries(path)
    if foreign:
        listed = ", ".join(repr(f) for f in foreign[:5]) + (", ..." if len(foreign) > 5 else "")
        raise SweepError(
            f"out: {str(path)!r} holds {listed}, which gnipy did not write; gnipy replaces "
            "a sweep store only when everything in it is its own: move them away, or choose another path"
        )
