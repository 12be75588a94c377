"""Series of the groups' maps: even functions of an angle, and the paper's series of $\\mathrm{dexp}$.

- Even functions of an angle, written as functions of its square $t = \\theta^2$, safe at $t = 0$:
  the closed forms used by the groups' `exp`, `log` and their derivatives. Each selects a Taylor
  branch near zero with a "safe" `jnp.where`, so neither values nor gradients (of any order)
  become NaN there.
- The paper's series of $\\mathrm{dexp}$ and $\\mathrm{dexp}^{-1}$ in powers of $\\mathrm{ad}_\\xi$
  (Appendix a), :func:`dexp_series` and :func:`dexp_inv_series`: the generic fallback of
  :meth:`~gnipy.lie_groups.MatrixLieGroup.dexp` and
  :meth:`~gnipy.lie_groups.MatrixLieGroup.dexp_inv` for a group without closed forms.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from ..compilation import traced_once

# Below this value of $t = \theta^2$ (|θ| < 0.5) the Taylor branch is used. The closed forms with a
# cancellation, such as $(\theta - \sin\theta)/\theta^3$, lose about $\epsilon/\theta^2$ (≤ 1e-15 at the
# switch, ≤ 1e-14 for their derivatives); the Taylor series below are truncated where the first
# omitted term is < 1e-18 at the switch. A smaller switch would trade truncation for cancellation.
_TAYLOR_T = 0.25
_TAYLOR_TERMS = 9


def bernoulli_numbers(n: int) -> list:
    """Bernoulli numbers $B_0, \\dots, B_n$ as exact fractions, with $B_1 = -1/2$."""
    from fractions import Fraction

    B = [Fraction(0)] * (n + 1)
    for m in range(n + 1):
        B[m] = Fraction(1) if m == 0 else -sum(math.comb(m + 1, j) * B[j] for j in range(m)) / (m + 1)
    return B


#: $B_0, \dots, B_{40}$ as exact fractions ($B_1 = -1/2$): the coefficients of $\mathrm{dexp}^{-1}$ (Appendix a).
BERNOULLI = bernoulli_numbers(40)


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


@traced_once
def sinc_sq(t):
    """$\\sin\\theta/\\theta$ as a function of $t = \\theta^2$ (safe at 0)."""
    coeffs = [(-1) ** j / math.factorial(2 * j + 1) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, lambda th: jnp.sin(th) / th, coeffs)


@traced_once
def cos_sq(t):
    """$\\cos\\theta$ as a function of $t = \\theta^2$ (safe at 0, where $\\sqrt t$ is not)."""
    coeffs = [(-1) ** j / math.factorial(2 * j) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, jnp.cos, coeffs)


@traced_once
def one_minus_cos_sq(t):
    """$(1 - \\cos\\theta)/\\theta^2$ as a function of $t = \\theta^2$.

    Written as $\\tfrac12(\\sin(\\theta/2)/(\\theta/2))^2$, which has no cancellation.
    """
    return 0.5 * sinc_sq(0.25 * t) ** 2


@traced_once
def theta_minus_sin_sq(t):
    """$(\\theta - \\sin\\theta)/\\theta^3$ as a function of $t = \\theta^2$ (safe at 0)."""
    coeffs = [(-1) ** j / math.factorial(2 * j + 3) for j in range(_TAYLOR_TERMS)]
    return _even_series_safe(t, lambda th: (th - jnp.sin(th)) / th**3, coeffs)


@traced_once
def dexp_inv_coefficient_sq(t):
    """$\\bigl(1 - \\tfrac{\\theta}{2}\\cot\\tfrac{\\theta}{2}\\bigr)/\\theta^2$ as a function of $t = \\theta^2$.

    The coefficient of $\\hat\\omega^2$ in $\\mathrm{dexp}^{-1}_\\omega$ on SO(3). Analytic for
    $|\\theta| < 2\\pi$ (a pole at $2\\pi$); its series is $\\sum_{n\\ge1} (-1)^{n+1} B_{2n} t^{n-1}/(2n)!$.
    """
    coeffs = [
        float((-1) ** (n + 1) * BERNOULLI[2 * n] / math.factorial(2 * n)) for n in range(1, _TAYLOR_TERMS + 1)
    ]

    def closed(th):
        half = 0.5 * th
        return (1.0 - half * jnp.cos(half) / jnp.sin(half)) / th**2

    return _even_series_safe(t, closed, coeffs)


@traced_once
def half_cot_half_sq(t):
    """$\\tfrac{\\theta}{2}\\cot\\tfrac{\\theta}{2}$ as a function of $t = \\theta^2$ (safe at 0)."""
    return 1.0 - t * dexp_inv_coefficient_sq(t)


# ---------------------------------------------------------------------------------------------
# The paper's series of dexp and dexp⁻¹ (Appendix a): the generic fallback of the groups
# ---------------------------------------------------------------------------------------------

#: Default number of terms of :func:`dexp_series`: $1/(j+1)!$, the first omitted term is
#: < 1e-19 for $\|\mathrm{ad}_\xi\| \le 1$.
DEXP_TERMS = 20
#: Default number of terms of :func:`dexp_inv_series`: $|B_j/j!| \approx 2/(2\pi)^j$, < 1e-22 at
#: $j = 28$ for $\|\mathrm{ad}_\xi\| \le 1$.
DEXP_INV_TERMS = 28


def matrix_series(A, coeffs):
    """$\\sum_j c_j A^j$ by Horner's rule.

    Arguments:
        A: a square matrix, shape (d, d).
        coeffs: the coefficients $c_0, c_1, \\dots$ (floats, at least one).

    Returns:
        shape (d, d).
    """
    eye = jnp.eye(A.shape[0], dtype=A.dtype)
    out = coeffs[-1] * eye
    for c in reversed(coeffs[:-1]):
        out = A @ out + c * eye
    return out


def dexp_series(group, xi, terms: int = DEXP_TERMS):
    """The paper's series $\\mathrm{dexp}_x = \\sum_{j\\ge0} \\mathrm{ad}_x^j/(j+1)!$ (Appendix a), truncated.

    Arguments:
        group: any :class:`~gnipy.lie_groups.MatrixLieGroup` (only its `ad` is used).
        xi: shape (d,).
        terms: number of terms $j = 0, \\dots, \\text{terms}-1$. The default reaches round-off for
            $\\|\\mathrm{ad}_\\xi\\| \\le 1$ (the series converges everywhere, more slowly for larger $\\xi$).

    Returns:
        shape (d, d).
    """
    coeffs = [1.0 / math.factorial(j + 1) for j in range(terms)]
    return matrix_series(group.ad(xi), coeffs)


def dexp_inv_series(group, xi, terms: int = DEXP_INV_TERMS):
    """The paper's series $\\mathrm{dexp}^{-1}_x = \\sum_{j\\ge0} (B_j/j!)\\,\\mathrm{ad}_x^j$ ($B_1 = -1/2$), truncated.

    Arguments:
        group: any :class:`~gnipy.lie_groups.MatrixLieGroup` (only its `ad` is used).
        xi: shape (d,).
        terms: number of terms. The default reaches round-off for $\\|\\mathrm{ad}_\\xi\\| \\le 1$;
            the series converges only for spectral radius of $\\mathrm{ad}_\\xi$ below $2\\pi$.

    Returns:
        shape (d, d).
    """
    coeffs = [float(BERNOULLI[j]) / math.factorial(j) for j in range(terms)]
    return matrix_series(group.ad(xi), coeffs)
