"""What gnipy trusts on disk as a cache folder: a folder that is the user's alone, opened without
following links; and the one warning per folder when it is refused. The entries in such a folder,
and the secret that authenticates them, are :mod:`gnipy.private_cache`'s.

**The folder** (:func:`private_directory`) is opened once, without following a link
(`O_DIRECTORY | O_NOFOLLOW`), and the open folder is checked: a directory owned by the effective
user (`os.geteuid()`) that neither its group nor others may write (`mode & 0o022 == 0`). Every
later step goes through that open folder (`dir_fd`, `O_NOFOLLOW`), so renaming or replacing a
component of the path after the check cannot send gnipy elsewhere. A missing folder is created
with mode 0700 (and so are the missing folders above it). The folders above the cache folder are
not checked: whoever can rename them can move the folder, but cannot write into it.

**Refusals** are not errors (a cache is an optimisation): the caller works without the disk and
:func:`warn_refused` emits one :class:`CacheWarning` per process and folder, which says which
folder, why, and what to do.
"""

from __future__ import annotations

import os
import stat
import threading
import warnings
from pathlib import Path

from .text import safe, user_name, writers

__all__ = ["CacheWarning", "CacheRefused", "DIR_FLAGS", "READ_FLAGS", "CREATE_FLAGS", "private_directory",
           "warn_refused", "ownership_problem", "stat_no_follow", "kind_of"]

_O_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_O_DIRECTORY = getattr(os, "O_DIRECTORY", 0)
_O_CLOEXEC = getattr(os, "O_CLOEXEC", 0)
_O_NONBLOCK = getattr(os, "O_NONBLOCK", 0)  # a FIFO put in place of a file must not block the open
#: How a cache folder is opened: a directory, never through a link.
DIR_FLAGS = os.O_RDONLY | _O_DIRECTORY | _O_NOFOLLOW | _O_CLOEXEC
#: How an entry or the secret is opened for reading: never through a link, never blocking (a FIFO).
READ_FLAGS = os.O_RDONLY | _O_NOFOLLOW | _O_NONBLOCK | _O_CLOEXEC
#: How a new file is created in a cache folder: exclusively, never through a link.
CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | _O_NOFOLLOW | _O_CLOEXEC


class CacheWarning(RuntimeWarning):
    """A cache folder or entry was not used because gnipy cannot trust it (the message says which,
    why, and what to do); the work was done without the disk cache."""


class CacheRefused(Exception):
    """A folder or file that gnipy does not trust for a cache; the message is the reason (e.g. `it
    is writable by others (mode 1777)`)."""


def _supported() -> str | None:
    """Why this platform cannot check a folder (None where it can)."""
    if not (_O_NOFOLLOW and _O_DIRECTORY and hasattr(os, "geteuid") and os.open in os.supports_dir_fd
            and os.stat in os.supports_dir_fd):
        return ("this platform cannot open a folder without following links and check who owns it, "
                "so gnipy keeps no cache on disk here")
    return None


def ownership_problem(st: os.stat_result, what: str) -> str | None:
    """Why a file or folder with status `st` is not the user's alone (None if it is)."""
    euid = os.geteuid()
    if st.st_uid != euid:
        return f"{what} belongs to {user_name(st.st_uid)}, not to you ({user_name(euid)})"
    if st.st_mode & 0o022:
        return f"{what} is writable by {writers(st.st_mode)} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def stat_no_follow(name, dir_fd: int | None = None) -> os.stat_result | None:
    """The status of `name` (in the open folder `dir_fd`), not following a link; None if it cannot be read."""
    try:
        return os.stat(name, dir_fd=dir_fd, follow_symlinks=False)
    except OSError:
        return None


def kind_of(st: os.stat_result) -> str:
    """What a file that is not a regular file is, in words (`a symbolic link`, `a FIFO`, ...)."""
    mode = st.st_mode
    for test, kind in ((stat.S_ISLNK, "a symbolic link"), (stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"),
                       (stat.S_ISSOCK, "a socket"), (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device")):
        if test(mode):
            return kind
    return "a special file"


def _open_directory(path: Path) -> int:
    try:
        return os.open(path, DIR_FLAGS)
    except ValueError as e:  # a NUL character in the path
        raise CacheRefused(f"it is not a path that can be opened ({e})") from None
    except FileNotFoundError:
        raise
    except OSError as e:
        st = stat_no_follow(path)
        if st is not None and stat.S_ISLNK(st.st_mode):
            raise CacheRefused("it is a symbolic link (gnipy does not follow links to its caches)") from None
        if st is not None and not stat.S_ISDIR(st.st_mode):
            raise CacheRefused(f"it is {kind_of(st) if not stat.S_ISREG(st.st_mode) else 'a file'}, "
                               "not a directory") from None
        raise e from None


def _make_directories(path: Path) -> None:
    """Create `path` and the missing folders above it, each with mode 0700 (`os.makedirs` gives
    the folders above the default mode)."""
    missing = []
    p = path
    while stat_no_follow(p) is None:
        missing.append(p)
        if p.parent == p:
            break
        p = p.parent
    for d in reversed(missing):
        try:
            os.mkdir(d, 0o700)
        except FileExistsError:  # made meanwhile (by another process): checked when opened
            pass


def private_directory(path, *, create: bool = True) -> int:
    """Open the folder `path` for a cache, if it is the user's alone.

    Arguments:
        path: the folder.
        create: create it (mode 0700, and the missing folders above it, also 0700) if missing.

    Returns:
        A file descriptor of the open folder (the caller closes it): open every file in it
        through this descriptor (`dir_fd=`) and with `O_NOFOLLOW`.

    Raises:
        CacheRefused: the folder is a symbolic link, not a directory, owned by another user, or
            writable by its group or others (the message says which).
        OSError: it cannot be created or opened (e.g. no permission, a read-only file system).
    """
    why = _supported()
    if why is not None:
        raise CacheRefused(why)
    path = Path(os.fspath(path))
    try:
        fd = _open_directory(path)
    except FileNotFoundError:
        if not create:
            raise
        _make_directories(path)
        fd = _open_directory(path)
    try:
        st = os.fstat(fd)
        if not stat.S_ISDIR(st.st_mode):  # O_DIRECTORY makes this impossible; kept for platforms without it
            raise CacheRefused("it is not a directory")
        why = ownership_problem(st, "it")
        if why is not None:
            raise CacheRefused(why)
    except BaseException:
        os.close(fd)
        raise
    return fd


_WARNED: set[str] = set()
_WARNED_LOCK = threading.Lock()


def warn_refused(folder, reason: str, *, what: str, instead: str, remedy: str, entry: str | None = None,
                 stacklevel: int = 2) -> bool:
    """Emit one :class:`CacheWarning` per process for `folder`: later calls for the same folder
    are silent. Returns whether this call warned.

    Arguments:
        folder: the cache folder.
        reason: why it (or `entry`) was refused, e.g. `it is writable by others (mode 1777)`.
        what: what the folder holds, e.g. `native object code`.
        instead: what gnipy did instead, e.g. `the program was compiled in memory`.
        remedy: what to do about it (the settings to change).
        entry: the name of the entry refused, when the folder itself is fine.
        stacklevel: as for `warnings.warn`, counted from the caller.
    """
    name = os.path.abspath(os.fspath(folder))
    with _WARNED_LOCK:
        if name in _WARNED:
            return False
        _WARNED.add(name)
    rule = ("gnipy loads a cache only from a folder that you own and no one else can write, never through a link, "
            "and only entries that your gnipy wrote")
    if entry is None:
        text = f"gnipy does not use the cache folder {safe(folder)} for {what}: {safe(reason)}. {rule}; {instead}. "
    else:
        text = (f"gnipy does not load {safe(entry)} from the cache folder {safe(folder)} ({what}): {safe(reason)}. "
                f"{rule}, and never makes such an entry (if you did not put it there, someone with your rights or "
                f"root did); {instead}, and gnipy's own entry replaces it (the name, never what a link points to). ")
    warnings.warn(CacheWarning(text + remedy), stacklevel=stacklevel + 1)
    return True
