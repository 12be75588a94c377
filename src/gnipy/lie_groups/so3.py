"""The rotation group SO(3): Rodrigues' `exp` and a quaternion-based principal `log`."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from .base import MatrixLieGroup, _check_matrix, _check_vector
from .series import one_minus_cos_sq, sinc_sq


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
    $\\mathrm{Ad}_R = R$, $\\mathrm{ad}_\\omega = \\hat\\omega$, $\\mathrm{ad}^*_\\omega M = M\\times\\omega$.
    """

    velocity_names: ClassVar[tuple[str, ...]] = ("omega1", "omega2", "omega3")

    @property
    def dim(self) -> int:
        return 3

    @property
    def matrix_size(self) -> int:
        return 3

    def hat(self, xi):
        """$\\hat\\omega$ with $\\hat\\omega\\rho = \\omega\\times\\rho$ (hatso).

        Arguments:
            xi: $\\omega$, shape (3,).

        Returns:
            shape (3, 3), skew-symmetric.
        """
        w1, w2, w3 = _check_vector(xi, 3)
        z = jnp.zeros_like(w1)
        return jnp.array([[z, -w3, w2], [w3, z, -w1], [-w2, w1, z]])

    def vee(self, X):
        """$\\omega$ from the skew part of $X$ (the orthogonal projection onto $\\mathfrak{so}(3)$).

        Arguments:
            X: shape (3, 3).

        Returns:
            shape (3,).
        """
        X = _check_matrix(X, 3, "X")
        return 0.5 * jnp.stack([X[2, 1] - X[1, 2], X[0, 2] - X[2, 0], X[1, 0] - X[0, 1]])

    def inverse(self, g):
        """$R^{-1} = R^T$."""
        return _check_matrix(g, 3).T

    def exp(self, xi):
        """Rodrigues: $\\exp\\hat\\omega = I + \\frac{\\sin\\theta}{\\theta}\\hat\\omega + \\frac{1-\\cos\\theta}{\\theta^2}\\hat\\omega^2$, $\\theta = |\\omega|$.

        Arguments:
            xi: $\\omega$, shape (3,).

        Returns:
            shape (3, 3). Safe at $\\omega = 0$ (values and gradients).
        """
        w = _check_vector(xi, 3)
        t = w @ w
        W = self.hat(w)
        return jnp.eye(3) + sinc_sq(t) * W + one_minus_cos_sq(t) * (W @ W)

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
        q = _quaternion_from_rotation(_check_matrix(g, 3))
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
        return _check_matrix(g, 3)

    def ad(self, xi):
        """$\\mathrm{ad}_\\omega = \\hat\\omega$ (the bracket is the cross product)."""
        return self.hat(xi)

    def ad_star(self, xi, m):
        """$\\mathrm{ad}^*_\\omega M = \\hat\\omega^T M = M\\times\\omega$."""
        return jnp.cross(jnp.asarray(m), _check_vector(xi, 3))

    def random(self, key):
        """A uniformly distributed rotation (normalized Gaussian quaternion)."""
        return _rotation_from_quaternion(jax.random.normal(key, (4,)))
