"""Multiple shooting with every step a segment (`segments = steps`), as one vectorized program with
sparse derivatives: the transcription IPOPT is made for (:mod:`gnipy.control.ipopt`).

The unknowns are the controls $u_0, \\dots, u_{K-1}$ and the method's state after every step,
$s_{k+1} = (b_{k+1}, p^+_{k+1})$, flattened ($b = x$, or $(x, R)$ with the nine entries of R on
$\\mathbb{R}^n\\times G$, as a simultaneous transcription has them: no chart about a reference
orientation, which a long rotation would leave); the start $s_0 = f_{init}(u_0)$ is the method's
own (the consistent impulse depends on the first input). The constraints are the defects
$f_k(s_k, u_k) - s_{k+1} = 0$ of every step (the GNI's step, its implicit equations solved inside
it and differentiated by the implicit function theorem) and the target $g$ at the last node. All
K steps are evaluated at once (`vmap`), not in a sequence, so a call costs about one step's work
per step and no loop; and each defect depends on $(s_k, u_k, s_{k+1})$ only, so the constraints'
Jacobian has $K\\,n_s(n_s + m + 1)$ nonzeros and the Hessian of the Lagrangian is block diagonal
over the steps ($\\nabla^2_{(s_k, u_k)}(\\lambda_k\\cdot f_k)$), plus the target's block over
$(s_K, u_0)$ and the cost's band: both handed to IPOPT as sparse (triplets), which factors them
with MUMPS. Why beside single shooting: single shooting's derivatives come from sweeps along the
run (a loop of K dependent steps, run once per sweep) and its Hessian is dense; here nothing is
sequential, which is what made CasADi's simultaneous transcription of the worked problems fast
(BENCHMARKS.md section 11). Every iterate is a trajectory only at convergence: the result is
polished and checked by single shooting, as every other (:func:`gnipy.control.sqp.finish_stage`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ..compilation import bind
from ..errors import InputError
from ..saveat import SaveAt
from ..simulate import simulate
from .sqp import AtPoint, Functions, cost_and_gradient, finite_hessian

__all__ = ["StepShooting", "SparseFunctions"]


class StepShooting(eqx.Module):
    """The functions of multiple shooting with every step a segment (module docstring) of the
    single-shooting problem `single` (:class:`gnipy.control.shooting.SingleShooting`, no running
    cost): unknowns $x = (u_0, \\dots, u_{K-1}, s_1, \\dots, s_K)$. A pytree whose numbers are
    arrays, compiled once per structure like the others."""

    single: Any
    s0: jax.Array  # the warm start's states after every step, (K, ns): the unknowns' first guess
    ns: int = eqx.field(static=True)

    @classmethod
    def make(cls, single, U0) -> "StepShooting":
        """The transcription of `single`'s problem about the run of the warm start `U0`."""
        from ..integrators.gni import GNIState

        if single.running_cost is not None:
            raise InputError("segments: every step a segment (segments = steps) does not take a running cost; "
                             "use fewer segments")
        K, h, t0 = single.K, float(single.h), float(single.t0)
        guess = simulate(single.system, single.method, single.q0, single.v0, R0=single.R0, h=h, steps=K, controls=U0,
                         t0=t0, saveat=SaveAt(steps=True, states=True))
        states = guess.states
        if not isinstance(states, GNIState):
            raise InputError(f"segments: multiple shooting needs a method whose state is (b, p+) (the GNI family), "
                             f"not {guess.method}")
        after = jax.tree_util.tree_map(lambda a: a[1:], (states.b, states.p_plus))
        s0 = jax.vmap(lambda b, p: ravel_pytree((b, p))[0])(*after)
        return cls(single=single, s0=jnp.asarray(s0, jnp.float64), ns=int(s0.shape[1]))

    # -- the pieces: the method as a compiled run has it, the start, a step, the target -----------------
    def _pieces(self):
        from ..forcing import drive
        from ..problem import resolve_method
        from ..transformed import traced_method, traced_point

        one = self.single
        method = traced_method(resolve_method(one.system, one.method)).memoryless()
        # the drive's table is not used (each step's held input is set): zeros of the right shape
        core = drive(one.system, jnp.zeros((one.K, one.m)), one.h, one.t0, one.K).without_metadata()
        b0 = traced_point(one.system, one.q0, one.R0)
        v0 = jnp.asarray(one.v0, jnp.float64)

        def holding(system, u):
            return eqx.tree_at(lambda s: s.drive.held, system, u)

        state0 = method.init(holding(core, jnp.zeros(one.m)), b0, v0, one.h)
        _, unravel = ravel_pytree((state0.b, state0.p_plus))

        def as_state(s):  # a GNIState; the compensated sum's rounding error starts from zero at every node
            b, p = unravel(s)
            return state0._replace(b=b, p_plus=p, x_err=None if state0.x_err is None else jnp.zeros_like(state0.x_err))

        def init(u):
            state = method.init(holding(core, u), b0, v0, one.h)
            return ravel_pytree((state.b, state.p_plus))[0]

        def step(k, s, u):
            # a step whose solve fails is NaN, as in a compiled run (simulate's throw=False): the optimizer's
            # host side stops or shortens its step there (gnipy.control.sqp.AtPoint)
            state, info = method.step(holding(core.at_step(k), u), as_state(s), one.h)
            return jnp.where(info.ok, ravel_pytree((state.b, state.p_plus))[0], jnp.nan)

        def terminal(s, u0):  # the target at the last node, observed as the run observes it
            b, v, _ = method.observe(holding(core, u0), as_state(s), one.h)
            return one.g(b, v)

        return init, step, terminal

    def split(self, x):
        """`(U (K, m), S (K, ns))` of the unknowns."""
        K, m = self.single.K, self.single.m
        return x[: K * m].reshape(K, m), x[K * m:].reshape(K, self.ns)

    def cost(self, x):
        return self.single.effort_cost(self.split(x)[0])

    def constraints(self, x):
        init, step, terminal = self._pieces()
        U, S = self.split(x)
        before = jnp.concatenate([init(U[0])[None], S[:-1]])
        defects = jax.vmap(step)(jnp.arange(self.single.K), before, U) - S
        return jnp.concatenate([defects.ravel(), terminal(S[-1], U[0])])

    def jacobian_values(self, x):
        """The constraints and the values of their Jacobian in the order of :meth:`jacobian_structure`."""
        init, step, terminal = self._pieces()
        U, S = self.split(x)
        K = self.single.K
        ks = jnp.arange(K)
        s_0 = init(U[0])
        before = jnp.concatenate([s_0[None], S[:-1]])
        F = jax.vmap(step)(ks, before, U)
        A, B = jax.vmap(jax.jacfwd(step, argnums=(1, 2)))(ks, before, U)
        # u_0 enters the first step also through the start
        B = B.at[0].add(A[0] @ jax.jacfwd(init)(U[0]))
        g = terminal(S[-1], U[0])
        Gs, Gu = jax.jacfwd(terminal, argnums=(0, 1))(S[-1], U[0])
        values = jnp.concatenate([B.ravel(), A[1:].ravel(), -jnp.ones(K * self.ns), Gs.ravel(), Gu.ravel()])
        return jnp.concatenate([(F - S).ravel(), g]), values

    def jacobian_structure(self, n_target: int) -> tuple[np.ndarray, np.ndarray]:
        """`(rows, cols)` of the Jacobian's nonzeros, in the order of :meth:`jacobian_values`."""
        K, m, ns = self.single.K, self.single.m, self.ns
        k, i, j = np.meshgrid(np.arange(K), np.arange(ns), np.arange(m), indexing="ij")
        rows, cols = [(k * ns + i).ravel()], [(k * m + j).ravel()]  # B_k: defect k, u_k
        k, i, j = np.meshgrid(np.arange(1, K), np.arange(ns), np.arange(ns), indexing="ij")
        rows.append((k * ns + i).ravel())
        cols.append((K * m + (k - 1) * ns + j).ravel())  # A_k: defect k, s_k (the unknown s_{k-1}+1)
        d = np.arange(K * ns)
        rows.append(d)
        cols.append(K * m + d)  # -I: defect k, s_{k+1}
        i, j = np.meshgrid(np.arange(n_target), np.arange(ns), indexing="ij")
        rows.append((K * ns + i).ravel())
        cols.append((K * m + (K - 1) * ns + j).ravel())
        i, j = np.meshgrid(np.arange(n_target), np.arange(m), indexing="ij")
        rows.append((K * ns + i).ravel())
        cols.append(j.ravel())
        return np.concatenate(rows), np.concatenate(cols)

    def hessian_values(self, x, lam, sigma):
        """The Hessian of $\\sigma J + \\lambda\\cdot c$ as blocks, in the order of :meth:`hessian_blocks`."""
        init, step, terminal = self._pieces()
        U, S = self.split(x)
        K, ns = self.single.K, self.ns
        lam_d, lam_g = lam[: K * ns].reshape(K, ns), lam[K * ns:]

        def weighted(k, s, u, a):
            return a @ step(k, s, u)

        W = jax.vmap(jax.hessian(weighted, argnums=(1, 2)))(jnp.arange(1, K), S[:-1], U[1:], lam_d[1:])
        W = jnp.concatenate([jnp.concatenate([W[0][0], W[0][1]], -1), jnp.concatenate([W[1][0], W[1][1]], -1)], -2)
        W0 = jax.hessian(lambda u: lam_d[0] @ step(0, init(u), u))(U[0])
        T = jax.hessian(lambda s, u: lam_g @ terminal(s, u), argnums=(0, 1))(S[-1], U[0])
        T = jnp.block([[T[0][0], T[0][1]], [T[1][0], T[1][1]]])
        n = U.size
        rows, cols = self._cost_band()
        HJ = sigma * jax.hessian(self.single.effort_cost)(U).reshape(n, n)[rows, cols]
        return jnp.concatenate([W.ravel(), W0.ravel(), T.ravel(), HJ])

    def _cost_band(self) -> tuple[np.ndarray, np.ndarray]:
        """The cost's Hessian's nonzeros, both triangles: the effort's diagonal and the smoothness's
        pairs $(u_k, u_{k+1})$ of each input (indices m apart)."""
        n, m = self.single.K * self.single.m, self.single.m
        i = np.arange(n)
        if not self.single.smooth:
            return i, i
        j = np.arange(n - m)
        return np.concatenate([i, j + m, j]), np.concatenate([i, j, j + m])

    def hessian_blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """`(rows, cols)` of every value :meth:`hessian_values` returns (full blocks, both triangles,
        repeated positions summed by the caller)."""
        K, m, ns = self.single.K, self.single.m, self.ns
        rows, cols = [], []
        for k in range(1, K):
            idx = np.concatenate([K * m + (k - 1) * ns + np.arange(ns), k * m + np.arange(m)])
            rows.append(np.repeat(idx, idx.size))
            cols.append(np.tile(idx, idx.size))
        u0 = np.arange(m)
        rows.append(np.repeat(u0, m))
        cols.append(np.tile(u0, m))
        idx = np.concatenate([K * m + (K - 1) * ns + np.arange(ns), u0])
        rows.append(np.repeat(idx, idx.size))
        cols.append(np.tile(idx, idx.size))
        band = self._cost_band()
        rows.append(band[0])
        cols.append(band[1])
        return np.concatenate(rows), np.concatenate(cols)


@dataclasses.dataclass(frozen=True)
class SparseFunctions(Functions):
    """:class:`gnipy.control.sqp.Functions` with the sparse derivatives IPOPT takes: the
    constraints' Jacobian and the lower triangle of the Lagrangian's Hessian as values at fixed
    `(rows, cols)` (`jacobian_structure`, `hessian_structure`). The dense Jacobian (SLSQP, the
    KKT check) is formed from the same values."""

    jacobian_structure: tuple = ()
    jacobian_values: Any = None
    hessian_structure: tuple = ()
    hessian_values: Any = None
    sparse = True

    @classmethod
    def of_steps(cls, problem: StepShooting, n_target: int) -> "SparseFunctions":
        """The compiled functions of `problem` (:class:`StepShooting`)."""
        n = problem.single.K * problem.single.m + problem.s0.size
        d = problem.single.K * problem.ns + n_target
        jrows, jcols = problem.jacobian_structure(n_target)
        hrows, hcols = problem.hessian_blocks()
        lower = hrows >= hcols
        # the lower triangle's distinct positions, and where each block value adds in
        pairs, where = np.unique(hrows[lower] * n + hcols[lower], return_inverse=True)
        cost = AtPoint(bind(cost_and_gradient, problem), "cost and its gradient")
        constraints = AtPoint(bind(_constraints_and_values, problem), "constraints and their Jacobian")
        hessian_program = bind(_hessian_values, problem)

        def dense(x):
            J = np.zeros((d, n))
            J[jrows, jcols] = constraints.second(x)
            return J

        def hessian_values(x, lam, sigma):
            v = finite_hessian(hessian_program(np.asarray(x, np.float64), np.asarray(lam, np.float64),
                                               np.asarray(sigma, np.float64)))
            return np.bincount(where, weights=v[lower], minlength=pairs.size)

        def hessian(x, lam, sigma):
            H = np.zeros((n, n))
            H[pairs // n, pairs % n] = hessian_values(x, lam, sigma)
            return H + np.tril(H, -1).T

        return cls(cost=cost.first, cost_gradient=cost.second, constraints=constraints.first,
                   constraints_jacobian=dense, hessian=hessian, jacobian_structure=(jrows, jcols),
                   jacobian_values=constraints.second, hessian_structure=(pairs // n, pairs % n),
                   hessian_values=hessian_values)


def _constraints_and_values(problem, x):
    return problem.jacobian_values(x)


def _hessian_values(problem, x, lam, sigma):
    return problem.hessian_values(x, lam, sigma)
