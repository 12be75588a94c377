"""Run-time diagnostics of a solution: the GNI's hidden momentum and its verdict, the energy of
$p^+$, and which quantity the model conserves.

**The hidden momentum.** The GNI family (the `gni-*` methods and the paper's schemes that are the
GNI in other variables: `euler-a`, `euler-b`, `euler-ab`, `rattle`, `rat`) carries the
post-momentum $p^+_k$, and reports $\\bar p_k = P^*p^+_k + Q^*\\Pi$. The difference
$p^+_k - \\bar p_k = Q^*(p^+_k - \\Pi)$ is a normal impulse the user never sees; for a healthy run it
is $\\approx -\\tfrac h2\\mu^T\\lambda$, with $\\lambda$ the continuous constraint multiplier, i.e.
$O(h)$. On problems with attracting relative equilibria (the Chaplygin sleigh, Suslov) and for the
first-order GNIs on stiff oscillations (the contact oscillator) it grows to $O(1)$ and the motion
goes qualitatively wrong — energy drained, looping paths — while the constraints still hold
exactly. Halving h only delays it. This module measures it at every saved node,

$$r_k = \\frac{\\|p^+_k - \\bar p_k\\|_{\\mathbb{G}^{-1}}}{\\|\\bar p_k\\|_{\\mathbb{G}^{-1}}},
\\qquad e_k = \\frac{|h|}2\\,\\frac{\\|\\mu^T\\lambda_k\\|_{\\mathbb{G}^{-1}}}{\\|\\bar p_k\\|_{\\mathbb{G}^{-1}}}$$

($e_k$ the size it should have, $\\lambda_k$ evaluated at $(b_k, \\bar v_k)$), and calls the run
*out of band* from the first node where

$$r_k > \\mathrm{BAND}\\cdot\\max\\Big(\\max_{j \\le k} e_j,\\ \\tfrac{|h|}{2}\\,\\rho_0\\Big) + \\mathrm{FLOOR},$$

$\\rho_0 = \\|\\mu^T\\lambda_0\\|/\\|\\bar p_0\\| + 1/T$ a rate of the problem, `BAND` = 4 and
`FLOOR` = 1e-8 (below it the ratio is round-off). The running maximum of $e_j$ allows the
impulse to keep the size it had earlier after $\\lambda$ passes through zero (the start
$p^+_0 = \\mathbb{G}v_0$ excites a neutral oscillation of that size); a run whose hidden momentum
grows past four times any size the continuous multiplier ever asked for has left the $O(h)$ regime.
The thresholds were set from measurements on every zoo model (docs: methods guide, "Where the
GNI struggles"): healthy runs stay below 2.2 times the band, failing ones exceed it by orders of
magnitude.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .linalg import solve_spd

__all__ = [
    "HIDDEN_BAND",
    "HIDDEN_FLOOR",
    "HiddenMomentumVerdict",
    "node_diagnostics",
    "hidden_momentum_verdict",
    "conserved_quantity",
]

#: How far above the size of $\\frac h2\\mu^T\\lambda$ the hidden momentum may go before the run is
#: called out of band.
HIDDEN_BAND = 4.0
#: Ratios below this are round-off, never a verdict.
HIDDEN_FLOOR = 1e-8


def node_diagnostics(system, b, v, p, hidden, h):
    """At one node: `(hidden_ratio, expected_ratio, energy_plus)`.

    Arguments:
        system: the :class:`~gnipy.System`.
        b, v, p: the reported base point, velocity $\\bar v$ and momentum $\\bar p$.
        hidden: $p^+ - \\bar p$ (see :meth:`gnipy.integrators.base.Integrator.hidden_momentum`).
        h: the step size.

    Returns:
        $r = \\|p^+ - \\bar p\\|/\\|\\bar p\\|$ and $e = \\frac{|h|}2\\|\\mu^T\\lambda\\|/\\|\\bar p\\|$ (norms
        in $\\mathbb{G}^{-1}$; inf where $\\bar p = 0$ and the hidden momentum is not), and the energy
        of the post-momentum $E^+ = \\tfrac12 p^{+T}\\mathbb{G}^{-1}p^+ + V$, the quantity of the
        paper's energy theorem.
    """
    from .reference import lagrange_dalembert_acceleration

    G = system.metric(b)
    _, lam = lagrange_dalembert_acceleration(system, b, v)
    impulse = system.mu(b).T @ lam
    p_plus = p + hidden
    X = solve_spd(G, jnp.stack([p, hidden, impulse, p_plus], axis=1))
    sq = jnp.sum(jnp.stack([p, hidden, impulse, p_plus], axis=1) * X, axis=0)
    norm_p, norm_hidden, norm_impulse = jnp.sqrt(jnp.maximum(sq[:3], 0.0))
    tiny = jnp.finfo(p.dtype).tiny

    def ratio(x):
        return jnp.where(norm_p > tiny, x / jnp.maximum(norm_p, tiny), jnp.where(x > 0, jnp.inf, 0.0))

    energy_plus = 0.5 * sq[3] + system.potential(b)
    return ratio(norm_hidden), ratio(0.5 * jnp.abs(h) * norm_impulse), energy_plus


@dataclasses.dataclass(frozen=True)
class HiddenMomentumVerdict:
    """Whether the hidden momentum stayed in its O(h) band.

    Attributes:
        in_band: True when it never left the band.
        first_time: the time of the first saved node out of band (None when in band).
        first_node: the index of that saved node (None when in band).
        max_ratio: the largest $r_k$ over the run.
        max_band_ratio: the largest $r_k$ divided by its band (> 1 when out of band).
    """

    in_band: bool
    first_time: float | None
    first_node: int | None
    max_ratio: float
    max_band_ratio: float

    def warning(self, method: str, system: str) -> str | None:
        """The warning to print when out of band, else None."""
        if self.in_band:
            return None
        return (
            f"WARNING: the hidden momentum of {method} left its O(h) band at t = {self.first_time:.6g} "
            f"(|p+ - p̄|/|p̄| up to {self.max_ratio:.3g}, {self.max_band_ratio:.3g}x the band): the GNI's "
            f"normal impulse has taken over, and the motion of {system} is qualitatively wrong from there on "
            "(energy drained or pumped, looping paths) even though the constraints hold. A smaller h only "
            "delays it. Use mp or dla (no hidden momentum), or check against method='reference'; see the "
            "methods guide, 'Where the GNI struggles'."
        )


def hidden_momentum_verdict(t, ratio, expected, h) -> HiddenMomentumVerdict:
    """The verdict on a run from its saved nodes (see the module docstring for the band).

    Arguments:
        t: the saved times, (T,).
        ratio: $r_k$, (T,).
        expected: $e_k$, (T,).
        h: the step size.
    """
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(ratio, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if r.size == 0:
        return HiddenMomentumVerdict(True, None, None, 0.0, 0.0)
    span = float(t[-1] - t[0]) if t.size > 1 else abs(float(h))
    rate0 = (2.0 * e[0] / abs(h) if np.isfinite(e[0]) and h else 0.0) + 1.0 / max(span, abs(float(h)))
    running = np.maximum.accumulate(np.where(np.isfinite(e), e, 0.0))
    band = HIDDEN_BAND * np.maximum(running, 0.5 * abs(h) * rate0) + HIDDEN_FLOOR
    rel = np.where(np.isnan(r), np.inf, r) / band
    out = np.flatnonzero(rel > 1.0)
    max_ratio = float(np.nanmax(np.where(np.isnan(r), np.inf, r)))
    max_rel = float(np.max(rel))
    if out.size == 0:
        return HiddenMomentumVerdict(True, None, None, max_ratio, max_rel)
    k = int(out[0])
    return HiddenMomentumVerdict(False, float(t[k]), k, max_ratio, max_rel)


def conserved_quantity(system, b0, *, gni_family: bool, invariants=()) -> str:
    """Which reported quantity the run should conserve, as a sentence for `summary()`.

    Linear constraints: the energy $\\tfrac12\\bar v^T\\mathbb{G}\\bar v + V$ is a constant of the
    continuous motion (the GNI's reported energy then has a bounded error, not a drift, in healthy
    runs); with V = 0, a constant metric on $\\mathbb{R}^n$ or a bi-invariant one on SO(3), the GNI
    conserves the energy of $p^+$ exactly (the paper's energy theorem, §4). Affine constraints:
    neither energy is conserved (the constraint forces do work); the model's Jacobi integral
    where one is registered.
    """
    names = tuple(invariants)
    if system.is_affine:
        if "jacobi" in names:
            return "affine constraints: neither energy is conserved; the Jacobi integral is (gnipy.get_model(...).invariants['jacobi'])"
        return "affine constraints: neither energy is conserved (the constraint forces do work)"
    if gni_family and energy_theorem_applies(system, b0):
        return ("the energy of p+ (energy_plus) is conserved exactly by the GNI (energy theorem: V = 0 and a "
                "constant or bi-invariant metric); the reported energy is conserved by the motion, not exactly by the scheme")
    return "the energy is conserved by the motion (linear constraints); the scheme conserves it only approximately"


def energy_theorem_applies(system, b0) -> bool:
    """Whether the hypotheses of the paper's energy theorem hold: V = 0, linear constraints, and a
    metric that is constant on $\\mathbb{R}^n$ or, with a group part, constant with the group block
    $c I$ on SO(3) (bi-invariant) and no coupling to $\\mathbb{R}^n$ (host side)."""
    from .lie_groups import SO3

    if system.is_affine or not system.has_constant_metric(b0):
        return False
    G, gradV = (np.asarray(a) for a in _metric_and_potential_gradients(system, b0))
    if np.max(np.abs(gradV), initial=0.0) > 0.0:
        return False
    if system.group is None:
        return True
    if not isinstance(system.group, SO3):
        return False
    n = system.n
    Gg = G[n:, n:]
    scale = max(float(np.max(np.abs(G))), 1e-300)
    return bool(np.max(np.abs(G[:n, n:]), initial=0.0) <= 1e-14 * scale
                and np.max(np.abs(Gg - Gg[0, 0] * np.eye(3))) <= 1e-14 * scale)


@jit
def _values(system, b):
    w = jnp.asarray(np.random.default_rng(0).standard_normal((3, system.dim)), dtype=jnp.float64)
    points = [b] + [system.space.move(b, wi) for wi in w]
    return system.metric(b), jnp.stack([system.potential_gradient(c) for c in points])


def _metric_and_potential_gradients(system, b0):
    """The metric at b0 and $\\partial V$ at b0 and at three fixed nearby points (one compile per
    system structure)."""
    return _values(system.without_metadata(), b0)
