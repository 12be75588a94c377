r"""Holonomic constraints $\varphi(q) = 0$ beside the nonholonomic ones: the discrete position
multiplier, the affine part on the joint constraints, and the projection onto $\varphi = 0$.

**Continuous equations.** A holonomic constraint $\varphi(q) = 0$ (r components) constrains the
velocity by $d\varphi(q)\,v = 0$ and the acceleration by its derivative; the constraint force
$d\varphi^T\Lambda$ is that of a linear velocity constraint with the rows $d\varphi$. So the
Lagrange–d'Alembert equations of :mod:`gnipy.equations` hold with the rows
$\tilde\mu = (\mu;\ d\varphi)$ (what :meth:`gnipy.System.mu` returns), and a solution that starts
on $\varphi = 0$ with $\tilde\mu(v - Y) = 0$ stays there. A numerical solution of these (index-2)
equations drifts off $\varphi = 0$, slowly; the continuous reference
(:class:`gnipy.reference.ContinuousReference`) projects every saved node back onto $\varphi = 0$ and
onto the velocity constraints (:func:`project_configuration`), which keeps the drift at the
solver's tolerance over any length of run (Hairer–Lubich–Wanner, *Geometric Numerical
Integration*, IV.4, "projection methods").

**Discrete equations.** Constrained discrete mechanics (Marsden–West, Acta Numerica 10 (2001),
§3.5) restricts the discrete Lagrangian to $\varphi = 0$ with a multiplier at each node:

$$D_2L_d(q_{k-1}, q_k) + D_1L_d(q_k, q_{k+1}) = d\varphi(q_k)^T\Lambda_k,\qquad \varphi(q_{k+1}) = 0.$$

In the GNI's one-step form (paper Def. 4.1, 6.1) with $p^-_k = -D_1L_d(q_k, q_{k+1})$ this is

$$FL^-(b_k, z_k) = p^-_k + d\varphi(b_k)^T\Lambda_k, \qquad \varphi(b_{k+1}) = 0,\qquad
  p^+_{k+1} = FL^+(b_k, z_k),$$

N + r equations for the step unknowns $z_k$ and the position multiplier $\Lambda_k$
(:func:`with_position_multiplier`). The reflection (Comb) that gives $p^-_k$ and the reported
$\bar p_k = P^*p^+_k + Q^*\Pi$ use the joint rows $\tilde\mu$: the reported velocity $\bar v_k$
satisfies the nonholonomic constraints and $d\varphi(b_k)\bar v_k = 0$ exactly, and the
$d\varphi^T$ part of the reflected impulse is absorbed by $\Lambda_k$ (any covector
$d\varphi(b_k)^T c$ added to $p^-_k$ changes $\Lambda_k$ and nothing else). Without nonholonomic
constraints this is the Marsden–West constrained discrete Euler–Lagrange equations, whose flow on
$\varphi = 0$ is symplectic; with the trapezoid $L_d$ and a constant metric it is RATTLE
(Andersen 1983; Leimkuhler–Skeel 1994) with the rest start, step for step. The nonholonomic rows
are the GNI's. The choice keeps the GNI's properties: the map is the GNI of the system restricted
to the submanifold $\varphi = 0$, written in the ambient coordinates (the constraint
distribution is $\mathcal D \cap T\{\varphi = 0\}$), so the reflection, the hidden momentum, the
$E^+$ energy theorem and the symmetry of a symmetric $L_d$ carry over. The discrete
Lagrange–d'Alembert method (`dla`) takes the same position multiplier with $\varphi(q_{k+1}) = 0$
in place of the discrete velocity constraint on the rows $d\varphi$.

Which methods keep $\varphi(q_k) = 0$: :data:`HOLONOMIC_METHODS` (the GNI with any discrete
Lagrangian and its compositions; the paper's explicit maps `euler-a`, `euler-b` and `rattle`, which
are the GNI in other variables, with a Newton solve for Λ in their drift; `sgni-*`, whose impulse
acting at both ends of a step covers the rows $d\varphi$ too, with Λ at the start; dla; and the
continuous reference); the others refuse a system with holonomic constraints
(:func:`require_support`): `euler-ab` (its half maps), `shake`, `rat`, `mp` and
`discrete-gradient`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .errors import MethodError
from .linalg import solve, solve_spd

__all__ = ["HOLONOMIC_METHODS", "affine_part", "with_position_multiplier", "position_multiplier_columns",
           "project_configuration",
           "project_state", "require_support", "phi_scale"]

#: The methods that keep holonomic constraints $\varphi(q_k) = 0$ to round-off (and the continuous
#: reference, which projects onto them); compositions of the GNI (`gni-*-s3`, …) too.
HOLONOMIC_METHODS = ("gni-euler-a", "gni-euler-b", "gni-trapezoid", "gni-midpoint", "sgni-trapezoid", "sgni-midpoint",
                     "euler-a", "euler-b", "rattle", "dla", "reference")


def require_support(method, system) -> None:
    """Raise :class:`MethodError` when `system` has holonomic constraints and `method` cannot keep
    them (its class attribute `holonomic` is False)."""
    if system.holonomic is None or getattr(method, "holonomic", False):
        return
    raise MethodError(
        f"method {method.name!r} does not keep holonomic constraints phi(q) = 0 (it would treat d phi as a "
        f"velocity constraint and let phi drift); {system.name!r} has holonomic constraints: use one of "
        f"{', '.join(HOLONOMIC_METHODS)}, or a composition of a gni-* method"
    )


def affine_part(G, mu, dphi, Y):
    r"""The affine field $\tilde Y$ with $\mu\tilde Y = \mu Y$ and $d\varphi\,\tilde Y = 0$: $Y$ minus
    its $\mathbb{G}$-orthogonal correction, $\tilde Y = Y - \mathbb{G}^{-1}\tilde\mu^T(\tilde\mu
    \mathbb{G}^{-1}\tilde\mu^T)^{-1}(0;\ d\varphi Y)$, $\tilde\mu = (\mu; d\varphi)$. The constraints
    $\tilde\mu(v - \tilde Y) = 0$ are then the user's $\mu(v - Y) = 0$ and $d\varphi\,v = 0$."""
    rows = jnp.concatenate([mu, dphi], axis=0)
    X = solve_spd(G, rows.T)
    rhs = jnp.concatenate([jnp.zeros(mu.shape[0], dtype=Y.dtype), dphi @ Y])
    return Y - X @ solve_spd(rows @ X, rhs)


def phi_scale(system, b, rows):
    """The magnitude of the terms of $\\varphi$ at `b` (for the round-off floor of a solve):
    $|d\\varphi|\\max(1, |x|)$."""
    x = system.space.coordinates(b)
    size = jnp.max(jnp.abs(x)) if x.shape[0] else jnp.zeros((), rows.dtype)
    return jnp.max(jnp.abs(rows), initial=0.0) * jnp.maximum(1.0, size)


def with_position_multiplier(system, b, residual, guess, floor_scale):
    r"""The step equations `residual(z) = 0` (N momentum rows, $FL^- - p^-$) joined with the
    holonomic constraints at the end of the step, in the unknowns $w = (z, \Lambda)$:

    $$\text{residual}(z) - d\varphi(b)^T\Lambda = 0, \qquad \varphi(b \oplus z) = 0$$

    ($b\oplus z$ the configuration the step reaches, :meth:`~gnipy.spaces.EuclideanSpace.advance`).

    Returns:
        `(F, w0, scale, rows)`: the residual of w, the first guess `(guess, 0)`, the magnitude of
        the terms of each row (`floor_scale` for the momentum rows, :func:`phi_scale` for φ), for
        :func:`gnipy.integrators.base.solve_step`, and the rows $d\varphi(b)$; the step's z and Λ
        are `w[:N]`, `w[N:]`.
    """
    space = system.space
    rows = system.holonomic_mu(b)
    N, r = guess.shape[0], rows.shape[0]

    def F(w):
        z, lam = w[:N], w[N:]
        return jnp.concatenate([residual(z) - rows.T @ lam, system.phi(space.advance(b, z))])

    scale = jnp.concatenate([jnp.broadcast_to(jnp.asarray(floor_scale, guess.dtype), (N,)),
                             jnp.full((r,), phi_scale(system, b, rows), dtype=guess.dtype)])
    return F, jnp.concatenate([guess, jnp.zeros(r, dtype=guess.dtype)]), scale, rows


def position_multiplier_columns(rows):
    r"""The Jacobian columns of Λ in the residual of :func:`with_position_multiplier`,
    $(-d\varphi(b)^T;\ 0)$: constant over the step's iterations (`tail_columns` of
    :func:`gnipy.integrators.base.newton`)."""
    r = rows.shape[0]
    return jnp.concatenate([-rows.T, jnp.zeros((r, r), dtype=rows.dtype)])


#: The cap on Newton's iterations of the projection onto φ = 0 (from a drift of the solver's
#: tolerance one iteration reaches round-off; from 5% off, five)
PROJECTION_ITERATIONS = 30


def project_configuration(system, b):
    r"""The point of $\varphi = 0$ nearest to `b` in the metric: Newton's iterations
    $b \leftarrow b \ominus \mathbb{G}^{-1}d\varphi^T(d\varphi\,\mathbb{G}^{-1}d\varphi^T)^{-1}\varphi(b)$
    (moving along :meth:`~gnipy.spaces.EuclideanSpace.move`) until the correction stops shrinking
    or is at round-off (at most :data:`PROJECTION_ITERATIONS`). `b` unchanged without holonomic
    constraints."""
    if system.holonomic is None:
        return b
    space = system.space
    eps = jnp.finfo(jnp.float64).eps

    def correction(c):
        rows = system.holonomic_mu(c)
        X = solve_spd(system.metric(c), rows.T)
        return -X @ solve(rows @ X, system.phi(c))

    def cond(carry):
        _, k, size, prev = carry
        return (k < PROJECTION_ITERATIONS) & (size > 4 * eps) & (size < prev)

    def body(carry):
        c, k, size, _ = carry
        w = correction(c)
        scale = jnp.maximum(1.0, jnp.max(jnp.abs(space.coordinates(c)), initial=0.0))
        return space.move(c, w), k + 1, jnp.max(jnp.abs(w)) / scale, size

    big, inf = jnp.asarray(jnp.finfo(jnp.float64).max), jnp.asarray(jnp.inf, jnp.float64)
    b, _, _, _ = jax.lax.while_loop(cond, body, (b, jnp.asarray(0), big, inf))
    return b


def project_state(system, b, v):
    """`(b, v)` projected onto $\\varphi = 0$ (:func:`project_configuration`) and then onto the
    velocity constraints $\\tilde\\mu(v - Y) = 0$ there ($\\mathbb{G}$-orthogonally)."""
    from .projectors import projectors

    b = project_configuration(system, b)
    P, Q = projectors(system.metric(b), system.mu(b))
    return b, P @ v + Q @ system.Y(b)
