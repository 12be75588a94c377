"""The continuous reference: the Lagrange–d'Alembert equations with λ eliminated (DESIGN.md §2).

For $l = \\tfrac12 v^T\\mathbb{G}(q)v - V(q)$ and constraints $\\mu(q)(v - Y(q)) = 0$:

$$\\mathbb{G}\\,\\ddot q = F + \\mu^T\\lambda, \\qquad F = \\partial_q l - (\\partial_q\\partial_v l)\\,\\dot q,$$

and differentiating the constraints along the motion,
$\\mu\\ddot q = \\mu\\,(\\partial_q Y)\\dot q - (\\partial_q\\mu\\cdot\\dot q)(\\dot q - Y) =: c$, so
$\\lambda = C^{-1}(c - \\mu\\mathbb{G}^{-1}F)$ with $C = \\mu\\mathbb{G}^{-1}\\mu^T$ (paper (H) in Lagrangian form).
Integrated with diffrax's 8th-order Dormand–Prince at tolerance ~1e-12.
"""

from __future__ import annotations

from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .solution import Solution, SolverFailure

__all__ = ["ContinuousReference", "lagrange_dalembert_acceleration"]


def lagrange_dalembert_acceleration(system, q, v):
    """The constrained acceleration $\\ddot q$ and the multipliers λ at `(q, v)`."""
    l = system.lagrangian
    G = system.metric(q)
    dl_dq = jax.grad(l, argnums=0)(q, v)
    _, dp = jax.jvp(lambda x: jax.grad(l, argnums=1)(x, v), (q,), (v,))  # (∂q ∂v l) v
    F = dl_dq - dp
    mu, dmu = jax.jvp(system.mu, (q,), (v,))
    Y, dY = jax.jvp(system.Y, (q,), (v,))
    c = mu @ dY - dmu @ (v - Y)
    Ginv_F = jnp.linalg.solve(G, F)
    Ginv_muT = jnp.linalg.solve(G, mu.T)
    lam = jnp.linalg.solve(mu @ Ginv_muT, c - mu @ Ginv_F)
    return Ginv_F + Ginv_muT @ lam, lam


class ContinuousReference(eqx.Module):
    """High-accuracy solution of the continuous equations (the yardstick of convergence tests).

    Arguments:
        rtol, atol: tolerances of the adaptive controller (default 1e-12).
        max_steps: cap on the number of adaptive steps.
    """

    rtol: float = eqx.field(static=True, default=1e-12)
    atol: float = eqx.field(static=True, default=1e-12)
    max_steps: int = eqx.field(static=True, default=1_000_000)
    name: ClassVar[str] = "reference"
    order: ClassVar[int | None] = None

    def solve(self, system, q0, v0, times, *, h=float("nan")) -> Solution:
        """Integrate from `times[0]` and save at `times` (host arrays); returns a Solution."""
        times = np.asarray(times, dtype=np.float64)
        ys, num_steps, ok = _solve(self, system, jnp.asarray(q0), jnp.asarray(v0), jnp.asarray(times))
        meta = dict(system=system.name, method=self.name, h=float(h), coordinates=system.coordinates,
                    params=system.params, start="continuous")
        if not bool(ok):
            raise SolverFailure(
                f"reference: the adaptive solver failed before t = {times[-1]:.6g} (step cap {self.max_steps} "
                "or non-finite values)", step=-1, time=float(times[0]), residual=float("nan"),
            )
        n = system.n
        q, v = ys[:, :n], ys[:, n:]
        p = jax.vmap(system.momentum)(q, v)
        energy = jax.vmap(system.energy)(q, v)
        res = jax.vmap(system.constraint_residual)(q, v)
        its = jnp.asarray([int(num_steps), 0], dtype=jnp.int32)
        return Solution(jnp.asarray(times), q, v, p, energy, res, its, **meta)


@eqx.filter_jit
def _solve(ref, system, q0, v0, times):
    n = q0.shape[0]

    def rhs(t, y, args):
        q, v = y[:n], y[n:]
        a, _ = lagrange_dalembert_acceleration(system, q, v)
        return jnp.concatenate([v, a])

    # Land a step on every save time: Dopri8's dense-output interpolant is far less accurate than
    # its steps (errors ~3e-10 at save points on the contact oscillator with rtol = atol = 1e-12).
    controller = diffrax.PIDController(rtol=ref.rtol, atol=ref.atol)
    if hasattr(diffrax, "ClipStepSizeController"):  # diffrax >= 0.7
        controller = diffrax.ClipStepSizeController(controller, step_ts=times)
    else:
        controller = diffrax.PIDController(rtol=ref.rtol, atol=ref.atol, step_ts=times)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs),
        diffrax.Dopri8(),
        t0=times[0],
        t1=times[-1],
        dt0=None,
        y0=jnp.concatenate([q0, v0]),
        saveat=diffrax.SaveAt(ts=times),
        stepsize_controller=controller,
        max_steps=ref.max_steps,
        throw=False,
    )
    ok = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(sol.ys))
    return sol.ys, sol.stats["num_steps"], ok
