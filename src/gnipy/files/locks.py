"""One writer per output: the lock a run holds on its output (:mod:`gnipy.files`)."""

from __future__ import annotations

import errno
import os
import stat
import threading
from pathlib import Path

from ..errors import OutputBusy, OutputError
from .destinations import file_kind


__all__ = ["lock_path", "output_lock", "pid_alive"]


def pid_alive(pid: int) -> bool:
    """Whether the process `pid` may be running (this one, or one that exists; a process of another
    user, or one that cannot be asked about, counts as running: its files are left alone)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True  # someone else's process (or cannot tell): leave its files
    return True


def lock_path(path) -> Path:
    """The lock file of the output `path`: `.NAME.gnipy-lock` beside it."""
    path = Path(os.fspath(path))
    return path.with_name(f".{path.name}.gnipy-lock")


_HELD: dict[str, list] = {}  # lock file -> [fd, count]: this process's locks (reentrant)
_HELD_LOCK = threading.Lock()


class output_lock:
    """`with output_lock(path, argument="out"):` hold the lock of the output `path` (a file or a
    directory gnipy writes), so that no other process writes it meanwhile.

    The lock is the file :func:`lock_path` locked with `flock` (exclusive, not waiting) and holding
    the owner's PID. A process that finds it locked raises :class:`OutputBusy` at once, naming
    `argument`, the path and the owner's PID. The kernel drops the lock of a process that dies
    (SIGKILL included), so a lock file left behind is taken over by the next writer and removed on
    release. The lock is reentrant within a process (a command that locks its `--out` and then
    calls a library function that locks it again). Where the file system does not support `flock`
    (some network file systems), the PID in the file decides: a live process other than this one
    holds it. Where the lock file cannot be created (a directory that is not writable), nothing is
    locked: the write that follows fails with its own, clearer, error.
    """

    def __init__(self, path, *, argument: str = "out"):
        self.path = Path(os.fspath(path))
        try:
            self.path = self.path.expanduser()
        except RuntimeError:  # "~nosuchuser": the destination's own check says so
            pass
        self.argument = argument
        self._key = None

    def __enter__(self) -> "output_lock":
        try:
            lock = lock_path(self.path)
        except ValueError:  # no name to lock (e.g. ""): the destination's own check refuses it
            return self
        if "\x00" in str(lock):
            return self
        key = os.path.abspath(lock)
        with _HELD_LOCK:
            held = _HELD.get(key)
            if held is not None:
                held[1] += 1
                self._key = key
                return self
            fd = self._acquire(lock)
            if fd is not None:
                _HELD[key] = [fd, 1]
                self._key = key
        return self

    def __exit__(self, *exc) -> bool:
        if self._key is None:
            return False
        with _HELD_LOCK:
            held = _HELD[self._key]
            held[1] -= 1
            if held[1] == 0:
                del _HELD[self._key]
                try:  # unlinked while still locked: whoever opens it next gets a fresh file
                    os.unlink(self._key)
                except OSError:
                    pass
                os.close(held[0])
        self._key = None
        return False

    def _busy(self, lock: Path, fd: int) -> OutputBusy:
        try:
            owner = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
        except OSError:
            owner = ""
        who = f"another gnipy process (PID {owner})" if owner.isdigit() else "another gnipy process"
        return OutputBusy(f"{self.argument}: {self.path} is being written by {who} "
                          f"(lock file {lock}); wait for it to finish, or choose another path")

    def _acquire(self, lock: Path) -> int | None:
        try:
            import fcntl
        except ImportError:  # not POSIX (Windows): the PID in the file decides
            fcntl = None

        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
        for _ in range(20):  # retried only when the holder released (and unlinked) it meanwhile
            try:
                fd = os.open(lock, flags, 0o600)
            except OSError as e:
                if e.errno == errno.ELOOP:
                    raise OutputError(f"{self.argument}: {lock} (the lock file of {self.path}) is a symbolic "
                                      "link; gnipy does not follow it (remove it)") from None
                return None  # cannot create it (a read-only directory): the write reports that itself
            try:
                st = os.fstat(fd)
                if not stat.S_ISREG(st.st_mode):
                    raise OutputError(f"{self.argument}: {lock} (the lock file of {self.path}) is "
                                      f"{file_kind(st)}; remove it")
                try:
                    if fcntl is None:
                        raise OSError(errno.ENOSYS, "no flock")
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    raise self._busy(lock, fd) from None
                except OSError:  # no flock here (a network file system, Windows): the PID in the file decides
                    owner = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                    if owner.isdigit() and int(owner) != os.getpid() and pid_alive(int(owner)):
                        raise self._busy(lock, fd) from None
                try:  # still the file at `lock`? (a holder unlinks it when it releases)
                    now = os.stat(lock, follow_symlinks=False)
                except FileNotFoundError:
                    os.close(fd)
                    continue
                if (now.st_dev, now.st_ino) != (st.st_dev, st.st_ino):
                    os.close(fd)
                    continue
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                return fd
            except BaseException:
                try:
                    os.close(fd)
                except OSError:
                    pass
                raise
        raise OutputBusy(f"{self.argument}: cannot lock {self.path}: its lock file {lock} keeps "
                         "changing (other gnipy processes are starting on it); try again")
