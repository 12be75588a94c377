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

Two retractions are provided, :class:`Cayley` (`"cayley"`) and :class:`Exp` (`"exp"`). The maps
themselves belong to the groups (jaxlie's pattern: the group knows its maps): a retraction only
validates its arguments and calls the group's methods, `cayley`, `dcayley`, ... or `exp`, `dexp`,
... of :class:`~gnipy.lie_groups.MatrixLieGroup`. The groups give closed forms for SO(3)
(Appendix, "Applications to matrix groups"), SE(2) and $\\mathbb{R}^n$, act blockwise on a
:class:`~gnipy.lie_groups.ProductGroup`, and fall back to a generic matrix formula (Cayley) or to
the paper's series (exp) for any other group. Everything is safe at $\\xi = 0$ (no NaN values or
gradients) and `jit`/`vmap`/`grad` friendly.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from .lie_groups import MatrixLieGroup
from .lie_groups.base import check_matrix, check_vector
from .lie_groups.series import dexp_inv_series, dexp_series

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

    The public methods validate their arguments and delegate to the subclass's `_tau`, `_dtau`,
    `_dtau_inv`, `_dtau_inv_along`, `_tau_inv`, each of which calls one method of the group (the
    group owns the maps: closed forms, blockwise products and generic fallbacks live there).
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
        return self._tau(group, check_vector(xi, group.dim))

    def dtau(self, group: MatrixLieGroup, xi):
        """The right-trivialized tangent $\\mathrm{d}\\tau_\\xi$ (eq:dtaudef) as a matrix.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d, d): column $j$ is $\\mathrm{d}\\tau_\\xi e_j$.
        """
        _check_group(group)
        return self._dtau(group, check_vector(xi, group.dim))

    def dtau_inv(self, group: MatrixLieGroup, xi):
        """The inverse $\\mathrm{d}\\tau^{-1}_\\xi$ (eq:dtauinversedef) as a matrix.

        Arguments:
            group: the group $G$.
            xi: shape (d,).

        Returns:
            shape (d, d), the inverse of `dtau(group, xi)`.
        """
        _check_group(group)
        return self._dtau_inv(group, check_vector(xi, group.dim))

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
        return self._dtau_inv_jump(group, check_vector(xi, group.dim))

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
        return self._dtau_inv_along(group, check_vector(xi, group.dim))

    def tau_inv(self, group: MatrixLieGroup, g):
        """The local inverse $\\tau^{-1}(g)$, e.g. to recover $\\sigma_k = \\tau^{-1}(R_k^{-1}R_{k+1})$.

        Arguments:
            group: the group $G$.
            g: shape (k, k), an element of $G$ in the image of $\\tau$.

        Returns:
            shape (d,).
        """
        _check_group(group)
        return self._tau_inv(group, check_matrix(g, group.matrix_size))

    def _tau(self, group, xi):
        raise NotImplementedError

    def _dtau(self, group, xi):
        raise NotImplementedError

    def _dtau_inv(self, group, xi):
        raise NotImplementedError

    def _dtau_inv_along(self, group, xi):
        return self._dtau_inv(group, xi) @ xi

    def _tau_inv(self, group, g):
        raise NotImplementedError


class Cayley(Retraction):
    """The Cayley map $\\mathrm{cay}(\\xi) = (I - \\hat\\xi/2)^{-1}(I + \\hat\\xi/2)$ (Appendix b).

    Calls the group's :meth:`~gnipy.lie_groups.MatrixLieGroup.cayley`, `cayley_inv`, `dcayley`,
    `dcayley_inv` and `dcayley_inv_along`. Generic (any matrix group, e.g. SE(2), whose algebra
    is closed under these products): $\\mathrm{dcay}_x y = (I - x/2)^{-1} y (I + x/2)^{-1}$ and
    $\\mathrm{dcay}^{-1}_x y = (I - x/2) y (I + x/2)$, written as matrices on vee-coordinates.
    SO(3) uses the Appendix's closed forms; on $\\mathbb{R}^n$ it is $I + \\hat x$ with
    $\\mathrm{dcay} = I$. No singularity on SO(3), SE(2), $\\mathbb{R}^n$ ($I - \\hat\\xi/2$ is always
    invertible there): its derivatives are polynomial or rational, safe at 0.
    """

    name: ClassVar[str] = "cayley"

    def _tau(self, group, xi):
        return group.cayley(xi)

    def _dtau(self, group, xi):
        return group.dcayley(xi)

    def _dtau_inv(self, group, xi):
        return group.dcayley_inv(xi)

    def _dtau_inv_along(self, group, xi):
        return group.dcayley_inv_along(xi)

    def _tau_inv(self, group, g):
        return group.cayley_inv(g)


class Exp(Retraction):
    """The exponential map $\\tau = \\exp$ (Appendix a).

    Calls the group's `exp`, `log`, :meth:`~gnipy.lie_groups.MatrixLieGroup.dexp`, `dexp_inv`
    and `dexp_inv_along`. Closed forms, safe at 0 (Taylor branches):

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
        return group.dexp(xi)

    def _dtau_inv(self, group, xi):
        return group.dexp_inv(xi)

    def _dtau_inv_along(self, group, xi):
        return group.dexp_inv_along(xi)

    def _tau_inv(self, group, g):
        return group.log(g)


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
