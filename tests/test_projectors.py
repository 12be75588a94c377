"""The projectors of paper §2 and the reflection (Comb), on random metrics and constraints."""

import jax.numpy as jnp
import numpy as np
import pytest

from gnipy import projectors, reflect_momentum, reported_momentum


def _random_data(seed, n=5, m=2):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    G = A @ A.T + n * np.eye(n)
    mu = rng.standard_normal((m, n))
    Pi = rng.standard_normal(n)
    p = rng.standard_normal(n)
    return G, mu, Pi, p


@pytest.mark.parametrize("seed", range(5))
def test_projector_identities(seed):
    G, mu, Pi, p = _random_data(seed)
    P, Q = (np.asarray(x) for x in projectors(jnp.asarray(G), jnp.asarray(mu)))
    n = G.shape[0]
    np.testing.assert_allclose(P + Q, np.eye(n), atol=1e-14)
    np.testing.assert_allclose(P @ P, P, atol=1e-12)
    np.testing.assert_allclose(Q @ Q, Q, atol=1e-12)
    np.testing.assert_allclose(P @ Q, 0, atol=1e-12)
    np.testing.assert_allclose(mu @ P, 0, atol=1e-12)  # P maps onto D = ker μ
    np.testing.assert_allclose(P.T @ G @ Q, 0, atol=1e-12)  # G-orthogonal splitting
    # Q's range is D^⊥ = G⁻¹ range μᵀ
    Z = np.linalg.solve(G, mu.T)
    np.testing.assert_allclose(Q @ Z, Z, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_reflection(seed):
    G, mu, Pi, p_plus = _random_data(seed)
    P, Q = (np.asarray(x) for x in projectors(jnp.asarray(G), jnp.asarray(mu)))
    p_minus = np.asarray(reflect_momentum(jnp.asarray(G), jnp.asarray(mu), jnp.asarray(Pi), jnp.asarray(p_plus)))
    # (GNIintAffa) and (GNIintAffb)
    np.testing.assert_allclose(P.T @ (p_minus - p_plus), 0, atol=1e-12)
    np.testing.assert_allclose(Q.T @ ((p_minus + p_plus) / 2 - Pi), 0, atol=1e-12)
    # the reflection of p − Π is an isometry of the G⁻¹ norm
    Ginv = np.linalg.inv(G)
    a, b = p_plus - Pi, p_minus - Pi
    assert abs(a @ Ginv @ a - b @ Ginv @ b) < 1e-12 * (a @ Ginv @ a)
    p_bar = np.asarray(reported_momentum(jnp.asarray(G), jnp.asarray(mu), jnp.asarray(Pi), jnp.asarray(p_plus)))
    np.testing.assert_allclose(p_bar, (p_minus + p_plus) / 2, atol=1e-12)
    np.testing.assert_allclose(mu @ Ginv @ (p_bar - Pi), 0, atol=1e-12)
