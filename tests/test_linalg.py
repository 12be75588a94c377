"""The unrolled solves of gnipy.linalg against LAPACK (NumPy) on matrices that need no pivoting."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.linalg import UNROLL_MAX, solve_spd

EPS = np.finfo(np.float64).eps


def _spd(n, seed):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    return A @ A.T + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 2, 5, UNROLL_MAX, UNROLL_MAX + 1])
def test_solve_spd_gives_the_inverse_to_round_off(n):
    """Unrolled up to UNROLL_MAX (the chord iteration's inverse, the pivots' reciprocals in the back
    substitution), LAPACK above; both within round-off of NumPy's inverse, scaled by the condition."""
    A = _spd(n, n)
    X = np.asarray(jax.jit(lambda A: solve_spd(A, jnp.eye(n)))(jnp.asarray(A)))
    reference = np.linalg.inv(A)
    assert np.max(np.abs(X - reference)) <= 50 * n * EPS * np.linalg.cond(A) * np.max(np.abs(reference))
    assert np.max(np.abs(X @ A - np.eye(n))) <= 50 * n * EPS * np.linalg.cond(A)


def test_solve_spd_on_one_and_on_several_right_hand_sides():
    A = _spd(7, 3)
    B = np.random.default_rng(4).standard_normal((7, 3))
    x = np.asarray(jax.jit(solve_spd)(jnp.asarray(A), jnp.asarray(B[:, 0])))
    X = np.asarray(jax.jit(solve_spd)(jnp.asarray(A), jnp.asarray(B)))
    assert x.shape == (7,) and X.shape == (7, 3)
    np.testing.assert_allclose(x, np.linalg.solve(A, B[:, 0]), rtol=1e-13, atol=0)
    np.testing.assert_allclose(X, np.linalg.solve(A, B), rtol=1e-13, atol=0)
