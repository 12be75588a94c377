"""Helpers shared by the tests of the Lie groups, the retractions and the property-based tests:
a reference matrix exponential independent of the groups' closed forms, the distance of a matrix
from a group, and a compile-once runner for check functions."""

import jax
import jax.numpy as jnp
from jax.scipy.linalg import block_diag

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
    """Compile and run a check function once, with XLA's backend (LLVM) optimizations off.

    The checks run once, so their compile time dominates; level 0 compiles about twice as fast and
    keeps IEEE semantics (the tolerances are far above any difference in instruction selection).
    """
    compiled = jax.jit(f).lower(*args).compile(compiler_options={"xla_backend_optimization_level": 0})
    return compiled(*args)


def maxabs(x):
    """max |x| (0 for an empty array)."""
    return jnp.abs(x).max() if x.size else jnp.zeros(())
