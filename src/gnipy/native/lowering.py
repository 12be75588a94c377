"""A jaxpr, lowered to scalar LLVM IR: the translator of the native CPU backend.

Every array of a (small, static-shaped) jaxpr becomes a NumPy object array of *scalars*, each an
LLVM SSA value (:class:`Reg`) or a constant known at lowering time (:class:`Const`). Structural
operations (reshape, broadcast, slice, transpose, concatenate, pad, gather with constant indices)
then cost nothing: they rearrange names. Arithmetic emits one LLVM instruction per element, with
IEEE semantics (no fast-math flags: LLVM may not reassociate or contract). Loops stay loops:
`while` becomes a loop with phi nodes, `cond` a branch, `scan` without stacked outputs a counted
loop; calls (`jit`, `custom_jvp_call`, `custom_vjp_call`, `custom_linear_solve`'s solve) are
inlined. LAPACK's `lu` and `triangular_solve` are written out for the matrix's size (partial
pivoting as in LAPACK's getf2: the first largest pivot).

Why by hand: no maintained library lowers a jaxpr to machine code other than XLA, and XLA runs a
scalar step as tens of separate kernels (about 16–20 ns each); Numba's front end takes 30–80 s on
such generated code (issue 16), while LLVM itself, through llvmlite, compiles it in about a
second.

A primitive without a rule raises :class:`Unsupported`; the backend then runs the XLA path.

The modules, each importing only those listed before it: :mod:`gnipy.native.scalars` (the scalars
and the function being written), :mod:`gnipy.native.rules` (the registry of rules and the jaxpr
walk), the rules (:mod:`gnipy.native.control`, :mod:`gnipy.native.dense`, and this module's rules
of arithmetic, arrays and indexing), then this module as the translator's entry point: importing
it registers every rule, so its :func:`lower_jaxpr` and :func:`lowered_primitives` know them all.
"""

from __future__ import annotations

import numpy as np

from . import control, dense
from .rules import RULES, lower_jaxpr, lowered_primitives, rule
from .scalars import NUMPY_TYPES, Const, Function, Reg, Unsupported, const_array, llvm_type, map_scalars, scalars_of

__all__ = ["Unsupported", "Reg", "Const", "Function", "lower_jaxpr", "lowered_primitives", "llvm_type", "scalars_of"]

#: The modules whose rules are registered with this module's (on import): calls, loops and
#: branches; dense linear algebra.
RULE_MODULES = (control, dense)


# ---- elementwise ----------------------------------------------------------------------------

def _binary_rule(kind):
    return lambda fn, eqn, ins: [map_scalars(lambda a, b: fn.binary(kind, a, b), *ins)]


for _k in ("add", "sub", "mul", "div", "rem"):
    RULES[_k] = _binary_rule(_k)
RULES["add_any"] = _binary_rule("add")
for _k in ("eq", "ne", "lt", "le", "gt", "ge"):
    RULES[_k] = (lambda k: lambda fn, eqn, ins: [map_scalars(lambda a, b: fn.cmp(k, a, b), *ins)])(_k)
for _k in ("and", "or", "xor"):
    RULES[_k] = (lambda k: lambda fn, eqn, ins: [map_scalars(lambda a, b: fn.logic(k, a, b), *ins)])(_k)
for _k in ("sqrt", "rsqrt", "sin", "cos", "tan", "exp", "exp2", "log", "log1p", "expm1", "abs", "floor", "ceil",
           "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh", "atanh", "cbrt", "square", "logistic",
           "sign", "is_finite", "erf", "erfc"):
    RULES[_k] = (lambda k: lambda fn, eqn, ins: [map_scalars(lambda a: fn.unary(k, a), ins[0])])(_k)
RULES["neg"] = lambda fn, eqn, ins: [map_scalars(fn.neg, ins[0])]
RULES["not"] = lambda fn, eqn, ins: [map_scalars(fn.not_, ins[0])]
RULES["max"] = lambda fn, eqn, ins: [map_scalars(lambda a, b: fn.maxmin("max", a, b), *ins)]
RULES["min"] = lambda fn, eqn, ins: [map_scalars(lambda a, b: fn.maxmin("min", a, b), *ins)]
for _k in ("stop_gradient", "copy", "copy_p", "optimization_barrier", "device_put"):
    RULES[_k] = lambda fn, eqn, ins: list(ins)


@rule("round")
def _round(fn, eqn, ins):
    if int(eqn.params.get("rounding_method", 0)) != 0:
        raise Unsupported("round to nearest even")
    return [map_scalars(lambda a: fn.unary("round", a), ins[0])]


@rule("atan2", "pow")
def _atan2_pow(fn, eqn, ins):
    name = eqn.primitive.name
    return [map_scalars(lambda a, b: fn.call2(name, a, b), *ins)]


@rule("integer_pow")
def _integer_pow(fn, eqn, ins):
    y = int(eqn.params["y"])

    def power(x):
        # square-and-multiply, as JAX lowers integer_pow
        if y == 0:
            return Const(1, x.ty)
        acc, base, n = None, x, abs(y)
        while n:
            if n & 1:
                acc = base if acc is None else fn.binary("mul", acc, base)
            n >>= 1
            if n:
                base = fn.binary("mul", base, base)
        return fn.binary("div", Const(1.0, x.ty), acc) if y < 0 else acc

    return [map_scalars(power, ins[0])]


@rule("select_n")
def _select_n(fn, eqn, ins):
    pred, cases = ins[0], ins[1:]

    def f(p, *cs):
        if len(cs) == 1:
            return cs[0]
        if p.ty == "i1":
            return fn.select(p, cs[1], cs[0])
        out = cs[0]
        for j in range(1, len(cs)):
            out = fn.select(fn.cmp("eq", p, Const(j, p.ty)), cs[j], out)
        return out

    return [map_scalars(f, pred, *cases)]


@rule("clamp")
def _clamp(fn, eqn, ins):
    lo, x, hi = ins
    return [map_scalars(lambda a, x_, b: fn.maxmin("min", fn.maxmin("max", x_, a), b), lo, x, hi)]


@rule("convert_element_type")
def _convert(fn, eqn, ins):
    ty = llvm_type(eqn.params["new_dtype"])
    return [map_scalars(lambda a: fn.cast(a, ty), ins[0])]


@rule("reduce_precision")
def _reduce_precision(fn, eqn, ins):
    if (eqn.params["exponent_bits"], eqn.params["mantissa_bits"]) != (11, 52):
        raise Unsupported("reduce_precision below float64")
    return [ins[0]]


# ---- structure ------------------------------------------------------------------------------

@rule("broadcast_in_dim")
def _broadcast(fn, eqn, ins):
    shape, dims = eqn.params["shape"], eqn.params["broadcast_dimensions"]
    x = ins[0]
    expanded = [1] * len(shape)
    for i, d in enumerate(dims):
        expanded[d] = x.shape[i]
    return [np.broadcast_to(x.reshape(expanded), shape).copy()]


@rule("reshape")
def _reshape(fn, eqn, ins):
    if eqn.params.get("dimensions") not in (None, ()):
        raise Unsupported("reshape with dimensions")
    return [ins[0].reshape(eqn.params["new_sizes"])]


RULES["squeeze"] = lambda fn, eqn, ins: [ins[0].reshape(eqn.outvars[0].aval.shape)]
RULES["expand_dims"] = lambda fn, eqn, ins: [ins[0].reshape(eqn.outvars[0].aval.shape)]
RULES["transpose"] = lambda fn, eqn, ins: [np.transpose(ins[0], eqn.params["permutation"])]
RULES["rev"] = lambda fn, eqn, ins: [np.flip(ins[0], tuple(eqn.params["dimensions"]))]
RULES["concatenate"] = lambda fn, eqn, ins: [np.concatenate(ins, axis=eqn.params["dimension"])]
RULES["unstack"] = lambda fn, eqn, ins: [np.take(ins[0], i, axis=eqn.params["axis"])
                                          for i in range(ins[0].shape[eqn.params["axis"]])]
RULES["stack"] = lambda fn, eqn, ins: [np.stack(ins, axis=eqn.params["axis"])]


@rule("slice")
def _slice(fn, eqn, ins):
    st, lim, strides = eqn.params["start_indices"], eqn.params["limit_indices"], eqn.params["strides"]
    strides = strides or (1,) * len(st)
    return [ins[0][tuple(slice(a, b, s) for a, b, s in zip(st, lim, strides))]]


@rule("split")
def _split(fn, eqn, ins):
    axis, sizes = eqn.params["axis"], [int(s) for s in eqn.params["sizes"]]
    return np.split(ins[0], np.cumsum(sizes)[:-1], axis=axis)


@rule("pad")
def _pad(fn, eqn, ins):
    x, pv = ins
    for axis, (lo, hi, interior) in enumerate(eqn.params["padding_config"]):
        lo, hi, interior = int(lo), int(hi), int(interior)
        n = x.shape[axis]
        if interior and n > 1:
            shape = list(x.shape)
            shape[axis] = n + (n - 1) * interior
            y = np.empty(shape, dtype=object)
            y[...] = pv[()]
            idx = [slice(None)] * x.ndim
            idx[axis] = slice(0, None, interior + 1)
            y[tuple(idx)] = x
            x = y
        pads = [(0, 0)] * x.ndim
        pads[axis] = (max(lo, 0), max(hi, 0))
        filler = np.empty(1, dtype=object)
        filler[0] = pv[()]
        parts = []
        if lo > 0:
            s = list(x.shape)
            s[axis] = lo
            parts.append(np.broadcast_to(filler.reshape((1,) * x.ndim), s))
        parts.append(x)
        if hi > 0:
            s = list(x.shape)
            s[axis] = hi
            parts.append(np.broadcast_to(filler.reshape((1,) * x.ndim), s))
        x = np.concatenate(parts, axis=axis) if len(parts) > 1 else x
        if lo < 0 or hi < 0:
            idx = [slice(None)] * x.ndim
            idx[axis] = slice(max(-lo, 0), x.shape[axis] - max(-hi, 0))
            x = x[tuple(idx)]
    return [np.array(x, dtype=object)]


@rule("iota")
def _iota(fn, eqn, ins):
    shape, dim = eqn.params["shape"], eqn.params["dimension"]
    ty = llvm_type(eqn.params["dtype"])
    vals = np.broadcast_to(np.arange(shape[dim]).reshape([-1 if i == dim else 1 for i in range(len(shape))]), shape)
    return [const_array(vals, ty)]


def _reducer(kind):
    def rule(fn, eqn, ins):
        axes = tuple(eqn.params["axes"])
        x = ins[0]
        keep = [d for d in range(x.ndim) if d not in axes]
        moved = np.transpose(x, keep + list(axes))
        out_shape = moved.shape[:len(keep)]
        flat = moved.reshape(out_shape + (-1,))
        out = np.empty(out_shape, dtype=object)
        for idx in np.ndindex(out_shape):
            items = list(flat[idx])
            if not items:  # the reduction's identity
                ty = llvm_type(eqn.outvars[0].aval.dtype)
                lo, hi = {"double": (-np.inf, np.inf), "i1": (False, True)}.get(ty, (None, None))
                if lo is None:
                    lo, hi = np.iinfo(NUMPY_TYPES[ty]).min, np.iinfo(NUMPY_TYPES[ty]).max
                ident = {"add": 0, "mul": 1, "max": lo, "min": hi, "and": True, "or": False, "xor": False}[kind]
                out[idx] = Const(ident, ty)
                continue
            acc = items[0]
            if kind == "add" and acc.ty == "double":  # XLA adds from its init value +0 (so -0 + -0 is +0)
                acc = fn.binary("add", Const(0.0, "double"), acc)
            for it in items[1:]:
                if kind in ("add", "mul"):
                    acc = fn.binary(kind, acc, it)
                elif kind in ("max", "min"):
                    acc = fn.maxmin(kind, acc, it)
                else:
                    acc = fn.logic(kind, acc, it)
            out[idx] = acc
        return [out]
    return rule


for _k, _v in (("reduce_sum", "add"), ("reduce_prod", "mul"), ("reduce_max", "max"), ("reduce_min", "min"),
               ("reduce_and", "and"), ("reduce_or", "or"), ("reduce_xor", "xor")):
    RULES[_k] = _reducer(_v)


@rule("argmax", "argmin")
def _argmax(fn, eqn, ins):
    axes = tuple(eqn.params["axes"])
    ty = llvm_type(eqn.params["index_dtype"])
    x = ins[0]
    if len(axes) != 1:
        raise Unsupported("argmax over several axes")
    ax = axes[0]
    moved = np.moveaxis(x, ax, -1)
    out = np.empty(moved.shape[:-1], dtype=object)
    better = "gt" if eqn.primitive.name == "argmax" else "lt"
    for idx in np.ndindex(out.shape):
        items = list(moved[idx])
        best, bi = items[0], Const(0, ty)
        for j, it in enumerate(items[1:], start=1):
            take = fn.cmp(better, it, best)
            if it.ty == "double":  # NaN wins (the first one), as in XLA
                take = fn.logic("or", take, fn.logic("and", fn.cmp("ne", it, it), fn.cmp("eq", best, best)))
            best, bi = fn.select(take, it, best), fn.select(take, Const(j, ty), bi)
        out[idx] = bi
    return [out]


@rule("dot_general")
def _dot_general(fn, eqn, ins):
    (lc, rc), (lb, rb) = eqn.params["dimension_numbers"]
    a, b = ins
    pref = eqn.params.get("preferred_element_type")
    if a.size and pref is not None and llvm_type(pref) != a.flat[0].ty:
        raise Unsupported("dot_general with a mixed element type")
    lf = [d for d in range(a.ndim) if d not in lc and d not in lb]
    rf = [d for d in range(b.ndim) if d not in rc and d not in rb]
    A = np.transpose(a, list(lb) + lf + list(lc))
    B = np.transpose(b, list(rb) + rf + list(rc))
    nb = len(lb)
    bshape, lshape, rshape = A.shape[:nb], A.shape[nb:nb + len(lf)], B.shape[nb:nb + len(rf)]
    K = int(np.prod([a.shape[d] for d in lc], dtype=np.int64))
    A = A.reshape(bshape + (int(np.prod(lshape, dtype=np.int64)), K))
    B = B.reshape(bshape + (int(np.prod(rshape, dtype=np.int64)), K))
    out = np.empty(bshape + (A.shape[-2], B.shape[-2]), dtype=object)
    for bi in np.ndindex(bshape):
        for i in range(A.shape[-2]):
            for j in range(B.shape[-2]):
                if K == 0:
                    out[bi + (i, j)] = Const(0, a.flat[0].ty if a.size else "double")
                    continue
                acc = fn.binary("mul", A[bi + (i, 0)], B[bi + (j, 0)])
                if acc.ty == "double" and K > 1:  # from XLA's init value +0, as XLA sums
                    acc = fn.binary("add", Const(0.0, "double"), acc)
                for k in range(1, K):
                    acc = fn.binary("add", acc, fn.binary("mul", A[bi + (i, k)], B[bi + (j, k)]))
                out[bi + (i, j)] = acc
    return [out.reshape(bshape + lshape + rshape)]


# ---- indexing ---------------------------------------------------------------------------------

def _flat_index(fn, shape, index):
    """The C-order flat position of a (possibly runtime) multi-index, as a Const or an i64 Reg."""
    acc = Const(0, "i64")
    for d, i in enumerate(index):
        stride = int(np.prod(shape[d + 1:], dtype=np.int64))
        term = fn.binary("mul", fn.cast(i, "i64"), Const(stride, "i64"))
        acc = fn.binary("add", acc, term)
    return acc


def _clamped(fn, i, lo: int, hi: int):
    """`i` clamped to [lo, hi] (as XLA clamps start indices)."""
    return fn.maxmin("min", fn.maxmin("max", i, Const(lo, i.ty)), Const(hi, i.ty))


@rule("dynamic_slice")
def _dynamic_slice(fn, eqn, ins):
    x, starts = ins[0], [s[()] for s in ins[1:]]
    sizes = eqn.params["slice_sizes"]
    starts = [_clamped(fn, s, 0, x.shape[d] - sizes[d]) for d, s in enumerate(starts)]
    if all(isinstance(s, Const) for s in starts):
        return [x[tuple(slice(int(s.value), int(s.value) + n) for s, n in zip(starts, sizes))]]
    flat = scalars_of(x)
    out = np.empty(tuple(sizes), dtype=object)
    for off in np.ndindex(tuple(sizes)):
        idx = [fn.binary("add", s, Const(o, s.ty)) for s, o in zip(starts, off)]
        out[off] = fn.lookup(flat, _flat_index(fn, x.shape, idx))
    return [out]


@rule("dynamic_update_slice")
def _dynamic_update_slice(fn, eqn, ins):
    x, upd, starts = ins[0], ins[1], [s[()] for s in ins[2:]]
    starts = [_clamped(fn, s, 0, x.shape[d] - upd.shape[d]) for d, s in enumerate(starts)]
    if not all(isinstance(s, Const) for s in starts):
        raise Unsupported("dynamic_update_slice at a runtime position")
    out = x.copy()
    out[tuple(slice(int(s.value), int(s.value) + n) for s, n in zip(starts, upd.shape))] = upd
    return [out]


@rule("gather")
def _gather(fn, eqn, ins):
    x, ind = ins
    dn = eqn.params["dimension_numbers"]
    if dn.operand_batching_dims or dn.start_indices_batching_dims:
        raise Unsupported("gather with batching dims")
    sizes = eqn.params["slice_sizes"]
    mode = str(eqn.params["mode"])
    fill = "FILL_OR_DROP" in mode
    offset_dims, collapsed, start_map = dn.offset_dims, dn.collapsed_slice_dims, dn.start_index_map
    out_shape = eqn.outvars[0].aval.shape
    batch_dims = [d for d in range(len(out_shape)) if d not in offset_dims]
    kept = [d for d in range(x.ndim) if d not in collapsed]
    flat = scalars_of(x)
    out = np.empty(out_shape, dtype=object)
    fill_value = eqn.params.get("fill_value")
    for o in np.ndindex(out_shape):
        g = tuple(o[d] for d in batch_dims)
        vec = ind[g] if ind.ndim > 1 else ind
        vec = list(np.asarray(vec, dtype=object).reshape(-1))
        starts = [Const(0, "i64") for _ in range(x.ndim)]
        valid = Const(True, "i1")
        for k, d in enumerate(start_map):
            s = vec[k]
            hi = x.shape[d] - sizes[d]
            if fill:
                ok = fn.logic("and", fn.cmp("ge", s, Const(0, s.ty)), fn.cmp("le", s, Const(hi, s.ty)))
                valid = fn.logic("and", valid, ok)
            starts[d] = _clamped(fn, s, 0, hi)
        offs = [o[d] for d in offset_dims]
        full = list(starts)
        for j, d in enumerate(kept):
            full[d] = fn.binary("add", fn.cast(starts[d], "i64"), Const(offs[j], "i64"))
        v = fn.lookup(flat, _flat_index(fn, x.shape, full))
        if fill:
            fv = fill_value if fill_value is not None else (np.nan if v.ty == "double" else 0)
            v = fn.select(valid, v, Const(fv, v.ty))
        out[o] = v
    return [out]


@rule("scatter-add", "scatter_add", "scatter")
def _scatter(fn, eqn, ins):
    x, ind, upd = ins
    if not all(isinstance(i, Const) for i in ind.flat):
        raise Unsupported("scatter at runtime positions")
    dn = eqn.params["dimension_numbers"]
    if dn.operand_batching_dims:
        raise Unsupported("scatter mode")
    # FILL_OR_DROP (what `x.at[i].set(y)` makes): a window not wholly inside the operand is dropped;
    # with the positions known here that is decided now, and the windows inside are the plain scatter's
    drop = "FILL_OR_DROP" in str(eqn.params["mode"])
    out = x.copy()
    uwd, iwd, sdims = dn.update_window_dims, dn.inserted_window_dims, dn.scatter_dims_to_operand_dims
    scatter_dims = [d for d in range(upd.ndim) if d not in uwd]
    window_operand_dims = [d for d in range(x.ndim) if d not in iwd]
    add = eqn.primitive.name != "scatter"

    def position(u):
        g = tuple(u[d] for d in scatter_dims)
        vec = ind[g] if ind.ndim > 1 else ind
        vec = [int(v.value) for v in np.asarray(vec, dtype=object).reshape(-1)]
        full = [0] * x.ndim
        for k, d in enumerate(sdims):
            full[d] = vec[k]
        for j, d in enumerate(window_operand_dims):
            full[d] += u[uwd[j]]
        return g, tuple(full), all(0 <= full[d] < x.shape[d] for d in range(x.ndim))

    positions = [position(u) for u in np.ndindex(upd.shape)]
    outside = {g for g, _, inside in positions if not inside}
    if outside and not drop:
        raise Unsupported("scatter out of bounds")
    for u, (g, full, _) in zip(np.ndindex(upd.shape), positions):
        if g in outside:  # FILL_OR_DROP drops a window that is not wholly inside
            continue
        out[full] = fn.binary("add", out[full], upd[u]) if add else upd[u]
    return [out]

