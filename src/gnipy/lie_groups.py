"""Matrix Lie groups: SO(3), SE(2), $\\mathbb{R}^n$, products and the trivial group.

Part of the core of the package (the docs' conventions page, "Architecture"). A group is a small
`equinox.Module` with static fields only; an element is a plain $k\\times k$ matrix and a Lie-algebra element a vector $\\xi\\in\\mathbb{R}^d$
(its matrix is $\\hat\\xi$). Every function is written for one unbatched element (use `jax.vmap` for
batches), in float64, and is `jit`/`vmap`/`grad` friendly.

Conventions (paper §7 and Appendix; the docs' conventions page):

- `hat`/`vee` identify $\\mathbb{R}^d$ with $\\mathfrak g$; for SO(3) `hat` is the paper's (hatso),
  $\\hat\\omega\\rho = \\omega\\times\\rho$.
- $\\mathrm{Ad}_g\\eta = (g\\hat\\eta g^{-1})^\\vee$, $\\mathrm{ad}_\\xi\\eta = [\\hat\\xi,\\hat\\eta]^\\vee$, and
  $\\mathrm{ad}^*_\\xi m = \\mathrm{ad}_\\xi^T m$ (for SO(3): $\\mathrm{ad}^*_\\omega M = M\\times\\omega$).
- `exp` and `log` are closed forms that are *safe at zero* in the style of jaxlie: near the
  identity a Taylor branch is selected with a "safe" `jnp.where` (the closed-form branch is fed a
  harmless dummy argument there), so neither values nor gradients (of any order) become NaN.

The base class :class:`MatrixLieGroup` implements every operation generically from `hat`, `vee` and
the basis of generators (`exp` by `jax.scipy.linalg.expm`); the concrete groups override them with
closed forms.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import block_diag, expm

__all__ = ["SE2", "SO3", "MatrixLieGroup", "ProductGroup", "Rn", "TrivialGroup"]


# ---------------------------------------------------------------------------------------------
# Even functions of an angle, written as functions of its square $t = \theta^2$, safe at $t = 0$.
# ---------------------------------------------------------------------------------------------

# Below this value of $t = \theta^2$ (|θ| < 0.5) the Taylor branch is used. The closed forms with a
# cancellation, such as $(\theta - \sin\theta)/\theta^3$, lose about $\epsilon/\theta^2$ (≤ 1e-15 at the
# switch, ≤ 1e-14 for their derivatives); the Taylor series below are truncated where the first
# omitted term is < 1e-18 at the switch. A smaller switch would trade truncation for cancellation.
_TAYLOR_T = 0.25
_TAYLOR_TERMS = 9


def _bernoulli_numbers(n: int) -> list:
    """Bernoulli numbers $B_0, \\dots, B_n$ as exact fractions, with $B_1 = -1/2$."""
    from fractions import Fraction

    B = [Fraction(0)] * (n + 1)
    for m in range(n + 1):
        B[m] = Fraction(1) if m == 0 else -sum(math.comb(m + 1, j) * B[j] for j in range(m)) / (m + 1)
    return B


_BERNOULLI = _bernoulli_numbers(40)


def _even_series_safe(t, closed, coeffs):
    """Evaluate an even function $f(\\theta)$ given $t = \\theta^2 \\ge 0$, safely near 0.

    Arguments:
        t: the squared angle $\\theta^2$ (a scalar array).
        closed: the closed form, a function of $\\theta > 0$.
        coeffs: Taylor coefficients $c_j$ with $f = \\sum_j c_j t^j$ for small $t$.

    Returns:
        $f$; the closed form is evaluated at a dummy $t = 1$ where the Taylor branch is taken, so
        that its (unused) gradient stays finite (the "double where" trick).
    """
    use_taylor = t < _TAYLOR_T
    t_safe = jnp.where(use_taylor, 1.0, t)
    closed_value = closed(jnp.sqrt(t_safe))
    taylor = jnp.zeros_like(t)
    for c in reversed(coeffs):
        taylor = taylor * t + c
    return jnp.where(use_taylor, taylor, closed_value)


def sinc_sq(t):
    """$\\sin\\theta/\\theta$ as a function of $t = \\theta^2$ (safe at 0)."""
    coeffs = [(-1) ** j / math.factorial(2 * j + 1) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, lambda th: jnp.sin(th) / th, coeffs)


def cos_sq(t):
    """$\\cos\\theta$ as a function of $t = \\theta^2$ (safe at 0, where $\\sqrt t$ is not)."""
    coeffs = [(-1) ** j / math.factorial(2 * j) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, jnp.cos, coeffs)


def one_minus_cos_sq(t):
    """$(1 - \\cos\\theta)/\\theta^2$ as a function of $t = \\theta^2$.

    Written as $\\tfrac12(\\sin(\\theta/2)/(\\theta/2))^2$, which has no cancellation.
    """
    return 0.5 * sinc_sq(0.25 * t) ** 2


def theta_minus_sin_sq(t):
    """$(\\theta - \\sin\\theta)/\\theta^3$ as a function of $t = \\theta^2$ (safe at 0)."""
    coeffs = [(-1) ** j / math.factorial(2 * j + 3) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, lambda th: (th - jnp.sin(th)) / th**3, coeffs)


def dexp_inv_coefficient_sq(t):
    """$\\bigl(1 - \\tfrac{\\theta}{2}\\cot\\tfrac{\\theta}{2}\\bigr)/\\theta^2$ as a function of $t = \\theta^2$.

    The coefficient of $\\hat\\omega^2$ in $\\mathrm{dexp}^{-1}_\\omega$ on SO(3). Analytic for
    $|\\theta| < 2\\pi$ (a pole at $2\\pi$); its series is $\\sum_{n\\ge1} (-1)^{n+1} B_{2n} t^{n-1}/(2n)!$.
    """
    coeffs = [
        float((-1) ** (n + 1) * _BERNOULLI[2 * n] / math.factorial(2 * n)) for n in range(1, _TAYLOR_TERMS + 1)
    ]

    def closed(th):
        half = 0.5 * th
        return (1.0 - half * jnp.cos(half) / jnp.sin(half)) / th**2

    return _even_series_safe(t, closed, coeffs)


def half_cot_half_sq(t):
    """$\\tfrac{\\theta}{2}\\cot\\tfrac{\\theta}{2}$ as a function of $t = \\theta^2$ (safe at 0)."""
    return 1.0 - t * dexp_inv_coefficient_sq(t)


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


# ---------------------------------------------------------------------------------------------
# SO(3)
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# SE(2)
# ---------------------------------------------------------------------------------------------

_J2 = ((0.0, -1.0), (1.0, 0.0))


class SE2(MatrixLieGroup):
    """The planar rigid motions SE(2) ($d = k = 3$), $g = \\begin{pmatrix} R(\\theta) & t\\\\ 0 & 1\\end{pmatrix}$.

    Algebra coordinates $\\xi = (v_x, v_y, \\omega)$ with
    $\\hat\\xi = \\begin{pmatrix} 0 & -\\omega & v_x\\\\ \\omega & 0 & v_y\\\\ 0&0&0\\end{pmatrix}$.
    Closed forms: $\\exp\\hat\\xi = (R(\\omega), V(\\omega)v)$ with
    $V(\\omega) = \\frac{\\sin\\omega}{\\omega} I + \\frac{1-\\cos\\omega}{\\omega} J$ (safe at $\\omega\\to0$),
    $J = \\begin{pmatrix}0&-1\\\\1&0\\end{pmatrix}$; $\\mathrm{Ad}_g = \\begin{pmatrix} R & -Jt\\\\ 0 & 1\\end{pmatrix}$;
    $\\mathrm{ad}_\\xi = \\begin{pmatrix} \\omega J & -Jv\\\\ 0 & 0\\end{pmatrix}$.
    """

    velocity_names: ClassVar[tuple[str, ...]] = ("v_x", "v_y", "omega")

    @property
    def dim(self) -> int:
        return 3

    @property
    def matrix_size(self) -> int:
        return 3

    def hat(self, xi):
        """$\\hat\\xi$ for $\\xi = (v_x, v_y, \\omega)$.

        Arguments:
            xi: shape (3,).

        Returns:
            shape (3, 3).
        """
        vx, vy, w = _check_vector(xi, 3)
        z = jnp.zeros_like(w)
        return jnp.array([[z, -w, vx], [w, z, vy], [z, z, z]])

    def vee(self, X):
        """$(X_{02}, X_{12}, (X_{10} - X_{01})/2)$.

        Arguments:
            X: shape (3, 3).

        Returns:
            shape (3,).
        """
        X = _check_matrix(X, 3, "X")
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
        g = _check_matrix(g, 3)
        Rt = g[:2, :2].T
        return jnp.zeros_like(g).at[:2, :2].set(Rt).at[:2, 2].set(-Rt @ g[:2, 2]).at[2, 2].set(1.0)

    def exp(self, xi):
        """$\\exp\\hat\\xi = (R(\\omega), V(\\omega)v)$.

        Arguments:
            xi: $(v_x, v_y, \\omega)$, shape (3,).

        Returns:
            shape (3, 3). Safe at $\\omega = 0$ (values and gradients).
        """
        xi = _check_vector(xi, 3)
        v, w = xi[:2], xi[2]
        t = w * w
        c, s = cos_sq(t), w * sinc_sq(t)
        R = jnp.array([[c, -s], [s, c]])
        g = jnp.zeros((3, 3), dtype=R.dtype)
        return g.at[:2, :2].set(R).at[:2, 2].set(self.V(w) @ v).at[2, 2].set(1.0)

    def log(self, g):
        """Principal logarithm: $\\omega = \\mathrm{atan2}(R_{10}, R_{00})\\in(-\\pi, \\pi]$, $v = V(\\omega)^{-1} t$.

        Arguments:
            g: shape (3, 3).

        Returns:
            $(v_x, v_y, \\omega)$, shape (3,).
        """
        g = _check_matrix(g, 3)
        w = jnp.arctan2(g[1, 0], g[0, 0])
        return jnp.concatenate([self.V_inv(w) @ g[:2, 2], w[None]])

    def Ad(self, g):
        """$\\mathrm{Ad}_g = \\begin{pmatrix} R & -Jt\\\\ 0 & 1\\end{pmatrix}$, i.e. the $\\omega$ column is $(t_y, -t_x, 1)$."""
        g = _check_matrix(g, 3)
        out = jnp.zeros_like(g).at[:2, :2].set(g[:2, :2])
        return out.at[0, 2].set(g[1, 2]).at[1, 2].set(-g[0, 2]).at[2, 2].set(1.0)

    def ad(self, xi):
        """$\\mathrm{ad}_\\xi = \\begin{pmatrix} \\omega J & -Jv\\\\ 0 & 0\\end{pmatrix}$: $[\\xi, \\eta] = (\\omega J u - \\eta_\\omega J v,\\ 0)$."""
        vx, vy, w = _check_vector(xi, 3)
        z = jnp.zeros_like(w)
        return jnp.array([[z, -w, vy], [w, z, -vx], [z, z, z]])

    def random(self, key):
        """$\\omega$ uniform in $(-\\pi, \\pi)$, translation standard normal."""
        k1, k2 = jax.random.split(key)
        w = jax.random.uniform(k1, (), minval=-jnp.pi, maxval=jnp.pi)
        t = jax.random.normal(k2, (2,))
        c, s = jnp.cos(w), jnp.sin(w)
        return jnp.array([[c, -s, t[0]], [s, c, t[1]], [0.0, 0.0, 1.0]])


# ---------------------------------------------------------------------------------------------
# R^n, trivial group, products
# ---------------------------------------------------------------------------------------------


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


class ProductGroup(MatrixLieGroup):
    """A direct product $G_1\\times\\dots\\times G_m$ as block-diagonal matrices.

    Algebra vectors are the concatenation of the factors' vectors; every operation (hat, vee, exp,
    log, Ad, ad, inverse) acts blockwise with each factor's closed form.

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
        xi = _check_vector(xi, self.dim)
        return [xi[s] for s in self._dim_slices()]

    def blocks(self, g):
        """The diagonal blocks of a $k\\times k$ matrix: the factors' elements.

        Arguments:
            g: shape (k, k).

        Returns:
            a list of arrays of shapes $(k_i, k_i)$.
        """
        g = _check_matrix(g, self.matrix_size)
        return [g[s, s] for s in self._matrix_slices()]

    def hat(self, xi):
        """$\\mathrm{diag}(\\hat\\xi_1, \\dots, \\hat\\xi_m)$."""
        return block_diag(*[f.hat(x) for f, x in zip(self.factors, self.split(xi))])

    def vee(self, X):
        """Concatenation of the blocks' vee (off-diagonal blocks are ignored)."""
        return jnp.concatenate([f.vee(B) for f, B in zip(self.factors, self.blocks(X))])

    def inverse(self, g):
        """Blockwise inverse."""
        return block_diag(*[f.inverse(B) for f, B in zip(self.factors, self.blocks(g))])

    def exp(self, xi):
        """Blockwise exp (safe at 0 when each factor's is)."""
        return block_diag(*[f.exp(x) for f, x in zip(self.factors, self.split(xi))])

    def log(self, g):
        """Blockwise principal logarithm."""
        return jnp.concatenate([f.log(B) for f, B in zip(self.factors, self.blocks(g))])

    def Ad(self, g):
        """$\\mathrm{diag}(\\mathrm{Ad}_{g_1}, \\dots)$."""
        return block_diag(*[f.Ad(B) for f, B in zip(self.factors, self.blocks(g))])

    def ad(self, xi):
        """$\\mathrm{diag}(\\mathrm{ad}_{\\xi_1}, \\dots)$."""
        return block_diag(*[f.ad(x) for f, x in zip(self.factors, self.split(xi))])

    def ad_star(self, xi, m):
        """Blockwise $\\mathrm{ad}^*$."""
        ms = [jnp.asarray(m)[s] for s in self._dim_slices()]
        return jnp.concatenate([f.ad_star(x, mi) for f, x, mi in zip(self.factors, self.split(xi), ms)])

    def random(self, key):
        """Independent random elements of the factors."""
        keys = jax.random.split(key, len(self.factors))
        return block_diag(*[f.random(k) for f, k in zip(self.factors, keys)])
