"""Configuration spaces: how a step's unknowns become the next configuration.

The GNI core (DESIGN.md §2) solves for the step unknowns $z$ and advances the configuration with
them. On $\\mathbb{R}^n$ the unknown is $z = x_{k+1}$ itself; on $\\mathbb{R}^n \\times G$ it is
$(x_{k+1}, \\sigma_k)$ with $R_{k+1} = R_k \\tau(\\sigma_k)$. Every space offers the same small set of
operations, so the core is written once against them.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["EuclideanSpace"]


class EuclideanSpace(eqx.Module):
    """The configuration space $\\mathbb{R}^n$ (the Lie group part is trivial).

    A base point `b` is the coordinate vector q; the step unknown `z` is $q_{k+1}$.
    """

    n: int = eqx.field(static=True)

    def step_points(self, b0, z, h):
        """Return `(b1, b_mid, velocity)` of the step from `b0` with unknowns `z`.

        `velocity` is the step's velocity $(q_{k+1} - q_k)/h$ and `b_mid` the midpoint.
        """
        return z, 0.5 * (b0 + z), (z - b0) / h

    def advance(self, b0, z):
        """The configuration reached by the step: $q_{k+1} = z$."""
        return z

    def initial_guess(self, b0, v, h):
        """A first guess of the unknowns from the velocity `v` at `b0`: $q_k + h v$."""
        return b0 + h * v

    def legendre_minus(self, ld: Callable, b0, z):
        """$FL^-$: $-\\partial l_d / \\partial q_k$ at fixed $q_{k+1}$ (a covector at $q_k$)."""
        return -jax.grad(ld, argnums=0)(b0, z)

    def legendre_plus(self, ld: Callable, b0, z):
        """$FL^+$: $\\partial l_d / \\partial q_{k+1}$ (a covector at $q_{k+1}$)."""
        return jax.grad(ld, argnums=1)(b0, z)

    def coordinates(self, b):
        """The coordinate vector that solutions report for the base point."""
        return jnp.asarray(b)
