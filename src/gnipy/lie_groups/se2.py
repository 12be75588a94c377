"""The planar rigid motions SE(2), with closed-form `exp`, `log`, `Ad`, `ad`, $\\mathrm{dexp}$ and
$\\mathrm{dexp}^{-1}$ (the Cayley map and its tangents are the base class's matrix formulas)."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from ..compilation import traced_once
from .base import MatrixLieGroup, check_matrix, check_vector
from .series import cos_sq, half_cot_half_sq, one_minus_cos_sq, sinc_sq, theta_minus_sin_sq


class SE2(MatrixLieGroup):
    """The planar rigid motions SE(2) ($d = k = 3$), $g = \\begin{pmatrix} R(\\theta) & t\\\\ 0 & 1\\end{pmatrix}$.

    Algebra coordinates $\\xi = (v_x, v_y, \\omega)$ with
    $\\hat\\xi = \\begin{pmatrix} 0 & -\\omega & v_x\\\\ \\omega & 0 & v_y\\\\ 0&0&0\\end{pmatrix}$.
    Closed forms: $\\exp\\hat\\xi = (R(\\omega), V(\\omega)v)$ with
    $V(\\omega) = \\frac{\\sin\\omega}{\\omega} I + \\frac{1-\\cos\\omega}{\\omega} J$ (safe at $\\omega\\to0$),
    $J = \\begin{pmatrix}0&-1\\\\1&0\\end{pmatrix}$; $\\mathrm{Ad}_g = \\begin{pmatrix} R & -Jt\\\\ 0 & 1\\end{pmatrix}$;
    $\\mathrm{ad}_\\xi = \\begin{pmatrix} \\omega J & -Jv\\\\ 0 & 0\\end{pmatrix}$;
    $\\mathrm{dexp}_\\xi$ and $\\mathrm{dexp}^{-1}_\\xi$ in closed form (:meth:`dexp`); the Cayley map and
    its tangents by the base class's matrix formulas (Appendix b), with
    $\\mathrm{dcay}^{-1}_\\xi\\xi = \\xi(1 + \\omega^2/4)$ in closed form.
    """

    velocity_names: ClassVar[tuple[str, ...]] = ("v_x", "v_y", "omega")

    @property
    def dim(self) -> int:
        return 3

    @property
    def matrix_size(self) -> int:
        return 3

    @traced_once
    def hat(self, xi):
        """$\\hat\\xi$ for $\\xi = (v_x, v_y, \\omega)$.

        Arguments:
            xi: shape (3,).

        Returns:
            shape (3, 3).
        """
        vx, vy, w = check_vector(xi, 3)
        z = jnp.zeros_like(w)
        return jnp.array([[z, -w, vx], [w, z, vy], [z, z, z]])

    @traced_once
    def vee(self, X):
        """$(X_{02}, X_{12}, (X_{10} - X_{01})/2)$.

        Arguments:
            X: shape (3, 3).

        Returns:
            shape (3,).
        """
        X = check_matrix(X, 3, "X")
        return jnp.stack([X[0, 2], X[1, 2], 0.5 * (X[1, 0] - X[0, 1])])

    @staticmethod
    def V(w):
        """$V(\\omega) = \\frac{\\sin\\omega}{\\omega} I + \\frac{1-\\cos\\omega}{\\omega} J$ (safe at 0).

        Arguments:
            w: the angle $\\omega$ (scalar).

        Returns:
            shape (2, 2): $\\exp\\hat\\xi$ has translation $V(\\omega)\\,v$.
        """
        t = w * w
        a = sinc_sq(t)
        b = w * one_minus_cos_sq(t)
        return jnp.array([[a, -b], [b, a]])

    @staticmethod
    def V_inv(w):
        """$V(\\omega)^{-1} = \\frac{\\omega}{2}\\cot\\frac{\\omega}{2} I - \\frac{\\omega}{2} J$ (safe at 0; pole at $2\\pi$)."""
        a = half_cot_half_sq(w * w)
        b = -0.5 * w
        return jnp.array([[a, -b], [b, a]])

    def inverse(self, g):
        """$(R, t)^{-1} = (R^T, -R^T t)$."""
        g = check_matrix(g, 3)
        Rt = g[:2, :2].T
        return jnp.zeros_like(g).at[:2, :2].set(Rt).at[:2, 2].set(-Rt @ g[:2, 2]).at[2, 2].set(1.0)

    @traced_once
    def exp(self, xi):
        """$\\exp\\hat\\xi = (R(\\omega), V(\\omega)v)$.

        Arguments:
            xi: $(v_x, v_y, \\omega)$, shape (3,).

        Returns:
            shape (3, 3). Safe at $\\omega = 0$ (values and gradients).
        """
        xi = check_vector(xi, 3)
        v, w = xi[:2], xi[2]
        t = w * w
        c, s = cos_sq(t), w * sinc_sq(t)
        R = jnp.array([[c, -s], [s, c]])
        g = jnp.zeros((3, 3), dtype=R.dtype)
        return g.at[:2, :2].set(R).at[:2, 2].set(self.V(w) @ v).at[2, 2].set(1.0)

    @traced_once
    def log(self, g):
        """Principal logarithm: $\\omega = \\mathrm{atan2}(R_{10}, R_{00})\\in(-\\pi, \\pi]$, $v = V(\\omega)^{-1} t$.

        Arguments:
            g: shape (3, 3).

        Returns:
            $(v_x, v_y, \\omega)$, shape (3,).
        """
        g = check_matrix(g, 3)
        w = jnp.arctan2(g[1, 0], g[0, 0])
        return jnp.concatenate([self.V_inv(w) @ g[:2, 2], w[None]])

    def Ad(self, g):
        """$\\mathrm{Ad}_g = \\begin{pmatrix} R & -Jt\\\\ 0 & 1\\end{pmatrix}$, i.e. the $\\omega$ column is $(t_y, -t_x, 1)$."""
        g = check_matrix(g, 3)
        out = jnp.zeros_like(g).at[:2, :2].set(g[:2, :2])
        return out.at[0, 2].set(g[1, 2]).at[1, 2].set(-g[0, 2]).at[2, 2].set(1.0)

    @traced_once
    def ad(self, xi):
        """$\\mathrm{ad}_\\xi = \\begin{pmatrix} \\omega J & -Jv\\\\ 0 & 0\\end{pmatrix}$: $[\\xi, \\eta] = (\\omega J u - \\eta_\\omega J v,\\ 0)$."""
        vx, vy, w = check_vector(xi, 3)
        z = jnp.zeros_like(w)
        return jnp.array([[z, -w, vy], [w, z, -vx], [z, z, z]])

    # -- retraction maps (paper, Appendix) ------------------------------------------------------

    def dcayley_inv_along(self, xi):
        """$\\mathrm{dcay}^{-1}_\\xi\\,\\xi = \\xi\\,(1 + \\omega^2/4)$: $\\hat\\xi - \\hat\\xi^3/4$ (Appendix b) with
        $\\hat\\xi^3 = -\\omega^2\\hat\\xi$ on $\\mathfrak{se}(2)$."""
        xi = check_vector(xi, 3)
        return xi * (1.0 + 0.25 * (xi[2] * xi[2]))

    @traced_once
    def dexp(self, xi):
        """$\\mathrm{dexp}_\\xi = \\begin{pmatrix} V(\\omega) & -W(\\omega)Jv\\\\ 0 & 1\\end{pmatrix}$ (Appendix a, summed).

        $V = \\varphi_1(\\omega J)$, $W = \\varphi_2(\\omega J) = \\frac{1-\\cos\\omega}{\\omega^2}I + \\frac{\\omega-\\sin\\omega}{\\omega^2}J$
        ($\\varphi_1(z) = (e^z - 1)/z$, $\\varphi_2(z) = (e^z - 1 - z)/z^2$; $\\mathrm{ad}_\\xi$ is block
        upper-triangular). Safe at $\\omega = 0$.

        Arguments:
            xi: $(v_x, v_y, \\omega)$, shape (3,).

        Returns:
            shape (3, 3).
        """
        xi = check_vector(xi, 3)
        v, w = xi[:2], xi[2]
        return _block(self.V(w), -_W(w) @ _J(v))

    @traced_once
    def dexp_inv(self, xi):
        """$\\mathrm{dexp}^{-1}_\\xi$, the block inverse of :meth:`dexp`:
        $\\begin{pmatrix} V^{-1} & V^{-1}WJv\\\\ 0 & 1\\end{pmatrix}$ (valid for $|\\omega| < 2\\pi$; safe at 0),
        a (3, 3) matrix for $\\xi = (v_x, v_y, \\omega)$ of shape (3,).
        """
        xi = check_vector(xi, 3)
        v, w = xi[:2], xi[2]
        Vinv = self.V_inv(w)
        # [[V, c], [0, 1]]⁻¹ = [[V⁻¹, −V⁻¹c], [0, 1]] with c = −W J v
        return _block(Vinv, Vinv @ (_W(w) @ _J(v)))

    def random(self, key):
        """$\\omega$ uniform in $(-\\pi, \\pi)$, translation standard normal."""
        k1, k2 = jax.random.split(key)
        w = jax.random.uniform(k1, (), minval=-jnp.pi, maxval=jnp.pi)
        t = jax.random.normal(k2, (2,))
        c, s = jnp.cos(w), jnp.sin(w)
        return jnp.array([[c, -s, t[0]], [s, c, t[1]], [0.0, 0.0, 1.0]])


def _J(v):
    """$Jv$ with $J$ the rotation by $\\pi/2$."""
    return jnp.stack([-v[1], v[0]])


def _W(w):
    """$W(\\omega) = \\frac{1-\\cos\\omega}{\\omega^2}I + \\frac{\\omega-\\sin\\omega}{\\omega^2}J$ (safe at 0)."""
    t = w * w
    a, b = one_minus_cos_sq(t), w * theta_minus_sin_sq(t)
    return jnp.array([[a, -b], [b, a]])


def _block(top_left, top_right):
    """$\\begin{pmatrix} A & c\\\\ 0 & 1\\end{pmatrix}$ (3x3)."""
    out = jnp.zeros((3, 3), dtype=top_left.dtype)
    return out.at[:2, :2].set(top_left).at[:2, 2].set(top_right).at[2, 2].set(1.0)
