"""What gnipy owns on disk: safe destinations, atomic writes, owned directories, checksums.

Every file or directory gnipy writes goes through this module, so the rules hold everywhere
(`gni run`, `gni sweep`, `gni convergence`, `gni reproduce`, :func:`gnipy.write_netcdf`,
:func:`gnipy.simulate_to_file`, :func:`gnipy.run_sweep`):

**Destinations** (:func:`check_destination`). gnipy writes a regular file or a directory at a
path only if nothing is there, or a regular file (resp. a directory that gnipy created, see
below) is there and the caller allowed replacing it (`overwrite=True`, `--overwrite`). It never
writes through or replaces a symbolic link, a device, a FIFO or a socket, whatever the flags.

**Atomic writes** (:func:`atomic_write`, :func:`atomic_write_text`, :func:`atomic_savefig`). The
data go to a temporary file beside the destination, are flushed to disk, and the temporary file
then replaces the destination with `os.replace` (atomic on POSIX within one file system). A reader
sees the old file or the new one, never half of one; on any failure (a full disk, Ctrl-C) the
temporary file is removed and the old file is left as it was. Every failure to write, including
the netCDF library's `RuntimeError: NetCDF: HDF error` on a full disk, becomes an
:class:`OutputError` that names the path.

**Temporaries** are named `.NAME.gnipy-PID-HEX.tmp` (or `.partial` for directories): the
process id lets the next run remove the temporaries of a process that died (SIGKILL, power loss)
without touching those of a run still going (:func:`clean_stale_temporaries`).

**Owned directories** (:func:`make_owned_dir`, :func:`remove_owned_dir`). A working directory
gnipy creates (the checkpoint parts of a streamed run, a sweep store) holds a marker file
:data:`MARKER`; gnipy removes or replaces a directory only when the marker is there, and even then
deletes only the files it writes itself: a file someone else put there is left, with the
directory.

**Checksums** (:class:`DataChecksum`). A checksum of named arrays (SHA-256 of each array's
dtype, shape and C-order bytes), computed in pieces along the first axis so long runs can be
summed as they stream; checkpoint parts, sweep chunks and result files carry one, and a resume or
`gni verify` recomputes it.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import stat
import uuid
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path

from .errors import OutputError

__all__ = [
    "OutputError",
    "MARKER",
    "check_destination",
    "check_directory_destination",
    "atomic_write",
    "atomic_write_text",
    "atomic_savefig",
    "temporary_name",
    "clean_stale_temporaries",
    "make_owned_dir",
    "is_owned_dir",
    "remove_owned_dir",
    "DataChecksum",
    "array_checksum",
    "as_output_error",
    "format_bytes",
    "free_bytes",
]

#: The marker file of a directory gnipy created (holds JSON: what the directory is for).
MARKER = ".gnipy-owned"


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


# ------------------------------------------------------------------------------------------
# Destinations
# ------------------------------------------------------------------------------------------
def _kind(st: os.stat_result) -> str:
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


def check_destination(path, *, overwrite: bool = False, argument: str = "out") -> Path:
    """`path` as a `Path`, if gnipy may write a regular file there; else :class:`OutputError`.

    Allowed: nothing at `path`, or a regular file when `overwrite` is true, in a writable
    directory. Refused always: a symbolic link (even to a regular file), a directory, a device,
    FIFO or socket. The message names `argument` (e.g. `--out`) and what is there.
    """
    path = _as_path(path, argument)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise OutputError(f"{argument}: cannot write {path}: {e.strerror or e}") from None
    if st is not None:
        kind = _kind(st)
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
    path = _as_path(path, argument)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise OutputError(f"{argument}: cannot use {path}: {e.strerror or e}") from None
    if st is not None:
        if not stat.S_ISDIR(st.st_mode):
            raise OutputError(f"{argument}: {path} is {_kind(st)}, not a directory gnipy created "
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


# ------------------------------------------------------------------------------------------
# Temporaries and atomic writes
# ------------------------------------------------------------------------------------------
_TEMP = re.compile(r"^\.(?P<name>.+)\.(?:gnipy-(?P<pid>\d+)-)?[0-9a-f]{8,32}\.(?:tmp|partial|old)$")


def temporary_name(path: Path, suffix: str = "tmp") -> Path:
    """A fresh temporary path beside `path`: `.NAME.gnipy-PID-HEX.SUFFIX`."""
    return path.with_name(f".{path.name}.gnipy-{os.getpid()}-{uuid.uuid4().hex[:12]}.{suffix}")


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # someone else's process (or cannot tell): leave its files
    return True


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
        if pid is not None and _pid_alive(int(pid)):
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

    Raises:
        OutputError: the destination is refused, or writing failed (the temporary is removed and
            an old file at `path` is untouched).
    """
    path = Path(os.fspath(path)) if checked else check_destination(path, overwrite=overwrite, argument=argument)
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


# ------------------------------------------------------------------------------------------
# Owned directories
# ------------------------------------------------------------------------------------------
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


# ------------------------------------------------------------------------------------------
# Checksums
# ------------------------------------------------------------------------------------------
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
            text = "".join("\x1f".join(map(str, np.asarray(r).ravel().tolist())) + "\x1e"
                           for r in a.reshape(rows, -1))
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


def array_checksum(arrays: Mapping[str, object]) -> str:
    """The :class:`DataChecksum` digest of whole named arrays."""
    c = DataChecksum()
    for name, a in arrays.items():
        c.update(name, a)
    return c.hexdigest()
