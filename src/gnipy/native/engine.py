"""The native backend's engine: LLVM IR compiled by llvmlite to object code for this CPU, kept in
an authenticated private cache on disk, and loaded into an MCJIT engine whose functions
:mod:`gnipy.native.program` and :mod:`gnipy.native.function` call through ctypes.

**Cache.** Compiled object code is kept in `$GNIPY_CACHE_DIR/native` (default
`~/.cache/gnipy/native`) and loaded by later processes instead of compiling again;
`GNIPY_NATIVE_CACHE=0` turns the disk cache off. Loading object code runs it, so the cache goes
through :mod:`gnipy.private_cache`, and what is trusted is exactly this: the folder, opened without
following a link, if it is a directory owned by the current user that its group and others cannot
write (a missing one is created with mode 0700); in it, the per-user secret `.key` (32 random
bytes, mode 0600, the user's); and an entry `<key>.o`, a regular file of the user with one link,
holding the object code then `HMAC-SHA256(secret, key + b"\\0" + object code)`. The key is the
SHA-256 of the program (its LLVM IR, the llvmlite version and the CPU's name and features), so an
entry loads only for the program it was compiled from, and only if this user's gnipy wrote it.
An entry that does not authenticate (damaged, truncated, another program's, planted, or written
by an older gnipy with the object code's SHA-256 at its end) is compiled again and replaced. A
folder that is refused (another user's, writable by others, a link, an unusable secret), or an
entry that is a link or not the user's, is not read: the program is compiled in memory, with
one :class:`~gnipy.private_folder.CacheWarning` per process and folder. Entries are written whole
(a temporary file `.<key>.o.gnipy-PID-HEX.tmp`, renamed); a failed write (a full disk, a
file-size limit) removes its temporary file and the run goes on with the compiled code.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import hashlib
import importlib
import os
import threading
import time
from pathlib import Path

from ..private_cache import open_private_cache

__all__ = ["available", "cores", "cache_dir", "llvm_binding", "target_machine", "compile_ir", "load_program"]

_LOCK = threading.Lock()
_ENGINES: dict = {}
_INIT = []


@functools.cache
def available() -> bool:
    """Whether llvmlite can be imported (the native backend's compiler)."""
    try:
        importlib.import_module("llvmlite.binding")
    except Exception:
        return False
    return True


def cores() -> int:
    """The cores this process may use (for batches)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def cache_dir() -> Path | None:
    """Where compiled object code is kept (None when `GNIPY_NATIVE_CACHE=0`)."""
    if os.environ.get("GNIPY_NATIVE_CACHE", "1").strip() in ("0", "false", "no", "off"):
        return None
    root = os.environ.get("GNIPY_CACHE_DIR")
    return (Path(root) if root else Path.home() / ".cache" / "gnipy") / "native"


def llvm_binding():
    """llvmlite's binding layer, with the native target initialized and libm loaded (once)."""
    import llvmlite.binding as llvm

    if not _INIT:
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        libm = ctypes.util.find_library("m")
        if libm:
            llvm.load_library_permanently(libm)
        _INIT.append(True)
    return llvm


def target_machine():
    """The target machine of this CPU (its name and features), at -O3."""
    llvm = llvm_binding()
    target = llvm.Target.from_default_triple()
    return target.create_target_machine(cpu=llvm.get_host_cpu_name(), features=llvm.get_host_cpu_features().flatten(),
                                        opt=3, reloc="default", codemodel="jitdefault")


_CACHE_TEXT = dict(
    what="native object code", instead="the program was compiled in memory",
    remedy="Set GNIPY_CACHE_DIR to a folder that only you can write (gnipy creates a missing one with mode "
           "0700; the cache is its 'native' folder), or GNIPY_NATIVE_CACHE=0 to keep no native code on disk.")


def _texts(ir) -> tuple[str, ...]:
    return (ir,) if isinstance(ir, str) else tuple(ir)


def compile_ir(ir) -> bytes:
    """The object code of `ir`: one module's LLVM IR, or several linked into the first (a
    :class:`~gnipy.native.module.Program`'s `texts`), optimized at -O3 for this CPU."""
    llvm = llvm_binding()
    texts = _texts(ir)
    module = llvm.parse_assembly(texts[0])
    for text in texts[1:]:
        module.link_in(llvm.parse_assembly(text))
    module.verify()
    tm = target_machine()
    pto = llvm.create_pipeline_tuning_options(speed_level=3)
    pb = llvm.create_pass_builder(tm, pto)
    if len(texts) > 1:
        # the bodies inlined where they are called, and dropped, before anything is optimized: -O3
        # then sees each exported function as if its body had been written in place (the same
        # optimized code; inlined by -O3's own inliner, a body would be optimized on its own first)
        inline = llvm.create_new_module_pass_manager()
        inline.add_always_inliner_pass()
        inline.add_global_dead_code_eliminate_pass()
        inline.run(module, pb)
        # LLVM's linker does not compare a declaration with the definition it links: a call that
        # does not match its body's signature is left as a call (undefined behaviour), so refuse it
        left = [f.name for f in module.functions if not f.is_declaration and f.linkage == llvm.Linkage.linkonce_odr]
        if left:
            raise RuntimeError(f"native program: {', '.join(left)} not inlined (a call that does not match the "
                               "body's signature)")
    pb.getModulePassManager().run(module, pb)
    return tm.emit_object(module)


def _object_code(ir, key: str) -> tuple[bytes, str]:
    """The object code of `ir` and where it came from ("disk" or "compiled"). Only an entry of a
    private cache folder authenticated for `key` is loaded (see the module docstring); anything
    else is compiled again, and the entry written (when the folder is usable)."""
    folder = cache_dir()
    cache = open_private_cache(folder, **_CACHE_TEXT) if folder is not None else None
    name = f"{key}.o"
    try:
        if cache is not None:
            obj = cache.read(name, key)
            if obj is not None:
                return obj, "disk"
        obj = compile_ir(ir)
        if cache is not None:
            cache.write(name, key, obj)  # False when it cannot be written: the code in memory serves
        return obj, "compiled"
    finally:
        if cache is not None:
            cache.close()


def load_program(ir):
    """`(engine, source, seconds)`: the program of `ir` (one module's LLVM IR, or the texts of a
    :class:`~gnipy.native.module.Program`) compiled and loaded: an llvmlite MCJIT engine whose
    functions are the program's exported ones, where its object code came from ("memory": built
    before in this process; "disk": the cache, see the module docstring; "compiled"), and the
    seconds that took."""
    import llvmlite

    llvm = llvm_binding()
    key = hashlib.sha256("\n".join([*_texts(ir), llvmlite.__version__, llvm.get_host_cpu_name(),
                                    llvm.get_host_cpu_features().flatten()]).encode()).hexdigest()
    with _LOCK:
        hit = _ENGINES.get(key)
        if hit is not None:
            return hit[0], "memory", 0.0
        t0 = time.perf_counter()
        obj, source = _object_code(ir, key)
        engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), target_machine())
        engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
        engine.finalize_object()
        _ENGINES[key] = (engine,)
        return engine, source, time.perf_counter() - t0
