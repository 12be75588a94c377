"""The lowering rules' registry and the jaxpr walk of the native lowering: the bottom of the
translator, below the modules that hold the rules.

A rule lowers one JAX primitive: `rule(fn, eqn, ins) -> outs`, with `fn` the
:class:`~gnipy.native.scalars.Function` being written, `eqn` the jaxpr equation and `ins`, `outs`
its inputs and outputs as object arrays of scalars. The modules of rules register theirs here
with :func:`rule` when they are imported: arrays, arithmetic and indexing in
:mod:`gnipy.native.lowering`, calls and control flow in :mod:`gnipy.native.control`, dense
linear algebra in :mod:`gnipy.native.dense`. :mod:`gnipy.native.lowering` imports the other two,
so its :func:`~gnipy.native.lowering.lower_jaxpr` (this walk) knows every rule; the rules of
calls and loops walk their inner jaxprs with :func:`lower_jaxpr` and :func:`lower_closed`.
"""

from __future__ import annotations

import numpy as np

from .scalars import Function, Unsupported, const_array, llvm_type

__all__ = ["RULES", "rule", "lowered_primitives", "lower_jaxpr", "lower_closed"]

#: The lowering rule of each primitive, by the primitive's name.
RULES: dict = {}


def rule(*names):
    """Decorator: register the decorated function as the lowering rule of the primitives `names`."""
    def deco(f):
        for n in names:
            RULES[n] = f
        return f
    return deco


def lowered_primitives() -> frozenset[str]:
    """The names of the primitives with a lowering rule (registered so far: import
    :mod:`gnipy.native.lowering` for all of them)."""
    return frozenset(RULES)


def lower_jaxpr(fn: Function, jaxpr, consts, args) -> list:
    """Emit `jaxpr` (a `Jaxpr`) into `fn` with `consts` and `args` (object arrays of scalars);
    returns its outputs (object arrays). A primitive without a rule, or one its rule cannot
    lower, raises :class:`~gnipy.native.scalars.Unsupported`."""
    env = {}

    def read(v):
        if type(v).__name__ == "Literal":  # jax.extend.core.Literal (its home moved between JAX versions)
            return const_array(v.val, llvm_type(v.aval.dtype))
        return env[v]

    for v, x in zip(jaxpr.constvars, consts):
        env[v] = x
    for v, x in zip(jaxpr.invars, args):
        env[v] = x
    for eqn in jaxpr.eqns:
        lower = RULES.get(eqn.primitive.name)
        if lower is None:
            raise Unsupported(f"primitive {eqn.primitive.name!r}")
        for o in eqn.outvars:
            llvm_type(o.aval.dtype)
        outs = lower(fn, eqn, [read(v) for v in eqn.invars])
        for v, o in zip(eqn.outvars, outs):
            if type(v).__name__ != "DropVar":
                o = np.asarray(o, dtype=object)
                if o.shape != tuple(v.aval.shape):
                    o = np.reshape(o, v.aval.shape)
                env[v] = o
    return [read(v) for v in jaxpr.outvars]


def lower_closed(fn: Function, closed, args) -> list:
    """:func:`lower_jaxpr` of a `ClosedJaxpr` (its constants become :class:`~gnipy.native.scalars.Const`)."""
    return lower_jaxpr(fn, closed.jaxpr, [const_array(c) for c in closed.consts], args)
