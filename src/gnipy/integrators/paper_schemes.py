"""The paper's explicit schemes, written separately as one-step maps (paper §5, §6.1).

These are the GNI (:mod:`gnipy.integrators.gni`) written in the paper's variables for a mechanical Lagrangian
$L = \\tfrac12 \\dot q^T M \\dot q - V(q)$ with a *constant* metric $M$. They do not call the GNI
core: tests hold them equal to it, which checks both.

Variables. The paper's one-step schemes act on $(q_k, \\tilde p_k, \\tilde\\lambda_k)$ with
$\\tilde p_k = M(q_{k+1} - q_{k-1})/2h$, $p_{k+1/2} = M(q_{k+1} - q_k)/h$ and
$\\tilde\\lambda_k = \\lambda_k / h$. All of them share the kick–drift–kick form

    p_{k+1/2}   = p̃_k − (h/2)(V_q(q_k) + μ(q_k)ᵀ λ̃_k)
    q_{k+1}     = q_k + h M⁻¹ p_{k+1/2}
    p̃_{k+1}     = p_{k+1/2} − (h/2)(V_q(q_{k+1}) + μ(q_{k+1})ᵀ λ̃_{k+1})

and differ only in the discrete constraint that fixes $\\tilde\\lambda_{k+1}$:

    μ(q) M⁻¹ (p̃ + s (h/2) V_q(q) − Π(q)) = 0,   s = +1 (Euler A), −1 (Euler B), 0 (RATTLE).

The constraint is linear in $\\tilde\\lambda_{k+1}$: substituting $\\tilde p_{k+1}$ gives the
$m \\times m$ system $(h/2)\\, C\\, \\tilde\\lambda_{k+1} = \\mu M^{-1}(p_{k+1/2} + (s-1)(h/2) V_q - \\Pi)$
at $q_{k+1}$, with $C = \\mu M^{-1} \\mu^T$.

Affine constraints. The paper writes (EuAHam), (EuBHam) for linear constraints only. For affine
ones, $\\mu(\\dot q - Y) = 0$ with $\\Pi = M Y$, the natural extension is the $-\\Pi$ term above: it
follows from (GNIintAffb) exactly as (EuAHamc/e) follow from (GNIintb). With the Euler A discrete
Lagrangian, $FL^- = p_{k+1/2} + h V_q(q_k)$ and $FL^+ = p_{k-1/2}$, so
$(FL^- + FL^+)/2 = \\tilde p_k + (h/2) V_q(q_k)$ and (GNIintAffb) reads
$\\mu M^{-1}(\\tilde p_k + (h/2)V_q - \\Pi) = 0$ (Euler B: $-(h/2)V_q$; trapezoid: none, which is
the affine RATTLE of §6.1).

Relation to the GNI state $(q_k, p^+_k)$: the GNI's reported momentum is
$\\bar p = (p^- + p^+)/2 = P^* p^+ + Q^* \\Pi$, and

    λ̃ = (2/h) C⁻¹ μ M⁻¹ (p⁺ − Π),      p̃ = p̄ − s (h/2) V_q.

Starting from $p^+_0 = M v_0$ with $v_0$ on the constraints gives $\\tilde\\lambda_0 = 0$ and
$\\tilde p_0 = M v_0 - s (h/2) V_q(q_0)$. Every class reports (`observe`) the GNI's $\\bar p$ and
$\\bar v = M^{-1}\\bar p$, so that solutions compare node by node.

Forces (:mod:`gnipy.forcing`). Each map takes the discrete forces of its discrete Lagrangian
(Euler A: $f^- = hF(q_k)$; Euler B: $f^+ = hF(q_{k+1})$; RATTLE: the trapezoid, $f^\\mp = \\tfrac h2F$
at the nodes) in the forced transforms, as the GNI does, so that each stays the GNI with its
$l_d$: $f^-$ joins the first kick and $f^+$ the second (:func:`_forced_kick_drift_kick`; the drift
is then a Newton solve whenever $f^-$ has nodes, as it depends on the step). The composition Euler A ∘ Euler B
takes its second half step at $t + h/2$.

SHAKE, the two-step form (Afin) of the same scheme, is :mod:`gnipy.integrators.shake`. :class:`EulerABComposition`
re-reads $\\tilde p$ between its two half steps, because Euler A and Euler B relate $\\tilde p$ to
$\\bar p$ differently (see its docstring: without that, the composition is only of order 1).
"""

from __future__ import annotations

from typing import ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from ..forcing import FORCE_RULES, discrete_forces
from ..linalg import solve_spd  # the metric and the C = μG⁻¹μᵀ are SPD
from ..spaces import compensated_add
from .base import (Integrator, MethodError, StepInfo, all_finite, explicit_step_info, require_constant_metric,
                   solve_step)

__all__ = [
    "TildeState",
    "euler_a_map",
    "euler_b_map",
    "rattle_map",
    "tilde_state_from_gni",
    "NonholonomicEulerA",
    "NonholonomicEulerB",
    "Rattle",
    "EulerABComposition",
]

# The sign s of the potential term in the discrete constraint μM⁻¹(p̃ + s(h/2)V_q − Π) = 0.
_S_EULER_A = 1.0
_S_EULER_B = -1.0
_S_RATTLE = 0.0
#: The force quadrature of each map (that of its discrete Lagrangian, :data:`gnipy.forcing.FORCE_RULES`).
_FORCE_RULE = {_S_EULER_A: "left", _S_EULER_B: "right", _S_RATTLE: "trapezoid"}


class TildeState(NamedTuple):
    """The paper's one-step variables at node k: $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.

    Attributes:
        q: configuration $q_k$, shape (n,).
        p_tilde: momentum $\\tilde p_k$, shape (n,).
        lambda_tilde: scaled multiplier $\\tilde\\lambda_k = \\lambda_k/h$, shape (m,).
        q_err: the rounding error of $q_k$ carried by compensated summation
            (:func:`gnipy.spaces.compensated_add`), shape (n,); None: plain summation.
        p_err: the same for $\\tilde p_k$, which the kicks change by O(h) per step.
    """

    q: jax.Array
    p_tilde: jax.Array
    lambda_tilde: jax.Array
    q_err: jax.Array | None = None
    p_err: jax.Array | None = None


def _add(x, dx, err):
    """`x + dx` with compensation when `err` is carried (see :class:`TildeState`)."""
    return (x + dx, None) if err is None else compensated_add(x, dx, err)


def _kick_drift_kick(system, state: TildeState, h, s: float) -> TildeState:
    """One step of the shared scheme with discrete constraint $\\mu M^{-1}(\\tilde p + s(h/2)V_q - \\Pi) = 0$.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric (evaluated once, at $q_k$).
        state: $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.
        h: step size (any nonzero real, negative allowed).
        s: +1 (Euler A), −1 (Euler B), 0 (RATTLE).

    Returns:
        $(q_{k+1}, \\tilde p_{k+1}, \\tilde\\lambda_{k+1})$ (a forced system: :func:`_forced_kick_drift_kick`).
    """
    if system.force is not None:
        return _forced_kick_drift_kick(system, state, h, s)[0]
    q, p, lam, q_err, p_err = state
    M = system.metric(q)  # constant metric: the same at q_k and q_{k+1}
    p_half, p_err = _add(p, -0.5 * h * (system.potential_gradient(q) + system.mu(q).T @ lam), p_err)  # (EuAHama)
    q1, q_err = _add(q, h * solve_spd(M, p_half), q_err)  # (EuAHamb)
    return _end_kick(system, M, q1, q_err, p_half, p_err, h, s)


def _end_kick(system, M, q1, q_err, p_half, p_err, h, s: float, f_plus=0.0) -> TildeState:
    """The second kick at $q_{k+1}$, with the multiplier $\\tilde\\lambda_{k+1}$ of the discrete
    constraint: (EuAHamd) substituted into (EuAHame),
    $(h/2) C\\tilde\\lambda = \\mu M^{-1}(p_{k+1/2} + f^+ + (s - 1)(h/2)V_q - \\Pi)$, then
    $\\tilde p_{k+1} = p_{k+1/2} + f^+ - (h/2)(V_q + \\mu^T\\tilde\\lambda_{k+1})$."""
    mu1 = system.mu(q1)
    Vq1 = system.potential_gradient(q1)
    Pi1 = system.Pi(q1)
    C1 = mu1 @ solve_spd(M, mu1.T)
    rhs = mu1 @ solve_spd(M, p_half + f_plus + (s - 1.0) * 0.5 * h * Vq1 - Pi1)
    lam1 = (2.0 / h) * solve_spd(C1, rhs)
    p1, p_err = _add(p_half, f_plus - 0.5 * h * (Vq1 + mu1.T @ lam1), p_err)  # (EuAHamd)
    return TildeState(q1, p1, lam1, q_err, p_err)


def _forced_kick_drift_kick(system, state: TildeState, h, s: float) -> tuple[TildeState, StepInfo]:
    """:func:`_kick_drift_kick` with the discrete forces of the map's discrete Lagrangian
    (:mod:`gnipy.forcing`; Euler A: $f^- = hF(q_k)$, Euler B: $f^+ = hF(q_{k+1})$, RATTLE: the
    trapezoid), at the step's velocity $(q_{k+1} - q_k)/h$. The forced transforms
    $FL^- - f^- = p^-$, $p^+_{k+1} = FL^+ + f^+$ add $f^-$ to the first kick and $f^+$ to the second:

        p_{k+1/2} = p̃_k − (h/2)(V_q(q_k) + μ(q_k)ᵀλ̃_k) + f⁻,    q_{k+1} = q_k + h M⁻¹ p_{k+1/2},
        p̃_{k+1}   = p_{k+1/2} + f⁺ − (h/2)(V_q(q_{k+1}) + μ(q_{k+1})ᵀλ̃_{k+1}),

    the constraint fixing $\\tilde\\lambda_{k+1}$ as before. $f^-$ depends on $q_{k+1}$ through the step's
    velocity: the drift is then one Newton solve for the increment (none for Euler B, whose
    $f^- = 0$). Returns the state and the :class:`StepInfo` of the solve."""
    q, p, lam, q_err, p_err = state
    rule = _FORCE_RULE[s]
    M = system.metric(q)
    kick = -0.5 * h * (system.potential_gradient(q) + system.mu(q).T @ lam)
    p_half0 = p + kick
    if FORCE_RULES[rule][0]:  # f⁻ depends on the step: M z/h = p_{k+1/2} + f⁻(z)
        def residual(z):
            return M @ z / h - p_half0 - discrete_forces(system, q, z, h, rule)[0]

        z, info = solve_step(residual, h * solve_spd(M, p_half0), explicit=False,
                             floor_scale=jnp.max(jnp.abs(p_half0)))
    else:
        z = h * solve_spd(M, p_half0)
        info = None
    f_minus, f_plus = discrete_forces(system, q, z, h, rule)
    p_half, p_err = _add(p, kick + f_minus, p_err)
    q1, q_err = _add(q, z, q_err)
    new = _end_kick(system, M, q1, q_err, p_half, p_err, h, s, f_plus)
    if info is None:
        return new, explicit_step_info(*new)
    return new, StepInfo(info.ok & all_finite(*new), info.iterations, info.residual)


def _holonomic_kick_drift_kick(system, state: TildeState, h, s: float) -> tuple[TildeState, StepInfo]:
    """:func:`_kick_drift_kick` on a system with holonomic constraints $\\varphi(q) = 0$
    (:mod:`gnipy.holonomic`): the first kick gains the position multiplier, found by Newton's
    method in its r unknowns so that the drift ends on $\\varphi = 0$,

        p_{k+1/2} = p̃_k − (h/2)(V_q(q_k) + μ̃(q_k)ᵀλ̃_k) + dφ(q_k)ᵀΛ_k,   φ(q_k + h M⁻¹ p_{k+1/2}) = 0,

    and the second kick's λ̃_{k+1} has a component on each row of μ̃ = (μ; dφ): RATTLE's velocity
    multiplier for the holonomic rows (Andersen 1983). The GNI's holonomic step in the paper's
    variables, as the map without them is the GNI's (tested step for step). Unforced systems only
    (:meth:`_TildeScheme.check`). Returns the state and the :class:`StepInfo` of the solve."""
    from ..holonomic import phi_scale

    q, p, lam, q_err, p_err = state
    M = system.metric(q)
    rows = system.holonomic_mu(q)
    kick = -0.5 * h * (system.potential_gradient(q) + system.mu(q).T @ lam)
    p_half0 = p + kick
    Minv_rows = solve_spd(M, rows.T)

    def residual(Lam):
        return system.phi(q + h * solve_spd(M, p_half0) + h * Minv_rows @ Lam)

    Lam, info = solve_step(residual, jnp.zeros(rows.shape[0], dtype=p.dtype), explicit=False,
                           floor_scale=phi_scale(system, q, rows))
    p_half, p_err = _add(p, kick + rows.T @ Lam, p_err)
    q1, q_err = _add(q, h * solve_spd(M, p_half), q_err)
    new = _end_kick(system, M, q1, q_err, p_half, p_err, h, s)
    return new, StepInfo(info.ok & all_finite(*new), info.iterations, info.residual)


def _map_step(system, state, h, s: float):
    """`(state, StepInfo)` of one step of the map with sign s (the classes' steps)."""
    state = TildeState(*state)
    if system.holonomic is not None:
        return _holonomic_kick_drift_kick(system, state, h, s)
    if system.force is not None:
        return _forced_kick_drift_kick(system, state, h, s)
    new = _kick_drift_kick(system, state, h, s)
    return new, explicit_step_info(*new)


def euler_a_map(system, state: TildeState, h) -> TildeState:
    """One step of nonholonomic Euler A, (EuAHam), with the affine extension.

    (EuAHama) $p_{k+1/2} = \\tilde p_k - \\tfrac h2(V_q(q_k) + \\mu^T(q_k)\\tilde\\lambda_k)$;
    (EuAHamb) $q_{k+1} = q_k + h M^{-1} p_{k+1/2}$;
    (EuAHamd) $\\tilde p_{k+1} = p_{k+1/2} - \\tfrac h2(V_q(q_{k+1}) + \\mu^T(q_{k+1})\\tilde\\lambda_{k+1})$;
    (EuAHame) $\\mu(q_{k+1}) M^{-1}(\\tilde p_{k+1} + \\tfrac h2 V_q(q_{k+1}) - \\Pi(q_{k+1})) = 0$
    ($\\Pi = 0$ for linear constraints), solved as an m×m linear system for $\\tilde\\lambda_{k+1}$.

    The input constraint (EuAHamc) is not used by the map (it is what the previous step made
    true), so the map is defined on all of $(q, \\tilde p, \\tilde\\lambda)$ and for negative `h`,
    as Theorem 5.2 needs.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric $M$.
        state: a :class:`TildeState` $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.
        h: step size, nonzero (negative allowed).

    Returns:
        The :class:`TildeState` $(q_{k+1}, \\tilde p_{k+1}, \\tilde\\lambda_{k+1})$.
    """
    return _kick_drift_kick(system, TildeState(*state), h, _S_EULER_A)


def euler_b_map(system, state: TildeState, h) -> TildeState:
    """One step of nonholonomic Euler B, (EuBHam), with the affine extension.

    The same as :func:`euler_a_map` ((EuBHama), (EuBHamb), (EuBHamd)) except for the discrete
    constraint (EuBHame): $\\mu(q_{k+1}) M^{-1}(\\tilde p_{k+1} - \\tfrac h2 V_q(q_{k+1}) - \\Pi(q_{k+1})) = 0$.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric $M$.
        state: a :class:`TildeState` $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.
        h: step size, nonzero (negative allowed).

    Returns:
        The :class:`TildeState` $(q_{k+1}, \\tilde p_{k+1}, \\tilde\\lambda_{k+1})$.
    """
    return _kick_drift_kick(system, TildeState(*state), h, _S_EULER_B)


def rattle_map(system, state: TildeState, h) -> TildeState:
    """One step of nonholonomic RATTLE, (nonholonomicRATTLE), and its affine form of §6.1.

    The same kicks and drift as :func:`euler_a_map`, with the discrete constraint
    $\\mu(q_{k+1}) M^{-1}(\\tilde p_{k+1} - \\Pi(q_{k+1})) = 0$.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric $M$.
        state: a :class:`TildeState` $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.
        h: step size, nonzero (negative allowed).

    Returns:
        The :class:`TildeState` $(q_{k+1}, \\tilde p_{k+1}, \\tilde\\lambda_{k+1})$.
    """
    return _kick_drift_kick(system, TildeState(*state), h, _S_RATTLE)


def tilde_state_from_gni(system, q, p_plus, h, s: float) -> TildeState:
    """The paper's variables from the GNI state $(q_k, p^+_k)$.

    $\\tilde\\lambda = (2/h) C^{-1}\\mu M^{-1}(p^+ - \\Pi)$ (from $p^- - p^+ = -h\\mu^T\\tilde\\lambda$ and
    the reflection (Comb)), $\\tilde p = \\bar p - s(h/2)V_q$ with $\\bar p = P^* p^+ + Q^*\\Pi$.

    Arguments:
        system: a :class:`~gnipy.System` with a constant metric.
        q: configuration $q_k$.
        p_plus: the GNI post-momentum $p^+_k$ (at the start, $M v_0$).
        h: the step size of the scheme.
        s: +1 (Euler A), −1 (Euler B), 0 (RATTLE).

    Returns:
        The :class:`TildeState` $(q_k, \\tilde p_k, \\tilde\\lambda_k)$.
    """
    M = system.metric(q)
    mu = system.mu(q)
    Pi = system.Pi(q)
    Minv_muT = solve_spd(M, mu.T)
    C = mu @ Minv_muT
    w = solve_spd(C, mu @ solve_spd(M, p_plus - Pi))  # C⁻¹μM⁻¹(p⁺ − Π)
    p_bar = p_plus - mu.T @ w  # P*p⁺ + Q*Π
    lam = (2.0 / h) * w
    p_tilde = p_bar - s * 0.5 * h * system.potential_gradient(q)
    return TildeState(q, p_tilde, lam, jnp.zeros_like(q), jnp.zeros_like(p_tilde))


class _TildeScheme(Integrator):
    """Shared init/observe of the one-step schemes on $(q, \\tilde p, \\tilde\\lambda)$."""

    # the sign s of the discrete constraint of the map whose output the state holds, and the
    # step of that map as a fraction of h (the composition ends with Euler A at h/2)
    _s: ClassVar[float] = 0.0
    _fraction: ClassVar[float] = 1.0

    #: the single maps (euler-a, euler-b, rattle) keep holonomic constraints, unforced
    #: (:func:`_holonomic_kick_drift_kick`); the composition euler-ab does not
    holonomic: ClassVar[bool] = True

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` unless the metric is constant (paper §5), and for a
        system with both holonomic constraints and a force."""
        require_constant_metric(self.name, system, q0)
        if system.holonomic is not None and system.force is not None:
            raise MethodError(
                f"method {self.name!r} keeps holonomic constraints on unforced systems only; {system.name!r} has "
                "a force as well: use the gni-* method it equals"
            )

    def symmetric_on(self, system) -> bool:
        """:attr:`symmetric` (RATTLE); Euler A, Euler B and their composition too where V is constant
        and there is no force (l does not depend on q, :meth:`gnipy.System.lagrangian_depends_on`): their
        discrete constraints, $\\mu M^{-1}(\\tilde p \\pm \\tfrac h2 V_q - \\Pi) = 0$, are then RATTLE's."""
        if self.symmetric:
            return True
        return system.force is None and not system.lagrangian_depends_on("configuration")

    def init(self, system, q0, v0, h):
        """$(q_0, \\tilde p_0, \\tilde\\lambda_0)$ from the GNI start $p^+_0 = M v_0$.

        Arguments:
            system: the system.
            q0: initial configuration.
            v0: initial velocity on the constraints.
            h: step size.

        Returns:
            A :class:`TildeState` ($\\tilde\\lambda_0 = 0$ up to round-off).
        """
        return tilde_state_from_gni(system, q0, system.momentum(q0, v0), self._fraction * h, self._s)

    def observe(self, system, state, h):
        """The GNI's reported $(q, \\bar v, \\bar p)$ with $\\bar p = \\tilde p + s(h'/2)V_q$.

        Arguments:
            system: the system.
            state: a :class:`TildeState`.
            h: step size.

        Returns:
            `(q, v, p)`.
        """
        q, p_tilde = state[0], state[1]
        p_bar = p_tilde + self._s * 0.5 * (self._fraction * h) * system.potential_gradient(q)
        return q, solve_spd(system.metric(q), p_bar), p_bar

    def hidden_momentum(self, system, state, h):
        """The GNI's $p^+ - \\bar p = \\tfrac{h'}{2}\\mu^T\\tilde\\lambda$ ($h'$ the step of the map whose
        output the state holds; see :func:`tilde_state_from_gni`)."""
        q, lam = state[0], state[2]
        return 0.5 * (self._fraction * h) * system.mu(q).T @ lam


class NonholonomicEulerA(_TildeScheme):
    """Nonholonomic Euler A, (EuAHam), explicit on $(q, \\tilde p, \\tilde\\lambda)$ (order 1, Thm 5.1).

    Equal to the GNI with the Euler A discrete Lagrangian ("gni-euler-a"). Constant metric only.
    Reports $\\bar p = \\tilde p + (h/2)V_q$ and $\\bar v = M^{-1}\\bar p$.
    """

    name: ClassVar[str] = "euler-a"
    order: ClassVar[int | None] = 1
    _s: ClassVar[float] = _S_EULER_A

    def step(self, system, state, h):
        """One step of :func:`euler_a_map`; returns `(state, StepInfo)` (no iterations; a Newton solve with a force)."""
        return _map_step(system, state, h, _S_EULER_A)


class NonholonomicEulerB(_TildeScheme):
    """Nonholonomic Euler B, (EuBHam), explicit on $(q, \\tilde p, \\tilde\\lambda)$ (order 1, Thm 5.1).

    Equal to the GNI with the Euler B discrete Lagrangian ("gni-euler-b"). Constant metric only.
    Reports $\\bar p = \\tilde p - (h/2)V_q$ and $\\bar v = M^{-1}\\bar p$.
    """

    name: ClassVar[str] = "euler-b"
    order: ClassVar[int | None] = 1
    _s: ClassVar[float] = _S_EULER_B

    def step(self, system, state, h):
        """One step of :func:`euler_b_map`; returns `(state, StepInfo)` (no iterations, also with a force: $f^- = 0$)."""
        return _map_step(system, state, h, _S_EULER_B)


class Rattle(_TildeScheme):
    """Nonholonomic RATTLE, (nonholonomicRATTLE), and affine RATTLE (§6.1) (order 2).

    Equal to the GNI with the trapezoid discrete Lagrangian ("gni-trapezoid"). Constant metric
    only. Reports $\\bar p = \\tilde p$ and $\\bar v = M^{-1}\\tilde p$.
    """

    name: ClassVar[str] = "rattle"
    order: ClassVar[int | None] = 2
    #: its step at −h from the end returns to the start ((q, p̃, λ̃) needs no involution)
    symmetric: ClassVar[bool] = True
    _s: ClassVar[float] = _S_RATTLE

    def step(self, system, state, h):
        """One step of :func:`rattle_map`; returns `(state, StepInfo)` (no iterations; a Newton solve with a force)."""
        return _map_step(system, state, h, _S_RATTLE)


class EulerABComposition(_TildeScheme):
    """Euler B then Euler A, each with step h/2 (Remark after Theorem 5.2) (order 2).

    The composition $F_A^{h/2} \\circ F_B^{h/2}$ of the two discrete flows, i.e. of the GNI with the
    Euler B and then the Euler A discrete Lagrangian at step h/2, written with the explicit maps
    :func:`euler_b_map` and :func:`euler_a_map`. The two maps read the GNI's momentum differently,
    $\\bar p = \\tilde p - (h'/2)V_q$ (B) and $\\bar p = \\tilde p + (h'/2)V_q$ (A), $h' = h/2$, so the
    $\\tilde p$ handed from one map to the other is shifted by $\\mp (h/2) V_q$ at each junction:

        p̃ ← p̃ + (h/2)V_q(q_k);  F_B^{h/2};  p̃ ← p̃ − (h/2)V_q(q_{k+1/2});  F_A^{h/2}.

    Without the shifts (composing (EuBHam) and (EuAHam) literally on $(q, \\tilde p, \\tilde\\lambda)$)
    the junctions add alternating tangential kicks of size $(h/2)P^*V_q$ and the method is only of
    order 1 (measured in the tests). The symmetry argument of the Remark fails there because
    Theorem 5.2's inverse $F_B^{h/2} = (F_A^{-h/2})^{-1}$ holds only on the states with
    $\\mu M^{-1}(\\tilde p - (h/4)V_q - \\Pi) = 0$, while $F_A^{h/2}$ produces states with
    $\\mu M^{-1}(\\tilde p + (h/4)V_q - \\Pi) = 0$.
    As the paper notes, the method does *not* reproduce RATTLE in the nonholonomic case.

    The state holds the output of Euler A at step h/2: it starts from $\\tilde p_0 = M v_0 - (h/4)V_q(q_0)$,
    $\\tilde\\lambda_0 = 0$, and reports $\\bar p = \\tilde p + (h/4)V_q$, $\\bar v = M^{-1}\\bar p$.
    Constant metric only.
    """

    name: ClassVar[str] = "euler-ab"
    holonomic: ClassVar[bool] = False  # its half maps are written without the position multiplier
    order: ClassVar[int | None] = 2
    _s: ClassVar[float] = _S_EULER_A
    _fraction: ClassVar[float] = 0.5

    def step(self, system, state, h):
        """One composite step (Euler B at h/2, then Euler A at h/2); returns `(state, StepInfo)`.

        Arguments:
            system: the system (constant metric).
            state: a :class:`TildeState` in Euler A's reading at step h/2.
            h: the composite step size.

        Returns:
            `(TildeState, StepInfo)`, no iterations.
        """
        half = 0.5 * h
        q, p_tilde, lam, q_err, p_err = state
        # Euler A reads p̄ = p̃ + (h/4)V_q; Euler B reads p̄ = p̃_B − (h/4)V_q: p̃_B = p̃ + (h/2)V_q
        p_b, p_err = _add(p_tilde, half * system.potential_gradient(q), p_err)
        if system.force is not None:  # Euler B on [t, t + h/2], Euler A on [t + h/2, t + h]
            mid, info_b = _forced_kick_drift_kick(system, TildeState(q, p_b, lam, q_err, p_err), half, _S_EULER_B)
        else:
            mid = euler_b_map(system, TildeState(q, p_b, lam, q_err, p_err), half)
        # and back at the middle node: p̃_A = p̃_B − (h/2)V_q
        p_a, p_err = _add(mid.p_tilde, -half * system.potential_gradient(mid.q), mid.p_err)
        mid = mid._replace(p_tilde=p_a, p_err=p_err)
        if system.force is not None:
            new, info_a = _forced_kick_drift_kick(system.shifted(half), mid, half, _S_EULER_A)
            return new, StepInfo(info_a.ok & info_b.ok, info_a.iterations + info_b.iterations,
                                 jnp.maximum(info_a.residual, info_b.residual))
        new = euler_a_map(system, mid, half)
        return new, explicit_step_info(*new)
