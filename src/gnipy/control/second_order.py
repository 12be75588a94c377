"""The exact Hessian of single shooting's Lagrangian by the second-order adjoint, for IPOPT
(:mod:`gnipy.control.ipopt`).

Single shooting's run is $s_0 = f_{init}(u_0)$, $s_{k+1} = f_k(s_k, u_k)$ ($s$ the method's state,
flattened; the start depends on the first input through the consistent impulse, and the step
through its held input), and the target $g$ reads the last node. The Lagrangian
$L(u) = \\sigma J(u) + \\lambda\\cdot g(s_K, u_0)$ then has the Hessian (the discrete second-order
adjoint; e.g. Griewank & Walther, *Evaluating Derivatives*, 2nd ed., SIAM 2008, ch. 5, for its
derivation)

$$\\nabla^2 L = \\sum_{k<K} M_k^T W_k M_k + E_0^T\\nabla^2_u(a_0\\cdot f_{init})E_0
  + M_K^T\\nabla^2\\varphi\\,M_K + \\sigma\\nabla^2 J,$$

with the sensitivities $S_0 = \\partial_u f_{init}E_0$, $S_{k+1} = A_kS_k + B_kE_k$ ($A_k$, $B_k$
the step's Jacobians with respect to its state and its input, $E_k$ the selection of $u_k$),
$M_k = [S_k; E_k]$ ($M_K = [S_K; E_0]$), the adjoints $a_K = \\partial_s\\varphi$, $a_k = A_k^Ta_{k+1}$ of
$\\varphi = \\lambda\\cdot g$, and $W_k = \\nabla^2_{(s,u)}(a_{k+1}\\cdot f_k)$ at the run's nodes.
Each step is differentiated on its own (its few state and input numbers as tangents, all steps at
once by `vmap`). The sum is not formed from the sensitivities (K·n numbers per state number, and
$O(K n^2 s)$ work for n controls): a backward sweep carries the second-order adjoint
$P_k = A_k^TP_{k+1}A_k + W^{ss}_k$ ($P_K = \\nabla^2_{ss}\\varphi$) and, for every later control
j, $\\Phi(j, k+1)^TG_j$ with $G_j = W^{su}_j + A_j^TP_{j+1}B_j$ and $\\Phi$ the products of the
$A$s, which give $\\partial^2L/\\partial u_k\\partial u_j = B_k^T\\Phi(j, k+1)^TG_j$ for $k < j$ and
$W^{uu}_k + B_k^TP_{k+1}B_k$ for $k = j$: $O(K n s^2)$ work. (The terminal's observation also reads
the first input, so the state carries a copy of $u_0$ through the sweep.) The result equals
forward over reverse mode through the whole run, which carries one tangent per control through
every step, to round-off (tested), and was 4-19 times faster on the worked problems (the control
guide). Written here because no JAX library computes a Hessian through a recurrence this way.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

__all__ = ["adjoint_hessian"]


def adjoint_hessian(single, U, lam, sigma):
    """$\\nabla^2(\\sigma J + \\lambda\\cdot g)$ of the single-shooting problem `single`
    (:class:`gnipy.control.shooting.SingleShooting`, no running cost) at the controls `U` (K, m),
    flattened (K·m, K·m) as the controls are; None where the method's state is not made of floats
    only (the caller then uses forward over reverse mode through the run)."""
    from ..forcing import drive
    from ..problem import resolve_method
    from ..transformed import traced_method, traced_point

    K, m, h = single.K, single.m, single.h
    # the method as the compiled run has it, without the state that only makes steps cheaper (DLA's kept
    # Jacobian), which the steps' derivatives must not see
    method = traced_method(resolve_method(single.system, single.method)).memoryless()
    # the inputs enter through each step's held input (set below); the drive's table is the run's grid
    core = drive(single.system, jax.lax.stop_gradient(U), h, single.t0, K).without_metadata()
    b0 = traced_point(single.system, single.q0, single.R0)
    v0 = jnp.asarray(single.v0, jnp.float64)

    def holding(system, u):
        return eqx.tree_at(lambda s: s.drive.held, system, u)

    state0 = method.init(holding(core, U[0]), b0, v0, h)
    if not all(jnp.issubdtype(leaf.dtype, jnp.floating) for leaf in jax.tree_util.tree_leaves(state0)):
        return None
    flat0, unravel = ravel_pytree(state0)

    def init(u):
        return ravel_pytree(method.init(holding(core, u), b0, v0, h))[0]

    def step(k, s, u):
        return ravel_pytree(method.step(holding(core.at_step(k), u), unravel(s), h)[0])[0]

    def terminal(s, u0):  # φ = λ·g at the last node, observed as the run observes it
        b, v, _ = method.observe(holding(core, u0), unravel(s), h)
        return lam @ single.g(b, v)

    ks = jnp.arange(K)
    sK, ss = jax.lax.scan(lambda s, k: (step(k, s, U[k]), s), init(U[0]), ks)  # ss[k] = s_k
    A, B = jax.vmap(jax.jacfwd(step, argnums=(1, 2)))(ks, ss, U)
    a_K = jax.grad(terminal)(sK, U[0])
    a_0, a_next = jax.lax.scan(lambda a, k: (A[k].T @ a, a), a_K, ks, reverse=True)  # a_next[k] = a_{k+1}
    W = jax.vmap(jax.hessian(lambda s, u, k, a: a @ step(k, s, u), argnums=(0, 1)))(ss, U, ks, a_next)
    # the state carries a copy c of u_0 (the terminal's observation reads the first input), so that u_0
    # enters the run at the start only (ŝ_0 = (f_init(u_0), u_0)) besides its own step
    ns, n = flat0.size, K * m
    eye_c, zeros_sc = jnp.eye(m), jnp.zeros((ns, m))

    def hat_A(Ak):
        return jnp.block([[Ak, zeros_sc], [zeros_sc.T, eye_c]])

    def hat_B(Bk):
        return jnp.concatenate([Bk, jnp.zeros((m, m))], axis=0)

    def sweep(carry, k):
        P, Y = carry  # P̂_{k+1}; Y[:, block j] = Φ̂(j, k+1)ᵀ Ĝ_j for the controls j > k, zero for j <= k
        Ak, Bk = hat_A(A[k]), hat_B(B[k])
        PB = P @ Bk
        Gk = jnp.concatenate([W[0][1][k], jnp.zeros((m, m))], axis=0) + Ak.T @ PB  # Ŵsu_k + Âᵀ P̂ B̂
        row = Bk.T @ Y  # H[u_k, u_j] for j > k
        diagonal = W[1][1][k] + Bk.T @ PB
        Wss = jnp.block([[W[0][0][k], zeros_sc], [zeros_sc.T, jnp.zeros((m, m))]])
        Y = jax.lax.dynamic_update_slice(Ak.T @ Y, Gk, (0, k * m))
        return (Ak.T @ P @ Ak + Wss, Y), (row, diagonal)

    P_K = _blocks(jax.hessian(terminal, argnums=(0, 1))(sK, U[0]))
    (P_0, Y_0), (rows, diagonals) = jax.lax.scan(sweep, (P_K, jnp.zeros((ns + m, n))), ks, reverse=True)
    upper = rows.reshape(n, n)  # row block k: H[u_k, u_j] for j > k, zeros for j <= k
    at = ks[:, None] * m + jnp.arange(m)  # the rows of u_k
    H = (upper + upper.T).at[at[:, :, None], at[:, None, :]].add(diagonals)
    # u_0 at the start, ŝ_0 = (f_init(u_0), u_0): its own curvature and its pairs with every control
    C = jnp.concatenate([jax.jacfwd(init)(U[0]), eye_c], axis=0)
    start = jax.hessian(lambda u: a_0 @ init(u))(U[0]) + C.T @ P_0 @ C
    cross = C.T @ Y_0  # (m, n): u_0's start against every control, u_0's own step included
    H = H.at[:m, :].add(cross).at[:, :m].add(cross.T).at[:m, :m].add(start)
    return H + sigma * jax.hessian(single.effort_cost)(U).reshape(n, n)


def _blocks(W):
    """The Hessian over `(s, u)` as one matrix from JAX's nested blocks ((ss, su), (us, uu)); a
    leading batch axis is kept."""
    return jnp.concatenate([jnp.concatenate([W[0][0], W[0][1]], -1), jnp.concatenate([W[1][0], W[1][1]], -1)], -2)
