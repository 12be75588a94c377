"""Discrete Lagrangians $l_d(q_k, q_{k+1}, h) \\approx \\int_0^h l\\,dt$ (paper (LagEuler), (Verlet)).

Each family is written once against the configuration space's `step_points`, so the same classes
serve $\\mathbb{R}^n$ and, later, $\\mathbb{R}^n \\times G$.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import equinox as eqx

__all__ = [
    "DiscreteLagrangian",
    "EulerA",
    "EulerB",
    "Trapezoid",
    "Midpoint",
    "CustomDiscreteLagrangian",
    "DISCRETE_LAGRANGIANS",
]


class DiscreteLagrangian(eqx.Module):
    """Base class: `ld(system, b0, z, h)` is the discrete Lagrangian of the step from `b0` with
    unknowns `z` (the increment $z = q_{k+1} - q_k$ on $\\mathbb{R}^n$, see :mod:`gnipy.spaces`).

    `explicit_if_flat` says that $FL^-$ is affine in the unknowns whenever the metric is constant,
    so that the GNI step is explicit (one linear solve, no Newton iteration). `order` is the
    global order of the GNI built on it (None: not known); the GNI's `order` reads it.
    """

    explicit_if_flat: ClassVar[bool] = False
    name: ClassVar[str] = "discrete-lagrangian"
    order: ClassVar[int | None] = None
    #: Symmetric: $l_d(b_1, -z, -h) = -l_d(b_0, z, h)$ (with a retraction $\tau(-\sigma) = \tau(\sigma)^{-1}$
    #: on $\mathbb{R}^n \times G$), so that the GNI built on it is time-reversible.
    symmetric: ClassVar[bool] = False
    #: The quadrature of a force's virtual work on a step (a rule of :data:`gnipy.forcing.FORCE_RULES`):
    #: the discrete forces $f^\mp_d$ of the forced methods.
    force_rule: ClassVar[str] = "trapezoid"

    def __call__(self, system, b0, z, h):
        raise NotImplementedError


class EulerA(DiscreteLagrangian):
    """Euler A: $l_d = h\\, l(q_k, (q_{k+1} - q_k)/h)$ ((LagEuler))."""

    explicit_if_flat: ClassVar[bool] = True
    name: ClassVar[str] = "euler-a"
    force_rule: ClassVar[str] = "left"  # f⁻ = hF(q_k), f⁺ = 0
    order: ClassVar[int | None] = 1  # Thm 5.1

    def __call__(self, system, b0, z, h):
        _, _, v = system.space.step_points(b0, z, h)
        return h * system.L(b0, v)


class EulerB(DiscreteLagrangian):
    """Euler B: $l_d = h\\, l(q_{k+1}, (q_{k+1} - q_k)/h)$ ((LagEuler))."""

    explicit_if_flat: ClassVar[bool] = True
    name: ClassVar[str] = "euler-b"
    force_rule: ClassVar[str] = "right"  # f⁻ = 0, f⁺ = hF(q_{k+1})
    order: ClassVar[int | None] = 1  # Thm 5.1

    def __call__(self, system, b0, z, h):
        b1, _, v = system.space.step_points(b0, z, h)
        return h * system.L(b1, v)


class Trapezoid(DiscreteLagrangian):
    """Trapezoid (Störmer–Verlet): the average of Euler A and Euler B ((Verlet)).

    With the GNI this gives nonholonomic SHAKE/RATTLE (Remark 5.1).
    """

    explicit_if_flat: ClassVar[bool] = True
    name: ClassVar[str] = "trapezoid"
    order: ClassVar[int | None] = 2  # symmetric (RATTLE)
    symmetric: ClassVar[bool] = True

    def __call__(self, system, b0, z, h):
        b1, _, v = system.space.step_points(b0, z, h)
        return 0.5 * h * (system.L(b0, v) + system.L(b1, v))


class Midpoint(DiscreteLagrangian):
    """Midpoint: $l_d = h\\, l((q_k + q_{k+1})/2, (q_{k+1} - q_k)/h)$."""

    name: ClassVar[str] = "midpoint"
    force_rule: ClassVar[str] = "midpoint"  # f⁻ = f⁺ = (h/2)F(q_{k+1/2})
    order: ClassVar[int | None] = 2
    symmetric: ClassVar[bool] = True

    def __call__(self, system, b0, z, h):
        _, bm, v = system.space.step_points(b0, z, h)
        return h * system.L(bm, v)

    @staticmethod
    def symmetric_on(system) -> bool:
        """Symmetric except where $l$ depends on the orientation and the retraction is not exp: the
        midpoint $R_k\\tau(\\sigma/2)$ seen from the end, $R_{k+1}\\tau(-\\sigma/2)$, is another point for
        Cayley (a run of 1000 steps forward and back on `chaplygin-top` misses by 1e-5; with exp, 4e-14)."""
        if not getattr(system, "depends_on_orientation", False):
            return True
        return getattr(system.space.retraction, "name", "") == "exp"


class CustomDiscreteLagrangian(DiscreteLagrangian):
    """A discrete Lagrangian supplied by the user.

    Arguments:
        fn: `fn(q0, q1, h) -> scalar`, smooth, with $\\partial^2 l_d/\\partial q_0 \\partial q_1$ regular
            (on $\\mathbb{R}^n \\times G$: `fn(b0, z1, h)` with `b0` a :class:`~gnipy.spaces.Point`
            and `z1` $= (x_1, \\sigma)$). It receives $q_1 = q_0 + \\Delta q$: a function that forms
            $(q_1 - q_0)/h$ itself loses $\\varepsilon|q|/h$ there (the built-in families do not).
        explicit: declare that $-\\partial l_d / \\partial q_0$ is affine in `q1` (then the GNI step is
            one linear solve); leave False when unsure: the Newton solve is always correct.
        order: declare the global order of the GNI built on it (e.g. 2 for a symmetric $l_d$);
            None (the default) when it is not known. `gni convergence` compares the fitted order
            with it.
        symmetric: declare $l_d(q_1, q_0, -h) = -l_d(q_0, q_1, h)$: the GNI built on it is then
            reversible (runs with h < 0 use its exact inverse) and can be composed to higher order.
    """

    fn: Callable = eqx.field(static=True)
    explicit: bool = eqx.field(static=True, default=False)
    order: int | None = eqx.field(static=True, default=None, kw_only=True)
    symmetric: bool = eqx.field(static=True, default=False, kw_only=True)  # type: ignore[assignment]
    name: ClassVar[str] = "custom"

    def __call__(self, system, b0, z, h):
        return self.fn(b0, system.space.end_coordinates(b0, z), h)


DISCRETE_LAGRANGIANS: dict[str, type[DiscreteLagrangian]] = {
    "euler-a": EulerA,
    "euler-b": EulerB,
    "trapezoid": Trapezoid,
    "midpoint": Midpoint,
}
