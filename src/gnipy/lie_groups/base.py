"""The base class :class:`MatrixLieGroup` and the checks of its arguments.

Every operation has a generic implementation here, from `hat`, `vee` and the basis of generators
(`exp` by `jax.scipy.linalg.expm`, the Cayley map and its tangents by matrix formulas, the tangents
of `exp` by the paper's series); the concrete groups override them with closed forms.

**A new group is one file.** Subclass :class:`MatrixLieGroup` and define what it *must*: `dim`,
`matrix_size`, `hat` and `vee` (and `log`, which has no generic form, if the exp retraction's
inverse $\\tau^{-1}$ is used). Then both retractions (:mod:`gnipy.retractions`), the spaces and the
integrators work on it through the generic fallbacks: `cayley`, `cayley_inv`, `dcayley`,
`dcayley_inv` and `dcayley_inv_along` by the matrix formulas of the Appendix (b); `exp` by
`expm`; `dexp`, `dexp_inv` by the paper's series in $\\mathrm{ad}_\\xi$ (Appendix a,
:mod:`~gnipy.lie_groups.series`, accurate to round-off for $\\|\\mathrm{ad}_\\xi\\|\\le 1$);
`inverse`, `Ad`, `ad`, `ad_star` through matrices and the basis of generators. A group *can*
override any of these with closed forms (safe at zero: a Taylor branch behind a "safe"
`jnp.where`, :mod:`~gnipy.lie_groups.series`), give `velocity_names` (the names of its algebra
coordinates), `random` (for tests), and the host-side checks the input validation asks of it:
`is_element` / `why_not_element` (membership of an initial orientation; by default nothing is
checked) and `is_bi_invariant` (whether a constant metric is bi-invariant, for the energy
theorem; by default none is claimed). A product of groups is :class:`~gnipy.lie_groups.ProductGroup`,
which combines its factors' maps block by block; no other module needs to change.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm

from ..compilation import traced_once
from ..linalg import solve as small_solve
from .series import dexp_inv_series, dexp_series


def as_float(x):
    """`x` as a JAX array of a floating (or complex) dtype: integers and booleans become float64.

    Arguments:
        x: an array or array-like.

    Returns:
        a JAX array.
    """
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.inexact) else x.astype(jnp.float64)


def check_vector(xi, d: int, name: str = "xi"):
    """`xi` as a floating Lie-algebra vector of shape (d,) (see :func:`as_float`).

    Arguments:
        xi: the vector.
        d: the expected length $d = \\dim\\mathfrak g$.
        name: the argument's name, for the error message.

    Returns:
        the vector, shape (d,).

    Raises:
        ValueError: for any other shape; the message names the argument.
    """
    xi = as_float(xi)
    if xi.shape != (d,):
        raise ValueError(f"{name}: expected a Lie-algebra vector of shape ({d},), got shape {xi.shape}")
    return xi


def check_matrix(g, k: int, name: str = "g"):
    """`g` as a floating $k\\times k$ matrix (see :func:`as_float`).

    Arguments:
        g: the matrix.
        k: the expected size.
        name: the argument's name, for the error message.

    Returns:
        the matrix, shape (k, k).

    Raises:
        ValueError: for any other shape; the message names the argument.
    """
    g = as_float(g)
    if g.shape != (k, k):
        raise ValueError(f"{name}: expected a {k}x{k} group matrix, got shape {g.shape}")
    return g


# ---------------------------------------------------------------------------------------------
# Base class
# ---------------------------------------------------------------------------------------------


class MatrixLieGroup(eqx.Module):
    """A matrix Lie group $G \\subset GL(k)$ with Lie algebra $\\mathfrak g \\cong \\mathbb{R}^d$.

    Subclasses define `dim`, `matrix_size`, `hat` and `vee`; everything else has a generic
    implementation here (through matrices, the basis of generators and the paper's series) that
    subclasses override with closed forms. `log` has no generic implementation. The group owns
    its retraction maps (paper, Appendix): the Cayley map `cayley` and the exponential `exp`, their
    local inverses `cayley_inv` and `log`, their right-trivialized tangents `dcayley`, `dexp`
    (eq:dtaudef) and the inverses `dcayley_inv`, `dexp_inv` (eq:dtauinversedef); the
    retractions of :mod:`gnipy.retractions` only call them. What a new group must and can
    implement: the docstring of :mod:`gnipy.lie_groups.base`.

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

    @traced_once
    def vee(self, X):
        """Inverse of :meth:`hat` (generic: least squares on the basis of generators).

        Arguments:
            X: shape (k, k), an element of $\\mathfrak g$.

        Returns:
            shape (d,).
        """
        X = check_matrix(X, self.matrix_size, "X")
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

    @traced_once
    def exp(self, xi):
        """The exponential map $\\exp(\\hat\\xi)$ (generic: `jax.scipy.linalg.expm`).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (k, k).
        """
        return expm(self.hat(check_vector(xi, self.dim)))

    def log(self, g):
        """The principal logarithm, inverse of :meth:`exp` near the identity.

        Arguments:
            g: shape (k, k).

        Returns:
            shape (d,).
        """
        raise NotImplementedError(f"{type(self).__name__}.log has no generic implementation")

    @traced_once
    def Ad(self, g):
        """The adjoint representation: $\\mathrm{Ad}_g\\eta = (g\\hat\\eta g^{-1})^\\vee$.

        Arguments:
            g: shape (k, k).

        Returns:
            shape (d, d).
        """
        g = check_matrix(g, self.matrix_size)
        if self.dim == 0:
            return jnp.zeros((0, 0), dtype=g.dtype)
        ginv = self.inverse(g)
        return jax.vmap(lambda E: self.vee(g @ E @ ginv))(self.basis()).T

    @traced_once
    def ad(self, xi):
        """The adjoint of the algebra: $\\mathrm{ad}_\\xi\\eta = [\\hat\\xi, \\hat\\eta]^\\vee$.

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d).
        """
        xi = check_vector(xi, self.dim)
        if self.dim == 0:
            return jnp.zeros((0, 0), dtype=xi.dtype)
        X = self.hat(xi)
        return jax.vmap(lambda E: self.vee(X @ E - E @ X))(self.basis()).T

    @traced_once
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

    # -- retraction maps (paper, Appendix) ----------------------------------------------------
    # Generic forms, for any matrix group whose algebra is closed under the products below; the
    # groups override them with closed forms. The tangents are d×d matrices on vee-coordinates.

    @traced_once
    def cayley(self, xi):
        """The Cayley map $\\mathrm{cay}(\\xi) = (I - \\hat\\xi/2)^{-1}(I + \\hat\\xi/2)$ (Appendix b).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (k, k), an element of $G$ (where $I - \\hat\\xi/2$ is invertible).
        """
        X = self.hat(check_vector(xi, self.dim))
        eye = jnp.eye(self.matrix_size, dtype=X.dtype)
        return small_solve(eye - 0.5 * X, eye + 0.5 * X)

    @traced_once
    def cayley_inv(self, g):
        """The local inverse of the Cayley map: $\\hat x = 2(g + I)^{-1}(g - I)$ (Appendix b).

        Arguments:
            g: shape (k, k), an element of $G$ in the image of :meth:`cayley`.

        Returns:
            shape (d,).
        """
        g = check_matrix(g, self.matrix_size)
        eye = jnp.eye(self.matrix_size, dtype=g.dtype)
        return self.vee(2.0 * small_solve(g + eye, g - eye))

    @traced_once
    def dcayley(self, xi):
        """The right-trivialized tangent of the Cayley map (eq:dtaudef):
        $\\mathrm{dcay}_x y = (I - x/2)^{-1}\\,y\\,(I + x/2)^{-1}$ (Appendix b).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d): column $j$ is $\\mathrm{dcay}_\\xi e_j$.
        """
        X = self.hat(check_vector(xi, self.dim))
        eye = jnp.eye(self.matrix_size, dtype=X.dtype)
        A_inv = small_solve(eye - 0.5 * X, eye)
        B_inv = small_solve(eye + 0.5 * X, eye)
        return self._on_generators(lambda E: A_inv @ E @ B_inv)

    @traced_once
    def dcayley_inv(self, xi):
        """The inverse tangent of the Cayley map (eq:dtauinversedef):
        $\\mathrm{dcay}^{-1}_x y = (I - x/2)\\,y\\,(I + x/2)$ (Appendix b).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d), the inverse of :meth:`dcayley`.
        """
        X = self.hat(check_vector(xi, self.dim))
        eye = jnp.eye(self.matrix_size, dtype=X.dtype)
        A, B = eye - 0.5 * X, eye + 0.5 * X
        return self._on_generators(lambda E: A @ E @ B)

    @traced_once
    def dcayley_inv_along(self, xi):
        """$\\mathrm{dcay}^{-1}_\\xi\\,\\xi$: $(I - x/2)\\,x\\,(I + x/2) = x - x^3/4$ (Appendix b).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d,).
        """
        X = self.hat(check_vector(xi, self.dim))
        return self.vee(X - 0.25 * (X @ X @ X))

    @traced_once
    def dexp(self, xi):
        """The right-trivialized tangent of the exponential (eq:dtaudef), generic: the paper's series
        $\\mathrm{dexp}_x = \\sum_{j\\ge0}\\mathrm{ad}_x^j/(j+1)!$ (Appendix a, :func:`~gnipy.lie_groups.series.dexp_series`),
        accurate to round-off for $\\|\\mathrm{ad}_\\xi\\|\\le 1$.

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d).
        """
        return dexp_series(self, check_vector(xi, self.dim))

    @traced_once
    def dexp_inv(self, xi):
        """The inverse tangent of the exponential (eq:dtauinversedef), generic: the paper's series
        $\\mathrm{dexp}^{-1}_x = \\sum_{j\\ge0}(B_j/j!)\\,\\mathrm{ad}_x^j$ (Appendix a,
        :func:`~gnipy.lie_groups.series.dexp_inv_series`), accurate to round-off for
        $\\|\\mathrm{ad}_\\xi\\|\\le 1$ (it converges for a spectral radius of $\\mathrm{ad}_\\xi$ below $2\\pi$).

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d, d), the inverse of :meth:`dexp`.
        """
        return dexp_inv_series(self, check_vector(xi, self.dim))

    def dexp_inv_along(self, xi):
        """$\\mathrm{dexp}^{-1}_\\xi\\,\\xi = \\xi$ on every group: every term of the series but the first
        holds $\\mathrm{ad}_\\xi\\xi = 0$.

        Arguments:
            xi: shape (d,).

        Returns:
            shape (d,).
        """
        return check_vector(xi, self.dim)

    def _on_generators(self, f):
        """The $d\\times d$ matrix whose column $j$ is $f(\\hat e_j)^\\vee$."""
        return jax.vmap(lambda E: self.vee(f(E)))(self.basis()).T

    # -- host-side checks (NumPy), for the validation of inputs --------------------------------

    def is_element(self, g, tol: float = 1e-10):
        """Whether the matrices `g` are elements of the group, to `tol` (host side, NumPy).

        The base class checks nothing (every matrix passes); a group with a cheap membership test
        overrides this and :meth:`why_not_element`.

        Arguments:
            g: shape (..., k, k), finite.
            tol: the tolerance of the test.

        Returns:
            a boolean array of shape `g.shape[:-2]`.
        """
        return np.ones(np.shape(g)[:-2], dtype=bool)

    def why_not_element(self, g) -> str:
        """A phrase saying why one matrix `g` fails :meth:`is_element`, for an error message.

        Arguments:
            g: shape (k, k).

        Returns:
            e.g. `"not a rotation matrix (|RᵀR − I| = 1.000e+00, det = 2)"`.
        """
        return f"not an element of {type(self).__name__}"

    def is_bi_invariant(self, metric, atol):
        """Whether a constant metric on $\\mathfrak g$ is known to be bi-invariant
        ($\\mathrm{Ad}_g^T M\\,\\mathrm{Ad}_g = M$ for every $g$), to `atol` (host side, NumPy).

        The hypothesis of the energy theorem on a group (:func:`gnipy.diagnostics.energy_theorem_applies`).
        The base class claims none (returns False); a group that knows its bi-invariant metrics
        overrides this.

        Arguments:
            metric: shape (..., d, d), the metric's group block(s) in algebra coordinates.
            atol: the absolute tolerance, broadcastable to `metric.shape[:-2]`.

        Returns:
            a boolean array of shape `metric.shape[:-2]`.
        """
        return np.zeros(np.shape(metric)[:-2], dtype=bool)
