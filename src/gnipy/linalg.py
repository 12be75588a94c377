"""Small dense linear solves, unrolled into elementwise XLA operations.

Why this is written by hand: a GNI step on a mechanical system of a few degrees of freedom solves a
handful of N×N systems with N ≤ 10. On CPU, `jnp.linalg.solve` lowers to a LAPACK custom call
that costs about 0.8 µs *per call* whatever the size (measured on the 2-core CI machine), which is
several times the arithmetic of a 5×5 solve and would dominate a step of about 1 µs. Unrolling
the elimination at trace time (static N) gives XLA plain scalar arithmetic that it fuses with the
rest of the step (measured 0.25 µs for a 5×5 SPD solve, 0.38 µs with partial pivoting). No
well-kept library offers this (lineax and jax.scipy both call LAPACK on CPU). Above
:data:`UNROLL_MAX` unknowns the LAPACK path is used.

Both functions accept a right-hand side `b` of shape (N,) or (N, K) and work under `jit`,
`vmap` and automatic differentiation (they are ordinary jnp code). Inside a program each is traced
once per shape (:func:`gnipy.compilation.traced_once`): a step solves with the metric several times.
"""

from __future__ import annotations

import jax.numpy as jnp

from .compilation import traced_once

__all__ = ["solve", "solve_spd", "UNROLL_MAX"]

#: Largest N for which the elimination is unrolled (beyond it the trace grows as N³).
UNROLL_MAX = 12


def _as_matrix_rhs(b, n):
    if b.ndim == 1:
        return b.reshape(n, 1), True
    return b, False


@traced_once
def solve_spd(A, b):
    """Solve $A x = b$ for a symmetric positive definite (or any matrix that needs no pivoting,
    e.g. diagonally dominant) A: Gaussian elimination without pivoting, unrolled for N ≤ 12.

    Arguments:
        A: (N, N).
        b: (N,) or (N, K).

    Returns:
        x with the shape of `b`.
    """
    n = A.shape[-1]
    if n > UNROLL_MAX:
        return jnp.linalg.solve(A, b)
    B, vec = _as_matrix_rhs(b, n)
    a = [[A[i, j] for j in range(n)] for i in range(n)]
    y = [B[i] for i in range(n)]
    for k in range(n):
        inv = 1.0 / a[k][k]
        for i in range(k + 1, n):
            f = a[i][k] * inv
            for j in range(k + 1, n):
                a[i][j] = a[i][j] - f * a[k][j]
            y[i] = y[i] - f * y[k]
    x = [None] * n
    for k in range(n - 1, -1, -1):
        s = y[k]
        for j in range(k + 1, n):
            s = s - a[k][j] * x[j]
        x[k] = s / a[k][k]
    X = jnp.stack(x)
    return X[:, 0] if vec else X


@traced_once
def solve(A, b):
    """Solve $A x = b$ for a general regular A: Gaussian elimination with partial pivoting, unrolled
    for N ≤ 12 (row exchanges by selects, so no gathers).

    Arguments:
        A: (N, N).
        b: (N,) or (N, K).

    Returns:
        x with the shape of `b` (non-finite when A is singular, as with LAPACK).
    """
    n = A.shape[-1]
    if n > UNROLL_MAX:
        return jnp.linalg.solve(A, b)
    B, vec = _as_matrix_rhs(b, n)
    M = jnp.concatenate([A, B.astype(jnp.result_type(A, B))], axis=1)
    rows = jnp.arange(n)
    for k in range(n - 1):
        col = jnp.where(rows >= k, jnp.abs(M[:, k]), -1.0)
        piv = jnp.argmax(col)
        is_piv = (rows == piv)[:, None]
        row_p = jnp.sum(jnp.where(is_piv, M, 0.0), axis=0)
        row_k = M[k]
        M = jnp.where((rows == k)[:, None], row_p[None], jnp.where(is_piv, row_k[None], M))
        f = jnp.where(rows > k, M[:, k] / M[k, k], 0.0)
        M = M - f[:, None] * M[k][None, :]
    x = [None] * n
    for k in range(n - 1, -1, -1):
        s = M[k, n:]
        for j in range(k + 1, n):
            s = s - M[k, j] * x[j]
        x[k] = s / M[k, k]
    X = jnp.stack(x)
    return X[:, 0] if vec else X
