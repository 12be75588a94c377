"""The projectors of paper §2 and the GNI reflection (equation (Comb)).

With $C = \\mu \\mathbb{G}^{-1} \\mu^T$: $Q = \\mathbb{G}^{-1} \\mu^T C^{-1} \\mu$ and $P = I - Q$ act on
velocities ((proQ), (proP)); on momenta their transposes $P^* = P^T$, $Q^* = Q^T$ act.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["projectors", "reflect_momentum", "reported_momentum"]


def projectors(G, mu):
    """Velocity projectors `(P, Q)` onto $\\mathcal{D}$ and $\\mathcal{D}^\\perp$ ($\\mathbb{G}$-orthogonal).

    Arguments:
        G: metric, (n, n) symmetric positive definite.
        mu: constraint one-forms, (m, n) of full row rank.

    Returns:
        `(P, Q)`, both (n, n), with $P + Q = I$, $P^2 = P$, $\\mu P = 0$.
    """
    Ginv_muT = jnp.linalg.solve(G, mu.T)  # G⁻¹μᵀ (n, m)
    C = mu @ Ginv_muT  # (m, m)
    Q = Ginv_muT @ jnp.linalg.solve(C, mu)
    P = jnp.eye(G.shape[0], dtype=Q.dtype) - Q
    return P, Q


def _Qstar(G, mu, p):
    """$Q^* p = \\mu^T C^{-1} \\mu \\mathbb{G}^{-1} p$ without forming matrices."""
    Ginv_p = jnp.linalg.solve(G, p)
    C = mu @ jnp.linalg.solve(G, mu.T)
    return mu.T @ jnp.linalg.solve(C, mu @ Ginv_p)


def reflect_momentum(G, mu, Pi, p_plus):
    """The reflection (Comb) of the GNI: $p^- = (P^* - Q^*) p^+ + 2 Q^* \\Pi$.

    Equivalent to $P^*(p^- - p^+) = 0$ and $Q^*((p^- + p^+)/2 - \\Pi) = 0$ ((GNIintAffa/b)).
    """
    return p_plus - 2.0 * _Qstar(G, mu, p_plus - Pi)


def reported_momentum(G, mu, Pi, p_plus):
    """The momentum reported at a node: $\\bar p = (p^- + p^+)/2 = P^* p^+ + Q^* \\Pi$.

    It satisfies the constraints $\\mu \\mathbb{G}^{-1} (\\bar p - \\Pi) = 0$ exactly.
    """
    return p_plus - _Qstar(G, mu, p_plus - Pi)
