r"""The paper's open questions 1 and 3 (§Conclusions), measured: the studies behind `gni
open-questions` and the docs page "The paper's open questions".

**Question 1 (backward error analysis).** :func:`backward_error_row` computes, for one method on one
model, the modified vector field $\tilde f = f_1 + h f_2 + h^2 f_3$ of the method's one-step map
(:func:`gnipy.modified_equations`; the GNI family's two steps of h/2, whose map tends to the
identity) and tests it for the structure of a nonholonomic mechanical system:

- *the same constraints*: the configuration velocity of $\tilde f$ must lie in the distribution,
  $\mu(q)f_{j,q} = 0$ for every j (:meth:`~gnipy.analysis.ModifiedEquations.normal_velocity`),
  at states the method visits;
- *a modified energy*: a Lagrange–d'Alembert system with linear homogeneous constraints (the
  same or modified ones) and a time-independent Lagrangian conserves its energy, so if the
  discrete evolution is such a system to order $h^p$, its energy $\tilde E = E + h^pE_p + \dots$
  is conserved and $\nabla E\cdot f_{p+1} = -\tfrac{d}{dt}E_p$ along the motion: the integral
  $G(t) = \int_0^t \nabla E\cdot f_{p+1}$ along the exact motion must stay bounded. Then
  $E_k - E_0 \approx h^pG(t_k)$ predicts the method's energy error, which :func:`backward_error_row`
  compares with a run of `steps` steps (10⁶ by default);
- *phase volume*: the GNI's map has Jacobian determinant −1, so its field is divergence-free at
  every order ($\operatorname{tr} Df_1$ is measured).

**Question 3 (sister systems).** :func:`sister_convergence` measures how the sister motion
(:func:`gnipy.analysis.sister.sister_trajectory`) and the sister method
(:func:`gnipy.analysis.sister.sister_method`) approach the nonholonomic motion as the time
between switches τ (the step h) tends to 0: the fitted order, the error constant and the energy
the plastic impacts dissipate per unit time. :func:`sister_relations` compares one step of the
sister method with one step of `gni-trapezoid`, `dla` and the continuous sister phase, from the
same state, at several h: the order of the difference says whether two methods are the same
(round-off), agree to some order, or differ at first order.
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis.modified_equations import modified_equations
from ..analysis.orders import fitted_order
from ..analysis.sister import sister_method, sister_trajectory
from ..ensembles import model_systems
from ..errors import InputError
from ..simulate import simulate
from ..solution import SolverFailure

__all__ = ["BackwardErrorRow", "backward_error_row", "SisterStudy", "sister_convergence", "sleigh_peg",
           "sister_relations", "LongRun", "long_runs", "BE_MODELS", "BE_METHODS", "SISTER_CASES"]

#: The models of the backward-error table (linear constraints and a conserved energy): three on R^n and
#: Veselova's problem on SO(3) (constraints that depend on the orientation). A row on a group costs
#: about ten times one on R^n (the nested derivatives through the retraction): 11 minutes for
#: gni-trapezoid on the sleigh on SE(2), measured.
BE_MODELS = ("nonholonomic-particle", "knife-edge", "chaplygin-sleigh", "veselova")
#: The methods of the backward-error table.
BE_METHODS = ("gni-trapezoid", "gni-midpoint", "sgni-trapezoid", "dla", "mp", "discrete-gradient")
#: The sister studies: (model, constraint) with constraint "rail" or "peg" (the sleigh's only).
SISTER_CASES = (("knife-edge", "rail"), ("chaplygin-sleigh", "rail"), ("chaplygin-sleigh", "peg"),
                ("vertical-disk", "rail"), ("nonholonomic-particle", "rail"))

#: the time span over which G is integrated and the energy error predicted (the run goes on to steps·h)
PREDICTION_SPAN = 2000.0

#: the time span of a row's saved series (the figure's window)
SERIES_SPAN = 40.0

#: |f_j| below this (relative to |f_1|) counts as zero when the leading correction is sought
ZERO_COEFFICIENT = 1e-9


def _model(name: str):
    system = model_systems(name)[0]
    q0, v0 = system.defaults[:2]
    return system, np.asarray(q0, dtype=np.float64), np.asarray(v0, dtype=np.float64)


@dataclasses.dataclass
class BackwardErrorRow:
    """One method on one model (:func:`backward_error_row`).

    Attributes:
        model, method: the names.
        steps_per_map: 2 for the GNI family (two steps of h/2 are expanded), else 1.
        leading: the index j ≥ 2 of the first non-zero $f_j$ (the map's order in its own
            variables is j − 1), or None if $f_2, f_3$ vanish.
        coefficient_sizes: $\\max|f_j|$ over the sampled states, j = 1, 2, 3.
        normal_velocity: $\\max|\\mu(q)f_{j,q}|$ over the sampled states, j = 1, 2, 3.
        energy_rate: $\\max|\\nabla E\\cdot f_j|$ over the sampled states, j = 1, 2, 3.
        defect: $\\max|\\Phi_0(y) - y|$ over the sampled states (:meth:`~gnipy.analysis.ModifiedEquations.defect`):
            the premise of the expansion holds where it is at round-off; where it is not (dla,
            whose momentum leaves the constraints by O(h) and whose map tends to a projection
            there) the coefficients are not a modified field.
        divergence: $\\max|\\operatorname{tr}Df_1|$ over the sampled states.
        g_max, g_slope: $\\max|G_j|$ and the fitted slope of $G_j(t) = \\int_0^t\\nabla E\\cdot f_j$
            along the reference motion over the run's time span, j = 2, 3.
        predicted_max, predicted_slope: the same for the predicted energy error
            $E(t) - E(0) \\approx HG_2(t) + H^2G_3(t)$ (H the map's step: 2h for the GNI family).
        measured_max: $\\max|E_k - E_0|$ over the prediction's span (:data:`PREDICTION_SPAN`) of
            the run of `steps` steps of `h`; run_max, measured_slope: the largest $|E_k - E_0|$
            and the fitted slope of $E_k - E_0$ over the whole run.
        h, steps, runtime_s: the run's step, its number of steps, the row's wall time.
        failure: the run's failure (a step's solve), or None; verdicts: its run-time warnings.
        series: `t`, `measured` ($E_k - E_0$) and `predicted` over the first :data:`SERIES_SPAN`
            time units (None when the run failed).
    """

    model: str
    method: str
    steps_per_map: int
    leading: int | None
    coefficient_sizes: list
    normal_velocity: list
    energy_rate: list
    defect: float
    divergence: float
    g_max: list
    g_slope: list
    predicted_max: float
    predicted_slope: float
    measured_max: float
    run_max: float
    measured_slope: float
    h: float
    steps: int
    runtime_s: float
    failure: str | None = None
    verdicts: list = dataclasses.field(default_factory=list)
    series: dict | None = None


def _samples(me, y0, h: float, count: int, stride: int):
    """`count` states of the method's own run from y0 (every `stride` maps of step h)."""
    step = jax.jit(me.step_map)
    ys, y = [], y0
    for _ in range(count):
        ys.append(np.asarray(y))
        for _ in range(stride):
            y = step(y, h)
    return jnp.asarray(np.stack(ys))


def backward_error_row(model: str, method: str, *, h: float = 0.01, steps: int = 1_000_000,
                       samples: int = 8, span: float | None = None, grid: float = 0.25) -> BackwardErrorRow:
    """The backward-error tests of the module docstring for `method` on `model` (from the model's
    documented initial condition): the modified field to order 2 at `samples` states of the method's
    own run, $G(t)$ on a grid of spacing `grid` along the continuous reference over `span` (default
    the run's span up to :data:`PREDICTION_SPAN`), and a run of `steps` steps of `h` with :func:`gnipy.simulate`
    (its energies saved on the same grid)."""
    start = time.perf_counter()
    system, q0, v0 = _model(model)
    two = method.startswith("gni-")
    R0 = system.defaults[2] if len(system.defaults) > 2 else None  # on R^n x G (None: the identity)
    me = modified_equations(system, method, order=2, q=q0, v=v0, R=R0, steps=2 if two else 1)
    H = 2 * h if two else h  # the map's step: two GNI steps of h
    y0 = me.state(q0, v0, h, R0)
    ys = _samples(me, y0, H, samples, max(1, int(round(0.25 / H))))
    # jax.lax.map, not vmap: the samples one after another inside one program. A vmap of these
    # nested derivatives through batched while loops (the steps' Newton solves) wedged XLA:CPU's
    # thread pool twice here (0% CPU, waiting on the result; a known failure of vmap graphs on
    # XLA:CPU), and a batch gains little where every lane runs the longest solve anyway.

    def measure(y):
        fs = jnp.stack([me.coefficient(j)(y) for j in (1, 2, 3)])
        normal = jnp.stack([me.normal_part(y, f) for f in fs])
        rates = fs @ jax.grad(me.energy)(y)
        return fs, normal, rates, me.defect(y), me.divergence(y)

    fields, normal, rates, defects, divergences = (np.asarray(a) for a in jax.jit(lambda ys: jax.lax.map(measure, ys))(ys))
    sizes = np.abs(fields).max(axis=(0, 2))
    rates = np.abs(rates).max(axis=0)
    defect, divergence = float(defects.max()), float(np.abs(divergences).max())
    leading = next((j for j in (2, 3) if sizes[j - 1] > ZERO_COEFFICIENT * max(1.0, sizes[0])), None)
    # G(t) along the reference motion, on the grid; the states the method would start from there
    T = float(min(steps * h, PREDICTION_SPAN) if span is None else span)
    count = int(round(T / grid))
    ref = simulate(system, "reference", q0, v0, R0=R0, h=grid, steps=count)
    t = np.asarray(ref.t)
    grouped = system.group is not None
    rate = jax.jit(lambda qs, vs, Rs: jax.lax.map(
        lambda qvR: jnp.stack([me.energy_rate(me.state(qvR[0], qvR[1], h, qvR[2] if grouped else None), j)
                               for j in (2, 3)]), (qs, vs, Rs)))
    chunk = 4096  # every chunk of one length (the last padded): one compilation

    def padded(a):
        a = np.asarray(a)
        return np.concatenate([a, np.repeat(a[-1:], -t.size % chunk, axis=0)])

    # the orientations along the reference on R^n x G (a placeholder per node on R^n, unused)
    qs, vs, Rs = padded(ref.q), padded(ref.v), padded(ref.R if grouped else np.zeros((t.size, 1)))
    values = np.concatenate([np.asarray(rate(qs[i:i + chunk], vs[i:i + chunk], Rs[i:i + chunk]))
                             for i in range(0, qs.shape[0], chunk)])
    values = values[:t.size]
    G = np.concatenate([np.zeros((1, 2)), np.cumsum(0.5 * (values[1:] + values[:-1]) * np.diff(t)[:, None], axis=0)])
    g_max = [float(x) for x in np.abs(G).max(axis=0)]
    g_slope = [float(x) for x in np.polyfit(t, G, 1)[0]]
    predicted = G @ np.array([H, H * H])  # E(t) - E(0) ≈ H G_2(t) + H² G_3(t)
    predicted_max, predicted_slope = float(np.abs(predicted).max()), float(np.polyfit(t, predicted, 1)[0])
    failure, verdicts, series = None, [], None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the run's verdicts are recorded in the row
            run = simulate(system, method, q0, v0, R0=R0, h=h, steps=steps, save_every=max(1, int(round(grid / h))))
        E = np.asarray(run.energy)
        dE = E - E[0]
        window = np.asarray(run.t) <= T + 1e-9  # the span of the prediction
        measured_max = float(np.abs(dE[window]).max())
        run_max, measured_slope = float(np.abs(dE).max()), float(np.polyfit(np.asarray(run.t), dE, 1)[0])
        verdicts = [str(w) for w in run.warnings()]
        shown = np.asarray(run.t) <= min(SERIES_SPAN, T) + 1e-9  # the figure's window, on the same grid
        series = {"t": [float(x) for x in np.asarray(run.t)[shown]], "measured": [float(x) for x in dE[shown]],
                  "predicted": [float(x) for x in predicted[:int(shown.sum())]]}
    except SolverFailure as e:  # the GNI on a volume-contracting system: recorded, not raised
        failure, measured_max, run_max, measured_slope = str(e), float("nan"), float("nan"), float("nan")
    return BackwardErrorRow(model=model, method=method, steps_per_map=2 if two else 1, leading=leading,
                            coefficient_sizes=[float(x) for x in sizes],
                            normal_velocity=[float(x) for x in np.abs(normal).max(axis=(0, 2))],
                            energy_rate=[float(x) for x in rates], defect=defect, divergence=divergence, g_max=g_max,
                            g_slope=g_slope, predicted_max=predicted_max, predicted_slope=predicted_slope,
                            measured_max=measured_max, run_max=run_max, measured_slope=measured_slope, h=h, failure=failure, verdicts=verdicts, series=series,
                            steps=steps, runtime_s=time.perf_counter() - start)


def sleigh_peg(system):
    """Coleman–Holmes's peg for the Chaplygin sleigh: `constraint(q, anchor)`, the lateral position
    (in the body's frame) of the plane's point where the contact point was at the switch, $n(\\theta)\\cdot
    ((x, y) - c(q_k))$ with $c(q) = (x, y) - a(\\cos\\theta, \\sin\\theta)$ the contact point; its
    differential at the anchor is the sleigh's constraint row."""
    a = float(system.parameters["a"])

    def peg(q, anchor):
        th, tha = q[2], anchor[2]
        contact = anchor[:2] - a * jnp.stack([jnp.cos(tha), jnp.sin(tha)])
        normal = jnp.stack([-jnp.sin(th), jnp.cos(th)])
        return jnp.atleast_1d(normal @ (q[:2] - contact))

    return peg


@dataclasses.dataclass
class SisterStudy:
    """How a sister approaches the nonholonomic motion (:func:`sister_convergence`).

    Attributes:
        model, constraint: the model and the sister's constraint ("rail" or "peg").
        kind: "system" (the sister motion, τ between switches) or "method" (the sister method, step h).
        taus: τ (or h).
        errors: $\\max_k|q(t_k) - q_{ref}(t_k)|$ over the switches up to `t_final`.
        dissipation: the energy lost per unit time, $(E_0 - E(t_{final}))/t_{final}$.
        order, constant: the fitted order of the errors and $\\mathrm{error}/\\tau^{order}$ at the smallest τ.
        dissipation_order, dissipation_constant: the same for the dissipation.
        constraint_kept: the largest |φ_k| at a phase's end over all runs.
        t_final: the span.
    """

    model: str
    constraint: str
    kind: str
    taus: list
    errors: list
    dissipation: list
    order: float
    constant: float
    dissipation_order: float
    dissipation_constant: float
    constraint_kept: float
    t_final: float


def sister_convergence(model: str, constraint: str = "rail", kind: str = "system",
                       taus=(0.1, 0.05, 0.025, 0.0125, 0.00625), t_final: float = 2.0) -> SisterStudy:
    """The sister of `model` ("rail" or, for the Chaplygin sleigh, "peg") against the continuous
    reference from the model's initial condition, for each τ of `taus` (`kind="system"`: the sister
    motion; `"method"`: the sister method with h = τ)."""
    system, q0, v0 = _model(model)
    peg = sleigh_peg(system) if constraint == "peg" else None
    finest = min(taus)
    ref = simulate(system, "reference", q0, v0, h=finest, steps=int(round(t_final / finest)))
    run = sister_trajectory if kind == "system" else sister_method
    errors, dissipation, kept = [], [], 0.0
    for tau in taus:
        kwargs = {"tau": tau} if kind == "system" else {"h": tau}
        r = run(system, q0, v0, t_final=t_final, constraint=peg, **kwargs)
        stride = int(round(tau / finest))
        errors.append(float(np.abs(r.q - np.asarray(ref.q)[::stride]).max()))
        dissipation.append(float((r.energy[0] - r.energy[-1]) / t_final))
        kept = max(kept, float(r.constraint.max()))
    order = fitted_order(taus, errors)
    dorder = fitted_order(taus, np.abs(dissipation))
    i = int(np.argmin(taus))
    return SisterStudy(model=model, constraint=constraint, kind=kind, taus=[float(t) for t in taus], errors=errors,
                       dissipation=dissipation, order=float(order), constant=errors[i] / taus[i] ** order,
                       dissipation_order=float(dorder), dissipation_constant=abs(dissipation[i]) / taus[i] ** dorder,
                       constraint_kept=kept, t_final=t_final)


def sister_relations(model: str, hs=(0.1, 0.05, 0.025, 0.0125), samples: int = 4, span: float = 2.0) -> dict:
    """One step of the sister method (rail) against one step of other maps from the same state $(q, v)$
    on the reference motion (`samples` states over `span`): `gni-trapezoid` and `dla` (each started
    from $(q, v)$ as a run starts) and the continuous sister phase of length h. Returns, per
    comparison, the largest configuration difference at each h and its fitted order in h (a local
    difference of order r + 1 means the two agree to order r; round-off means the same map)."""
    system, q0, v0 = _model(model)
    ref = simulate(system, "reference", q0, v0, h=span / samples, steps=samples - 1)
    out = {}
    starts = list(zip(np.asarray(ref.q), np.asarray(ref.v)))
    for other in ("sister-system", "gni-trapezoid", "dla"):
        diffs = []
        for h in hs:
            worst = 0.0
            for q, v in starts:
                mine = sister_method(system, q, v, h=h, t_final=h).q[-1]
                if other == "sister-system":
                    theirs = sister_trajectory(system, q, v, tau=h, t_final=h).q[-1]
                else:
                    theirs = np.asarray(simulate(system, other, q, v, h=h, steps=1).q[-1])
                worst = max(worst, float(np.abs(mine - theirs).max()))
            diffs.append(worst)
        out[other] = {"h": [float(h) for h in hs], "difference": diffs, "order": float(fitted_order(hs, diffs))}
    return out


@dataclasses.dataclass
class LongRun:
    """One method on one model over a long span (:func:`long_runs`): the error at the end against
    the reference, the largest energy error, and the failure if a step's solve failed."""

    model: str
    method: str
    h: float
    t_final: float
    error: float
    energy_error: float
    failure: str | None
    verdicts: list


def long_runs(model: str, methods=("sister", "gni-trapezoid", "sgni-trapezoid", "dla"), *, h: float = 0.01,
              t_final: float = 50.0) -> list[LongRun]:
    """The sister method (`"sister"`, the rail) beside gnipy's methods on `model` from its initial
    condition: where it fails and where it does better."""
    system, q0, v0 = _model(model)
    steps = int(round(t_final / h))
    ref = simulate(system, "reference", q0, v0, h=t_final / 50, steps=50)
    q_ref, E0 = np.asarray(ref.q)[-1], float(np.asarray(ref.energy)[0])
    rows = []
    for method in methods:
        failure, verdicts, error, energy_error = None, [], float("nan"), float("nan")
        try:
            if method == "sister":
                r = sister_method(system, q0, v0, h=h, t_final=t_final)
                q_end, E = r.q[-1], r.energy
            else:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    s = simulate(system, method, q0, v0, h=h, steps=steps, save_every=steps // 50)
                q_end, E = np.asarray(s.q)[-1], np.asarray(s.energy)
                verdicts = [str(w) for w in s.warnings()]
            error, energy_error = float(np.abs(q_end - q_ref).max()), float(np.abs(E - E0).max())
        except (SolverFailure, InputError) as e:
            failure = str(e)
        rows.append(LongRun(model, method, h, t_final, error, energy_error, failure, verdicts))
    return rows
