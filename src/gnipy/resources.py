"""The resource bounds gnipy checks before it computes anything: the memory a run may take and
the bytes of a saved node. One place for these facts, used by `gni run`
(:mod:`gnipy.cli.resources`), optimal control and identification (:mod:`gnipy.control`)."""

from __future__ import annotations

import os

__all__ = ["MAX_MEMORY_BYTES", "memory_bound", "node_bytes"]

#: Runs are refused (before anything is compiled or allocated, unless the user lifts the bound)
#: when they are estimated to need more memory than the smaller of this and half the machine's
#: RAM (:func:`memory_bound`).
MAX_MEMORY_BYTES = 8 * 2**30


def memory_bound() -> int:
    """min(:data:`MAX_MEMORY_BYTES`, half the physical memory)."""
    bound = MAX_MEMORY_BYTES
    try:
        phys = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        if phys > 0:
            bound = min(bound, phys // 2)
    except (ValueError, OSError, AttributeError):  # not known on this system
        pass
    return bound


def node_bytes(system) -> int:
    """Bytes of one saved node of a result (a generous estimate): t, q, v, p, the hidden momentum,
    energy, energy of p+, the constraint residual (at most one entry per velocity), R, the node and
    step indices."""
    k = system.group.matrix_size if system.group is not None else 0
    values = 1 + system.n + 4 * len(system.velocities) + k * k + 4
    return 8 * values + 16
