"""Checksums of named arrays, computed in pieces (:mod:`gnipy.files`)."""

from __future__ import annotations

import hashlib
from collections.abc import Mapping


__all__ = ["DataChecksum", "array_checksum", "as_stored"]


class DataChecksum:
    """A checksum of named arrays, fed in pieces along their first axis.

    `update(name, block)` appends `block` (its C-order bytes) to the array `name`; the digest
    covers every array's name, dtype, trailing shape, length and bytes, so the same data give the
    same digest however they were cut, and a changed, missing, extra or reordered value changes
    it. Non-array data (e.g. a JSON spec) can be fed with :meth:`update_text`.
    """

    def __init__(self):
        self._hashes: dict[str, hashlib._Hash] = {}
        self._meta: dict[str, tuple[str, tuple[int, ...], int]] = {}

    def update(self, name: str, block) -> None:
        import numpy as np

        a = np.asarray(block)
        if a.ndim == 0:
            a = a.reshape(1)
        rows = int(a.shape[0])
        if a.dtype.kind in "OUS":  # strings: a canonical byte form, each first-axis entry ended by \x1e
            entries = a.reshape(rows, -1) if rows else ()  # none: e.g. the coordinate names of a model on G alone
            text = "".join("\x1f".join(map(str, np.asarray(r).ravel().tolist())) + "\x1e" for r in entries)
            a = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
            dtype, tail = "str", ()
        else:
            a = np.ascontiguousarray(a)
            dtype, tail = a.dtype.str, tuple(int(n) for n in a.shape[1:])
        if name in self._meta:
            old_dtype, old_tail, n = self._meta[name]
            if (old_dtype, old_tail) != (dtype, tail):
                raise ValueError(f"checksum of {name}: a piece of dtype {dtype} and trailing shape {tail} does "
                                 f"not continue one of dtype {old_dtype} and trailing shape {old_tail}")
            self._meta[name] = (dtype, tail, n + rows)
        else:
            self._hashes[name] = hashlib.sha256()
            self._meta[name] = (dtype, tail, rows)
        self._hashes[name].update(a.tobytes())

    def update_text(self, name: str, text: str) -> None:
        import numpy as np

        self.update(name, np.frombuffer(text.encode("utf-8"), dtype=np.uint8))

    def hexdigest(self) -> str:
        """The digest (`sha256:` and 64 hex digits)."""
        total = hashlib.sha256()
        for name in sorted(self._hashes):
            dtype, tail, n = self._meta[name]
            total.update(f"{name}\0{dtype}\0{tail}\0{n}\0{self._hashes[name].hexdigest()}\n".encode())
        return "sha256:" + total.hexdigest()


def as_stored(values):
    """What a checksum of a file's variable is fed for `values` written whole: the values, or, for a
    variable with no entries along its first axis, float zeros of its trailing shape whatever its
    type (the form :func:`gnipy.io.netcdf_checksum` reads such a variable in, and in which the files
    gnipy has written were checksummed: netCDF gives an empty string variable no numpy type)."""
    import numpy as np

    a = np.asarray(values)
    return np.zeros((0, *a.shape[1:])) if a.ndim and a.shape[0] == 0 else a


def array_checksum(arrays: Mapping[str, object]) -> str:
    """The :class:`DataChecksum` digest of whole named arrays."""
    c = DataChecksum()
    for name, a in arrays.items():
        c.update(name, a)
    return c.hexdigest()
