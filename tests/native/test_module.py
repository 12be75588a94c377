"""The contract between a native program's skeleton (llvmlite.ir) and its bodies (text): a body is
inlined where it is called and dropped; a call that does not match the body's signature is refused
(LLVM's linker alone would link it); the skeleton's conversions of the carry are the lowering's."""

import ctypes

import numpy as np
import pytest

from gnipy.native import engine as native_engine
from gnipy.native.module import Program, convert, ir_type
from gnipy.native.scalars import Function

BODY = """define linkonce_odr {double, i32} @body(double %arg0, i32 %arg1) alwaysinline {
entry:
  %t1 = fmul double %arg0, 0x4000000000000000
  %t2 = insertvalue {double, i32} poison, double %t1, 0
  %t3 = insertvalue {double, i32} %t2, i32 %arg1, 1
  ret {double, i32} %t3
}
"""


def _skeleton(declared: str, call: str) -> str:
    return f"""declare {declared}
define double @gnipy_f(double %x) {{
  %r = call {call}
  %v = extractvalue {{double, i32}} %r, 0
  ret double %v
}}
"""


def test_a_body_is_inlined_and_dropped():
    ok = _skeleton("{double, i32} @body(double, i32)", "{double, i32} @body(double %x, i32 7)")
    obj = native_engine.compile_ir((ok, BODY))
    assert obj and b"body" not in obj


def test_a_call_that_does_not_match_the_body_is_refused():
    wrong = _skeleton("{double, i32} @body(double)", "{double, i32} @body(double %x)")
    with pytest.raises(RuntimeError, match="not inlined"):
        native_engine.compile_ir((wrong, BODY))


def test_a_program_of_a_function_body_runs():
    """A body written by Function, called from a skeleton built with llvmlite.ir: x -> (x·x, 2x as i32)."""
    prog = Program("test")
    fn = Function()
    (x,) = fn.arguments(["double"])
    body = prog.body(fn, "twice", [fn.binary("mul", x, x), fn.binary("add", x, x)], ["double", "i32"])
    f, b = prog.function("gnipy_t", [("io", "ptr", True)])
    f64 = ir_type("double")
    at = [b.gep(f.args[0], [ir_type("i64")(j)], source_etype=f64) for j in range(3)]
    r = b.call(body, [b.load(at[0], typ=f64)])
    b.store(b.extract_value(r, 0), at[1])
    b.store(convert(b, b.extract_value(r, 1), "i32", "double"), at[2])
    b.ret_void()
    engine, source, _ = native_engine.load_program(prog.texts)
    io = np.array([1.75, 0.0, 0.0])
    ctypes.CFUNCTYPE(None, ctypes.c_void_p)(engine.get_function_address("gnipy_t"))(io.ctypes.data)
    # 2·1.75 = 3.5 as i32 rounds toward zero, as the lowering converts (fptosi)
    np.testing.assert_array_equal(io, [1.75, 1.75 * 1.75, 3.0])
