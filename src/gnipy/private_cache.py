"""What gnipy trusts on disk for its caches: a private folder, and entries authenticated in it.

A cache that is loaded from disk is code gnipy runs (the native backend's object code, JAX's
compiled executables), so a cache folder is used only if no one but the current user (and root)
could have written what is in it:

**The folder** is :func:`gnipy.private_folder.private_directory`'s: the user's alone, opened
without following a link, and every file in it opened through it (`dir_fd`, `O_NOFOLLOW`).

**The secret.** A private folder used by :class:`PrivateCache` holds a per-user secret,
:data:`SECRET_NAME`: 32 random bytes, created with mode 0600 and whole (written to a temporary
file that is then hard-linked into place, so two processes creating it at once agree on the
winner's). It is used only if it is a regular file of the user, that no one else may read or
write, of exactly 32 bytes; otherwise the folder is refused.

**Entries** (:meth:`PrivateCache.read`, :meth:`PrivateCache.write`) are the data followed by
`HMAC-SHA256(secret, key + b"\\0" + data)`: an entry loads only for the key it was written for,
and only if this user's gnipy wrote it. An entry whose tag does not match (damaged, truncated,
written by an older gnipy, another key's entry copied here, or planted) is not used: the caller
computes the data again and writes its own entry over it. An entry that is not a regular file of
the user with one link and no write permission for others (a symbolic link, a hard link, someone
else's file, a FIFO) is refused without being opened or followed, with a warning (gnipy never
makes one: only the user or root can have put it in a private folder), and the next write
replaces it: `os.replace` swaps the folder's name for gnipy's new file, never what a link points
to. Entries are written whole: a temporary file `.NAME.gnipy-PID-HEX.tmp` (the convention of
:mod:`gnipy.files`), flushed, then renamed; on any failure (a full disk, a file-size limit,
Ctrl-C) the temporary file is removed, and the temporaries of processes that died are removed by
the next write.

**Refusals** are not errors (a cache is an optimisation): the caller works without the disk, with
one :class:`~gnipy.private_folder.CacheWarning` per process and folder (:func:`~gnipy.private_folder.warn_refused`).

What this does not protect against: someone who already has the user's rights (or root's) can
change the folder, the secret and the entries, and gnipy itself.
"""

from __future__ import annotations

import errno
import hashlib
import hmac
import os
import re
import secrets
import stat
from pathlib import Path

from .files import clean_stale_temporaries, temporary_name
from .private_folder import (CREATE_FLAGS, READ_FLAGS, CacheRefused, CacheWarning, kind_of, ownership_problem,
                             private_directory, stat_no_follow, warn_refused)
from .text import user_name

__all__ = [
    "SECRET_NAME",
    "MAX_ENTRY_BYTES",
    "TAG_BYTES",
    "PrivateCache",
    "open_private_cache",
]

#: The name of the per-user secret in a private cache folder.
SECRET_NAME = ".key"
#: The length of the secret, in bytes.
SECRET_BYTES = 32
#: The length of an entry's tag (HMAC-SHA256), in bytes.
TAG_BYTES = 32
#: The largest entry read (larger files are not ours: they are not read at all).
MAX_ENTRY_BYTES = 256 * 1024 * 1024

# a temporary of gnipy's convention (gnipy.files.temporary_name), for the name it is written for
_TEMPORARY = re.compile(r"^\.(?P<name>.+)\.gnipy-\d+-[0-9a-f]{8,32}\.tmp$")
# a temporary of gnipy 0.1's native cache (tempfile.mkstemp: no process id in its name), removed once
# it is older than OLD_TEMPORARY_SECONDS (no write takes that long)
_OLD_TEMPORARY = re.compile(r"^tmp[a-z0-9_]{8}\.tmp$")
OLD_TEMPORARY_SECONDS = 3600.0


def _read_all(fd: int, limit: int) -> bytes:
    """Up to `limit` bytes of `fd`, to its end."""
    chunks, n = [], 0
    while n < limit:
        chunk = os.read(fd, min(limit - n, 1 << 20))
        if not chunk:
            break
        chunks.append(chunk)
        n += len(chunk)
    return b"".join(chunks)


def _write_all(fd: int, data: bytes) -> None:
    """Write all of `data` to `fd` (`os.write` may write less than it is given)."""
    view = memoryview(data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_secret(dir_fd: int) -> bytes | None:
    """The secret of the open folder, None if there is none yet; CacheRefused if it is not usable."""
    try:
        fd = os.open(SECRET_NAME, READ_FLAGS, dir_fd=dir_fd)
    except FileNotFoundError:
        return None
    except OSError:
        st = stat_no_follow(SECRET_NAME, dir_fd)
        if st is not None and stat.S_ISLNK(st.st_mode):
            raise CacheRefused(f"its secret file {SECRET_NAME} is a symbolic link") from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise CacheRefused(f"its secret file {SECRET_NAME} is {kind_of(st)}, not a regular file")
        if st.st_uid != os.geteuid():
            raise CacheRefused(f"its secret file {SECRET_NAME} belongs to {user_name(st.st_uid)}, not to you "
                               f"({user_name(os.geteuid())}); remove it and gnipy makes a new one")
        if st.st_mode & 0o077:
            raise CacheRefused(f"its secret file {SECRET_NAME} may be read or written by others (mode "
                               f"{stat.S_IMODE(st.st_mode):04o}, not 0600); remove it and gnipy makes a new one")
        data = _read_all(fd, SECRET_BYTES + 1) if st.st_size == SECRET_BYTES else b""
    finally:
        os.close(fd)
    if len(data) != SECRET_BYTES:
        raise CacheRefused(f"its secret file {SECRET_NAME} does not hold {SECRET_BYTES} bytes (it holds "
                           f"{st.st_size}); remove it and gnipy makes a new one")
    return data


def _secret(dir_fd: int) -> bytes:
    """The secret of the open folder, made if there is none."""
    found = _read_secret(dir_fd)
    if found is not None:
        return found
    tmp = temporary_name(Path(SECRET_NAME)).name
    fd = os.open(tmp, CREATE_FLAGS, 0o600, dir_fd=dir_fd)
    try:
        try:
            _write_all(fd, secrets.token_bytes(SECRET_BYTES))
            os.fsync(fd)
        finally:
            os.close(fd)
        try:  # a hard link never replaces: of two processes making the secret at once, one wins
            os.link(tmp, SECRET_NAME, src_dir_fd=dir_fd, dst_dir_fd=dir_fd, follow_symlinks=False)
        except FileExistsError:
            pass  # another process made it first: its secret is the one (read below)
        except OSError as e:
            if e.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK, errno.ENOSYS):
                raise
            # a file system without hard links: a rename (two first processes at once: the last one's
            # secret stays, and the entries written with the other one are computed again)
            os.replace(tmp, SECRET_NAME, src_dir_fd=dir_fd, dst_dir_fd=dir_fd)
    finally:
        try:
            os.unlink(tmp, dir_fd=dir_fd)
        except FileNotFoundError:
            pass
    found = _read_secret(dir_fd)
    if found is None:
        raise OSError(errno.ENOENT, f"the secret file {SECRET_NAME} disappeared as it was made")
    return found


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name or name.startswith(".") or "/" in name or "\x00" in name:
        raise ValueError(f"name: {name!r} is not the name of a cache entry (a file name that does not start "
                         "with '.': those are the secret's and the temporaries')")
    return name


class PrivateCache:
    """An open private cache folder: entries authenticated with the folder's secret.

    Arguments:
        path: the folder (created with mode 0700 if missing).
        what: what the folder holds, for warnings (e.g. `native object code`).
        instead: what the caller does without a usable entry, for warnings.
        remedy: what the user can do about a refusal, for warnings.

    Raises:
        CacheRefused: the folder or its secret is not the user's alone (see :func:`private_directory`).
        OSError: the folder or its secret cannot be created or read.

    Use it as a context manager, or call :meth:`close`.
    """

    def __init__(self, path, *, what: str = "cached data", instead: str = "the data were computed again",
                 remedy: str = "Set GNIPY_CACHE_DIR to a folder that only you can write."):
        self.path = Path(os.fspath(path))
        self.what, self.instead, self.remedy = what, instead, remedy
        self.fd = private_directory(self.path)
        try:
            self._secret = _secret(self.fd)
        except BaseException:
            os.close(self.fd)
            raise

    def close(self) -> None:
        """Close the folder."""
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> PrivateCache:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def tag(self, key: str, data: bytes) -> bytes:
        """`HMAC-SHA256(secret, key + b"\\0" + data)`: what follows `data` in the entry for `key`."""
        return hmac.new(self._secret, key.encode("utf-8") + b"\0" + data, hashlib.sha256).digest()

    def _refuse(self, name: str, reason: str) -> None:
        warn_refused(self.path, f"it {reason}", what=self.what, instead=self.instead, remedy=self.remedy,
                     entry=name, stacklevel=3)

    def read(self, name: str, key: str) -> bytes | None:
        """The data of the entry `name` written for `key`, or None when there is none, or it was not
        written by this user's gnipy for `key` (or it is damaged): compute the data and
        :meth:`write` them. An entry that is not a regular file of this user (a link, a hard link,
        another user's file, a FIFO) is not opened and is reported with a :class:`CacheWarning`."""
        _check_name(name)
        st = stat_no_follow(name, self.fd)
        if st is None:
            return None
        why = self._entry_problem(st)
        if why is not None:
            self._refuse(name, why)
            return None
        if not TAG_BYTES < st.st_size <= MAX_ENTRY_BYTES:
            return None
        try:
            fd = os.open(name, READ_FLAGS, dir_fd=self.fd)
        except OSError:  # replaced meanwhile (by this user's other process): read next time
            return None
        try:
            opened = os.fstat(fd)
            if (opened.st_dev, opened.st_ino) != (st.st_dev, st.st_ino) or self._entry_problem(opened):
                return None
            data = _read_all(fd, opened.st_size + 1)
        except OSError:
            return None
        finally:
            os.close(fd)
        if len(data) != opened.st_size:
            return None
        body, tag = data[:-TAG_BYTES], data[-TAG_BYTES:]
        if not hmac.compare_digest(tag, self.tag(key, body)):
            return None
        return body

    @staticmethod
    def _entry_problem(st: os.stat_result) -> str | None:
        if not stat.S_ISREG(st.st_mode):
            return f"is {kind_of(st)}, not a regular file"
        why = ownership_problem(st, "")
        if why is not None:
            return why.strip()
        if st.st_nlink != 1:
            return f"has {st.st_nlink} hard links (gnipy writes entries with one)"
        return None

    def write(self, name: str, key: str, data: bytes) -> bool:
        """Write the entry `name` for `key`: `data` and their tag, whole (a temporary file in the
        folder, flushed and renamed over `name`). Returns whether it was written: on an `OSError`
        (a full disk, a file-size limit) nothing is raised; on any failure the temporary file is
        removed. The temporaries that dead processes left in the folder are removed first."""
        _check_name(name)
        self.clean()
        tmp = temporary_name(Path(name)).name
        fd = -1
        created = False
        try:
            fd = os.open(tmp, CREATE_FLAGS, 0o600, dir_fd=self.fd)
            created = True
            _write_all(fd, bytes(data) + self.tag(key, bytes(data)))
            os.fsync(fd)  # on disk before it counts as written
            os.close(fd)
            fd = -1
            os.replace(tmp, name, src_dir_fd=self.fd, dst_dir_fd=self.fd)
            return True
        except BaseException as e:
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
            if created:
                try:
                    os.unlink(tmp, dir_fd=self.fd)
                except OSError:
                    pass
            if isinstance(e, OSError):
                return False
            raise

    def clean(self) -> list[Path]:
        """Remove the temporaries (`.NAME.gnipy-PID-HEX.tmp`) that processes which are no longer
        running left in the folder, and those of an older gnipy (`tmpXXXXXXXX.tmp`, without a
        process id) once they are :data:`OLD_TEMPORARY_SECONDS` old. Returns what was removed."""
        import time

        try:
            entries = list(os.scandir(self.fd))
        except (OSError, TypeError, NotImplementedError):  # no os.scandir of a descriptor here
            return []
        names = {m.group("name") for entry in entries if (m := _TEMPORARY.match(entry.name))}
        removed = []
        for entry in entries:
            if not _OLD_TEMPORARY.match(entry.name):
                continue
            st = stat_no_follow(entry.name, self.fd)
            if st is not None and stat.S_ISREG(st.st_mode) and time.time() - st.st_mtime > OLD_TEMPORARY_SECONDS:
                try:
                    os.unlink(entry.name, dir_fd=self.fd)
                    removed.append(self.path / entry.name)
                except OSError:
                    pass
        # through the open folder where /proc gives it a path: the folder checked, not what its path
        # names now
        proc = f"/proc/self/fd/{self.fd}"
        base = Path(proc) if os.path.isdir(proc) else self.path
        for name in sorted(names):
            removed += clean_stale_temporaries(base / name)
        return removed


def open_private_cache(path, *, what: str, instead: str, remedy: str) -> PrivateCache | None:
    """A :class:`PrivateCache` for `path`, or None: when the folder is refused (after one
    :func:`warn_refused` warning per process for it) or cannot be created or opened (silently: the
    cache is an optimisation).

    Arguments:
        path: the folder.
        what: what the folder holds, for warnings (e.g. `native object code`).
        instead: what the caller does without the cache, for warnings.
        remedy: what the user can do about a refusal, for warnings.
    """
    try:
        return PrivateCache(path, what=what, instead=instead, remedy=remedy)
    except CacheRefused as e:
        warn_refused(path, str(e), what=what, instead=instead, remedy=remedy, stacklevel=2)
    except OSError:
        pass
    return None
