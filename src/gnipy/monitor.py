"""The verdicts from every step: a small vector carried through the stepping loop
(:mod:`gnipy.stepping`, on both backends) that follows the hidden momentum and the energy at every
node, whatever is saved.

The rules are those of :mod:`gnipy.diagnostics` (the hidden momentum's O(h) band, the energy's
drift against the largest kinetic energy so far), applied at each node $k = 0, 1, \\dots, N$ of
the run instead of at the saved ones only: a failure that comes and goes between two saved nodes
(the GNI on the Chaplygin sleigh spikes for 5–10 time units, then looks healthy again) cannot be
missed. What the loop carries, per trajectory (:data:`SLOTS`):

- the constants of the run: $1/\\max(T, |h|)$ (T the whole run's span, for the band's floor
  $\\tfrac{|h|}2\\rho_0$), the call's $t_0$ and h (the node times $t_0 + k h$), the steps the
  call takes (`k_end`: the loop's last iteration, k = k_end, only checks the last node, so that
  the check is compiled once, in the loop), whether the energy is a constant of this member's
  motion;
- the values at the run's first node: $e_0$ and $E_0$;
- the running extremes: $\\max_j e_j$, $\\max_j r_j$, $\\max_j r_j/\\mathrm{band}_j$,
  $\\max_j |K_j|$, the largest relative drift;
- the first times out of band (NaN while in band), and the number of nodes seen.

A run continued from an earlier one (`simulate(..., state0=sol.final_state,
monitor0=sol.monitor)`, the chunks of a streamed run) carries the vector on, so its verdict is
that of one run. A failed step freezes the vector (the nodes after it are not the motion's).
"""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np

from .errors import InputError, QualitativeFailure, QualitativeFailureWarning
from .diagnostics import (ENERGY_BAND, HIDDEN_BAND, HIDDEN_FLOOR, EnergyVerdict, HiddenMomentumVerdict,
                          judged_ratio, node_diagnostics)

__all__ = ["SLOTS", "SIZE", "initial", "continued", "start", "with_end", "stepping", "update", "hidden_verdict",
           "energy_verdict", "nodes_seen", "RunVerdicts", "announce"]

#: The monitor's entries, in order.
SLOTS = ("inv_span", "t0", "h", "k_end", "started", "nodes", "energy_applies",
         "e0", "e_running", "ratio_max", "band_ratio_max", "hidden_first_time",
         "E0", "kinetic_max", "drift_max", "energy_first_time")
SIZE = len(SLOTS)
_I = {name: i for i, name in enumerate(SLOTS)}


def initial(h: float, span: float, t0: float, *, energy_applies=True, members: int | None = None) -> np.ndarray:
    """The monitor at the start of a run of step `h` over `span` (the whole run's length) from
    `t0`: (SIZE,), or (members, SIZE) with `energy_applies` per member."""
    m = np.zeros(SIZE if members is None else (members, SIZE), dtype=np.float64)
    m[..., _I["inv_span"]] = 1.0 / max(abs(float(span)), abs(float(h)))
    m[..., _I["t0"]] = float(t0)
    m[..., _I["h"]] = float(h)
    m[..., _I["energy_applies"]] = np.asarray(energy_applies, dtype=np.float64)
    for name in ("e0", "E0", "hidden_first_time", "energy_first_time"):
        m[..., _I[name]] = np.nan
    return m


def with_end(monitor, k_end):
    """The monitor for a call whose loop takes `k_end` steps (traced or not): its iteration
    k = k_end checks the last node and steps no further. A NumPy `monitor` with a Python `k_end`
    gives a NumPy array (no dispatch to JAX)."""
    if isinstance(monitor, np.ndarray) and isinstance(k_end, (int, float)):
        out = np.array(monitor, dtype=np.float64)
        out[..., _I["k_end"]] = float(k_end)
        return out
    return jnp.asarray(monitor, jnp.float64).at[..., _I["k_end"]].set(jnp.asarray(k_end, jnp.float64))


def stepping(monitor, k):
    """Whether the loop's iteration `k` takes its step (k < k_end; the last only checks)."""
    return k.astype(jnp.float64) < monitor[_I["k_end"]]


def continued(monitor, h: float, t0: float) -> np.ndarray:
    """An earlier run's final `monitor`, for a call that continues it from `t0` with step `h`."""
    m = np.array(monitor, dtype=np.float64)
    if m.shape[-1:] != (SIZE,) or not np.all(np.isfinite(m[..., _I["inv_span"]])):
        raise InputError(f"monitor0: expected the monitor of an earlier run (Solution.monitor, {SIZE} values), "
                         f"got an array of shape {m.shape}")
    m[..., _I["t0"]] = float(t0)
    m[..., _I["h"]] = float(h)
    return m


def update(method, system, monitor, state, h, k, active):
    """The monitor after the node that `state` holds (step index `k` of this call, step size `h`
    of the step that follows it); unchanged where not `active` (after a failed step). Traced
    (inside the loop)."""
    get = {name: monitor[i] for i, name in enumerate(SLOTS)}
    t = get["t0"] + k.astype(jnp.float64) * get["h"]
    started = get["started"] > 0
    b, v, p = method.observe(system, state, h)
    new = dict(get, started=jnp.ones_like(get["started"]), nodes=get["nodes"] + 1.0)
    hidden = method.hidden_momentum(system, state, h)
    if hidden is not None:  # the GNI family (static: known when the loop is traced)
        r, e, _ = node_diagnostics(system, b, v, p, hidden, h)
        e0 = jnp.where(started, get["e0"], e)
        e_running = jnp.maximum(get["e_running"], jnp.where(jnp.isfinite(e), e, 0.0))
        floor = jnp.where(jnp.isfinite(e0), e0, 0.0) + 0.5 * jnp.abs(h) * get["inv_span"]
        band = HIDDEN_BAND * jnp.maximum(e_running, floor) + HIDDEN_FLOOR
        r = judged_ratio(r, e)
        rel = r / band
        new.update(e0=e0, e_running=e_running, ratio_max=jnp.maximum(get["ratio_max"], r),
                   band_ratio_max=jnp.maximum(get["band_ratio_max"], rel),
                   hidden_first_time=jnp.where(jnp.isnan(get["hidden_first_time"]) & (rel > 1.0), t,
                                               get["hidden_first_time"]))
    E = system.energy(b, v)
    K = 0.5 * jnp.dot(v, p)
    E0 = jnp.where(started, get["E0"], E)
    kmax = jnp.maximum(get["kinetic_max"], jnp.where(jnp.isfinite(K), jnp.abs(K), jnp.inf))
    drift = jnp.abs(E - E0)
    safe = jnp.where(kmax > 0, kmax, 1.0)
    rel = jnp.where(kmax > 0, drift / safe, jnp.where(drift > 0, jnp.inf, 0.0))
    rel = jnp.where(jnp.isfinite(E) & ~jnp.isnan(rel), rel, jnp.inf)
    rel = jnp.where(get["energy_applies"] > 0, rel, 0.0)
    new.update(E0=E0, kinetic_max=kmax, drift_max=jnp.maximum(get["drift_max"], rel),
               energy_first_time=jnp.where(jnp.isnan(get["energy_first_time"]) & ~(rel <= ENERGY_BAND), t,
                                           get["energy_first_time"]))
    out = jnp.stack([jnp.asarray(new[name], jnp.float64) for name in SLOTS])
    return jnp.where(active, out, monitor)


def _first_node(times, first_time):
    """The index of the first saved node at or after `first_time` (None if none)."""
    t = np.asarray(times, dtype=np.float64)
    if t.size == 0:
        return None
    s = 1.0 if t[-1] >= t[0] else -1.0  # a run backward in time: decreasing times
    later = np.flatnonzero(s * t >= s * first_time)
    return int(later[0]) if later.size else None


def hidden_verdict(monitor, times=None) -> HiddenMomentumVerdict:
    """The hidden-momentum verdict of one trajectory from its final `monitor` (a GNI-family run);
    `first_node` is the first saved node at or after the crossing (of `times`)."""
    m = np.asarray(monitor, dtype=np.float64)
    first = float(m[_I["hidden_first_time"]])
    out = not np.isnan(first)
    return HiddenMomentumVerdict(not out, first if out else None, _first_node(times, first) if out and times is not None else None,
                                 float(m[_I["ratio_max"]]), float(m[_I["band_ratio_max"]]))


def energy_verdict(monitor) -> EnergyVerdict | None:
    """The energy verdict of one trajectory from its final `monitor` (None where the energy is not
    a constant of its motion)."""
    m = np.asarray(monitor, dtype=np.float64)
    if not m[_I["energy_applies"]] > 0:
        return None
    first = float(m[_I["energy_first_time"]])
    out = not np.isnan(first)
    return EnergyVerdict(not out, first if out else None, float(m[_I["drift_max"]]))


def nodes_seen(monitor) -> int:
    """How many nodes the monitor has checked (each call's first node counts again when a run is
    continued)."""
    return int(np.asarray(monitor, dtype=np.float64)[..., _I["nodes"]].max())


class RunVerdicts:
    """The verdicts of one run from its final `monitor` (a streamed run: its last part's), as
    file attributes and warnings (as :class:`gnipy.Solution` gives them).

    Arguments:
        monitor: the run's final monitor, (SIZE,).
        gni_family: the method carries a hidden momentum (else there is no hidden verdict).
    """

    def __init__(self, monitor, gni_family: bool):
        self.hidden = hidden_verdict(monitor) if gni_family else None
        self.energy = energy_verdict(monitor)

    @property
    def in_band(self) -> bool:
        """Whether every verdict stayed in band."""
        return all(v is None or v.in_band for v in (self.hidden, self.energy))

    def attrs(self, method: str, system: str) -> dict:
        """The verdicts as file attributes (as :meth:`gnipy.Solution.to_xarray` writes them; the
        `health` attribute is the caller's, which knows whether the steps converged)."""
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


def start(monitor0, state0, h: float, steps: float, t0: float, energy_applies: bool):
    """The monitor a single run starts from (:mod:`gnipy.monitor`): a fresh one over this call's
    span, or the continued run's (`monitor0`, with `state0`)."""
    if monitor0 is None:
        return initial(h, steps * h, t0, energy_applies=energy_applies)
    if state0 is None:
        raise InputError("monitor0: give it with state0 (it continues the verdicts of the run state0 ends)")
    if isinstance(monitor0, (str, bytes, bool)) or np.ndim(monitor0) != 1:
        raise InputError(f"monitor0: expected Solution.monitor of an earlier single run, got {monitor0!r}")
    return continued(monitor0, h, t0)


def announce(sol, strict: bool = False, stacklevel: int = 3):
    """`sol`, after a :class:`~gnipy.QualitativeFailureWarning` when its steps converged but a
    verdict left its band (:attr:`Solution.healthy`); with `strict`, that is raised as
    :class:`~gnipy.QualitativeFailure` instead."""
    if not sol.success or sol.healthy:
        return sol
    texts = [w.removeprefix("WARNING: ") for w in sol.warnings()]
    message = f"{sol.system} with {sol.method}: {sol.health}.\n" + "\n".join(texts)
    if strict:
        times = [v.first_time for kind in ("hidden", "energy") for v in member_verdicts(sol, kind).values()
                 if not v.in_band]
        raise QualitativeFailure(message, time=min(times, default=None), solution=sol)
    warnings.warn(QualitativeFailureWarning(message), stacklevel=stacklevel)
    return sol


# The verdicts' helpers are functions, not methods: an equinox Module's method is bound by building
# a Module on every access (about 35 µs, measured), and every run reads them (gnipy.Solution.healthy).


def member_verdicts(sol, kind: str = "hidden") -> dict:
    """The verdicts of `sol` of one kind ("hidden" or "energy") by member index (a single trajectory:
    index 0); a member without one (not the GNI family, or an energy that its motion does not
    conserve) is left out."""
    attr = f"{kind}_verdict"
    if sol.batch_size is None:
        v = getattr(sol, attr)
        return {} if v is None else {0: v}
    if kind == "hidden" and sol.hidden_momentum is None:
        return {}
    if sol.monitor is not None:
        rows = np.asarray(sol.monitor)
        found = ((i, hidden_verdict(r, sol.t) if kind == "hidden" else energy_verdict(r))
                 for i, r in enumerate(rows))
    else:
        found = ((i, getattr(sol.member(i), attr)) for i in range(sol.batch_size))
    return {i: v for i, v in found if v is not None}


def verdicts_out(sol, kind: str):
    """`(verdicts, out, first)`: the verdicts of `sol` of one kind by member, the members out of band,
    and the one that left first (None when none did)."""
    verdicts = member_verdicts(sol, kind)
    out = [i for i, v in verdicts.items() if not v.in_band]
    first = min(out, key=lambda i: verdicts[i].first_time) if out else None
    return verdicts, out, first
