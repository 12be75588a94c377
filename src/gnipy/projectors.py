"""The projectors of paper §2 and the GNI reflection (equation (Comb)).

With $C = \\mu \\mathbb{G}^{-1} \\mu^T$: $Q = \\mathbb{G}^{-1} \\mu^T C^{-1} \\mu$ and $P = I - Q$ act on
velocities ((proQ), (proP)); on momenta their transposes $P^* = P^T$, $Q^* = Q^T$ act.
"""

from __future__ import annotations

import jax.numpy as jnp

from .linalg import solve_spd

__all__ = ["projectors", "reflect_momentum", "reported_momentum", "Qstar", "reflect_and_report"]


def projectors(G, mu):
    """Velocity projectors `(P, Q)` onto $\\mathcal{D}$ and $\\mathcal{D}^\\perp$ ($\\mathbb{G}$-orthogonal).

    Arguments:
        G: metric, (n, n) symmetric positive definite.
        mu: constraint one-forms, (m, n) of full row rank.

    Returns:
        `(P, Q)`, both (n, n), with $P + Q = I$, $P^2 = P$, $\\mu P = 0$.
    """
    Ginv_muT = solve_spd(G, mu.T)  # G⁻¹μᵀ (n, m)
    C = mu @ Ginv_muT  # (m, m)
    Q = Ginv_muT @ solve_spd(C, mu)
    P = jnp.eye(G.shape[0], dtype=Q.dtype) - Q
    return P, Q


def Qstar(G, mu, p):
    """$Q^* p = \\mu^T C^{-1} \\mu \\mathbb{G}^{-1} p$ without forming matrices (G and C are SPD:
    one unrolled elimination for $\\mathbb{G}^{-1}[p, \\mu^T]$, one for C)."""
    X = solve_spd(G, jnp.concatenate([p[:, None], mu.T], axis=1))
    Ginv_p, Ginv_muT = X[:, 0], X[:, 1:]
    C = mu @ Ginv_muT
    return mu.T @ solve_spd(C, mu @ Ginv_p)


def reflect_momentum(G, mu, Pi, p_plus):
    """The reflection (Comb) of the GNI: $p^- = (P^* - Q^*) p^+ + 2 Q^* \\Pi$.

    Equivalent to $P^*(p^- - p^+) = 0$ and $Q^*((p^- + p^+)/2 - \\Pi) = 0$ ((GNIintAffa/b)).
    """
    return p_plus - 2.0 * Qstar(G, mu, p_plus - Pi)


def reported_momentum(G, mu, Pi, p_plus):
    """The momentum reported at a node: $\\bar p = (p^- + p^+)/2 = P^* p^+ + Q^* \\Pi$.

    It satisfies the constraints $\\mu \\mathbb{G}^{-1} (\\bar p - \\Pi) = 0$ exactly.
    """
    return p_plus - Qstar(G, mu, p_plus - Pi)


def reflect_and_report(G, mu, Pi, p_plus):
    """One GNI node's momenta in one pass: `(p_minus, p_bar, v_bar)`, the reflection (Comb)
    $p^- = p^+ - 2Q^*(p^+ - \\Pi)$, the reported $\\bar p = p^+ - Q^*(p^+ - \\Pi)$ and its velocity
    $\\bar v = \\mathbb{G}^{-1}\\bar p$ (one elimination on $\\mathbb{G}$ with the right-hand sides
    $[p^+, \\Pi, \\mu^T]$, one on C)."""
    X = solve_spd(G, jnp.concatenate([p_plus[:, None], Pi[:, None], mu.T], axis=1))
    Ginv_p, Ginv_muT = X[:, 0] - X[:, 1], X[:, 2:]
    C = mu @ Ginv_muT
    c = solve_spd(C, mu @ Ginv_p)
    q_star = mu.T @ c
    v_bar = X[:, 0] - Ginv_muT @ c
    return p_plus - 2.0 * q_star, p_plus - q_star, v_bar
