r"""The sister method: one switch of a piecewise-holonomic *sister* system per step (the paper's
open question 3; the theory, and the sister motion it discretizes, in :mod:`gnipy.analysis.sister`).

At node k the constraints $\mu(q)\dot q = 0$ are replaced, for one step, by a holonomic constraint
through $q_k$ tangent to the distribution there: by default the *rail* $\varphi_k(q) = \mu(q_k)(q - q_k)$,
or any function `constraint(q, anchor)` c, engaged as $\varphi_k(q) = c(q, q_k)$. One step from
$(q_k, p_k)$, $p_k$ on the constraints, is RATTLE on the engaged constraint (the constrained
discrete Euler–Lagrange equations of Marsden and West, Acta Numerica 10 (2001) §3.5, trapezoid
$L_d$), then the plastic impact onto the distribution at $q_{k+1}$:

$$FL^-(q_k, q_{k+1}) = p_k + d\varphi_k(q_k)^T\Lambda_k,\qquad \varphi_k(q_{k+1}) = 0,$$

$$p^-_{k+1} = P^*_{\varphi}(q_{k+1})\,FL^+(q_k, q_{k+1}),\qquad p_{k+1} = P^*(q_{k+1})\,p^-_{k+1},$$

$P^*_\varphi$ the $\mathbb{G}$-orthogonal projection onto the covectors whose velocity satisfies
$d\varphi_k(q_{k+1})\dot q = 0$ (RATTLE's end), $P^*$ the GNI's projection onto the constraints
((Comb), :func:`gnipy.projectors.reported_momentum`). The impact removes the energy
$\tfrac12(p^-\cdot\mathbb{G}^{-1}p^- - p\cdot\mathbb{G}^{-1}p)$ at every step: the method is of
order 1 and dissipates $O(h)$ per unit time, as the sister motion does $O(\tau)$ (measured in
:mod:`gnipy.experiments.open_questions` and on the docs page "The paper's open questions").

With the rail, $\varphi_k$ is linear, so the step's constraint equation is $\mu(q_k)\Delta q = 0$ on the
increment. For the GNI the same step is a *free* discrete flow with an *elastic* reflection at each
node; the two are different maps (their local difference is $O(h^2)$, measured).

Written for systems on $\mathbb{R}^n$ with linear nonholonomic constraints and no holonomic
constraints or forces: the rail needs a vector space, and a sister of an affine constraint would need
a moving rail.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..discrete_lagrangians import Trapezoid
from ..projectors import reported_momentum
from ..holonomic import phi_scale
from .base import Integrator, MethodError, solve_step

__all__ = ["SisterMethod", "SisterState"]


class SisterState(NamedTuple):
    """State at node k: the configuration $q_k$, the momentum $p_k$ (on the constraints, after the
    impact) and the rounding error of $q_k$ (compensated summation, :func:`gnipy.spaces.compensated_add`)."""

    b: jax.Array
    p: jax.Array
    x_err: jax.Array


class SisterMethod(Integrator):
    """The sister method (module docstring): RATTLE on a holonomic constraint through $q_k$ tangent
    to the distribution, then the plastic impact onto the constraints, every step.

    Arguments:
        constraint: `constraint(q, anchor)`, the holonomic constraint engaged at the node `anchor`
            (one entry per nonholonomic constraint, zero at `q = anchor`, its differential there
            spanning the rows of $\\mu(\\text{anchor})$); default None, the rail
            $\\mu(\\text{anchor})(q - \\text{anchor})$.
        root_finder: optimistix root finder (default the built-in Newton, tolerance 1e-12).
        max_steps: Newton iteration cap.
    """

    constraint: Any = None
    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)

    name: ClassVar[str] = "sister"
    #: first order: the impact's dissipation is O(h) per unit time (measured, module docstring)
    order: ClassVar[int | None] = 1
    #: the state (q, p) does not depend on h
    can_change_step: ClassVar[bool] = True
    #: the plastic impact removes energy at every step (O(h) per unit time)
    dissipates_energy: ClassVar[bool] = True

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` unless the system is on $\\mathbb{R}^n$ with linear
        nonholonomic constraints and no holonomic constraints or forces."""
        if system.group is not None:
            raise MethodError(f"method {self.name!r} (the sister method) needs a system on R^n: the rail "
                              f"mu(q_k)(q - q_k) is laid in a vector space, and {system.name!r} has a group part; "
                              "use sgni-trapezoid or dla")
        if system.affine is not None:
            raise MethodError(f"method {self.name!r} is written for linear constraints: {system.name!r} has an "
                              "affine part Y, whose sister would need a moving rail; use sgni-trapezoid or dla")
        if system.force is not None:
            raise MethodError(f"method {self.name!r} does not support forces: {system.name!r} has a force "
                              "F(q, v, u, t); use sgni-trapezoid or gni-trapezoid")

    @property
    def start_label(self) -> str:
        """`"p = G v0 projected onto the constraints"` (:meth:`init`)."""
        return "p = G v0 projected onto the constraints"

    def init(self, system, q0, v0, h):
        """$(q_0, p_0)$: $\\mathbb{G}v_0$ projected onto the constraints (a no-op up to round-off for
        a $v_0$ on them)."""
        p0 = reported_momentum(system.metric(q0), system.mu(q0), jnp.zeros_like(v0), system.momentum(q0, v0))
        return SisterState(q0, p0, jnp.zeros_like(q0))

    def engaged(self, system, q, anchor):
        """$\\varphi(q)$ of the constraint engaged at the node `anchor` (:attr:`constraint`, or the rail)."""
        if self.constraint is None:
            return system.mu(anchor) @ (q - anchor)
        return jnp.atleast_1d(self.constraint(q, anchor))

    def advance(self, system, state, h):
        """One step with its intermediate momentum: `(SisterState, StepInfo, p_minus)`, `p_minus`
        RATTLE's end momentum $p^-_{k+1}$ before the impact."""
        q, p, x_err = state
        space = system.space
        ld = Trapezoid()
        n = q.shape[0]
        rows0 = system.mu(q) if self.constraint is None else jax.jacfwd(lambda x: self.engaged(system, x, q))(q)
        m = rows0.shape[0]

        def lagrangian(b0, z):
            return ld(system, b0, z, h)

        def holds(z):
            # the rail on the increment itself, mu(q_k) z: written as mu(q_k)((q_k + z) - q_k) it would lose
            # eps|q_k| to the sum, far above round-off of the step where |q| >> |z|
            return rows0 @ z if self.constraint is None else self.engaged(system, q + z, q)

        def residual(w):
            z, lam = w[:n], w[n:]
            return jnp.concatenate([space.legendre_minus(lagrangian, q, z) - p - rows0.T @ lam, holds(z)])

        v = system.velocity(q, p)
        guess = jnp.concatenate([space.initial_guess(q, v, h), jnp.zeros(m, dtype=p.dtype)])
        # the round-off floor: momentum rows of the size of p; the constraint's rows |mu||z| for the rail
        # (z ~ h v), |dphi| max(1, |q|) for a constraint of the absolute configuration
        size = (jnp.max(jnp.abs(rows0)) * jnp.maximum(jnp.max(jnp.abs(h * v)), jnp.finfo(p.dtype).tiny)
                if self.constraint is None else phi_scale(system, q, rows0))
        scale = jnp.concatenate([jnp.full((n,), jnp.max(jnp.abs(p))), jnp.full((m,), size)])
        w, info = solve_step(residual, guess, explicit=False, solver=self.root_finder, max_steps=self.max_steps,
                             floor_scale=scale)
        z, lam = w[:n], w[n:]
        q1, x_err = space.advance_compensated(q, x_err, z)
        # FL⁺ = FL⁻ + (FL⁺ − FL⁻) at the solution (the momentum carried, as in the GNI)
        p_plus = p + rows0.T @ lam + space.legendre_jump(lagrangian, q, z)
        G1, zero = system.metric(q1), jnp.zeros_like(p)
        # the rail's rows are constant (mu(q_k)); another constraint's are its differential at q_{k+1}
        rows1 = rows0 if self.constraint is None else jax.jacfwd(lambda x: self.engaged(system, x, q))(q1)
        p_minus = reported_momentum(G1, rows1, zero, p_plus)  # RATTLE's end: tangent to φ_k = 0
        p1 = reported_momentum(G1, system.mu(q1), zero, p_minus)  # the plastic impact
        return SisterState(q1, p1, x_err), info, p_minus

    def step(self, system, state, h):
        """One step (:meth:`advance`): `(SisterState, StepInfo)`."""
        new, info, _ = self.advance(system, state, h)
        return new, info

    def observe(self, system, state, h):
        """$(q_k, \\mathbb{G}^{-1}p_k, p_k)$."""
        q, p, _ = state
        return q, system.velocity(q, p), p
