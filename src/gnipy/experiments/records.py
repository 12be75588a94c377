"""What the theorem table and the errata share: their records (:class:`Row`, :class:`Erratum`), the
tolerances, the progress bookkeeping, and :func:`all_nodes`, every node of one
:func:`gnipy.simulate` run as numpy arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from ..analysis.orders import ROUND_OFF
from ..compilation import jit
from ..errors import verdicts_reported_by_caller
from ..saveat import SaveAt
from ..simulate import simulate
from ..system import System

__all__ = ["Row", "Erratum", "Work", "all_nodes", "bare", "rel", "EPS", "ORDER_TOL", "ROUND_OFF", "EQUAL_TOL",
           "EQUAL_PER_STEP", "ROUNDOFF_WALK"]

Progress = Callable[[float, str], None] | None

EPS = float(np.finfo(np.float64).eps)
#: Tolerance on a fitted order against the paper's claim.
ORDER_TOL = 0.15
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


class Work:
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


@jit
def _step_velocity_residual(system, q, h):
    """μ(q_k)(Δ_k − Y(q_k)) for the step velocity Δ_k = (q_{k+1} − q_k)/h (on $\\mathbb{R}^n$)."""
    return jax.vmap(system.constraint_residual)(q[:-1], (q[1:] - q[:-1]) / h)


def all_nodes(system, method, q0, v0, *, h: float, steps: int, run_steps: int | None = None, R0=None,
              project_v0: bool = False, states: bool = False) -> dict:
    """Every node 0..`steps` of one :func:`gnipy.simulate` run, as numpy arrays.

    The run takes `run_steps` (≥ `steps`, default `steps`) steps and saves every node; the nodes
    past `steps` are dropped. `simulate` compiles one program per number of saved nodes, so runs of
    one method at several h that all take `run_steps` steps share one compilation.

    Arguments:
        system, method, q0, v0, R0, project_v0: as for :func:`gnipy.simulate` (an integrator object
            is best: repeated calls with the same objects reuse their preparation).
        h: step size.
        steps: the nodes returned are 0..steps.
        run_steps: the steps the run takes.
        states: also return the integrator states (e.g. the GNI's $p^+_k$).

    Returns:
        A dict: `q` (coordinates), `v`, `p` (the reported velocity and momentum), `residual`
        (μ(v − Y)), `R` (orientations, or None), `states` (if asked) and, on $\\mathbb{R}^n$,
        `step_residual` (μ(Δ_k − Y) for the step velocity Δ_k = (q_{k+1} − q_k)/h, k < steps, a
        control: it is not on the constraints).
    """
    run_steps = steps if run_steps is None else int(run_steps)
    if not 1 <= steps <= run_steps:
        raise ValueError(f"steps = {steps} must lie in 1..run_steps = {run_steps}")
    with verdicts_reported_by_caller():  # records of failing runs are made on purpose
        sol = simulate(system, method, q0, v0, R0=R0, h=h, steps=run_steps, saveat=SaveAt(steps=True, states=states),
                       project_v0=project_v0)

    def cut(a):
        return None if a is None else np.asarray(a)[: steps + 1]

    out = {"q": cut(sol.q), "v": cut(sol.v), "p": cut(sol.p), "residual": cut(sol.constraint_residual),
           "R": cut(sol.R)}
    if system.group is None:  # over all the run's nodes: one shape per run_steps, one compilation
        out["step_residual"] = np.asarray(_step_velocity_residual(system.without_metadata(), sol.q, jnp.asarray(h, jnp.float64)))[:steps]
    if states:
        out["states"] = jax.tree_util.tree_map(cut, sol.states)
    return out


def bare(system: System) -> System:
    """The same functions under default static metadata (name, params), so that systems of one
    model with different parameter values share compilations."""
    group = system.group
    return System(
        system.lagrangian, system.constraints, system.affine, holonomic=system.holonomic, n=system.n, group=group,
        retraction=system.space.retraction if group is not None else "cayley",
        depends_on_orientation=system.depends_on_orientation, reconstruction=system.reconstruction or "left",
        name="theorem-table", args=system.args, params={},
    )


def rel(a, b) -> float:
    """max|a − b| / max|b|."""
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))
