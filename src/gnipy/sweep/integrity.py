"""The integrity of a sweep store: each chunk's checksum, the check of every chunk flagged
done, and what a resumed sweep checks before it skips anything.

For each chunk the data are written first, then the SHA-256 digest of its member variables
(`chunk_checksum`, :func:`gnipy.files.array_checksum` of the chunk's members in C order), and
its `chunk_done` flag last: an interrupted sweep leaves at worst one chunk whose data were
written and whose flag was not.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .errors import SweepError, SweepWarning, damaged, why
from .grid import ChunkLayout, GridAxis, describe_members
from .plan import MEMBER_VARS, Plan
from .store import MAX_ZARR_CHUNK_BYTES, array_names, check_arrays, check_coordinates, digest, old_format, \
    open_group, read_done

__all__ = ["digest", "verify_chunks", "resume"]


def verify_chunks(arrays, names, layout: ChunkLayout, done: np.ndarray,
                  block_bytes: int = MAX_ZARR_CHUNK_BYTES) -> dict[int, str]:
    """Read every chunk flagged done back and compare its checksum: `{chunk: what is wrong}`
    for those unreadable or different. Consecutive chunks of a row of the grid are read
    together, up to about `block_bytes` at a time (a block that cannot be read is read again
    chunk by chunk, to find the chunks at fault)."""
    bad = {}
    data_names = sorted(n for n in names if n in MEMBER_VARS)
    g = len(layout.shape)
    try:
        sums = np.asarray(arrays["chunk_checksum"][...], dtype=np.uint8)
    except Exception:  # noqa: BLE001 - read them one by one below
        sums = None
    per_member = sum(math.prod(arrays[n].shape[g:]) * arrays[n].dtype.itemsize for n in data_names)
    per_block = max(1, block_bytes // max(1, layout.size * per_member))
    for block in _blocks([int(i) for i in np.flatnonzero(done)], layout, per_block):
        a0 = layout.member_range(block[0])[0]
        data = _read_chunks(arrays, data_names, layout, block[0], block[-1]) if len(block) > 1 else None
        for i in block:
            a, b = layout.member_range(i)
            if isinstance(data, dict):
                part = {name: x[a - a0: b - a0] for name, x in data.items()}
            else:
                part = _read_chunks(arrays, data_names, layout, i, i)
            reason = _check_chunk(arrays, sums, i, part)
            if reason is not None:
                bad[i] = reason
    return bad


def _blocks(todo: list[int], layout: ChunkLayout, per_block: int) -> list[list[int]]:
    """The chunks `todo` (in order) as runs of consecutive chunks of one row, cut into blocks of
    at most `per_block` chunks."""
    blocks, start = [], 0
    for k in range(1, len(todo) + 1):
        if (k == len(todo) or todo[k] != todo[k - 1] + 1 or layout.row(todo[k]) != layout.row(todo[start])
                or k - start == per_block):
            blocks.append(todo[start:k])
            start = k
    return blocks


def _read_chunks(arrays, data_names, layout: ChunkLayout, first: int, last: int) -> dict[str, np.ndarray] | str:
    """The member variables `data_names` of the chunks `first` to `last` (members along the first
    axis), or what cannot be read."""
    g = len(layout.shape)
    region = layout.region(first, last)
    out = {}
    for name in data_names:
        try:
            a = np.asarray(arrays[name][region])
        except Exception as e:  # noqa: BLE001 - a truncated or corrupted chunk file
            return f"its {name!r} data cannot be read ({why(e)})"
        out[name] = a.reshape(-1, *a.shape[g:])
    return out


def _check_chunk(arrays, sums: np.ndarray | None, i: int, data: dict[str, np.ndarray] | str) -> str | None:
    """What is wrong with chunk `i`, whose data (or what could not be read) are `data`, against
    its checksum (in `sums`, or read alone when they could not be read together); None: nothing."""
    if sums is not None:
        stored = sums[i]
    else:
        try:
            stored = np.asarray(arrays["chunk_checksum"][i], dtype=np.uint8)
        except Exception as e:  # noqa: BLE001
            return f"its checksum cannot be read ({why(e)})"
    if stored.shape != (32,) or not stored.any():
        return "it has no checksum"
    if isinstance(data, str):
        return data
    if digest(data) != stored.tobytes():
        return "its data differ from their checksum"
    return None


def list_bad(axes, layout: ChunkLayout, bad: Mapping[int, str], most: int = 5) -> str:
    """`chunk 3, members 6..7 (...): why; ...` for the first `most` damaged chunks."""
    listed = "; ".join(f"chunk {i}, {describe_members(axes, *layout.member_range(i))}: {reason}"
                       for i, reason in list(bad.items())[:most])
    return listed + (f"; and {len(bad) - most} more" if len(bad) > most else "")


def _fmt_value(key, value) -> str:
    if key == "grid" and isinstance(value, list):
        try:
            return " ".join(str(GridAxis(**g)) for g in value)
        except Exception:  # noqa: BLE001
            pass
    return json.dumps(value, sort_keys=True) if isinstance(value, (dict, list)) else repr(value)


def compare_specs(path: Path, stored: dict[str, Any], requested: dict[str, Any]) -> None:
    """SweepError (`out: ...`) unless the store at `path` holds the requested sweep."""
    if stored.get("format") != requested["format"]:
        raise old_format("out", path, stored, "resumed")
    for key in requested:
        if stored.get(key) != requested[key]:
            raise SweepError(
                f"out: the store {str(path)!r} holds a different sweep: {key} is "
                f"{_fmt_value(key, stored.get(key))} there and {_fmt_value(key, requested[key])} here; "
                "choose another output path or start afresh with overwrite=True"
            )
    extra = sorted(set(stored) - set(requested))
    if extra:
        raise SweepError(
            f"out: the store {str(path)!r} holds a different sweep (it has {extra[0]!r}); choose another "
            "output path or start afresh with overwrite=True"
        )


def resume(path: Path, plan: Plan) -> tuple[np.ndarray, int]:
    """Check the store at `path` holds this sweep, intact; return its chunk flags (the damaged
    chunks' flags cleared, with a warning each) and the number of damaged chunks."""
    group, stored = open_group(path, "out", mode="r+")
    compare_specs(path, stored, plan.spec)
    names = array_names(plan.member_vars, [a.dim for a in plan.axes])
    arrays = check_arrays("out", path, group, names, plan.spec)
    check_coordinates("out", path, arrays, plan.spec)
    done = read_done("out", path, arrays, plan.chunks)
    bad = verify_chunks(arrays, names, plan.layout, done)
    for i, reason in bad.items():
        warnings.warn(SweepWarning(
            f"out: chunk {i} of {str(path)!r}, {describe_members(plan.axes, *plan.member_range(i))}, was "
            f"done but is damaged ({reason}): computing it again"), stacklevel=3)
        try:
            arrays["chunk_done"][i] = False
        except Exception as e:  # noqa: BLE001
            raise damaged("out", path, f"its chunk flags cannot be written ({why(e)})") from None
        done[i] = False
    return done, len(bad)
