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
`FLOOR` = 1e-8 (below it the ratio is round-off); a node where $\\bar p_k = 0$ while
$\\mu^T\\lambda_k \\neq 0$ (a start from rest under a force) has both ratios infinite and is not
judged (:func:`judged_ratio`). The running maximum of $e_j$ allows the
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
    "scheme_energy",
    "HIDDEN_BAND",
    "HIDDEN_FLOOR",
    "ENERGY_BAND",
    "HiddenMomentumVerdict",
    "EnergyVerdict",
    "energy_verdict",
    "hidden_momentum_band",
    "node_diagnostics",
    "saved_node_diagnostics",
    "hidden_momentum_verdict",
    "judged_ratio",
    "conserved_quantity",
    "DIAGNOSTIC_ARRAYS",
    "diagnostic_fields",
    "member_conservation",
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
    from .equations import constraint_terms
    from .linalg import solve

    # one elimination of G for the multiplier and the three norms (the run-time monitor evaluates
    # this at every node: gnipy.monitor); |mu^T lam|^2 in G^-1 is lam^T C lam, C = mu G^-1 mu^T
    G, F, mu, c = constraint_terms(system, b, v, t)
    m = mu.shape[0]
    X = solve_spd(G, jnp.concatenate([F[:, None], mu.T, p[:, None], hidden[:, None]], axis=1))
    XF, Xmu, Xp, Xh = X[:, 0], X[:, 1:1 + m], X[:, 1 + m], X[:, 2 + m]
    C = mu @ Xmu
    lam = solve(C, c - mu @ XF) if m else jnp.zeros(0, dtype=p.dtype)
    p_plus = p + hidden
    sq = jnp.stack([p @ Xp, hidden @ Xh, lam @ C @ lam, p_plus @ (Xp + Xh)])
    norm_p, norm_hidden, norm_impulse = jnp.sqrt(jnp.maximum(sq[:3], 0.0))
    tiny = jnp.finfo(p.dtype).tiny

    def ratio(x):
        return jnp.where(norm_p > tiny, x / jnp.maximum(norm_p, tiny), jnp.where(x > 0, jnp.inf, 0.0))

    energy_plus = 0.5 * sq[3] + system.potential(b)
    return ratio(norm_hidden), ratio(0.5 * jnp.abs(h) * norm_impulse), energy_plus


def judged_ratio(ratio, expected, xp=jnp):
    """The hidden-momentum ratio $r_k$ as the verdicts judge it: NaN counts as infinite (out of band),
    and a node where both $r_k$ and $e_k$ are infinite is not judged (0): there $\\bar p_k = 0$ while
    the continuous impulse is not (a start from rest under a force or an input), so the relative
    size is undefined; the hidden momentum p⁺ − p̄ is then the step's own impulse. Measured on the
    sleigh steered from rest (h = 0.05): r = e = inf at t = 0, then r = 0.250 against e = 0.249 at the
    next node; before this rule every controlled run from rest was called qualitatively wrong at t = 0.
    `xp`: `jax.numpy` (in the loop, :mod:`gnipy.monitor`) or `numpy` (saved nodes)."""
    unjudged = xp.isposinf(ratio) & xp.isposinf(expected)  # tested before NaN becomes inf
    return xp.where(unjudged, 0.0, xp.where(xp.isnan(ratio), xp.inf, ratio))


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
            "delays it. Use dla, sgni-trapezoid, or mp on R^n with a constant metric and no holonomic constraints: "
            "they carry no hidden momentum (dla follows the reference on the sleigh and Suslov, dla and "
            "sgni-trapezoid on the Whipple bicycle); check against method='reference'; see the methods guide, "
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
    r = judged_ratio(r, np.asarray(expected, dtype=np.float64), np)
    rel = r / band
    out = np.flatnonzero(rel > 1.0)
    max_ratio = float(np.max(r))
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
            "euler-a/b; sister, which dissipates the energy by design) needs a much smaller h or a symmetric one (gni-trapezoid, gni-midpoint, mp); if the hidden "
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


def scheme_energy(method) -> str:
    """How a method's scheme treats an energy the motion conserves: `"exact"` (to round-off,
    `method.conserves_energy`: the discrete-gradient method), `"dissipated"` (`method.dissipates_energy`:
    the sister method's plastic impacts) or `"approximate"`."""
    if getattr(method, "conserves_energy", False):
        return "exact"
    return "dissipated" if getattr(method, "dissipates_energy", False) else "approximate"


def conserved_quantity(system, b0, *, gni_family: bool, invariants=(), scheme: str = "approximate") -> str:
    """Which reported quantity the run should conserve, as a sentence for `summary()`.

    Linear constraints: the energy $\\tfrac12\\bar v^T\\mathbb{G}\\bar v + V$ is a constant of the
    continuous motion (the GNI's reported energy then has a bounded error, not a drift, in healthy
    runs); with V = 0, a constant metric on $\\mathbb{R}^n$ or a bi-invariant one on SO(3), the GNI
    conserves the energy of $p^+$ exactly (the paper's energy theorem, §4). Affine constraints:
    neither energy is conserved (the constraint forces do work); the model's Jacobi integral
    where one is registered. `scheme`: how the method treats that energy (:func:`scheme_energy`).
    """
    invariant = energy_is_invariant(system, b0)
    theorem = gni_family and invariant and scheme == "approximate" and energy_theorem_applies(system, b0)
    return _sentence(system.is_forced, invariant, theorem, tuple(invariants), scheme, gni_family)


def _sentence(forced: bool, invariant: bool, theorem: bool, names: tuple, scheme: str,
              gni_family: bool) -> str:
    if forced:
        return "external forces act: the energy is not conserved (the force F(q, v, u, t) does work)"
    if not invariant:
        if "jacobi" in names:
            return "affine constraints: neither energy is conserved; the Jacobi integral is (gnipy.get_model(...).invariants['jacobi'])"
        return "affine constraints: neither energy is conserved (the constraint forces do work)"
    if scheme == "exact":
        return "the energy is conserved by the motion (linear constraints) and by the scheme, to round-off"
    if scheme == "dissipated":
        return ("the energy is conserved by the motion (linear constraints); the scheme dissipates it, O(h) per "
                "unit time (an inelastic impact at every step)")
    if gni_family and theorem:
        return ("the energy of p+ (energy_plus) is conserved exactly by the GNI (energy theorem: V = 0 and a "
                "constant or bi-invariant metric); the reported energy is conserved by the motion, not exactly by the scheme")
    return "the energy is conserved by the motion (linear constraints); the scheme conserves it only approximately"


def member_conservation(system, core, batched_system: bool, b0, *, gni_family: bool, invariants=(),
                        scheme: str = "approximate") -> tuple[tuple[str, ...], np.ndarray]:
    """Each member's :func:`conserved_quantity` sentence and whether its energy is a constant of
    its motion (:func:`energy_is_invariant`), for a batch: `system` its first member, `core` the
    members' systems stacked when `batched_system` (else the one system), `b0` the members' start
    points (leading axis B). One vectorized program: a parameter batch's members may differ (a
    turning table at Ω = 0 and Ω = 1)."""
    import jax

    B = int(np.shape(jax.tree_util.tree_leaves(b0)[0])[0])
    names = tuple(invariants)
    if system.is_forced:
        return (_sentence(True, False, False, names, scheme, gni_family),) * B, np.zeros(B, dtype=bool)
    G, gradV, Y, dG = (np.asarray(a) for a in _member_values(core, batched_system, b0))
    invariant = np.ones(B, dtype=bool) if not system.is_affine else ~np.any(Y.reshape(B, -1) != 0.0, axis=1)
    theorem = invariant & ~np.any(dG.reshape(B, -1) != 0.0, axis=1) & ~np.any(gradV.reshape(B, -1) != 0.0, axis=1)
    if system.group is not None:
        n = system.n
        scale = np.maximum(np.max(np.abs(G.reshape(B, -1)), axis=1), 1e-300)
        # no coupling to R^n, and a group block the group knows to be bi-invariant (cI on SO(3))
        theorem &= (np.max(np.abs(G[:, :n, n:]).reshape(B, -1), axis=1, initial=0.0) <= 1e-14 * scale) & (
            system.group.is_bi_invariant(G[:, n:, n:], 1e-14 * scale))
    sentences = tuple(_sentence(False, bool(inv), bool(th), names, scheme, gni_family)
                      for inv, th in zip(invariant, theorem))
    return sentences, invariant


@jit
def _member_values(system, batched_system, b):
    import equinox as eqx
    import jax

    ws = jnp.asarray(0.3 * np.random.default_rng(1).standard_normal((2, system.dim)))

    def one(s, bb):
        G, gradV, Y = _values_at(s, bb)

        def dmetric(w):
            c = s.space.move(bb, w)
            return jax.jacfwd(lambda u: s.metric(s.space.move(c, u)))(jnp.zeros(s.dim))

        return G, gradV, Y, jax.vmap(dmetric)(ws)

    return eqx.filter_vmap(one, in_axes=(eqx.if_array(0) if batched_system else None, 0))(system, b)


def energy_theorem_applies(system, b0) -> bool:
    """Whether the hypotheses of the paper's energy theorem hold: V = 0, linear constraints, and a
    metric that is constant on $\\mathbb{R}^n$ or, with a group part, constant with a group block
    the group knows to be bi-invariant (`group.is_bi_invariant`: $c I$ on SO(3)) and no coupling to
    $\\mathbb{R}^n$ (host side)."""
    if not energy_is_invariant(system, b0) or not system.has_constant_metric(b0):
        return False
    G, gradV, _ = (np.asarray(a) for a in _sampled_values(system, b0))
    if np.max(np.abs(gradV), initial=0.0) > 0.0:
        return False
    if system.group is None:
        return True
    n = system.n
    scale = max(float(np.max(np.abs(G))), 1e-300)
    return bool(np.max(np.abs(G[:n, n:]), initial=0.0) <= 1e-14 * scale
                and system.group.is_bi_invariant(G[n:, n:], 1e-14 * scale))


def energy_is_invariant(system, b0) -> bool:
    """Whether the energy is a constant of the motion: the constraints are linear, i.e. there is no
    affine part or it vanishes (e.g. a model's turning table at $\\Omega = 0$), checked at b0 and
    three nearby points (host side); never for a forced system (the force does work)."""
    if system.is_forced:
        return False
    if not system.is_affine:
        return True
    return not np.any(np.asarray(_sampled_values(system, b0)[2]) != 0.0)


def _values_at(system, b):
    w = jnp.asarray(np.random.default_rng(0).standard_normal((3, system.dim)), dtype=jnp.float64)
    points = [b] + [system.space.move(b, wi) for wi in w]
    return (system.metric(b), jnp.stack([system.potential_gradient(c) for c in points]),
            jnp.stack([system.Y(c) for c in points]))


_values = jit(_values_at)


def _sampled_values(system, b0):
    """The metric at b0, and $\\partial V$ and $Y$ at b0 and at three fixed nearby points (one
    compile per system structure)."""
    return _values(system.without_metadata(), b0)


#: The Solution's arrays of the GNI family's node diagnostics.
DIAGNOSTIC_ARRAYS = ("hidden_momentum", "hidden_expected", "energy_plus")


def diagnostic_fields(system, core, b0, nodes, h, *, batched_system: bool = False, batch: bool = False,
                     cached: dict | None = None, prepared=None, scheme: str = "approximate", times=None) -> dict:
    """The Solution's diagnostic fields: the GNI family's hidden momentum, its expected size and
    the energy of p⁺ (:mod:`gnipy.diagnostics`), and the sentence on what is conserved (kept in
    `cached`, per system and start, when given). A single run passes `prepared = (Prepared, padded
    nodes, arrays)`: the arrays when its program computed them (a native run), else the nodes
    padded for :meth:`gnipy.preparation.Prepared.node_diagnostics`."""
    from .registry import registered_invariants

    gni_family = nodes[3] is not None
    key = ("conserved", gni_family, scheme)
    if cached is not None and key in cached:
        out = dict(cached[key])
    else:
        out = {"conserved": conserved_quantity(system, b0, gni_family=gni_family,
                                               invariants=registered_invariants(system.model),
                                               scheme=scheme),
               "energy_invariant": energy_is_invariant(system, b0)}
        if cached is not None:
            cached[key] = dict(out)
    if gni_family and prepared is not None and prepared[2] is not None:  # computed by the run's program
        out |= dict(zip(DIAGNOSTIC_ARRAYS, prepared[2]))
    elif gni_family and prepared is not None:  # a single run: its nodes come padded from the run's program
        diag = prepared[0].node_diagnostics(prepared[1], h, int(np.shape(nodes[1])[0]), times=times)
        out |= dict(zip(DIAGNOSTIC_ARRAYS, diag))
    elif gni_family:
        diag = saved_node_diagnostics(core, *nodes, h, batched_system=batched_system, batch=batch,
                                      times=times if system.is_forced else None)
        out |= dict(zip(DIAGNOSTIC_ARRAYS, diag))
    return out
