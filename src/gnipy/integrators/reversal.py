r"""Runs backward in time: a symmetric method's exact inverse, for `simulate` with h < 0.

A symmetric method satisfies $\Phi_h^{-1} = \sigma\circ\Phi_{-h}\circ\sigma$ with an involution
$\sigma$ of its state (:meth:`~gnipy.integrators.base.Integrator.reverse`): the identity for states
$(q, v)$ or $(q, p)$; for the GNI's $(b, p^+)$ the reflection (Comb) $p^+ \mapsto p^- = \bar p - (p^+ - \bar p)$,
which turns the hidden impulse $\approx -\tfrac h2\mu^T\lambda$ of a step of h into that of a step of
$-h$. (Stepping the GNI back with $-h$ from $(b, p^+)$ without it misses the start by $O(h^2)$
per step, ~1e-4 over a short run; with it, a run of N steps forward and N back returns to the
start to round-off.) Forced systems (:mod:`gnipy.forcing`) run forward only: :class:`Reversed`
refuses them (:meth:`Reversed.check`), and a step of a traced h that turns out negative fails.
States keep the orientation of forward runs, so a backward run can continue
a forward one (`state0=sol.final_state`) and vice versa.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from .base import Integrator, MethodError

__all__ = ["Reversed", "backward"]


class Reversed(Integrator):
    """The exact inverse of a symmetric `method`: each step with h < 0 is $\\sigma\\circ\\Phi_h\\circ\\sigma$.

    Arguments:
        method: the symmetric integrator.
        dynamic: decide by the sign of h at run time (for a traced h, under `jax.jit`): steps with
            h > 0 are then the method's own.
    """

    method: Integrator
    dynamic: bool = eqx.field(static=True, default=False)

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.method.name

    @property
    def order(self):  # type: ignore[override]
        return self.method.order

    @property
    def symmetric(self) -> bool:  # type: ignore[override]
        return True

    @property
    def can_change_step(self) -> bool:  # type: ignore[override]
        return self.method.can_change_step

    def _orient(self, system, state, h):
        flipped = self.method.reverse(system, state)
        if not self.dynamic:
            return flipped
        back = h < 0
        return jax.tree_util.tree_map(lambda a, b: jnp.where(back, b, a), state, flipped)

    def check(self, system, q0) -> None:
        """The method's check; and a forced system is refused for a run backward (its force is not
        reversible in general: :func:`gnipy.simulate` refuses h < 0 for it, this catches the other ways in)."""
        if system.force is not None and not self.dynamic:
            raise MethodError(
                f"method {self.method.name!r} runs backward here (h < 0), and {system.name!r} has a force "
                "F(q, v, u, t): forced systems run forward in time only (h > 0)"
            )
        self.method.check(system, q0)

    def prepare(self, system, q0):
        return dataclasses.replace(self, method=self.method.prepare(system, q0))

    def init(self, system, q0, v0, h):
        """The method's start for a step of |h| (states keep the forward orientation)."""
        return self.method.init(system, q0, v0, jnp.abs(h))

    def step(self, system, state, h):
        state, info = self.method.step(system, self._orient(system, state, h), h)
        if system.force is not None:  # a traced h that turns out negative: the step fails (check's reason)
            info = info._replace(ok=info.ok & (h > 0))
        return self._orient(system, state, h), info

    def change_step(self, system, state, h_old, h_new):
        return self.method.change_step(system, state, jnp.abs(h_old), jnp.abs(h_new))

    def symmetric_on(self, system) -> bool:
        return self.method.symmetric_on(system)

    def reverse(self, system, state):
        return self.method.reverse(system, state)

    def observe(self, system, state, h):
        return self.method.observe(system, state, jnp.abs(h))

    def hidden_momentum(self, system, state, h):
        return self.method.hidden_momentum(system, state, jnp.abs(h))


def backward(method, h, system=None):
    """The method that `simulate` runs for step `h` on `system`: a symmetric method's exact inverse
    when h < 0 (or when h is traced, decided at run time); otherwise the method itself (a method
    that is not symmetric there runs its own formula at h < 0, an approximation of the backward
    flow but not the inverse of its forward steps)."""
    if not isinstance(method, Integrator) or isinstance(method, Reversed):
        return method
    if not (method.symmetric if system is None else method.symmetric_on(system)):
        return method
    if isinstance(h, jax.core.Tracer):
        return Reversed(method, dynamic=True)
    return Reversed(method) if float(h) < 0 else method
