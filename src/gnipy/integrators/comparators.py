"""Methods the GNI is compared against.

- :class:`DiscreteLagrangeDAlembert` (`"dla"`): the discrete Lagrange–d'Alembert principle of
  Cortés–Martínez, $p^+_k - p^-_k = \\mu(q_k)^T\\lambda_k$ with a discrete constraint imposed at the
  midpoint of each step.
- :class:`McLachlanPerlmutter` (`"mp"`): the reversible scheme (4.18) of McLachlan–Perlmutter (2006),
  for a constant metric.

Forces (:mod:`gnipy.forcing`): DLA takes them in the forced discrete Legendre transforms, as the
GNI ($FL^- - f^- = p^-$, $p^+_{k+1} = FL^+ + f^+$, the quadrature of its $l_d$); McLachlan–Perlmutter
adds the impulse $f^- + f^+$ of the midpoint rule, $hF\big(\tfrac12(q_0 + q_1), (q_1 - q_0)/h, u,
t + \tfrac h2\big)$, to its kick, which keeps it symmetric and of order 2.

Both are implicit: each step is one Newton solve through :func:`~gnipy.integrators.base.solve_step`
(optimistix, `throw=False`, the result promoted into :class:`~gnipy.StepInfo`), so a failed step is
reported by :func:`~gnipy.simulate` like any other method's.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..linalg import LU_UNROLL_MAX, UNROLL_MAX, solve_spd  # the metric and the C = μG⁻¹μᵀ are SPD
from ..discrete_lagrangians import DiscreteLagrangian, Midpoint
from ..forcing import discrete_forces
from ..holonomic import phi_scale
from ..spaces import compensated_add
from .base import Integrator, chord_solver, momentum_constraint_scale, require_constant_metric, solve_step

__all__ = ["DiscreteLagrangeDAlembert", "DLAState", "McLachlanPerlmutter", "MPState"]


class DLAState(NamedTuple):
    """DLA state at node k: the configuration $q_k$, the post-momentum $p^+_k$, the rounding
    error of the Euclidean coordinates (compensated summation), and where the step keeps its
    Jacobian (`reuse_jacobian`), `jacobian = (solver, h_solver, w, h_w)`: the chord solver of a
    Jacobian (:func:`~gnipy.integrators.base.chord_solver`) and the step size it serves (0: form a
    new one at the next step), the last step's solution $w = (\\Delta q, \\lambda)$ and the step
    size it was made with (0 before the first step); None otherwise."""

    b: jax.Array
    p_plus: jax.Array
    x_err: jax.Array
    jacobian: Any = None


class DiscreteLagrangeDAlembert(Integrator):
    """Discrete Lagrange–d'Alembert integrator (Cortés–Martínez).

    One step from $(q_k, p^+_k)$ solves, for the $n + m$ unknowns $(q_{k+1}, \\lambda_k)$,

    $$FL^-(q_k, q_{k+1}) = p^+_k - \\mu(q_k)^T\\lambda_k \\qquad (p^+_k - p^-_k = \\mu(q_k)^T\\lambda_k),$$
    $$\\mu(q_{k+1/2})\\Big(\\frac{q_{k+1} - q_k}{h} - Y(q_{k+1/2})\\Big) = 0,
      \\qquad q_{k+1/2} = \\tfrac12(q_k + q_{k+1}),$$

    and sets $p^+_{k+1} = FL^+(q_k, q_{k+1})$. The first equation is the discrete
    Lagrange–d'Alembert principle (the constraint force acts at the node $q_k$, as in (GNIloca));
    the second is the continuous constraint evaluated at the step's velocity and the step's midpoint
    (the documented base point of the discrete constraint). It starts from $p^+_0 = \\mathbb{G}(q_0)v_0$.

    On $\\mathbb{R}^n \\times G$ (IMMM) the unknowns are $(x_{k+1}, \\sigma_k)$ with
    $R_{k+1} = R_k\\tau(\\sigma_k)$, $FL^\\mp$ are the (RedLegTr) transforms (:mod:`gnipy.spaces`), and the
    discrete constraint is imposed at the base point
    $b_{k+1/2} = \\big(\\tfrac12(x_k + x_{k+1}),\\ R_k\\tau(\\sigma_k/2)\\big)$ on the step velocity
    $(\\Delta_k, \\xi_k)$, $\\Delta_k = (x_{k+1} - x_k)/h$, whose group part is carried by the retraction's
    inverse tangent (eq:dtauinversedef):

    $$\\xi_k = \\mathrm{d}\\tau^{-1}_{\\sigma_k}\\sigma_k/h, \\qquad
      \\mu(b_{k+1/2})\\Big(\\big(\\Delta_k, \\xi_k\\big) - Y(b_{k+1/2})\\Big) = 0$$

    (for a reduced system only $\\tfrac12(x_k + x_{k+1})$ matters; $\\sigma_k = \\tau^{-1}(R_k^{-1}R_{k+1})$).
    The momenta carry $\\partial l_d/\\partial\\sigma$ by $(\\mathrm{d}\\tau^{-1}_{\\pm\\sigma_k})^T$ ((RedLegTr));
    the same $\\mathrm{d}\\tau^{-1}$ on the velocity makes the constraint see the velocity that the
    momentum holds, as the GNI's constraint, imposed on the momenta ((GNIredb-aff), (RBb)), does.
    $\\mathrm{d}\\tau^{-1}_\\sigma\\sigma$ (:meth:`gnipy.retractions.Retraction.dtau_inv_along`) is σ for
    the exponential map and $\\sigma(1 + |\\sigma|^2/4)$ for the Cayley map on SO(3). For a rotation at
    rate ω over the step, $\\sigma/h = \\omega(1 + h^2|\\omega|^2/12) + O(h^4)$, while for a kinetic
    energy $\\tfrac12\\dot x^TM\\dot x + \\tfrac c2|\\omega|^2$ the Cayley momentum is
    $c\\,\\omega(1 + h^2|\\omega|^2/3) + O(h^4)$. The constraint on $\\sigma/h$ alone (before issue 29)
    gave the Cayley `rolling-ball` 550 times the error of the same motion on $\\mathbb{R}^5$
    (`rotating-table-ball`; h = 0.01, T = 10: 1.04e-2 against 1.88e-5, both order 2). Now the two agree
    to round-off (for such a kinetic energy the scheme in $(x, \\mathbb{G}^{-1}p)$ is the
    $\\mathbb{R}^n$ one, step for step), and on the other group models DLA with Cayley has the error
    constant of the GNI with Cayley (methods guide, "Methods to compare against"). A constraint
    linear in the group velocity alone (`suslov`, `veselova`, `chaplygin-sleigh-se2`) has the same
    solutions either way: $\\mathrm{d}\\tau^{-1}_\\sigma\\sigma$ is a multiple of σ on SO(3) and SE(2).

    What is reported at node k is $p = p^+_k$ and $v = \\mathbb{G}(q_k)^{-1}p^+_k$. Unlike the GNI's
    $\\bar v$, this velocity does **not** satisfy the continuous constraint $\\mu(q_k)(v - Y(q_k)) = 0$
    exactly (its residual is $O(h)$, the size of the impulse $\\mu(q_k)^T\\lambda_k$ that separates
    $p^+_k$ from $p^-_k$): what DLA preserves exactly is the *discrete* constraint above, on
    consecutive configurations. The reported velocity is therefore only first-order accurate, while
    the configurations are second order with the midpoint $l_d$.

    Works for position-dependent metrics and affine constraints (the Newton solve is always used).

    With more than :data:`gnipy.linalg.UNROLL_MAX` unknowns (and up to
    :data:`gnipy.linalg.LU_UNROLL_MAX`) the step keeps its Jacobian: the LU factors of the Newton
    matrix travel in the state, the next step's chord iterations start with them from the last
    step's solution (the guess, in place of $h\\,\\mathbb{G}^{-1}p^+$), and the Jacobian is formed
    again only where they do not converge, contract too slowly, or took more than
    :data:`~gnipy.integrators.base.REUSE_MAX_EVALUATIONS` evaluations of the residual (then at the
    next step; :func:`~gnipy.integrators.base.newton`, `reuse`). The steps solve the same
    equations to the same round-off test either way, so the runs agree to round-off. There the
    forward-mode Jacobian is most of a step: on the native backend (2-core Intel Xeon, h = 0.01)
    the SymBRiM bicycle's step takes 4.4 µs instead of 6.7, `gnipy.models.whipple_bicycle`'s
    6.7 µs instead of 14.7 (BENCHMARKS.md, section 10). For smaller systems the Jacobian is cheap
    and a fresh one converges in fewer evaluations: keeping it made the Chaplygin sleigh's step
    slower (0.127 → 0.159 µs) and the rolling ball's (0.325 → 0.356 µs), Suslov's faster (0.257 →
    0.186 µs); with no gain to count on there, DLA forms it at every step by default up to 12
    unknowns (`reuse_jacobian=True` keeps it for them too).

    Arguments:
        discrete_lagrangian: the $l_d$ (default :class:`~gnipy.Midpoint`).
        root_finder: optimistix root finder (default Newton, tolerances 1e-12).
        max_steps: Newton iteration cap.
        reuse_jacobian: keep the Jacobian from step to step: None (default) above
            :data:`gnipy.linalg.UNROLL_MAX` unknowns, True always, False never (ignored with a
            `root_finder`, and above :data:`gnipy.linalg.LU_UNROLL_MAX` unknowns).
    """

    discrete_lagrangian: DiscreteLagrangian = Midpoint()
    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)
    reuse_jacobian: bool | None = eqx.field(static=True, default=None)
    name: ClassVar[str] = "dla"
    #: keeps holonomic constraints with a position multiplier (:mod:`gnipy.holonomic`)
    holonomic: ClassVar[bool] = True

    @property
    def order(self) -> int | None:  # type: ignore[override]
        """Expected global order of the configurations: the discrete Lagrangian's `order` (2 for
        the midpoint and trapezoid $l_d$, a symmetric two-step scheme; 1 for Euler A/B; what a
        :class:`~gnipy.CustomDiscreteLagrangian` declares)."""
        return self.discrete_lagrangian.order

    def init(self, system, q0, v0, h):
        """$(q_0, p^+_0 = \\mathbb{G}(q_0)v_0)$, and no Jacobian to reuse yet."""
        p0 = system.momentum(q0, v0)
        return DLAState(q0, p0, jnp.zeros_like(system.space.coordinates(q0)), self._no_jacobian_yet(system, q0, p0))

    def _no_jacobian_yet(self, system, b, p):
        """The `jacobian` field of a state from which no step was taken with this method: zeros
        with step sizes 0 (nothing to reuse), or None where the method keeps no Jacobian."""
        N = p.shape[0] + system.mu(b).shape[0]  # the unknowns (q_{k+1}, λ_k)
        reuse = N > UNROLL_MAX if self.reuse_jacobian is None else self.reuse_jacobian
        if not (reuse and self.root_finder is None and N <= LU_UNROLL_MAX):
            return None
        shapes = jax.eval_shape(chord_solver, jax.ShapeDtypeStruct((N, N), p.dtype))
        zero = jnp.zeros((), p.dtype)
        return (jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes), zero, jnp.zeros(N, p.dtype), zero)

    def continue_from(self, system, state):
        """A state without the kept Jacobian (a batch member's, :meth:`memoryless`) gets an empty
        one, so that a run continues from it (:meth:`Integrator.continue_from`)."""
        if isinstance(state, DLAState) and state.jacobian is None:
            return state._replace(jacobian=self._no_jacobian_yet(system, state.b, state.p_plus))
        return state

    def memoryless(self):
        """DLA without the kept Jacobian: the same step map (:meth:`Integrator.memoryless`)."""
        return dataclasses.replace(self, reuse_jacobian=False)

    def step(self, system, state, h):
        """One DLA step: Newton on $(q_{k+1}, \\lambda_k)$; returns `(DLAState, StepInfo)`."""
        b, p_plus, x_err, kept = state
        space = system.space
        mu_k = system.mu(b)
        m = mu_k.shape[0]
        n = p_plus.shape[0]

        def ld(b0, z):
            return self.discrete_lagrangian(system, b0, z, h)

        forced = system.force is not None
        rule = self.discrete_lagrangian.force_rule

        def residual(w):
            z, lam = w[:n], w[n:]
            momentum = space.legendre_minus(ld, b, z) - (p_plus - mu_k.T @ lam)  # p⁺ − p⁻ = μ(q_k)ᵀλ
            if forced:  # the forced transform (gnipy.forcing): FL⁻ − f⁻ = p⁻
                momentum = momentum - discrete_forces(system, b, z, h, rule)[0]
            _, b_mid, _ = space.step_points(b, z, h)
            vel = space.constraint_velocity(z, h)  # (Δ, dτ⁻¹_σ σ/h) on a group: as FL∓ carry ∂l_d/∂σ
            if system.holonomic is None:
                constraint = system.mu(b_mid) @ (vel - system.Y(b_mid))  # discrete constraint at q_{k+½}
                return jnp.concatenate([momentum, constraint])
            # the multipliers of the rows dφ(q_k) are the position multiplier Λ: φ(q_{k+1}) = 0
            # in place of the discrete velocity constraint on those rows (gnipy.holonomic)
            constraint = system.nonholonomic_mu(b_mid) @ (vel - system.Y(b_mid))
            return jnp.concatenate([momentum, constraint, system.phi(space.advance(b, z))])

        def from_velocity(_):
            v = system.velocity(b, p_plus)
            return jnp.concatenate([space.initial_guess(b, v, h), jnp.zeros(m, dtype=p_plus.dtype)])

        if kept is None:
            guess = from_velocity(None)
        else:  # the previous step's solution, where it was made with this step size
            guess = jax.lax.cond(kept[3] == h, lambda _: kept[2], from_velocity, None)
        v = guess[:n] / h  # the velocity (h v: the guess), or the previous step's
        scale = momentum_constraint_scale(n, p_plus, mu_k, v, system.Y(b))
        if system.holonomic is not None:  # the φ rows: terms of the size |dφ||q|
            r = system.phi(b).shape[0]
            scale = scale.at[n + m - r:].set(phi_scale(system, b, system.holonomic_mu(b)))
        # λ enters only the momentum rows, through μ(q_k)ᵀλ: constant Jacobian columns (newton)
        tail = jnp.concatenate([mu_k.T, jnp.zeros((m, m), dtype=mu_k.dtype)])
        if kept is None:
            w, info = solve_step(residual, guess, explicit=False, solver=self.root_finder,
                                 max_steps=self.max_steps, floor_scale=scale, tail_columns=tail)
        else:  # the last step's Jacobian, where it was formed for this step size
            w, info, (solver, keep) = solve_step(residual, guess, explicit=False, solver=self.root_finder,
                                                 max_steps=self.max_steps, floor_scale=scale, tail_columns=tail,
                                                 reuse=(kept[0], kept[1] == h))
            # the step size it serves, or 0 where it has aged (formed again at the next step) or is not
            # finite (a zero pivot: the step was solved by the pivoted fallback; zeros kept instead)
            hh = jnp.asarray(h, dtype=p_plus.dtype)
            kept = (solver, jnp.where(keep, hh, jnp.zeros_like(kept[1])), w, hh + jnp.zeros_like(kept[3]))
        z, lam = w[:n], w[n:]
        b1, x_err = space.advance_compensated(b, x_err, z)
        p1 = p_plus - mu_k.T @ lam + space.legendre_jump(ld, b, z)  # FL⁺ = p⁻ + (FL⁺ − FL⁻)
        if forced:  # p⁺_{k+1} = FL⁺ + f⁺ = p⁻ + f⁻ + (FL⁺ − FL⁻) + f⁺
            f_minus, f_plus = discrete_forces(system, b, z, h, rule)
            p1 = p1 + (f_minus + f_plus)
        return DLAState(b1, p1, x_err, kept), info

    def observe(self, system, state, h):
        """$(q_k,\\ \\mathbb{G}^{-1}p^+_k,\\ p^+_k)$ (see the class docstring on the velocity)."""
        b, p_plus = state.b, state.p_plus
        return b, system.velocity(b, p_plus), p_plus


class MPState(NamedTuple):
    """McLachlan–Perlmutter state at node k: configuration, velocity (on the constraints) and
    the rounding error of q (compensated summation)."""

    q: jax.Array
    v: jax.Array
    q_err: jax.Array


class McLachlanPerlmutter(Integrator):
    """The reversible nonholonomic scheme (4.18) of McLachlan–Perlmutter (2006).

    For $l = \\tfrac12 v^TMv - V(q)$ with a constant metric $M$, one step from $(q_0, v_0)$:

    $$q_{1/2} = q_0 + \\tfrac h2 v_0,\\qquad
      v_1 = v_0 + hM^{-1}\\big(-V_q(q_{1/2}) + \\mu(q_{1/2})^T\\lambda\\big),$$
    $$q_1 = q_{1/2} + \\tfrac h2 v_1,\\qquad \\mu(q_1)\\big(v_1 - Y(q_1)\\big) = 0,$$

    with the $m$ unknowns $\\lambda$ found by Newton's method. The velocity satisfies the constraints
    exactly at every node. For linear constraints ($Y = 0$) the map is reversible:
    $(q_1, -v_1) \\mapsto (q_0, -v_0)$ with the same $\\lambda$, hence symmetric and of order 2.
    Reports $v$ and $p = Mv$.

    With a force $F(q, v, u, t)$ the kick gains the impulse $f^- + f^+ = hF\\big(\\tfrac12(q_0 + q_1),
    \\tfrac12(v_0 + v_1), u, t + \\tfrac h2\\big)$ (:func:`gnipy.forcing.discrete_forces`, midpoint rule),
    symmetric under $(q_0, v_0, t) \\leftrightarrow (q_1, v_1, t + h)$, $h \\to -h$: the step stays of
    order 2, and is one Newton solve on $(v_1, \\lambda)$.

    Arguments:
        root_finder: optimistix root finder (default Newton, tolerances 1e-12).
        max_steps: Newton iteration cap.

    Raises:
        MethodError: from :meth:`check`, when the metric depends on q.
    """

    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)
    name: ClassVar[str] = "mp"
    can_change_step: ClassVar[bool] = True  # the state (q, v) does not depend on h
    order: ClassVar[int | None] = 2
    #: the step at −h from $(q_1, v_1)$ has $q_{1/2}$ and the same λ as a root: it returns to $(q_0, v_0)$
    symmetric: ClassVar[bool] = True

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` unless the metric is constant (the scheme uses $M^{-1}$)."""
        require_constant_metric(self.name, system, q0)

    def init(self, system, q0, v0, h):
        """$(q_0, v_0)$."""
        return MPState(q0, v0, jnp.zeros_like(q0))

    def step(self, system, state, h):
        """One step of (4.18): Newton on λ; returns `(MPState, StepInfo)`."""
        q0, v0, q_err = state
        q_half = q0 + 0.5 * h * v0
        M = system.metric(q_half)  # constant by `check`
        mu_half = system.mu(q_half)
        force = -system.potential_gradient(q_half)
        m = mu_half.shape[0]

        if system.force is not None:
            return self._forced_step(system, state, h, q_half, M, mu_half, force)

        def velocity(lam):
            return v0 + h * solve_spd(M, force + mu_half.T @ lam)

        def residual(lam):
            v1 = velocity(lam)
            q1 = q_half + 0.5 * h * v1
            return system.mu(q1) @ (v1 - system.Y(q1))

        # the residual μ(v₁ − Y) has terms of the size |μ|(|v| + |Y|), but ∂/∂λ = O(h): λ itself is
        # only determined to ~ε|v|/h, so the round-off floor of the residual decides convergence
        scale = jnp.max(jnp.abs(mu_half)) * (jnp.max(jnp.abs(v0)) + jnp.max(jnp.abs(system.Y(q_half))))
        lam, info = solve_step(
            residual, jnp.zeros(m, dtype=v0.dtype), explicit=False, solver=self.root_finder, max_steps=self.max_steps,
            floor_scale=scale,
        )
        v1 = velocity(lam)
        # q_1 = q_{1/2} + (h/2)v_1 = q_0 + (h/2)(v_0 + v_1), summed onto q_0 with compensation
        q1, q_err = compensated_add(q0, 0.5 * h * (v0 + v1), q_err)
        return MPState(q1, v1, q_err), info

    def _forced_step(self, system, state, h, q_half, M, mu_half, force):
        """The step with the discrete force (module docstring): Newton on $(v_1, \\lambda)$, since the
        impulse $f^- + f^+$ of the midpoint rule depends on $v_1$ through the step's velocity
        $(q_1 - q_0)/h = \\tfrac12(v_0 + v_1)$:
        $M(v_1 - v_0) = h(-V_q(q_{1/2}) + \\mu(q_{1/2})^T\\lambda) + f^- + f^+$."""
        q0, v0, q_err = state
        n, m = v0.shape[0], mu_half.shape[0]

        def impulse(v1):
            f_minus, f_plus = discrete_forces(system, q0, 0.5 * h * (v0 + v1), h, "midpoint")
            return f_minus + f_plus

        def residual(w):
            v1, lam = w[:n], w[n:]
            q1 = q_half + 0.5 * h * v1
            return jnp.concatenate([
                M @ (v1 - v0) - h * (force + mu_half.T @ lam) - impulse(v1),
                system.mu(q1) @ (v1 - system.Y(q1)),
            ])

        f0 = system.external_force(q_half, v0, system.drive.t + 0.5 * h)
        guess = jnp.concatenate([v0 + h * solve_spd(M, force + f0), jnp.zeros(m, dtype=v0.dtype)])
        p_size = jnp.abs(M @ v0) + jnp.abs(h) * (jnp.abs(force) + jnp.abs(f0))
        scale = momentum_constraint_scale(n, p_size, mu_half, v0, system.Y(q_half))
        w, info = solve_step(residual, guess, explicit=False, solver=self.root_finder, max_steps=self.max_steps,
                             floor_scale=scale)
        v1 = w[:n]
        q1, q_err = compensated_add(q0, 0.5 * h * (v0 + v1), q_err)
        return MPState(q1, v1, q_err), info

    def observe(self, system, state, h):
        """$(q_k, v_k, Mv_k)$."""
        q, v, _ = state
        return q, v, system.momentum(q, v)
