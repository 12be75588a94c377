"""The user's own systems, named by reference: `path/to/file.py:make_sleigh` or
`package.module:make_sleigh` (as `uvicorn module:app` or `pytest path::name` name theirs).

Wherever gnipy takes a zoo model's name (:func:`gnipy.get_model`, `gni run`, `gni sweep`, `gni
fit`, `gni control`, `gni convergence`, `gni stability`, `gni atlas`, :func:`gnipy.run_sweep`, :func:`gnipy.fit`),
it also takes a reference `SOURCE:NAME` to a function of the user's that returns a
:class:`gnipy.System` (or to a System itself). The registry (:func:`gnipy.registry.get_model`) turns
the function into a model: its keyword parameters with numeric defaults are the model's parameters
(`--set` and sweeps reach them), and the System's `defaults` its initial condition. This module
loads the function and says where it came from; it runs nothing else.

**What is loaded, and what is refused.** SOURCE is a file when it ends in `.py` or contains a path
separator, else a dotted module name:

- *A file* (a symbolic link is followed to its target) is read through one open folder and one
  open file, both checked on what was opened: a regular file owned by the current user (or root)
  that neither its group nor others may write, in a folder likewise, or in a folder with the
  sticky bit (such as /tmp) where no one else can replace the user's file. Group write is allowed
  where the group is the user's private group (systems with umask 002: the user's primary group,
  named as the user, with no other member). A file that fails is refused with an
  :class:`~gnipy.InputError` that says why, *before* any of it runs: code that another user could
  have changed is not run under this user's name. Its text is compiled by gnipy (`compile`), so no
  cached bytecode (`__pycache__`) is read or written, and its folder is not added to `sys.path` (a
  file that imports a sibling module must be a package's, named as `package.module:NAME`).
- *A module* is imported by Python's own import system (`importlib.import_module`), as any
  installed code would be: gnipy checks nothing of it (it is code on the user's `sys.path`).

An exception raised by the user's code (the file's top level, the module's import, the function)
becomes an InputError naming `model`, the exception and the line that raised it.

**Where it came from** (:attr:`Loaded.digest`): the SHA-256 of the file's text (of the module's
source file as it was when this process first imported it; a module whose source changed since is
refused, as the process would run the old code; None for a module without a `.py` source, whose
changes are not tracked). Streamed runs and sweeps record the reference and the digest, and refuse
to resume when the file changed; a sweep's workers load the reference again and refuse a file that
is no longer the one planned.

**In files of data** (the problem files of `gni fit` and `gni control`, the `--config` of `gni
run`), a model reference may only name a `.py` file in the data file's folder or below it
(:func:`data_file_reference`): a data file received from someone else cannot make gnipy run an
arbitrary module or a script elsewhere on the user's disk.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import os
import re
import stat
import sys
import threading
import types
from pathlib import Path
from typing import Any

from .errors import InputError
from .text import safe, user_name, writers

__all__ = ["MAX_SOURCE_BYTES", "Loaded", "is_reference", "split_reference", "data_file_reference", "private_group",
           "user_code_error", "load"]

#: The largest source file read (a model's file is a few kilobytes; a larger file is not one).
MAX_SOURCE_BYTES = 16 * 1024 * 1024

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_MODULE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*$")
_O_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)


@dataclasses.dataclass(frozen=True)
class Loaded:
    """A loaded reference.

    Attributes:
        reference: the canonical reference: `ABSOLUTE_PATH:NAME` for a file (so that workers and
            resumed runs in another folder find it), `module:NAME` for a module.
        obj: what NAME is in the file or module (a function returning a System, or a System).
        digest: `"sha256:<hex>"` of the file's text (the module's source file); None for a module
            without a source file.
        source: the file it came from (None for a module without one).
    """

    reference: str
    obj: Any
    digest: str | None
    source: str | None


def is_reference(text) -> bool:
    """Whether `text` is a reference `SOURCE:NAME` to a user's system (a zoo model's name has no
    colon)."""
    return isinstance(text, str) and ":" in text


def split_reference(text: str) -> tuple[str, str, bool]:
    """`(source, name, is_file)` of a reference `SOURCE:NAME`, checked (InputError naming `model`)."""
    if not is_reference(text):
        raise InputError(f"model: expected a reference SOURCE:NAME (a file or module, then a function), got {text!r}")
    source, _, name = text.rpartition(":")
    if not _NAME.match(name):
        raise InputError(f"model: {safe(text)!r}: expected SOURCE:NAME with NAME a Python name (the function "
                         f"that returns the System), got {safe(name)!r}")
    is_file = source.endswith(".py") or "/" in source or os.sep in source
    if not source or (not is_file and not _MODULE.match(source)):
        raise InputError(f"model: {safe(text)!r}: SOURCE must be a file ending in .py or a dotted module name, "
                         f"got {safe(source)!r}")
    return source, name, is_file


def data_file_reference(text: str, folder: Path, key: str) -> str:
    """The reference `text` found under `key` of a data file in `folder`, made absolute: only
    `FILE.py:NAME` with FILE relative to the folder and inside it (InputError naming `key`
    otherwise, see the module docstring)."""
    if not is_reference(text):
        return text
    source, name, is_file = split_reference(text)
    inside = Path(os.path.normpath(source))
    if not is_file or inside.is_absolute() or source.startswith("~") or inside.parts[:1] == ("..",):
        raise InputError(f"{key}: in a file of data, a model of your own must be a .py file beside it or below "
                         f"it (FILE.py:NAME, relative to {safe(str(folder))!r}), got {safe(text)!r}: a file "
                         "received from someone else must not run other code of yours; pass it on the command "
                         "line (gni run), or copy the file beside this one")
    return f"{Path(folder) / inside}:{name}"


def private_group(gid: int) -> bool:
    """Whether the group `gid` is the user's private group (a user-private-group system, umask 002:
    the user's primary group, named as the user, with no other members), whose write permission
    lets no one else write."""
    try:
        import grp
        import pwd

        user = pwd.getpwuid(os.geteuid())
        group = grp.getgrgid(gid)
    except (ImportError, KeyError):
        return False
    return gid == user.pw_gid and group.gr_name == user.pw_name and set(group.gr_mem) <= {user.pw_name}


def _trust_problem(st: os.stat_result, what: str, *, folder: bool = False) -> str | None:
    """Why `what` (status `st`) could have been written by someone other than the user or root."""
    euid = os.geteuid()
    if st.st_uid not in (euid, 0):
        return f"{what} belongs to {user_name(st.st_uid)}, not to you ({user_name(euid)}) or root"
    mode = st.st_mode & ~0o020 if st.st_mode & 0o020 and private_group(st.st_gid) else st.st_mode
    if mode & 0o022 and not (folder and mode & stat.S_ISVTX):
        return f"{what} is writable by {writers(mode)} (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def _read_trusted(path: Path) -> bytes:
    """The bytes of the file `path` (a symbolic link resolved to its target), read through one open
    file in one open folder, both checked on what was opened (`fstat`): no component can be
    swapped between the check and the read."""
    if not hasattr(os, "geteuid"):
        raise InputError(f"model: {safe(str(path))!r}: loading a system from a file needs POSIX file ownership "
                         "(not available here); install it as a package and name it package.module:NAME")
    try:
        real = Path(os.path.realpath(path))
        folder_fd = os.open(real.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | _O_NOFOLLOW
                            | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputError(f"model: no file {safe(str(path))!r}") from None
    except (OSError, ValueError) as e:  # ValueError: a NUL byte in the path
        raise InputError(f"model: cannot open {safe(str(path))!r}: {safe(getattr(e, 'strerror', None) or str(e))}"
                         ) from None
    try:
        try:
            fd = os.open(real.name, os.O_RDONLY | _O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0)
                         | getattr(os, "O_NONBLOCK", 0), dir_fd=folder_fd)
        except FileNotFoundError:
            raise InputError(f"model: no file {safe(str(path))!r}") from None
        except OSError as e:
            raise InputError(f"model: cannot open {safe(str(path))!r}: {safe(e.strerror or str(e))}") from None
        folder_st = os.fstat(folder_fd)
    finally:
        os.close(folder_fd)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"model: {safe(str(path))!r} is not a regular file")
        why = _trust_problem(st, "the file") or _trust_problem(folder_st, "its folder", folder=True)
        if why is None and folder_st.st_mode & stat.S_ISVTX and folder_st.st_mode & 0o022 and st.st_uid != os.geteuid():
            why = "the file is in a folder others may write and is not yours"
        if why is not None:
            raise InputError(f"model: refusing to run {safe(str(path))!r}: {why}; another user could have changed "
                             "it. Make it yours and not writable by others (chmod go-w), or copy it to a "
                             "folder of your own")
        if st.st_size > MAX_SOURCE_BYTES:
            raise InputError(f"model: {safe(str(path))!r} is {st.st_size} bytes, more than a model's source "
                             f"({MAX_SOURCE_BYTES} bytes at most)")
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, 1 << 20)
            if not chunk:
                break
            total += len(chunk)
            if total > MAX_SOURCE_BYTES:
                raise InputError(f"model: {safe(str(path))!r} grew beyond {MAX_SOURCE_BYTES} bytes while read")
            chunks.append(chunk)
        return b"".join(chunks)
    finally:
        os.close(fd)


def _digest(data: bytes) -> str:
    return "sha256:" + hashlib.sha256(data).hexdigest()


#: Files already run in this process: (absolute path, digest) -> module (a file is run once per
#: content, so that its functions, and their compilations, are shared by later loads).
_FILES: dict[tuple[str, str], types.ModuleType] = {}
#: The digests of the modules' sources when this process first loaded them (module form).
_MODULES: dict[str, str | None] = {}
_LOCK = threading.RLock()


def user_code_error(where: str, e: Exception, source: str | None = None) -> InputError:
    """An InputError naming `model` for an exception raised by the user's own code (its file, its
    function), with the line of that code (the last frame in the file `source` when given, else the
    last frame) that raised it."""
    import traceback

    frames = traceback.extract_tb(e.__traceback__)
    own = [f for f in frames if source is not None and f.filename == source] or frames
    at = f" (at {own[-1].filename}:{own[-1].lineno})" if own else ""
    return InputError(f"model: {safe(where)!r}: running it raised {type(e).__name__}: {safe(str(e))}{at}")


def _load_file(source: str) -> tuple[types.ModuleType, str, str]:
    path = Path(os.path.abspath(os.path.expanduser(source)))
    data = _read_trusted(path)
    digest = _digest(data)
    key = (str(path), digest)
    with _LOCK:  # a worker's threads load a file once
        module = _FILES.get(key)
        if module is None:
            try:
                code = compile(data, str(path), "exec", dont_inherit=True)
            except (SyntaxError, ValueError) as e:
                raise InputError(f"model: {safe(str(path))!r} is not valid Python: {safe(str(e))}") from None
            # named for the path and the content: two files of the same text are two modules
            name = "gnipy_user_" + hashlib.sha256(f"{path}\0{digest}".encode()).hexdigest()[:16]
            module = types.ModuleType(name, f"gnipy user system from {path}")
            module.__file__ = str(path)
            sys.modules[name] = module  # dataclasses and pickling look the module up by name
            try:
                exec(code, module.__dict__)  # noqa: S102 - the user's own file, checked above
            except Exception as e:
                sys.modules.pop(name, None)
                raise user_code_error(str(path), e, str(path)) from e
            except BaseException:
                sys.modules.pop(name, None)
                raise
            _FILES[key] = module
    return module, str(path), digest


def _load_module(source: str) -> tuple[types.ModuleType, str | None, str | None]:
    """Import `source` with Python's import system (as any installed code: gnipy checks nothing of
    it), and the SHA-256 of its source file as it was when this process first imported it."""
    with _LOCK:
        try:
            module = importlib.import_module(source)
        except ModuleNotFoundError as e:
            if e.name and source.startswith(e.name):
                raise InputError(f"model: no module {source!r} (a file needs its path, ending in .py)") from None
            raise user_code_error(source, e) from e
        except Exception as e:
            raise user_code_error(source, e) from e
        origin = getattr(module, "__file__", None)
        digest = None
        if origin is not None and origin.endswith(".py"):
            try:
                with open(origin, "rb") as f:
                    digest = _digest(f.read(MAX_SOURCE_BYTES + 1))
            except OSError:
                digest = None
        first = _MODULES.setdefault(source, digest)
        if first != digest:
            raise InputError(f"model: the source of module {source!r} changed since this process imported it "
                             f"({first} then, {digest} now); restart the process (a sweep: its cluster) to run "
                             "the new code")
    return module, origin, digest


def load(text: str) -> Loaded:
    """Load the reference `text` (`path/to/file.py:NAME` or `package.module:NAME`).

    Raises:
        InputError: a malformed reference, a file that is missing, not the user's or writable by
            others (refused before it runs), not valid Python, or without NAME.
    """
    source, name, is_file = split_reference(text)
    if is_file:
        module, origin, digest = _load_file(source)
        reference = f"{origin}:{name}"
    else:
        module, origin, digest = _load_module(source)
        reference = f"{source}:{name}"
    if not hasattr(module, name):
        public = sorted(k for k, v in vars(module).items() if callable(v) and not k.startswith("_"))
        raise InputError(f"model: {safe(origin or source)!r} has no {name!r} (its functions: "
                         f"{', '.join(public[:20]) or 'none'})")
    return Loaded(reference=reference, obj=getattr(module, name), digest=digest, source=origin)
