"""Run-time diagnostics of a solution (the driver's layer: :func:`gnipy.simulate` and the streamed
runs compute them as they run; :mod:`gnipy.analysis` re-exports them): the GNI's hidden momentum and its verdict, the energy of
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
The thresholds were set from measurements on every zoo model and GNI-family method at h = 0.05
and 0.01 over T = 200 (docs: methods guide, "Where the GNI struggles"): healthy runs peak at half
the band (0.25–0.50), failing ones exceed it by factors of 15 to $10^5$.

**Energy drift.** The first-order GNIs fail differently on the contact oscillator: their hidden
momentum stays in its band (it is consistent with the state), but the state itself gains energy
step after step until it blows up (measured: E from 3.15 to 27 by t = 78, then overflow, h = 0.05).
Where the energy is a constant of the motion (linear constraints), a run whose energy has moved by
more than `ENERGY_BAND` = 1/2 of the largest kinetic energy seen so far is called out of band too:
$|E_k - E_0| > \\tfrac12\\max_{j\\le k} K_j$, $K = \\tfrac12\\bar v^T\\bar p$. This applies to every
method (healthy runs of the zoo stay below 6% of it at h = 0.05).
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
    "ENERGY_BAND",
    "HiddenMomentumVerdict",
    "EnergyVerdict",
    "energy_verdict",
    "hidden_momentum_band",
    "node_diagnostics",
    "saved_node_diagnostics",
    "StreamedVerdicts",
    "hidden_momentum_verdict",
    "conserved_quantity",
    "energy_is_invariant",
    "energy_theorem_applies",
]

#: How far above the size of $\\frac h2\\mu^T\\lambda$ the hidden momentum may go before the run is
#: called out of band.
HIDDEN_BAND = 4.0
#: Ratios below this are round-off, never a verdict.
HIDDEN_FLOOR = 1e-8
#: A conserved energy that moves by more than this fraction of the largest kinetic energy so far
#: is out of band.
ENERGY_BAND = 0.5


def node_diagnostics(system, b, v, p, hidden, h, t=None):
    """At one node: `(hidden_ratio, expected_ratio, energy_plus)`.

    Arguments:
        system: the :class:`~gnipy.System`.
        b, v, p: the reported base point, velocity $\\bar v$ and momentum $\\bar p$.
        hidden: $p^+ - \\bar p$ (see :meth:`gnipy.integrators.base.Integrator.hidden_momentum`).
        h: the step size.
        t: the node's time (a forced system's force, and so λ, at the node's time and input).

    Returns:
        $r = \\|p^+ - \\bar p\\|/\\|\\bar p\\|$ and $e = \\frac{|h|}2\\|\\mu^T\\lambda\\|/\\|\\bar p\\|$ (norms
        in $\\mathbb{G}^{-1}$; inf where $\\bar p = 0$ and the hidden momentum is not), and the energy
        of the post-momentum $E^+ = \\tfrac12 p^{+T}\\mathbb{G}^{-1}p^+ + V$, the quantity of the
        paper's energy theorem.
    """
    from .equations import lagrange_dalembert_acceleration

    G = system.metric(b)
    _, lam = lagrange_dalembert_acceleration(system, b, v, t)
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


def saved_node_diagnostics(system, b, v, p, hidden, h, *, batched_system: bool = False, batch: bool = False,
                           times=None):
    """:func:`node_diagnostics` at every saved node: `(hidden_ratio, expected_ratio, energy_plus)`,
    each (T,) or, for a batch, (B, T).

    Compiled apart from the simulation (the continuous multiplier costs as much to compile as a
    step): one program per system structure, shared by every method and run on it, with the node
    axis padded to a power of two so that runs saving different numbers of nodes share it too.

    Arguments:
        system: the System (stacked, with a leading member axis, when `batched_system`).
        b, v, p, hidden: the saved nodes (leading axes (T,) or (B, T)).
        h: the step size.
        batched_system: `system` is a stack of member systems.
        batch: the arrays have a leading member axis.
        times: the saved nodes' times (T,), for a forced system's λ at each node's time and
            input (None: at the drive's step; unforced systems do not need them).
    """
    import jax

    axis = 1 if batch else 0
    T = int(np.shape(jax.tree_util.tree_leaves(v)[0])[axis])
    padded = max(16, 1 << (T - 1).bit_length())

    def pad(a):
        a = np.asarray(a)
        widths = [(0, 0)] * a.ndim
        widths[axis] = (0, padded - T)
        return np.pad(a, widths, mode="edge")

    b, v, p, hidden = jax.tree_util.tree_map(pad, (b, v, p, hidden))
    t = None if times is None else np.pad(np.asarray(times, np.float64)[:T], (0, padded - T), mode="edge")
    out = _saved_node_diagnostics(system, batched_system, batch, b, v, p, hidden, np.float64(h), t)
    return tuple(np.asarray(x)[:, :T] if batch else np.asarray(x)[:T] for x in out)


@jit
def _saved_node_diagnostics(system, batched_system, batch, b, v, p, hidden, h, t=None):
    import equinox as eqx
    import jax

    def nodes(s, b_, v_, p_, x_):
        if t is None:
            return jax.vmap(lambda bb, vv, pp, xx: node_diagnostics(s, bb, vv, pp, xx, h))(b_, v_, p_, x_)
        return jax.vmap(lambda bb, vv, pp, xx, tt: node_diagnostics(s, bb, vv, pp, xx, h, tt))(b_, v_, p_, x_, t)

    if not batch:
        return nodes(system, b, v, p, hidden)
    return eqx.filter_vmap(nodes, in_axes=(eqx.if_array(0) if batched_system else None, 0, 0, 0, 0))(
        system, b, v, p, hidden)


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
            "delays it. Use dla (or mp on R^n with a constant metric): they carry no hidden momentum and follow "
            "the reference on the sleigh and Suslov; check against method='reference'; see the methods guide, "
            "'Where the GNI struggles'."
        )


def hidden_momentum_band(t, expected, h, *, span=None, e0=None, running0: float = 0.0) -> np.ndarray:
    """The upper edge of the hidden momentum's O(h) band at each saved node (module docstring):
    $\\mathrm{BAND}\\cdot\\max(\\max_{j\\le k} e_j, \\tfrac{|h|}2\\rho_0) + \\mathrm{FLOOR}$.

    Arguments:
        t: the saved times, (T,).
        expected: $e_k$, (T,).
        h: the step size.
        span, e0, running0: for a run read in pieces (streamed): its whole time span, its $e_0$ and
            the largest $e_j$ of the earlier pieces (default: this piece is the whole run).
    """
    t = np.asarray(t, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if e.size == 0:
        return e
    if span is None:
        span = float(t[-1] - t[0]) if t.size > 1 else abs(float(h))
    e0 = e[0] if e0 is None else e0
    rate0 = (2.0 * e0 / abs(h) if np.isfinite(e0) and h else 0.0) + 1.0 / max(span, abs(float(h)))
    running = np.maximum.accumulate(np.maximum(np.where(np.isfinite(e), e, 0.0), running0))
    return HIDDEN_BAND * np.maximum(running, 0.5 * abs(h) * rate0) + HIDDEN_FLOOR


def hidden_momentum_verdict(t, ratio, expected, h, **piece) -> HiddenMomentumVerdict:
    """The verdict on a run from its saved nodes (see the module docstring for the band).

    Arguments:
        t: the saved times, (T,).
        ratio: $r_k$, (T,).
        expected: $e_k$, (T,).
        h: the step size.
        piece: `span`, `e0`, `running0` of :func:`hidden_momentum_band`, for a piece of a run.
    """
    t = np.asarray(t, dtype=np.float64)
    r = np.asarray(ratio, dtype=np.float64)
    if r.size == 0:
        return HiddenMomentumVerdict(True, None, None, 0.0, 0.0)
    band = hidden_momentum_band(t, expected, h, **piece)
    rel = np.where(np.isnan(r), np.inf, r) / band
    out = np.flatnonzero(rel > 1.0)
    max_ratio = float(np.nanmax(np.where(np.isnan(r), np.inf, r)))
    max_rel = float(np.max(rel))
    if out.size == 0:
        return HiddenMomentumVerdict(True, None, None, max_ratio, max_rel)
    k = int(out[0])
    return HiddenMomentumVerdict(False, float(t[k]), k, max_ratio, max_rel)


@dataclasses.dataclass(frozen=True)
class EnergyVerdict:
    """Whether an energy that the motion conserves stayed within its band (module docstring).

    Attributes:
        in_band: True when it never left the band.
        first_time: the time of the first saved node out of band (None when in band).
        max_drift: the largest $|E_k - E_0| / \\max_{j\\le k} K_j$ over the run.
    """

    in_band: bool
    first_time: float | None
    max_drift: float

    def warning(self, method: str, system: str) -> str | None:
        """The warning to print when out of band, else None."""
        if self.in_band:
            return None
        return (
            f"WARNING: the energy of {system}, a constant of this motion, drifted by more than half the kinetic "
            f"energy from t = {self.first_time:.6g} on (up to {self.max_drift:.3g}x the kinetic energy) with "
            f"{method}: the run is qualitatively wrong from there on. A first-order method (gni-euler-a/b, "
            "euler-a/b) needs a much smaller h or a symmetric one (gni-trapezoid, gni-midpoint, mp); if the hidden "
            "momentum left its band too, follow that warning. Check against method='reference'; see the methods "
            "guide, 'Where the GNI struggles'."
        )


def energy_verdict(t, energy, kinetic, *, e0=None, kmax0: float = 0.0) -> EnergyVerdict:
    """The energy verdict from the saved nodes: `energy` (T,) and the kinetic energies `kinetic` (T,)
    (for a piece of a run: the run's initial energy `e0` and the largest kinetic energy before it)."""
    t = np.asarray(t, dtype=np.float64)
    e = np.asarray(energy, dtype=np.float64)
    k = np.asarray(kinetic, dtype=np.float64)
    if e.size == 0:
        return EnergyVerdict(True, None, 0.0)
    scale = np.maximum.accumulate(np.maximum(np.where(np.isfinite(k), np.abs(k), np.inf), kmax0))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # a run that blew up: inf/NaN nodes
        drift = np.abs(e - (e[0] if e0 is None else e0))
        rel = np.where(scale > 0, drift / scale, np.where(drift > 0, np.inf, 0.0))
    rel = np.where(np.isfinite(e), rel, np.inf)
    out = np.flatnonzero(~(rel <= ENERGY_BAND))
    max_drift = float(np.max(rel))
    if out.size == 0:
        return EnergyVerdict(True, None, max_drift)
    return EnergyVerdict(False, float(t[out[0]]), max_drift)


class StreamedVerdicts:
    """The verdicts of a run read chunk by chunk (:func:`gnipy.simulate_to_file`): the same rules
    as for a whole run, with the running maxima carried from chunk to chunk.

    Arguments:
        h: the step size.
        span: the run's whole time span.
        energy_invariant: whether the energy is a constant of the motion.
    """

    def __init__(self, h: float, span: float, energy_invariant: bool):
        self.h, self.span, self.energy_invariant = float(h), float(span), bool(energy_invariant)
        self._e0 = self._E0 = None
        self._running = self._kmax = 0.0
        self.hidden: HiddenMomentumVerdict | None = None
        self.energy: EnergyVerdict | None = None

    def update(self, t, energy, kinetic, ratio=None, expected=None) -> None:
        """Add one chunk's saved nodes (times, energies, kinetic energies, and for the GNI family
        the hidden-momentum ratios and their expected sizes)."""
        t = np.asarray(t, dtype=np.float64)
        if t.size == 0:
            return
        if ratio is not None:
            e = np.asarray(expected, dtype=np.float64)
            self._e0 = e[0] if self._e0 is None else self._e0
            v = hidden_momentum_verdict(t, ratio, e, self.h, span=self.span, e0=self._e0, running0=self._running)
            self._running = max(self._running, float(np.max(np.where(np.isfinite(e), e, 0.0))))
            old = self.hidden
            if old is None:
                self.hidden = v
            else:
                first = old if not old.in_band else v
                self.hidden = HiddenMomentumVerdict(
                    old.in_band and v.in_band, first.first_time, None, max(old.max_ratio, v.max_ratio),
                    max(old.max_band_ratio, v.max_band_ratio))
        if self.energy_invariant:
            E = np.asarray(energy, dtype=np.float64)
            self._E0 = E[0] if self._E0 is None else self._E0
            v = energy_verdict(t, E, kinetic, e0=self._E0, kmax0=self._kmax)
            k = np.asarray(kinetic, dtype=np.float64)
            self._kmax = max(self._kmax, float(np.max(np.where(np.isfinite(k), np.abs(k), np.inf))))
            old = self.energy
            if old is None:
                self.energy = v
            else:
                first = old if not old.in_band else v
                self.energy = EnergyVerdict(old.in_band and v.in_band, first.first_time, max(old.max_drift, v.max_drift))

    def attrs(self, method: str, system: str) -> dict:
        """The verdicts as file attributes (as :meth:`gnipy.Solution.to_xarray` writes them)."""
        out = {}
        for prefix, v, largest in (("hidden_momentum", self.hidden, "max_ratio"), ("energy_drift", self.energy, "max_drift")):
            if v is None:
                continue
            out[f"{prefix}_verdict"] = "in band" if v.in_band else "out of band"
            out[f"{prefix}_max"] = getattr(v, largest)
            if not v.in_band:
                out[f"{prefix}_first_time"] = v.first_time
                out[f"{prefix}_warning"] = v.warning(method, system)
        return out

    def warnings(self, method: str, system: str) -> list[str]:
        """The warnings (as :meth:`gnipy.Solution.warnings`)."""
        return [v.warning(method, system) for v in (self.hidden, self.energy) if v is not None and not v.in_band]


def conserved_quantity(system, b0, *, gni_family: bool, invariants=(), conserves_energy: bool = False) -> str:
    """Which reported quantity the run should conserve, as a sentence for `summary()`.

    Linear constraints: the energy $\\tfrac12\\bar v^T\\mathbb{G}\\bar v + V$ is a constant of the
    continuous motion (the GNI's reported energy then has a bounded error, not a drift, in healthy
    runs); with V = 0, a constant metric on $\\mathbb{R}^n$ or a bi-invariant one on SO(3), the GNI
    conserves the energy of $p^+$ exactly (the paper's energy theorem, §4). Affine constraints:
    neither energy is conserved (the constraint forces do work); the model's Jacobi integral
    where one is registered. `conserves_energy`: the method conserves the energy exactly
    (`method.conserves_energy`, the discrete-gradient method).
    """
    names = tuple(invariants)
    if system.is_forced:
        return "external forces act: the energy is not conserved (the force F(q, v, u, t) does work)"
    if not energy_is_invariant(system, b0):
        if "jacobi" in names:
            return "affine constraints: neither energy is conserved; the Jacobi integral is (gnipy.get_model(...).invariants['jacobi'])"
        return "affine constraints: neither energy is conserved (the constraint forces do work)"
    if conserves_energy:
        return "the energy is conserved by the motion (linear constraints) and by the scheme, to round-off"
    if gni_family and energy_theorem_applies(system, b0):
        return ("the energy of p+ (energy_plus) is conserved exactly by the GNI (energy theorem: V = 0 and a "
                "constant or bi-invariant metric); the reported energy is conserved by the motion, not exactly by the scheme")
    return "the energy is conserved by the motion (linear constraints); the scheme conserves it only approximately"


def energy_theorem_applies(system, b0) -> bool:
    """Whether the hypotheses of the paper's energy theorem hold: V = 0, linear constraints, and a
    metric that is constant on $\\mathbb{R}^n$ or, with a group part, constant with the group block
    $c I$ on SO(3) (bi-invariant) and no coupling to $\\mathbb{R}^n$ (host side)."""
    from .lie_groups import SO3

    if not energy_is_invariant(system, b0) or not system.has_constant_metric(b0):
        return False
    G, gradV, _ = (np.asarray(a) for a in _sampled_values(system, b0))
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


def energy_is_invariant(system, b0) -> bool:
    """Whether the energy is a constant of the motion: the constraints are linear, i.e. there is no
    affine part or it vanishes (e.g. a model's turning table at $\\Omega = 0$), checked at b0 and
    three nearby points (host side); never for a forced system (the force does work)."""
    if system.is_forced:
        return False
    if not system.is_affine:
        return True
    return not np.any(np.asarray(_sampled_values(system, b0)[2]) != 0.0)


@jit
def _values(system, b):
    w = jnp.asarray(np.random.default_rng(0).standard_normal((3, system.dim)), dtype=jnp.float64)
    points = [b] + [system.space.move(b, wi) for wi in w]
    return (system.metric(b), jnp.stack([system.potential_gradient(c) for c in points]),
            jnp.stack([system.Y(c) for c in points]))


def _sampled_values(system, b0):
    """The metric at b0, and $\\partial V$ and $Y$ at b0 and at three fixed nearby points (one
    compile per system structure)."""
    return _values(system.without_metadata(), b0)
