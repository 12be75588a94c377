"""The bounds `gni run` checks before anything is compiled: memory of the saved nodes, the size of
the file and the free disk space (`--yes` lifts them), and when a run is streamed."""

from __future__ import annotations

from pathlib import Path

from gnipy.files import format_bytes, free_bytes
from gnipy.resources import MAX_MEMORY_BYTES, memory_bound, node_bytes

from .errors import UsageError

__all__ = ["MAX_MEMORY_BYTES", "MAX_OUTPUT_BYTES", "MEMORY_COPIES", "STREAM_NODES", "check_resources",
           "check_result_file", "memory_bound", "node_bytes"]

#: `gni run` streams runs that save more nodes than this (memory stays bounded by one chunk).
STREAM_NODES = 1_000_000

#: `gni run` refuses (unless --yes) a run whose saved nodes would need more memory than
#: :func:`gnipy.resources.memory_bound` ...
#: ... or a result file larger than this, or than the free space of its file system.
MAX_OUTPUT_BYTES = 64 * 2**30
#: The memory of an in-memory run, as a multiple of its saved nodes' bytes (the device arrays,
#: their host copies, the dataset written).
MEMORY_COPIES = 3


def check_resources(system, n_steps: int, stride: int, streamed: bool, chunk, out: Path | None, length: str,
                    chunk_given: bool = True) -> None:
    """Refuse (`UsageError`) a run whose memory or file is estimated beyond the bounds
    (:data:`MAX_MEMORY_BYTES`, :data:`MAX_OUTPUT_BYTES`, the free disk space); `--yes` skips this.
    `out` None: a run that writes no file (its memory is checked)."""

    per_node = node_bytes(system)
    nodes = 1 + -(-n_steps // stride)  # the initial node, every stride-th, and the last
    file_bytes = nodes * per_node
    if streamed:
        from gnipy.streaming import DEFAULT_CHUNK_NODES

        chunk_nodes = (chunk // stride if chunk is not None else DEFAULT_CHUNK_NODES) + 1
        memory = min(chunk_nodes, nodes) * per_node * MEMORY_COPIES
        disk = 2 * file_bytes  # the checkpoint parts and the file they are joined into, at the end
        where = "in one chunk"
        option = "--checkpoint-every" if chunk_given else f"{length}/--save-every"
    else:
        memory = nodes * per_node * MEMORY_COPIES
        disk = file_bytes
        where = "in memory"
        option = f"{length}/--save-every"
    bound = memory_bound()
    if memory > bound:
        raise UsageError(
            option, f"the run would hold {min(nodes, chunk_nodes) if streamed else nodes:,} saved nodes {where}, "
            f"about {format_bytes(memory)}: more than gnipy's bound of {format_bytes(bound)} (the smaller of "
            f"{format_bytes(MAX_MEMORY_BYTES)} and half the RAM); "
            + ("choose a smaller --checkpoint-every" if streamed else
               "stream the run with --checkpoint-every K (memory then holds one chunk) or save fewer nodes "
               "(--save-every K)") + ", or pass --yes to run anyway"
        )
    if out is None:
        return
    parts = " (twice that on disk while the run goes on: the checkpoint parts and the file)" if streamed else ""
    what = f"the file would hold {nodes:,} saved nodes, about {format_bytes(file_bytes)}{parts}"
    if file_bytes > MAX_OUTPUT_BYTES:
        raise UsageError(
            f"{length}/--save-every", f"{what}: more than gnipy's bound of {format_bytes(MAX_OUTPUT_BYTES)}; save fewer "
            "nodes (--save-every K), or pass --yes to run anyway"
        )
    directory = out.parent if str(out.parent) else Path(".")
    free = free_bytes(directory)
    if free is not None and disk > free:
        raise UsageError(
            f"{length}/--save-every", f"{what}, but {str(directory)!r} has {format_bytes(free)} free; save fewer nodes "
            "(--save-every K) or free some space, or pass --yes to run anyway"
        )


def check_result_file(system, nodes: int, out: Path, key: str) -> None:
    """Refuse (`UsageError` naming `key`, the entry of the problem file that sets the run's length)
    a result file of `gni control` / `gni fit` that would hold `nodes` nodes of `system` beyond
    :data:`MAX_OUTPUT_BYTES` or the free disk space of its folder; `--yes` skips this. (Their memory
    is bounded by the library, before anything is compiled: `max_bytes`.)"""
    file_bytes = nodes * node_bytes(system)
    what = f"--out would hold {nodes:,} nodes, about {format_bytes(file_bytes)}"
    if file_bytes > MAX_OUTPUT_BYTES:
        raise UsageError(key, f"{what}: more than gnipy's bound of {format_bytes(MAX_OUTPUT_BYTES)}; shorten the run, "
                         "or pass --yes to run anyway")
    directory = out.parent if str(out.parent) else Path(".")
    free = free_bytes(directory)
    if free is not None and file_bytes > free:
        raise UsageError(key, f"{what}, but {str(directory)!r} has {format_bytes(free)} free; free some space or "
                         "shorten the run, or pass --yes to run anyway")
