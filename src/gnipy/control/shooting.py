"""The shooting transcriptions of a discrete optimal-control problem
(:func:`gnipy.control.optimal_control.solve_optimal_control`, whose docstring states the problem
and why single shooting is the default): :class:`SingleShooting` (the controls the unknowns, the
states by the steps), :class:`MultipleShooting` (the method's state at the segments' starts
unknowns too, the defects constraints), and :func:`sqp_problem`, the problem the SQP solves.
Each is an equinox Module whose numbers are arrays, so that the SQP's compiled programs
(:meth:`gnipy.control.sqp.Functions.of`) serve every problem of one structure."""

from __future__ import annotations

import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..saveat import SaveAt
from ..simulate import simulate
from .control_arguments import ControlArguments
from .second_order import adjoint_hessian
from .sqp import Functions, SQPProblem

__all__ = ["SingleShooting", "MultipleShooting", "ControlsProblem", "sqp_problem", "final_point"]


class SingleShooting(eqx.Module):
    """The functions of single shooting: the unknowns are the controls (K, m); the states are
    eliminated by the steps themselves (a run from the start). A pytree whose numbers are arrays:
    problems of one structure (system, method, target's shape, K, m) share the compiled programs
    whatever their numbers (start, step, weights, target values, warm start)."""

    system: Any
    method: Any
    g: Any
    q0: Any
    v0: Any
    R0: Any
    h: jax.Array
    t0: jax.Array
    effort: jax.Array
    smoothness: jax.Array
    ts: jax.Array
    K: int = eqx.field(static=True)
    m: int = eqx.field(static=True)
    smooth: bool = eqx.field(static=True)
    running_cost: Any = eqx.field(static=True)

    @classmethod
    def make(cls, system, method, g, q0, v0, R0, a: ControlArguments, running_cost) -> "SingleShooting":
        """The single-shooting functions of a problem."""
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        return cls(system=system, method=method, g=g, q0=f64(q0), v0=f64(v0), R0=None if R0 is None else f64(R0),
                   h=f64(a.h), t0=f64(a.t0), effort=f64(a.effort), smoothness=f64(a.smoothness),
                   ts=f64(a.t0 + a.h * np.arange(a.K)), K=int(a.K), m=int(a.m), smooth=bool(a.smoothness),
                   running_cost=running_cost)

    def run(self, U, concrete: bool = False):
        """The run driven by the controls `U` (every node); `concrete`: outside a compiled program
        (the step and start time as numbers, as a run the user makes)."""
        h, t0 = (float(self.h), float(self.t0)) if concrete else (self.h, self.t0)
        # compiled, a failed step leaves NaN nodes (throw=False), which the SQP's host side turns into a
        # SolverFailure (gnipy.control.sqp): no host callback, so JAX's persistent cache keeps the programs
        return simulate(self.system, self.method, self.q0, self.v0, R0=self.R0, h=h, steps=self.K, controls=U, t0=t0,
                        throw=concrete)

    def check(self, U0, controls: int) -> tuple[str, int]:
        """`(the method's name, the number of the target's components)`: the problem checked once,
        eagerly, by a run from the warm start `U0`: the start, the method, the target's shape (clear
        errors before anything is compiled; no more components than `controls`)."""
        # the same run as the result's (every node): one compiled program for both
        first = self.run(U0, concrete=True)
        g0 = np.asarray(self.g(final_point(self.system, first), first.v[-1]))
        if g0.ndim != 1 or g0.size == 0:
            raise InputError(f"target: the residual g(b, v) must be a non-empty vector, got shape {g0.shape}")
        if g0.size > controls:
            raise InputError(f"target: {g0.size} conditions on {controls} controls; use more steps")
        return first.method, len(g0)

    def effort_cost(self, U):
        """The effort and smoothness terms of the cost."""
        J = 0.5 * self.effort * self.h * jnp.sum(U**2)
        if self.smooth:
            J = J + 0.5 * self.smoothness / self.h * jnp.sum(jnp.diff(U, axis=0) ** 2)
        return J

    def cost(self, U):
        """The cost J(U)."""
        J = self.effort_cost(U)
        if self.running_cost is not None:
            sol = self.run(U)
            K = self.K
            J = J + self.h * jnp.sum(jax.vmap(self.running_cost)(sol.q[:K], sol.v[:K], U, self.ts))
        return J

    def constraint(self, U):
        """The target's residual g at the end of the run."""
        sol = self.run(U)
        return self.g(final_point(self.system, sol), sol.v[-1])

    def continuous_miss(self, U) -> float:
        """$\\max|g|$ when the held controls `U` drive the continuous system (the reference); inf
        when that run fails."""
        from ..errors import SolverFailure

        try:
            ref = simulate(self.system, "reference", self.q0, self.v0, R0=self.R0, h=float(self.h), steps=self.K,
                           controls=U, t0=float(self.t0), saveat=SaveAt(t1=True))
            return float(np.max(np.abs(np.asarray(self.g(final_point(self.system, ref), ref.v[-1])))))
        except SolverFailure:
            return float("inf")


class ControlsProblem(eqx.Module):
    """Single shooting as a function of the flattened controls (K·m,)."""

    single: SingleShooting
    shape: tuple = eqx.field(static=True)

    def cost(self, u):
        return self.single.cost(u.reshape(self.shape))

    def constraints(self, u):
        return self.single.constraint(u.reshape(self.shape))

    def lagrangian_hessian(self, u, lam, sigma):
        """$\\nabla^2(\\sigma J + \\lambda\\cdot g)$ by the second-order adjoint
        (:func:`gnipy.control.second_order.adjoint_hessian`), or None where it does not apply (a
        running cost; a method state that is not all floats): forward over reverse mode then."""
        if self.single.running_cost is not None:
            return None
        return adjoint_hessian(self.single, u.reshape(self.shape), lam, sigma)


def sqp_problem(single: SingleShooting, a: ControlArguments, U0, running_cost, n_target: int) -> SQPProblem:
    """The problem the SQP solves: single shooting on the controls with one segment, else multiple
    shooting on the controls and the segments' states; the cost scaled for SLSQP."""
    shape = (a.K, a.m)
    # the single-shooting functions of the controls: the polish, the KKT check and (one segment)
    # the SQP itself
    controls = Functions.of(ControlsProblem(single, shape))
    lo_x, hi_x = np.tile(a.lo, a.K), np.tile(a.hi, a.K)
    if a.segments == 1:
        x0, x_lo, x_hi, unknowns = U0.ravel(), np.tile(a.lo, a.K), np.tile(a.hi, a.K), controls
    else:
        if a.segments == a.K:  # every step a segment: one vectorized program, sparse derivatives
            from .step_shooting import SparseFunctions, StepShooting

            shooting = StepShooting.make(single, U0)
            unknowns = SparseFunctions.of_steps(shooting, n_target)
        else:
            shooting = MultipleShooting.make(single, a.segments, U0)
            unknowns = Functions.of(shooting)
        s0 = np.asarray(shooting.s0).ravel()
        x0 = np.concatenate([U0.ravel(), s0])
        x_lo = np.concatenate([lo_x, np.full(s0.size, -np.inf)])
        x_hi = np.concatenate([hi_x, np.full(s0.size, np.inf)])
    # SLSQP starts its quasi-Newton Hessian at the identity; the effort's Hessian is h w I, so the
    # cost is divided by h w (its first steps are otherwise 1/(h w) too long)
    scale = 1.0 / (a.h * a.effort) if a.effort > 0 else 1.0 / a.h
    effort_only = running_cost is None and not a.smoothness and a.segments == 1
    return SQPProblem(controls=controls, unknowns=unknowns, single=a.segments == 1, x0=x0, x_lo=x_lo, x_hi=x_hi,
                      lo=lo_x, hi=hi_x, n_target=n_target, scale=scale,
                      hessian=scale * a.h * a.effort if effort_only else None)


class MultipleShooting(eqx.Module):
    """The functions of multiple shooting: the unknowns are the controls and, for segments 2..S,
    the method's state at the segment's start, $s_j = (x_j, \\eta_j, p^+_j)$ with the orientation
    $R_j = \\bar R_j\\exp(\\hat\\eta_j)$ about the warm start's $\\bar R_j$; the constraints are the
    defects at the boundaries (the end of segment j − 1 minus $s_j$; $\\log(R_j^{-1}R_{end})$ for
    the orientation) and the target at the end of the last segment. A pytree like
    :class:`SingleShooting`: compiled once per structure."""

    single: SingleShooting
    Rbar: Any  # the warm start's orientations at the boundaries, or None
    s0: jax.Array  # the warm start's states at the boundaries (the unknowns' first guess)
    cuts: tuple = eqx.field(static=True)
    n: int = eqx.field(static=True)
    N: int = eqx.field(static=True)
    d: int = eqx.field(static=True)

    @classmethod
    def make(cls, single: SingleShooting, S: int, U0) -> "MultipleShooting":
        """The multiple-shooting functions of `single`'s problem with S segments, about the run
        of the warm start `U0`."""
        from ..integrators.gni import GNIState

        system, K, h, t0 = single.system, single.K, float(single.h), float(single.t0)
        cuts = tuple(int(c) for c in np.linspace(0, K, S + 1).round().astype(int))
        # the warm start's states at the boundaries: the first guesses and the orientations R̄_j
        guess = simulate(system, single.method, single.q0, single.v0, R0=single.R0, h=h, steps=K, controls=U0, t0=t0,
                         saveat=SaveAt(ts=t0 + h * np.asarray(cuts[1:-1]), states=True))
        states = guess.states
        if not isinstance(states, GNIState):
            raise InputError(f"segments: multiple shooting needs a method whose state is (b, p+) (the GNI family), "
                             f"not {guess.method}")
        space = system.space
        n, N = system.n, system.dim
        d = 0 if system.group is None else system.group.dim
        x = np.asarray(space.coordinates(states.b)).reshape(S - 1, n)
        Rbar = None if system.group is None else jnp.asarray(space.orientation(states.b))
        p = np.asarray(states.p_plus).reshape(S - 1, N)
        s0 = np.concatenate([x, np.zeros((S - 1, d)), p], axis=1).ravel()
        return cls(single=single, Rbar=Rbar, s0=jnp.asarray(s0), cuts=cuts, n=n, N=N, d=d)

    def _state(self, j, s):
        from ..integrators.gni import GNIState
        from ..spaces import Point

        x, eta, p = s[: self.n], s[self.n : self.n + self.d], s[self.n + self.d :]
        system = self.single.system
        b = x if system.group is None else Point(x, self.Rbar[j] @ system.group.exp(eta))
        return GNIState(b, p, jnp.zeros_like(x))

    def _runs(self, x):
        one = self.single
        K, m, S = one.K, one.m, len(self.cuts) - 1
        U = x[: K * m].reshape(K, m)
        svars = x[K * m :].reshape(S - 1, self.n + self.d + self.N)
        save = SaveAt(steps=True, states=True) if one.running_cost is not None else SaveAt(t1=True, states=True)
        sols = []
        for j in range(S):
            k0, k1 = int(self.cuts[j]), int(self.cuts[j + 1])
            common = dict(h=one.h, steps=k1 - k0, controls=U[k0:k1], t0=one.t0 + k0 * one.h, saveat=save,
                          throw=False)  # NaN after a failed step, no host callback (SingleShooting.run)
            if j == 0:
                sols.append(simulate(one.system, one.method, one.q0, one.v0, R0=one.R0, **common))
            else:
                sols.append(simulate(one.system, one.method, state0=self._state(j - 1, svars[j - 1]), **common))
        return U, svars, sols

    def constraints(self, x):
        U, svars, sols = self._runs(x)
        system = self.single.system
        space = system.space
        parts = []
        for j in range(1, len(sols)):
            end = sols[j - 1].final_state
            start = self._state(j - 1, svars[j - 1])
            parts.append(space.coordinates(end.b) - space.coordinates(start.b))
            if system.group is not None:
                parts.append(system.group.log(space.orientation(start.b).T @ space.orientation(end.b)))
            parts.append(end.p_plus - start.p_plus)
        last = sols[-1]
        parts.append(self.single.g(final_point(system, last), last.v[-1]))
        return jnp.concatenate(parts)

    def cost(self, x):
        one = self.single
        U = x[: one.K * one.m].reshape(one.K, one.m)
        J = one.effort_cost(U)
        if one.running_cost is not None:
            _, _, sols = self._runs(x)
            q = jnp.concatenate([s.q[:-1] for s in sols])
            v = jnp.concatenate([s.v[:-1] for s in sols])
            J = J + one.h * jnp.sum(jax.vmap(one.running_cost)(q, v, U, one.ts))
        return J



def final_point(system, sol):
    """The base point at the solution's last node."""
    from ..spaces import Point

    if system.group is None:
        return sol.q[-1]
    return Point(sol.q[-1], sol.R[-1])
