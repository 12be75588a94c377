"""Calls and control flow of the native lowering: calls inlined (`jit`, `custom_jvp_call`,
`custom_vjp_call`, remat, `custom_linear_solve`'s solve), `while` as a loop with phi nodes (with
lanes: running while any lane's condition holds, updating only those lanes), `cond` as a branch
(with lanes: every branch, then each lane's), `scan` as a counted loop or, short with stacked
values, unrolled."""

from __future__ import annotations

import numpy as np

from .rules import lower_closed, lower_jaxpr, rule
from .scalars import Const, Unsupported, flatten, unflatten

__all__ = ["emit_loop"]


@rule("pjit", "jit", "closed_call", "core_call", "custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr",
       "remat", "checkpoint", "custom_lin")
def _call(fn, eqn, ins):
    p = eqn.params
    inner = p.get("jaxpr") or p.get("call_jaxpr") or p.get("fun_jaxpr")
    if inner is None:
        raise Unsupported(f"{eqn.primitive.name} without a jaxpr")
    n_args = len(inner.jaxpr.invars) if hasattr(inner, "jaxpr") else len(inner.invars)
    args = ins[len(ins) - n_args:] if eqn.primitive.name.startswith("custom_vjp") else ins
    if hasattr(inner, "consts"):
        return lower_closed(fn, inner, args)
    return lower_jaxpr(fn, inner, [], args)


@rule("custom_linear_solve")
def _linear_solve(fn, eqn, ins):
    lens = eqn.params["const_lengths"]
    jaxprs = eqn.params["jaxprs"]
    start = lens.matvec + lens.vecmat
    consts = ins[start:start + lens.solve]
    b = ins[lens.matvec + lens.vecmat + lens.solve + lens.transpose_solve:]
    return lower_closed(fn, jaxprs.solve, list(consts) + list(b))


def emit_loop(fn, init: list, cond, body):
    """A loop over the carried arrays `init`: `cond(carry) -> i1 scalar`, `body(carry) -> carry`.
    Returns the carry at exit."""
    flat0, shapes = flatten(init)
    pre = fn.block
    head, body_l, exit_l = fn.label("head"), fn.label("body"), fn.label("exit")
    fn.br(head)
    fn.start(head)
    regs, phis = fn.open_phis([v.ty for v in flat0])
    carry = unflatten(regs, shapes)
    c = cond(carry)
    if isinstance(c, Const) and not bool(c.value):  # the loop never runs
        fn.br(exit_l)
        fn.close_phis(regs, phis, [[(v, pre)] for v in flat0])
        fn.start(exit_l)
        return unflatten(flat0, shapes)
    fn.condbr(fn.any(c), body_l, exit_l)
    fn.start(body_l)
    new_flat, _ = flatten(body(carry))
    if fn.lanes > 1 and not isinstance(c, Const):  # only the lanes whose condition holds move on
        new_flat = [fn.select(c, n, r) for n, r in zip(new_flat, regs)]
    end = fn.block
    fn.br(head)
    fn.close_phis(regs, phis, [[(v, pre), (n, end)] for v, n in zip(flat0, new_flat)])
    fn.start(exit_l)
    return carry


@rule("while")
def _while(fn, eqn, ins):
    p = eqn.params
    cn, bn = p["cond_nconsts"], p["body_nconsts"]
    cconsts, bconsts, init = ins[:cn], ins[cn:cn + bn], ins[cn + bn:]

    def cond(carry):
        return lower_closed(fn, p["cond_jaxpr"], list(cconsts) + list(carry))[0][()]

    def body(carry):
        return lower_closed(fn, p["body_jaxpr"], list(bconsts) + list(carry))

    return emit_loop(fn, list(init), cond, body)


@rule("cond")
def _cond(fn, eqn, ins):
    branches = eqn.params["branches"]
    index, args = ins[0][()], ins[1:]
    if isinstance(index, Const):
        j = min(max(int(index.value), 0), len(branches) - 1)
        return lower_closed(fn, branches[j], list(args))
    if fn.lanes > 1:  # every branch, then each lane's (as jax.vmap runs a cond)
        outs = [flatten(lower_closed(fn, br, list(args))) for br in branches]
        (acc, shapes) = outs[-1]
        for j in range(len(branches) - 2, -1, -1):
            pick = fn.not_(index) if index.ty == "i1" else fn.cmp("le", index, Const(j, index.ty))
            acc = [fn.select(pick, x, y) for x, y in zip(outs[j][0], acc)]
        return unflatten(acc, shapes)
    labels = [fn.label("case") for _ in branches]
    merge = fn.label("merge")
    if index.ty == "i1":
        fn.condbr(index, labels[1], labels[0])
    else:
        fn.switch(index, labels[-1], labels[:-1])
    results = []
    for lab, br in zip(labels, branches):
        fn.start(lab)
        outs = lower_closed(fn, br, list(args))
        results.append((flatten(outs), fn.block))
        fn.br(merge)
    fn.start(merge)
    (flat0, shapes), _ = results[0]
    merged = []
    for i, v in enumerate(flat0):
        incoming = [(res[0][0][i], blk) for res, blk in ((r, r[1]) for r in results)]
        if all(x is incoming[0][0] for x, _ in incoming):
            merged.append(incoming[0][0])
            continue
        merged.append(fn.phi(v.ty, incoming))
    return unflatten(merged, shapes)


@rule("scan")
def _scan(fn, eqn, ins):
    p = eqn.params
    nc, ncar, length = p["num_consts"], p["num_carry"], int(p["length"])
    consts, init, xs = ins[:nc], ins[nc:nc + ncar], ins[nc + ncar:]
    n_ys = len(eqn.outvars) - ncar
    body = p["jaxpr"]
    if not xs and not n_ys:
        counter = np.empty((), dtype=object)
        counter[()] = Const(0, "i64")

        def cond(carry):
            return fn.cmp("lt", carry[0][()], Const(length, "i64"))

        def step(carry):
            out = lower_closed(fn, body, list(consts) + list(carry[1:]))
            k = np.empty((), dtype=object)
            k[()] = fn.binary("add", carry[0][()], Const(1, "i64"))
            return [k] + list(out)

        return emit_loop(fn, [counter] + list(init), cond, step)[1:]
    if length > 64:
        raise Unsupported("scan with stacked inputs or outputs over more than 64 steps")
    carry, ys = list(init), []
    order = range(length - 1, -1, -1) if p["reverse"] else range(length)
    for i in order:
        out = lower_closed(fn, body, list(consts) + carry + [x[i] for x in xs])
        carry, y = out[:ncar], out[ncar:]
        ys.append((i, y))
    ys.sort(key=lambda t: t[0])
    stacked = [np.stack([y[j] for _, y in ys]) for j in range(n_ys)]
    return carry + stacked
