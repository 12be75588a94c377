r"""Higher-order methods by composing a symmetric method: Yoshida's and Suzuki's order 4, order 6.

A composition $\Psi_h = \Phi_{\gamma_s h}\circ\dots\circ\Phi_{\gamma_1 h}$ of a symmetric method
$\Phi$ of order 2 with palindromic coefficients ($\gamma_i = \gamma_{s+1-i}$, $\sum\gamma_i = 1$) is
symmetric, and with the coefficients below of order 4 or 6 (Hairer–Lubich–Wanner, *Geometric
Numerical Integration*, §II.4 and §V.3).

For the GNI this needs two things beyond calling the step with $\gamma_i h$, because the GNI's
state $(b_k, p^+_k)$ carries a hidden normal impulse $p^+_k - \bar p_k \approx
-\tfrac{h}{2}\mu^T\lambda$ proportional to the step that produced it (docs/conventions.md):

- **impulse rescaling**: before each substep the impulse is scaled to the new step,
  $p^+ \leftarrow \bar p + (\gamma_i/\gamma_{i-1})(p^+ - \bar p)$, the ratio signed (the base
  method's :meth:`~gnipy.integrators.base.Integrator.change_step`);
- **a consistent start**: the run starts with the impulse of the first substep,
  $p^+_0 = \bar p_0 - \tfrac{\gamma_1 h}{2}\mu^T\lambda_0$ (the GNI's `start="consistent"`).

Without them the composed GNI stays of order 2 (its error ~40 times the base method's for the
triple jump); with them Yoshida's and Suzuki's compositions are of order 4 (measured in the tests
and by `gni convergence`). The order-6 schemes applied to the GNI also measure order 4, not 6:
the rescaling is exact only to leading order in h (the impulse left by a step is not exactly
proportional to it; rescaling its remainder by the cube of the ratio does not help either,
measured), so the GNI's compositions are declared of order 4
(:data:`GNI_COMPOSITION_ORDER`). Methods whose state does not depend on the step ($(q, v)$ of
McLachlan–Perlmutter, $(q, p)$ of the discrete-gradient method) compose as they are and reach
order 6 (`"kahanli6-mp"`: errors 4e-11 → 6e-13 when h halves on the rotating-table ball).

A forced system (:mod:`gnipy.forcing`) takes substep i at its own time, $t_k + (\gamma_1 + \dots +
\gamma_{i-1})h$ (:meth:`gnipy.System.shifted`; inputs held over the step keep $u_k$, a signal $u(t)$
is read at the substeps' quadrature nodes): the composition of the forced base method is then of
order 4 with a smooth signal (tested).
"""

from __future__ import annotations

import dataclasses
import math
from typing import ClassVar

import equinox as eqx

from ..errors import MethodError
from .base import Integrator, StepInfo

__all__ = ["Composition", "COMPOSITIONS", "composition_coefficients", "GNI_COMPOSITION_ORDER"]

#: The highest order a composition of the GNI reaches (measured: the order-6 schemes give 4).
GNI_COMPOSITION_ORDER = 4


def _triple_jump(order: int) -> tuple[float, float]:
    """Yoshida's triple jump raising a symmetric method of order `order` by 2: $(\\gamma_1, \\gamma_2)$."""
    r = 2.0 ** (1.0 / (order + 1))
    return 1.0 / (2.0 - r), -r / (2.0 - r)


def _yoshida4():
    g1, g2 = _triple_jump(2)
    return (g1, g2, g1)


def _suzuki4():
    r = 4.0 ** (1.0 / 3.0)
    g = 1.0 / (4.0 - r)
    return (g, g, -r * g, g, g)


def _yoshida6():
    """The triple jump of the order-4 triple jump (9 stages; Yoshida 1990)."""
    a1, a2 = _triple_jump(4)
    inner = _yoshida4()
    return tuple(a * g for a in (a1, a2, a1) for g in inner)


def _kahan_li6():
    """Kahan–Li's 9-stage order-6 composition (Kahan & Li 1997; Hairer–Lubich–Wanner V.3.2), the
    smallest error constant among the 9-stage order-6 schemes."""
    half = (0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
            0.082213596293550800230)
    middle = 1.0 - 2.0 * math.fsum(half)  # 0.79854399093482996340, exact to round-off
    return half + (middle,) + half[::-1]


#: Composition name -> (order reached from a symmetric order-2 method, coefficients, description).
COMPOSITIONS: dict[str, tuple[int, tuple[float, ...], str]] = {
    "yoshida4": (4, _yoshida4(), "Yoshida's triple jump, 3 stages, order 4"),
    "suzuki4": (4, _suzuki4(), "Suzuki's fractal composition, 5 stages, order 4"),
    "yoshida6": (6, _yoshida6(), "the triple jump of the triple jump (Yoshida), 9 stages, order 6"),
    "kahanli6": (6, _kahan_li6(), "Kahan–Li, 9 stages, order 6"),
}


def composition_coefficients(scheme: str) -> tuple[float, ...]:
    """The substep fractions $\\gamma_i$ of a composition scheme (a key of :data:`COMPOSITIONS`)."""
    if scheme not in COMPOSITIONS:
        raise MethodError(f"scheme: unknown composition {scheme!r} (known: {', '.join(COMPOSITIONS)})")
    return COMPOSITIONS[scheme][1]


class Composition(Integrator):
    """A symmetric method composed into a higher-order one (module docstring).

    Arguments:
        base: the symmetric method of order 2 to compose (e.g. `GNI(Midpoint())`; a GNI is started
            consistently, `start="consistent"`, whatever its own setting).
        scheme: `"yoshida4"`, `"suzuki4"`, `"yoshida6"` or `"kahanli6"` (:data:`COMPOSITIONS`).

    Raises:
        MethodError: the base method is not symmetric, not of order 2, or cannot change its step.
    """

    base: Integrator
    scheme: str = eqx.field(static=True, default="yoshida4")
    can_change_step: ClassVar[bool] = True
    symmetric: ClassVar[bool] = True

    def __check_init__(self):
        if self.scheme not in COMPOSITIONS:
            raise MethodError(f"scheme: unknown composition {self.scheme!r} (known: {', '.join(COMPOSITIONS)})")
        if not isinstance(self.base, Integrator):
            raise MethodError(f"base: expected an integrator, got {type(self.base).__name__}")
        if not self.base.symmetric:
            raise MethodError(f"base: {self.base.name} is not symmetric; compositions need a symmetric method")
        if self.base.order != 2:
            raise MethodError(f"base: {self.base.name} has order {self.base.order}; the compositions raise order 2")
        if not self.base.can_change_step:
            raise MethodError(f"base: {self.base.name} cannot rescale its state to another step size")

    @property
    def name(self) -> str:  # type: ignore[override]
        return f"{self.scheme}-{self.base.name}"

    @property
    def order(self) -> int:  # type: ignore[override]
        """4 or 6 (:data:`COMPOSITIONS`); at most 4 for a GNI (module docstring: its impulse
        rescaling is exact to leading order only, and the order-6 schemes measure order 4)."""
        from .gni import GNI

        order = COMPOSITIONS[self.scheme][0]
        return min(order, GNI_COMPOSITION_ORDER) if isinstance(self.base, GNI) else order

    @property
    def coefficients(self) -> tuple[float, ...]:
        """The substep fractions $\\gamma_i$."""
        return COMPOSITIONS[self.scheme][1]

    def _base(self):
        from .gni import GNI

        if isinstance(self.base, GNI) and self.base.start != "consistent":
            return dataclasses.replace(self.base, start="consistent")
        return self.base

    @property
    def holonomic(self) -> bool:  # type: ignore[override]
        """Whether the base method keeps holonomic constraints (then every substep does)."""
        return bool(self.base.holonomic)

    def check(self, system, q0) -> None:
        self.base.validate(system, q0)

    def prepare(self, system, q0):
        return dataclasses.replace(self, base=self._base().prepare(system, q0))

    def memoryless(self):
        return dataclasses.replace(self, base=self.base.memoryless())

    def continue_from(self, system, state):
        return self.base.continue_from(system, state)

    @property
    def start_label(self) -> str:
        """The base method's start (for the GNI, always the consistent one, :meth:`init`)."""
        return self._base().start_label

    def init(self, system, q0, v0, h):
        """The base method's start for the first substep, $\\gamma_1 h$ (a consistent impulse for the GNI)."""
        return self._base().init(system, q0, v0, self.coefficients[0] * h)

    def step(self, system, state, h):
        """The substeps $\\gamma_i h$, the state's impulse rescaled before each; returns the state and
        the combined :class:`StepInfo` (all substeps ok, iterations summed, largest residual)."""
        import jax.numpy as jnp

        base = self._base()
        gammas = self.coefficients
        ok = iterations = residual = None
        for i, g in enumerate(gammas):
            # a forced system's substep i starts at t + (γ_1 + … + γ_{i−1})h (its input: the step's
            # held u_k, or the signal at the substep's times); an unforced system is itself
            sub = system.shifted(math.fsum(gammas[:i]) * h) if i and system.force is not None else system
            if i:
                state = base.change_step(sub, state, gammas[i - 1] * h, g * h)
            state, info = base.step(sub, state, g * h)
            if ok is None:
                ok, iterations, residual = info.ok, info.iterations, info.residual
            else:
                ok, iterations = ok & info.ok, iterations + info.iterations
                residual = jnp.maximum(residual, info.residual)
        # the state leaves with the impulse of the last substep, γ_s h = γ_1 h (palindromic): the
        # next step starts where it should
        return state, StepInfo(ok, iterations, residual)

    def change_step(self, system, state, h_old, h_new):
        """The base method's rescaling between first substeps, $\\gamma_1 h_{old} \\to \\gamma_1 h_{new}$."""
        g = self.coefficients[0]
        return self._base().change_step(system, state, g * h_old, g * h_new)

    def symmetric_on(self, system) -> bool:
        """The base method's (a palindromic composition of a method symmetric on the system is)."""
        return self.base.symmetric_on(system)

    def reverse(self, system, state):
        """The base method's involution (a palindromic composition of a symmetric method is symmetric
        with the same one)."""
        return self.base.reverse(system, state)

    def observe(self, system, state, h):
        return self._base().observe(system, state, self.coefficients[0] * h)

    def hidden_momentum(self, system, state, h):
        """The base method's hidden impulse scaled from the first substep to the step h, so that the
        run-time diagnostics compare it with $\\tfrac h2\\mu^T\\lambda$ as for the base method."""
        g = self.coefficients[0]
        hidden = self._base().hidden_momentum(system, state, g * h)
        return None if hidden is None else hidden / g
