"""The checks behind :meth:`gnipy.System.check`, :meth:`~gnipy.System.check_mechanical`,
:meth:`~gnipy.System.has_constant_metric` and :meth:`~gnipy.System.lagrangian_depends_on`: the
compiled evaluations of a system's values and derivatives at sample points around $b_0$ (the system
is an argument, so one compilation serves every system of a shape), and the tests of those values
(host side), each raising an :class:`~gnipy.InputError` that names the function at fault.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .errors import InputError
from .inputs import format_scientific


def check_metric(G, tol: float) -> None:
    """The metric $\\mathbb{G}(b_0)$ is finite, symmetric and positive definite (to `tol`)."""
    if not np.all(np.isfinite(G)):
        raise InputError("lagrangian: the metric d²l/dv² is not finite at q0")
    if np.max(np.abs(G - G.T)) > tol * max(1.0, np.max(np.abs(G))):
        raise InputError("lagrangian: the metric d²l/dv² is not symmetric at q0")
    eig = np.linalg.eigvalsh(G)
    if eig[0] <= tol * max(1.0, eig[-1]):
        raise InputError(
            "lagrangian: the metric d²l/dv² is not positive definite at q0 "
            f"(smallest eigenvalue {format_scientific(eig[0])})"
        )


def check_constraint_forms(mu, N: int):
    """The constraint one-forms $\\mu(b_0)$: shape (m, N) with 0 < m < N, finite, full row rank;
    returned as given."""
    if mu.ndim != 2 or mu.shape[1] != N:
        raise InputError(f"constraints: mu(q) must have shape (m, {N}), got {mu.shape}")
    if not np.all(np.isfinite(mu)):
        raise InputError("constraints: mu(q0) is not finite")
    m = mu.shape[0]
    if m == 0:
        raise InputError(
            f"constraints: mu(q0) has no rows (shape {mu.shape}); gnipy integrates constrained systems, give "
            "at least one constraint"
        )
    if m >= N:
        raise InputError(f"constraints: {m} constraints on a {N}-dimensional velocity space leave no motion")
    sv = np.linalg.svd(mu, compute_uv=False)
    if sv[-1] <= 1e-10 * max(1.0, sv[0]):
        raise InputError(
            f"constraints: mu(q0) is rank deficient (rank {int(np.sum(sv > 1e-10 * max(1.0, sv[0])))} "
            f"< {m} constraints; smallest singular value {format_scientific(sv[-1])})"
        )
    return mu


def check_affine_field(Y, N: int):
    """The affine field $Y(b_0)$: shape (N,), finite; returned as given."""
    if Y.shape != (N,):
        raise InputError(f"affine: Y(q) must have shape ({N},), got {Y.shape}")
    if not np.all(np.isfinite(Y)):
        raise InputError("affine: Y(q0) is not finite")
    return Y


def check_mechanical_type(vals: dict, samples: int, *, tol: float) -> None:
    """`l(b, v) = ½vᵀG(b)v − V(b)` at the sample points of :func:`validation_values` (`vals`, with
    the velocities `vs`): finite, no linear term in v, no mismatch with its quadratic part."""
    for i in range(samples):
        lv, G, V, lin, v = vals["lv"][i], vals["Gs"][i], vals["Vs"][i], vals["lin"][i], vals["vs"][i]
        if not np.isfinite(lv):
            raise InputError("lagrangian: l(q, v) is not finite near q0")
        quad = 0.5 * v @ G @ v - V
        scale = max(1.0, abs(lv), abs(quad))
        if np.max(np.abs(lin)) > tol * scale or abs(lv - quad) > tol * scale:
            raise InputError(
                "lagrangian: not of mechanical type ½ vᵀG(q)v − V(q) "
                f"(linear term {format_scientific(np.max(np.abs(lin)))}, "
                f"mismatch with the quadratic part {format_scientific(abs(lv - quad))})"
            )


@jit
def validation_values(system, b0, ws, vs):
    """What :meth:`gnipy.System.check` and :meth:`~gnipy.System.check_mechanical` test: l, the metric
    G and the potential at the sample points $(b_0 \\cdot w_i, v_i)$ and the linear term of l in v
    there (`lv`, `Gs`, `Vs`, `lin`), and G, μ and Y at $b_0$ (`G`, `mu`, `Y`)."""
    def at(w, v):
        b = system.space.move(b0, w)
        return dict(
            lv=system.L(b, v),
            Gs=system.metric(b),
            Vs=system.potential(b),
            lin=jax.grad(lambda u: system.L(b, u))(jnp.zeros_like(v)),
        )

    out = jax.vmap(at)(ws, vs)
    out.update(G=system.metric(b0), mu=system.mu(b0), Y=system.Y(b0))
    return out


@jit
def metric_derivatives(system, b0, ws):
    """The derivative of the metric G in the base point's local coordinates at each $b_0 \\cdot w_i$
    (exact zeros where G is constant)."""
    def one(w):
        b = system.space.move(b0, w)
        return jax.jacfwd(lambda u: system.metric(system.space.move(b, u)))(jnp.zeros(system.dim))

    return jax.vmap(one)(ws)


@jit
def lagrangian_derivatives(system, b0, ws, vs):
    """$\\partial l/\\partial w$ at $(b_0 \\cdot w_i, v_i)$, w the base point's local coordinates
    ($(x, \\xi)$ on $\\mathbb{R}^n \\times G$): exact zeros where l does not depend on them."""
    def one(w, v):
        b = system.space.move(b0, w)
        return jax.grad(lambda u: system.L(system.space.move(b, u), v))(jnp.zeros(system.dim))

    return jax.vmap(one)(ws, vs)
