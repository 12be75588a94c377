"""The size of a streamed run's output, estimated and checked before anything is computed
(:mod:`gnipy.streaming`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..files import OutputError, format_bytes, free_bytes, is_owned_dir
from .parts import part_indices

#: The largest destination :func:`simulate_to_file` writes unless told otherwise (`max_bytes`):
#: 64 GiB.
DEFAULT_MAX_BYTES = 2**36
#: Estimated overhead (HDF5 header, state, attributes) of one file, in bytes.
_FILE_OVERHEAD = 32 * 1024


def _estimate(system, b0, steps: int, save_every: int, n_chunks: int, gni_family: bool) -> tuple[int, int, int]:
    """(saved nodes, bytes per node in the destination, estimated bytes of the destination)."""
    nodes = steps // save_every + 1 + (1 if steps % save_every else 0)
    n, N = len(np.atleast_1d(np.asarray(system.space.coordinates(b0)))), int(system.dim)
    m = system.num_constraints(b0)
    R = system.space.orientation(b0)
    k2 = 0 if R is None else int(np.asarray(R).size)
    per_node = 8 * (3 + n + 2 * N + 1 + m + k2 + (3 if gni_family else 0))  # time, node, step, q, v, p, E, res, R, diag
    return nodes, per_node, nodes * per_node + _FILE_OVERHEAD


def check_size(system, b0, steps, save_every, n_chunks, gni_family, path: Path, parts: Path, max_bytes) -> None:
    """:class:`OutputError` when the destination `path` would exceed `max_bytes`, or the destination and
    the parts (those in `parts` counted) would not fit on the disk."""
    nodes, per_node, size = _estimate(system, b0, steps, save_every, n_chunks, gni_family)
    allow = "pass max_bytes=None to write it anyway"
    if size > max_bytes:
        raise OutputError(
            f"path: {path} would hold {nodes:,} saved nodes of {per_node} bytes, about {format_bytes(size)}, more than "
            f"max_bytes = {format_bytes(max_bytes)}; save fewer nodes (a larger save_every, fewer steps), "
            f"or {allow}"
        )
    parts_size = size - 8 * nodes + n_chunks * _FILE_OVERHEAD  # the parts: no node index, a header each
    existing = 0
    if is_owned_dir(parts):
        for _, f in part_indices(parts):
            try:
                existing += f.stat().st_size
            except OSError:
                pass
    need = size + max(0, parts_size - existing)
    directory = path.parent if str(path.parent) else Path(".")
    free = free_bytes(directory)
    if free is not None and need > free:
        raise OutputError(
            f"path: the run needs about {format_bytes(need)} of disk space ({nodes:,} saved nodes: the checkpoint parts "
            f"and {path}, about {format_bytes(size)}, coexist while they are merged), and {directory} has "
            f"{format_bytes(free)} free; free some space, save fewer nodes, or {allow}"
        )
