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

    def symmetric_on(self, system) -> bool:
        """Whether $l_d$ is symmetric on `system` (:attr:`symmetric`, unless a family says otherwise
        for some systems: :meth:`Midpoint.symmetric_on`, :meth:`EulerA.symmetric_on`)."""
        return bool(self.symmetric)


def _symmetric_where_l_is_constant(system) -> bool:
    """Euler A and B on a system whose l does not depend on the base point (nor has a force): both are
    then $h\\, l(\\Delta q/h)$, which is symmetric ($\\tau(-\\sigma) = \\tau(\\sigma)^{-1}$ on a group:
    the step back has the same velocity). Measured: 50 steps forward and 50 back return to the start
    to 1e-15 on both Chaplygin sleighs, the Chaplygin sphere, the rolling balls, Suslov, the vertical
    disk and Veselova's system, and miss by 0.08–0.6 where l depends on q (a potential, a metric)."""
    return system.force is None and not system.lagrangian_depends_on("configuration")


class EulerA(DiscreteLagrangian):
    """Euler A: $l_d = h\\, l(q_k, (q_{k+1} - q_k)/h)$ ((LagEuler))."""

    explicit_if_flat: ClassVar[bool] = True
    name: ClassVar[str] = "euler-a"
    force_rule: ClassVar[str] = "left"  # f⁻ = hF(q_k), f⁺ = 0
    order: ClassVar[int | None] = 1  # Thm 5.1

    def __call__(self, system, b0, z, h):
        _, _, v = system.space.step_points(b0, z, h)
        return h * system.L(b0, v)

    def symmetric_on(self, system) -> bool:
        """Not symmetric ($l_d(q_1, q_0, -h) = -h\\,l(q_1, v) \\ne -l_d(q_0, q_1, h)$), except on a
        system whose l does not depend on the base point and that has no force: there every $l_d$
        is $h\\, l(\\Delta q/h)$ (:meth:`gnipy.System.lagrangian_depends_on`)."""
        return _symmetric_where_l_is_constant(system)


class EulerB(DiscreteLagrangian):
    """Euler B: $l_d = h\\, l(q_{k+1}, (q_{k+1} - q_k)/h)$ ((LagEuler))."""

    explicit_if_flat: ClassVar[bool] = True
    name: ClassVar[str] = "euler-b"
    force_rule: ClassVar[str] = "right"  # f⁻ = 0, f⁺ = hF(q_{k+1})
    order: ClassVar[int | None] = 1  # Thm 5.1

    def __call__(self, system, b0, z, h):
        b1, _, v = system.space.step_points(b0, z, h)
        return h * system.L(b1, v)

    def symmetric_on(self, system) -> bool:
        """As :meth:`EulerA.symmetric_on`: only where l does not depend on the base point (no force)."""
        return _symmetric_where_l_is_constant(system)


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

    def symmetric_on(self, system) -> bool:
        """Symmetric except where l depends on the orientation R and the retraction is not exp.

        The step back from $b_1 = (x_0 + \\Delta x, R_0\\tau(\\sigma))$ has $\\sigma' = -\\sigma$ (both
        retractions have $\\tau(-\\sigma) = \\tau(\\sigma)^{-1}$) and the same velocity, and its midpoint
        is $(x_0 + \\Delta x/2, R_0\\tau(\\sigma)\\tau(-\\sigma/2))$: the same x, and for exp the same
        orientation $R_0\\tau(\\sigma/2)$, for Cayley another one. So $l_d(b_1, -z, -h) = -l_d(b_0, z, h)$
        holds for every system with exp, and with Cayley exactly when l does not depend on R
        (:meth:`gnipy.System.lagrangian_depends_on`; the constraints μ, Y may: the GNI imposes them at
        the nodes). Measured with Cayley, N = 50 steps of h = 0.05 forward and N back (the exact
        inverse, :class:`~gnipy.integrators.reversal.Reversed`): `chaplygin-top` (l depends on R
        through its potential) misses the start by 9e-5; `chaplygin-sphere` and `veselova` (only
        their constraints depend on R) return to 1e-15."""
        if not system.lagrangian_depends_on("orientation"):
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
