"""The abelian groups: the translations $\\mathbb{R}^n$ and the trivial group $\\{e\\}$."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import MatrixLieGroup, check_matrix, check_vector


class _SquareZeroAlgebra(MatrixLieGroup):
    """The retraction maps of a group whose algebra squares to zero ($\\hat x\\hat y = 0$, so
    $\\exp\\hat x = I + \\hat x$): the Cayley map is the exponential, $\\mathrm{cay}(\\hat x) =
    (I - \\hat x/2)^{-1}(I + \\hat x/2) = I + \\hat x$, its inverse is `log`, and every tangent is the
    identity (the algebra is abelian)."""

    def cayley(self, xi):
        """$\\mathrm{cay}(\\hat x) = I + \\hat x = \\exp\\hat x$."""
        return self.exp(xi)

    def cayley_inv(self, g):
        """The local inverse of :meth:`cayley`: `log`."""
        return self.log(g)

    def dcayley(self, xi):
        """$\\mathrm{dcay}_x = I$."""
        return self._identity_tangent(xi)

    def dcayley_inv(self, xi):
        """$\\mathrm{dcay}^{-1}_x = I$."""
        return self._identity_tangent(xi)

    def dcayley_inv_along(self, xi):
        """$\\mathrm{dcay}^{-1}_x x = x$."""
        return check_vector(xi, self.dim)

    def dexp(self, xi):
        """$\\mathrm{dexp}_x = I$."""
        return self._identity_tangent(xi)

    def dexp_inv(self, xi):
        """$\\mathrm{dexp}^{-1}_x = I$."""
        return self._identity_tangent(xi)

    def _identity_tangent(self, xi):
        xi = check_vector(xi, self.dim)
        return jnp.eye(self.dim, dtype=xi.dtype)


class Rn(_SquareZeroAlgebra):
    """The translations $\\mathbb{R}^n$ as $(n+1)\\times(n+1)$ homogeneous matrices $\\begin{pmatrix} I & x\\\\ 0 & 1\\end{pmatrix}$.

    Abelian: $\\exp\\hat x = I + \\hat x = \\mathrm{cay}(\\hat x)$, $\\mathrm{Ad} = I$, $\\mathrm{ad} = 0$,
    and the tangents of both retractions are the identity.

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
        xi = check_vector(xi, self.n)
        return jnp.zeros((self.n + 1, self.n + 1), dtype=xi.dtype).at[: self.n, self.n].set(xi)

    def vee(self, X):
        """The last column $X_{:n, n}$."""
        return check_matrix(X, self.n + 1, "X")[: self.n, self.n]

    def inverse(self, g):
        """$(I, x)^{-1} = (I, -x)$."""
        g = check_matrix(g, self.n + 1)
        return jnp.eye(self.n + 1, dtype=g.dtype).at[: self.n, self.n].set(-g[: self.n, self.n])

    def exp(self, xi):
        """$I + \\hat x$."""
        X = self.hat(xi)
        return jnp.eye(self.n + 1, dtype=X.dtype) + X

    def log(self, g):
        """The translation $x$ (last column)."""
        return check_matrix(g, self.n + 1)[: self.n, self.n]

    def Ad(self, g):
        """$\\mathrm{Ad}_g = I$."""
        g = check_matrix(g, self.n + 1)
        return jnp.eye(self.n, dtype=g.dtype)

    def ad(self, xi):
        """$\\mathrm{ad}_\\xi = 0$."""
        xi = check_vector(xi, self.n)
        return jnp.zeros((self.n, self.n), dtype=xi.dtype)

    def ad_star(self, xi, m):
        """Zero (abelian)."""
        check_vector(xi, self.n)
        return jnp.zeros_like(jnp.asarray(m, dtype=jnp.float64))

    def random(self, key):
        """A standard normal translation."""
        return self.exp(jax.random.normal(key, (self.n,)))


class TrivialGroup(_SquareZeroAlgebra):
    """The trivial group $\\{e\\}$: $d = 0$, elements are the $1\\times1$ matrix $[1]$.

    Lets an $\\mathbb{R}^n$ system be written as $\\mathbb{R}^n\\times\\{e\\}$ when a group is required.
    Both retractions are $[1]$, their inverses the empty vector and their tangents $0\\times0$.
    """

    @property
    def dim(self) -> int:
        return 0

    @property
    def matrix_size(self) -> int:
        return 1

    def hat(self, xi):
        """The zero $1\\times1$ matrix."""
        xi = check_vector(xi, 0)
        return jnp.zeros((1, 1), dtype=xi.dtype)

    def vee(self, X):
        """The empty vector."""
        X = check_matrix(X, 1, "X")
        return jnp.zeros((0,), dtype=X.dtype)

    def inverse(self, g):
        """$e^{-1} = e$."""
        return check_matrix(g, 1)

    def exp(self, xi):
        """$[1]$."""
        xi = check_vector(xi, 0)
        return jnp.ones((1, 1), dtype=xi.dtype)

    def log(self, g):
        """The empty vector."""
        g = check_matrix(g, 1)
        return jnp.zeros((0,), dtype=g.dtype)

    def random(self, key):
        """$e$."""
        return self.identity()
