"""The method atlas: every method on every zoo model over long horizons, and from it each model's
recommended method (`gni atlas`; the report is :mod:`gnipy.experiments.atlas_report`).

**One run per (model, method)** where the method applies (:meth:`Integrator.check` raises
:class:`~gnipy.MethodError` elsewhere), at the fixed step h of :data:`H` (the step of the rule,
:mod:`gnipy.experiments.choice_rule`) for `steps` steps (:func:`plan`: 10⁵ or 10⁶ in the full
atlas, chosen per model so that the whole atlas fits half an hour on 2 cores), saving the nodes
of every 10 steps up to the reference horizon `t_ref` and :data:`LONG_NODES` more nodes spread
over the rest. Measured (:class:`PairResult`):

- **error against the reference**: $\\max_k |q_k - q^{\\mathrm{ref}}(t_k)|$ over the saved nodes
  with $t_k \\le t_{\\mathrm{ref}}$ (with $\\|R_k - R^{\\mathrm{ref}}(t_k)\\|$ on
  $\\mathbb{R}^n\\times G$), against the continuous reference (`method="reference"`: Dopri8 at
  tolerance 1e-12) run to `t_ref` (200 in the full atlas, as the rule's measurement always was);
- **energy** (where the motion conserves it, :func:`gnipy.diagnostics.energy_is_invariant`) and
  **each registered invariant** (`gnipy.get_model(name).invariants`) over the whole run: the error
  $\\max_k |I_k - I_0|$ relative to the invariant's size along the reference (absolute, to 1e-6,
  for one that stays near zero), and its **growth**, the largest deviation in the last quarter of
  the run divided by the largest in the first quarter (about 1: a bounded error; 3 to 4: a linear
  drift; the deviations are floored at 1e-15 so that round-off reads about 1);
- the largest **constraint residual** of the reported velocities;
- the run-time **verdicts** (:mod:`gnipy.diagnostics`: the GNI family's hidden momentum, an energy
  drifting away) and solver failures;
- **reversibility**: from the last state, `steps` steps of $-h$ (`simulate(..., h=-h,
  state0=sol.final_state)`: a symmetric method runs its exact inverse there), then the largest
  difference of $(q, v, R)$ from the start, relative to max(1, |start|); measured for the methods
  symmetric on the model only (`simulate` refuses h < 0 for the others, whose formula at $-h$ is not
  their inverse: the table says "not symmetric");
- **cost per step**: the wall time of the long run divided by its steps, measured after a short run
  that compiles the same program (a run's compiled program depends only on how many nodes it saves),
  so it excludes compilation (reported apart: the first call's time).

**The recommendation** is :func:`gnipy.experiments.choice_rule.choose` (the documented rule,
stated there once) on these measurements: a method qualifies when the long run completes, raises no
warning and keeps every invariant to 1e-2; the smallest error against the reference wins, with the
rule's tie-breaks. The atlas is the source of the recorded defaults
(:mod:`gnipy.models.default_methods`, shown by `gni models`): it writes their module with its
recommendations (:func:`gnipy.experiments.atlas_report.default_methods_source`), and
`python -m gnipy.experiments.method_choice` runs the same measurement.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import verdicts_reported_by_caller
from .choice_rule import H, T_FINAL, MethodMeasurement, choose

__all__ = ["H", "QUICK_MODELS", "LONG_NODES", "Plan", "plan", "PairResult", "ModelResult", "AtlasResult",
           "measure_model", "run_atlas"]

#: Nodes saved over the part of a run after the reference horizon.
LONG_NODES = 1000
#: Steps between the saved nodes up to the reference horizon.
REF_EVERY = 10
#: Full atlas: the long runs' steps per model: 10⁵ (T = 1000), and 10⁶ (T = 10⁴) on three cheap models
#: on Rⁿ (a step there costs a few µs; compiling about 400 programs, a forward and a backward run for
#: each of the ~200 pairs, is most of the atlas's 19–23 minutes measured on 2 cores), and the
#: reference horizon.
FULL_STEPS_DEFAULT = 10**5
FULL_STEPS: dict[str, int] = {"nonholonomic-particle": 10**6, "contact-oscillator-mp": 10**6, "vertical-disk": 10**6}
FULL_T_REF = T_FINAL
#: Quick atlas (`gni atlas --quick`): these models (unless others are named: a linear constraint, a
#: stiff oscillation, the GNI's hidden-momentum failure), 2000 steps, the reference horizon 20.
QUICK_MODELS = ("nonholonomic-particle", "contact-oscillator", "chaplygin-sleigh")
QUICK_STEPS = 2000
QUICK_T_REF = 20.0


@dataclasses.dataclass(frozen=True)
class Plan:
    """How one model is run: step `h`, `steps` steps, error against the reference over
    t <= `t_ref` (nodes every `ref_every` steps there), `long_nodes` nodes after it; `reverse`:
    measure reversibility (one more run)."""

    h: float = H
    steps: int = FULL_STEPS_DEFAULT
    t_ref: float = FULL_T_REF
    ref_every: int = REF_EVERY
    long_nodes: int = LONG_NODES
    reverse: bool = True

    @property
    def t_final(self) -> float:
        return self.steps * self.h

    @property
    def ref_steps(self) -> int:
        return min(round(self.t_ref / self.h), self.steps)

    def save_steps(self) -> np.ndarray:
        """The step indices of the saved nodes (0 and the last included)."""
        dense = np.arange(0, self.ref_steps + 1, self.ref_every)
        tail = np.linspace(self.ref_steps, self.steps, self.long_nodes + 1).round().astype(np.int64)
        return np.unique(np.concatenate([dense, tail, [self.ref_steps, self.steps]]))


def plan(name: str, quick: bool = False) -> Plan:
    """The atlas's plan for the zoo model `name` (module docstring)."""
    if quick:
        return Plan(steps=QUICK_STEPS, t_ref=QUICK_T_REF, long_nodes=100)
    return Plan(steps=FULL_STEPS.get(name, FULL_STEPS_DEFAULT))


@dataclasses.dataclass
class PairResult:
    """One method on one model (module docstring). The energy and invariant errors are relative
    (see there); None: not measured (not diagnosed, not conserved, or the run did not get there).

    Attributes:
        model, method: the names.
        order, symmetric: the method's expected order (0: unknown) and whether it is symmetric on
            this model (`method.symmetric_on(system)`: e.g. the midpoint GNI is not on a system
            whose Lagrangian depends on the orientation).
        completed: every step converged (else `failed_time` is the time of the last good node).
        warnings: the run's warnings (:meth:`gnipy.Solution.warnings`).
        error: the error against the reference over t <= t_ref (inf when the run failed).
        energy_error, energy_growth: the energy's error and growth (None where not conserved).
        invariants: invariant name -> (error, growth).
        constraint_residual: the largest constraint residual.
        hidden_max, hidden_in_band: the hidden-momentum ratio's maximum and verdict (GNI family).
        energy_verdict_max, energy_in_band: the energy verdict (largest |E - E0| / max K).
        reversibility: the distance to the start after `steps` steps back (None: not measured, e.g.
            for a method that is not symmetric on this model, which cannot run back).
        cost_us: microseconds per step (after compilation); compile_s: the first call's time.
        iterations: Newton iterations per step (mean).
        note: what went wrong, when something did.
    """

    model: str
    method: str
    order: int = 0
    symmetric: bool = False
    completed: bool = False
    failed_time: float | None = None
    warnings: tuple[str, ...] = ()
    error: float = math.inf
    energy_error: float | None = None
    energy_growth: float | None = None
    invariants: dict = dataclasses.field(default_factory=dict)
    constraint_residual: float = math.nan
    hidden_max: float | None = None
    hidden_in_band: bool | None = None
    energy_verdict_max: float | None = None
    energy_in_band: bool | None = None
    reversibility: float | None = None
    cost_us: float = math.nan
    compile_s: float = math.nan
    iterations: float = 0.0
    note: str = ""

    @property
    def invariant_drift(self) -> float:
        """The largest relative error of the energy (where conserved) and the invariants."""
        values = [self.energy_error or 0.0] + [e for e, _ in self.invariants.values()]
        return max(values)

    @property
    def measurement(self):
        """This pair as a :class:`~gnipy.experiments.choice_rule.MethodMeasurement` (the rule's input)."""
        return MethodMeasurement(self.method, self.error if self.completed else math.inf, self.invariant_drift,
                                 self.warnings, not self.completed, self.iterations, self.constraint_residual,
                                 self.order, self.hidden_max is not None)

    @property
    def qualifies(self) -> bool:
        """The rule's qualification (:attr:`MethodMeasurement.qualifies`)."""
        return self.measurement.qualifies

    @property
    def verdict(self) -> str:
        """`failed`, `warning`, `drift` (an invariant not kept to the rule's tolerance) or `ok`."""
        if not self.completed:
            return "failed"
        if self.warnings:
            return "warning"
        return "ok" if self.qualifies else "drift"


@dataclasses.dataclass
class ModelResult:
    """The atlas of one model: its plan, the measured pairs, the methods that do not apply (name ->
    why), the recommendation `(method, reason)` and the recorded default (`gni models`)."""

    model: str
    plan: Plan
    pairs: list[PairResult]
    not_applicable: dict[str, str]
    recommended: tuple[str, str]
    recorded: str | None
    runtime_s: float = 0.0
    reference_s: float = 0.0
    note: str = ""

    @property
    def agrees(self) -> bool:
        """Whether the recommendation is the recorded default."""
        return self.recommended[0] == self.recorded

    def pair(self, method: str) -> PairResult | None:
        return next((p for p in self.pairs if p.method == method), None)


@dataclasses.dataclass
class AtlasResult:
    """Everything :func:`run_atlas` measured: one :class:`ModelResult` per model, the methods asked
    for, the mode (`quick` or `full`) and the run time."""

    models: list[ModelResult]
    methods: list[str]
    quick: bool
    runtime_s: float

    @property
    def disagreements(self) -> list[ModelResult]:
        return [m for m in self.models if not m.agrees]


# ------------------------------------------------------------------------------------------------
# measurements
# ------------------------------------------------------------------------------------------------
class _Invariant:
    """One registered invariant over the saved nodes: vectorized and compiled once per model where
    the function traces (jax), else evaluated node by node (a function written with numpy)."""

    def __init__(self, f, params):
        import jax

        from ..compilation import compiler_options

        self.f, self.params = f, params
        self.with_R = len(inspect.signature(f).parameters) >= 4
        self.traced = True
        if self.with_R:
            self.g = jax.jit(jax.vmap(lambda q, v, R: f(params, q, v, R)), compiler_options=compiler_options())
        else:
            self.g = jax.jit(jax.vmap(lambda q, v: f(params, q, v)), compiler_options=compiler_options())

    def __call__(self, q, v, R) -> np.ndarray:
        args = (q, v, R) if self.with_R else (q, v)
        if self.traced:
            try:
                with np.errstate(all="ignore"):
                    return np.asarray(self.g(*args), dtype=np.float64)
            except Exception:  # not traceable: node by node from now on
                self.traced = False
        with np.errstate(all="ignore"):
            return np.asarray([float(self.f(self.params, *(a[k] for a in args))) for k in range(len(q))],
                              dtype=np.float64)


def invariant_functions(spec, params) -> dict[str, _Invariant]:
    """name -> the invariant over the saved nodes (:class:`_Invariant`)."""
    return {name: _Invariant(f, params) for name, f in spec.invariants.items()}


def invariants_along(functions, sol) -> dict[str, np.ndarray]:
    """Each invariant of `functions` (:func:`invariant_functions`) at the saved nodes of `sol`, name -> (T,)."""
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    R = None if sol.R is None else np.asarray(sol.R)
    return {name: g(q, v, R) for name, g in functions.items()}


def _scale(reference_values) -> float:
    """The size of an invariant along the reference (1e-6 at least: near-zero invariants absolute)."""
    return max(float(np.max(np.abs(reference_values))), 1e-6)


def relative_error(values, scale: float) -> float:
    """$\\max_k |I_k - I_0|$ / scale (inf when a value is not finite)."""
    values = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(values)):
        return math.inf
    return float(np.max(np.abs(values - values[0])) / scale)


def growth(t, values, scale: float) -> float:
    """Largest deviation from the start in the last quarter of the run over the largest in the first
    quarter (each relative to `scale` and floored at 1e-15); NaN when it cannot be told."""
    t, values = np.asarray(t, dtype=np.float64), np.asarray(values, dtype=np.float64)
    if t.size < 8 or not np.all(np.isfinite(values)):
        return math.nan
    dev = np.abs(values - values[0]) / scale
    t0, t1 = t[0], t[-1]
    first = dev[(t > t0) & (t <= t0 + 0.25 * (t1 - t0))]
    last = dev[t >= t0 + 0.75 * (t1 - t0)]
    if first.size == 0 or last.size == 0:
        return math.nan
    return float((np.max(last) + 1e-15) / (np.max(first) + 1e-15))


def _distance(a, b) -> float:
    a, b = np.asarray(a, dtype=np.float64).ravel(), np.asarray(b, dtype=np.float64).ravel()
    return float(np.max(np.abs(a - b), initial=0.0))


def _reversibility(system, method, sol, p: Plan) -> float:
    """(q, v, R) after `steps` steps back from the run's last state, against the start."""
    import gnipy

    with verdicts_reported_by_caller():  # a run back over a motion that went wrong may go wrong too
        back = gnipy.simulate(system, method, h=-p.h, steps=p.steps, state0=sol.final_state, t0=float(sol.t[-1]),
                              saveat=gnipy.SaveAt(t1=True), throw=False)
    if back.result != 0:
        return math.inf
    parts = [(back.q[-1], sol.q[0]), (back.v[-1], sol.v[0])]
    if sol.R is not None:
        parts.append((back.R[-1], sol.R[0]))
    start = max([1.0] + [float(np.max(np.abs(np.asarray(b)), initial=0.0)) for _, b in parts])
    d = max(_distance(a, b) for a, b in parts)
    return d / start if math.isfinite(d) else math.inf


def _measure_pair(system, method: str, p: Plan, ref, ref_inv, energy_scale, functions, ts) -> PairResult | str:
    """One pair (module docstring), or the reason the method does not apply."""
    import gnipy

    m = gnipy.get_method(method)
    symmetric = m.symmetric_on(system) if hasattr(m, "symmetric_on") else bool(getattr(m, "symmetric", False))
    out = PairResult(system.name, method, int(m.order or 0), bool(symmetric))
    saveat = gnipy.SaveAt(ts=tuple(ts))
    try:
        t = time.perf_counter()  # a short run that saves as many nodes: the same compiled program
        with verdicts_reported_by_caller():
            gnipy.simulate(system, method, h=p.h, steps=len(ts) - 1, throw=False)
        out.compile_s = time.perf_counter() - t
    except gnipy.MethodError as e:
        return str(e)
    t = time.perf_counter()
    with verdicts_reported_by_caller():  # the atlas reports every verdict in its table
        sol = gnipy.simulate(system, method, h=p.h, steps=p.steps, saveat=saveat, throw=False)
    q = np.asarray(sol.q)
    out.cost_us = (time.perf_counter() - t) / p.steps * 1e6
    out.completed = sol.result == 0
    if not out.completed:
        out.failed_time = float(sol.t[-1])
        out.note = sol.message
    out.warnings = tuple(sol.warnings())
    its = np.asarray(sol.iterations)
    out.iterations = float(its[0]) / max(sol.steps, 1)
    # error against the reference, over the nodes with t <= t_ref
    n = min(len(sol.t), len(ref.t))
    err = float(np.max(np.abs(q[:n] - np.asarray(ref.q)[:n]), initial=0.0))
    if sol.R is not None:
        err = max(err, float(np.max(np.abs(np.asarray(sol.R)[:n] - np.asarray(ref.R)[:n]), initial=0.0)))
    out.error = err if out.completed and math.isfinite(err) else math.inf
    with np.errstate(all="ignore"):
        out.constraint_residual = float(np.max(np.abs(np.asarray(sol.constraint_residual)), initial=0.0))
    if sol.energy_invariant:
        E = np.asarray(sol.energy)
        out.energy_error, out.energy_growth = relative_error(E, energy_scale), growth(sol.t, E, energy_scale)
    for name, values in invariants_along(functions, sol).items():
        if np.all(np.isfinite(ref_inv[name])):
            s = _scale(ref_inv[name])
            out.invariants[name] = (relative_error(values, s), growth(sol.t, values, s))
    hv, ev = sol.hidden_verdict, sol.energy_verdict
    if hv is not None:
        out.hidden_max, out.hidden_in_band = float(hv.max_ratio), bool(hv.in_band)
    if ev is not None:
        out.energy_verdict_max, out.energy_in_band = float(ev.max_drift), bool(ev.in_band)
    if p.reverse and out.completed and out.symmetric:  # h < 0 is refused for the others (no inverse)
        try:
            out.reversibility = _reversibility(system, method, sol, p)
        except Exception as e:  # reported, never fatal: the forward measurements stand
            out.note = f"reversibility not measured: {type(e).__name__}: {e}"
    return out


def measure_model(name: str, p: Plan | None = None, *, methods: Sequence[str] | None = None,
                  progress: Callable[[str, str], None] | None = None, quick: bool = False) -> ModelResult:
    """The atlas of the zoo model `name`: every method of `methods` (default: all but the reference)
    by plan `p` (default :func:`plan`); `progress(model, method)` is called after each method."""
    import gnipy

    t_start = time.perf_counter()
    p = p or plan(name, quick)
    spec = gnipy.get_model(name)
    params = spec.resolve_params()
    system = spec.system()
    methods = [m for m in (methods or gnipy.method_names()) if m != "reference"]
    idx = p.save_steps()
    ts = idx * p.h
    t = time.perf_counter()
    ref_ts = ts[idx <= p.ref_steps]
    ref = gnipy.simulate(system, "reference", h=p.h, steps=p.ref_steps, saveat=gnipy.SaveAt(ts=tuple(ref_ts)))
    reference_s = time.perf_counter() - t
    functions = invariant_functions(spec, params)
    ref_inv = invariants_along(functions, ref)
    energy_scale = _scale(np.asarray(ref.energy))
    pairs, not_applicable = [], {}
    for method in methods:
        try:
            r = _measure_pair(system, method, p, ref, ref_inv, energy_scale, functions, ts)
        except Exception as e:  # a method that breaks is a finding of the atlas, not the end of it
            r = PairResult(name, method, note=f"{type(e).__name__}: {str(e).strip()[:300]}")
        if isinstance(r, str):
            not_applicable[method] = r
        else:
            pairs.append(r)
        if progress is not None:
            progress(name, method)
    recommended = choose([r.measurement for r in pairs], h=p.h, t_final=p.t_final, t_ref=p.t_ref)
    return ModelResult(name, p, pairs, not_applicable, recommended, spec.default_method,
                       time.perf_counter() - t_start, reference_s)


def run_atlas(*, quick: bool = False, models: Sequence[str] | None = None, methods: Sequence[str] | None = None,
              progress: Callable[..., None] | None = None, plans: dict[str, Plan] | None = None) -> AtlasResult:
    """Measure the atlas: `models` (default: every zoo model; with `quick`, :data:`QUICK_MODELS`) ×
    `methods` (default: every method but the reference), each model by :func:`plan` (or
    `plans[model]`). `progress(done, total, description)` is called after each pair (the form
    :class:`gnipy.cli.progress.Progress` takes)."""
    import gnipy

    t_start = time.perf_counter()
    names = list(models) if models else (list(QUICK_MODELS) if quick else gnipy.model_names())
    methods = [m for m in (methods or gnipy.method_names()) if m != "reference"]
    total, done = len(names) * len(methods), [0]

    def tick(model: str, method: str) -> None:
        done[0] += 1
        if progress is not None:
            progress(done[0], total, f"{model}: {method}")

    results = []
    for n in names:
        p = (plans or {}).get(n) or plan(n, quick)
        try:
            results.append(measure_model(n, p, methods=methods, progress=tick))
        except Exception as e:  # a model that cannot be measured (its reference run) is reported, not fatal
            results.append(ModelResult(n, p, [], {}, ("reference", f"not measured: {type(e).__name__}: {e}"),
                                       gnipy.get_model(n).default_method, note=f"{type(e).__name__}: {e}"))
            done[0] = (names.index(n) + 1) * len(methods)
    return AtlasResult(results, methods, quick, time.perf_counter() - t_start)
