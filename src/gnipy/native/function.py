"""A jaxpr compiled on its own, outside the step loop: the native lowering of
:mod:`gnipy.native.lowering` and the compiler of :mod:`gnipy.native.program` applied to one
function, for tests and experiments (the lowering checked against XLA and NumPy, operation by
operation)."""

from __future__ import annotations

import ctypes

import numpy as np

from .control import _flatten
from .lowering import lower_jaxpr
from .program import _load
from .scalars import Function, _const_array, llvm_type

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
    args, k = [], 0
    for v in closed.jaxpr.invars:
        ty = llvm_type(v.aval.dtype)
        a = np.empty(v.aval.shape, dtype=object)
        for idx in np.ndindex(v.aval.shape):
            p = fn.op("ptr", f"getelementptr double, ptr %in, i64 {k}")
            x = fn.op("double", f"load double, ptr {p.text}")
            a[idx] = fn.cast(x, ty)
            k += 1
        args.append(a)
    outs = lower_jaxpr(fn, closed.jaxpr, [_const_array(np.asarray(c)) for c in closed.consts], args)
    flat, _ = _flatten(outs)
    for j, v in enumerate(flat):
        p = fn.op("ptr", f"getelementptr double, ptr %out, i64 {j}")
        fn.emit(f"store double {fn.cast(v, 'double').text}, ptr {p.text}")
    fn.emit("ret void")
    ir = (f"{chr(10).join(sorted(fn.decls))}\n\ndefine void @gnipy_fn(ptr noalias %in, ptr noalias %out) {{\n"
          f"entry:\n{chr(10).join(fn.allocas)}\n{chr(10).join(fn.lines)}\n}}\n")
    engine, source, _ = _load(ir)
    return NativeFunction(engine, [v.aval for v in closed.jaxpr.invars], [v.aval for v in closed.jaxpr.outvars],
                          source)
