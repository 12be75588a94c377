"""Fitted orders of convergence: the one rule gnipy uses everywhere.

The order of a method is measured, never assumed: the errors against a reference (an exact
solution, or a far more accurate run) at several step sizes are fitted by a least-squares line in
log(error) against log(h), on the points above round-off only. `gni convergence`, the theorem
table and the figures of `gni reproduce`, and the test suite all call :func:`fitted_order`.

    >>> from gnipy.analysis import fitted_order
    >>> round(fitted_order([0.1, 0.05, 0.025], [1e-2, 2.5e-3, 6.25e-4]), 6)
    2.0
"""

from __future__ import annotations

import numpy as np

__all__ = ["ROUND_OFF", "fit_points", "fitted_order"]

#: Errors at or below this are treated as round-off by :func:`fitted_order` (not used in the fit).
ROUND_OFF = 1e-11


def fit_points(h, errors, floor: float = ROUND_OFF, *, stop_at_minimum: bool = False) -> np.ndarray:
    """The mask of the points :func:`fitted_order` fits on: finite, h > 0, error above `floor`, and
    with `stop_at_minimum` no step size smaller than the one with the smallest error."""
    h = np.asarray(h, dtype=float)
    e = np.asarray(errors, dtype=float)
    keep = np.isfinite(e) & np.isfinite(h) & (e > floor) & (h > 0)
    if stop_at_minimum and keep.any():
        keep &= h >= h[keep][np.argmin(e[keep])]
    return keep


def fitted_order(h, errors, floor: float = ROUND_OFF, *, min_points: int = 2,
                 stop_at_minimum: bool = False) -> float:
    """The least-squares slope of log(error) against log(h), on the points above `floor`.

    Points at or below `floor` (round-off, or an exact result) and non-finite points are left out;
    with fewer than `min_points` step sizes left the result is NaN. The one implementation of the
    fitted order in gnipy (`gni convergence`, the theorem table and the figures of `gni reproduce`).

    Arguments:
        h: step sizes.
        errors: the errors at those step sizes.
        floor: the round-off level (default :data:`ROUND_OFF` = 1e-11).
        min_points: the fewest step sizes a slope is fitted on.
        stop_at_minimum: also leave out the step sizes smaller than the one with the smallest
            error (past it the error grows as h shrinks: round-off, not truncation).

    Returns:
        The fitted order (a float, NaN when it cannot be fitted).
    """
    h = np.asarray(h, dtype=float)
    e = np.asarray(errors, dtype=float)
    keep = fit_points(h, e, floor, stop_at_minimum=stop_at_minimum)
    if np.unique(h[keep]).size < max(2, min_points):
        return float("nan")
    return float(np.polyfit(np.log(h[keep]), np.log(e[keep]), 1)[0])
