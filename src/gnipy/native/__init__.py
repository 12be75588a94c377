"""The native CPU backend: a method's step, traced from JAX and compiled by LLVM to scalar machine
code (:mod:`gnipy.native.lowering`, :mod:`gnipy.native.program`)."""

from .lowering import Unsupported
from .engine import available, cache_dir, cores
from .program import NativeLoop, build_loop

__all__ = ["Unsupported", "NativeLoop", "available", "build_loop", "cache_dir", "cores"]
