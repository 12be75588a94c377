"""The abelian groups: the translations $\\mathbb{R}^n$ and the trivial group $\\{e\\}$."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import MatrixLieGroup, _check_matrix, _check_vector


class Rn(MatrixLieGroup):
    """The translations $\\mathbb{R}^n$ as $(n+1)\\times(n+1)$ homogeneous matrices $\\begin{pmatrix} I & x\\\\ 0 & 1\\end{pmatrix}$.

    Abelian: $\\exp\\hat x = I + \\hat x$, $\\mathrm{Ad} = I$, $\\mathrm{ad} = 0$.

    Arguments:
        n: the dimension ($\\ge 1$).
    """

    n: int = eqx.field(static=True)

    def __check_init__(self):
        if isinstance(self.n, bool) or not isinstance(self.n, int) or self.n < 1:
            raise ValueError(f"n: expected a positive integer, got {self.n!r}")

    @property
    def dim(self) -> int:
        return self.n

    @property
    def matrix_size(self) -> int:
        return self.n + 1

    def hat(self, xi):
        """$\\hat x = \\begin{pmatrix} 0 & x\\\\ 0 & 0\\end{pmatrix}$ (shape (n+1, n+1))."""
        xi = _check_vector(xi, self.n)
        return jnp.zeros((self.n + 1, self.n + 1), dtype=xi.dtype).at[: self.n, self.n].set(xi)

    def vee(self, X):
        """The last column $X_{:n, n}$."""
        return _check_matrix(X, self.n + 1, "X")[: self.n, self.n]

    def inverse(self, g):
        """$(I, x)^{-1} = (I, -x)$."""
        g = _check_matrix(g, self.n + 1)
        return jnp.eye(self.n + 1, dtype=g.dtype).at[: self.n, self.n].set(-g[: self.n, self.n])

    def exp(self, xi):
        """$I + \\hat x$."""
        X = self.hat(xi)
        return jnp.eye(self.n + 1, dtype=X.dtype) + X

    def log(self, g):
        """The translation $x$ (last column)."""
        return _check_matrix(g, self.n + 1)[: self.n, self.n]

    def Ad(self, g):
        """$\\mathrm{Ad}_g = I$."""
        g = _check_matrix(g, self.n + 1)
        return jnp.eye(self.n, dtype=g.dtype)

    def ad(self, xi):
        """$\\mathrm{ad}_\\xi = 0$."""
        xi = _check_vector(xi, self.n)
        return jnp.zeros((self.n, self.n), dtype=xi.dtype)

    def ad_star(self, xi, m):
        """Zero (abelian)."""
        _check_vector(xi, self.n)
        return jnp.zeros_like(jnp.asarray(m, dtype=jnp.float64))

    def random(self, key):
        """A standard normal translation."""
        return self.exp(jax.random.normal(key, (self.n,)))


class TrivialGroup(MatrixLieGroup):
    """The trivial group $\\{e\\}$: $d = 0$, elements are the $1\\times1$ matrix $[1]$.

    Lets an $\\mathbb{R}^n$ system be written as $\\mathbb{R}^n\\times\\{e\\}$ when a group is required.
    """

    @property
    def dim(self) -> int:
        return 0

    @property
    def matrix_size(self) -> int:
        return 1

    def hat(self, xi):
        """The zero $1\\times1$ matrix."""
        xi = _check_vector(xi, 0)
        return jnp.zeros((1, 1), dtype=xi.dtype)

    def vee(self, X):
        """The empty vector."""
        X = _check_matrix(X, 1, "X")
        return jnp.zeros((0,), dtype=X.dtype)

    def inverse(self, g):
        """$e^{-1} = e$."""
        return _check_matrix(g, 1)

    def exp(self, xi):
        """$[1]$."""
        xi = _check_vector(xi, 0)
        return jnp.ones((1, 1), dtype=xi.dtype)

    def log(self, g):
        """The empty vector."""
        g = _check_matrix(g, 1)
        return jnp.zeros((0,), dtype=g.dtype)

    def random(self, key):
        """$e$."""
        return self.identity()
