"""Retraction maps $\\tau: \\mathfrak g \\to G$ and their right-trivialized tangents (paper, Appendix).

A retraction is an analytic local diffeomorphism with $\\tau(0) = e$ and $\\tau(\\xi)\\tau(-\\xi) = e$.
The GNI moves on the group by $R_{k+1} = R_k\\tau(\\sigma_k)$ (paper §7.2), and its discrete
Legendre transforms need the right-trivialized tangent (Definition "Retr_again")

$$\\mathrm{d}\\tau_\\xi\\,\\eta = \\Bigl(\\tfrac{d}{d\\epsilon}\\tau(\\xi + \\epsilon\\eta)\\big|_{\\epsilon=0}\\,\\tau(\\xi)^{-1}\\Bigr)^\\vee
\\qquad\\text{(eq:dtaudef)}$$

and its inverse $\\mathrm{d}\\tau^{-1}_\\xi$ (eq:dtauinversedef), both returned as $d\\times d$ matrices
acting on algebra coordinates. They satisfy (eq:dtauAd)
$\\mathrm{d}\\tau_\\xi = \\mathrm{Ad}_{\\tau(\\xi)}\\mathrm{d}\\tau_{-\\xi}$ and (eq:dtauinverseAd)
$\\mathrm{d}\\tau^{-1}_\\xi = \\mathrm{d}\\tau^{-1}_{-\\xi}\\mathrm{Ad}_{\\tau(-\\xi)}$.

Two retractions are provided, :class:`Cayley` (`"cayley"`) and :class:`Exp` (`"exp"`). Each has
closed forms for SO(3) (Appendix, "Applications to matrix groups"), SE(2) and $\\mathbb{R}^n$,
acts blockwise on a :class:`~gnipy.lie_groups.ProductGroup` (so the factors' closed forms are used),
and falls back to a generic matrix formula (Cayley) or to the paper's series (exp) for any other
:class:`~gnipy.lie_groups.MatrixLieGroup`. Everything is safe at $\\xi = 0$ (no NaN values or
gradients) and `jit`/`vmap`/`grad` friendly.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import block_diag

from .linalg import solve as small_solve

from .lie_groups import (
    _BERNOULLI,
    SE2,
    SO3,
    MatrixLieGroup,
    ProductGroup,
    Rn,
    _check_matrix,
    _check_vector,
    dexp_inv_coefficient_sq,
    one_minus_cos_sq,
    theta_minus_sin_sq,
)

__all__ = [
    "Cayley",
    "Exp",
    "Retraction",
    "dexp_inv_series",
    "dexp_series",
    "get_retraction",
    "retraction_names",
]


def _check_group(group):
    if not isinstance(group, MatrixLieGroup):
        raise TypeError(f"group: expected a gnipy.lie_groups.MatrixLieGroup, got {type(group).__name__}")


class Retraction(eqx.Module):
    """Base class of retraction maps $\\tau:\\mathfrak g\\to G$ (paper, Appendix).

    The public methods validate their arguments, treat a :class:`~gnipy.lie_groups.ProductGroup`
    blockwise and a zero-dimensional group trivially, and delegate a single group to the
    subclass's `_tau`, `_dtau`, `_dtau_inv`, `_tau_inv`.
    """

    name: ClassVar[str] = ""

    def tau(self, group: MatrixLieGroup, xi):
        """The retraction $\\tau(\\xi)$.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (k, k), an element of $G$.
        """
        _check_group(group)
        xi = _check_vector(xi, group.dim)
        if isinstance(group, ProductGroup):
            return block_diag(*[self.tau(f, x) for f, x in zip(group.factors, group.split(xi))])
        if group.dim == 0:
            return jnp.eye(group.matrix_size, dtype=xi.dtype)
        return self._tau(group, xi)

    def dtau(self, group: MatrixLieGroup, xi):
        """The right-trivialized tangent $\\mathrm{d}\\tau_\\xi$ (eq:dtaudef) as a matrix.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d, d): column $j$ is $\\mathrm{d}\\tau_\\xi e_j$.
        """
        _check_group(group)
        xi = _check_vector(xi, group.dim)
        if isinstance(group, ProductGroup):
            return block_diag(*[self.dtau(f, x) for f, x in zip(group.factors, group.split(xi))])
        if group.dim == 0:
            return jnp.zeros((0, 0), dtype=xi.dtype)
        return self._dtau(group, xi)

    def dtau_inv(self, group: MatrixLieGroup, xi):
        """The inverse $\\mathrm{d}\\tau^{-1}_\\xi$ (eq:dtauinversedef) as a matrix.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d, d), the inverse of `dtau(group, xi)`.
        """
        _check_group(group)
        xi = _check_vector(xi, group.dim)
        if isinstance(group, ProductGroup):
            return block_diag(*[self.dtau_inv(f, x) for f, x in zip(group.factors, group.split(xi))])
        if group.dim == 0:
            return jnp.zeros((0, 0), dtype=xi.dtype)
        return self._dtau_inv(group, xi)

    def dtau_inv_jump(self, group: MatrixLieGroup, xi):
        """$\\mathrm{d}\\tau^{-1}_{-\\xi} - \\mathrm{d}\\tau^{-1}_\\xi$ as a matrix, without the cancellation
        of the two (the jump $FL^+ - FL^-$ of the group momentum, :meth:`gnipy.spaces.GroupSpace.legendre_jump`).

        For the Cayley map and the exponential it is $\\mathrm{ad}_\\xi$ exactly: the odd part of
        $\\mathrm{dcay}^{-1}_x y = (I - x/2)\\,y\\,(I + x/2)$ and of the Bernoulli series of
        $\\mathrm{dexp}^{-1}$ is $-\\tfrac12\\mathrm{ad}_x$.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d, d).
        """
        _check_group(group)
        xi = _check_vector(xi, group.dim)
        if isinstance(group, ProductGroup):
            return block_diag(*[self.dtau_inv_jump(f, x) for f, x in zip(group.factors, group.split(xi))])
        if group.dim == 0:
            return jnp.zeros((0, 0), dtype=xi.dtype)
        return self._dtau_inv_jump(group, xi)

    def _dtau_inv_jump(self, group, xi):
        return group.ad(xi)

    def dtau_inv_along(self, group: MatrixLieGroup, xi):
        """$\\mathrm{d}\\tau^{-1}_\\xi\\,\\xi$, the inverse tangent (eq:dtauinversedef) applied to its own base point.

        The velocity on which discrete Lagrange–d'Alembert imposes its discrete constraint on a group
        (:class:`~gnipy.DiscreteLagrangeDAlembert`): $\\mathrm{d}\\tau^{-1}_\\sigma\\sigma/h$, the same
        matrix that carries $\\partial l_d/\\partial\\sigma$ into the momentum ((RedLegTr)). It is even in
        the sense $\\mathrm{d}\\tau^{-1}_{-\\xi}\\xi = \\mathrm{d}\\tau^{-1}_\\xi\\xi$ (the odd part
        $-\\tfrac12\\mathrm{ad}_\\xi$ of both retractions' $\\mathrm{d}\\tau^{-1}$ vanishes on ξ), so
        left and right trivializations give the same vector. Closed forms:

        - exp: $\\xi$ exactly (every term of the Bernoulli series but the first holds $\\mathrm{ad}_\\xi\\xi = 0$);
        - Cayley: $\\hat\\xi - \\hat\\xi^3/4$ ((I − x/2) x (I + x/2), Appendix b), which is
          $\\xi(1 + |\\xi|^2/4)$ on SO(3) and $\\xi(1 + \\omega^2/4)$ on SE(2) ($\\hat\\xi^3 = -|\\xi|^2\\hat\\xi$,
          resp. $-\\omega^2\\hat\\xi$), $\\xi$ on $\\mathbb{R}^n$.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d,).
        """
        _check_group(group)
        xi = _check_vector(xi, group.dim)
        if isinstance(group, ProductGroup):
            return jnp.concatenate([self.dtau_inv_along(f, x) for f, x in zip(group.factors, group.split(xi))])
        if group.dim == 0:
            return xi
        return self._dtau_inv_along(group, xi)

    def _dtau_inv_along(self, group, xi):
        return self._dtau_inv(group, xi) @ xi

    def tau_inv(self, group: MatrixLieGroup, g):
        """The local inverse $\\tau^{-1}(g)$, e.g. to recover $\\sigma_k = \\tau^{-1}(R_k^{-1}R_{k+1})$.

        Arguments:
            group: the group $G$.
            g: shape (k, k), an element of $G$ in the image of $\\tau$.

        Returns:
            shape (d,).
        """
        _check_group(group)
        g = _check_matrix(g, group.matrix_size)
        if isinstance(group, ProductGroup):
            return jnp.concatenate([self.tau_inv(f, B) for f, B in zip(group.factors, group.blocks(g))])
        if group.dim == 0:
            return jnp.zeros((0,), dtype=g.dtype)
        return self._tau_inv(group, g)

    def _tau(self, group, xi):
        raise NotImplementedError

    def _dtau(self, group, xi):
        raise NotImplementedError

    def _dtau_inv(self, group, xi):
        raise NotImplementedError

    def _tau_inv(self, group, g):
        raise NotImplementedError


# ---------------------------------------------------------------------------------------------
# Cayley
# ---------------------------------------------------------------------------------------------


class Cayley(Retraction):
    """The Cayley map $\\mathrm{cay}(\\xi) = (I - \\hat\\xi/2)^{-1}(I + \\hat\\xi/2)$ (Appendix b).

    Generic (any matrix group, e.g. SE(2), whose algebra is closed under these products):
    $\\mathrm{dcay}_x y = (I - x/2)^{-1} y (I + x/2)^{-1}$ and
    $\\mathrm{dcay}^{-1}_x y = (I - x/2) y (I + x/2)$, written as matrices on vee-coordinates.
    SO(3) uses the Appendix's closed forms; on $\\mathbb{R}^n$ it is $I + \\hat x$ with
    $\\mathrm{dcay} = I$. No singularity on SO(3), SE(2), $\\mathbb{R}^n$ ($I - \\hat\\xi/2$ is always
    invertible there): its derivatives are polynomial or rational, safe at 0.
    """

    name: ClassVar[str] = "cayley"

    def _tau(self, group, xi):
        if isinstance(group, SO3):
            # cay(ω̂) = I + 4/(4+|ω|²)(ω̂ + ω̂²/2)  (Appendix, SO(3))
            W = group.hat(xi)
            return jnp.eye(3) + (4.0 / (4.0 + xi @ xi)) * (W + 0.5 * (W @ W))
        if isinstance(group, Rn):
            return group.exp(xi)
        X = group.hat(xi)
        eye = jnp.eye(group.matrix_size, dtype=X.dtype)
        return small_solve(eye - 0.5 * X, eye + 0.5 * X)

    def _dtau(self, group, xi):
        if isinstance(group, SO3):
            # dcay_ω = 2/(4+|ω|²)(2I + ω̂)  (Appendix, SO(3))
            return (2.0 / (4.0 + xi @ xi)) * (2.0 * jnp.eye(3) + group.hat(xi))
        if isinstance(group, Rn):
            return jnp.eye(group.dim, dtype=xi.dtype)
        X = group.hat(xi)
        eye = jnp.eye(group.matrix_size, dtype=X.dtype)
        A_inv = small_solve(eye - 0.5 * X, eye)
        B_inv = small_solve(eye + 0.5 * X, eye)
        # dcay_x y = (I − x/2)⁻¹ y (I + x/2)⁻¹  (Appendix b)
        return jax.vmap(lambda E: group.vee(A_inv @ E @ B_inv))(group.basis()).T

    def _dtau_inv(self, group, xi):
        if isinstance(group, SO3):
            # dcay⁻¹_ω = I − ω̂/2 + ωωᵀ/4  (Appendix, SO(3))
            return jnp.eye(3) - 0.5 * group.hat(xi) + 0.25 * jnp.outer(xi, xi)
        if isinstance(group, Rn):
            return jnp.eye(group.dim, dtype=xi.dtype)
        X = group.hat(xi)
        eye = jnp.eye(group.matrix_size, dtype=X.dtype)
        A, B = eye - 0.5 * X, eye + 0.5 * X
        # dcay⁻¹_x y = (I − x/2) y (I + x/2)  (Appendix b)
        return jax.vmap(lambda E: group.vee(A @ E @ B))(group.basis()).T

    def _dtau_inv_along(self, group, xi):
        if isinstance(group, SO3):
            return xi * (1.0 + 0.25 * (xi @ xi))  # (I − ω̂/2 + ωωᵀ/4) ω
        if isinstance(group, SE2):
            return xi * (1.0 + 0.25 * (xi[2] * xi[2]))  # ξ̂³ = −ω²ξ̂ on se(2)
        if isinstance(group, Rn):
            return xi
        X = group.hat(xi)
        return group.vee(X - 0.25 * (X @ X @ X))  # (I − x/2) x (I + x/2) = x − x³/4

    def _tau_inv(self, group, g):
        if isinstance(group, SO3):
            # R = cay(ω̂)  ⇔  ω = 2 (R − Rᵀ)^∨ / (1 + tr R)  (defined for rotation angles < π)
            return (4.0 / (1.0 + jnp.trace(g))) * group.vee(g)
        if isinstance(group, Rn):
            return group.log(g)
        # x = 2 (g + I)⁻¹ (g − I)
        eye = jnp.eye(group.matrix_size, dtype=g.dtype)
        return group.vee(2.0 * small_solve(g + eye, g - eye))


# ---------------------------------------------------------------------------------------------
# Exp
# ---------------------------------------------------------------------------------------------

# Horner coefficients of the paper's series (Appendix a), for the generic fallback.
_DEXP_TERMS = 20  # 1/(j+1)!: the first omitted term is < 1e-19 for |ad_ξ| ≤ 1
_DEXP_INV_TERMS = 28  # B_j/j!: |B_j/j!| ≈ 2/(2π)^j, < 1e-22 at j = 28 for |ad_ξ| ≤ 1


def _matrix_series(A, coeffs):
    """$\\sum_j c_j A^j$ by Horner's rule."""
    eye = jnp.eye(A.shape[0], dtype=A.dtype)
    out = coeffs[-1] * eye
    for c in reversed(coeffs[:-1]):
        out = A @ out + c * eye
    return out


def dexp_series(group: MatrixLieGroup, xi, terms: int = _DEXP_TERMS):
    """The paper's series $\\mathrm{dexp}_x = \\sum_{j\\ge0} \\mathrm{ad}_x^j/(j+1)!$ (Appendix a), truncated.

    Arguments:
        group: any matrix group.
        xi: shape (d,).
        terms: number of terms $j = 0, \\dots, \\text{terms}-1$. The default reaches round-off for
            $\\|\\mathrm{ad}_\\xi\\| \\le 1$ (the series converges everywhere, more slowly for larger $\\xi$).

    Returns:
        shape (d, d).
    """
    coeffs = [1.0 / math.factorial(j + 1) for j in range(terms)]
    return _matrix_series(group.ad(xi), coeffs)


def dexp_inv_series(group: MatrixLieGroup, xi, terms: int = _DEXP_INV_TERMS):
    """The paper's series $\\mathrm{dexp}^{-1}_x = \\sum_{j\\ge0} (B_j/j!)\\,\\mathrm{ad}_x^j$ ($B_1 = -1/2$), truncated.

    Arguments:
        group: any matrix group.
        xi: shape (d,).
        terms: number of terms. The default reaches round-off for $\\|\\mathrm{ad}_\\xi\\| \\le 1$;
            the series converges only for spectral radius of $\\mathrm{ad}_\\xi$ below $2\\pi$.

    Returns:
        shape (d, d).
    """
    coeffs = [float(_BERNOULLI[j]) / math.factorial(j) for j in range(terms)]
    return _matrix_series(group.ad(xi), coeffs)


class Exp(Retraction):
    """The exponential map $\\tau = \\exp$ (Appendix a).

    Closed forms, safe at 0 (Taylor branches):

    - SO(3), $\\theta = |\\omega|$: $\\mathrm{dexp}_\\omega = I + \\frac{1-\\cos\\theta}{\\theta^2}\\hat\\omega + \\frac{\\theta-\\sin\\theta}{\\theta^3}\\hat\\omega^2$,
      $\\mathrm{dexp}^{-1}_\\omega = I - \\tfrac12\\hat\\omega + \\frac{1}{\\theta^2}\\bigl(1 - \\frac\\theta2\\cot\\frac\\theta2\\bigr)\\hat\\omega^2$
      (valid for $\\theta < 2\\pi$);
    - SE(2): $\\mathrm{dexp}_\\xi = \\begin{pmatrix} V(\\omega) & -W(\\omega)Jv\\\\ 0 & 1\\end{pmatrix}$ with
      $V = \\varphi_1(\\omega J)$, $W = \\varphi_2(\\omega J) = \\frac{1-\\cos\\omega}{\\omega^2}I + \\frac{\\omega-\\sin\\omega}{\\omega^2}J$
      ($\\varphi_1(z) = (e^z - 1)/z$, $\\varphi_2(z) = (e^z - 1 - z)/z^2$; $\\mathrm{ad}_\\xi$ is block
      upper-triangular), and $\\mathrm{dexp}^{-1}_\\xi$ its block inverse (valid for $|\\omega| < 2\\pi$);
    - $\\mathbb{R}^n$: $\\mathrm{dexp} = I$.

    Other groups use the truncated series :func:`dexp_series` and :func:`dexp_inv_series`, accurate
    to round-off for $\\|\\mathrm{ad}_\\xi\\| \\le 1$.
    """

    name: ClassVar[str] = "exp"

    def _tau(self, group, xi):
        return group.exp(xi)

    def _dtau(self, group, xi):
        if isinstance(group, SO3):
            t = xi @ xi
            W = group.hat(xi)
            return jnp.eye(3) + one_minus_cos_sq(t) * W + theta_minus_sin_sq(t) * (W @ W)
        if isinstance(group, SE2):
            v, w = xi[:2], xi[2]
            t = w * w
            Wmat = _rot_scale(one_minus_cos_sq(t), w * theta_minus_sin_sq(t))
            c = -Wmat @ _J(v)
            return _se2_block(SE2.V(w), c)
        if isinstance(group, Rn):
            return jnp.eye(group.dim, dtype=xi.dtype)
        return dexp_series(group, xi)

    def _dtau_inv(self, group, xi):
        if isinstance(group, SO3):
            W = group.hat(xi)
            return jnp.eye(3) - 0.5 * W + dexp_inv_coefficient_sq(xi @ xi) * (W @ W)
        if isinstance(group, SE2):
            v, w = xi[:2], xi[2]
            t = w * w
            Wmat = _rot_scale(one_minus_cos_sq(t), w * theta_minus_sin_sq(t))
            Vinv = SE2.V_inv(w)
            # [[V, c], [0, 1]]⁻¹ = [[V⁻¹, −V⁻¹c], [0, 1]] with c = −W J v
            return _se2_block(Vinv, Vinv @ (Wmat @ _J(v)))
        if isinstance(group, Rn):
            return jnp.eye(group.dim, dtype=xi.dtype)
        return dexp_inv_series(group, xi)

    def _dtau_inv_along(self, group, xi):
        return xi  # dexp⁻¹_ξ ξ = ξ: ad_ξ ξ = 0

    def _tau_inv(self, group, g):
        return group.log(g)


def _J(v):
    """$Jv$ with $J$ the rotation by $\\pi/2$."""
    return jnp.stack([-v[1], v[0]])


def _rot_scale(a, b):
    """$aI + bJ$."""
    return jnp.array([[a, -b], [b, a]])


def _se2_block(top_left, top_right):
    """$\\begin{pmatrix} A & c\\\\ 0 & 1\\end{pmatrix}$ (3x3)."""
    out = jnp.zeros((3, 3), dtype=top_left.dtype)
    return out.at[:2, :2].set(top_left).at[:2, 2].set(top_right).at[2, 2].set(1.0)


_RETRACTIONS = {"cayley": Cayley, "exp": Exp}


def retraction_names() -> tuple[str, ...]:
    """The names accepted by :func:`get_retraction`."""
    return tuple(_RETRACTIONS)


def get_retraction(name: str) -> Retraction:
    """The retraction with a given name.

    Arguments:
        name: `"cayley"` or `"exp"` (case-insensitive).

    Returns:
        a :class:`Retraction` instance.

    Raises:
        ValueError: for any other name; the message names the argument `retraction`.
    """
    key = name.strip().lower() if isinstance(name, str) else None
    if key not in _RETRACTIONS:
        raise ValueError(f"retraction: expected one of {', '.join(map(repr, _RETRACTIONS))}, got {name!r}")
    return _RETRACTIONS[key]()
