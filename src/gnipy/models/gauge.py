"""Modin–Verdier's gauge perturbation of a test problem, written for mechanical-type Lagrangians.

Modin & Verdier make the standard, reversible integrable test problems non-reversible without
changing their motion: they shift the canonical momenta by a gradient,

$$H_S(q, p) = H\\big(q, p + c\\nabla S(q)\\big), \\qquad\\text{i.e.}\\qquad
l_S(q, \\dot q) = l(q, \\dot q) - c\\langle\\nabla S(q), \\dot q\\rangle = l - c\\tfrac{d}{dt}S(q).$$

The term is a total time derivative: the motion $q(t)$ is that of $l$, and the conjugate momenta are
$p = \\mathbb{G}\\dot q - c\\nabla S(q)$. The continuous flow in $(q, \\dot q)$ stays reversible, but
in $(q, p)$ the reversing map becomes $p \\mapsto -p - 2c\\nabla S$, no longer the standard
$p \\mapsto -p$ that discrete schemes built on the momenta respect (K. Modin and O. Verdier, *What
makes nonholonomic integrators work?*, Numer. Math. 145 (2020) 405–435, arXiv:1707.04514; O.
Verdier's implementation of the perturbed contact oscillator, odelab's
`NonReversibleContactOscillator`, takes $S = \\cos z$, $c = 1$).

**In gnipy.** A :class:`~gnipy.System` takes Lagrangians of mechanical type only (no term linear in
the velocity), so the zoo writes the gauge term through one more, cyclic, coordinate $w$
(Kaluza–Klein):

$$\\hat l(q, w, \\dot q, \\dot w) = l(q, \\dot q) + \\tfrac12\\big(\\dot w - \\langle\\nabla S(q), \\dot q\\rangle\\big)^2,$$

with the constraints of $l$ (no $w$ in them). Then:

- $p_w = \\dot w - \\langle\\nabla S(q), \\dot q\\rangle$ is conserved ($w$ is cyclic and no constraint
  force acts on it), and Routh reduction at $p_w = c$ gives
  $\\hat l - c\\dot w = l - c\\langle\\nabla S, \\dot q\\rangle - \\tfrac12 c^2$: the perturbed $l_S$ up
  to a constant. The motion of $q$ is that of $l$, and $w(t) = w_0 + ct + S(q(t)) - S(q_0)$
  (:func:`gauge_coordinate`).
- The momenta conjugate to $q$ are $\\partial\\hat l/\\partial\\dot q = \\mathbb{G}\\dot q - p_w\\nabla S(q)$:
  Modin–Verdier's. Every discrete Lagrangian of gnipy is invariant under $w \\mapsto w + a$, so the
  variational methods (the GNI family, `dla`, compositions of the GNI) keep the discrete $p_w$ to
  round-off (discrete Noether) and discretize the perturbed problem on the level $p_w = c$. A method
  that is not variational need not: `discrete-gradient` keeps the energy of $\\hat l$ but lets $p_w$
  drift, leaving the level (the registered invariant `p_w` shows it).
- The standard reversing map $(\\dot q, \\dot w) \\mapsto (-\\dot q, -\\dot w)$ of $\\hat l$ takes the level
  $p_w = c$ to $p_w = -c$. With $c \\ne 0$ the discrete methods see a non-reversible problem; $c = 0$
  is the unperturbed, reversible problem in the same four coordinates (a control).

The metric of $\\hat l$ depends on $q$ (through $\\nabla S$), so the methods written for a constant
metric (`mp`, `rattle`, `shake`, `euler-*`) do not apply; the GNI family and `dla` do.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

__all__ = ["kaluza_klein_term", "lift_constraints", "lift_initial_condition", "gauge_momentum", "gauge_coordinate"]


def kaluza_klein_term(grad_S, v):
    """$\\tfrac12(\\dot w - \\langle\\nabla S, \\dot q\\rangle)^2$ for `v` $= (\\dot q, \\dot w)$ and `grad_S`
    $= \\nabla S(q)$ (traceable)."""
    pw = v[-1] - grad_S @ v[:-1]
    return 0.5 * pw * pw


def lift_constraints(mu):
    """The constraint rows `mu` (m, n) of $l$ with a zero column for $\\dot w$: (m, n + 1) (traceable)."""
    mu = jnp.atleast_2d(mu)
    return jnp.concatenate([mu, jnp.zeros((mu.shape[0], 1), dtype=mu.dtype)], axis=1)


def lift_initial_condition(q0, v0, grad_S0, c, w0=0.0):
    """$(q_0, w_0)$ and $(\\dot q_0, \\dot w_0)$ with $\\dot w_0 = c + \\langle\\nabla S(q_0), \\dot q_0\\rangle$,
    so that $p_w = c$ (host side; `grad_S0` $= \\nabla S(q_0)$)."""
    q0 = tuple(float(x) for x in q0)
    v0 = tuple(float(x) for x in v0)
    wdot0 = float(c) + float(np.dot(np.asarray(grad_S0, dtype=np.float64), np.asarray(v0)))
    return (*q0, float(w0)), (*v0, wdot0)


def gauge_momentum(grad_S, v):
    """$p_w = \\dot w - \\langle\\nabla S(q), \\dot q\\rangle$, conserved ($= c$)."""
    return v[-1] - np.dot(np.asarray(grad_S, dtype=np.float64), np.asarray(v[:-1], dtype=np.float64))


def gauge_coordinate(S, c, q0, t, q):
    """The exact $w(t) = w_0 + ct + S(q(t)) - S(q_0)$ given the motion `q` (T, n + 1) of the other
    coordinates at the times `t` (T,), from `q0` $= (q_0, w_0)$; `S` acts on one configuration
    (host side)."""
    q = np.asarray(q, dtype=np.float64)
    q0 = np.asarray(q0, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    S_t = np.array([float(S(qk[:-1])) for qk in q])
    return q0[-1] + c * t + S_t - float(S(q0[:-1]))
