"""Two identities of the paper measured by gnipy: Theorem 5.2 (nonholonomic Euler A and B are each
other's adjoint, checked one step at a time on random states) and the energy theorem of §4 (a
GNI run on SO(3) with a bi-invariant metric conserves the energy).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ..compilation import jit
from ..discrete_lagrangians import EulerA
from ..integrators import paper_schemes as ps
from ..integrators.gni import GNI
from ..lie_groups import SO3
from ..system import System
from .records import EPS, ROUNDOFF_WALK, all_nodes

__all__ = ["constrained_tilde_states", "adjointness", "energy_theorem_system", "energy_theorem", "C_INERTIA",
           "ENERGY_H"]


# ------------------------------------------------------------------------------------------------
# Theorem 5.2
# ------------------------------------------------------------------------------------------------
def constrained_tilde_states(system, n_states: int, h: float, sign: float, seed: int) -> ps.TildeState:
    """Random $(q, \\tilde p, \\tilde\\lambda)$ (standard normal) with
    $\\mu M^{-1}(\\tilde p + \\mathrm{sign}\\,(h/2)V_q - \\Pi) = 0$ ($\\tilde p$ projected
    $M^{-1}$-orthogonally): sign = +1 is the domain of $F_B^{-h}$ (the output constraint (EuBHame)
    at step −h), where Theorem 5.2 applies."""
    rng = np.random.default_rng(seed)
    n = system.n
    m = system.num_constraints(jnp.zeros(n))
    q, p, lam = (jnp.asarray(rng.normal(size=(n_states, k))) for k in (n, n, m))
    return ps.TildeState(q, _project_tilde(system, q, p, jnp.asarray(h), jnp.asarray(sign)), lam)


@jit
def _project_tilde(system, q, p, h, sign):
    def project(q, p):
        M, mu = system.metric(q), system.mu(q)
        r = mu @ jnp.linalg.solve(M, p + sign * 0.5 * h * system.potential_gradient(q) - system.Pi(q))
        C = mu @ jnp.linalg.solve(M, mu.T)
        return p - mu.T @ jnp.linalg.solve(C, r)

    return jax.vmap(project)(q, p)


def _max_rel(out, states) -> jax.Array:
    """max over the components of max|out − s| / max(1, max|s|)."""
    return jnp.max(jnp.stack([jnp.max(jnp.abs(a - b)) / jnp.maximum(1.0, jnp.max(jnp.abs(b)))
                              for a, b in zip(out, states) if b is not None]))


def _manifold_residual(system, s, h):
    """$\\mu M^{-1}(\\tilde p + (h/2)V_q - \\Pi)$: zero on $M_A^h$, where $F_A^h$ starts ((EuAHamc))."""
    M = system.metric(s.q)
    return system.mu(s.q) @ jnp.linalg.solve(M, s.p_tilde + 0.5 * h * system.potential_gradient(s.q) - system.Pi(s.q))


@jit
def _round_trips(system, states, off_states, h):
    """Theorem 5.2 on a batch of states of $M_A^h$ (and a batch off it, for the control).

    Returns the residual of $F_A^h\\circ F_B^{-h}$ on $M_A^h$; how far $F_B^{-h}$ leaves $M_A^h$ (it
    maps $M_A^h$ into itself: the inverse of $F_A^h$ as a map of $M_A^h$); how far $F_A^{-h}$ leaves
    it (the control: the same formulas taken backwards are not that inverse); the residual of the
    round trip from states off $M_A^h$ (the control: the domain matters); and how far the
    intermediate state moved (the identity is not trivial)."""

    def one(s):
        mid = ps.euler_b_map(system, s, -h)
        back = ps.euler_a_map(system, mid, h)
        mid_a = ps.euler_a_map(system, s, -h)
        return back, jnp.max(jnp.abs(_manifold_residual(system, mid, h))), \
            jnp.max(jnp.abs(_manifold_residual(system, mid_a, h))), jnp.max(jnp.abs(mid.q - s.q))

    def off(s):
        return ps.euler_a_map(system, ps.euler_b_map(system, s, -h), h)

    back, mid_res, mid_a_res, moved = jax.vmap(one)(states)
    off_back = jax.vmap(off)(off_states)
    return (_max_rel(back, states), jnp.max(mid_res), jnp.max(mid_a_res), _max_rel(off_back, off_states),
            jnp.max(moved))


def adjointness(system, hs=(0.1, 0.01), seeds=(0, 1, 2), n_states=64) -> dict:
    """Theorem 5.2 over `len(seeds) * n_states` random states of $M_A^h$ for each h (see :func:`_round_trips`)."""
    out = {"residual": 0.0, "manifold_B": 0.0, "manifold_A": np.inf, "off_domain": np.inf, "moved": np.inf}

    def cat(xs):
        return jtu.tree_map(lambda *a: jnp.concatenate(a), *xs)

    for h in hs:
        states = cat([constrained_tilde_states(system, n_states, h, +1.0, seed) for seed in seeds])
        off = cat([constrained_tilde_states(system, n_states, h, -1.0, seed) for seed in seeds])
        r, mb, ma, od, mv = (float(x) for x in _round_trips(system, states, off, jnp.asarray(h)))
        out["residual"], out["manifold_B"] = max(out["residual"], r), max(out["manifold_B"], mb)
        out["manifold_A"], out["off_domain"], out["moved"] = min(out["manifold_A"], ma), min(out["off_domain"], od), \
            min(out["moved"], mv)
    out["states"] = len(seeds) * n_states * len(hs)
    return out


# ------------------------------------------------------------------------------------------------
# The energy theorem on SO(3)
# ------------------------------------------------------------------------------------------------
C_INERTIA = 1.7  # l = ½ c |Ω|²: bi-invariant metric c·identity
ENERGY_H = 0.05
_rng = np.random.default_rng(20240601)
_B1, _B1_0 = _rng.standard_normal((3, 9)), _rng.standard_normal(3)


def _bi_invariant_lagrangian(c, x, R, v):
    return 0.5 * c * v @ v


def _random_distribution(B, b0, x, R):
    return (B @ R.reshape(-1) + b0)[None, :]  # one attitude-dependent constraint row μ(R)


def energy_theorem_system(retraction: str = "cayley") -> tuple[System, np.ndarray, np.ndarray]:
    """`(system, R0, v0)` of the energy theorem: SO(3), $l = \\tfrac12 c|\\Omega|^2$ (bi-invariant),
    V = 0, one random attitude-dependent constraint $\\mu(R) = B\\,\\mathrm{vec}(R) + b$; $v_0$ is the
    orthogonal projection of (1, −2, 0.5) onto $D(R_0)$."""
    s = System(
        jtu.Partial(_bi_invariant_lagrangian, jnp.asarray(C_INERTIA)),
        jtu.Partial(_random_distribution, jnp.asarray(_B1), jnp.asarray(_B1_0)),
        n=0, group=SO3(), depends_on_orientation=True, retraction=retraction, name="bi-invariant-so3",
    )
    R0 = np.asarray(SO3().exp(jnp.asarray([0.3, -0.5, 0.8])))
    mu = np.asarray(s.mu(s.initial_point((), R0)))
    w = np.array([1.0, -2.0, 0.5])
    v0 = w - mu.T @ np.linalg.solve(mu @ mu.T, mu @ w)
    return s, R0, v0


def energy_theorem(steps: int) -> dict:
    """GNI (Euler A l_d, Cayley) for `steps` steps of :data:`ENERGY_H` from :func:`energy_theorem_system`:
    the drift of |p⁺_k| (max and fitted trend, against the round-off bound ROUNDOFF_WALK·√N·eps),
    the variation of the reported energy and the constraint residual."""
    s, R0, v0 = energy_theorem_system()
    out = all_nodes(s, GNI(EulerA(), start="rest"), (), v0, R0=R0, h=ENERGY_H, steps=steps, states=True)
    p_plus = out["states"].p_plus
    norm = np.linalg.norm(p_plus, axis=1)
    norm0 = C_INERTIA * float(np.linalg.norm(v0))
    rel = np.abs(norm / norm0 - 1.0)
    slope = float(np.polyfit(np.arange(len(norm)), norm / norm[0] - 1.0, 1)[0])
    v = out["v"]
    E = 0.5 * C_INERTIA * np.sum(v * v, axis=1)
    E0 = 0.5 * C_INERTIA * float(v0 @ v0)
    return {"drift": float(np.max(rel)), "trend": abs(slope) * steps, "bound": ROUNDOFF_WALK * math.sqrt(steps) * EPS,
            "reported_energy_variation": float(np.ptp(E) / E0), "constraint_residual": float(np.max(np.abs(out["residual"]))),
            "steps": steps}
