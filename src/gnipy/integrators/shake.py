"""Nonholonomic SHAKE in two-step form (paper §5, (Afin) and Remark 5.1).

The two-step recurrence on positions $(q_{k-1}, q_k, q_{k+1})$ of the explicit schemes of
:mod:`gnipy.integrators.paper_schemes`: for a mechanical Lagrangian with a *constant* metric it is
RATTLE (and the GNI with the trapezoid rule) node by node, which the tests check. It refuses
forces (:meth:`Shake.check`): its state holds $q_{k+1}$ before the step that reaches it is taken.
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from ..linalg import solve_spd  # the metric and the C = μM⁻¹μᵀ are SPD
from ..spaces import compensated_add
from .base import Integrator, MethodError, explicit_step_info, require_constant_metric

__all__ = ["ShakeState", "shake_map", "Shake"]


class ShakeState(NamedTuple):
    """The two-step SHAKE state held at node k, in summed form: $q_k$ and the increments
    $d_{k-1} = q_k - q_{k-1}$, $d_k = q_{k+1} - q_k$.

    The two-step recurrence $q_{k+1} = 2q_k - q_{k-1} + \\dots$ on positions loses $\\varepsilon|q|$ in
    each second difference, which is $\\varepsilon|q|/h^2$ in the acceleration; written on the
    increments ($d_k = d_{k-1} + h^2(\\dots)$, Hairer–Lubich–Wanner, *Geometric Numerical
    Integration*, VIII.5) it is the same map in exact arithmetic with round-off at the floor.

    Attributes:
        q: $q_k$, the node reported.
        d_prev: $q_k - q_{k-1}$.
        d_next: $q_{k+1} - q_k$.
        q_err: the rounding error of $q_k$ (compensated summation).
    """

    q: jax.Array
    d_prev: jax.Array
    d_next: jax.Array
    q_err: jax.Array

    @property
    def q_prev(self):
        """$q_{k-1}$."""
        return self.q - self.d_prev

    @property
    def q_next(self):
        """$q_{k+1}$."""
        return self.q + self.d_next


def shake_map(system, state: ShakeState, h) -> ShakeState:
    """One step of nonholonomic SHAKE in two-step form, (Afin) and Remark 5.1.

    From $(q_{k-1}, q_k, q_{k+1})$ compute $q_{k+2}$ at node $k+1$:
    (Afina) $q_{k+2} - 2q_{k+1} + q_k = -h^2 M^{-1}(V_q(q_{k+1}) + \\mu^T(q_{k+1})\\tilde\\lambda_{k+1})$
    (Remark 5.1 prints $q_{k+1} - 2q_k + q_{k+1}$; the second $q_{k+1}$ is a misprint for $q_{k-1}$),
    (Afinb) $\\mu(q_{k+1})\\big((q_{k+2} - q_k)/2h - Y(q_{k+1})\\big) = 0$,
    linear in $\\tilde\\lambda_{k+1}$: $h^2 C \\tilde\\lambda = \\mu(a - q_k - 2hY)$ with
    $a = 2q_{k+1} - q_k - h^2 M^{-1} V_q(q_{k+1})$.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric $M$.
        state: a :class:`ShakeState` at node k (summed form: $q_k$, $q_k - q_{k-1}$, $q_{k+1} - q_k$).
        h: step size, nonzero.

    Returns:
        The :class:`ShakeState` at node k+1.
    """
    # the new node is k+1: q_{k+1} = q_k + d_k, and (Afina) in increments,
    # d_{k+1} = d_k − h²M⁻¹(V_q + μᵀλ̃) at q_{k+1}; (Afinb) μ((d_{k+1} + d_k)/2h − Y) = 0 is linear in λ̃:
    # h²C λ̃ = μ(2d_k − h²M⁻¹V_q − 2hY)
    q0, _, d0, q_err = state
    q1, q_err = compensated_add(q0, d0, q_err)
    M = system.metric(q1)
    mu = system.mu(q1)
    Minv_muT = solve_spd(M, mu.T)
    C = mu @ Minv_muT
    a = d0 - h * h * solve_spd(M, system.potential_gradient(q1))  # d_{k+1} before the constraint force
    lam = solve_spd(C, mu @ (a + d0 - 2.0 * h * system.Y(q1))) / (h * h)  # (Afinb)
    d1 = a - h * h * (Minv_muT @ lam)  # (Afina)
    return ShakeState(q1, d0, d1, q_err)


class Shake(Integrator):
    """Nonholonomic SHAKE in two-step form, (Afin) / Remark 5.1, linear and affine (order 2).

    The state at node k is $(q_{k-1}, q_k, q_{k+1})$ (held as $q_k$ and the two increments, see
    :class:`ShakeState`), so that the reported velocity is
    $v_k = (q_{k+1} - q_{k-1})/2h$ (which satisfies the discrete constraint (Afinb) exactly) and
    $p_k = M v_k$ (RATTLE's $\\tilde p_k$). Start: $q_{\\pm 1} = q_0 \\pm h v_0 - (h^2/2) M^{-1} V_q(q_0)$,
    which is RATTLE from $\\tilde p_0 = M v_0$, $\\tilde\\lambda_0 = 0$. Equal to "rattle" and
    "gni-trapezoid" node by node. Constant metric only.
    """

    name: ClassVar[str] = "shake"
    order: ClassVar[int | None] = 2

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` unless the metric is constant (paper §5), and for a
        forced system (its two-step state holds $q_{k+1}$ before the step that reaches it is
        taken, so a step's force could not be that step's: use rattle or gni-trapezoid)."""
        require_constant_metric(self.name, system, q0)
        if system.force is not None:
            raise MethodError(
                f"method {self.name!r} does not support forces: {system.name!r} has a force F(q, v, u, t), and "
                "the two-step form (Afin) holds q_(k+1) before its step's force and input are known; use "
                "rattle or gni-trapezoid (the same scheme with the forced trapezoid rule)"
            )

    def init(self, system, q0, v0, h):
        """$(q_{-1}, q_0, q_1)$ with $q_{\\pm1} = q_0 \\pm h v_0 - (h^2/2)M^{-1}V_q(q_0)$.

        Arguments:
            system: the system.
            q0: initial configuration.
            v0: initial velocity on the constraints.
            h: step size.

        Returns:
            A :class:`ShakeState`.
        """
        kick = 0.5 * h * h * solve_spd(system.metric(q0), system.potential_gradient(q0))
        return ShakeState(q0, h * v0 + kick, h * v0 - kick, jnp.zeros_like(q0))

    def step(self, system, state, h):
        """One step of :func:`shake_map`; returns `(state, StepInfo)` (no iterations)."""
        new = shake_map(system, state, h)
        return new, explicit_step_info(*new)

    def observe(self, system, state, h):
        """$(q_k, v_k, M v_k)$ with $v_k = (q_{k+1} - q_{k-1})/2h$.

        Arguments:
            system: the system.
            state: a :class:`ShakeState`.
            h: step size.

        Returns:
            `(q, v, p)`.
        """
        q, d_prev, d_next, _ = state
        v = (d_next + d_prev) / (2.0 * h)
        return q, v, system.metric(q) @ v
