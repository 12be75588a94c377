"""The compiled evaluations behind :meth:`gnipy.System.check`, :meth:`~gnipy.System.check_mechanical`,
:meth:`~gnipy.System.has_constant_metric` and :meth:`~gnipy.System.lagrangian_depends_on`: a system's
values and derivatives at sample points around $b_0$ (the system is an argument, so one compilation
serves every system of a shape).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .compilation import jit


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
