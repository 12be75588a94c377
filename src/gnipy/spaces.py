"""Configuration spaces: how a step's unknowns become the next configuration.

The GNI core (the formulation on the docs' conventions page) solves for the step unknowns $z$ and
advances the configuration with them. The unknowns are *increments*: on $\\mathbb{R}^n$,
$z = \\Delta x = x_{k+1} - x_k$; on $\\mathbb{R}^n \\times G$, $z = (\\Delta x, \\sigma_k)$ with $R_{k+1} = R_k \\tau(\\sigma_k)$. Solving for
$x_{k+1}$ itself and forming $(x_{k+1} - x_k)/h$ would lose $\\varepsilon|x|/h$ in every step
velocity, an error that adds up step after step (measured: 1.8e-5 at h = 1e-5 over T = 10 on
`rotating-table-ball`); the increment carries the step velocity $\\Delta x/h$ to full precision.
Positions are accumulated with compensated summation (:func:`compensated_add`), so that their
round-off grows like a random walk instead of step by step. Both spaces offer the same small set
of operations, so the core (integrators, discrete Lagrangians, the continuous reference) is written
once against them:

- `step_points(b0, z, h)`: the end point, the midpoint and the step velocity;
- `constraint_velocity(z, h)`: the step velocity of a discrete constraint, consistent with the
  discrete Legendre transforms ($\\Delta x/h$, $\\mathrm{d}\\tau^{-1}_\\sigma\\sigma/h$ on a group);
- `end_coordinates(b0, z)`: the unknowns with $x_{k+1}$ in place of $\\Delta x$ (user-supplied $l_d$);
- `advance`, `initial_guess`: the step map and a first guess of the unknowns;
- `legendre_minus`, `legendre_plus`: the discrete Legendre transforms $FL^\\mp$ ((RedLegTr); the docs' conventions page, "The group
  part and retractions"), and
  `legendre_jump` = $FL^+ - FL^-$, the impulse of the step (the GNI forms $p^+_{k+1} = p^-_k +$ jump,
  so that the momentum is never rebuilt from the increment: $\\mathbb{G}(\\Delta x/h)$ rounds with a
  bias that adds up over $10^6$ steps, measured 1.4e-11 at h = 1e-5 over T = 10);
- `move(b, w)`: the point reached from `b` along a velocity-space vector `w` (used to
  differentiate along motions: $(x + w_x, R\\exp(w_\\xi))$);
- `reconstruct(R, g)`: the orientation after a group increment, $Rg$, or $gR$ for a reduced
  system whose group velocity is the *space* velocity (`reconstruction="right"`, below);
- `lie_correction(v, p)`: the $\\mathrm{ad}^*_\\xi$ term of the Lagrange–d'Alembert–Poincaré equations.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["EuclideanSpace", "GroupSpace", "Point", "compensated_add"]


def compensated_add(x, dx, err):
    r"""$x + \\Delta x$ with the rounding error carried over: returns `(s, err1)` where `s` is the
    rounded sum of `x` and $\\Delta x$ + `err`, and `err1` what rounding lost, exactly
    (Knuth's TwoSum, no branch, valid for any magnitudes).

    Summing the increments of $10^6$ steps naively adds one rounding error of up to
    $\\varepsilon|x|/2$ per step, and for slowly varying increments these errors share a sign and
    add up linearly. Carrying the lost part into the next addition (Kahan's compensated summation)
    leaves an error of about one rounding of $x$, whatever the number of steps. Written here
    because no library offers it for values inside a compiled step (it relies on IEEE rounding,
    which XLA keeps: it does not reassociate floating-point sums).
    """
    y = dx + err
    s = x + y
    y_part = s - x
    x_part = s - y_part
    return s, (x - x_part) + (y - y_part)


class EuclideanSpace(eqx.Module):
    """The configuration space $\\mathbb{R}^n$ (the Lie group part is trivial).

    A base point `b` is the coordinate vector q; the step unknown `z` is the increment
    $\\Delta q = q_{k+1} - q_k$.
    """

    n: int = eqx.field(static=True)

    @property
    def dim(self) -> int:
        """Dimension N of the velocity space."""
        return self.n

    def step_points(self, b0, z, h):
        """Return `(b1, b_mid, velocity)` of the step from `b0` with unknowns `z`.

        `velocity` is the step's velocity $\\Delta q/h$ and `b_mid` the midpoint.
        """
        return b0 + z, b0 + 0.5 * z, z / h

    def constraint_velocity(self, z, h):
        """The step velocity on which a discrete constraint is imposed (discrete Lagrange–d'Alembert):
        $\\Delta q/h$, the velocity of :meth:`step_points`."""
        return z / h

    def end_coordinates(self, b0, z):
        """$q_{k+1} = q_k + \\Delta q$."""
        return b0 + z

    def advance(self, b0, z):
        """The configuration reached by the step: $q_{k+1} = q_k + \\Delta q$."""
        return b0 + z

    def advance_compensated(self, b0, err, z):
        """:meth:`advance` with compensated summation: `(q_{k+1}, err_{k+1})`, see :func:`compensated_add`."""
        return compensated_add(b0, z, err)

    def initial_guess(self, b0, v, h):
        """A first guess of the unknowns from the velocity `v` at `b0`: $\\Delta q = h v$."""
        return h * v

    def legendre_minus(self, ld: Callable, b0, z):
        """$FL^-$: $-\\partial l_d / \\partial q_k$ at fixed $q_{k+1}$ (a covector at $q_k$).

        With the increment as unknown, $l_d(q_k, q_k + \\Delta q)$: the derivative at fixed $q_{k+1}$
        is $\\partial_{q_k} - \\partial_{\\Delta q}$, both taken without forming a difference of positions.
        """
        g0, gz = jax.grad(ld, argnums=(0, 1))(b0, z)
        return gz - g0

    def legendre_plus(self, ld: Callable, b0, z):
        """$FL^+$: $\\partial l_d / \\partial q_{k+1}$ (a covector at $q_{k+1}$), i.e. $\\partial l_d/\\partial\\Delta q$."""
        return jax.grad(ld, argnums=1)(b0, z)

    def legendre_jump(self, ld: Callable, b0, z):
        """$FL^+ - FL^-$ $= \\partial l_d/\\partial q_k$ at fixed $\\Delta q$ (e.g. $-\\tfrac h2(V_q(q_k) + V_q(q_{k+1}))$
        for the trapezoid with a constant metric): small, and computed without cancellation."""
        return jax.grad(ld, argnums=0)(b0, z)

    def move(self, b, w):
        """$q + w$."""
        return b + w

    def lie_correction(self, v, p):
        """Zero: $\\mathbb{R}^n$ is abelian."""
        return jnp.zeros_like(p)

    def coordinates(self, b):
        """The coordinate vector that solutions report for the base point."""
        return b

    def orientation(self, b):
        """None: there is no group part."""
        return None

    def pack(self, b):
        """The base point as a flat vector (for ODE solvers)."""
        return b

    def unpack(self, y):
        """Inverse of :meth:`pack`."""
        return y

    def pack_velocity(self, b, v):
        """$d/dt$ of `pack(b)` along the velocity `v`."""
        return v


class Point(NamedTuple):
    """A point $b = (x, R)$ of $\\mathbb{R}^n \\times G$ ($R$ a group matrix)."""

    x: jax.Array
    R: jax.Array


class GroupSpace(eqx.Module):
    """The configuration space $\\mathbb{R}^n \\times G$ with velocities in left trivialization.

    A base point is a :class:`Point` $(x, R)$; a velocity is $v = (\\dot x, \\xi) \\in \\mathbb{R}^{n+d}$
    with $\\xi = R^{-1}\\dot R$; the step unknowns are $z = (\\Delta x, \\sigma_k)$,
    $x_{k+1} = x_k + \\Delta x$ and
    $R_{k+1} = R_k\\tau(\\sigma_k)$, $\\sigma_k = h\\xi_k$ (paper §7.2).

    **Reconstruction.** For a *reduced* system (nothing depends on R, paper §7) the equations of
    $(x, \\xi)$ do not involve R, and R is only reconstructed from ξ. With `reconstruction="right"`
    ξ is read as the *space* velocity $\\xi = (\\dot R R^{-1})^\\vee$ (right trivialization):
    $\\dot R = \\hat\\xi R$, and the steps reconstruct $R_{k+1} = \\tau(\\sigma_k)R_k$. This is how the
    paper's §7.4 equations use ω (the rolling constraints hold for the space angular velocity: an
    erratum of the paper, on the docs' conventions page, "Errata in the paper"). The equations and
    steps of $(x, \\xi)$ are unchanged, to the last bit; only R differs. Systems that depend on R
    need the left-trivialized equations (:class:`~gnipy.System` refuses the right side for them).

    Arguments:
        n: dimension of the Euclidean factor (may be 0).
        group: a :class:`~gnipy.lie_groups.MatrixLieGroup`.
        retraction: a :class:`~gnipy.retractions.Retraction` (Cayley or exp).
        reconstruction: `"left"` (default: $\\dot R = R\\hat\\xi$, ξ the body velocity) or
            `"right"` ($\\dot R = \\hat\\xi R$, ξ the space velocity; reduced systems only).
    """

    n: int = eqx.field(static=True)
    group: object
    retraction: object
    reconstruction: str = eqx.field(static=True, default="left")

    @property
    def dim(self) -> int:
        """Dimension N = n + dim 𝔤 of the velocity space."""
        return self.n + self.group.dim

    def _split(self, w):
        return w[: self.n], w[self.n :]

    def tau(self, sigma):
        """The retraction $\\tau(\\sigma)$."""
        return self.retraction.tau(self.group, sigma)

    def reconstruct(self, R, g):
        """The orientation reached from `R` by the group increment `g`: $Rg$, or $gR$ with
        `reconstruction="right"` (ξ the space velocity, see the class docstring)."""
        return g @ R if self.reconstruction == "right" else R @ g

    def step_points(self, b0, z, h):
        """`(b1, b_mid, velocity)`: $b_1 = (x_0 + \\Delta x, R_0\\tau(\\sigma))$, the midpoint
        $(x_0 + \\Delta x/2, R_0\\tau(\\sigma/2))$ and the step velocity $(\\Delta x/h, \\sigma/h)$
        ($\\tau(\\sigma)R_0$, $\\tau(\\sigma/2)R_0$ with `reconstruction="right"`)."""
        dx, sigma = self._split(z)
        b1 = Point(b0.x + dx, self.reconstruct(b0.R, self.tau(sigma)))
        bm = Point(b0.x + 0.5 * dx, self.reconstruct(b0.R, self.tau(0.5 * sigma)))
        return b1, bm, z / h

    def constraint_velocity(self, z, h):
        """The step velocity on which a discrete constraint is imposed (discrete Lagrange–d'Alembert):
        $(\\Delta x/h,\\ \\mathrm{d}\\tau^{-1}_\\sigma\\sigma/h)$
        (:meth:`gnipy.retractions.Retraction.dtau_inv_along`), consistent with the momenta of
        :meth:`legendre_minus` and :meth:`legendre_plus`, which carry $\\partial l_d/\\partial\\sigma$ by
        $(\\mathrm{d}\\tau^{-1}_{\\pm\\sigma})^T$ ((RedLegTr)): on $\\mathbb{R}^n \\times SO(3)$ with a
        kinetic energy $\\tfrac12\\dot x^TM\\dot x + \\tfrac c2|\\xi|^2$, their group part is c times this
        velocity's. The plain $\\sigma/h$ is not: for
        the Cayley map and a rotation at rate ω it is $\\omega(1 + h^2|\\omega|^2/12)$ where the momentum
        holds $c\\,\\omega(1 + h^2|\\omega|^2/3)$ (to $O(h^4)$). With the exponential map it is
        $(\\Delta x, \\sigma)/h$, the velocity of :meth:`step_points`."""
        dx, sigma = self._split(z)
        return jnp.concatenate([dx / h, self.retraction.dtau_inv_along(self.group, sigma) / h])

    def end_coordinates(self, b0, z):
        """$(x_{k+1}, \\sigma_k)$ from $(\\Delta x, \\sigma_k)$."""
        dx, sigma = self._split(z)
        return jnp.concatenate([b0.x + dx, sigma])

    def advance(self, b0, z):
        """$(x_k + \\Delta x, R_k\\tau(\\sigma_k))$ (or $\\tau(\\sigma_k)R_k$, :meth:`reconstruct`)."""
        dx, sigma = self._split(z)
        return Point(b0.x + dx, self.reconstruct(b0.R, self.tau(sigma)))

    def advance_compensated(self, b0, err, z):
        """:meth:`advance` with the Euclidean part summed with compensation (:func:`compensated_add`):
        `(b_{k+1}, err_{k+1})`, `err` of the shape of x."""
        dx, sigma = self._split(z)
        x1, err1 = compensated_add(b0.x, dx, err)
        return Point(x1, self.reconstruct(b0.R, self.tau(sigma))), err1

    def initial_guess(self, b0, v, h):
        """$(h\\dot x, h\\xi)$."""
        return h * v

    def _grads(self, ld, b0, z):
        """Gradients of $l_d$ with respect to $x_k$ and the left-trivialized $R_k$ (both at fixed z)
        and z."""
        d = self.group.dim
        eye = jnp.eye(self.group.matrix_size, dtype=z.dtype)

        def f(x0, eta, z_):
            # the left-trivialized gradient is the derivative along R exp(t η) at t = 0, which equals
            # the derivative along R (I + t η̂) for any function of the matrix entries: the first-order
            # curve gives the same value (and the same mixed derivatives in z) with far fewer operations
            # than the exponential's series and branches (a GNI step evaluates this in every iteration)
            return ld(Point(x0, b0.R @ (eye + self.group.hat(eta))), z_)

        return jax.grad(f, argnums=(0, 1, 2))(b0.x, jnp.zeros(d, dtype=z.dtype), z)

    def legendre_minus(self, ld: Callable, b0, z):
        """$FL^- = (-\\partial l_d/\\partial x_k,\\ (d\\tau^{-1}_{\\sigma})^T \\partial l_d/\\partial\\sigma - \\nabla^L_{R_k} l_d)$
        ((RedLegTr)), with $\\partial/\\partial x_k$ at fixed $x_{k+1}$: with the increment as
        unknown, $\\partial_{x_k}|_{\\Delta x} - \\partial_{\\Delta x}$."""
        gx0, gR, gz = self._grads(ld, b0, z)
        _, sigma = self._split(z)
        gdx, gs = self._split(gz)
        dtinv = self.retraction.dtau_inv(self.group, sigma)
        return jnp.concatenate([gdx - gx0, dtinv.T @ gs - gR])

    def legendre_plus(self, ld: Callable, b0, z):
        """$FL^+ = (\\partial l_d/\\partial x_{k+1},\\ (d\\tau^{-1}_{-\\sigma})^T \\partial l_d/\\partial\\sigma)$ ((RedLegTr))."""
        gz = jax.grad(ld, argnums=1)(b0, z)
        _, sigma = self._split(z)
        gx1, gs = self._split(gz)
        dtinv = self.retraction.dtau_inv(self.group, -sigma)
        return jnp.concatenate([gx1, dtinv.T @ gs])

    def legendre_jump(self, ld: Callable, b0, z):
        """$FL^+ - FL^- = (\\partial l_d/\\partial x_k|_{\\Delta x},\\ (d\\tau^{-1}_{-\\sigma} - d\\tau^{-1}_\\sigma)^T
        \\partial l_d/\\partial\\sigma + \\nabla^L_{R_k} l_d)$, the difference of the dτ⁻¹ taken in closed
        form (:meth:`gnipy.retractions.Retraction.dtau_inv_jump`: $\\mathrm{ad}_\\sigma$ for Cayley and exp)."""
        gx0, gR, gz = self._grads(ld, b0, z)
        _, sigma = self._split(z)
        _, gs = self._split(gz)
        jump = self.retraction.dtau_inv_jump(self.group, sigma)
        return jnp.concatenate([gx0, jump.T @ gs + gR])

    def move(self, b, w):
        """$(x + w_x, R\\exp(w_\\xi))$ (or $\\exp(w_\\xi)R$, :meth:`reconstruct`)."""
        wx, wxi = self._split(w)
        return Point(b.x + wx, self.reconstruct(b.R, self.group.exp(wxi)))

    def lie_correction(self, v, p):
        """$(0, \\mathrm{ad}^*_\\xi p_{\\mathfrak g})$: the term of $\\frac{d}{dt}\\partial l/\\partial\\xi - \\mathrm{ad}^*_\\xi\\partial l/\\partial\\xi$."""
        _, xi = self._split(v)
        _, pg = self._split(p)
        return jnp.concatenate([jnp.zeros(self.n, dtype=p.dtype), self.group.ad_star(xi, pg)])

    def coordinates(self, b):
        """The Euclidean coordinates x."""
        return b.x

    def orientation(self, b):
        """The group element R (a matrix)."""
        return b.R

    def pack(self, b):
        """$(x, \\mathrm{vec}\\,R)$ as one flat vector."""
        return jnp.concatenate([b.x, b.R.reshape(-1)])

    def unpack(self, y):
        """Inverse of :meth:`pack`."""
        k = self.group.matrix_size
        return Point(y[: self.n], y[self.n :].reshape(k, k))

    def pack_velocity(self, b, v):
        """$d/dt\\,(x, \\mathrm{vec}\\,R) = (\\dot x, \\mathrm{vec}(R\\hat\\xi))$ (reconstruction
        $\\dot R = R\\hat\\xi$; $\\dot R = \\hat\\xi R$ with `reconstruction="right"`)."""
        xd, xi = self._split(v)
        return jnp.concatenate([xd, self.reconstruct(b.R, self.group.hat(xi)).reshape(-1)])
