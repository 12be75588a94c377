"""A GNI variant without a hidden momentum: one constraint impulse per step, acting at both ends.

**Why the GNI needs one on the Chaplygin sleigh and Suslov's problem.** The GNI carries
$(b_k, p^+_k)$ and starts each step from the reflection $p^-_k = p^+_k - 2Q^*(p^+_k - \\Pi)$: it
leaves node k with the normal impulse it arrived with, so the impulses of consecutive steps are
coupled as in a two-step method, and the hidden momentum $p^+_k - \\bar p_k$ carries that
recursion's parasitic component. The GNI's map of $(b, p^+)$ preserves volume (a symplectic
discrete Legendre step after a reflection that is linear in p: $\\det = -1$, measured along a sleigh
run), but the motion on the constraint distribution contracts phase volume on systems without an
invariant measure, such as the sleigh and Suslov with their attracting relative equilibria. The
hidden direction must then expand at the rate at which the motion contracts: on the sleigh it
grows as $\\exp\\int (ma/J)u\\,dt$ (measured factor 11.0 over $4 \\le t \\le 8$, predicted 11.0), to O(1)
whatever the step. Resetting it to its consistent value $-\\tfrac h2\\mu^T\\lambda$ every step stops
the growth but makes the step non-invertible (not symmetric: N steps forward and N back miss the
start by 1e-6 to 2e-4 at N = 2000, h = 0.01). This variant is symmetric.

**The step.** From $(b_k, \\bar p_k)$, $\\bar p_k$ on the constraints, solve for the $N + m$ unknowns
$(z, \\alpha)$ (z the GNI's step unknowns)

$$FL^-(b_k, z) = \\bar p_k + \\tfrac h2\\mu(b_k)^T\\alpha, \\qquad
  \\bar p_{k+1} = FL^+(b_k, z) + \\tfrac h2\\mu(b_{k+1})^T\\alpha,$$
$$\\mu(b_{k+1})\\big(\\mathbb{G}(b_{k+1})^{-1}\\bar p_{k+1} - Y(b_{k+1})\\big) = 0.$$

With a force (:mod:`gnipy.forcing`) the transforms are the forced ones, $FL^- - f^-$ and
$FL^+ + f^+$ (the quadrature of the $l_d$, :func:`gnipy.forcing.discrete_forces`), as in the GNI.

It uses the GNI's discrete Lagrangian, Legendre transforms and reported momentum $\\bar p$. The
difference is the departure impulse: instead of reflecting the previous arrival impulse, one
multiplier $\\alpha_k$ acts at both ends of step k, as in RATTLE. The step is then a one-step map
of $(b_k, \\bar p_k)$ with no hidden state. For a symmetric $l_d$ the step with $-h$ is its exact
inverse (the reversed step reproduces $FL^\\mp$ with the same $\\alpha$; the involution σ is the
identity). It is then of order 2 and time-reversible, and its compositions reach order 6
(the GNI's stop at 4, see :mod:`gnipy.integrators.composition`). The constraints hold exactly at
every node, affine ones included. Energy: on $\\mathbb{R}^n$ with V = 0, a constant metric and a
constant $C = \\mu\\mathbb{G}^{-1}\\mu^T$ (the sleigh, the vertical disk) the energy is exactly
conserved, since
$|\\bar p_{k+1}|^2 - |\\bar p_k|^2 = \\tfrac{h^2}4(|\\mu_k^T\\alpha|^2 - |\\mu_{k+1}^T\\alpha|^2)$ in the
$\\mathbb{G}^{-1}$ norm. It is also conserved to round-off on `chaplygin-sleigh-se2`. On Suslov's
problem it is not: the scheme has no exact discrete steady rotations, and the energy drifts by
$O(h^2 t)$ along the attracting one (measured 3.7e-4 relative at T = 1000, h = 0.01; dla keeps
it to 4e-6).

On a constant metric it is the kick–drift–kick counterpart of McLachlan–Perlmutter's scheme
(4.18) (`mp`, drift–kick–drift). It also works for a metric that depends on the configuration, a
potential, any discrete Lagrangian, and on $\\mathbb{R}^n \\times G$. Cost: one Newton solve in
N + m unknowns per step (1.1–5.2 iterations on the zoo), where the GNI with the trapezoid is explicit
on a constant metric.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..discrete_lagrangians import DiscreteLagrangian, Trapezoid
from ..forcing import discrete_forces
from ..holonomic import phi_scale
from ..linalg import solve_spd
from ..projectors import reported_momentum
from .base import Integrator, momentum_constraint_scale, solve_step

__all__ = ["SymmetricImpulseGNI", "SymmetricImpulseState"]


class SymmetricImpulseState(NamedTuple):
    """State at node k: the configuration, the momentum $\\bar p_k$ (on the constraints) and the
    rounding error of the Euclidean coordinates (compensated summation)."""

    b: jax.Array
    p: jax.Array
    x_err: jax.Array


class SymmetricImpulseGNI(Integrator):
    """The GNI with one constraint impulse per step, acting at both of its ends (module docstring).

    Arguments:
        discrete_lagrangian: the $l_d$ (default :class:`~gnipy.Trapezoid`).
        root_finder: optimistix root finder (default: the built-in Newton, tolerance 1e-12).
        max_steps: Newton iteration cap.
    """

    discrete_lagrangian: DiscreteLagrangian = Trapezoid()
    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)

    #: the state $(b, \\bar p)$ does not depend on h
    can_change_step: ClassVar[bool] = True
    #: keeps holonomic constraints with a position multiplier at the start of each step (:meth:`step`)
    holonomic: ClassVar[bool] = True

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"sgni-{self.discrete_lagrangian.name}"

    @property
    def order(self) -> int | None:  # type: ignore[override]
        """The discrete Lagrangian's `order` (2 for the trapezoid and the midpoint)."""
        return self.discrete_lagrangian.order

    @property
    def symmetric(self) -> bool:  # type: ignore[override]
        """Whether the discrete Lagrangian is symmetric: then $\\Phi_h^{-1} = \\Phi_{-h}$ on $(b, \\bar p)$
        (the involution of :meth:`reverse` is the identity: the state holds no impulse)."""
        return bool(getattr(self.discrete_lagrangian, "symmetric", False))

    def symmetric_on(self, system) -> bool:
        """Whether the discrete Lagrangian is symmetric on this system
        (:meth:`~gnipy.discrete_lagrangians.DiscreteLagrangian.symmetric_on`: the midpoint is not
        where l depends on the orientation and the retraction is Cayley; Euler A and B are where
        l does not depend on the base point)."""
        ld = self.discrete_lagrangian
        return bool(ld.symmetric_on(system)) if hasattr(ld, "symmetric_on") else self.symmetric

    @property
    def start_label(self) -> str:
        """`"p = G v0 projected onto the constraints"` (:meth:`init`)."""
        return "p = G v0 projected onto the constraints (no hidden impulse)"

    def init(self, system, q0, v0, h):
        """$(b_0, \\bar p_0)$: $\\mathbb{G}v_0$ projected onto the constraints (a no-op up to round-off
        for a $v_0$ on them)."""
        x = system.space.coordinates(q0)
        p0 = reported_momentum(system.metric(q0), system.mu(q0), system.Pi(q0), system.momentum(q0, v0))
        return SymmetricImpulseState(q0, p0, jnp.zeros_like(x))

    def step(self, system, state, h):
        """One step: Newton on $(z, \\alpha)$; returns `(SymmetricImpulseState, StepInfo)`."""
        b, p_bar, x_err = state
        space = system.space
        G, mu = system.metric(b), system.mu(b)
        n, m = p_bar.shape[0], mu.shape[0]
        v_bar = solve_spd(G, p_bar)

        def ld(b0, z):
            return self.discrete_lagrangian(system, b0, z, h)

        forced = system.force is not None
        rule = self.discrete_lagrangian.force_rule

        # with holonomic constraints φ (gnipy.holonomic): α has a component on each row of μ = (μ; dφ),
        # and a position multiplier Λ at the start, dφ(b_k)ᵀΛ, keeps φ(b_{k+1}) = 0 (r more unknowns
        # and equations; the reversed step has −Λ at its start and α + 2Λ/h, so it stays symmetric)
        rows = system.holonomic_mu(b) if system.holonomic is not None else None
        r = 0 if rows is None else rows.shape[0]

        def departure(alpha, lam):
            p_minus = p_bar + 0.5 * h * (mu.T @ alpha)
            return p_minus if rows is None else p_minus + rows.T @ lam

        def residual(w):
            z, alpha, lam = w[:n], w[n:n + m], w[n + m:]
            p_minus = departure(alpha, lam)
            b1 = space.advance(b, z)
            mu1 = system.mu(b1)
            holds = [] if rows is None else [system.phi(b1)]
            if forced:  # the forced transforms (gnipy.forcing): FL⁻ − f⁻ = p⁻, p̄_{k+1} = FL⁺ + f⁺ + ...
                f_minus, f_plus = discrete_forces(system, b, z, h, rule)
                p1 = p_minus + (f_minus + f_plus) + space.legendre_jump(ld, b, z) + 0.5 * h * (mu1.T @ alpha)
                return jnp.concatenate([
                    space.legendre_minus(ld, b, z) - f_minus - p_minus,
                    mu1 @ (system.velocity(b1, p1) - system.Y(b1)), *holds,
                ])
            p1 = p_minus + space.legendre_jump(ld, b, z) + 0.5 * h * (mu1.T @ alpha)
            return jnp.concatenate([
                space.legendre_minus(ld, b, z) - p_minus,
                mu1 @ (system.velocity(b1, p1) - system.Y(b1)), *holds,
            ])

        # α = 0 as the first guess: measured cheaper than the continuous multiplier λ(b, v̄), whose
        # evaluation costs more than the iteration it saves
        guess = jnp.concatenate([space.initial_guess(b, v_bar, h), jnp.zeros(m + r, dtype=p_bar.dtype)])
        scale = momentum_constraint_scale(n, p_bar, mu, v_bar, system.Y(b))
        if rows is not None:  # the φ rows: terms of the size |dφ||q|
            scale = jnp.concatenate([scale, jnp.full((r,), phi_scale(system, b, rows), dtype=scale.dtype)])
        w, info = solve_step(residual, guess, explicit=False, solver=self.root_finder, max_steps=self.max_steps,
                             floor_scale=scale)
        z, alpha, lam = w[:n], w[n:n + m], w[n + m:]
        b1, x_err = space.advance_compensated(b, x_err, z)
        p_minus = departure(alpha, lam)
        if forced:  # summed as in the residual, so that the constraint holds at the stored p̄_{k+1}
            f_minus, f_plus = discrete_forces(system, b, z, h, rule)
            p1 = (p_minus + (f_minus + f_plus) + space.legendre_jump(ld, b, z)
                  + 0.5 * h * (system.mu(b1).T @ alpha))
        else:
            p1 = p_minus + space.legendre_jump(ld, b, z) + 0.5 * h * (system.mu(b1).T @ alpha)
        return SymmetricImpulseState(b1, p1, x_err), info

    def observe(self, system, state, h):
        """$(b_k, \\mathbb{G}^{-1}\\bar p_k, \\bar p_k)$."""
        b, p, _ = state
        return b, system.velocity(b, p), p
