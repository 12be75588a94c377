"""The integrator interface: a small object with an initial state and a one-step map.

Modelled on diffrax's solvers: `init(system, q0, v0, h) -> state`,
`step(system, state, h) -> (state, StepInfo)`, and `observe(system, state, h) -> (b, v, p)`, the
base point (q on R^n, `Point(x, R)` on R^n x G), velocity and momentum that a solution reports at
the node held by `state`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

__all__ = ["Integrator", "StepInfo", "MethodError", "solve_step", "default_root_finder"]


class MethodError(ValueError):
    """A method cannot be applied to a system (the message says why)."""


class StepInfo(NamedTuple):
    """What one step reports: whether it succeeded, Newton iterations, the final residual."""

    ok: jax.Array
    iterations: jax.Array
    residual: jax.Array


def default_root_finder():
    """Newton's method with tolerances near round-off (the GNI's implicit steps)."""
    return optx.Newton(rtol=1e-12, atol=1e-12)


def solve_step(F: Callable, guess, *, explicit: bool, solver=None, max_steps: int = 50):
    """Solve `F(z) = 0` for the step unknowns.

    Arguments:
        F: residual function of the unknowns.
        guess: the first guess.
        explicit: `F` is affine in `z`: one Newton step from `guess` is the exact solution, so no
            iteration and no convergence test are needed (the fast path of explicit schemes).
        solver: an optimistix root finder for the implicit case (default Newton, tol 1e-12).
        max_steps: iteration cap of the implicit case.

    Returns:
        `(z, StepInfo)`.
    """
    if explicit:
        J = jax.jacfwd(F)(guess)
        z = guess - jnp.linalg.solve(J, F(guess))
        ok = jnp.all(jnp.isfinite(z))
        return z, StepInfo(ok, jnp.asarray(1, dtype=jnp.int32), jnp.asarray(0.0, dtype=z.dtype))
    solver = default_root_finder() if solver is None else solver
    # The Cauchy test of optx.Newton asks |F| < atol absolutely, but F has a round-off floor of
    # about eps·|dF/dz|·|z| (e.g. G(z - q)/h), which passes atol once |z|/h is large, and the solve
    # then never terminates. Dividing F by that scale leaves the Newton iterates unchanged and
    # makes the f-space test relative; the y-space test still sets the accuracy.
    scale = jax.lax.stop_gradient(
        jnp.maximum(1.0, jnp.max(jnp.abs(jax.jacfwd(F)(guess))) * jnp.max(jnp.abs(guess)))
    )
    sol = optx.root_find(lambda y, _: F(y) / scale, solver, guess, throw=False, max_steps=max_steps)
    z = sol.value
    residual = jnp.max(jnp.abs(F(z)))
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(z)) & jnp.isfinite(residual)
    return z, StepInfo(ok, jnp.asarray(sol.stats["num_steps"], dtype=jnp.int32), residual)


class Integrator(eqx.Module):
    """Base class of all one-step methods.

    Class attributes: `name` (the CLI name) and `order` (the expected global order, or None).
    """

    name: ClassVar[str] = "integrator"
    order: ClassVar[int | None] = None

    def check(self, system, q0) -> None:
        """Raise :class:`MethodError` if the method cannot integrate `system` (host side)."""

    def prepare(self, system, q0) -> "Integrator":
        """Return a copy configured for `system` (host side; e.g. choosing the explicit fast path)."""
        return self

    def init(self, system, q0, v0, h):
        """The state at the first node from a configuration and a velocity on the constraints."""
        raise NotImplementedError

    def step(self, system, state, h):
        """Advance one step: returns `(state, StepInfo)`."""
        raise NotImplementedError

    def observe(self, system, state, h):
        """The `(b, v, p)` reported at the node that `state` holds (b: the base point)."""
        raise NotImplementedError


def require_constant_metric(method: str, system, q0) -> None:
    """Raise :class:`MethodError` unless the system lives on R^n and its metric is constant."""
    if system.group is not None:
        raise MethodError(
            f"method {method!r} is written for systems on R^n (paper §5); {system.name!r} has a group "
            "part: use a gni-* method"
        )
    if not system.has_constant_metric(q0):
        raise MethodError(
            f"method {method!r} is written for a constant metric M (paper §5); "
            f"the metric of {system.name!r} depends on q: use a gni-* method"
        )
