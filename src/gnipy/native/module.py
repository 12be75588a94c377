"""An LLVM program of the native backend, and the code around its lowered bodies, built with
llvmlite's IR builder (:mod:`llvmlite.ir`).

A program is two LLVM modules that LLVM links into one (:attr:`Program.texts`):

- the *skeleton*, built here with llvmlite.ir: the exported functions (the step loop's
  `gnipy_run`, `gnipy_run_lanes` and `gnipy_run_batch` of :mod:`gnipy.native.program`, the
  `gnipy_fn` of :mod:`gnipy.native.function`): their loops over blocks, steps and trajectories,
  and the loads and stores of the buffers they are given;
- the *bodies* it calls (one step, one function), each the text that a
  :class:`~gnipy.native.scalars.Function` wrote while the jaxpr was lowered, defined
  `linkonce_odr` and `alwaysinline`: LLVM inlines each into its caller before optimizing, and
  drops it, so the machine code is that of one function.

The contract between the two is the body's signature: its arguments are scalars of the
:meth:`~gnipy.native.scalars.Function.arguments` types, its result one struct of the types
given to :meth:`Program.body`; the skeleton declares it with the same types (LLVM's linker
checks that they agree).
"""

from __future__ import annotations

__all__ = ["Program", "ir_type", "convert"]


def ir_type(ty: str, lanes: int = 1):
    """The llvmlite.ir type of a scalar of LLVM type `ty` ("double", "i32", "i64", "i1"; a vector of
    `lanes` of them when `lanes` > 1)."""
    from llvmlite import ir

    base = ir.DoubleType() if ty == "double" else ir.IntType(int(ty[1:]))
    return base if lanes == 1 else ir.VectorType(base, lanes)


def convert(builder, value, src: str, dst: str, lanes: int = 1):
    """`value` of scalar type `src` converted to `dst` as the lowering converts (an integer from a
    double rounds toward zero, `fptosi`; a double from an integer, `sitofp`): the carry's
    counters travel as doubles in the buffers and as integers in the loop."""
    if src == dst:
        return value
    if src == "double":
        return builder.fptosi(value, ir_type(dst, lanes))
    if dst == "double":
        return builder.sitofp(value, ir_type(dst, lanes))
    raise ValueError(f"convert: {src} to {dst}")


class Program:
    """The skeleton module under construction (`module`, an `llvmlite.ir.Module`) and the bodies it calls."""

    def __init__(self, name: str = "gnipy"):
        from llvmlite import ir

        self.module = ir.Module(name)
        self.module.triple = ""  # LLVM's target machine supplies the CPU (gnipy.native.program)
        self.module.data_layout = ""
        self._bodies: list[str] = []
        self._decls: set[str] = set()

    def body(self, fn, name: str, results: list, types: list[str]):
        """End the body that `fn` (a :class:`~gnipy.native.scalars.Function`) holds, returning
        `results` cast to `types` (:meth:`~gnipy.native.scalars.Function.define`), add it to the
        program, and return its declaration in the skeleton (an `llvmlite.ir.Function` to call,
        whose result is a struct: `builder.extract_value(result, j)`)."""
        from llvmlite import ir

        self._bodies.append(fn.define(name, results, types))
        self._decls |= fn.decls
        ret = ir.LiteralStructType([ir_type(ty, fn.lanes) for ty in types])
        return ir.Function(self.module, ir.FunctionType(ret, [ir_type(r.ty, fn.lanes) for r in fn.params]), name)

    def function(self, name: str, args: list[tuple[str, str, bool]]):
        """A new exported function of the skeleton returning nothing: `args` are `(name, type,
        noalias)` with type "ptr", "double" or "i64". Returns `(function, builder)`, the builder
        at the end of its entry block."""
        from llvmlite import ir

        types = [ir.PointerType() if ty == "ptr" else ir_type(ty) for _, ty, _ in args]
        f = ir.Function(self.module, ir.FunctionType(ir.VoidType(), types), name)
        for a, (arg_name, _, noalias) in zip(f.args, args):
            a.name = arg_name
            if noalias:
                a.add_attribute("noalias")
        return f, ir.IRBuilder(f.append_basic_block("entry"))

    @property
    def texts(self) -> tuple[str, str]:
        """The LLVM IR of the program: the skeleton's module, then the bodies' (to link into it)."""
        bodies = "\n".join(sorted(self._decls)) + "\n\n" + "\n".join(self._bodies)
        return str(self.module), bodies
