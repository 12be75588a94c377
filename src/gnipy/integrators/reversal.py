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

A method that is not symmetric on the system (:meth:`~gnipy.integrators.base.Integrator.symmetric_on`)
has no such inverse: its formula at $-h$ is another method, whose run back misses the start of the
forward run by $O(h^p)$. :func:`backward` refuses it (:class:`~gnipy.InputError` naming the methods
that are symmetric there); with a traced h, whose sign is known only at run time, it is wrapped in
:class:`ForwardOnly`, whose steps fail when h turns out negative (as a forced system's do).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp

from ..errors import InputError
from .base import Integrator, MethodError

__all__ = ["Reversed", "ForwardOnly", "backward", "symmetric_methods"]


class _Wrapped(Integrator):
    """A method run through a wrapper (:class:`Reversed`, :class:`ForwardOnly`): its name, order,
    preparation, start and settings are the wrapped method's."""

    method: Integrator

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.method.name

    @property
    def order(self):  # type: ignore[override]
        return self.method.order

    @property
    def can_change_step(self) -> bool:  # type: ignore[override]
        return self.method.can_change_step

    @property
    def holonomic(self) -> bool:  # type: ignore[override]
        return self.method.holonomic

    def prepare(self, system, q0):
        return dataclasses.replace(self, method=self.method.prepare(system, q0))

    def memoryless(self):
        return dataclasses.replace(self, method=self.method.memoryless())

    def continue_from(self, system, state):
        return self.method.continue_from(system, state)

    @property
    def start_label(self) -> str:
        return self.method.start_label

    def settings(self) -> dict:
        return self.method.settings()


class Reversed(_Wrapped):
    """The exact inverse of a symmetric `method`: each step with h < 0 is $\\sigma\\circ\\Phi_h\\circ\\sigma$.

    Arguments:
        method: the symmetric integrator.
        dynamic: decide by the sign of h at run time (for a traced h, under `jax.jit`): steps with
            h > 0 are then the method's own.
    """

    method: Integrator
    dynamic: bool = eqx.field(static=True, default=False)

    @property
    def symmetric(self) -> bool:  # type: ignore[override]
        return True

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
        self.method.validate(system, q0)

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


class ForwardOnly(_Wrapped):
    """A method that is not symmetric on the system, run with a traced h (under `jax.jit`): its
    steps are the method's own when h > 0 and fail when h < 0 (:func:`backward`: its formula at
    $-h$ is not the inverse of its steps with h). With `simulate(..., throw=True)` the failed step
    is raised at run time; with `throw=False` the saved nodes from the first step on are NaN."""

    def check(self, system, q0) -> None:
        self.method.validate(system, q0)

    def init(self, system, q0, v0, h):
        return self.method.init(system, q0, v0, h)

    def step(self, system, state, h):
        state, info = self.method.step(system, state, h)
        return state, info._replace(ok=info.ok & (h > 0))

    def change_step(self, system, state, h_old, h_new):
        return self.method.change_step(system, state, h_old, h_new)

    def symmetric_on(self, system) -> bool:
        return self.method.symmetric_on(system)

    def reverse(self, system, state):
        return self.method.reverse(system, state)

    def observe(self, system, state, h):
        return self.method.observe(system, state, h)

    def hidden_momentum(self, system, state, h):
        return self.method.hidden_momentum(system, state, h)


def symmetric_methods(system) -> list[str]:
    """The registered methods (:func:`gnipy.method_names`, less the continuous reference) that are
    symmetric on `system` and apply to it (their `check` passes at its default point): those whose
    run with h < 0 is the exact inverse of a run with h > 0. No runs: `symmetric_on` and `check`
    only (host-side probes, compiled once per system structure)."""
    from ..registry import method_table

    get_method, method_names = method_table()
    b0 = system._default_point()
    out = []
    for name in method_names():
        if name == "reference":
            continue
        m = get_method(name)
        try:
            if not m.symmetric_on(system):
                continue
            m.validate(system, b0)
        except Exception:  # refuses the system (MethodError), or cannot tell (traced parameters)
            continue
        out.append(name)
    return out


def _refusal(method, h, system) -> InputError:
    where = "this system" if system is None else repr(system.name)
    why = (f"h: h = {h!r} runs backward in time, and method {method.name!r} is not symmetric on {where}: its "
           "step with -h is not the inverse of its step with h, so a run backward would not retrace a forward "
           "run (N steps forward and N back miss the start by O(h^p)).")
    if getattr(method, "symmetric", False):
        why += (" It is symmetric in general, but not here: the midpoint rule with the Cayley retraction is "
                "symmetric only where the Lagrangian does not depend on the orientation (System(..., "
                "retraction='exp') makes it symmetric).")
    if system is None:
        return InputError(why + " Pass the system to see which methods are symmetric on it.")
    names = symmetric_methods(system)
    listed = ", ".join(names) if names else "none of the registered methods"
    return InputError(f"{why} Methods symmetric on {where}, whose h < 0 runs their exact inverse: {listed} "
                      "(or the continuous 'reference', or integrate forward with h > 0).")


def backward(method, h, system=None):
    """The method that `simulate` runs for step `h` on `system`.

    - h > 0: the method itself.
    - h < 0: a symmetric method's exact inverse (:class:`Reversed`); a method that is not symmetric
      on `system` (:meth:`~gnipy.integrators.base.Integrator.symmetric_on`; without a system,
      :attr:`~gnipy.integrators.base.Integrator.symmetric`) is refused with an
      :class:`~gnipy.InputError` that starts with `h:` and lists the methods symmetric there
      (:func:`symmetric_methods`): its formula at h < 0 is not the inverse of its steps with h > 0.
    - h traced (under `jax.jit`, sign unknown until run time): a symmetric method as
      `Reversed(method, dynamic=True)`, which decides by the sign in the compiled program; any
      other method, and any method on a forced system (which runs forward only), as
      :class:`ForwardOnly`, whose steps fail at run time if h turns out negative. (A dynamic
      `Reversed` computes the involution before and after every step to select by the sign; on
      the sleigh-steering problem's controlled run, 80 steps with its Jacobian, that made each
      call 2.1 times as long: 1.09 ms against 0.52 ms.)

    Objects that are not :class:`~gnipy.integrators.base.Integrator` (the continuous reference, which
    integrates backward directly) are returned as they are."""
    if not isinstance(method, Integrator) or isinstance(method, (Reversed, ForwardOnly)):
        return method
    traced = isinstance(h, jax.core.Tracer)
    if not traced and float(h) >= 0:
        return method
    symmetric = method.symmetric if system is None else method.symmetric_on(system)
    if traced:
        forced = system is not None and system.force is not None
        return Reversed(method, dynamic=True) if symmetric and not forced else ForwardOnly(method)
    if not symmetric:
        raise _refusal(method, h, system)
    return Reversed(method)
