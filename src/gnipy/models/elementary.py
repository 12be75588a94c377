"""Elementary functions that closed-form solutions need, safe at small arguments (the ratios of sines)
and at large ones (the ratios of hyperbolic cosines, which overflow when written directly).

Closed forms such as $(\\sin(\\phi_0 + \\omega t) - \\sin\\phi_0)/\\omega$ cancel catastrophically when
$\\omega t \\to 0$ (and divide by zero at $\\omega = 0$). Written with the ratios below they are exact
and well conditioned for every $\\omega$, including 0. Host-side numpy (exact solutions are
yardsticks for tests and reports, not part of the jitted hot path).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sinc", "versine_ratio", "sine_defect_ratio", "cosh_ratio", "log_cosh_ratio", "gudermannian"]


def sinc(x):
    """$\\sin x / x$ (1 at 0)."""
    return np.sinc(np.asarray(x, dtype=np.float64) / np.pi)


def versine_ratio(x):
    """$(1 - \\cos x)/x^2 = \\tfrac12 (\\sin(x/2)/(x/2))^2$ ($\\tfrac12$ at 0)."""
    return 0.5 * sinc(0.5 * np.asarray(x, dtype=np.float64)) ** 2


def sine_defect_ratio(x):
    """$(x - \\sin x)/x^3$ ($\\tfrac16$ at 0).

    For $|x| < 0.1$ a Taylor series (truncation error below $10^{-20}$); above it the direct formula,
    whose cancellation costs at most $6\\varepsilon/x^2 \\approx 10^{-13}$ relative.
    """
    x = np.asarray(x, dtype=np.float64)
    small = np.abs(x) < 0.1
    xs = np.where(small, x, 0.0)
    x2 = xs * xs
    series = 1 / 6 - x2 / 120 + x2**2 / 5040 - x2**3 / 362880 + x2**4 / 39916800
    xl = np.where(small, 1.0, x)
    direct = (xl - np.sin(xl)) / xl**3
    return np.where(small, series, direct)


def cosh_ratio(c0, s):
    """$\\cosh c_0/\\cosh s$ without overflow (for large $|c_0|$, $|s|$)."""
    c0, s = np.abs(np.asarray(c0, dtype=np.float64)), np.abs(np.asarray(s, dtype=np.float64))
    return np.exp(c0 - s) * (1 + np.exp(-2 * c0)) / (1 + np.exp(-2 * s))


def log_cosh_ratio(s, c0):
    """$\\log(\\cosh s/\\cosh c_0)$ without overflow."""
    def log_cosh(x):
        x = np.abs(np.asarray(x, dtype=np.float64))
        return x + np.log1p(np.exp(-2 * x)) - np.log(2.0)

    return log_cosh(s) - log_cosh(c0)


def gudermannian(s):
    """The Gudermannian $\\operatorname{gd}(s) = 2\\arctan\\tanh(s/2) = \\int_0^s \\operatorname{sech}$."""
    return 2 * np.arctan(np.tanh(0.5 * np.asarray(s, dtype=np.float64)))
