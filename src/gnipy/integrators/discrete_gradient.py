"""An energy-conserving nonholonomic method: a discrete-gradient scheme with the constraints exact.

:class:`DiscreteGradient` (`"discrete-gradient"`) integrates the Hamiltonian form of the
Lagrange–d'Alembert(–Poincaré) equations,

$$\\dot x = \\partial_{p_x} H,\\qquad \\dot p_x = -\\partial_x H + \\mu_x^T\\lambda,\\qquad
\\dot\\pi = \\mathrm{ad}^*_\\xi\\pi + \\mu_{\\mathfrak g}^T\\lambda,\\quad \\xi = \\partial_\\pi H,\\qquad
\\mu(x)\\big(\\partial_p H - Y(x)\\big) = 0,$$

with $H(x, p) = \\tfrac12 p^T K(x) p + V(x)$, $K = \\mathbb{G}^{-1}$, $p = (p_x, \\pi)$ (no π on
$\\mathbb{R}^n$), by a discrete gradient of H and a constraint force modified so that it does no
work on the step. One step from $(x_0, p_0)$ (and $R_0$) solves for the $n + N + m$ unknowns
$(\\Delta x, \\Delta p, \\lambda)$, with $x_1 = x_0 + \\Delta x$, $p_1 = p_0 + \\Delta p$,
$x_{1/2} = x_0 + \\tfrac12\\Delta x$, $p_{1/2} = p_0 + \\tfrac12\\Delta p$:

$$\\Delta x = h\\,u_x,\\qquad
\\Delta p = h\\big(-\\bar\\nabla_x H,\\ \\mathrm{ad}^*_{u_\\xi}\\pi_{1/2}\\big) + \\tilde\\mu^T\\lambda,\\qquad
\\mu(x_1)\\big(K(x_1)p_1 - Y(x_1)\\big) = 0,$$

then $R_1 = R_0\\tau(h u_\\xi)$ ($\\tau(h u_\\xi)R_0$ for `reconstruction="right"`), where
$(\\bar\\nabla_x H, u)$ is a discrete gradient of H:

- with $\\bar K = \\tfrac12\\big(K(x_0) + K(x_1)\\big)$, $\\bar{\\mathbb{G}} = \\tfrac12\\big(\\mathbb{G}(x_0) +
  \\mathbb{G}(x_1)\\big)$ and $g(x) = \\tfrac14\\big(p_0^TK(x)p_0 + p_1^TK(x)p_1\\big) + V(x)$, the product
  rule gives exactly $H(x_1, p_1) - H(x_0, p_0) = g(x_1) - g(x_0) + (\\bar K p_{1/2})\\cdot\\Delta p$
  (the cross terms of $\\bar K$ cancel by symmetry);
- $a = -\\tfrac12\\partial_x\\big(l(x_{1/2}, \\bar Kp_0) + l(x_{1/2}, \\bar Kp_1)\\big)$ is $\\nabla g(x_{1/2})$
  up to $O(h^2)$ (as $\\partial_x(p^TKp) = -w^T(\\partial_x\\mathbb{G})w$, $w = Kp$; no metric at $x_{1/2}$);
- Gonzalez's correction, in the metric $(W, \\kappa^2\\bar K)$ on $(\\Delta x, \\Delta p)$,
  $W = \\bar{\\mathbb{G}}_{xx}$, $\\kappa$ = `KAPPA` = 1 time unit:
  $\\bar\\nabla_x H = a + c\\,W\\Delta x$, $u = \\bar K p_{1/2} + c\\,\\kappa^2\\bar K\\Delta p$, with
  $c = R/D$, $R = g(x_1) - g(x_0) - a\\cdot\\Delta x$ and
  $D = \\Delta x^TW\\Delta x + \\kappa^2\\Delta p^T\\bar K\\Delta p$, so that
  $\\bar\\nabla_x H\\cdot\\Delta x + u\\cdot\\Delta p = H_1 - H_0$ exactly. $R = O(h^3)$, $D \\sim h^2$:
  $c = O(h)$ and the correction is $O(h^2)$, which keeps the order. (Near an equilibrium,
  $D < \\delta = \\theta^2h^2(|g_0| + |g_1|)$, $\\theta$ = `THETA` = 1e-3, c is faded out as
  $RD/(D^2 + \\delta^2)$: see "Rounding" below.);
- $\\tilde\\mu = \\mu_{1/2} - \\frac{(\\mu_{1/2}d)(d^T\\bar{\\mathbb{G}})}{d^T\\bar{\\mathbb{G}}d}$,
  $d = u - Y(x_{1/2})$, $\\mu_{1/2} = \\mu(x_{1/2})$ (the quotient set to 0 where $d = 0$): the
  constraint one-forms at the midpoint, corrected so that $\\tilde\\mu d = 0$ exactly. Since the
  constraints hold at both nodes, $\\mu_{1/2}d = O(h^2)$: the correction is $O(h^2)$ and keeps the
  order.

**Energy.** With the step equations, $\\Delta H = \\bar\\nabla_x H\\cdot\\Delta x + u\\cdot\\Delta p =
h\\,u_\\xi\\cdot\\mathrm{ad}^*_{u_\\xi}\\pi_{1/2} + u\\cdot\\tilde\\mu^T\\lambda = (\\tilde\\mu u)\\cdot\\lambda$,
because $\\langle\\mathrm{ad}^*_\\xi\\pi, \\xi\\rangle =
\\langle\\pi, [\\xi, \\xi]\\rangle = 0$. With linear constraints ($Y = 0$, $d = u$) this is zero:
the energy is conserved to round-off, for any metric $\\mathbb{G}(x)$ and potential $V(x)$. With
affine constraints it is $\\Delta H = (\\tilde\\mu Y_{1/2})\\cdot\\lambda$ (λ is an impulse), the
discrete counterpart of $\\dot H = \\lambda\\cdot\\mu Y$ (the constraint forces do work): nothing
is claimed.

**Forces** (:mod:`gnipy.forcing`). A force $F(b, v, u, t)$ adds its impulse by the midpoint rule,
$f^- + f^+ = hF(b_{1/2}, z/h, u, t + \\tfrac h2)$ with z the step's increment ($\\Delta x$, and
$\\sigma = hu_\\xi$ on the group; :func:`gnipy.forcing.discrete_forces`), to $\\Delta p$. The balance
above becomes $H_1 - H_0 = (f^- + f^+)\\cdot u + (\\tilde\\mu u)\\cdot\\lambda$: with linear constraints
the energy changes by exactly the discrete work of the force, $(f^- + f^+)\\cdot z/h$ (to round-off;
tested), the discrete counterpart of $\\dot H = F\\cdot v$. The step stays symmetric (the midpoint
rule is), hence of order 2.

**Symmetry.** Every quantity is a function of the midpoints, symmetric in the two nodes, or odd in
$(\\Delta x, \\Delta p)$ together with h: exchanging the nodes and $h \\to -h$ maps the equations
to themselves with the same λ (and $\\tilde\\mu$ is even in d). The constraint is imposed at the
new node, and the old one satisfies it, so the step with $-h$ from the end returns to the start:
the method is symmetric with $\\sigma$ = identity, hence of even order: 2.
On the group, $\\tau(-\\sigma) = \\tau(\\sigma)^{-1}$ (Cayley and exp) undoes the reconstruction.

**Why this discrete gradient** (rather than Gonzalez's on $z = (x, p)$ with $\\nabla H(z_{1/2})$):
the kinetic part is split exactly by the product rule, so with a constant metric and V = 0 (most of
the zoo) g does not depend on x, $R = 0$ exactly and the step is a midpoint rule with no rounding
noise from the quotient; the metric of the quotient is the system's, so no length is added to a
momentum and the scheme is invariant under linear changes of the coordinates x; the group part is
the Lie–Poisson midpoint $h\\,\\mathrm{ad}^*_{u_\\xi}\\pi_{1/2}$, orthogonal to $u_\\xi$ exactly.

**Rounding.** $R$ is a difference of terms of the size of $|g|$, so it carries a rounding error
$\\rho \\approx \\varepsilon|g|$ whatever its true size, and the quotient adds a force noise
$\\rho|W\\Delta x|/D$ to a step (the price of conserving the computed energy to its last bit). The
$\\Delta p$ part of D keeps it bounded where x alone stops (a turning point of an oscillation: with
$\\kappa = h$ instead of 1, the round trip $\\Phi_{-h}\\circ\\Phi_h$ of such a step was off by 130ε on
the test rotor, against 5ε now); near an equilibrium, where both $\\Delta x$ and $\\Delta p$ vanish,
the fade keeps the noise below about $\\varepsilon|p|/\\theta$, at the cost of an energy error of at
most $|R| = O(\\theta^3h^3)$ in such a step.

**Where it does not apply.** Systems that depend on the orientation
(`depends_on_orientation=True`, paper §9: Veselova, the Chaplygin sphere and top): H then depends
on R and a discrete gradient on the group is needed; :meth:`DiscreteGradient.check` raises
:class:`~gnipy.MethodError` (use `gni-trapezoid`, `gni-midpoint` or `dla`). Affine constraints
are integrated (order 2, symmetric, constraints exact) but the energy is not conserved (by the
motion either).

**Solve.** Newton's method (:func:`~gnipy.integrators.base.newton`) on the $n + N + m$ unknowns,
from a Taylor step of the continuous motion whose multiplier comes from the derivative of the
constraint along it (about 3 evaluations of the residual per step on the zoo, against 6–7 from
$\\lambda = 0$). The constraint is imposed at the new node as it is stored (the compensated sums
below), so it holds there to round-off even after many turns of an angle.

**Round-off.** The unknowns are increments; x and p are summed with compensation
(:func:`~gnipy.spaces.compensated_add`); Newton stops at its round-off floor
(:func:`~gnipy.integrators.base.newton`), so that the energy error of a step is rounding with no
bias and grows like a random walk. Derivatives (`jax.grad` through :func:`gnipy.simulate`) come
from the implicit function theorem (:func:`~gnipy.integrators.base.solve_step`).

**Not conserved: the momenta of symmetries.** The scheme is not variational, so a cyclic
coordinate's momentum is not kept: Gonzalez's correction acts along $\\bar{\\mathbb{G}}\\Delta x$,
which moves it where the metric couples that coordinate to the others. Measured on the gauge
models (h = 0.01): $p_w$ drifts linearly, 8.6e-4 (contact-oscillator-gauge) and 5.5e-3
(nonholonomic-particle-gauge) over $10^5$ steps, where the GNI keeps it to 4e-16 (the methods guide).
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..errors import MethodError
from ..forcing import discrete_forces
from ..linalg import solve_spd
from ..spaces import Point, compensated_add
from .base import Integrator, solve_step

__all__ = ["DiscreteGradient", "DiscreteGradientState"]


class DiscreteGradientState(NamedTuple):
    """State at node k: the configuration (q, or `Point(x, R)`), the momentum $p_k$ (on the
    constraints), and the rounding errors of x and p (compensated summation)."""

    b: Any
    p: jax.Array
    x_err: jax.Array
    p_err: jax.Array


#: The fade of the discrete gradient's quotient: below D ≈ θ²h²(|g₀| + |g₁|) its correction is faded
#: out (module docstring, "Rounding").
THETA = 1e-3
#: The time scale that weighs Δp against Δx in the quotient's metric (module docstring).
KAPPA = 1.0


def _safe_quotient(num, den):
    """num/den, and 0 where den = 0 (differentiable: no NaN from the unused branch)."""
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), jnp.zeros_like(num))


def _inv_metric(G, *ps):
    """$\\mathbb{G}^{-1}p$ for each p, by one solve."""
    out = solve_spd(G, jnp.stack(ps, axis=1))
    return [out[:, i] for i in range(len(ps))]


def _first_guess(system, b0, p0, k00, G0, V0, h):
    """The first guess of a step, and the magnitudes of the terms of its residual (Newton's
    round-off floor): `(guess, scale)`, with $k_{00} = \\mathbb{G}(b_0)^{-1}p_0$."""
    group, n, N = system.group, system.n, system.dim
    x0 = system.space.coordinates(b0)
    m = system.mu(b0).shape[0]

    def at(x):  # the base point with coordinates x (R is not used by a reduced system)
        return x if group is None else Point(x, b0.R)

    # a Taylor step of the continuous motion, with the multiplier from the derivative of the
    # constraint along it, d/dt μ(Kp − Y) = 0: Cλ = −D_v(μ(Kp₀ − Y)) − μK f₀, C = μKμᵀ
    f0 = jax.grad(lambda y: system.L(at(y), k00))(x0)  # −∂H/∂x = ∂l/∂x at v = Kp
    if group is not None:
        f0 = jnp.concatenate([f0, group.ad_star(k00[n:], p0[n:])])
    if system.force is not None:
        f0 = f0 + system.external_force(b0, k00, system.drive.t + 0.5 * h)

    def along(x):
        (kp,) = _inv_metric(system.metric(at(x)), p0)
        return kp, system.mu(at(x)) @ (kp - system.Y(at(x)))

    Jk, Jc = jax.jacfwd(along)(x0)
    dk, dc = Jk @ k00[:n], Jc @ k00[:n]
    mu0 = system.mu(b0)
    k_mu = solve_spd(G0, mu0.T)
    lam_c = solve_spd(mu0 @ k_mu, -dc - k_mu.T @ f0)
    p_dot = f0 + mu0.T @ lam_c
    x_ddot = dk[:n] + solve_spd(G0, p_dot)[:n]
    guess = jnp.concatenate([h * k00[:n] + 0.5 * h * h * x_ddot, h * p_dot, h * lam_c])
    # the magnitudes of the terms of F (for Newton's round-off floor): the position increment,
    # the momentum with the force and the quotient of the discrete gradient (whose numerator has
    # terms of the size of the energy), and the constraint's μ(Kp − Y) with its change over one
    # rounding of the new node's coordinates: x₁ = x₀ + Δx moves in steps of ulp(x₀), so where
    # |x₀| is large (a heading after thousands of turns) the constraint at x₁ cannot be met more
    # closely than eps·|∂(μ(Kp − Y))/∂x|·|x₀| (measured: a false failure at residual 1.6e-12 with
    # heading 8917, vertical disk, step 891,692)
    dx_g, dp_g = guess[:n], guess[n:n + N]
    D_g = dx_g @ G0[:n, :n] @ dx_g + KAPPA**2 * (dp_g @ solve_spd(G0, dp_g))
    energy_size = 0.5 * jnp.abs(p0 @ k00) + jnp.abs(V0)
    D_g = D_g + (THETA * h) ** 2 * energy_size  # the fade bounds the quotient
    quotient = jnp.abs(h) * energy_size * _safe_quotient(jnp.max(jnp.abs(G0[:n, :n] @ dx_g), initial=0.0), D_g)
    Y0 = system.Y(b0)
    scale = jnp.concatenate([
        jnp.full(n, jnp.abs(h) * jnp.max(jnp.abs(k00))),
        jnp.full(N, jnp.max(jnp.abs(p0)) + jnp.abs(h) * jnp.max(jnp.abs(f0)) + quotient),
        jnp.full(m, jnp.max(jnp.abs(mu0)) * (jnp.max(jnp.abs(k00)) + jnp.max(jnp.abs(Y0)))
                 + jnp.max(jnp.abs(Jc) @ jnp.abs(x0), initial=0.0)),
    ])
    return guess, scale


class DiscreteGradient(Integrator):
    """Energy-conserving discrete-gradient method with the constraints exact at the nodes.

    The scheme and its properties are in the module docstring
    (:mod:`gnipy.integrators.discrete_gradient`): order 2, symmetric ($\\Phi_{-h} = \\Phi_h^{-1}$,
    σ = identity), the energy conserved to round-off for linear constraints, any metric
    $\\mathbb{G}(x)$ and potential $V(x)$, on $\\mathbb{R}^n$ and on reduced systems on
    $\\mathbb{R}^n \\times G$. Reports $(b_k, v_k = \\mathbb{G}^{-1}p_k, p_k)$, on the constraints.

    Arguments:
        root_finder: optimistix root finder (default: the built-in Newton, which stops at round-off).
        max_steps: Newton iteration cap.

    Raises:
        MethodError: from :meth:`check`, for systems that depend on the orientation.
    """

    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)
    name: ClassVar[str] = "discrete-gradient"
    order: ClassVar[int | None] = 2
    symmetric: ClassVar[bool] = True
    conserves_energy: ClassVar[bool] = True
    can_change_step: ClassVar[bool] = True  # the state (b, p) does not depend on h

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` for a system whose functions depend on the orientation R."""
        if system.depends_on_orientation:
            raise MethodError(
                f"method {self.name!r} needs a Hamiltonian that does not depend on the orientation R; "
                f"{system.name!r} depends on it (depends_on_orientation=True, paper §9), which would need "
                "a discrete gradient on the group: use gni-trapezoid, gni-midpoint or dla"
            )

    def init(self, system, q0, v0, h):
        """$(b_0, p_0 = \\mathbb{G}(b_0)v_0)$ and zero rounding errors."""
        x = system.space.coordinates(q0)
        p = system.momentum(q0, v0)
        return DiscreteGradientState(q0, p, jnp.zeros_like(x), jnp.zeros_like(p))

    def step(self, system, state, h):
        """One step: Newton on $(\\Delta x, \\Delta p, \\lambda)$; returns `(state, StepInfo)`."""
        b0, p0, x_err, p_err = state
        space = system.space
        group = system.group
        n, N = system.n, system.dim
        x0 = space.coordinates(b0)

        def at(x):  # the base point with coordinates x (R is not used by a reduced system)
            return x if group is None else Point(x, b0.R)

        G0 = system.metric(b0)
        V0 = system.potential(b0)
        (k00,) = _inv_metric(G0, p0)
        forced = system.force is not None

        def _increment(dx, u):  # the step's unknowns z of the space (Δx, and σ = h u_ξ on the group)
            return dx if group is None else jnp.concatenate([dx, h * u[n:]])

        def parts(w):
            dx, dp, lam = w[:n], w[n:n + N], w[n + N:]
            # the new node as it will be stored (the compensated sums): the constraint then holds there
            # to round-off even where |x| is large (e.g. a heading angle after many turns)
            x1, _ = compensated_add(x0, dx, x_err)
            p1, _ = compensated_add(p0, dp, p_err)
            xm, pm = x0 + 0.5 * dx, p0 + 0.5 * dp
            b1, bm = at(x1), at(xm)
            G1 = system.metric(b1)
            k01, k0d = _inv_metric(G0, p1, dp)
            k10, k11, k1d = _inv_metric(G1, p0, p1, dp)
            w0, w1 = 0.5 * (k00 + k10), 0.5 * (k01 + k11)  # K̄p₀, K̄p₁ with K̄ = ½(K(x₀) + K(x₁))
            Kdp = 0.5 * (k0d + k1d)  # K̄Δp
            # g(x) = ¼(p₀ᵀK(x)p₀ + p₁ᵀK(x)p₁) + V(x) at the nodes, so that H₁ − H₀ = g₁ − g₀ + (K̄p_{1/2})·Δp
            # exactly; a ≈ ∇g(x_{1/2}) from ∂(pᵀKp)/∂x = −wᵀ(∂G/∂x)w, w = Kp, here with w = K̄p
            g0 = 0.25 * (p0 @ k00 + p1 @ k01) + V0
            g1 = 0.25 * (p0 @ k10 + p1 @ k11) + system.potential(b1)
            a = -0.5 * jax.grad(lambda y: system.L(at(y), w0) + system.L(at(y), w1))(xm)
            # Gonzalez's quotient in the metric (Ḡₓₓ, κ²K̄) on (Δx, Δp), faded out below D ≈ δ (near
            # equilibria, where it would be rounding noise divided by a vanishing D)
            G_bar = 0.5 * (G0 + G1)
            Wdx = G_bar[:n, :n] @ dx
            D = dx @ Wdx + KAPPA**2 * (dp @ Kdp)
            delta = (THETA * h) ** 2 * (jnp.abs(g0) + jnp.abs(g1))
            c = _safe_quotient((g1 - g0 - a @ dx) * D, D * D + delta * delta)
            grad_bar = a + c * Wdx  # ∂̄H/∂x
            u = 0.5 * (w0 + w1) + c * KAPPA**2 * Kdp  # ∂̄H/∂p = K̄p_{1/2} + c κ²K̄Δp: the step velocity
            force = -grad_bar
            if group is not None:
                force = jnp.concatenate([force, group.ad_star(u[n:], pm[n:])])
            mu_m = system.mu(bm)
            d = u - system.Y(bm)
            Gd = G_bar @ d
            mu_tilde = mu_m - jnp.outer(_safe_quotient(mu_m @ d, d @ Gd), Gd)  # μ̃ d = 0
            if forced:  # the impulse of the midpoint rule, f⁻ + f⁺ = hF(b_{1/2}, z/h): it does the work u·(f⁻ + f⁺)
                f_minus, f_plus = discrete_forces(system, b0, _increment(dx, u), h, "midpoint")
                momentum = dp - h * force - (f_minus + f_plus) - mu_tilde.T @ lam
            else:
                momentum = dp - h * force - mu_tilde.T @ lam
            residual = jnp.concatenate([
                dx - h * u[:n],
                momentum,
                system.mu(b1) @ (k11 - system.Y(b1)),
            ])
            return residual, u

        def residual(w):
            return parts(w)[0]

        guess, scale = _first_guess(system, b0, p0, k00, G0, V0, h)
        w, info = solve_step(residual, guess, explicit=False, solver=self.root_finder, max_steps=self.max_steps,
                             floor_scale=scale)
        dx, dp = w[:n], w[n:n + N]
        if group is None:
            b1, x_err = space.advance_compensated(b0, x_err, dx)
        else:
            _, u = parts(w)
            b1, x_err = space.advance_compensated(b0, x_err, jnp.concatenate([dx, h * u[n:]]))
        p1, p_err = compensated_add(p0, dp, p_err)
        return DiscreteGradientState(b1, p1, x_err, p_err), info

    def observe(self, system, state, h):
        """$(b_k,\\ \\mathbb{G}(b_k)^{-1}p_k,\\ p_k)$."""
        b, p, _, _ = state
        return b, system.velocity(b, p), p
