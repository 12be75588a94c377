"""The paper's theorems and its errata, measured by running gnipy.

Two calls, both `(quick, progress=None)`:

- :func:`theorem_table` -> list of :class:`Row`: each claim of the paper that gnipy can check by
  running it, with the paper's statement, the measured value and pass/fail:

  * Theorem 5.1 and the remarks of §5: fitted convergence orders of nonholonomic Euler A and B
    ((EuAHam), (EuBHam): 1), RATTLE ((nonholonomicRATTLE), [SDD2]: 2), the composition
    $F_A^{h/2}\\circ F_B^{h/2}$ (remark after Thm 5.2: 2), the GNI with the Euler A, Euler B,
    trapezoid and midpoint discrete Lagrangians (1, 1, 2, 2), on the nonholonomic particle against
    the continuous reference;
  * Theorem 5.2: $F_A^h\\circ F_B^{-h} = \\mathrm{Id}$, residual over random constrained states;
  * §4 (after (GNIloc)) and §6: the reported momentum of every GNI variant satisfies the
    constraints exactly;
  * §4 (end, [SDD1]): on SO(3) with a bi-invariant metric, an attitude-dependent distribution and
    a left-invariant $l_d$, the GNI conserves the energy: relative drift of $|p^+_k|$ over
    $10^4$ (quick) or $10^5$ steps;
  * §5: the explicit schemes (EuAHam), (EuBHam), (nonholonomicRATTLE) are the GNI with the Euler A,
    Euler B and trapezoid $l_d$ (equal node by node).

- :func:`errata_rows` -> list of :class:`Erratum`: the misprints and readings of the paper
  (docs/conventions.md, "Errata"), each with a measurement that shows the printed form failing and the
  corrected one holding.

**Order study.** Each method integrates the nonholonomic particle ($l = \\tfrac12|\\dot q|^2 -
\\tfrac12(x^2 + y^2)$, $\\dot z = y\\dot x$) to T = 2 with h = T/2^j (j = 5..8 quick, 5..10 full);
the error is the largest $|q - q_\\mathrm{ref}|$ at t = 0, 0.5, 1, 1.5, 2 and the order is the
least-squares slope of log(error) against log(h) over the points above round-off (1e-11), as in
`tests/test_convergence_orders.py`. The reference (:func:`continuous_reference`) integrates gnipy's
Lagrange–d'Alembert equations (:func:`gnipy.reference.lagrange_dalembert_acceleration`) with
scipy's DOP853 at tolerance 1e-12, restarted at every save time; it compiles only the right-hand
side, where :class:`gnipy.ContinuousReference` (diffrax) compiles a whole adaptive solver (about 5 s
on one core here). The full run also solves with :class:`gnipy.ContinuousReference` and reports the
gap between the two.

**Compile time.** Every run of one method goes through one jit-compiled driver
(:func:`run_all_nodes`) whose h and step count are traced: one compilation per method and system,
not per h. The rolling ball runs of the errata go through :func:`gnipy.experiments.figures.run_nodes`,
which the figures compile already (when the figures ran first in the same process, the errata
compile nothing new).

**Progress.** `progress(advance, description)` is called as work proceeds; the advances of one
call add up to 1.0 (as for the figures).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ..compilation import jit
from ..discrete_lagrangians import CustomDiscreteLagrangian, EulerA, Trapezoid
from ..integrators import paper_schemes as ps
from ..integrators.gni import GNI
from ..lie_groups import SO3
from ..methods import get_method
from ..models import get_model
from ..models import rolling_ball as rb
from ..plots import fitted_order as _plots_fitted_order
from ..reference import ContinuousReference, lagrange_dalembert_acceleration
from ..system import System, project_velocity

__all__ = [
    "Row",
    "Erratum",
    "theorem_table",
    "errata_rows",
    "fitted_order",
    "run_all_nodes",
    "continuous_reference",
    "constrained_tilde_states",
    "LiteralEulerABComposition",
    "five_equations",
    "cayley_steps",
    "energy_theorem_system",
    "ORDER_TOL",
    "ROUND_OFF",
]

Progress = Callable[[float, str], None] | None

EPS = float(np.finfo(np.float64).eps)
#: Tolerance on a fitted order against the paper's claim.
ORDER_TOL = 0.15
#: Errors at or below this are round-off, not truncation, and are left out of fitted slopes.
ROUND_OFF = 1e-11
#: The constraint residual bound (absolute; the velocities are of order 1).
EQUAL_TOL = 1e-12
#: Two formulations of one scheme agree to EQUAL_PER_STEP · N · eps (relative) after N steps: a few
#: eps of round-off per step, accumulating at most linearly, with a margin.
EQUAL_PER_STEP = 20.0
#: Round-off model of the energy theorem: drift ≤ ROUNDOFF_WALK · √N · eps (random walk, a few eps a step).
ROUNDOFF_WALK = 25.0


@dataclasses.dataclass(frozen=True)
class Row:
    """One checked claim of the paper.

    Attributes:
        claim: the statement, in words.
        paper_ref: where the paper makes it (theorem, remark, equation label).
        expected: what the paper says (e.g. "order 1", "0 (exact)").
        measured: what gnipy measured, formatted.
        passed: whether the measurement agrees with the claim within the stated tolerance.
        detail: how it was measured (system, steps, tolerance, controls).
        values: the measured numbers (e.g. `{"order": 1.01}`), for programs and tests.
    """

    claim: str
    paper_ref: str
    expected: str
    measured: str
    passed: bool
    detail: str
    values: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True)
class Erratum:
    """A misprint or a reading of the paper, with the measurement that shows it.

    Attributes:
        location: where in the paper (section, equation label).
        printed: the form as printed.
        corrected: the corrected form (or reading).
        measurement: what was run and measured, with both numbers.
        evidence_value: the headline number: how far the printed form is off (a relative residual,
            a difference of trajectories, or a fitted order where the finding is about order).
        values: every measured number, e.g. `printed_residual` and `corrected_residual`.
    """

    location: str
    printed: str
    corrected: str
    measurement: str
    evidence_value: float
    values: dict = dataclasses.field(default_factory=dict)


class _Work:
    """Feeds `progress(advance, description)` so that the advances of one call add up to 1.0."""

    def __init__(self, progress: Progress, weights: dict[str, float]):
        self.progress = progress
        self.weights = weights
        self.total = float(sum(weights.values()))
        self.done = 0.0

    def __call__(self, stage: str, description: str):
        if self.progress is None:
            return
        adv = self.weights.get(stage, 0.0) / self.total
        adv = min(adv, 1.0 - self.done)
        self.done += adv
        self.progress(max(adv, 0.0), description)

    def finish(self, description: str):
        if self.progress is not None and self.done < 1.0:
            self.progress(1.0 - self.done, description)
            self.done = 1.0


# ------------------------------------------------------------------------------------------------
# Shared numerics
# ------------------------------------------------------------------------------------------------
def fitted_order(hs: Sequence[float], errors: Sequence[float], floor: float = ROUND_OFF) -> float:
    """Least-squares slope of log(error) against log(h) over the points with error > `floor`;
    NaN when fewer than three such points remain (:func:`gnipy.plots.fitted_order` with
    `min_points=3`)."""
    return _plots_fitted_order(hs, errors, floor, min_points=3)


def _finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jtu.tree_leaves(tree) if eqx.is_inexact_array(x)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


@jit
def _drive(method, system, b0, v0, h, n, length: int, project: bool, keep_states: bool):
    """Start `method` at `(b0, v0)` (v0 projected onto the constraints if `project`) and take `n` ≤
    `length` steps; return the observations at nodes 0..length (nodes past n repeat node n).

    `h` and `n` are traced: every run of one method on one system shares one
    compilation. The start is compiled with the run: the integrators' `init` and the system's
    checks are many small operations, slow when dispatched one by one.
    """
    if project:
        v0 = project_velocity(system, b0, v0)
    state0 = method.init(system, b0, v0, h)

    def observe(state):
        b, v, p = method.observe(system, state, h)
        return b, v, p, system.constraint_residual(b, v)

    def body(carry, i):
        state, ok = carry
        new, info = method.step(system, state, h)
        active = i < n
        ok = ok & jnp.where(active, info.ok & _finite(new), True)
        new = jtu.tree_map(lambda a, b: jnp.where(active, a, b), new, state)
        return (new, ok), (observe(new), new if keep_states else None)

    (_, ok), (obs, states) = jax.lax.scan(body, (state0, jnp.asarray(True)), jnp.arange(length))
    obs = jtu.tree_map(lambda a, b: jnp.concatenate([a[None], b]), observe(state0), obs)
    if keep_states:
        states = jtu.tree_map(lambda a, b: jnp.concatenate([a[None], b]), state0, states)
    return obs, states, v0, system.constraint_residual(b0, v0), ok


@jit
def _step_velocity_residual(system, q, h):
    """μ(q_k)(Δ_k − Y(q_k)) for the step velocity Δ_k = (q_{k+1} − q_k)/h (on $\\mathbb{R}^n$)."""
    return jax.vmap(system.constraint_residual)(q[:-1], (q[1:] - q[:-1]) / h)


_CHECKED: dict = {}


@jit
def _metric_is_constant(system, b0):
    """$\\partial\\mathbb{G}/\\partial q = 0$ exactly at two random points near `b0` (the test of
    :meth:`gnipy.System.has_constant_metric`, compiled: op by op it costs about 2 s the first time)."""
    rng = np.random.default_rng(1)
    nonzero = []
    for _ in range(2):
        b = system.space.move(b0, jnp.asarray(0.3 * rng.standard_normal(system.dim)))
        dG = jax.jacfwd(lambda w, b=b: system.metric(system.space.move(b, w)))(jnp.zeros(system.dim))
        nonzero.append(jnp.any(dG != 0.0))
    return ~jnp.any(jnp.stack(nonzero))


def _prepared(method, system, b0):
    """The method checked and prepared for the system, as in :func:`gnipy.simulate` (cached per
    pair). On $\\mathbb{R}^n$ with a constant metric the checks are answered by one compiled
    evaluation: the paper's explicit schemes require nothing else, and the GNI takes its explicit
    fast path for the built-in discrete Lagrangians exactly as :meth:`gnipy.GNI.prepare` decides."""
    if isinstance(method, str):
        method = get_method(method)
    key = (type(method), type(getattr(method, "discrete_lagrangian", None)), id(system))
    if key not in _CHECKED:
        flat_constant = system.group is None and bool(_metric_is_constant(system, b0))
        if flat_constant and isinstance(method, (ps._TildeScheme, ps.Shake)):
            prepared = method  # their check is require_constant_metric
        elif (flat_constant and isinstance(method, GNI) and method.explicit is None
              and not isinstance(method.discrete_lagrangian, CustomDiscreteLagrangian)):
            prepared = dataclasses.replace(method, explicit=bool(type(method.discrete_lagrangian).explicit_if_flat))
        else:
            method.check(system, b0)
            prepared = method.prepare(system, b0)
        _CHECKED[key] = (prepared, system)  # keeps `system` alive: ids stay unique
    return _CHECKED[key][0]


def run_all_nodes(method, system, q0, v0, h: float, steps: int, *, length: int | None = None, R0=None,
                  project_v0: bool = False, states: bool = False, tol: float = 1e-10):
    """Run `method` (an integrator or a method name) for `steps` steps of size `h` and return every
    node, through one compiled driver per (method, system, length).

    Unlike :func:`gnipy.simulate`, the system is not validated (:meth:`gnipy.System.check`): only
    the initial velocity is checked against the constraints. For the fixed systems of the paper.

    Arguments:
        method: an integrator object or a method name.
        system: the :class:`~gnipy.System`.
        q0, v0, R0: the initial condition (as for :func:`gnipy.simulate`).
        h: step size.
        steps: number of steps.
        length: the compiled scan length (≥ steps; default `steps`). Runs with different `steps`
            and `h` but one `length` share one compilation.
        project_v0: project `v0` onto the constraints ($\\mathbb{G}$-orthogonally).
        states: also return the stacked integrator states (e.g. the GNI's $p^+_k$).
        tol: tolerance of the check of `v0`.

    Returns:
        A dict of numpy arrays over the nodes 0..steps: `q` (coordinates), `v`, `p` (reported
        velocity and momentum), `residual` (μ(v − Y)), `R` (orientations, or None),
        `v0` (the velocity started from), `states` (if asked) and, on $\\mathbb{R}^n$, `step_residual`
        (μ(Δ_k − Y) for the step velocity Δ_k = (q_{k+1} − q_k)/h, a control: it is not on the
        constraints).

    Raises:
        ValueError: `v0` violates the constraints (without `project_v0`).
        RuntimeError: a step failed (no convergence or a non-finite value).
    """
    length = steps if length is None else int(length)
    if not 1 <= steps <= length:
        raise ValueError(f"steps = {steps} must lie in 1..length = {length}")
    b0 = system.initial_point(q0, R0)
    method = _prepared(method, system, b0)
    hj = jnp.asarray(h, jnp.float64)
    (b, v, p, res), st, v_start, start_res, ok = _drive(
        method, system, b0, jnp.asarray(v0, jnp.float64), hj, jnp.asarray(steps, jnp.int32),
        length, bool(project_v0), bool(states))
    if not bool(ok):
        raise RuntimeError(f"{method.name}: a step failed (h = {h:g}, {steps} steps)")
    scale = max(1.0, float(np.max(np.abs(np.asarray(v_start)))))
    if float(np.max(np.abs(np.asarray(start_res)), initial=0.0)) > tol * scale:
        raise ValueError(f"v0 violates the constraints of {system.name!r} (pass project_v0=True)")

    def cut(a):
        return None if a is None else np.asarray(a)[: steps + 1]

    space = system.space
    out = {"q": cut(space.coordinates(b)), "v": cut(v), "p": cut(p), "residual": cut(res),
           "R": cut(space.orientation(b)), "v0": np.asarray(v_start)}
    if system.group is None:  # same shapes for every run of one length: one compilation
        out["step_residual"] = np.asarray(_step_velocity_residual(system, b, hj))[:steps]
    if states:
        out["states"] = jtu.tree_map(cut, st)
    return out


def _bare(system: System) -> System:
    """The same functions under default static metadata (name, params), so that systems of one
    model with different parameter values share compilations."""
    group = system.group
    return System(
        system.lagrangian, system.constraints, system.affine, n=system.n, group=group,
        retraction=system.space.retraction if group is not None else "cayley",
        depends_on_orientation=system.depends_on_orientation, reconstruction=system.reconstruction or "left",
        name="theorem-table",
    )


@jit
def _constraint_residual(system, b, v):
    return system.constraint_residual(b, v)


@jit
def _ldap_rhs(system, y):
    space = system.space
    N = system.dim
    b, v = space.unpack(y[:-N]), y[-N:]
    a, _ = lagrange_dalembert_acceleration(system, b, v)
    return jnp.concatenate([space.pack_velocity(b, v), a])


def continuous_reference(system, q0, v0, times, *, R0=None, rtol: float = 1e-12, atol: float = 1e-12):
    """The continuous solution at `times` (from `times[0]`): gnipy's Lagrange–d'Alembert(–Poincaré)
    equations (:func:`gnipy.reference.lagrange_dalembert_acceleration`, the equations of
    :class:`gnipy.ContinuousReference`) integrated by scipy's DOP853, restarted at every save time
    (no dense-output interpolation).

    Returns:
        `(q, v, R)` as numpy arrays over `times` (R is None on $\\mathbb{R}^n$).
    """
    from scipy.integrate import solve_ivp

    times = np.asarray(times, dtype=np.float64)
    b0 = system.initial_point(q0, R0)
    bare = _bare(system)
    res = np.asarray(_constraint_residual(bare, b0, jnp.asarray(v0, jnp.float64)))
    if np.max(np.abs(res), initial=0.0) > 1e-10 * max(1.0, float(np.max(np.abs(v0)))):
        raise ValueError(f"v0 violates the constraints of {system.name!r}")
    space = system.space
    y = np.concatenate([np.asarray(space.pack(b0)), np.asarray(v0)])

    def f(t, y):
        return np.asarray(_ldap_rhs(bare, jnp.asarray(y)))

    ys = [y]
    for t0, t1 in itertools.pairwise(times):
        sol = solve_ivp(f, (t0, t1), y, method="DOP853", rtol=rtol, atol=atol)
        if not sol.success:
            raise RuntimeError(f"continuous reference: {sol.message}")
        y = sol.y[:, -1]
        ys.append(y)
    Y = np.stack(ys)
    N, n = system.dim, system.n
    q = Y[:, :n]
    R = None if system.group is None else Y[:, n:-N].reshape(len(times), *np.shape(b0.R))
    return q, Y[:, -N:], R


# ------------------------------------------------------------------------------------------------
# The order study on the nonholonomic particle (shared by the theorems and the errata)
# ------------------------------------------------------------------------------------------------
class LiteralEulerABComposition(ps.EulerABComposition):
    """(EuAHam) at h/2 after (EuBHam) at h/2 on $(q, \\tilde p, \\tilde\\lambda)$, composed literally
    (no change of the $\\tilde p$ reading at the junctions; see
    :class:`gnipy.EulerABComposition`)."""

    name = "euler-ab-literal"

    def step(self, system, state, h):
        new = ps.euler_a_map(system, ps.euler_b_map(system, state, 0.5 * h), 0.5 * h)
        return new, ps._explicit_info(*new)


# claim per method: (paper's order, where the paper says it)
_ORDER_CLAIMS = {
    "euler-a": (1, "Theorem 5.1, (EuAHam)"),
    "euler-b": (1, "Theorem 5.1, (EuBHam)"),
    "rattle": (2, "Remark 5.1, (nonholonomicRATTLE), [SDD2]"),
    "euler-ab": (2, "Remark after Theorem 5.2"),
    "gni-euler-a": (1, "Theorem 5.1 (GNI with the Euler A l_d, (LagEuler))"),
    "gni-euler-b": (1, "Theorem 5.1 (GNI with the Euler B l_d, (LagEuler))"),
    "gni-trapezoid": (2, "Remark 5.1, (Verlet): GNI with the trapezoid l_d is RATTLE"),
    "gni-midpoint": (2, "§4, GNI with the midpoint l_d (symmetric)"),
}
_EQUAL_PAIRS = [("euler-a", "gni-euler-a", "(EuAHam)"), ("euler-b", "gni-euler-b", "(EuBHam)"),
                ("rattle", "gni-trapezoid", "(nonholonomicRATTLE)")]
_GNI_VARIANTS = ["gni-euler-a", "gni-euler-b", "gni-trapezoid", "gni-midpoint"]
_LD_NAMES = {"gni-euler-a": "Euler A", "gni-euler-b": "Euler B", "gni-trapezoid": "trapezoid", "gni-midpoint": "midpoint"}

T_ORDER = 2.0
SAVES = 4
_STUDY: dict[bool, dict] = {}


def _particle():
    spec = get_model("nonholonomic-particle")
    return spec.system(), np.asarray(spec.q0, dtype=np.float64), np.asarray(spec.v0, dtype=np.float64)


# Ball on a table turning at rate Ω with a spring (affine constraints and a potential), on R⁵:
# l = ½m(ẋ²+ẏ²) + ½I|ω|² − ½k(x²+y²); ẋ − rω₂ + Ωy = 0, ẏ + rω₁ − Ωx = 0.
_B = {"m": 1.0, "I": 0.4, "r": 1.0, "Omega": 0.7, "k": 1.0}


def _spring_ball_lagrangian(q, v):
    return (0.5 * _B["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * _B["I"] * (v[2:] @ v[2:])
            - 0.5 * _B["k"] * (q[0] ** 2 + q[1] ** 2))


def _spring_ball_mu(q):
    return jnp.array([[1.0, 0.0, 0.0, -_B["r"], 0.0], [0.0, 1.0, _B["r"], 0.0, 0.0]], dtype=q.dtype)


def _spring_ball_Y(q):
    z = jnp.zeros_like(q[0])
    return jnp.stack([-_B["Omega"] * q[1], _B["Omega"] * q[0], z, z, z])


def _spring_ball():
    """`(system, q0, v0)`: an affine system with a potential (the ball on a turning table with a spring)."""
    s = System(_spring_ball_lagrangian, _spring_ball_mu, _spring_ball_Y, n=5, name="spring-ball-on-turning-table")
    q0 = np.array([1.0, 0.5, 0.0, 0.0, 0.0])
    w = np.array([0.3, -0.2, 0.5])
    v0 = np.array([_B["r"] * w[1] - _B["Omega"] * q0[1], -_B["r"] * w[0] + _B["Omega"] * q0[0], *w])
    return s, q0, v0


def _particle_study(quick: bool, tick: Callable[[str], None] = lambda d: None) -> dict:
    """Runs of every method on the particle for every h, the reference, and the fitted orders (cached)."""
    if quick in _STUDY:
        return _STUDY[quick]
    t_start = time.perf_counter()
    system, q0, v0 = _particle()
    js = range(5, 9) if quick else range(5, 11)
    Ns = [2**j for j in js]
    hs = [T_ORDER / N for N in Ns]
    times = np.linspace(0.0, T_ORDER, SAVES + 1)
    q_ref, v_ref, _ = continuous_reference(system, q0, v0, times)
    ref_gap = None
    if not quick:  # cross-check against the library's diffrax reference
        lib = ContinuousReference().solve(system, jnp.asarray(q0), jnp.asarray(v0), times)
        ref_gap = float(max(np.max(np.abs(np.asarray(lib.q) - q_ref)), np.max(np.abs(np.asarray(lib.v) - v_ref))))
    tick("reference")
    methods: dict[str, object] = {name: name for name in _ORDER_CLAIMS}
    methods["euler-ab-literal"] = LiteralEulerABComposition()
    if not quick:
        methods["shake"] = "shake"
    runs: dict[str, list[dict]] = {}
    errors: dict[str, list[float]] = {}
    for key, method in methods.items():
        runs[key], errors[key] = [], []
        for N, h in zip(Ns, hs):
            out = run_all_nodes(method, system, q0, v0, h, N, length=Ns[-1])
            runs[key].append(out)
            errors[key].append(float(np.max(np.abs(out["q"][:: N // SAVES] - q_ref))))
        tick(key)
    orders = {key: fitted_order(hs, errors[key]) for key in methods}
    study = {"system": system, "q0": q0, "v0": v0, "hs": hs, "Ns": Ns, "runs": runs, "errors": errors,
             "orders": orders, "reference_gap": ref_gap, "runtime_s": time.perf_counter() - t_start}
    if not quick:
        s, bq0, bv0 = _spring_ball()
        study["affine"] = {name: run_all_nodes(name, s, bq0, bv0, 0.02, 1000)
                           for name in ["euler-a", "euler-b", "rattle", "shake", *_GNI_VARIANTS]}
        tick("affine")
    _STUDY[quick] = study
    return study


def _rel(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


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


def _adjointness(system, hs=(0.1, 0.01), seeds=(0, 1, 2), n_states=64) -> dict:
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
_C_INERTIA = 1.7  # l = ½ c |Ω|²: bi-invariant metric c·identity
_ENERGY_H = 0.05
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
        jtu.Partial(_bi_invariant_lagrangian, jnp.asarray(_C_INERTIA)),
        jtu.Partial(_random_distribution, jnp.asarray(_B1), jnp.asarray(_B1_0)),
        n=0, group=SO3(), depends_on_orientation=True, retraction=retraction, name="bi-invariant-so3",
    )
    R0 = np.asarray(SO3().exp(jnp.asarray([0.3, -0.5, 0.8])))
    mu = np.asarray(s.mu(s.initial_point((), R0)))
    w = np.array([1.0, -2.0, 0.5])
    v0 = w - mu.T @ np.linalg.solve(mu @ mu.T, mu @ w)
    return s, R0, v0


def _energy_theorem(steps: int) -> dict:
    """GNI (Euler A l_d, Cayley) for `steps` steps: drift of |p⁺_k| and of the reported energy."""
    s, R0, v0 = energy_theorem_system()
    out = run_all_nodes(GNI(EulerA()), s, (), v0, _ENERGY_H, steps, R0=R0, states=True)
    p_plus = out["states"].p_plus
    norm = np.linalg.norm(p_plus, axis=1)
    norm0 = _C_INERTIA * float(np.linalg.norm(v0))
    rel = np.abs(norm / norm0 - 1.0)
    slope = float(np.polyfit(np.arange(len(norm)), norm / norm[0] - 1.0, 1)[0])
    v = out["v"]
    E = 0.5 * _C_INERTIA * np.sum(v * v, axis=1)
    E0 = 0.5 * _C_INERTIA * float(v0 @ v0)
    return {"drift": float(np.max(rel)), "trend": abs(slope) * steps, "bound": ROUNDOFF_WALK * math.sqrt(steps) * EPS,
            "reported_energy_variation": float(np.ptp(E) / E0), "constraint_residual": float(np.max(np.abs(out["residual"]))),
            "steps": steps}


# ------------------------------------------------------------------------------------------------
# The theorem table
# ------------------------------------------------------------------------------------------------
def theorem_table(quick: bool, progress: Progress = None) -> list[Row]:
    """Measure the paper's claims with gnipy (module docstring); quick: fewer h and 10⁴ steps for
    the energy theorem instead of 10⁵.

    Arguments:
        quick: the short run (about 20 s on two cores, most of it compilation).
        progress: optional `progress(advance, description)`; the advances add up to 1.0.

    Returns:
        The rows, in the paper's order.
    """
    weights = {"reference": 1.0, **{k: 1.0 for k in [*_ORDER_CLAIMS, "euler-ab-literal", "shake"]},
               "affine": 3.0, "adjoint": 1.5, "energy": 8.0 if quick else 20.0}
    if quick:
        weights.pop("shake"), weights.pop("affine")
    work = _Work(progress, weights)
    study = _particle_study(quick, lambda key: work(key, f"theorems: particle runs ({key})"))
    rows: list[Row] = []
    hs, Ns = study["hs"], study["Ns"]
    h_range = f"h = T/{Ns[0]} … T/{Ns[-1]}, T = {T_ORDER:g}"
    ref_note = (" Reference: gnipy's Lagrange–d'Alembert equations by scipy DOP853 at tolerance 1e-12"
                + ("" if study["reference_gap"] is None
                   else f" (gap to gnipy.ContinuousReference, diffrax Dopri8: {study['reference_gap']:.1e})") + ".")

    # --- orders (Theorem 5.1, Remark 5.1, Remark after Theorem 5.2) -------------------------
    names = {"euler-a": "nonholonomic Euler A (EuAHam)", "euler-b": "nonholonomic Euler B (EuBHam)",
             "rattle": "nonholonomic RATTLE", "euler-ab": "composition Euler A(h/2) ∘ Euler B(h/2)",
             "gni-euler-a": "GNI, Euler A l_d", "gni-euler-b": "GNI, Euler B l_d",
             "gni-trapezoid": "GNI, trapezoid l_d", "gni-midpoint": "GNI, midpoint l_d"}
    for key, (claim, ref) in _ORDER_CLAIMS.items():
        order = study["orders"][key]
        errs = study["errors"][key]
        rows.append(Row(
            claim=f"{names[key]} ({key}) converges with order {claim}",
            paper_ref=ref,
            expected=f"order {claim}",
            measured=f"order {order:.2f}",
            passed=bool(abs(order - claim) <= ORDER_TOL),
            detail=(f"Nonholonomic particle, {h_range}; error = max |q − q_ref| at t = 0, 0.5, …, 2 "
                    f"({errs[0]:.2e} at the largest h, {errs[-1]:.2e} at the smallest); least-squares slope, "
                    f"tolerance ±{ORDER_TOL}." + ref_note),
            values={"method": key, "order": order, "expected": float(claim), "errors": list(errs), "hs": list(hs)},
        ))

    # --- Theorem 5.2 --------------------------------------------------------------------------
    cases = {"linear": study["system"]}
    if not quick:
        cases["affine"] = _spring_ball()[0]
    adj = {name: _adjointness(s) for name, s in cases.items()}
    res = max(a["residual"] for a in adj.values())
    work("adjoint", "theorems: Theorem 5.2")
    mb = max(a["manifold_B"] for a in adj.values())
    ma, od = min(a["manifold_A"] for a in adj.values()), min(a["off_domain"] for a in adj.values())
    rows.append(Row(
        claim="nonholonomic Euler A and B are each other's adjoint: F_A^h ∘ F_B^{−h} = Id",
        paper_ref="Theorem 5.2",
        expected="0 (identity)",
        measured=f"{res:.1e}",
        passed=bool(res <= EQUAL_TOL and mb <= EQUAL_TOL),
        detail=(f"max relative |F_A^h ∘ F_B^{{−h}}(s) − s| over {adj['linear']['states']} random states s = (q, p̃, λ̃) "
                "of M_A = {μM⁻¹(p̃ + (h/2)V_q − Π) = 0}, where F_A^h starts ((EuAHamc)), h = 0.1 and 0.01, on "
                + ("the nonholonomic particle" if quick else "the nonholonomic particle and an affine ball with a spring")
                + f"; tolerance {EQUAL_TOL:g}. F_B^{{−h}} maps M_A into itself (residual {mb:.1e}), so it is the "
                f"inverse of F_A^h there. Controls: the intermediate state moves (min max|Δq| "
                f"{min(a['moved'] for a in adj.values()):.2e}); from states off M_A the round trip fails ({od:.1e}); "
                f"F_A^{{−h}} leaves M_A ({ma:.1e}). Note: F_A^h depends on (p̃, λ̃) only through p_{{k+1/2}}, so as "
                "formulas F_A^h ∘ F_A^{−h} also returns every s of M_A; the adjoint is the map that stays on M_A."),
        values={"residual": res, "manifold_B": mb, "manifold_A": ma, "off_domain": od},
    ))

    # --- exact constraints of the reported momentum --------------------------------------------
    for key in _GNI_VARIANTS:
        res_p = max(float(np.max(np.abs(r["residual"]))) for r in study["runs"][key])
        delta = max(float(np.max(np.abs(r["step_residual"]))) for r in study["runs"][key])
        where = "the nonholonomic particle (all nodes of every run)"
        if not quick:
            a = study["affine"][key]
            res_p = max(res_p, float(np.max(np.abs(a["residual"]))))
            where += " and the affine ball with a spring (h = 0.02, 1000 steps)"
        rows.append(Row(
            claim=f"the reported momentum p̄ = (p⁻ + p⁺)/2 of {key} satisfies the constraints",
            paper_ref="§4 after (GNIloc); (GNIintAffb)",
            expected="0 (exact)",
            measured=f"{res_p:.1e}",
            passed=bool(res_p <= EQUAL_TOL),
            detail=(f"max |μ(v̄ − Y)| with v̄ = 𝔾⁻¹p̄ on {where}; tolerance {EQUAL_TOL:g}. Control: the step "
                    f"velocity (q_{{k+1}} − q_k)/h violates them by up to {delta:.1e}."),
            values={"method": key, "residual": res_p, "step_velocity_residual": delta},
        ))

    # --- the explicit schemes are the GNI -------------------------------------------------------
    for explicit, gni, label in _EQUAL_PAIRS + ([] if quick else [("shake", "gni-trapezoid", "(Afin), SHAKE")]):
        pairs = list(zip(study["runs"][explicit], study["runs"][gni]))
        if not quick:
            pairs.append((study["affine"][explicit], study["affine"][gni]))
        diff = max(max(_rel(e["q"], g["q"]), _rel(e["v"], g["v"]), _rel(e["p"], g["p"])) for e, g in pairs)
        tol = EQUAL_PER_STEP * max(len(e["q"]) - 1 for e, _ in pairs) * EPS
        rows.append(Row(
            claim=f"{label} ({explicit}) is the GNI with the {_LD_NAMES[gni]} l_d ({gni})",
            paper_ref="§5 (EuAHam)/(EuBHam) from (GNIint); Remark 5.1" + ("; §6.1" if not quick else ""),
            expected="equal node by node",
            measured=f"{diff:.1e} (relative)",
            passed=bool(diff <= tol),
            detail=(f"max relative difference of q, v̄ and p̄ over all nodes of the particle runs ({h_range})"
                    + ("" if quick else " and of the affine ball with a spring (h = 0.02, 1000 steps)")
                    + f"; tolerance {EQUAL_PER_STEP:g}·N·eps = {tol:.1e} (round-off of N steps). The explicit maps "
                    "(gnipy.integrators.paper_schemes) are written separately from the GNI core."),
            values={"methods": (explicit, gni), "difference": diff, "tolerance": tol},
        ))

    # --- the energy theorem -----------------------------------------------------------------------
    steps = 10_000 if quick else 100_000
    en = _energy_theorem(steps)
    work("energy", "theorems: energy theorem on SO(3)")
    passed = en["drift"] <= en["bound"] and en["trend"] <= en["bound"] and en["constraint_residual"] <= EQUAL_TOL
    rows.append(Row(
        claim="on a Lie group with a bi-invariant metric, any distribution and a left-invariant l_d, the GNI "
              "conserves the energy",
        paper_ref="§4 (end of the section), [SDD1]",
        expected="0 drift (exact)",
        measured=f"{en['drift']:.1e} (relative drift of |p⁺| over {steps:,} steps)",
        passed=bool(passed),
        detail=(f"SO(3), l = ½c|Ω|² (c = {_C_INERTIA}), V = 0, one random attitude-dependent constraint μ(R), "
                f"GNI with the Euler A l_d (left-invariant) and the Cayley map, h = {_ENERGY_H}. The conserved energy is "
                f"|p⁺_k|²/2c: max_k ||p⁺_k|/|p⁺_0| − 1| = {en['drift']:.1e}, fitted trend over the run "
                f"{en['trend']:.1e}, both within the round-off model {ROUNDOFF_WALK:g}·√N·eps = {en['bound']:.1e}. "
                f"Reported v̄ on the constraints to {en['constraint_residual']:.0e}. Control: the energy of the "
                f"reported v̄ (a projection of p⁺) varies by {en['reported_energy_variation']:.1e} (relative)."),
        values=en,
    ))
    work.finish("theorems: done")
    return rows


# ------------------------------------------------------------------------------------------------
# Errata
# ------------------------------------------------------------------------------------------------
def _hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cayley_steps(R, *, right: bool = False) -> np.ndarray:
    """σ_k = cay⁻¹(R_kᵀR_{k+1}) from consecutive attitudes, or cay⁻¹(R_{k+1}R_kᵀ) with `right` (R
    reconstructed as R_{k+1} = cay(σ_k)R_k, e.g. `rolling-ball`) (numpy; Appendix:
    cay⁻¹(Q) = 2 vee((Q − I)(Q + I)⁻¹)), shape (K − 1, 3)."""
    R = np.asarray(R, dtype=np.float64)
    Q = np.einsum("kij,klj->kil", R[1:], R[:-1]) if right else np.einsum("kji,kjl->kil", R[:-1], R[1:])
    eye = np.eye(3)
    S = 2.0 * (Q - eye) @ np.linalg.inv(Q + eye)
    return 0.5 * np.stack([S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0], S[:, 1, 0] - S[:, 0, 1]], axis=1)


def five_equations(p: dict, x, y, w, h: float) -> np.ndarray:
    """The five explicit equations of §7.4 (with their O(h) and O(h²) terms, the 4th and 5th with
    the correct sign of Π, as printed) at the nodes k = 1 .. K−1; rows are nodes, columns equations.

    Arguments:
        p: the parameters m, r, I1, I2, I3, Omega.
        x, y: the contact point at nodes 0..K.
        w: the step angular velocities ω^k = σ_k/h, k = 0..K−1.
        h: the step size.
    """
    m, r, I1, I2, I3, W = (p[k] for k in ("m", "r", "I1", "I2", "I3", "Omega"))
    I = np.array([I1, I2, I3])
    a, b = w[1:], w[:-1]  # ω^k, ω^{k−1}
    na, nb = (I * a**2).sum(1), (I * b**2).sum(1)  # ||ω||²_I
    x1, x0, xm = x[2:], x[1:-1], x[:-2]
    y1, y0, ym = y[2:], y[1:-1], y[:-2]
    e1 = (m * r * (x1 - 2 * x0 + xm) / h + I2 * (a[:, 1] - b[:, 1])
          + h / 2 * (I1 - I3) * (a[:, 0] * a[:, 2] + b[:, 0] * b[:, 2]) + h**2 / 4 * (a[:, 1] * na - b[:, 1] * nb))
    e2 = (m * r * (y1 - 2 * y0 + ym) / h - I1 * (a[:, 0] - b[:, 0])
          - h / 2 * (I3 - I2) * (a[:, 1] * a[:, 2] + b[:, 1] * b[:, 2]) - h**2 / 4 * (a[:, 0] * na - b[:, 0] * nb))
    e3 = (I3 * (a[:, 2] - b[:, 2]) + h / 2 * (I2 - I1) * (a[:, 0] * a[:, 1] + b[:, 0] * b[:, 1])
          + h**2 / 4 * (a[:, 2] * na - b[:, 2] * nb))
    e4 = ((x1 - xm) / (2 * h) + W * y0 - r * (a[:, 1] + b[:, 1]) / 2
          - r * h / 4 * (I1 - I3) / I2 * (a[:, 0] * a[:, 2] - b[:, 0] * b[:, 2])
          - h**2 / (8 * I2) * r * (a[:, 1] * na + b[:, 1] * nb))
    e5 = ((y1 - ym) / (2 * h) - W * x0 + r * (a[:, 0] + b[:, 0]) / 2
          + r * h / 4 * (I3 - I2) / I1 * (a[:, 1] * a[:, 2] - b[:, 1] * b[:, 2])
          + h**2 / (8 * I1) * r * (a[:, 0] * na + b[:, 0] * nb))
    return np.stack([e1, e2, e3, e4, e5], axis=1)


def _rolling_ball_nodes(system, q0, v0, h: float, steps: int):
    """`(x, R, v)` at the nodes 0..steps of the GNI (Euler A l_d, Cayley) on a rolling-ball System,
    through the figures' driver when it is there (one compilation shared with the figures)."""
    try:
        from .figures import run_nodes
    except ImportError:  # the figures module is optional here
        out = run_all_nodes(GNI(EulerA()), system, q0, v0, h, steps, project_v0=True)
        return out["q"], out["R"], out["v"]
    b0 = system.initial_point(q0)
    method = _prepared(GNI(EulerA()), system, b0)
    state0, v0_bar = _gni_start(method, system, b0, jnp.asarray(v0, jnp.float64), jnp.asarray(h, jnp.float64))
    x, R, v = run_nodes(method, system, state0, h, steps, steps)
    return (np.concatenate([np.asarray(b0.x)[None], x]), np.concatenate([np.asarray(b0.R)[None], R]),
            np.concatenate([np.asarray(v0_bar)[None], v]))


@jit
def _gni_start(method, system, b0, v0, h):
    """The GNI state from v0 projected onto the constraints, and the velocity it reports."""
    state0 = method.init(system, b0, project_velocity(system, b0, v0), h)
    return state0, method.observe(system, state0, h)[1]


def _erratum_sign(quick: bool) -> Erratum:
    """(GNIredb-aff)/(RBb) print +2Q*Π: the GNI with Π → −Π (Ω → −Ω in Y) on example 2."""
    p = dict(rb.EXAMPLE_2["params"])
    _, q0, v0 = rb.example_2()
    h, steps = 0.1, 40 if quick else 150
    scale_G = np.array([p["m"], p["m"], p["I1"], p["I2"], p["I3"]])
    out = {}
    for label, W in (("corrected", p["Omega"]), ("printed", -p["Omega"])):
        # Y = (−Ωy, Ωx, 0, 0, 0): negating Ω negates Y and Π = 𝔾Y, i.e. it imposes
        # Q*((FL⁻ + FL⁺)/2 + Π) = 0, which is (RBb) as printed
        system = rb.build_system(dict(p, Omega=W), defaults=(q0, v0))
        x, R, v = _rolling_ball_nodes(system, q0, v0, h, steps)
        w = cayley_steps(R, right=system.reconstruction == "right") / h
        eq = np.max(np.abs(five_equations(p, x[:, 0], x[:, 1], w, h)), axis=0)
        pbar = v * scale_G
        rel = eq / np.array([np.max(np.abs(pbar))] * 3 + [np.max(np.abs(v))] * 2)
        true_res = np.stack([v[:, 0] - p["r"] * v[:, 3] + p["Omega"] * x[:, 1],
                             v[:, 1] + p["r"] * v[:, 2] - p["Omega"] * x[:, 0]], axis=1)  # (Cona), (Conb)
        out[label] = {"eq123": float(np.max(rel[:3])), "eq45": float(np.max(rel[3:])),
                      "constraints": float(np.max(np.abs(true_res)) / np.max(np.abs(v)))}
    pr, co = out["printed"], out["corrected"]
    return Erratum(
        location="§7.3 (GNIredb-aff) and §7.4 (RBb)",
        printed="Q*(FL⁻_k) + Q*(FL⁺_k) + 2Q*Π = 0",
        corrected="Q*(FL⁻_k) + Q*(FL⁺_k) − 2Q*Π = 0, i.e. Q*((FL⁻ + FL⁺)/2 − Π) = 0, as in (GNIintAffb) "
                  "and as the 4th and 5th explicit equations of §7.4 are printed",
        measurement=(f"Rolling ball, example 2 (I = (1, 1.1, 1.2), m = 3, Ω = 0.2), GNI with the paper's l_d and "
                     f"Cayley, h = {h}, {steps} steps. The printed sign is the GNI with Π → −Π (a System with Y "
                     f"negated). Relative residual of the §7.4 equations 4–5: printed {pr['eq45']:.2f}, corrected "
                     f"{co['eq45']:.1e}; of the rolling constraints (Cona), (Conb) for the reported velocity: printed "
                     f"{pr['constraints']:.2f}, corrected {co['constraints']:.1e}. Equations 1–3 (the P* part, which "
                     f"the sign does not touch) hold for both ({max(pr['eq123'], co['eq123']):.1e})."),
        evidence_value=pr["eq45"],
        values={"printed_residual": pr["eq45"], "corrected_residual": co["eq45"],
                "printed_constraint_residual": pr["constraints"], "corrected_constraint_residual": co["constraints"],
                "equations_1_3_residual": max(pr["eq123"], co["eq123"])},
    )


@jit
def _node_terms(system, q):
    """M⁻¹V_q(q_k) and the projector P = I − M⁻¹μᵀC⁻¹μ at a batch of configurations."""

    def one(x):
        M, mu = system.metric(x), system.mu(x)
        Minv_muT = jnp.linalg.solve(M, mu.T)
        P = jnp.eye(x.shape[0]) - Minv_muT @ jnp.linalg.solve(mu @ Minv_muT, mu)
        return jnp.linalg.solve(M, system.potential_gradient(x)), P

    return jax.vmap(one)(q)


def _erratum_remark_5_1(quick: bool) -> Erratum:
    """Remark 5.1 prints q_{k+1} − 2q_k + q_{k+1}: residual of both two-step forms on RATTLE/SHAKE."""
    study = _particle_study(quick)
    key = "rattle" if quick else "shake"
    q = study["runs"][key][-1]["q"]
    h = study["hs"][-1]
    qm, qk, qp = q[:-2], q[1:-1], q[2:]
    MinvVq, P = (np.asarray(a) for a in _node_terms(study["system"], jnp.asarray(qk)))
    # the size of the terms the corrected equation balances: the second difference and h²M⁻¹V_q
    scale = float(np.max(np.abs(qp - 2 * qk + qm)) + np.max(np.abs(h * h * MinvVq)))

    def residual(second):  # P(q_{k+1} − 2q_k + second + h²M⁻¹V_q): the multiplier term drops out under P
        return float(np.max(np.abs(np.einsum("kij,kj->ki", P, qp - 2 * qk + second + h * h * MinvVq)))) / scale

    printed, corrected = residual(qp), residual(qm)
    return Erratum(
        location="Remark 5.1 (two-step SHAKE of McLachlan–Perlmutter)",
        printed="q_{k+1} − 2q_k + q_{k+1} = −h²M⁻¹(V_q(q_k) + μᵀ(q_k)λ̃_k)",
        corrected="q_{k+1} − 2q_k + q_{k−1} = −h²M⁻¹(V_q(q_k) + μᵀ(q_k)λ̃_k)",
        measurement=(f"Nonholonomic particle, {key} (= RATTLE = GNI with the trapezoid l_d), h = T/{study['Ns'][-1]}, "
                     f"{study['Ns'][-1]} steps. Residual of the equation projected by P = I − M⁻¹μᵀC⁻¹μ (which "
                     f"removes the unknown λ̃_k), relative to the size of its terms (the second difference and "
                     f"h²M⁻¹V_q, O(h²)): printed {printed:.1e} (it is off by 2(q_{{k+1}} − q_k) = O(h)), corrected "
                     f"{corrected:.1e} (round-off eps·|q|/h²)."),
        evidence_value=printed,
        values={"printed_residual": printed, "corrected_residual": corrected},
    )


def _sphere_systems(p: dict):
    """The paper's `rolling-ball` and the physical `chaplygin-sphere` for parameters `p`, under
    shared static metadata (one compilation per model for all parameter values)."""
    ball = _bare(rb.build_system(p))
    sphere = _bare(get_model("chaplygin-sphere").system(**p))
    return ball, sphere


def _erratum_sphere(quick: bool) -> Erratum:
    """§7.4's model with unequal moments is not the physical Chaplygin sphere."""
    p = dict(rb.EXAMPLE_2["params"])
    _, q0, v0 = rb.example_2()  # at R0 = I the body and space angular velocities agree
    T = 15.0
    times = np.linspace(0.0, T, 31)
    gaps = {}
    for label, params in (("unequal", p), ("equal", dict(p, I1=1.1, I2=1.1, I3=1.1))):
        ball, sphere = _sphere_systems(params)
        xb, vb, _ = continuous_reference(ball, q0, v0, times, R0=np.eye(3))
        xs, vs, Rs = continuous_reference(sphere, q0, v0, times, R0=np.eye(3))
        # the model's ω is the space angular velocity: compare with the sphere's RΩ
        ws = np.einsum("kij,kj->ki", Rs, vs[:, 2:])
        gaps[label] = (float(np.max(np.linalg.norm(xb - xs, axis=1))), float(np.max(np.abs(vb[:, 2:] - ws))))
    return Erratum(
        location="§7.4 (Cona), (Conb), (LagCont)",
        printed="ẋ − rω₂ + Ωy = 0, ẏ + rω₁ − Ωx = 0 with ω the body angular velocity and l = ½m|ẋ|² + ½Σ Iᵢωᵢ², "
                "presented as the Chaplygin sphere with three different moments",
        corrected="the rolling constraints involve the space angular velocity Rω (attitude-dependent constraints, "
                  "model chaplygin-sphere); the paper's model is that sphere only for I1 = I2 = I3 (kept as "
                  "rolling-ball, which Fig. 3 integrates)",
        measurement=(f"Continuous solutions (gnipy's equations, DOP853, tolerance 1e-12) of rolling-ball and "
                     f"chaplygin-sphere from the same initial condition (example 2: (x, y) = (1, 0), R0 = I, "
                     f"ω0 = (−0.2, 0, 0.4), m = 3, Ω = 0.2) up to t = {T:g}. Unequal moments (1, 1.1, 1.2): the "
                     f"contact points differ by up to {gaps['unequal'][0]:.2f} (and the model's ω from the sphere's "
                     f"space angular velocity by {gaps['unequal'][1]:.2f}). Equal moments (1.1, 1.1, 1.1): they agree "
                     f"to {gaps['equal'][0]:.1e} ({gaps['equal'][1]:.1e} in ω)."),
        evidence_value=gaps["unequal"][0],
        values={"printed_residual": gaps["unequal"][0], "corrected_residual": gaps["equal"][0],
                "omega_gap_unequal": gaps["unequal"][1], "omega_gap_equal": gaps["equal"][1]},
    )


def _erratum_composition(quick: bool) -> Erratum:
    """The literal composition of (EuBHam) and (EuAHam) is of order 1; the re-read one of order 2."""
    study = _particle_study(quick)
    lit, rer = study["orders"]["euler-ab-literal"], study["orders"]["euler-ab"]
    return Erratum(
        location="Remark after Theorem 5.2 (composition F_A^{h/2} ∘ F_B^{h/2})",
        printed="the composition (time step h/2) of (EuAHam) and (EuBHam) generates a second-order method since "
                "the two are each other's adjoint",
        corrected="composed literally on (q, p̃, λ̃) it is of order 1: the two maps read p̃ differently "
                  "(p̄ = p̃ ∓ (h/4)V_q for B and A at step h/2), so the output of one does not lie where the other "
                  "starts and Theorem 5.2 does not apply at the junctions; with p̃ re-read there "
                  "(p̃ ← p̃ ± (h/2)V_q, i.e. the GNI flows composed) it is of order 2 (gnipy method euler-ab)",
        measurement=(f"Nonholonomic particle, h = T/{study['Ns'][0]} … T/{study['Ns'][-1]}, T = {T_ORDER:g}, against "
                     f"the continuous reference: fitted order of the literal composition {lit:.2f}, of the re-read "
                     f"composition {rer:.2f}."),
        evidence_value=lit,
        values={"printed_order": lit, "corrected_order": rer},
    )


# A reduced system with a coupling block G_xξ ≠ 0 (where the two readings of (RATc) differ),
# a potential V(x) and x-dependent constraint rows (μ(x), η(x)).
_G_XX = np.array([[2.0, 0.3], [0.3, 1.5]])
_G_XS = np.array([[0.2, -0.1, 0.05], [0.0, 0.15, -0.1]])
_G_SS = np.array([[1.0, 0.1, 0.0], [0.1, 1.3, -0.05], [0.0, -0.05, 0.8]])
_METRIC = np.block([[_G_XX, _G_XS], [_G_XS.T, _G_SS]])


def _coupled_lagrangian(x, v):
    V = 0.5 * (x[0] ** 2 + 2.0 * x[1] ** 2) + 0.1 * jnp.sin(x[0] * x[1])
    return 0.5 * v @ jnp.asarray(_METRIC) @ v - V


def _coupled_mu(x):
    one, zero = jnp.ones_like(x[0]), jnp.zeros_like(x[0])
    return jnp.stack([jnp.stack([one, zero, zero, -one, 0.2 * jnp.sin(x[1])]),
                      jnp.stack([0.3 * x[0], one, 0.8 * one, zero, 0.1 * x[1]])])


def _erratum_ratc(quick: bool) -> Erratum:
    """(RATc): (G̃⁻¹)^{ij} is the inverse of the block G_xx, not the xx block of G⁻¹."""
    Gxx_inv, block_of_inv = np.linalg.inv(_G_XX), np.linalg.inv(_METRIC)[:2, :2]
    # equation level: x_{k+1} from (RATc) with p_{k+1/2} as §7.2 defines it, for random steps
    rng = np.random.default_rng(7)
    D, xi = rng.standard_normal((64, 2)), rng.standard_normal((64, 3))
    p_half = D @ _G_XX.T + xi @ _G_XS.T  # (p_{k+1/2})_i = G_ij Δ^j + G_is ξ^s
    rhs = p_half - xi @ _G_XS.T
    eq_right = float(np.max(np.abs(rhs @ Gxx_inv.T - D)) / np.max(np.abs(D)))
    eq_wrong = float(np.max(np.abs(rhs @ block_of_inv.T - D)) / np.max(np.abs(D)))
    values = {"equation_right": eq_right, "equation_wrong": eq_wrong}
    measurement = (f"Coupled reduced test system on R² × SO(3) (constant metric with G_xξ ≠ 0). Equation level: x_{{k+1}} "
                   f"recovered from (RATc) with p_{{k+1/2}} as defined in §7.2, relative error over 64 random steps: "
                   f"inverse of G_xx {eq_right:.1e}, xx block of G⁻¹ {eq_wrong:.1e}.")
    printed_value, corrected_value = eq_wrong, eq_right
    if not quick:  # trajectory level: RAT with each reading against the GNI with the trapezoid l_d
        from ..integrators.reduced_rattle import ReducedRattle

        class _BlockOfInverse(ReducedRattle):
            @staticmethod
            def _blocks(system, R):
                G, _, Gxs = ReducedRattle._blocks(system, R)
                return G, jnp.linalg.inv(jnp.linalg.inv(G)[:2, :2]), Gxs

        s = System(_coupled_lagrangian, _coupled_mu, n=2, group=SO3(), retraction="cayley", name="coupled-reduced")
        q0, v0 = np.array([0.5, -0.3]), np.array([0.4, -0.2, 0.3, 0.5, -0.6])
        kw = dict(R0=np.eye(3), project_v0=True)
        gni = run_all_nodes(GNI(Trapezoid()), s, q0, v0, 0.05, 200, **kw)
        right = run_all_nodes("rat", s, q0, v0, 0.05, 200, **kw)
        wrong = run_all_nodes(_BlockOfInverse(), s, q0, v0, 0.05, 200, **kw)
        corrected_value, printed_value = _rel(right["q"], gni["q"]), _rel(wrong["q"], gni["q"])
        values.update(trajectory_right=corrected_value, trajectory_wrong=printed_value)
        measurement += (f" Trajectory level (h = 0.05, 200 steps): max relative |x − x_GNI| of (RAT) against the GNI "
                        f"with the trapezoid l_d: inverse of G_xx {corrected_value:.1e}, xx block of G⁻¹ "
                        f"{printed_value:.1e}.")
    values.update(printed_residual=printed_value, corrected_residual=corrected_value)
    return Erratum(
        location="§7.2 (RATc)",
        printed="x_{k+1} = x_k + h (𝔾̃⁻¹)^{ij}((p_{k+1/2})_j − 𝔾̃_{jt} ξ_k^t), with the symbol 𝔾̃⁻¹ that denotes the "
                "inverse of the whole metric in A^{i,a}, B^{t,a}",
        corrected="(𝔾̃⁻¹)^{ij} in (RATc) is the inverse of the block 𝔾̃_{ij} (from the definition of p_{k+1/2}); "
                  "the two readings differ when 𝔾̃_{it} ≠ 0",
        measurement=measurement,
        evidence_value=printed_value,
        values=values,
    )


def errata_rows(quick: bool, progress: Progress = None) -> list[Erratum]:
    """Measure each erratum of the paper (docs/conventions.md, "Errata"): the printed form fails, the
    corrected form holds (module docstring).

    Arguments:
        quick: the short run.
        progress: optional `progress(advance, description)`; the advances add up to 1.0.

    Returns:
        The errata: the sign of Π in (GNIredb-aff)/(RBb); Remark 5.1's two-step equation; §7.4's
        model against the physical Chaplygin sphere; the composition remark; the reading of (RATc).
    """
    # the particle study is shared with theorem_table (cached): when it has not run yet, the
    # first erratum that needs it (Remark 5.1) runs it
    remark_weight = 0.5 if quick in _STUDY else 10.0
    steps = [("sign", _erratum_sign, 4.0), ("remark", _erratum_remark_5_1, remark_weight), ("sphere", _erratum_sphere, 3.0),
             ("composition", _erratum_composition, 0.5), ("ratc", _erratum_ratc, 0.2 if quick else 6.0)]
    work = _Work(progress, {key: w for key, _, w in steps})
    out = []
    for key, fn, _ in steps:
        out.append(fn(quick))
        work(key, f"errata: {out[-1].location}")
    work.finish("errata: done")
    return out
