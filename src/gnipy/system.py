"""Nonholonomic mechanical systems: a Lagrangian, constraint one-forms and an affine part.

A :class:`System` holds the user's data (DESIGN.md §2):

- a Lagrangian of mechanical type $l(q, v) = \\tfrac12 v^T \\mathbb{G}(q) v - V(q)$,
- constraint one-forms $\\mu(q)$ ($m \\times n$, full row rank),
- an optional affine vector field $Y(q)$; the constraints are $\\mu(q)(v - Y(q)) = 0$.

Everything else (metric, potential, momenta, projectors, $\\Pi = \\mathbb{G} Y$) is derived by
automatic differentiation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .spaces import EuclideanSpace

__all__ = ["System", "SystemError"]


class SystemError(ValueError):
    """A system or an initial condition is not acceptable (the message says which argument and why)."""


def _fmt(x: float) -> str:
    return f"{float(x):.3e}"


class System(eqx.Module):
    """A nonholonomic mechanical system on $\\mathbb{R}^n$.

    Arguments:
        lagrangian: `l(q, v) -> scalar`, of mechanical type (quadratic in `v`, no linear term).
        constraints: `mu(q) -> (m, n)` array, the constraint one-forms as rows.
        affine: optional `Y(q) -> (n,)`; the constraints are then `mu(q) @ (v - Y(q)) = 0`.
        n: dimension of the configuration space (inferred from `coordinates` if omitted).
        coordinates: names of the coordinates (default `q0, q1, ...`).
        name: a short name used in reports and files.
        params: parameters of the system, for provenance (a dict of floats).
        defaults: optional default initial condition `(q0, v0)`.

    Raises:
        SystemError: on inconsistent dimensions or names.
    """

    lagrangian: Callable[..., Any]
    constraints: Callable[..., Any]
    affine: Callable[..., Any] | None
    space: EuclideanSpace
    coordinates: tuple[str, ...] = eqx.field(static=True)
    name: str = eqx.field(static=True)
    params: tuple[tuple[str, float], ...] = eqx.field(static=True)
    defaults: tuple[tuple[float, ...], tuple[float, ...]] | None = eqx.field(static=True)

    def __init__(
        self,
        lagrangian: Callable[..., Any],
        constraints: Callable[..., Any],
        affine: Callable[..., Any] | None = None,
        *,
        n: int | None = None,
        coordinates: Sequence[str] | None = None,
        name: str = "system",
        params: dict[str, float] | None = None,
        defaults: tuple[Sequence[float], Sequence[float]] | None = None,
    ):
        if not callable(lagrangian):
            raise SystemError(f"lagrangian: expected a callable l(q, v), got {type(lagrangian).__name__}")
        if not callable(constraints):
            raise SystemError(f"constraints: expected a callable mu(q), got {type(constraints).__name__}")
        if affine is not None and not callable(affine):
            raise SystemError(f"affine: expected a callable Y(q) or None, got {type(affine).__name__}")
        if n is None and coordinates is None:
            raise SystemError("n: give the dimension n of the configuration space (or coordinates=...)")
        if n is None:
            n = len(tuple(coordinates))
        if int(n) != n or n < 1:
            raise SystemError(f"n: expected a positive integer, got {n!r}")
        n = int(n)
        if coordinates is None:
            coordinates = tuple(f"q{i}" for i in range(n))
        coordinates = tuple(str(c) for c in coordinates)
        if len(coordinates) != n:
            raise SystemError(f"coordinates: expected {n} names, got {len(coordinates)}")
        self.lagrangian = lagrangian
        self.constraints = constraints
        self.affine = affine
        self.space = EuclideanSpace(n)
        self.coordinates = coordinates
        self.name = str(name)
        self.params = tuple((str(k), float(v)) for k, v in (params or {}).items())
        if defaults is not None:
            dq, dv = defaults
            defaults = (tuple(float(x) for x in dq), tuple(float(x) for x in dv))
        self.defaults = defaults

    # ----------------------------------------------------------------------------------------
    # Derived quantities (all traceable)
    # ----------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Dimension of the configuration space."""
        return self.space.n

    @property
    def parameters(self) -> dict[str, float]:
        """The system's parameters as a dict (for provenance)."""
        return dict(self.params)

    def metric(self, q):
        """The kinetic-energy metric $\\mathbb{G}(q) = \\partial^2 l / \\partial v^2$ (n×n)."""
        return jax.hessian(lambda v: self.lagrangian(q, v))(jnp.zeros(self.n))

    def potential(self, q):
        """The potential $V(q) = -l(q, 0)$."""
        return -self.lagrangian(q, jnp.zeros(self.n))

    def potential_gradient(self, q):
        """$\\partial V / \\partial q$."""
        return jax.grad(self.potential)(q)

    def momentum(self, q, v):
        """The Legendre transform $p = \\partial l / \\partial v = \\mathbb{G}(q) v$."""
        return jax.grad(lambda w: self.lagrangian(q, w))(v)

    def velocity(self, q, p):
        """Inverse Legendre transform $v = \\mathbb{G}(q)^{-1} p$."""
        return jnp.linalg.solve(self.metric(q), p)

    def mu(self, q):
        """Constraint one-forms $\\mu(q)$ as an (m, n) array."""
        return jnp.atleast_2d(jnp.asarray(self.constraints(q)))

    def Y(self, q):
        """Affine part $Y(q)$ (zero for linear constraints)."""
        if self.affine is None:
            return jnp.zeros(self.n, dtype=jnp.result_type(q))
        return jnp.asarray(self.affine(q)).reshape(self.n)

    def Pi(self, q):
        """The one-form $\\Pi = \\mathbb{G} Y$ of paper §6."""
        return self.metric(q) @ self.Y(q)

    def energy(self, q, v):
        """Energy $\\tfrac12 v^T \\mathbb{G} v + V$."""
        return 0.5 * v @ self.metric(q) @ v + self.potential(q)

    def constraint_residual(self, q, v):
        """$\\mu(q)(v - Y(q))$, one entry per constraint."""
        return self.mu(q) @ (v - self.Y(q))

    @property
    def is_affine(self) -> bool:
        """Whether the constraints have an affine part."""
        return self.affine is not None

    # ----------------------------------------------------------------------------------------
    # Validation (host side, outside jit)
    # ----------------------------------------------------------------------------------------
    def num_constraints(self, q) -> int:
        """Number of constraints m, evaluated at q."""
        return int(np.asarray(self.mu(jnp.asarray(q, dtype=jnp.float64))).shape[0])

    def check(self, q0, v0=None, *, project_v0: bool = False, tol: float = 1e-10):
        """Validate the system at the initial point and return `(q0, v0)` as float64 arrays.

        Checks: shapes and finiteness; that `l` is of mechanical type (quadratic in `v` with no
        linear term, at `q0` and nearby points); that the metric is symmetric positive definite;
        that the constraints have full row rank; that `v0` satisfies the constraints.

        Arguments:
            q0: initial configuration, length n.
            v0: initial velocity, length n (optional).
            project_v0: project `v0` onto the constraint space ($\\mathbb{G}$-orthogonally)
                instead of raising when it violates the constraints.
            tol: tolerance of the checks.

        Raises:
            SystemError: naming the argument and the problem.
        """
        q0 = _as_vector("q0", q0, self.n)
        if v0 is not None:
            v0 = _as_vector("v0", v0, self.n)
        self.check_mechanical(q0, tol=tol)
        G = np.asarray(self.metric(jnp.asarray(q0)))
        if not np.all(np.isfinite(G)):
            raise SystemError("lagrangian: the metric d²l/dv² is not finite at q0")
        if np.max(np.abs(G - G.T)) > tol * max(1.0, np.max(np.abs(G))):
            raise SystemError("lagrangian: the metric d²l/dv² is not symmetric at q0")
        eig = np.linalg.eigvalsh(G)
        if eig[0] <= tol * max(1.0, eig[-1]):
            raise SystemError(
                "lagrangian: the metric d²l/dv² is not positive definite at q0 "
                f"(smallest eigenvalue {_fmt(eig[0])})"
            )
        mu = np.asarray(self.mu(jnp.asarray(q0)))
        if mu.ndim != 2 or mu.shape[1] != self.n:
            raise SystemError(f"constraints: mu(q) must have shape (m, {self.n}), got {mu.shape}")
        if not np.all(np.isfinite(mu)):
            raise SystemError("constraints: mu(q0) is not finite")
        m = mu.shape[0]
        if m >= self.n:
            raise SystemError(f"constraints: {m} constraints on a {self.n}-dimensional space leave no motion")
        sv = np.linalg.svd(mu, compute_uv=False)
        if sv[-1] <= 1e-10 * max(1.0, sv[0]):
            raise SystemError(
                f"constraints: mu(q0) is rank deficient (rank {int(np.sum(sv > 1e-10 * max(1.0, sv[0])))} "
                f"< {m} constraints; smallest singular value {_fmt(sv[-1])})"
            )
        Y = np.asarray(self.Y(jnp.asarray(q0)))
        if not np.all(np.isfinite(Y)):
            raise SystemError("affine: Y(q0) is not finite")
        if v0 is None:
            return q0, None
        res = mu @ (v0 - Y)
        scale = max(1.0, float(np.max(np.abs(v0))), float(np.max(np.abs(Y))))
        if np.max(np.abs(res)) > tol * scale:
            if not project_v0:
                raise SystemError(
                    "v0: the initial velocity violates the constraints mu(q0)(v0 - Y(q0)) = 0 "
                    f"(residual {_fmt(np.max(np.abs(res)))}); pass project_v0=True to project it"
                )
            v0 = np.asarray(project_velocity(self, jnp.asarray(q0), jnp.asarray(v0)))
        return q0, v0

    def check_mechanical(self, q0, *, tol: float = 1e-9, samples: int = 3):
        """Raise :class:`SystemError` unless `l(q, v) = ½vᵀG(q)v − V(q)` near `q0`."""
        rng = np.random.default_rng(0)
        n = self.n
        for i in range(samples):
            q = np.asarray(q0) + (0.0 if i == 0 else 0.1) * rng.standard_normal(n)
            v = rng.standard_normal(n)
            q_, v_ = jnp.asarray(q), jnp.asarray(v)
            try:
                lv = float(self.lagrangian(q_, v_))
            except Exception as e:  # the user's function failed: say where
                raise SystemError(f"lagrangian: evaluating l(q, v) failed: {e}") from e
            G = np.asarray(self.metric(q_))
            V = float(self.potential(q_))
            lin = np.asarray(jax.grad(lambda w: self.lagrangian(q_, w))(jnp.zeros(n)))
            quad = 0.5 * v @ G @ v - V
            scale = max(1.0, abs(lv), abs(quad))
            if not np.isfinite(lv):
                raise SystemError("lagrangian: l(q, v) is not finite near q0")
            if np.max(np.abs(lin)) > tol * scale or abs(lv - quad) > tol * scale:
                raise SystemError(
                    "lagrangian: not of mechanical type ½ vᵀG(q)v − V(q) "
                    f"(linear term {_fmt(np.max(np.abs(lin)))}, "
                    f"mismatch with the quadratic part {_fmt(abs(lv - quad))})"
                )

    def has_constant_metric(self, q0) -> bool:
        """Whether the metric does not depend on q (exact zero derivative at sample points).

        Automatic differentiation returns an exact zero for a metric that does not depend on q,
        and a nonzero value almost surely at random points otherwise.
        """
        rng = np.random.default_rng(1)
        for _ in range(2):
            q = jnp.asarray(np.asarray(q0) + 0.3 * rng.standard_normal(self.n))
            dG = np.asarray(jax.jacfwd(self.metric)(q))
            if np.any(dG != 0.0):
                return False
        return True


def _as_vector(name: str, x, n: int) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise SystemError(f"{name}: expected {n} numbers, got {x!r}") from e
    if a.ndim != 1 or a.shape[0] != n:
        raise SystemError(f"{name}: expected a vector of length {n}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SystemError(f"{name}: contains NaN or infinite values: {a.tolist()}")
    return a


def project_velocity(system: System, q, v):
    """$\\mathbb{G}$-orthogonal projection of v onto the affine constraint space: $P v + Q Y$."""
    from .projectors import projectors

    P, Q = projectors(system.metric(q), system.mu(q))
    return P @ v + Q @ system.Y(q)
