"""Direct products $G_1\\times\\dots\\times G_m$ of groups, as block-diagonal matrices."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import block_diag

from ..compilation import traced_once
from .base import MatrixLieGroup, check_matrix, check_vector


class ProductGroup(MatrixLieGroup):
    """A direct product $G_1\\times\\dots\\times G_m$ as block-diagonal matrices.

    Algebra vectors are the concatenation of the factors' vectors; every operation (hat, vee, exp,
    log, Ad, ad, inverse, and the retraction maps: the Cayley map, its inverse, the tangents of
    both retractions and their inverses) acts blockwise with each factor's closed form.

    Arguments:
        *factors: the groups $G_1, \\dots, G_m$ (at least one), e.g. `ProductGroup(SO3(), SE2())`.
    """

    factors: tuple = eqx.field(static=True)

    def __init__(self, *factors: MatrixLieGroup):
        if len(factors) == 0:
            raise ValueError("factors: expected at least one group")
        for f in factors:
            if not isinstance(f, MatrixLieGroup):
                raise TypeError(f"factors: expected MatrixLieGroup instances, got {type(f).__name__}")
        self.factors = tuple(factors)

    @property
    def dim(self) -> int:
        return sum(f.dim for f in self.factors)

    @property
    def matrix_size(self) -> int:
        return sum(f.matrix_size for f in self.factors)

    def _dim_slices(self):
        out, i = [], 0
        for f in self.factors:
            out.append(slice(i, i + f.dim))
            i += f.dim
        return out

    def _matrix_slices(self):
        out, i = [], 0
        for f in self.factors:
            out.append(slice(i, i + f.matrix_size))
            i += f.matrix_size
        return out

    def split(self, xi):
        """The factors' algebra vectors.

        Arguments:
            xi: shape (d,).

        Returns:
            a list of arrays of shapes $(d_i,)$.
        """
        xi = check_vector(xi, self.dim)
        return [xi[s] for s in self._dim_slices()]

    def blocks(self, g):
        """The diagonal blocks of a $k\\times k$ matrix: the factors' elements.

        Arguments:
            g: shape (k, k).

        Returns:
            a list of arrays of shapes $(k_i, k_i)$.
        """
        g = check_matrix(g, self.matrix_size)
        return [g[s, s] for s in self._matrix_slices()]

    def _diag(self, method, parts):
        """$\\mathrm{diag}(f_1(a_1), \\dots, f_m(a_m))$ with $f_i$ the factor's `method`, $a_i$ its part."""
        return block_diag(*[getattr(f, method)(a) for f, a in zip(self.factors, parts)])

    def _concat(self, method, parts):
        """$(f_1(a_1), \\dots, f_m(a_m))$ concatenated, with $f_i$ the factor's `method`, $a_i$ its part."""
        return jnp.concatenate([getattr(f, method)(a) for f, a in zip(self.factors, parts)])

    @traced_once
    def hat(self, xi):
        """$\\mathrm{diag}(\\hat\\xi_1, \\dots, \\hat\\xi_m)$."""
        return self._diag("hat", self.split(xi))

    @traced_once
    def vee(self, X):
        """Concatenation of the blocks' vee (off-diagonal blocks are ignored)."""
        return self._concat("vee", self.blocks(X))

    def inverse(self, g):
        """Blockwise inverse."""
        return self._diag("inverse", self.blocks(g))

    @traced_once
    def exp(self, xi):
        """Blockwise exp (safe at 0 when each factor's is)."""
        return self._diag("exp", self.split(xi))

    @traced_once
    def log(self, g):
        """Blockwise principal logarithm."""
        return self._concat("log", self.blocks(g))

    @traced_once
    def cayley(self, xi):
        """Blockwise Cayley map."""
        return self._diag("cayley", self.split(xi))

    @traced_once
    def cayley_inv(self, g):
        """Blockwise inverse of the Cayley map."""
        return self._concat("cayley_inv", self.blocks(g))

    @traced_once
    def dcayley(self, xi):
        """$\\mathrm{diag}(\\mathrm{dcay}_{\\xi_1}, \\dots)$."""
        return self._diag("dcayley", self.split(xi))

    @traced_once
    def dcayley_inv(self, xi):
        """$\\mathrm{diag}(\\mathrm{dcay}^{-1}_{\\xi_1}, \\dots)$."""
        return self._diag("dcayley_inv", self.split(xi))

    @traced_once
    def dcayley_inv_along(self, xi):
        """The factors' $\\mathrm{dcay}^{-1}_{\\xi_i}\\xi_i$, concatenated."""
        return self._concat("dcayley_inv_along", self.split(xi))

    @traced_once
    def dexp(self, xi):
        """$\\mathrm{diag}(\\mathrm{dexp}_{\\xi_1}, \\dots)$."""
        return self._diag("dexp", self.split(xi))

    @traced_once
    def dexp_inv(self, xi):
        """$\\mathrm{diag}(\\mathrm{dexp}^{-1}_{\\xi_1}, \\dots)$."""
        return self._diag("dexp_inv", self.split(xi))

    @traced_once
    def Ad(self, g):
        """$\\mathrm{diag}(\\mathrm{Ad}_{g_1}, \\dots)$."""
        return self._diag("Ad", self.blocks(g))

    @traced_once
    def ad(self, xi):
        """$\\mathrm{diag}(\\mathrm{ad}_{\\xi_1}, \\dots)$."""
        return self._diag("ad", self.split(xi))

    @traced_once
    def ad_star(self, xi, m):
        """Blockwise $\\mathrm{ad}^*$."""
        ms = [jnp.asarray(m)[s] for s in self._dim_slices()]
        return jnp.concatenate([f.ad_star(x, mi) for f, x, mi in zip(self.factors, self.split(xi), ms)])

    def random(self, key):
        """Independent random elements of the factors."""
        keys = jax.random.split(key, len(self.factors))
        return block_diag(*[f.random(k) for f, k in zip(self.factors, keys)])
