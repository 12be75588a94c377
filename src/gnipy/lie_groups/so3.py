"""The rotation group SO(3): Rodrigues' `exp`, a quaternion-based principal `log`, and the closed
forms of the Cayley map, of $\\mathrm{dexp}$ and of their inverses (paper, Appendix)."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import traced_once
from .base import MatrixLieGroup, check_matrix, check_vector
from .series import dexp_inv_coefficient_sq, one_minus_cos_sq, sinc_sq, theta_minus_sin_sq


def _quaternion_from_rotation(R):
    """Unit quaternion $(w, x, y, z)$ of a rotation matrix (Shepperd's method).

    Of the four formulas, the one with the largest $t\\in\\{4w^2, 4x^2, 4y^2, 4z^2\\}$ is selected
    *before* the square root, so the root's argument is $\\ge 1$ and no branch produces NaN
    gradients.
    """
    m = R
    tw = 1.0 + m[0, 0] + m[1, 1] + m[2, 2]
    tx = 1.0 + m[0, 0] - m[1, 1] - m[2, 2]
    ty = 1.0 - m[0, 0] + m[1, 1] - m[2, 2]
    tz = 1.0 - m[0, 0] - m[1, 1] + m[2, 2]
    qw = jnp.stack([tw, m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    qx = jnp.stack([m[2, 1] - m[1, 2], tx, m[1, 0] + m[0, 1], m[0, 2] + m[2, 0]])
    qy = jnp.stack([m[0, 2] - m[2, 0], m[1, 0] + m[0, 1], ty, m[2, 1] + m[1, 2]])
    qz = jnp.stack([m[1, 0] - m[0, 1], m[0, 2] + m[2, 0], m[2, 1] + m[1, 2], tz])
    ts = jnp.stack([tw, tx, ty, tz])
    i = jnp.argmax(ts)
    t = ts[i]
    q = jnp.stack([qw, qx, qy, qz])[i]
    return q * (0.5 / jnp.sqrt(t))


def _rotation_from_quaternion(q):
    w, x, y, z = q / jnp.linalg.norm(q)
    return jnp.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class SO3(MatrixLieGroup):
    """The rotation group SO(3) ($d = k = 3$), with the paper's hat map (hatso).

    Closed forms: Rodrigues' `exp`, a quaternion-based principal `log` (robust up to angle $\\pi$),
    $\\mathrm{Ad}_R = R$, $\\mathrm{ad}_\\omega = \\hat\\omega$, $\\mathrm{ad}^*_\\omega M = M\\times\\omega$;
    the Cayley map, its inverse and tangents from the Appendix ("Applications to matrix groups",
    SO(3)); $\\mathrm{dexp}$ and $\\mathrm{dexp}^{-1}$ in closed form (safe at 0, Taylor branches).
    """

    velocity_names: ClassVar[tuple[str, ...]] = ("omega1", "omega2", "omega3")

    @property
    def dim(self) -> int:
        return 3

    @property
    def matrix_size(self) -> int:
        return 3

    @traced_once
    def hat(self, xi):
        """$\\hat\\omega$ with $\\hat\\omega\\rho = \\omega\\times\\rho$ (hatso).

        Arguments:
            xi: $\\omega$, shape (3,).

        Returns:
            shape (3, 3), skew-symmetric.
        """
        w1, w2, w3 = check_vector(xi, 3)
        z = jnp.zeros_like(w1)
        return jnp.array([[z, -w3, w2], [w3, z, -w1], [-w2, w1, z]])

    @traced_once
    def vee(self, X):
        """$\\omega$ from the skew part of $X$ (the orthogonal projection onto $\\mathfrak{so}(3)$).

        Arguments:
            X: shape (3, 3).

        Returns:
            shape (3,).
        """
        X = check_matrix(X, 3, "X")
        return 0.5 * jnp.stack([X[2, 1] - X[1, 2], X[0, 2] - X[2, 0], X[1, 0] - X[0, 1]])

    def inverse(self, g):
        """$R^{-1} = R^T$."""
        return check_matrix(g, 3).T

    @traced_once
    def exp(self, xi):
        """Rodrigues: $\\exp\\hat\\omega = I + \\frac{\\sin\\theta}{\\theta}\\hat\\omega + \\frac{1-\\cos\\theta}{\\theta^2}\\hat\\omega^2$, $\\theta = |\\omega|$.

        Arguments:
            xi: $\\omega$, shape (3,).

        Returns:
            shape (3, 3). Safe at $\\omega = 0$ (values and gradients).
        """
        w = check_vector(xi, 3)
        t = w @ w
        W = self.hat(w)
        return jnp.eye(3) + sinc_sq(t) * W + one_minus_cos_sq(t) * (W @ W)

    @traced_once
    def log(self, g):
        """Principal logarithm: $\\omega$ with $|\\omega| \\le \\pi$ and $\\exp\\hat\\omega = R$.

        Computed through the unit quaternion $(w, v)$ of $R$, taken with $w \\ge 0$:
        $\\omega = 2\\,\\mathrm{atan2}(|v|, w)\\, v/|v|$, with a Taylor branch in $|v|^2/w^2$ near the
        identity (values and gradients safe there). Exactly at angle $\\pi$ either sign is returned.

        Arguments:
            g: $R$, shape (3, 3).

        Returns:
            shape (3,).
        """
        q = _quaternion_from_rotation(check_matrix(g, 3))
        q = jnp.where(q[0] < 0, -q, q)
        w, v = q[0], q[1:]
        n2 = v @ v
        use_taylor = n2 < 1e-3
        # Taylor: 2 atan(x)/x / w with x = |v|/w; w ≥ 0.99 on this branch.
        w_safe = jnp.where(use_taylor, w, 1.0)
        x2 = n2 / w_safe**2
        series = jnp.zeros_like(x2)
        for j in reversed(range(7)):
            series = series * x2 + (-1) ** j / (2 * j + 1)
        taylor = 2.0 * series / w_safe
        n_safe = jnp.sqrt(jnp.where(use_taylor, 1.0, n2))
        closed = 2.0 * jnp.arctan2(n_safe, w) / n_safe
        return jnp.where(use_taylor, taylor, closed) * v

    def Ad(self, g):
        """$\\mathrm{Ad}_R = R$."""
        return check_matrix(g, 3)

    def ad(self, xi):
        """$\\mathrm{ad}_\\omega = \\hat\\omega$ (the bracket is the cross product)."""
        return self.hat(xi)

    def ad_star(self, xi, m):
        """$\\mathrm{ad}^*_\\omega M = \\hat\\omega^T M = M\\times\\omega$."""
        return jnp.cross(jnp.asarray(m), check_vector(xi, 3))

    def random(self, key):
        """A uniformly distributed rotation (normalized Gaussian quaternion)."""
        return _rotation_from_quaternion(jax.random.normal(key, (4,)))

    # -- retraction maps (paper, Appendix, "Applications to matrix groups": SO(3)) -------------

    @traced_once
    def cayley(self, xi):
        """$\\mathrm{cay}(\\hat\\omega) = I + \\frac{4}{4 + |\\omega|^2}\\bigl(\\hat\\omega + \\tfrac12\\hat\\omega^2\\bigr)$ (Appendix, SO(3))."""
        w = check_vector(xi, 3)
        W = self.hat(w)
        return jnp.eye(3) + (4.0 / (4.0 + w @ w)) * (W + 0.5 * (W @ W))

    @traced_once
    def cayley_inv(self, g):
        """$R = \\mathrm{cay}(\\hat\\omega) \\Leftrightarrow \\omega = 2\\,(R - R^T)^\\vee/(1 + \\mathrm{tr}\\,R)$
        (Appendix, SO(3); defined for rotation angles below $\\pi$)."""
        g = check_matrix(g, 3)
        return (4.0 / (1.0 + jnp.trace(g))) * self.vee(g)

    @traced_once
    def dcayley(self, xi):
        """$\\mathrm{dcay}_\\omega = \\frac{2}{4 + |\\omega|^2}(2I + \\hat\\omega)$ (Appendix, SO(3))."""
        w = check_vector(xi, 3)
        return (2.0 / (4.0 + w @ w)) * (2.0 * jnp.eye(3) + self.hat(w))

    @traced_once
    def dcayley_inv(self, xi):
        """$\\mathrm{dcay}^{-1}_\\omega = I - \\tfrac12\\hat\\omega + \\tfrac14\\omega\\omega^T$ (Appendix, SO(3))."""
        w = check_vector(xi, 3)
        return jnp.eye(3) - 0.5 * self.hat(w) + 0.25 * jnp.outer(w, w)

    @traced_once
    def dcayley_inv_along(self, xi):
        """$\\mathrm{dcay}^{-1}_\\omega\\,\\omega = \\omega\\,(1 + |\\omega|^2/4)$ ($\\hat\\omega\\omega = 0$)."""
        w = check_vector(xi, 3)
        return w * (1.0 + 0.25 * (w @ w))  # (I − ω̂/2 + ωωᵀ/4) ω

    @traced_once
    def dexp(self, xi):
        """$\\mathrm{dexp}_\\omega = I + \\frac{1-\\cos\\theta}{\\theta^2}\\hat\\omega + \\frac{\\theta-\\sin\\theta}{\\theta^3}\\hat\\omega^2$,
        $\\theta = |\\omega|$ (Appendix a, summed; safe at 0)."""
        w = check_vector(xi, 3)
        t = w @ w
        W = self.hat(w)
        return jnp.eye(3) + one_minus_cos_sq(t) * W + theta_minus_sin_sq(t) * (W @ W)

    @traced_once
    def dexp_inv(self, xi):
        """$\\mathrm{dexp}^{-1}_\\omega = I - \\tfrac12\\hat\\omega + \\frac{1}{\\theta^2}\\bigl(1 - \\frac\\theta2\\cot\\frac\\theta2\\bigr)\\hat\\omega^2$
        (Appendix a, summed; safe at 0, valid for $\\theta < 2\\pi$)."""
        w = check_vector(xi, 3)
        W = self.hat(w)
        return jnp.eye(3) - 0.5 * W + dexp_inv_coefficient_sq(w @ w) * (W @ W)

    # -- host-side checks ----------------------------------------------------------------------

    def is_element(self, g, tol: float = 1e-10):
        """Rotation matrices: $|R^TR - I| \\le$ `tol` (largest entry) and $\\det R > 0$ (host side, NumPy)."""
        err, det = _orthogonality_defect(g)
        return ~((err > tol) | (det <= 0))

    def why_not_element(self, g) -> str:
        """`"not a rotation matrix (|RᵀR − I| = …, det = …)"`."""
        err, det = _orthogonality_defect(g)
        return f"not a rotation matrix (|RᵀR − I| = {float(err):.3e}, det = {float(det):.3g})"

    def is_bi_invariant(self, metric, atol):
        """The bi-invariant metrics on $\\mathfrak{so}(3)$ are $cI$ (SO(3) is simple): whether every
        entry of $M - M_{00}I$ is within `atol` (host side, NumPy)."""
        M = np.asarray(metric)
        return np.max(np.abs(M - M[..., :1, :1] * np.eye(3)), axis=(-2, -1)) <= atol


def _orthogonality_defect(g):
    """$\\max|R^TR - I|$ and $\\det R$ of the matrices `g` (shape (..., 3, 3), NumPy)."""
    g = np.asarray(g)
    err = np.max(np.abs(np.einsum("...ji,...jk->...ik", g, g) - np.eye(3)), axis=(-2, -1))
    return err, np.linalg.det(g)
