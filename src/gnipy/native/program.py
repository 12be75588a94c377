"""The native step loop: one method's step (its jaxpr, lowered by :mod:`gnipy.native.lowering`)
inside the loop of :func:`gnipy.stepping.run_nodes`, compiled by LLVM (llvmlite) to machine code
for this CPU, kept on disk, and run over one trajectory or a batch split across the CPU's cores.

The compiled loop does what `run_nodes` does between saved nodes: the steps with their failure
bookkeeping (the first failed step and its residual; the state stays at the last good step), and
after each block of steps the state, written to a buffer. The observation of the saved states
(velocities, momenta, energy, constraint residuals) and a shortened last step run on XLA
(:func:`gnipy.stepping.finish_native`). Once a step has failed the loop skips to the end of its
block: the state no longer changes, so the result is that of the XLA loop.

**Cache.** Compiled object code is kept in `$GNIPY_CACHE_DIR/native` (default
`~/.cache/gnipy/native`) and loaded by later processes instead of compiling again;
`GNIPY_NATIVE_CACHE=0` turns the disk cache off. Loading object code runs it, so the cache goes
through :mod:`gnipy.private_cache`, and what is trusted is exactly this: the folder, opened without
following a link, if it is a directory owned by the current user that its group and others cannot
write (a missing one is created with mode 0700); in it, the per-user secret `.key` (32 random
bytes, mode 0600, the user's); and an entry `<key>.o`, a regular file of the user with one link,
holding the object code then `HMAC-SHA256(secret, key + b"\0" + object code)`. The key is the
SHA-256 of the program (its LLVM IR, the llvmlite version and the CPU's name and features), so an
entry loads only for the program it was compiled from, and only if this user's gnipy wrote it.
An entry that does not authenticate (damaged, truncated, another program's, planted, or written
by an older gnipy with the object code's SHA-256 at its end) is compiled again and replaced. A
folder that is refused (another user's, writable by others, a link, an unusable secret), or an
entry that is a link or not the user's, is not read: the program is compiled in memory, with
one :class:`~gnipy.private_cache.CacheWarning` per process and folder. Entries are written whole
(a temporary file `.<key>.o.gnipy-PID-HEX.tmp`, renamed); a failed write (a full disk, a
file-size limit) removes its temporary file and the run goes on with the compiled code.

Batches run the members in chunks, one per core (threads: the compiled code runs without the
GIL), and within a chunk several members at a time in vector lanes (`gnipy_run_lanes`, built with
:class:`~gnipy.native.lowering.Function`'s `lanes`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import hashlib
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..private_cache import open_private_cache
from .control import _flatten, _unflatten
from .lowering import lower_jaxpr
from .scalars import Function, Reg, Unsupported, _const_array, llvm_type

__all__ = ["NativeLoop", "build_loop", "cache_dir", "available", "cores"]

_LOCK = threading.Lock()
_ENGINES: dict = {}
_INIT = []


@functools.cache
def available() -> bool:
    """Whether llvmlite can be imported (the native backend's compiler)."""
    try:
        import llvmlite.binding  # noqa: F401
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


def _llvm():
    import llvmlite.binding as llvm

    if not _INIT:
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        libm = ctypes.util.find_library("m")
        if libm:
            llvm.load_library_permanently(libm)
        _INIT.append(True)
    return llvm


def _target_machine():
    llvm = _llvm()
    target = llvm.Target.from_default_triple()
    return target.create_target_machine(cpu=llvm.get_host_cpu_name(), features=llvm.get_host_cpu_features().flatten(),
                                        opt=3, reloc="default", codemodel="jitdefault")


_CACHE_TEXT = dict(
    what="native object code", instead="the program was compiled in memory",
    remedy="Set GNIPY_CACHE_DIR to a folder that only you can write (gnipy creates a missing one with mode "
           "0700; the cache is its 'native' folder), or GNIPY_NATIVE_CACHE=0 to keep no native code on disk.")


def _compile(ir: str) -> bytes:
    llvm = _llvm()
    module = llvm.parse_assembly(ir)
    module.verify()
    tm = _target_machine()
    pto = llvm.create_pipeline_tuning_options(speed_level=3)
    pb = llvm.create_pass_builder(tm, pto)
    pb.getModulePassManager().run(module, pb)
    return tm.emit_object(module)


def _object_code(ir: str, key: str) -> tuple[bytes, str]:
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
        obj = _compile(ir)
        if cache is not None:
            cache.write(name, key, obj)  # False when it cannot be written: the code in memory serves
        return obj, "compiled"
    finally:
        if cache is not None:
            cache.close()


def _load(ir: str):
    """`(engine, source, seconds)`: the program of `ir`, from memory, disk or LLVM."""
    import llvmlite

    llvm = _llvm()
    key = hashlib.sha256("\n".join([ir, llvmlite.__version__, llvm.get_host_cpu_name(),
                                    llvm.get_host_cpu_features().flatten()]).encode()).hexdigest()
    with _LOCK:
        hit = _ENGINES.get(key)
        if hit is not None:
            return hit[0], "memory", 0.0
        t0 = time.perf_counter()
        obj, source = _object_code(ir, key)
        engine = llvm.create_mcjit_compiler(llvm.parse_assembly(""), _target_machine())
        engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
        engine.finalize_object()
        _ENGINES[key] = (engine,)
        return engine, source, time.perf_counter() - t0


_SINGLE = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p)
_BATCH = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_int64, ctypes.c_void_p,
                          ctypes.c_int64, ctypes.c_int64)


class NativeLoop:
    """A compiled step loop. `run(carry, h, blocks)` → `(carry, saved)`: `carry` the flat carry of
    :func:`gnipy.stepping.run_nodes` as float64 (the state's scalars first, then the step index,
    first failed step, its residual, total and largest iterations), `(B, M)` for a batch; `saved`
    the state after each block, `(blocks, S)` or `(B, blocks, S)`."""

    def __init__(self, engine, n_carry: int, n_state: int, source: str, seconds: float, lines: int,
                 timings: dict | None = None):
        self._engine = engine
        self.n_carry, self.n_state = n_carry, n_state
        #: where the program came from ("compiled", "disk", "memory"), the seconds that took, the
        #: lines of LLVM IR, and the seconds of each stage of the build (trace, lower, load)
        self.source, self.seconds, self.lines = source, seconds, lines
        self.timings = timings or {}
        self._single = _SINGLE(engine.get_function_address("gnipy_run"))
        self._batch = _BATCH(engine.get_function_address("gnipy_run_batch"))

    def run(self, carry: np.ndarray, h: float, blocks) -> tuple[np.ndarray, np.ndarray]:
        carry = np.array(carry, dtype=np.float64, order="C")
        lengths = np.ascontiguousarray(blocks, dtype=np.int32)
        nb = lengths.shape[0]
        if carry.ndim == 1:
            saved = np.empty((nb, self.n_state), dtype=np.float64)
            self._single(carry.ctypes.data, float(h), lengths.ctypes.data, nb, saved.ctypes.data)
            return carry, saved
        B = carry.shape[0]
        saved = np.empty((B, nb, self.n_state), dtype=np.float64)
        args = (carry.ctypes.data, float(h), lengths.ctypes.data, nb, saved.ctypes.data)
        workers = min(cores(), B)
        if workers <= 1:
            self._batch(*args, 0, B)
        else:  # ctypes releases the GIL during the call: the chunks run on every core
            edges = np.linspace(0, B, workers + 1).astype(np.int64)
            with ThreadPoolExecutor(workers) as pool:
                list(pool.map(lambda j: self._batch(*args, int(edges[j]), int(edges[j + 1])), range(workers)))
        return carry, saved


def _loop_heads(fn: Function) -> None:
    """The two loops of a driver, up to the step's block `sbody`: over the blocks (`%b` of
    `%nblocks`, each `%len` steps from `%lengths`; after a block, `bsave`) and over a block's
    steps (`%i`; the next step from `slatch`); `done` after the last block."""
    fn.br("bhead")
    fn.start("bhead")
    fn.emit("%b = phi i64 [ 0, %entry ], [ %bnext, %bsave ]")
    fn.emit("%bc = icmp slt i64 %b, %nblocks")
    fn.emit("br i1 %bc, label %bbody, label %done")
    fn.start("bbody")
    fn.emit("%lp = getelementptr i32, ptr %lengths, i64 %b")
    fn.emit("%len32 = load i32, ptr %lp")
    fn.emit("%len = sext i32 %len32 to i64")
    fn.br("shead")
    fn.start("shead")
    fn.emit("%i = phi i64 [ 0, %bbody ], [ %inext, %slatch ]")
    fn.emit("%sc = icmp slt i64 %i, %len")
    fn.emit("br i1 %sc, label %sbody, label %bsave")
    fn.start("sbody")


def _driver(fn: Function, n_carry_types: list[str], n_state: int, emit_step, k_index: int, fail_index: int) -> str:
    """The LLVM IR of `gnipy_run` (one trajectory) and `gnipy_run_batch` around the step."""
    slots = [fn.alloca(ty) for ty in n_carry_types]
    # entry: the carry from io
    for j, (slot, ty) in enumerate(zip(slots, n_carry_types)):
        p = fn.op("ptr", f"getelementptr double, ptr %io, i64 {j}")
        v = fn.op("double", f"load double, ptr {p.text}")
        fn.emit(f"store {ty} {fn.cast(v, ty).text}, ptr {slot}")
    _loop_heads(fn)
    carry = [fn.op(ty, f"load {ty}, ptr {slot}") for slot, ty in zip(slots, n_carry_types)]
    new = emit_step(carry, Reg("%h", "double"))
    for slot, ty, v in zip(slots, n_carry_types, new):
        fn.emit(f"store {ty} {fn.cast(v, ty).text}, ptr {slot}")
    fn.br("slatch")
    fn.start("slatch")
    fn.emit("%inext = add i64 %i, 1")
    fk_ty = n_carry_types[fail_index]
    fn.emit(f"%fk = load {fk_ty}, ptr {slots[fail_index]}")
    fn.emit(f"%failed = icmp sge {fk_ty} %fk, 0")
    fn.emit("br i1 %failed, label %sskip, label %shead")
    fn.start("sskip")  # failed: the state stays; only the step index moves on to the block's end
    k_ty = n_carry_types[k_index]
    fn.emit("%rest = sub i64 %len, %inext")
    fn.emit(f"%rest_k = trunc i64 %rest to {k_ty}" if k_ty != "i64" else "%rest_k = add i64 %rest, 0")
    fn.emit(f"%k_old = load {k_ty}, ptr {slots[k_index]}")
    fn.emit(f"%k_new = add {k_ty} %k_old, %rest_k")
    fn.emit(f"store {k_ty} %k_new, ptr {slots[k_index]}")
    fn.br("bsave")
    fn.start("bsave")
    fn.emit(f"%row = mul i64 %b, {n_state}")
    for j in range(n_state):
        ty = n_carry_types[j]
        v = fn.op(ty, f"load {ty}, ptr {slots[j]}")
        d = fn.cast(v, "double")
        idx = fn.op("i64", f"add i64 %row, {j}")
        p = fn.op("ptr", f"getelementptr double, ptr %saved, i64 {idx.text}")
        fn.emit(f"store double {d.text}, ptr {p.text}")
    fn.emit("%bnext = add i64 %b, 1")
    fn.br("bhead")
    fn.start("done")
    for j, (slot, ty) in enumerate(zip(slots, n_carry_types)):
        v = fn.op(ty, f"load {ty}, ptr {slot}")
        p = fn.op("ptr", f"getelementptr double, ptr %io, i64 {j}")
        fn.emit(f"store double {fn.cast(v, 'double').text}, ptr {p.text}")
    fn.emit("ret void")
    return _define(fn, "gnipy_run")


def _define(fn: Function, name: str) -> str:
    return (f"define void @{name}(ptr noalias %io, double %h, ptr noalias %lengths, i64 %nblocks, "
            f"ptr noalias %saved) {{\nentry:\n" + "\n".join(fn.allocas) + "\n" + "\n".join(fn.lines) + "\n}\n")


def _lanes_driver(fn: Function, types: list[str], n_state: int, emit_step) -> str:
    """`gnipy_run_lanes`: `fn.lanes` consecutive trajectories at once, one per vector lane (no early
    exit after a failure: a failed lane keeps its state through the step's own bookkeeping)."""
    W, M = fn.lanes, len(types)
    slots = [fn.alloca(fn.T(ty)) for ty in types]

    def gather(base_index):  # <W x double> of io[l*M + i] over the lanes
        acc = "poison"
        for lane in range(W):
            p = fn.op("ptr", f"getelementptr double, ptr %io, i64 {lane * M + base_index}")
            x = fn.fresh()
            fn.emit(f"{x} = load double, ptr {p.text}")
            nxt = fn.fresh()
            fn.emit(f"{nxt} = insertelement {fn.T('double')} {acc}, double {x}, i32 {lane}")
            acc = nxt
        return Reg(acc, "double")

    for i, (slot, ty) in enumerate(zip(slots, types)):
        fn.emit(f"store {fn.T(ty)} {fn.V(fn.cast(gather(i), ty))}, ptr {slot}")
    hv = "poison"
    for lane in range(W):
        nxt = fn.fresh()
        fn.emit(f"{nxt} = insertelement {fn.T('double')} {hv}, double %h, i32 {lane}")
        hv = nxt
    h_reg = Reg(hv, "double")
    fn.emit(f"%rowlen = mul i64 %nblocks, {n_state}")
    _loop_heads(fn)
    carry = [fn.op(ty, f"load {fn.T(ty)}, ptr {slot}") for slot, ty in zip(slots, types)]
    new = emit_step(carry, h_reg)
    for slot, ty, v in zip(slots, types, new):
        fn.emit(f"store {fn.T(ty)} {fn.V(fn.cast(v, ty))}, ptr {slot}")
    fn.br("slatch")
    fn.start("slatch")
    fn.emit("%inext = add i64 %i, 1")
    fn.br("shead")
    fn.start("bsave")
    fn.emit(f"%row = mul i64 %b, {n_state}")

    def scatter(value, offset_text):  # lane l to base[l*stride + offset]
        for lane in range(W):
            e = fn.fresh()
            fn.emit(f"{e} = extractelement {fn.T('double')} {value.text}, i32 {lane}")
            p = fn.op("ptr", offset_text(lane))
            fn.emit(f"store double {e}, ptr {p.text}")

    for j in range(n_state):
        v = fn.op(types[j], f"load {fn.T(types[j])}, ptr {slots[j]}")
        d = fn.cast(v, "double")
        for lane in range(W):
            e = fn.fresh()
            fn.emit(f"{e} = extractelement {fn.T('double')} {fn.V(d)}, i32 {lane}")
            a = fn.fresh()
            fn.emit(f"{a} = mul i64 %rowlen, {lane}")
            b = fn.fresh()
            fn.emit(f"{b} = add i64 {a}, %row")
            c = fn.fresh()
            fn.emit(f"{c} = add i64 {b}, {j}")
            p = fn.op("ptr", f"getelementptr double, ptr %saved, i64 {c}")
            fn.emit(f"store double {e}, ptr {p.text}")
    fn.emit("%bnext = add i64 %b, 1")
    fn.br("bhead")
    fn.start("done")
    for i, (slot, ty) in enumerate(zip(slots, types)):
        v = fn.op(ty, f"load {fn.T(ty)}, ptr {slot}")
        d = fn.cast(v, "double")
        scatter(Reg(fn.V(d), "double"), lambda lane, i=i: f"getelementptr double, ptr %io, i64 {lane * M + i}")
    fn.emit("ret void")
    return _define(fn, "gnipy_run_lanes")


def _batch_function(M: int, n_state: int, lanes: int) -> str:
    """`gnipy_run_batch(.., lo, hi)`: trajectories lo..hi-1, `lanes` at a time while they last."""
    vector = ""
    if lanes > 1:
        vector = f"""  %left = sub i64 %hi, %j
  %wide = icmp sge i64 %left, {lanes}
  br i1 %wide, label %vec, label %one
vec:
  %voff = mul i64 %j, {M}
  %vio = getelementptr double, ptr %io, i64 %voff
  %vrows = mul i64 %j, %nblocks
  %vsoff = mul i64 %vrows, {n_state}
  %vs = getelementptr double, ptr %saved, i64 %vsoff
  call void @gnipy_run_lanes(ptr %vio, double %h, ptr %lengths, i64 %nblocks, ptr %vs)
  %jv = add i64 %j, {lanes}
  br label %head
one:
"""
    incoming = "[ %jnext, %one ]" + (", [ %jv, %vec ]" if lanes > 1 else "")
    return f"""define void @gnipy_run_batch(ptr %io, double %h, ptr %lengths, i64 %nblocks, ptr %saved, i64 %lo, i64 %hi) {{
entry:
  br label %head
head:
  %j = phi i64 [ %lo, %entry ], {incoming}
  %more = icmp slt i64 %j, %hi
  br i1 %more, label %body, label %out
body:
{vector}{"" if lanes > 1 else "  br label %one" + chr(10) + "one:" + chr(10)}  %off = mul i64 %j, {M}
  %pio = getelementptr double, ptr %io, i64 %off
  %rows = mul i64 %j, %nblocks
  %soff = mul i64 %rows, {n_state}
  %ps = getelementptr double, ptr %saved, i64 %soff
  call void @gnipy_run(ptr %pio, double %h, ptr %lengths, i64 %nblocks, ptr %ps)
  %jnext = add i64 %j, 1
  br label %head
out:
  ret void
}}
"""


def default_lanes() -> int:
    """Trajectories per vector in batches: 8 with AVX-512, 4 with AVX (doubles), else 2."""
    feats = _llvm().get_host_cpu_features()
    if feats.get("avx512f"):
        return 8
    return 4 if feats.get("avx") else 2


def build_loop(step, carry0, h, lanes: int = 1, params=None) -> NativeLoop:
    """Trace `step(carry, h) -> carry` at the example `carry0` (a pytree whose leaves are the
    state's arrays then the loop's counters, as :func:`gnipy.stepping._carry0` builds it), lower it
    and compile the loop; with `lanes` > 1 also a version that runs that many trajectories at once
    in vector lanes (for batches). Raises :class:`~gnipy.native.lowering.Unsupported` when it
    cannot.

    With `params` (a list of arrays: an example of the values), the step is `step(carry, h,
    params)` and the values are inputs of the program instead of constants in it: each trajectory's
    row of the carry holds them after the counters (:class:`NativeLoop`'s `n_carry` counts them),
    and the loop passes them on unchanged. One program then serves every value (a batch of
    parameter values)."""
    import jax

    t0 = time.perf_counter()
    n_state_leaves = len(jax.tree_util.tree_leaves(carry0[0]))  # the state; then counters (and a monitor)
    if params is not None:
        inner, params = step, tuple(params)
        carry0 = (carry0, params)

        def step(c, hh):
            return inner(c[0], hh, c[1]), c[1]
    leaves, treedef = jax.tree_util.tree_flatten(carry0)
    closed = jax.make_jaxpr(lambda ls, hh: jax.tree_util.tree_leaves(step(jax.tree_util.tree_unflatten(treedef, ls), hh)))(
        leaves, h)
    jaxpr = closed.jaxpr
    try:  # drop what the outputs do not need (e.g. the transposed solves of custom_linear_solve)
        from jax._src.interpreters import partial_eval as pe

        jaxpr, _ = pe.dce_jaxpr(jaxpr, [True] * len(jaxpr.outvars))
        consts = [dict(zip(closed.jaxpr.constvars, closed.consts))[v] for v in jaxpr.constvars]
    except Exception:
        jaxpr, consts = closed.jaxpr, closed.consts
    shapes = [np.shape(x) for x in leaves]
    types = [llvm_type(np.asarray(x).dtype) if not hasattr(x, "dtype") else llvm_type(x.dtype) for x in leaves]
    n_state = int(sum(int(np.prod(s, dtype=np.int64)) for s in shapes[:n_state_leaves]))
    flat_types = [ty for s, ty in zip(shapes, types) for _ in range(int(np.prod(s, dtype=np.int64)))]
    const_arrays = [_const_array(np.asarray(c)) for c in consts]

    def emitter(fn):
        def emit_step(flat, h_reg):
            args = _unflatten(flat, shapes)
            hh = np.empty((), dtype=object)
            hh[()] = h_reg
            outs = lower_jaxpr(fn, jaxpr, const_arrays, args + [hh])
            out_flat, _ = _flatten(outs)
            return out_flat
        return emit_step

    for i, (ty, x) in enumerate(zip(types, leaves)):
        if ty not in ("double", "i32", "i64"):
            what = "a parameter of the system" if params is not None and i >= len(leaves) - len(params) else "the state"
            raise Unsupported(f"{what} has a leaf of dtype {np.asarray(x).dtype} (the loop carries float64, "
                              "int32 and int64)")
    t1 = time.perf_counter()
    fn = Function()
    parts = [_driver(fn, flat_types, n_state, emitter(fn), k_index=n_state, fail_index=n_state + 1)]
    decls = set(fn.decls)
    if lanes > 1:
        fv = Function(lanes)
        parts.append(_lanes_driver(fv, flat_types, n_state, emitter(fv)))
        decls |= fv.decls
    parts.append(_batch_function(len(flat_types), n_state, lanes))
    ir = "; gnipy native step loop\n" + "\n".join(sorted(decls)) + "\n\n" + "\n".join(parts)
    t2 = time.perf_counter()
    engine, source, seconds = _load(ir)
    timings = {"trace_s": t1 - t0, "lower_s": t2 - t1, "load_s": time.perf_counter() - t2}
    loop = NativeLoop(engine, len(flat_types), n_state, source, seconds, ir.count("\n"), timings)
    loop.lanes = lanes
    return loop
