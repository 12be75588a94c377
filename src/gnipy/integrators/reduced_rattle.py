"""The reduced RATTLE algorithm (RAT) of paper §7.2, written as in the paper.

For a *reduced* system on $\\mathbb{R}^n \\times G$ (nothing depends on the orientation R) with a
**constant** metric

$$\\mathbb{G} = \\begin{pmatrix} G_{xx} & G_{x\\xi} \\\\ G_{\\xi x} & G_{\\xi\\xi} \\end{pmatrix},$$

a potential $V(x)$, constraint rows $(\\mu^a(x), \\eta^a(x))$ (x-part, group part) and an optional
affine part $Y(x)$, $\\Pi = \\mathbb{G}Y$, and the retracted trapezoid discrete Lagrangian

$$l_d(x_k, x_{k+1}, \\sigma_k) = \\tfrac h2\\Delta^T G_{xx}\\Delta + h\\Delta^T G_{x\\xi}\\tfrac{\\sigma_k}{h}
 + \\tfrac h2 \\big(\\tfrac{\\sigma_k}{h}\\big)^T G_{\\xi\\xi}\\tfrac{\\sigma_k}{h} - \\tfrac h2\\big(V(x_k) + V(x_{k+1})\\big),
 \\qquad \\Delta = \\frac{x_{k+1} - x_k}{h},$$

one step maps $(x_k, \\tilde p_k, \\xi_k, \\tilde M_k, \\tilde\\lambda_k)$ (and the reconstructed $R_k$) to
the same at $k + 1$ by

- (RATa) $p_{k+1/2} = \\tilde p_k - \\tfrac h2\\big(V_x(x_k) + \\tilde\\lambda_{a,k}\\mu^a(x_k)\\big)$;
- (RATc) $x_{k+1} = x_k + h\\,G_{xx}^{-1}\\big(p_{k+1/2} - G_{x\\xi}\\xi_k\\big)$;
- $R_{k+1} = R_k\\tau(h\\xi_k)$ (the discrete reconstruction of the Remark after (RAT); $\\tau(h\\xi_k)R_k$
  for a system built with `reconstruction="right"`, :class:`~gnipy.spaces.GroupSpace`);
- (RATb), (RATd), (RATe), (RATf), which are *linear* in $\\tilde\\lambda_{k+1}$:
  $M_{k+1/2} = \\mathrm{Ad}^*_{\\tau(h\\xi_k)}\\tilde M_k - \\tfrac12\\lambda_{a,k+1}\\eta^a(x_{k+1})$,
  $\\tilde p_{k+1} = p_{k+1/2} - \\tfrac h2\\big(V_x(x_{k+1}) + \\tilde\\lambda_{a,k+1}\\mu^a(x_{k+1})\\big)$,
  $\\tilde M_{k+1} = M_{k+1/2} - \\tfrac12\\lambda_{a,k+1}\\eta^a(x_{k+1})$, with $\\lambda = h\\tilde\\lambda$, and
  (RATd) $A^a\\tilde p_{k+1} + \\tfrac12 B^a(\\mathrm{Ad}^*_{\\tau(h\\xi_k)}\\tilde M_k + \\tilde M_{k+1}) = 0$, i.e.
  $(\\mu^a, \\eta^a)\\,\\mathbb{G}^{-1}(\\bar p_{k+1} - \\Pi(x_{k+1})) = 0$ with
  $\\bar p_{k+1} = (\\tilde p_{k+1}, M_{k+1/2})$ ($(A^a, B^a) = \\mathbb{G}^{-1}(\\mu^a, \\eta^a)$; the
  $-\\Pi$ is the affine extension of §7.3, zero for linear constraints). Solved in closed form:
  $\\tilde\\lambda_{k+1} = \\tfrac2h C^{-1}\\mu\\mathbb{G}^{-1}(\\hat p - \\Pi)$ with
  $\\hat p = (p_{k+1/2} - \\tfrac h2 V_x(x_{k+1}),\\ \\mathrm{Ad}^*_{\\tau(h\\xi_k)}\\tilde M_k)$ and
  $C = \\mu\\mathbb{G}^{-1}\\mu^T$ (here μ is the full row $(\\mu^a, \\eta^a)$);
- the implicit equation for $\\xi_{k+1}$:
  $\\tilde M_{k+1} = (\\mathrm{d}\\tau^{-1}_{h\\xi_{k+1}})^T D_3 l_d(x_{k+1}, x_{k+2}, h\\xi_{k+1})$, with
  $x_{k+2}$ from (RATa), (RATc) one step ahead, solved by Newton's method
  (:func:`~gnipy.integrators.base.solve_step`).

**Relation to the GNI.** With $p_{k+1/2} = G_{xx}\\Delta_k + G_{x\\xi}\\xi_k$ the Legendre transforms of
this $l_d$ are $FL^-_k = (p_{k+1/2} + \\tfrac h2 V_x(x_k),\\ \\tilde M_k)$ and
$FL^+_{k+1} = (p_{k+1/2} - \\tfrac h2 V_x(x_{k+1}),\\ \\mathrm{Ad}^*_{\\tau(h\\xi_k)}\\tilde M_k)$, since
$(\\mathrm{d}\\tau^{-1}_{-\\sigma})^T = \\mathrm{Ad}^*_{\\tau(\\sigma)}(\\mathrm{d}\\tau^{-1}_{\\sigma})^T$ (eq:dtauinverseAd).
The GNI gives $p^-_k - p^+_k = -\\lambda_k(\\mu^a, \\eta^a)$ and $\\bar p_k = (p^-_k + p^+_k)/2$ on the
constraints; hence $\\tilde p_k$ is the x-part of $\\bar p_k$, $\\tilde M_k$ the group part of
$p^-_k$, $M_{k+1/2}$ the group part of $\\bar p_{k+1}$, and (RAT) is the GNI with the trapezoid $l_d$
(`GNI(Trapezoid())`) in other variables: the tests hold them equal to round-off.

**Conventions and reading of the printed formulas** (each checked against the GNI):

- $\\mathrm{Ad}^*_g$ is the dual (transpose) of $\\mathrm{Ad}_g$, $\\mathrm{Ad}^*_g = \\mathrm{Ad}_g^T$ (on
  SO(3): $\\mathrm{Ad}^*_R M = R^TM$), not the coadjoint action $\\mathrm{Ad}_{g^{-1}}^T$.
- In (RATc) the symbol $(\\tilde{\\mathbb G}^{-1})^{ij}$ must be read as the inverse of the block
  $G_{xx}$ (from the definition of $p_{k+1/2}$), whereas in $A^{i,a}$, $B^{t,a}$ the same symbol is the
  block of the inverse of the whole metric. The two differ when $G_{x\\xi} \\ne 0$.
- The signs of (RATa)–(RATf) as printed are consistent with the GNI: (RATb) and (RATf) each subtract
  half of the impulse $\\lambda_{k+1}\\eta(x_{k+1})$ (so $\\tilde M_{k+1} = \\mathrm{Ad}^*\\tilde M_k - \\lambda_{k+1}\\eta$,
  as the text after (RAT) says). Note that (RATb) uses the multiplier of node $k+1$, so $M_{k+1/2}$ is
  the group part of the node momentum $\\bar p_{k+1}$, not a half-step quantity like $p_{k+1/2}$.
- For affine constraints the condition is $Q^*((p^- + p^+)/2 - \\Pi) = 0$, as in (GNIintAffb);
  (GNIredb-aff) and (RBb) print $+2Q^*\\Pi$ (an erratum: the docs' conventions page, "Errata in the
  paper").

**Start.** As the GNI: $p^+_0 = \\mathbb{G}v_0$, reflected at node 0, which gives $\\tilde\\lambda_0$,
$\\tilde p_0$, $\\tilde M_0$; then $\\xi_0$ from the implicit equation above.

**Reported.** At node k: $b_k$ = `Point(x_k, R_k)`, $\\bar p_k = (\\tilde p_k,\\ \\tilde M_k + \\tfrac h2\\tilde\\lambda_k\\eta(x_k))$
(the GNI's $\\bar p_k$, on the constraints) and $\\bar v_k = \\mathbb{G}^{-1}\\bar p_k$.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

from ..linalg import solve_spd  # the metric and the C = μG⁻¹μᵀ are SPD
from ..spaces import Point, compensated_add
from .base import Integrator, MethodError, solve_step

__all__ = ["RATState", "ReducedRattle"]


class RATState(NamedTuple):
    """State of (RAT) at node k: $(x_k, R_k, \\tilde p_k, \\xi_k, \\tilde M_k, \\tilde\\lambda_k)$ and the
    rounding error of $x_k$ (compensated summation, :func:`gnipy.spaces.compensated_add`)."""

    x: jax.Array
    R: jax.Array
    p_tilde: jax.Array
    xi: jax.Array
    M_tilde: jax.Array
    lam_tilde: jax.Array
    x_err: jax.Array


class ReducedRattle(Integrator):
    """The reduced RATTLE algorithm (RAT) of paper §7.2 (and its affine extension), see the module
    docstring.

    Arguments:
        root_finder: optimistix root finder for the implicit equation of $\\xi_{k+1}$
            (default Newton, tolerances 1e-12).
        max_steps: Newton iteration cap.

    Raises:
        MethodError: from :meth:`check`, for a system without a group part, one that depends on the
            orientation (not reduced), one with a non-constant metric, or one with a force
            (:mod:`gnipy.forcing`; use `gni-trapezoid`).
    """

    root_finder: Any = None
    max_steps: int = eqx.field(static=True, default=50)
    name: ClassVar[str] = "rat"
    order: ClassVar[int | None] = 2

    def check(self, system, q0) -> None:
        """Raise :class:`~gnipy.MethodError` unless the system is reduced, on $\\mathbb{R}^n\\times G$,
        with a constant metric (the hypotheses of §7.2)."""
        if system.group is None:
            raise MethodError(
                f"method {self.name!r} (reduced RATTLE, paper §7.2) needs a system on R^n x G; "
                f"{system.name!r} has no group part: use rattle or a gni-* method"
            )
        if system.depends_on_orientation:
            raise MethodError(
                f"method {self.name!r} is written for reduced systems (paper §7.2); {system.name!r} "
                "depends on the orientation R: use a gni-* method"
            )
        if not system.has_constant_metric(q0):
            raise MethodError(
                f"method {self.name!r} is written for a constant metric (paper §7.2); the metric of "
                f"{system.name!r} depends on the configuration: use a gni-* method"
            )
        if system.force is not None:
            raise MethodError(
                f"method {self.name!r} (reduced RATTLE) does not support forces: {system.name!r} has a force "
                "F(q, v, u, t), and the implicit equation for xi_(k+1) looks one step ahead, into the next "
                "step's force and input; use gni-trapezoid (the same scheme, with the forced trapezoid rule)"
            )

    # ------------------------------------------------------------------------------------------
    # The ingredients, evaluated on the Euclidean part x (R only completes the base point)
    # ------------------------------------------------------------------------------------------
    @staticmethod
    def _blocks(system, R):
        n = system.n
        G = system.metric(Point(jnp.zeros(n), R))  # constant (checked)
        return G, G[:n, :n], G[:n, n:]

    @staticmethod
    def _V(system, x, R):
        return system.potential(Point(x, R))

    @classmethod
    def _Vx(cls, system, x, R):
        return jax.grad(lambda y: cls._V(system, y, R))(x)

    @staticmethod
    def _solve_xx(Gxx, r):
        return r if r.shape[0] == 0 else solve_spd(Gxx, r)

    def _ld(self, system, R, h):
        """The retracted trapezoid $l_d(x_k, x_k + \\Delta x, \\sigma_k)$ of §7.2, as a function of
        $(x_k, \\Delta x, \\sigma_k)$ (the increment keeps the step velocity at full precision)."""
        G, Gxx, Gxs = self._blocks(system, R)
        Gss = G[system.n :, system.n :]

        def ld(x0, dx, sigma):
            D = dx / h
            x1 = x0 + dx
            w = sigma / h
            return (
                0.5 * h * D @ Gxx @ D
                + h * D @ Gxs @ w
                + 0.5 * h * w @ Gss @ w
                - 0.5 * h * (self._V(system, x0, R) + self._V(system, x1, R))
            )

        return ld

    def _solve_xi(self, system, x1, R1, pt1, lam1, M1, guess, h):
        """$\\xi_{k+1}$ from $\\tilde M_{k+1} = (\\mathrm{d}\\tau^{-1}_{h\\xi})^T D_3l_d(x_{k+1}, x_{k+2}(\\xi), h\\xi)$."""
        space = system.space
        n = system.n
        _, Gxx, Gxs = self._blocks(system, R1)
        mu1 = system.mu(Point(x1, R1))[:, :n]
        p_half = pt1 - 0.5 * h * (self._Vx(system, x1, R1) + mu1.T @ lam1)  # (RATa), one step ahead
        ld = self._ld(system, R1, h)

        def residual(xi):
            dx2 = h * self._solve_xx(Gxx, p_half - Gxs @ xi)  # (RATc), one step ahead: x_{k+2} − x_{k+1}
            sigma = h * xi
            d3 = jax.grad(ld, argnums=2)(x1, dx2, sigma)
            return space.retraction.dtau_inv(space.group, sigma).T @ d3 - M1

        return solve_step(residual, guess, explicit=False, solver=self.root_finder, max_steps=self.max_steps,
                          floor_scale=jnp.max(jnp.abs(jnp.concatenate([M1, pt1]))))

    def _multipliers(self, system, b, p_hat, h):
        """$\\tilde\\lambda$ with $\\mu\\mathbb{G}^{-1}(\\hat p - \\tfrac h2\\mu^T\\tilde\\lambda - \\Pi) = 0$ ((RATd))."""
        G = system.metric(b)
        mu = system.mu(b)
        Ginv_muT = solve_spd(G, mu.T)
        C = mu @ Ginv_muT
        return (2.0 / h) * solve_spd(C, Ginv_muT.T @ (p_hat - system.Pi(b)))

    # ------------------------------------------------------------------------------------------
    # The integrator interface
    # ------------------------------------------------------------------------------------------
    def init(self, system, q0, v0, h):
        """From the GNI start $p^+_0 = \\mathbb{G}v_0$: $\\tilde\\lambda_0$, $\\tilde p_0$, $\\tilde M_0$, then $\\xi_0$."""
        n = system.n
        b = q0
        p_plus = system.momentum(b, v0)
        lam = self._multipliers(system, b, p_plus, h)  # reflection at node 0
        mu = system.mu(b)
        p_bar = p_plus - 0.5 * h * mu.T @ lam
        p_minus = p_plus - h * mu.T @ lam
        pt, M = p_bar[:n], p_minus[n:]
        xi, info = self._solve_xi(system, b.x, b.R, pt, lam, M, v0[n:], h)
        xi = jnp.where(info.ok, xi, jnp.nan)  # a failed start surfaces as a failed first step
        return RATState(b.x, b.R, pt, xi, M, lam, jnp.zeros_like(b.x))

    def step(self, system, state, h):
        """One step (RATa)–(RATf), then $\\xi_{k+1}$; returns `(RATState, StepInfo)`."""
        x, R, pt, xi, M, lam, x_err = state
        space = system.space
        n = system.n
        _, Gxx, Gxs = self._blocks(system, R)
        mu = system.mu(Point(x, R))[:, :n]
        p_half = pt - 0.5 * h * (self._Vx(system, x, R) + mu.T @ lam)  # (RATa)
        x1, x_err = compensated_add(x, h * self._solve_xx(Gxx, p_half - Gxs @ xi), x_err)  # (RATc)
        g = space.tau(h * xi)
        R1 = space.reconstruct(R, g)  # reconstruction R_{k+1} = R_k τ(hξ_k) (τ(hξ_k) R_k for a right one)
        AdM = space.group.Ad(g).T @ M  # Ad*_{τ(hξ_k)} M̃_k
        b1 = Point(x1, R1)
        Vx1 = self._Vx(system, x1, R1)
        p_hat = jnp.concatenate([p_half - 0.5 * h * Vx1, AdM])
        lam1 = self._multipliers(system, b1, p_hat, h)  # (RATd) with (RATb), (RATe), (RATf)
        mu_full1 = system.mu(b1)
        mu1, eta1 = mu_full1[:, :n], mu_full1[:, n:]
        pt1 = p_half - 0.5 * h * (Vx1 + mu1.T @ lam1)  # (RATe)
        M_half = AdM - 0.5 * h * eta1.T @ lam1  # (RATb): ½λ_{k+1}η with λ = hλ̃
        M1 = M_half - 0.5 * h * eta1.T @ lam1  # (RATf)
        xi1, info = self._solve_xi(system, x1, R1, pt1, lam1, M1, xi, h)
        return RATState(x1, R1, pt1, xi1, M1, lam1, x_err), info

    def observe(self, system, state, h):
        """`(Point(x_k, R_k), v̄_k, p̄_k)` with $\\bar p_k = (\\tilde p_k, \\tilde M_k + \\tfrac h2\\tilde\\lambda_k\\eta(x_k))$."""
        x, R, pt, _, M, lam, _ = state
        n = system.n
        b = Point(x, R)
        eta = system.mu(b)[:, n:]
        p_bar = jnp.concatenate([pt, M + 0.5 * h * eta.T @ lam])
        return b, system.velocity(b, p_bar), p_bar

    def hidden_momentum(self, system, state, h):
        """The GNI's $p^+_k - \\bar p_k = \\tfrac h2\\mu^T\\tilde\\lambda_k$ (the reflection at node k)."""
        x, R, lam = state.x, state.R, state.lam_tilde
        return 0.5 * h * system.mu(Point(x, R)).T @ lam
