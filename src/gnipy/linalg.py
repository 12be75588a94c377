"""Small dense linear solves, unrolled into elementwise XLA operations.

Why this is written by hand: a GNI step on a mechanical system of a few degrees of freedom solves a
handful of N×N systems with N ≤ 10. On CPU, `jnp.linalg.solve` lowers to a LAPACK custom call
that costs about 0.8 µs *per call* whatever the size (measured on the 2-core CI machine), which is
several times the arithmetic of a 5×5 solve and would dominate a step of about 1 µs. Unrolling
the elimination at trace time (static N) gives XLA plain scalar arithmetic that it fuses with the
rest of the step (measured 0.25 µs for a 5×5 SPD solve, 0.38 µs with partial pivoting). No
well-kept library offers this (lineax and jax.scipy both call LAPACK on CPU). Above
:data:`UNROLL_MAX` unknowns the LAPACK path is used.

:func:`solve` and :func:`solve_spd` accept a right-hand side `b` of shape (N,) or (N, K);
:func:`lu_factor` and :func:`lu_solve` factor once and solve many times (the chord iteration of a
step with many unknowns). All work under `jit`, `vmap` and automatic differentiation (they are
ordinary jnp code). Inside a program each is traced
once per shape (:func:`gnipy.compilation.traced_once`): a step solves with the metric several times.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax

from .compilation import traced_once

__all__ = ["solve", "solve_spd", "lu_factor", "lu_solve", "UNROLL_MAX", "LU_UNROLL_MAX"]

#: Largest N for which the elimination is unrolled (beyond it the trace grows as N³).
UNROLL_MAX = 12
#: Largest N for which :func:`lu_factor` is unrolled. The chord iteration of
#: :func:`gnipy.integrators.base.newton` factors its Jacobian once per step above UNROLL_MAX and
#: solves with the factors at each iteration: a third of the inverse's arithmetic, worth unrolling
#: further (the Whipple bicycle's DLA step, 13 unknowns: LAPACK's pivoted `lu`, which the native
#: backend writes out with a select per swapped entry, and its 13 right-hand sides cost 6 µs of a
#: 12 µs step, measured on the 2-core machine).
LU_UNROLL_MAX = 16


def _as_matrix_rhs(b, n):
    if b.ndim == 1:
        return b.reshape(n, 1), True
    return b, False


@traced_once
def solve_spd(A, b):
    """Solve $A x = b$ for a symmetric positive definite (or any matrix that needs no pivoting,
    e.g. diagonally dominant) A: Gaussian elimination without pivoting, unrolled for N ≤ 12.

    The back substitution multiplies by each pivot's reciprocal, which the elimination forms
    anyway, instead of dividing every right-hand side by the pivot (as LAPACK's `dgetf2` scales by
    1/pivot): a division costs several multiplications, and the chord iteration's 5 x 5 inverse
    took 25 of them (the native loop of the rolling ball's GNI step: 97 -> 51 divisions a step,
    docs/user-guide/native-design.md). With a matrix that stays the same from step to step (a
    constant metric) the reciprocal's rounding is the same at every step: a relative change of the
    matrix by at most one rounding, the size of the error its entries already carry.

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
    inv = [None] * n
    for k in range(n):
        inv[k] = 1.0 / a[k][k]
        for i in range(k + 1, n):
            f = a[i][k] * inv[k]
            for j in range(k + 1, n):
                a[i][j] = a[i][j] - f * a[k][j]
            y[i] = y[i] - f * y[k]
    x = [None] * n
    for k in range(n - 1, -1, -1):
        s = y[k]
        for j in range(k + 1, n):
            s = s - a[k][j] * x[j]
        x[k] = s * inv[k]
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


@traced_once
def lu_factor(A):
    """Factor $A = LDU$ once, for several solves with :func:`lu_solve`: Gaussian elimination
    without pivoting (as :func:`solve_spd`, for matrices that need none), unrolled for N ≤
    :data:`LU_UNROLL_MAX`; beyond it LAPACK's pivoted factorization (`jax.scipy.linalg.lu_factor`).

    The unrolled elimination works on the trailing block as a whole (an outer product per column),
    so XLA sees O(N) operations rather than O(N³) scalars; the native backend writes the same
    arithmetic out as scalars. The factors are the unit lower triangle L, the reciprocals of the
    pivots $D^{-1}$ and the unit upper triangle $D^{-1}U$: the solves multiply, no division on
    their chain of dependent operations, and each is one `triangular_solve` for XLA.

    Arguments:
        A: (N, N).

    Returns:
        the factors, an opaque tuple for :func:`lu_solve` (non-finite entries where a pivot is zero).
    """
    n = A.shape[-1]
    if n > LU_UNROLL_MAX:
        import jax.scipy.linalg as jsl

        return jsl.lu_factor(A)
    lower, upper, inv = [], [], []
    block = A
    for k in range(n):
        r = 1.0 / block[0, 0]
        m = block[1:, 0] * r
        pad = jnp.zeros(k + 1, dtype=A.dtype)
        lower.append(jnp.concatenate([pad, m]))
        upper.append(jnp.concatenate([pad, block[0, 1:] * r]))
        inv.append(r)
        block = block[1:, 1:] - m[:, None] * block[0, 1:][None, :]
    return jnp.stack(lower, axis=1), jnp.stack(inv), jnp.stack(upper)


@traced_once
def lu_solve(factors, b):
    """Solve $A x = b$ with the factors of :func:`lu_factor`: forward substitution with L, the
    pivots' reciprocals, back substitution with $D^{-1}U$.

    Arguments:
        factors: from :func:`lu_factor`.
        b: (N,).

    Returns:
        x, (N,).
    """
    if len(factors) == 2:  # LAPACK's factors (N > LU_UNROLL_MAX)
        import jax.scipy.linalg as jsl

        return jsl.lu_solve(factors, b)
    lower, inv, upper = factors
    y = lax.linalg.triangular_solve(lower, b[:, None], left_side=True, lower=True, unit_diagonal=True)
    return lax.linalg.triangular_solve(upper, y * inv[:, None], left_side=True, lower=False,
                                       unit_diagonal=True)[:, 0]
