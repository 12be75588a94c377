"""The base class :class:`MatrixLieGroup` and the checks of its arguments.

Every operation has a generic implementation here, from `hat`, `vee` and the basis of generators
(`exp` by `jax.scipy.linalg.expm`); the concrete groups override them with closed forms.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import expm


def _as_float(x):
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.inexact) else x.astype(jnp.float64)


def _check_vector(xi, d: int, name: str = "xi"):
    xi = _as_float(xi)
    if xi.shape != (d,):
        raise ValueError(f"{name}: expected a Lie-algebra vector of shape ({d},), got shape {xi.shape}")
    return xi


def _check_matrix(g, k: int, name: str = "g"):
    g = _as_float(g)
    if g.shape != (k, k):
        raise ValueError(f"{name}: expected a {k}x{k} group matrix, got shape {g.shape}")
    return g


# ---------------------------------------------------------------------------------------------
# Base class
# ---------------------------------------------------------------------------------------------


class MatrixLieGroup(eqx.Module):
    """A matrix Lie group $G \\subset GL(k)$ with Lie algebra $\\mathfrak g \\cong \\mathbb{R}^d$.

    Subclasses define `dim`, `matrix_size`, `hat` and `vee`; everything else has a generic
    implementation here (through matrices and the basis of generators) that subclasses override
    with closed forms. `log` has no generic implementation.

    Elements are $k\\times k$ arrays; algebra elements are vectors of length $d$. All methods act on
    a single element (vmap for batches).
    """

    @property
    def dim(self) -> int:
        """$d = \\dim\\mathfrak g$."""
        raise NotImplementedError

    @property
    def matrix_size(self) -> int:
        """$k$: elements are $k\\times k$ matrices."""
        raise NotImplementedError

    # -- algebra -----------------------------------------------------------------------------

    def hat(self, xi):
        """The matrix $\\hat\\xi\\in\\mathfrak g\\subset\\mathfrak{gl}(k)$ of a vector.

        Arguments:
            xi: shape (d,).

        Returns:
            shape (k, k).
        """
        raise NotImplementedError

    def vee(self, X):
        """Inverse of :meth:`hat` (generic: least squares on the basis of generators).

        Arguments:
            X: shape (k, k), an element of $\\mathfrak g$.

        Returns:
            shape (d,).
        """
        X = _check_matrix(X, self.matrix_size, "X")
        E = self.basis().reshape(self.dim, -1)
        return jnp.linalg.solve(E @ E.T, E @ X.reshape(-1))

    def basis(self):
        """The generators $\\hat e_1,\\dots,\\hat e_d$.

        Returns:
            shape (d, k, k).
        """
        d, k = self.dim, self.matrix_size
        if d == 0:
            return jnp.zeros((0, k, k))
        return jax.vmap(self.hat)(jnp.eye(d))

    # -- group ---------------------------------------------------------------------------------

    def identity(self):
        """The identity $e$ (shape (k, k))."""
        return jnp.eye(self.matrix_size)

    def compose(self, g, h):
        """The product $gh$ (matrix product)."""
        return g @ h

    def inverse(self, g):
        """$g^{-1}$ (generic: matrix inverse)."""
        return jnp.linalg.inv(g)

    def exp(self, xi):
        """The exponential map $\\exp(\\hat\\xi)$ (generic: `jax.scipy.linalg.expm`).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (k, k).
        """
        return expm(self.hat(_check_vector(xi, self.dim)))

    def log(self, g):
        """The principal logarithm, inverse of :meth:`exp` near the identity.

        Arguments:
            g: shape (k, k).

        Returns:
            shape (d,).
        """
        raise NotImplementedError(f"{type(self).__name__}.log has no generic implementation")

    def Ad(self, g):
        """The adjoint representation: $\\mathrm{Ad}_g\\eta = (g\\hat\\eta g^{-1})^\\vee$.

        Arguments:
            g: shape (k, k).

        Returns:
            shape (d, d).
        """
        g = _check_matrix(g, self.matrix_size)
        if self.dim == 0:
            return jnp.zeros((0, 0), dtype=g.dtype)
        ginv = self.inverse(g)
        return jax.vmap(lambda E: self.vee(g @ E @ ginv))(self.basis()).T

    def ad(self, xi):
        """The adjoint of the algebra: $\\mathrm{ad}_\\xi\\eta = [\\hat\\xi, \\hat\\eta]^\\vee$.

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d).
        """
        xi = _check_vector(xi, self.dim)
        if self.dim == 0:
            return jnp.zeros((0, 0), dtype=xi.dtype)
        X = self.hat(xi)
        return jax.vmap(lambda E: self.vee(X @ E - E @ X))(self.basis()).T

    def ad_star(self, xi, m):
        """The coadjoint action $\\mathrm{ad}^*_\\xi m = \\mathrm{ad}_\\xi^T m$ on $\\mathfrak g^*\\cong\\mathbb{R}^d$.

        Arguments:
            xi: shape (d,).
            m: shape (d,), a covector (momentum).

        Returns:
            shape (d,). For SO(3): $M\\times\\omega$.
        """
        return self.ad(xi).T @ jnp.asarray(m)

    def random(self, key):
        """A random element (for tests): generic $\\exp(\\xi)$ with $\\xi$ standard normal."""
        return self.exp(jax.random.normal(key, (self.dim,)))
