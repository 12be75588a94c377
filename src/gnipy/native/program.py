"""The native step loop: one method's step (its jaxpr, lowered by :mod:`gnipy.native.lowering`)
inside the loop of :func:`gnipy.stepping.run_nodes`, compiled by LLVM (llvmlite) to machine code
for this CPU, kept on disk, and run over one trajectory or a batch split across the CPU's cores.

The compiled loop does what `run_nodes` does between saved nodes: the steps with their failure
bookkeeping (the first failed step and its residual; the state stays at the last good step), and
after each block of steps the state, written to a buffer. The observation of the saved states
(velocities, momenta, energy, constraint residuals) and a shortened last step run on XLA
(:func:`gnipy.stepping.finish_native`). Once a step has failed the loop skips to the end of its
block: the state no longer changes, so the result is that of the XLA loop.

**Cache.** Compiled object code is kept on disk, authenticated, by :mod:`gnipy.native.engine`.

Batches run the members in chunks, one per core (threads: the compiled code runs without the
GIL), and within a chunk several members at a time in vector lanes (`gnipy_run_lanes`, built with
:class:`~gnipy.native.lowering.Function`'s `lanes`).

**The program** (:class:`~gnipy.native.module.Program`): the step, lowered into a body function
`gnipy_step` (`gnipy_step_lanes` on vectors) that takes the carry's scalars and `h` and returns
the new carry, and around it the exported functions, built with llvmlite's IR builder:
`gnipy_run(io, h, lengths, nblocks, saved)` (one trajectory: `io` its carry, `lengths` the steps
of each of the `nblocks` blocks, `saved` the state after each block), `gnipy_run_lanes` (the same
for consecutive trajectories, one per lane) and `gnipy_run_batch(.., lo, hi)` (trajectories lo..hi-1
of a batch). Before -O3, LLVM's always-inliner puts the step in place: the machine code is what
the same loop written as one function gives (for the benchmarked models byte for byte).
"""

from __future__ import annotations

import ctypes
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .engine import cores, llvm_binding, load_program
from .lowering import lower_jaxpr
from .module import Program, convert, ir_type
from .scalars import Function, Unsupported, const_array, flatten, llvm_type, unflatten

__all__ = ["NativeLoop", "build_loop", "trace_step", "default_lanes"]

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
        if carry.ndim not in (1, 2) or carry.shape[-1] != self.n_carry or lengths.ndim != 1:
            # the compiled code reads and writes n_carry values per trajectory: anything else would
            # run past the ends of the buffers
            raise ValueError(f"NativeLoop.run: expected a carry (n_carry,) or (B, n_carry) with n_carry = "
                             f"{self.n_carry} and blocks (nblocks,), got {carry.shape} and {lengths.shape}")
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


#: The arguments of `gnipy_run` and `gnipy_run_lanes`: (name, type, noalias).
_RUN_ARGS = [("io", "ptr", True), ("h", "double", False), ("lengths", "ptr", True), ("nblocks", "i64", False),
             ("saved", "ptr", True)]


def _i64(n: int):
    return ir_type("i64")(int(n))


def _at(b, base, index, ty: str = "double"):
    """The address of element `index` (an int or an i64 value) of `base`, an array of `ty`."""
    return b.gep(base, [_i64(index) if isinstance(index, int) else index], source_etype=ir_type(ty))


class _Loops:
    """The two loops of a driver, the builder `b` left in the step's block `sbody`: over the
    blocks (`block` of `nblocks`, each `length` steps from `lengths`; after a block, `bsave`)
    and over a block's steps (`step`; the next step from `slatch`); `done` after the last block.
    The blocks are laid out in that order (`sskip` after `slatch`)."""

    def __init__(self, f, b, lengths, nblocks, skip: bool):
        from llvmlite import ir

        names = ("bhead", "bbody", "shead", "sbody", "slatch") + (("sskip",) if skip else ()) + ("bsave", "done")
        blocks = {n: f.append_basic_block(n) for n in names}
        self.bhead, self.bbody, self.shead, self.sbody, self.slatch, self.bsave, self.done = (
            blocks[n] for n in ("bhead", "bbody", "shead", "sbody", "slatch", "bsave", "done"))
        #: with `skip`: where a failed step goes (the rest of its block is skipped)
        self.sskip = blocks.get("sskip")
        pre = b.block
        b.branch(self.bhead)
        b.position_at_end(self.bhead)
        self.block = b.phi(ir.IntType(64), "b")
        self.block.add_incoming(_i64(0), pre)
        b.cbranch(b.icmp_signed("<", self.block, nblocks), self.bbody, self.done)
        b.position_at_end(self.bbody)
        n = b.load(_at(b, lengths, self.block, "i32"), typ=ir_type("i32"))
        self.length = b.sext(n, ir.IntType(64), "len")
        b.branch(self.shead)
        b.position_at_end(self.shead)
        self.step = b.phi(ir.IntType(64), "i")
        self.step.add_incoming(_i64(0), self.bbody)
        b.cbranch(b.icmp_signed("<", self.step, self.length), self.sbody, self.bsave)
        b.position_at_end(self.sbody)

    def latch(self, b):
        """End the step's block; the builder in `slatch`: returns the next step's index."""
        b.branch(self.slatch)
        b.position_at_end(self.slatch)
        following = b.add(self.step, _i64(1), "inext")
        self.step.add_incoming(following, self.slatch)
        return following

    def next_block(self, b):
        """End the block's save (`bsave`): on to the next block; the builder in `done`."""
        self.block.add_incoming(b.add(self.block, _i64(1), "bnext"), b.block)
        b.branch(self.bhead)
        b.position_at_end(self.done)


def _run_function(prog: Program, step, types: list[str], n_state: int, k_index: int, fail_index: int):
    """`gnipy_run` (one trajectory): the carry from `io` into one slot per scalar, then the blocks
    of steps (each a call of `step`, the lowered step); after a failed step the loop skips to its
    block's end, only the step index moving on; after each block the state goes to `saved`; at
    the end the carry goes back to `io`."""
    f, b = prog.function("gnipy_run", _RUN_ARGS)
    io, h, lengths, nblocks, saved = f.args
    slots = [b.alloca(ir_type(ty)) for ty in types]
    for j, (slot, ty) in enumerate(zip(slots, types)):
        b.store(convert(b, b.load(_at(b, io, j), typ=ir_type("double")), "double", ty), slot)
    loops = _Loops(f, b, lengths, nblocks, skip=True)
    new = b.call(step, [b.load(slot, typ=ir_type(ty)) for slot, ty in zip(slots, types)] + [h])
    for j, slot in enumerate(slots):
        b.store(b.extract_value(new, j), slot)
    following = loops.latch(b)
    fk = b.load(slots[fail_index], typ=ir_type(types[fail_index]), name="fk")
    failed = b.icmp_signed(">=", fk, ir_type(types[fail_index])(0), "failed")
    b.cbranch(failed, loops.sskip, loops.shead)
    b.position_at_end(loops.sskip)  # failed: the state stays; only the step index moves on to the block's end
    k_ty = ir_type(types[k_index])
    rest = b.sub(loops.length, following, "rest")
    if types[k_index] != "i64":
        rest = b.trunc(rest, k_ty, "rest_k")
    b.store(b.add(b.load(slots[k_index], typ=k_ty, name="k_old"), rest, "k_new"), slots[k_index])
    b.branch(loops.bsave)
    b.position_at_end(loops.bsave)
    row = b.mul(loops.block, _i64(n_state), "row")
    for j in range(n_state):
        v = convert(b, b.load(slots[j], typ=ir_type(types[j])), types[j], "double")
        b.store(v, _at(b, saved, b.add(row, _i64(j))))
    loops.next_block(b)
    for j, (slot, ty) in enumerate(zip(slots, types)):
        b.store(convert(b, b.load(slot, typ=ir_type(ty)), ty, "double"), _at(b, io, j))
    b.ret_void()
    return f


def _lanes_function(prog: Program, step, types: list[str], n_state: int, lanes: int):
    """`gnipy_run_lanes`: `lanes` consecutive trajectories at once, one per vector lane (no early
    exit after a failure: a failed lane keeps its state through the step's own bookkeeping)."""
    from llvmlite import ir

    W, M = lanes, len(types)
    f, b = prog.function("gnipy_run_lanes", _RUN_ARGS)
    io, h, lengths, nblocks, saved = f.args
    lane = [ir.IntType(32)(j) for j in range(W)]
    vector = ir_type("double", W)

    def gather(value_of):  # <W x double> of value_of(lane) over the lanes
        acc = ir.Constant(vector, ir.Undefined)
        for j in range(W):
            acc = b.insert_element(acc, value_of(j), lane[j])
        return acc

    slots = [b.alloca(ir_type(ty, W)) for ty in types]
    for i, (slot, ty) in enumerate(zip(slots, types)):
        v = gather(lambda j, i=i: b.load(_at(b, io, j * M + i), typ=ir_type("double")))
        b.store(convert(b, v, "double", ty, W), slot)
    h_lanes = gather(lambda j: h)
    rowlen = b.mul(nblocks, _i64(n_state), "rowlen")
    loops = _Loops(f, b, lengths, nblocks, skip=False)
    new = b.call(step, [b.load(slot, typ=ir_type(ty, W)) for slot, ty in zip(slots, types)] + [h_lanes])
    for j, slot in enumerate(slots):
        b.store(b.extract_value(new, j), slot)
    loops.latch(b)
    b.branch(loops.shead)
    b.position_at_end(loops.bsave)
    row = b.mul(loops.block, _i64(n_state), "row")
    for j in range(n_state):
        d = convert(b, b.load(slots[j], typ=ir_type(types[j], W)), types[j], "double", W)
        for k in range(W):  # lane k's state to saved[k*nblocks*n_state + row + j]
            e = b.extract_element(d, lane[k])
            b.store(e, _at(b, saved, b.add(b.add(b.mul(rowlen, _i64(k)), row), _i64(j))))
    loops.next_block(b)
    for i, (slot, ty) in enumerate(zip(slots, types)):
        d = convert(b, b.load(slot, typ=ir_type(ty, W)), ty, "double", W)
        for k in range(W):
            b.store(b.extract_element(d, lane[k]), _at(b, io, k * M + i))
    b.ret_void()
    return f


def _batch_function(prog: Program, run, run_lanes, M: int, n_state: int, lanes: int) -> None:
    """`gnipy_run_batch(.., lo, hi)`: trajectories lo..hi-1, `lanes` at a time (`run_lanes`)
    while they last, then one at a time (`run`)."""
    from llvmlite import ir

    f, b = prog.function("gnipy_run_batch", [(name, ty, False) for name, ty, _ in _RUN_ARGS]
                         + [("lo", "i64", False), ("hi", "i64", False)])
    io, h, lengths, nblocks, saved, lo, hi = f.args
    names = ("head", "body") + (("vec",) if lanes > 1 else ()) + ("one", "out")
    blocks = {n: f.append_basic_block(n) for n in names}
    head, body, one, out = (blocks[n] for n in ("head", "body", "one", "out"))
    entry = b.block
    b.branch(head)
    b.position_at_end(head)
    j = b.phi(ir.IntType(64), "j")
    j.add_incoming(lo, entry)
    b.cbranch(b.icmp_signed("<", j, hi), body, out)

    def call(fn, width):  # run trajectories j.. (width of them) and go on from the next j
        pio = b.gep(io, [b.mul(j, _i64(M))], source_etype=ir_type("double"))
        ps = b.gep(saved, [b.mul(b.mul(j, nblocks), _i64(n_state))], source_etype=ir_type("double"))
        b.call(fn, [pio, h, lengths, nblocks, ps])
        j.add_incoming(b.add(j, _i64(width)), b.block)
        b.branch(head)

    b.position_at_end(body)
    if lanes > 1:
        b.cbranch(b.icmp_signed(">=", b.sub(hi, j), _i64(lanes)), blocks["vec"], one)
    else:
        b.branch(one)
    b.position_at_end(one)
    call(run, 1)
    if lanes > 1:
        b.position_at_end(blocks["vec"])
        call(run_lanes, lanes)
    b.position_at_end(out)
    b.ret_void()


def default_lanes() -> int:
    """Trajectories per vector in batches: 8 with AVX-512, 4 with AVX (doubles), else 2."""
    feats = llvm_binding().get_host_cpu_features()
    if feats.get("avx512f"):
        return 8
    return 4 if feats.get("avx") else 2


def trace_step(step, carry0, h, params=None):
    """`(jaxpr, consts, leaves)`: the step that :func:`build_loop` lowers, traced (no
    compilation): the `Jaxpr` of `step(carry, h)` (with `params`, `step(carry, h, params)`) on the
    flat leaves of the carry (then of the params) and `h`, returning the new carry's leaves, with
    what its outputs do not need dropped; its constants; and the example's leaves (arrays or
    `jax.ShapeDtypeStruct`: only shapes and dtypes are used)."""
    import jax

    if params is not None:
        inner, params = step, tuple(params)
        carry0 = (carry0, params)

        def step(c, hh):
            return inner(c[0], hh, c[1]), c[1]
    leaves, treedef = jax.tree_util.tree_flatten(carry0)
    closed = jax.make_jaxpr(lambda ls, hh: jax.tree_util.tree_leaves(step(jax.tree_util.tree_unflatten(treedef, ls), hh)))(
        leaves, h)
    try:  # drop what the outputs do not need (e.g. the transposed solves of custom_linear_solve)
        from jax._src.interpreters import partial_eval as pe

        jaxpr, _ = pe.dce_jaxpr(closed.jaxpr, [True] * len(closed.jaxpr.outvars))
        consts = [dict(zip(closed.jaxpr.constvars, closed.consts))[v] for v in jaxpr.constvars]
    except Exception:
        jaxpr, consts = closed.jaxpr, closed.consts
    return jaxpr, consts, leaves


def build_loop(step, carry0, h, lanes: int = 1, params=None) -> NativeLoop:
    """Trace `step(carry, h) -> carry` at the example `carry0` (a pytree whose leaves are the
    state's arrays then the loop's counters, as :func:`gnipy.stepping.initial_carry` builds it), lower it
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
    jaxpr, consts, leaves = trace_step(step, carry0, h, params)
    shapes = [np.shape(x) for x in leaves]
    types = [llvm_type(np.asarray(x).dtype) if not hasattr(x, "dtype") else llvm_type(x.dtype) for x in leaves]
    n_state = int(sum(int(np.prod(s, dtype=np.int64)) for s in shapes[:n_state_leaves]))
    flat_types = [ty for s, ty in zip(shapes, types) for _ in range(int(np.prod(s, dtype=np.int64)))]
    const_arrays = [const_array(np.asarray(c)) for c in consts]

    for i, (ty, x) in enumerate(zip(types, leaves)):
        if ty not in ("double", "i32", "i64"):
            what = "a parameter of the system" if params is not None and i >= len(leaves) - len(params) else "the state"
            raise Unsupported(f"{what} has a leaf of dtype {np.asarray(x).dtype} (the loop carries float64, "
                              "int32 and int64)")
    t1 = time.perf_counter()
    prog = Program("gnipy native step loop")
    run = _run_function(prog, _step_body(prog, "gnipy_step", 1, jaxpr, const_arrays, shapes, flat_types), flat_types,
                        n_state, k_index=n_state, fail_index=n_state + 1)
    run_lanes = None
    if lanes > 1:
        step_lanes = _step_body(prog, "gnipy_step_lanes", lanes, jaxpr, const_arrays, shapes, flat_types)
        run_lanes = _lanes_function(prog, step_lanes, flat_types, n_state, lanes)
    _batch_function(prog, run, run_lanes, len(flat_types), n_state, lanes)
    texts = prog.texts
    t2 = time.perf_counter()
    engine, source, seconds = load_program(texts)
    timings = {"trace_s": t1 - t0, "lower_s": t2 - t1, "load_s": time.perf_counter() - t2}
    loop = NativeLoop(engine, len(flat_types), n_state, source, seconds, sum(t.count("\n") for t in texts), timings)
    loop.lanes = lanes
    return loop


def _step_body(prog: Program, name: str, lanes: int, jaxpr, const_arrays, shapes, types: list[str]):
    """The lowered step `name` of `prog` (:meth:`Program.body <gnipy.native.module.Program.body>`):
    `(carry scalars..., h) -> {carry scalars}`, each of its type in `types`; with `lanes`, on vectors."""
    fn = Function(lanes)
    *flat, h = fn.arguments(list(types) + ["double"])
    hh = np.empty((), dtype=object)
    hh[()] = h
    outs = lower_jaxpr(fn, jaxpr, const_arrays, unflatten(flat, shapes) + [hh])
    return prog.body(fn, name, flatten(outs)[0], types)
