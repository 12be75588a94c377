"""Bounds on the quantities a fit estimates (:func:`gnipy.fit`'s `bounds`): the defaults, the
checks, and the change of variables that keeps the solver inside them.

**Defaults.** A zoo model's masses, moments of inertia and lengths are positive
(:attr:`gnipy.registry.ModelSpec.positive`): each of them that a fit estimates is bounded below
by 0 unless `bounds` says otherwise (`bounds={"m": None}` lifts the bound, `bounds={"m": (0.5, 2)}`
replaces it). A user's System or `build` function has no default bounds.

**The change of variables.** Levenberg–Marquardt (optimistix) has no bounds, so the solver works
in unbounded internal variables $z$ mapped onto the bounded quantities $y$, with $s$ the
quantity's scale:

- no bound: $y = s z$, $s$ the initial guess's size (1 where the guess is 0);
- a lower bound $a$: $y = a + s\\,e^{z - 1}$, $s$ the guess's distance to $a$;
- an upper bound $b$: $y = b - s\\,e^{z - 1}$, likewise;
- both: $y = a + (b - a)(\\sin z + 1)/2$ (MINUIT's transform: F. James, M. Winkler, *MINUIT
  User's Guide*, CERN 2004, §1.3.1; also lmfit's), $s = (b - a)/2$.

Every $z$ gives a $y$ inside the bounds, so no trial point of the solver leaves them; the guess
sits at $z = \\pm 1$ with $dy/dz = s$ (at $z = 1$ for a one-sided bound), as an unbounded one does,
so the solver's first steps are nearly those of the unbounded problem. (MINUIT's one-sided
transform $a + s(\\sqrt{z^2+1} - 1)$ curves more near the guess: it took the control guide's
sleigh fit from 7 iterations to 27; the exponential takes 23, 16 of them rejected steps at the
round-off floor of the minimum, reached at the 4th.) An estimate pressed against its bound
approaches it without reaching it, and the fit reports it (:meth:`Bounds.at_bound`: within
:data:`AT_BOUND` of it, or an unconstrained Gauss–Newton step from the estimate that crosses it)
instead of returning a point near the boundary as a minimum. The standard errors are computed in
$y$ (the Jacobian is divided by $dy/dz$, or taken anew where $dy/dz$ is about 0).

These lines are written here because optimistix (the project's least-squares solver) has no
bounded variant, and lmfit, which has one, drives SciPy's solvers rather than JAX's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..inputs import is_text_or_bool

__all__ = ["Bounds", "fit_bounds", "bounded_quantities", "AT_BOUND"]

#: An estimate within this fraction of its scale of a bound is at the bound.
AT_BOUND = 1e-6


_FREE, _LOWER, _UPPER, _BOTH = 0, 1, 2, 3


@dataclasses.dataclass(frozen=True)
class Bounds:
    """The bounds of a fit's estimated quantities and the change of variables onto them (module
    docstring).

    Attributes:
        names: the estimated quantities (as :attr:`gnipy.FitResult.names`).
        lower, upper: the bounds, (P,) (`-inf`/`inf` where a side is open).
        scale: the scale $s$ of each quantity, (P,).
    """

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray

    @property
    def kinds(self) -> tuple[int, ...]:
        """Which transform each quantity takes (free, lower, upper, both)."""
        lo, hi = np.isfinite(self.lower), np.isfinite(self.upper)
        return tuple(int(_BOTH if a and b else _LOWER if a else _UPPER if b else _FREE) for a, b in zip(lo, hi))

    @property
    def bounded(self) -> dict[str, tuple[float, float]]:
        """The bounded quantities, name -> `(lower, upper)`."""
        return {n: (float(a), float(b)) for n, a, b, k in zip(self.names, self.lower, self.upper, self.kinds) if k}

    def quantities(self, z):
        """The quantities $y$ at the internal variables `z` (traceable)."""
        return bounded_quantities(self.kinds, self.lower, self.upper, self.scale, z)

    def internal(self, y) -> np.ndarray:
        """The internal variables $z$ of the quantities `y` (inside the bounds)."""
        y = np.asarray(y, dtype=np.float64)
        z = np.empty_like(y)
        for i, kind in enumerate(self.kinds):
            s, a, b = self.scale[i], self.lower[i], self.upper[i]
            if kind == _FREE:
                z[i] = y[i] / s
            elif kind in (_LOWER, _UPPER):
                z[i] = 1.0 + math.log((y[i] - a if kind == _LOWER else b - y[i]) / s)
            else:
                z[i] = math.asin(min(1.0, max(-1.0, 2.0 * (y[i] - a) / (b - a) - 1.0)))
        return z

    def derivative(self, z) -> np.ndarray:
        """$dy/dz$ at `z`, (P,) (each $y_i$ depends on $z_i$ alone: one forward-mode pass)."""
        z = jnp.asarray(z, jnp.float64)
        return np.asarray(jax.jvp(self.quantities, (z,), (jnp.ones_like(z),))[1])

    def at_bound(self, y, step=None) -> dict[str, float]:
        """The quantities of `y` pressed against one of their bounds, name -> the bound: within
        :data:`AT_BOUND` of their scale of it, or (given the solver's unconstrained next `step`
        from `y`, a Gauss–Newton step) with `y + step` beyond it. The second catches what the
        change of variables hides: near a bound $dy/dz \\to 0$, so the solver's steps in $z$
        shrink and it may stop short of the bound, while the data still push beyond it."""
        y = np.asarray(y, dtype=np.float64)
        step = np.zeros_like(y) if step is None else np.asarray(step, dtype=np.float64)
        out = {}
        for i, name in enumerate(self.names):
            lo, hi = self.lower[i], self.upper[i]
            if math.isfinite(lo) and (y[i] - lo <= AT_BOUND * self.scale[i] or y[i] + step[i] < lo):
                out[name] = float(lo)
            elif math.isfinite(hi) and (hi - y[i] <= AT_BOUND * self.scale[i] or y[i] + step[i] > hi):
                out[name] = float(hi)
        return out


def bounded_quantities(kinds, lower, upper, scale, z):
    """The quantities $y$ at the internal variables `z` (traceable: `lower`, `upper` and `scale`
    may be JAX arrays; `kinds` is static), the transforms of the module docstring."""
    z = jnp.asarray(z, jnp.float64)
    out = []
    for i, kind in enumerate(kinds):
        s, a, b = scale[i], lower[i], upper[i]
        if kind == _FREE:
            out.append(s * z[i])
        elif kind == _LOWER:
            out.append(a + s * jnp.exp(z[i] - 1.0))
        elif kind == _UPPER:
            out.append(b - s * jnp.exp(z[i] - 1.0))
        else:
            out.append(a + (b - a) * (jnp.sin(z[i]) + 1.0) / 2.0)
    return jnp.stack(out)


def fit_bounds(bounds, positive, names, y0) -> Bounds:
    """The :class:`Bounds` of :func:`gnipy.fit`: `positive` (the model's positive parameters,
    bounded below by 0) updated by the user's `bounds` (name -> `(lower, upper)` with None or
    ±inf for an open side, or None for no bound), for the estimated `names` with initial guesses
    `y0`; InputError naming `bounds` for an unknown name, a pair that is not two numbers with
    lower < upper, or a guess that is not strictly inside its bounds."""
    y0 = np.asarray(y0, dtype=np.float64)
    table = {n: (0.0, math.inf) for n in positive if n in names}
    if bounds is not None:
        if not isinstance(bounds, Mapping):
            raise InputError(f"bounds: expected a dict name -> (lower, upper), got {type(bounds).__name__}")
        for name, pair in bounds.items():
            if name not in names:
                raise InputError(f"bounds: {name!r} is not an estimated quantity (estimated: {', '.join(names)})")
            if pair is None:
                table.pop(name, None)
                continue
            lo, hi = _pair(name, pair)
            if math.isinf(lo) and math.isinf(hi):  # (None, None): no bound
                table.pop(name, None)
            else:
                table[name] = (lo, hi)
    lower = np.full(len(names), -math.inf)
    upper = np.full(len(names), math.inf)
    scale = np.where(y0 != 0, np.abs(y0), 1.0)
    for name, (a, b) in table.items():
        i = names.index(name)
        if not a < y0[i] < b:
            why = " (masses, moments of inertia and lengths are positive by default; bounds={%r: None} lifts it)" % (
                name,) if name in positive and (bounds is None or name not in bounds) else ""
            raise InputError(f"bounds: the initial guess {float(y0[i])!r} of {name!r} is not strictly inside its bounds "
                             f"({a:g}, {b:g}){why}")
        lower[i], upper[i] = a, b
        if math.isfinite(a) and math.isfinite(b):
            scale[i] = (b - a) / 2.0
        else:  # the guess's distance to its bound: z = 1 at the guess, dy/dz = s there
            scale[i] = y0[i] - a if math.isfinite(a) else b - y0[i]
    return Bounds(names=tuple(names), lower=lower, upper=upper, scale=scale)


def _pair(name: str, pair) -> tuple[float, float]:
    """`(lower, upper)` of one entry of `bounds` (None an open side)."""
    if isinstance(pair, (str, bytes)) or not hasattr(pair, "__len__") or len(pair) != 2:
        raise InputError(f"bounds: {name!r} must be a pair (lower, upper) or None, got {pair!r}")
    out = []
    for side, x, open_value in (("lower", pair[0], -math.inf), ("upper", pair[1], math.inf)):
        if x is None:
            out.append(open_value)
            continue
        if is_text_or_bool(x):
            raise InputError(f"bounds: the {side} bound of {name!r} must be a number or None, got {x!r}")
        try:
            x = float(x)
        except (TypeError, ValueError):
            raise InputError(f"bounds: the {side} bound of {name!r} must be a number or None, got {x!r}") from None
        if math.isnan(x):
            raise InputError(f"bounds: the {side} bound of {name!r} is NaN")
        out.append(x)
    if not out[0] < out[1]:
        raise InputError(f"bounds: the lower bound of {name!r} must be below its upper bound, got {tuple(pair)!r}")
    return out[0], out[1]
