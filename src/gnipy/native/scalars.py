"""Scalars of the native lowering and the LLVM function that holds them.

A value of a lowered jaxpr is a NumPy object array of scalars: SSA registers (:class:`Reg`) or
constants known when lowering (:class:`Const`). :class:`Function` writes the LLVM IR of one
function body: an instruction per scalar operation, with IEEE semantics (no fast-math flags),
constants folded only when every operand is one; with `lanes` the same instructions run on
vectors, one trajectory per lane. Its result is one function (:meth:`Function.define`) that the
code around it (:mod:`gnipy.native.module`, built with llvmlite's IR builder) calls and LLVM
inlines.

Why text and not llvmlite's IR builder here: this is the hot path of a build (one call per scalar
operation, about 7,400 instructions for a rolling-ball step), and llvmlite.ir takes about 5 times
as long per instruction (7.3 µs against 1.5 µs to build and print one; the user guide's page "The
native backend: design decisions"). The text stays inside this class: each method writes one
instruction from a fixed template with typed operands, and no other module writes IR text.
"""

from __future__ import annotations

import math
import struct

import numpy as np

__all__ = ["Unsupported", "Reg", "Const", "Function", "llvm_type", "scalars_of", "const_array", "map_scalars",
           "flatten", "unflatten", "NUMPY_TYPES", "LIBM_SYMBOLS"]


class Unsupported(Exception):
    """A jaxpr the native backend cannot lower (the message names the primitive or the reason)."""


# ---------------------------------------------------------------------------------------------
# Scalars: registers and constants
# ---------------------------------------------------------------------------------------------

_TYPES = {np.dtype(np.float64): "double", np.dtype(np.int32): "i32", np.dtype(np.int64): "i64",
          np.dtype(np.bool_): "i1"}
#: The NumPy scalar type of each LLVM type of a scalar.
NUMPY_TYPES = {"double": np.float64, "i32": np.int32, "i64": np.int64, "i1": np.bool_}


def llvm_type(dtype) -> str:
    """The LLVM type of a JAX dtype (float64, int32, int64, bool); others are :class:`Unsupported`."""
    try:
        return _TYPES[np.dtype(dtype)]
    except (KeyError, TypeError):
        raise Unsupported(f"dtype {dtype}") from None


class Reg:
    """An SSA register `name` of LLVM type `ty`."""

    __slots__ = ("name", "ty")

    def __init__(self, name: str, ty: str):
        self.name, self.ty = name, ty

    @property
    def text(self) -> str:
        return self.name


class _Scalar:
    """A scalar i1 register in a function with lanes (a branch condition)."""

    __slots__ = ("text",)
    ty = "i1"

    def __init__(self, name: str):
        self.text = name


class Const:
    """A constant scalar (a NumPy scalar of the type's dtype)."""

    __slots__ = ("value", "ty")

    def __init__(self, value, ty: str):
        self.value, self.ty = NUMPY_TYPES[ty](value), ty

    @property
    def text(self) -> str:
        if self.ty == "double":
            return "0x%016X" % struct.unpack("<Q", struct.pack("<d", float(self.value)))[0]
        if self.ty == "i1":
            return "true" if bool(self.value) else "false"
        return str(int(self.value))


def const_array(value, ty=None) -> np.ndarray:
    """`value` (an array) as an object array of :class:`Const` of LLVM type `ty` (default: its dtype's)."""
    a = np.asarray(value)
    ty = ty or llvm_type(a.dtype)
    out = np.empty(a.shape, dtype=object)
    for idx in np.ndindex(a.shape):
        out[idx] = Const(a[idx], ty)
    return out


def scalars_of(a: np.ndarray) -> list:
    """The scalars of an object array, in C order."""
    return list(np.asarray(a, dtype=object).reshape(-1))


def map_scalars(f, *arrays) -> np.ndarray:
    """`f` applied to the scalars of object arrays (broadcast together), element by element."""
    arrays = np.broadcast_arrays(*[np.asarray(a, dtype=object) for a in arrays])
    out = np.empty(arrays[0].shape, dtype=object)
    for idx in np.ndindex(out.shape):
        out[idx] = f(*(a[idx] for a in arrays))
    return out


def flatten(arrays) -> tuple[list, list]:
    """`(scalars, shapes)`: the scalars of object arrays, one list in C order, and their shapes."""
    shapes = [a.shape for a in arrays]
    flat = [s for a in arrays for s in scalars_of(a)]
    return flat, shapes


def unflatten(flat, shapes) -> list[np.ndarray]:
    """The object arrays of `shapes` holding the scalars `flat` (the inverse of :func:`flatten`)."""
    out, i = [], 0
    for s in shapes:
        n = int(np.prod(s, dtype=np.int64))
        a = np.empty(n, dtype=object)
        for j in range(n):
            a[j] = flat[i + j]
        out.append(a.reshape(s))
        i += n
    return out


# ---------------------------------------------------------------------------------------------
# The function being emitted
# ---------------------------------------------------------------------------------------------

_INTRINSIC = {"sqrt": "llvm.sqrt.f64", "sin": "llvm.sin.f64", "cos": "llvm.cos.f64", "exp": "llvm.exp.f64",
              "log": "llvm.log.f64", "abs": "llvm.fabs.f64", "floor": "llvm.floor.f64", "ceil": "llvm.ceil.f64",
              "round": "llvm.round.f64", "exp2": "llvm.exp2.f64", "pow": "llvm.pow.f64",
              "copysign": "llvm.copysign.f64", "maximum": "llvm.maximum.f64", "minimum": "llvm.minimum.f64"}
_LIBM = {"tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan", "atan2": "atan2", "sinh": "sinh",
         "cosh": "cosh", "tanh": "tanh", "asinh": "asinh", "acosh": "acosh", "atanh": "atanh", "expm1": "expm1",
         "log1p": "log1p", "cbrt": "cbrt", "erf": "erf", "erfc": "erfc"}
#: libm functions the generated code may call (resolved in the process when it is loaded)
LIBM_SYMBOLS = tuple(sorted(set(_LIBM.values())))


class Function:
    """The body of one LLVM function under construction: its arguments (:meth:`arguments`),
    instructions, blocks and declarations; :meth:`define` ends it and gives its text.

    With `lanes` > 1 every scalar is a vector of that many lanes, one trajectory each (the same
    instructions on `<lanes x double>`): loops run while any lane's condition holds and update
    only those lanes, and `cond` computes every branch and selects per lane, so each lane gets
    the bits of the scalar code."""

    def __init__(self, lanes: int = 1):
        self.lanes = int(lanes)
        self.lines: list = []  # instruction and label lines; a list in it holds phi nodes (open_phis)
        self.decls: set[str] = set()
        self.allocas: list[str] = []
        self.params: list[Reg] = []
        self._n = 0
        self.block = "entry"

    def arguments(self, types: list[str]) -> list[Reg]:
        """New arguments of the function, of scalar types `types` (vectors with lanes)."""
        regs = [Reg(f"%arg{len(self.params) + j}", ty) for j, ty in enumerate(types)]
        self.params.extend(regs)
        return regs

    def result_type(self, types: list[str]) -> str:
        """The LLVM type of the struct :meth:`define` returns for results of `types`."""
        return "{" + ", ".join(self.T(ty) for ty in types) + "}"

    def define(self, name: str, results: list, types: list[str]) -> str:
        """End the body: return `results` (scalars, cast to `types`) as one struct, and give the
        LLVM IR text of the function `@name` (its :meth:`arguments`, then the body). The function
        is `linkonce_odr` and `alwaysinline`: the code that calls it (:mod:`gnipy.native.module`)
        gets it inlined, and nothing of it is left in the object code."""
        st = self.result_type(types)
        acc = "poison"
        for j, (v, ty) in enumerate(zip(results, types)):
            nxt = self.fresh()
            self.emit(f"{nxt} = insertvalue {st} {acc}, {self.T(ty)} {self.V(self.cast(v, ty))}, {j}")
            acc = nxt
        self.emit(f"ret {st} {acc}")
        params = ", ".join(f"{self.T(r.ty)} {r.name}" for r in self.params)
        body = [line for item in self.lines for line in ([item] if isinstance(item, str) else item)]
        return "\n".join([f"define linkonce_odr {st} @{name}({params}) alwaysinline {{", "entry:", *self.allocas,
                          *body, "}", ""])

    def T(self, ty: str) -> str:
        """The LLVM type of a scalar of type `ty` (a vector of them with lanes)."""
        return ty if self.lanes == 1 or ty == "ptr" else f"<{self.lanes} x {ty}>"

    def V(self, x) -> str:
        """The operand text of a register or constant (a constant vector with lanes)."""
        if self.lanes == 1 or isinstance(x, Reg):
            return x.text
        return "<" + ", ".join([f"{x.ty} {x.text}"] * self.lanes) + ">"

    def any(self, c):
        """A scalar i1: whether the condition `c` holds in any lane."""
        if self.lanes == 1 or isinstance(c, Const):
            return c
        name = f"llvm.vector.reduce.or.v{self.lanes}i1"
        self.decls.add(f"declare i1 @{name}({self.T('i1')})")
        r = self.fresh()
        self.emit(f"{r} = call i1 @{name}({self.T('i1')} {c.text})")
        return _Scalar(r)

    def fresh(self, prefix="t") -> str:
        self._n += 1
        return f"%{prefix}{self._n}"

    def label(self, prefix="L") -> str:
        self._n += 1
        return f"{prefix}{self._n}"

    def emit(self, line: str) -> None:
        self.lines.append("  " + line)

    def op(self, ty: str, text: str) -> Reg:
        name = self.fresh()
        self.emit(f"{name} = {text}")
        return Reg(name, ty)

    def start(self, label: str) -> None:
        self.lines.append(f"{label}:")
        self.block = label

    def br(self, label: str) -> None:
        self.emit(f"br label %{label}")

    def condbr(self, c, yes: str, no: str) -> None:
        """Branch on a scalar i1 (reduce a lane vector with :meth:`any` first)."""
        self.emit(f"br i1 {c.text}, label %{yes}, label %{no}")

    def switch(self, index, default: str, labels: list[str]) -> None:
        """Branch to `labels[index]`, or to `default` for any other value of the scalar `index`."""
        cases = " ".join(f"{index.ty} {j}, label %{lab}" for j, lab in enumerate(labels))
        self.emit(f"switch {index.ty} {index.text}, label %{default} [ {cases} ]")

    def phi(self, ty: str, incoming: list) -> Reg:
        """A phi node of type `ty` here (at the top of a block): `incoming` is `(value, block)` pairs."""
        return self.op(ty, f"phi {self.T(ty)} " + ", ".join(f"[ {self.V(x)}, %{blk} ]" for x, blk in incoming))

    def open_phis(self, types: list[str]) -> tuple[list[Reg], list]:
        """Phi nodes of `types` here (at the top of a block) whose incoming values are known
        later (a loop's head, before its body is emitted): `(registers, handle)`; give the
        incoming values with :meth:`close_phis`."""
        regs = [Reg(self.fresh("p"), ty) for ty in types]
        handle: list = []
        self.lines.append(handle)  # the phi lines go here, wherever later lines are inserted
        return regs, handle

    def close_phis(self, regs: list[Reg], handle: list, incoming: list) -> None:
        """The phi nodes `regs` of :meth:`open_phis`: `incoming[i]` is the `(value, block)` pairs of `regs[i]`."""
        handle.extend(f"  {r.name} = phi {self.T(r.ty)} " + ", ".join(f"[ {self.V(x)}, %{blk} ]" for x, blk in inc)
                      for r, inc in zip(regs, incoming))

    def alloca(self, ty: str, n: int = 1) -> str:
        name = self.fresh("a")
        self.allocas.append(f"  {name} = alloca {ty}, i64 {n}")
        return name

    def call(self, fn: str, ty: str, *args) -> Reg:
        if fn in _INTRINSIC:
            name = _INTRINSIC[fn]
            if self.lanes > 1:
                name = name.replace(".f64", f".v{self.lanes}f64")
        elif fn in _LIBM:
            name = _LIBM[fn]
            if self.lanes > 1:  # the C library's function, lane by lane
                lanes = [[self.op(ty, f"extractelement {self.T(ty)} {self.V(a)}, i32 {j}") for a in args]
                         for j in range(self.lanes)]
                self.decls.add(f"declare {ty} @{name}({', '.join(ty for _ in args)})")
                acc = "poison"
                for j, xs in enumerate(lanes):
                    r = self.fresh()
                    self.emit(f"{r} = call {ty} @{name}({', '.join(f'{ty} {x.name}' for x in xs)})")
                    nxt = self.fresh()
                    self.emit(f"{nxt} = insertelement {self.T(ty)} {acc}, {ty} {r}, i32 {j}")
                    acc = nxt
                return Reg(acc, ty)
        else:
            raise Unsupported(fn)
        T = self.T(ty)
        self.decls.add(f"declare {T} @{name}({', '.join(T for _ in args)})")
        return self.op(ty, f"call {T} @{name}({', '.join(f'{T} {self.V(a)}' for a in args)})")

    def call2(self, fn: str, a, b):
        """`atan2` or `pow` of two doubles, folded when both are constants."""
        if a.ty != "double" or b.ty != "double":
            raise Unsupported(f"{fn} of integers")
        if isinstance(a, Const) and isinstance(b, Const):
            with np.errstate(all="ignore"):
                return Const(_fold2(fn, a.value, b.value), "double")
        return self.call(fn, "double", a, b)

    # ---- scalar arithmetic, folded when every operand is a constant --------------------------

    def binary(self, kind: str, a, b):
        ty = a.ty
        if isinstance(a, Const) and isinstance(b, Const):
            with np.errstate(all="ignore"):
                return Const(_fold2(kind, a.value, b.value), ty)
        # exact identities only (IEEE: x*1 = x, x - 0 = x, x + (-0) = x)
        if kind == "mul" and ty == "double":
            if isinstance(b, Const) and b.value == 1.0:
                return a
            if isinstance(a, Const) and a.value == 1.0:
                return b
        if kind == "sub" and ty == "double" and isinstance(b, Const) and b.value == 0.0 and not np.signbit(b.value):
            return a
        if ty == "double":
            ins = {"add": "fadd", "sub": "fsub", "mul": "fmul", "div": "fdiv", "rem": "frem"}[kind]
            return self.op(ty, f"{ins} {self.T(ty)} {self.V(a)}, {self.V(b)}")
        if kind in ("div", "rem"):
            # XLA's integer division by zero is defined (x / 0 = -1, x % 0 = x); LLVM's is not
            zero = self.cmp("eq", b, Const(0, ty))
            safe = self.select(zero, Const(1, ty), b)
            q = self.op(ty, f"{'sdiv' if kind == 'div' else 'srem'} {self.T(ty)} {self.V(a)}, {self.V(safe)}")
            return self.select(zero, Const(-1, ty) if kind == "div" else a, q)
        ins = {"add": "add", "sub": "sub", "mul": "mul", "and": "and", "or": "or", "xor": "xor", "shr": "ashr"}[kind]
        return self.op(ty, f"{ins} {self.T(ty)} {self.V(a)}, {self.V(b)}")

    def logic(self, kind: str, a, b):
        if isinstance(a, Const) and isinstance(b, Const):
            f = {"and": np.bitwise_and, "or": np.bitwise_or, "xor": np.bitwise_xor}[kind]
            return Const(f(a.value, b.value), a.ty)
        return self.op(a.ty, f"{kind} {self.T(a.ty)} {self.V(a)}, {self.V(b)}")

    def neg(self, a):
        if isinstance(a, Const):
            return Const(-a.value, a.ty)
        if a.ty == "double":
            return self.op("double", f"fneg {self.T('double')} {self.V(a)}")
        return self.op(a.ty, f"sub {self.T(a.ty)} {self.V(Const(0, a.ty))}, {self.V(a)}")

    def cmp(self, kind: str, a, b):
        if isinstance(a, Const) and isinstance(b, Const):
            with np.errstate(all="ignore"):
                return Const(_fold2(kind, a.value, b.value), "i1")
        if a.ty == "double":
            pred = {"eq": "oeq", "ne": "une", "lt": "olt", "le": "ole", "gt": "ogt", "ge": "oge"}[kind]
            return self.op("i1", f"fcmp {pred} {self.T('double')} {self.V(a)}, {self.V(b)}")
        pred = {"eq": "eq", "ne": "ne", "lt": "slt", "le": "sle", "gt": "sgt", "ge": "sge"}[kind]
        if a.ty == "i1":
            pred = {"lt": "ult", "le": "ule", "gt": "ugt", "ge": "uge"}.get(kind, pred)
        return self.op("i1", f"icmp {pred} {self.T(a.ty)} {self.V(a)}, {self.V(b)}")

    def select(self, c, a, b):
        """`c ? a : b`."""
        if isinstance(c, Const):
            return a if bool(c.value) else b
        if a is b:
            return a
        T = self.T(a.ty)
        return self.op(a.ty, f"select {self.T('i1')} {self.V(c)}, {T} {self.V(a)}, {T} {self.V(b)}")

    def not_(self, a):
        if isinstance(a, Const):
            return Const(~a.value if a.ty != "i1" else not bool(a.value), a.ty)
        return self.op(a.ty, f"xor {self.T(a.ty)} {self.V(a)}, {self.V(Const(True if a.ty == 'i1' else -1, a.ty))}")

    def unary(self, fn: str, a):
        if a.ty != "double":
            if fn == "abs":
                return self.select(self.cmp("lt", a, Const(0, a.ty)), self.neg(a), a)
            if fn == "sign":
                pos = self.cast(self.cmp("gt", a, Const(0, a.ty)), a.ty)
                neg = self.cast(self.cmp("lt", a, Const(0, a.ty)), a.ty)
                return self.binary("sub", pos, neg)
            raise Unsupported(f"{fn} of {a.ty}")
        if isinstance(a, Const):
            if fn == "is_finite":  # a predicate: an i1, as the instruction below gives
                return Const(bool(np.isfinite(a.value)), "i1")
            with np.errstate(all="ignore"):
                return Const(_fold1(fn, a.value), "double")
        if fn == "rsqrt":
            return self.binary("div", Const(1.0, "double"), self.call("sqrt", "double", a))
        if fn == "square":
            return self.binary("mul", a, a)
        if fn == "logistic":
            e = self.call("exp", "double", self.neg(a))
            return self.binary("div", Const(1.0, "double"), self.binary("add", Const(1.0, "double"), e))
        if fn == "sign":
            pos = self.cast(self.cmp("gt", a, Const(0.0, "double")), "double")
            neg = self.cast(self.cmp("lt", a, Const(0.0, "double")), "double")
            s = self.binary("sub", pos, neg)
            keep = self.logic("or", self.cmp("ne", a, a), self.cmp("eq", a, Const(0.0, "double")))
            return self.select(keep, a, s)  # NaN stays NaN, ±0 stays ±0
        if fn == "is_finite":
            return self.cmp("lt", self.call("abs", "double", a), Const(np.inf, "double"))
        return self.call(fn, "double", a)

    def maxmin(self, kind: str, a, b):
        """XLA's max/min: NaN if either operand is NaN, and -0 < +0 (LLVM's `maximum`/`minimum`)."""
        if isinstance(a, Const) and isinstance(b, Const):
            if a.ty == "double" and a.value == 0 and b.value == 0:
                neg = np.signbit(a.value) and np.signbit(b.value) if kind == "max" else \
                    np.signbit(a.value) or np.signbit(b.value)
                return Const(-0.0 if neg else 0.0, "double")
            with np.errstate(all="ignore"):
                return Const((np.maximum if kind == "max" else np.minimum)(a.value, b.value), a.ty)
        if a.ty == "double":
            return self.call("maximum" if kind == "max" else "minimum", "double", a, b)
        return self.select(self.cmp("gt" if kind == "max" else "lt", a, b), a, b)

    def cast(self, a, ty: str):
        if a.ty == ty:
            return a
        if isinstance(a, Const):
            if ty == "i1":
                return Const(bool(a.value != 0), ty)
            with np.errstate(all="ignore"):
                return Const(NUMPY_TYPES[ty](a.value), ty)
        src = a.ty
        if ty == "i1":
            return self.cmp("ne", a, Const(0, src))
        if ty == "double":
            return self.op(ty, f"{'uitofp' if src == 'i1' else 'sitofp'} {self.T(src)} {self.V(a)} to {self.T(ty)}")
        if src == "double":
            return self.op(ty, f"fptosi {self.T(src)} {self.V(a)} to {self.T(ty)}")
        width = {"i1": 1, "i32": 32, "i64": 64}
        if width[src] < width[ty]:
            return self.op(ty, f"{'zext' if src == 'i1' else 'sext'} {self.T(src)} {self.V(a)} to {self.T(ty)}")
        return self.op(ty, f"trunc {self.T(src)} {self.V(a)} to {self.T(ty)}")

    def total_order_key(self, a):
        """An i64 whose signed order is IEEE's total order of the double `a`."""
        if isinstance(a, Const):
            bits = np.int64(np.float64(a.value).view(np.int64))
            return Const(bits ^ ((bits >> 63) & np.int64(0x7FFFFFFFFFFFFFFF)), "i64")
        bits = self.op("i64", f"bitcast {self.T('double')} {self.V(a)} to {self.T('i64')}")
        sign = self.binary("shr", bits, Const(63, "i64"))
        mask = self.logic("and", sign, Const(0x7FFFFFFFFFFFFFFF, "i64"))
        return self.logic("xor", bits, mask)

    def lookup(self, values: list, index):
        """`values[index]` for a runtime integer `index` (clamped by the caller)."""
        if isinstance(index, Const):
            return values[int(index.value)]
        if all(v is values[0] for v in values):
            return values[0]
        ty = values[0].ty
        if len(values) <= 8 or self.lanes > 1:
            out = values[0]
            for j in range(1, len(values)):
                out = self.select(self.cmp("eq", index, Const(j, index.ty)), values[j], out)
            return out
        buf = self.alloca(ty, len(values))
        for j, v in enumerate(values):
            p = self.op("ptr", f"getelementptr {ty}, ptr {buf}, i64 {j}")
            self.emit(f"store {ty} {v.text}, ptr {p.text}")
        i64 = self.cast(index, "i64")
        p = self.op("ptr", f"getelementptr {ty}, ptr {buf}, i64 {i64.text}")
        return self.op(ty, f"load {ty}, ptr {p.text}")


def _fold2(kind, x, y):
    if kind in ("div", "rem") and np.issubdtype(type(x), np.integer):
        if y == 0:
            return -1 if kind == "div" else x
        q = int(math.trunc(int(x) / int(y))) if abs(int(x)) < 2**52 else int(x) // int(y)
        return q if kind == "div" else int(x) - q * int(y)
    return {"add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide, "rem": np.fmod,
            "eq": np.equal, "ne": np.not_equal, "lt": np.less, "le": np.less_equal, "gt": np.greater,
            "ge": np.greater_equal, "pow": np.power, "atan2": np.arctan2, "and": np.bitwise_and,
            "or": np.bitwise_or, "xor": np.bitwise_xor, "shr": np.right_shift}[kind](x, y)


def _fold1(fn, x):
    f = {"sqrt": np.sqrt, "sin": np.sin, "cos": np.cos, "exp": np.exp, "log": np.log, "abs": np.abs,
         "floor": np.floor, "ceil": np.ceil, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos,
         "atan": np.arctan, "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "expm1": np.expm1,
         "log1p": np.log1p, "cbrt": np.cbrt, "exp2": np.exp2, "square": np.square,
         "rsqrt": lambda v: 1.0 / np.sqrt(v), "sign": np.sign, "is_finite": np.isfinite,
         "logistic": lambda v: 1.0 / (1.0 + np.exp(-v)), "asinh": np.arcsinh, "acosh": np.arccosh,
         "atanh": np.arctanh, "round": lambda v: np.copysign(np.floor(abs(v) + 0.5), v)}.get(fn)
    if f is None:
        raise Unsupported(fn)
    return f(x)
