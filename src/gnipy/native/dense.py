"""Dense linear algebra of the native lowering, written out for the matrix's size: LAPACK's
`lu` (partial pivoting as getf2: the first largest pivot), `triangular_solve` in every variant,
and `sort` of one short key (ranks in XLA's total order)."""

from __future__ import annotations

import numpy as np

from .rules import rule
from .scalars import Const, Unsupported

__all__: list[str] = []


@rule("lu")
def _lu(fn, eqn, ins):
    a = ins[0]
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise Unsupported("lu of a batched or non-square matrix")
    n = a.shape[0]
    A = [[a[i, j] for j in range(n)] for i in range(n)]
    perm = [Const(i, "i32") for i in range(n)]
    piv = []
    for k in range(n):
        # the pivot: the first row of largest |a_ik| (LAPACK's idamax); NaN never wins
        best, p = fn.unary("abs", A[k][k]), Const(k, "i32")
        for i in range(k + 1, n):
            c = fn.unary("abs", A[i][k])
            take = fn.cmp("gt", c, best)
            best, p = fn.select(take, c, best), fn.select(take, Const(i, "i32"), p)
        piv.append(p)
        if isinstance(p, Const):
            r = int(p.value)
            A[k], A[r] = A[r], A[k]
            perm[k], perm[r] = perm[r], perm[k]
        else:
            rows = [A[i] for i in range(k, n)]
            newk = [fn.lookup([row[j] for row in rows], fn.binary("sub", p, Const(k, "i32"))) for j in range(n)]
            pk = fn.lookup(perm[k:], fn.binary("sub", p, Const(k, "i32")))
            for i in range(k + 1, n):
                hit = fn.cmp("eq", p, Const(i, "i32"))
                A[i] = [fn.select(hit, A[k][j], A[i][j]) for j in range(n)]
                perm[i] = fn.select(hit, perm[k], perm[i])
            A[k], perm[k] = newk, pk
        d = A[k][k]
        for i in range(k + 1, n):
            m = fn.binary("div", A[i][k], d)
            A[i][k] = m
            for j in range(k + 1, n):
                A[i][j] = fn.binary("sub", A[i][j], fn.binary("mul", m, A[k][j]))
    out = np.empty((n, n), dtype=object)
    for i in range(n):
        for j in range(n):
            out[i, j] = A[i][j]
    piv_a, perm_a = np.empty(n, dtype=object), np.empty(n, dtype=object)
    for i in range(n):
        piv_a[i], perm_a[i] = piv[i], perm[i]
    return [out, piv_a, perm_a]


@rule("triangular_solve")
def _triangular_solve(fn, eqn, ins):
    a, b = ins
    p = eqn.params
    if a.ndim != 2 or b.ndim != 2:
        raise Unsupported("batched triangular_solve")
    lower, unit = bool(p["lower"]), bool(p["unit_diagonal"])
    A = a.T if p["transpose_a"] else a
    if p["transpose_a"]:
        lower = not lower
    if not p["left_side"]:
        # x A = b  <=>  Aᵀ xᵀ = bᵀ
        A, b, lower = A.T, b.T, not lower
    n, k = b.shape
    x = np.empty((n, k), dtype=object)
    order = range(n) if lower else range(n - 1, -1, -1)
    for c in range(k):
        for i in order:
            s = b[i, c]
            js = range(i) if lower else range(i + 1, n)
            for j in js:
                s = fn.binary("sub", s, fn.binary("mul", A[i, j], x[j, c]))
            x[i, c] = s if unit else fn.binary("div", s, A[i, i])
    return [x if p["left_side"] else x.T]


@rule("sort")
def _sort(fn, eqn, ins):
    if len(ins[0].shape) != 1 or eqn.params["num_keys"] != 1 or ins[0].shape[0] > 16:
        raise Unsupported("sort beyond one short key")
    keys = list(ins[0])
    n = len(keys)
    if keys and keys[0].ty == "double":  # XLA's total order (-NaN < -inf < -0 < +0 < inf < NaN) as integers
        keys = [fn.total_order_key(k) for k in keys]
    # the rank of each element (stable): r_i = #{j : k_j < k_i or (k_j == k_i and j < i)}
    ranks = []
    for i in range(n):
        r = Const(0, "i64")
        for j in range(n):
            if j == i:
                continue
            before = fn.cmp("lt", keys[j], keys[i])
            if j < i:
                before = fn.logic("or", before, fn.cmp("eq", keys[j], keys[i]))
            r = fn.binary("add", r, fn.cast(before, "i64"))
        ranks.append(r)
    outs = []
    for arr in ins:
        vals = list(arr)
        res = np.empty(n, dtype=object)
        for pos in range(n):
            v = vals[0]
            for i in range(1, n):
                v = fn.select(fn.cmp("eq", ranks[i], Const(pos, "i64")), vals[i], v)
            res[pos] = v
        outs.append(res)
    return outs
