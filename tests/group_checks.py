"""Helpers shared by the tests of the Lie groups, the retractions and the property-based tests:
a reference matrix exponential independent of the groups' closed forms, the distance of a matrix
from a group, and a compile-once runner for check functions."""

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import block_diag

from gnipy.compilation import compiler_options
from gnipy.lie_groups import SE2, SO3, ProductGroup, Rn, TrivialGroup


def series_expm(X, *, squarings: int, terms: int):
    """exp(X) by the Taylor series of $e^{X/2^s}$ with `terms` terms, squared s = `squarings` times:
    independent of the groups' closed forms, round-off accurate for |X| up to about 2^s (cheaper
    to compile than `jax.scipy.linalg.expm`)."""
    A = X / 2**squarings
    eye = jnp.eye(X.shape[0], dtype=X.dtype)
    out = eye
    for j in range(terms, 0, -1):
        out = eye + A @ out / j
    for _ in range(squarings):
        out = out @ out
    return out


def membership_error(group, g):
    """Distance of the matrix g from the group (0 for an exact element)."""
    if isinstance(group, SO3):
        return jnp.maximum(jnp.abs(g.T @ g - jnp.eye(3)).max(), jnp.abs(jnp.linalg.det(g) - 1.0))
    if isinstance(group, SE2):
        R = g[:2, :2]
        return jnp.max(
            jnp.stack(
                [
                    jnp.abs(R.T @ R - jnp.eye(2)).max(),
                    jnp.abs(jnp.linalg.det(R) - 1.0),
                    jnp.abs(g[2] - jnp.array([0.0, 0.0, 1.0])).max(),
                ]
            )
        )
    if isinstance(group, Rn):
        n = group.n
        return jnp.maximum(jnp.abs(g[:n, :n] - jnp.eye(n)).max(), jnp.abs(g[n] - jnp.eye(n + 1)[n]).max())
    if isinstance(group, TrivialGroup):
        return jnp.abs(g - 1.0).max()
    if isinstance(group, ProductGroup):
        blocks = group.blocks(g)
        off = jnp.abs(g - block_diag(*blocks)).max()
        return jnp.max(jnp.stack([off] + [membership_error(f, b) for f, b in zip(group.factors, blocks)]))
    raise TypeError(type(group))


def run_once(f, *args):
    """Compile and run a check function once, with XLA's backend (LLVM) optimizations off and gnipy's
    own compiler options (:func:`gnipy.compilation.compiler_options`: the CPU fusion emitters off).

    The checks run once, so their compile time dominates; level 0 compiles about twice as fast and
    keeps IEEE semantics (the tolerances are far above any difference in instruction selection), and
    without the fusion emitters the largest check function (the retractions' derivatives on the
    product group) compiles in 2.7 s instead of 5.8 s.
    """
    options = {**compiler_options(), "xla_backend_optimization_level": 0}
    compiled = jax.jit(f).lower(*args).compile(compiler_options=options)
    return compiled(*args)


def maxabs(x):
    """max |x| (0 for an empty array)."""
    return jnp.abs(x).max() if x.size else jnp.zeros(())


def factorwise_samples(group, magnitudes, n_directions, rng, *, roll=3):
    """Algebra samples of a :class:`ProductGroup` in which every factor's block takes each of
    `magnitudes` as its own norm (so that each factor sits on both sides of each of its Taylor
    switches, as in a check of that factor alone), in random directions. The i-th factor's
    magnitudes are rolled by `roll`·i, so that the factors sit on different branches at once
    (`roll=0`: every factor at the same magnitude, e.g. all exactly 0 in the first sample).

    Returns the samples, shape (len(magnitudes) * n_directions, group.dim), and each sample's
    largest factor norm (the scale of O(|ξ|) bounds, per factor as for a single group)."""
    magnitudes = np.asarray(magnitudes, dtype=np.float64)
    blocks = []
    for _ in range(n_directions):
        parts = []
        for i, factor in enumerate(group.factors):
            u = rng.standard_normal((len(magnitudes), factor.dim))
            if factor.dim:
                u /= np.linalg.norm(u, axis=1, keepdims=True)
            parts.append(np.roll(magnitudes, -roll * i)[:, None] * u)
        blocks.append(np.concatenate(parts, axis=1))
    xi = np.concatenate(blocks)
    return xi, factor_norms(group, xi).max(axis=1)


def factor_norms(group, xi):
    """|ξ_f| of every factor f of a ProductGroup (0 for a factor of dimension 0), shape (..., factors)."""
    xi = np.asarray(xi)
    out, start = [], 0
    for factor in group.factors:
        out.append(np.linalg.norm(xi[..., start:start + factor.dim], axis=-1))
        start += factor.dim
    return np.stack(out, axis=-1)


def factorwise_relative(group, err, xi):
    """max over the factors f of |err_f|_∞ / |ξ_f| (err and ξ vectors of the algebra): a relative
    error per factor, as a check of each factor alone would measure it (traceable)."""
    worst = jnp.zeros(())
    for e, x in zip(group.split(err), group.split(xi)):
        if x.size:
            worst = jnp.maximum(worst, maxabs(e) / jnp.maximum(jnp.linalg.norm(x), 1e-300))
    return worst
