"""A jaxpr compiled on its own, outside the step loop: the native lowering of
:mod:`gnipy.native.lowering` and the compiler of :mod:`gnipy.native.program` applied to one
function, for tests and experiments (the lowering checked against XLA and NumPy, operation by
operation)."""

from __future__ import annotations

import ctypes

import numpy as np

from .lowering import lower_jaxpr
from .module import Program, ir_type
from .engine import load_program
from .scalars import Function, const_array, flatten, llvm_type

__all__ = ["NativeFunction", "build_function"]

_FUNC = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)


class NativeFunction:
    """A jaxpr compiled on its own (:func:`build_function`): `f(*arrays)` → list of NumPy arrays."""

    def __init__(self, engine, in_avals, out_avals, source: str):
        self._engine, self.source = engine, source
        self.in_avals, self.out_avals = in_avals, out_avals
        self._fn = _FUNC(engine.get_function_address("gnipy_fn"))

    def __call__(self, *args):
        flat = np.concatenate([np.ravel(np.asarray(a, dtype=np.float64)) for a in args] or [np.zeros(0)])
        flat = np.ascontiguousarray(flat)
        n_out = sum(int(np.prod(a.shape, dtype=np.int64)) for a in self.out_avals)
        out = np.empty(max(n_out, 1), dtype=np.float64)
        self._fn(flat.ctypes.data, out.ctypes.data)
        res, i = [], 0
        for a in self.out_avals:
            n = int(np.prod(a.shape, dtype=np.int64))
            res.append(out[i:i + n].reshape(a.shape).astype(a.dtype))
            i += n
        return res


def build_function(f, *example_args) -> NativeFunction:
    """Compile `f` (a JAX function of arrays, returning an array or a tuple of them) through the
    native lowering: the same translator as the step loop, for tests and experiments. Inputs and
    outputs travel as float64 (integers and booleans converted exactly)."""
    import jax

    closed = jax.make_jaxpr(lambda *a: tuple(jax.tree_util.tree_leaves(f(*a))))(*example_args)
    fn = Function()
    args = []
    for v in closed.jaxpr.invars:
        a = np.empty(v.aval.shape, dtype=object)
        ty = llvm_type(v.aval.dtype)
        for idx in np.ndindex(v.aval.shape):
            a[idx] = fn.cast(fn.arguments(["double"])[0], ty)
        args.append(a)
    outs = lower_jaxpr(fn, closed.jaxpr, [const_array(np.asarray(c)) for c in closed.consts], args)
    flat, _ = flatten(outs)
    prog = Program("gnipy native function")
    body = prog.body(fn, "gnipy_fn_body", flat, ["double"] * len(flat))
    # gnipy_fn(in, out): the inputs from `in`, the body, its outputs to `out` (all float64)
    g, b = prog.function("gnipy_fn", [("in", "ptr", True), ("out", "ptr", True)])
    src, dst = g.args
    f64 = ir_type("double")
    i64 = ir_type("i64")
    result = b.call(body, [b.load(b.gep(src, [i64(k)], source_etype=f64), typ=f64) for k in range(len(fn.params))])
    for j in range(len(flat)):
        b.store(b.extract_value(result, j), b.gep(dst, [i64(j)], source_etype=f64))
    b.ret_void()
    engine, source, _ = load_program(prog.texts)
    return NativeFunction(engine, [v.aval for v in closed.jaxpr.invars], [v.aval for v in closed.jaxpr.outvars],
                          source)
