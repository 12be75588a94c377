"""How well a run keeps what the model conserves, and how far it is from the model's exact solution.

A zoo model (:class:`~gnipy.registry.ModelSpec`) may register invariants (conserved
quantities, `f(params, q, v)` or on $\\mathbb{R}^n \\times G$ `f(params, q, v, R)`) and an exact
solution (`exact(params, q0, v0, t)`). These functions evaluate them on the saved nodes of a run;
`gni run` and `gni demo` print and store what they return.
"""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np

__all__ = ["ExactErrors", "exact_errors", "invariant_drifts"]


def invariant_drifts(spec, params, q, v, R=None) -> dict[str, float]:
    """The drift of each invariant of the model `spec`: `{name: max_k |f(q_k, v_k) − f(q_0, v_0)|}`.

    Arguments:
        spec: the :class:`~gnipy.registry.ModelSpec` (its `invariants`).
        params: the model's parameter values (`spec.resolve_params(...)`).
        q, v: the saved configurations (T, n) and velocities (T, N).
        R: the saved orientations (T, k, k) on $\\mathbb{R}^n \\times G$; an invariant with four
            arguments then receives them.

    Returns:
        The drifts by invariant name (empty when the model registers none).
    """
    out = {}
    # host arrays: iterating a device array costs a dispatch per row
    q, v = np.asarray(q), np.asarray(v)
    R = None if R is None else np.asarray(R)
    for name, f in spec.invariants.items():
        with_R = R is not None and len(inspect.signature(f).parameters) >= 4
        args = zip(q, v, R) if with_R else zip(q, v)
        values = np.array([float(f(params, *a)) for a in args])
        out[name] = float(np.max(np.abs(values - values[0]))) if values.size else 0.0
    return out


@dataclasses.dataclass(frozen=True)
class ExactErrors:
    """A run against the model's exact solution at its saved times.

    Attributes:
        q, v: the exact configurations (T, n) and velocities (T, N).
        max_error_q: $\\max_k \\|q_k - q(t_k)\\|_\\infty$.
        max_error_v: $\\max_k \\|v_k - v(t_k)\\|_\\infty$.
    """

    q: np.ndarray
    v: np.ndarray
    max_error_q: float
    max_error_v: float


def exact_errors(spec, params, sol, q0, v0) -> ExactErrors | None:
    """The errors of the solution `sol` against the exact solution of the model `spec` from
    `(q0, v0)` (the initial velocity the run used); None when the model has no exact solution, or
    none for these parameters."""
    if spec.exact is None:
        return None
    t = np.asarray(sol.t) - float(sol.t[0])
    result = spec.exact(params, q0, v0, t)
    if result is None:  # no closed form for these parameters (e.g. rolling-ball, unequal moments)
        return None
    qe, ve = (np.asarray(a) for a in result)
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    # initial=0: on R^0 × G there are no coordinates q
    return ExactErrors(qe, ve, float(np.max(np.abs(q - qe), initial=0.0)), float(np.max(np.abs(v - ve), initial=0.0)))
