"""The continuous equations of motion: the Lagrange–d'Alembert(–Poincaré) equations with λ eliminated.

For $l = \\tfrac12 v^T\\mathbb{G}(b)v - V(b)$ and constraints $\\mu(b)(v - Y(b)) = 0$, with $D_v$ the
derivative along the motion ($b \\mapsto (x + \\epsilon\\dot x, R\\exp(\\epsilon\\xi))$):

$$\\mathbb{G}\\,\\dot v = F + \\mu^T\\lambda, \\qquad
F = \\partial_b l - D_v(\\partial_v l) + (0, \\mathrm{ad}^*_\\xi\\,\\partial_\\xi l),$$

where $\\partial_b l = (\\partial_x l, \\nabla^L_R l)$. Differentiating the constraints along the
motion, $\\mu\\dot v = \\mu\\,D_v Y - (D_v\\mu)(v - Y) =: c$, so
$\\lambda = C^{-1}(c - \\mu\\mathbb{G}^{-1}F)$ with $C = \\mu\\mathbb{G}^{-1}\\mu^T$ (paper (H) in
Lagrangian form; on SO(3), $\\mathrm{ad}^*_\\Omega M = M\\times\\Omega$ gives Euler's equations).
A generalized force $F_{ext}(b, v, u, t)$ of the system (:mod:`gnipy.forcing`) adds to $F$.
The reference solver :class:`gnipy.ContinuousReference` (:mod:`gnipy.reference`) integrates them.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .linalg import solve

__all__ = ["lagrange_dalembert_acceleration", "constraint_terms"]


def _along(f, space, b, v):
    """`(f(b), D_v f(b))`: the value and the derivative along the motion with velocity v."""
    zero = jnp.zeros((), dtype=v.dtype)
    return jax.jvp(lambda s: f(space.move(b, s * v)), (zero,), (jnp.ones_like(zero),))


def constraint_terms(system, b, v, t=None):
    """`(G, F, mu, c)` at `(b, v)`: the metric, the force $F$ of the module docstring, the
    constraints' $\\mu$ and $c = \\mu D_v Y - (D_v\\mu)(v - Y)$, from which
    $\\lambda = C^{-1}(c - \\mu\\mathbb{G}^{-1}F)$, $C = \\mu\\mathbb{G}^{-1}\\mu^T$ (the acceleration here,
    the run-time diagnostics in :mod:`gnipy.diagnostics`). A forced system's force enters at time
    `t` (see :func:`lagrange_dalembert_acceleration`)."""
    space = system.space
    G = system.metric(b)
    p = system.momentum(b, v)
    dl_db = jax.grad(lambda w: system.L(space.move(b, w), v))(jnp.zeros_like(v))
    _, dp = _along(lambda c: system.momentum(c, v), space, b, v)
    F = dl_db - dp + space.lie_correction(v, p)
    if system.force is not None:
        F = F + (system.external_force(b, v) if t is None else system.external_force_continuous(b, v, t))
    mu, dmu = _along(system.mu, space, b, v)
    Y, dY = _along(system.Y, space, b, v)
    return G, F, mu, mu @ dY - dmu @ (v - Y)


def lagrange_dalembert_acceleration(system, b, v, t=None):
    """The constrained acceleration $\\dot v$ and the multipliers λ at `(b, v)`.

    A forced system's force enters at time `t` with the input held over the step containing it
    (None: at the start of the step the system's drive is at, with that step's input)."""
    G, F, mu, c = constraint_terms(system, b, v, t)
    # gnipy.linalg.solve, not jnp.linalg.solve: vmapped over many nodes (the run-time diagnostics of
    # a batch), jaxlib 0.10's LAPACK triangular solves share XLA's CPU thread pool with the program
    # that calls them, and two of them at once waited on each other for ever on a 2-core machine
    X = solve(G, jnp.concatenate([F[:, None], mu.T], axis=1))
    Ginv_F, Ginv_muT = X[:, 0], X[:, 1:]
    lam = solve(mu @ Ginv_muT, c - mu @ Ginv_F)
    return Ginv_F + Ginv_muT @ lam, lam
