"""What the figures of :mod:`gnipy.experiments.figures` share: the result record, the runs
(one :func:`gnipy.simulate` call each), the fitted slopes, the error measures, the progress feed
and the writer."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..extras import require
from ..analysis.orders import ROUND_OFF, fit_points, fitted_order
from ..errors import verdicts_reported_by_caller
from ..saveat import SaveAt
from ..simulate import simulate

__all__ = ["FigureResult", "Progress"]

Progress = Callable[[float, str], None] | None


@dataclasses.dataclass
class FigureResult:
    """What one figure reports.

    Attributes:
        name: e.g. `"figure1"`.
        title: the plot's title.
        caption: what was run (parameters, h range, reference, how errors are measured).
        files: the PNG and PDF written.
        metrics: fitted orders and other numbers (e.g. `gni_order_position`), plus `runtime_s`.
        table: per-h rows for the report.
        notes: findings in words.
    """

    name: str
    title: str
    caption: str
    files: list[Path]
    metrics: dict[str, float]
    table: list[dict]
    notes: list[str]


# ------------------------------------------------------------------------------------------------
# Numerics shared by the figures
# ------------------------------------------------------------------------------------------------
def observed_order(hs, errors, floor: float = ROUND_OFF) -> float:
    """The fitted slope (:func:`gnipy.analysis.fitted_order` with `stop_at_minimum=True`)."""
    return fitted_order(hs, errors, floor, stop_at_minimum=True)


def asymptotic_order(hs, errors, floor: float = ROUND_OFF, points: int = 3) -> float:
    """The slope over the `points` smallest h among the fitted points (the asymptotic order)."""
    hs, errors = np.asarray(hs, dtype=np.float64), np.asarray(errors, dtype=np.float64)
    keep = fit_points(hs, errors, floor, stop_at_minimum=True)
    finest = np.argsort(hs[keep])[:points]
    return observed_order(hs[keep][finest], errors[keep][finest], floor)


def run_saved_nodes(system, method, h: float, steps: int, saveat: SaveAt, q0=None, v0=None, *, state0=None, t0: float = 0.0):
    """`(x, v)` at the saved nodes of one :func:`gnipy.simulate` call, as numpy arrays (v is the
    velocity the method reports: the GNI's $\\bar v_k$, DLA's $\\mathbb{G}^{-1}p^+_k$)."""
    with verdicts_reported_by_caller():  # the paper's figures show failing runs on purpose
        sol = simulate(system, method, q0, v0, h=h, steps=steps, saveat=saveat, state0=state0, t0=t0)
    return np.asarray(sol.q), np.asarray(sol.v)


def _energy(p, v):
    """$E = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12\\sum_i I_i\\omega_i^2$ along the last axis."""
    inertia = np.array([p["I1"], p["I2"], p["I3"]])
    return 0.5 * p["m"] * (v[..., 0] ** 2 + v[..., 1] ** 2) + 0.5 * np.sum(inertia * v[..., 2:] ** 2, axis=-1)


def ball_errors(x, v, x_ref, v_ref, p):
    """Max over the saved nodes of |(x, y) − ref|₂, |ω − ref|₂ and |E − E_ref|."""
    return (
        float(np.max(np.linalg.norm(x - x_ref, axis=-1))),
        float(np.max(np.linalg.norm(v[:, 2:] - v_ref[:, 2:], axis=-1))),
        float(np.max(np.abs(_energy(p, v) - _energy(p, v_ref)))),
    )


class FigureProgress:
    """Feeds `progress(advance, description)` with advances that add up to 1.0 per figure."""

    def __init__(self, progress: Progress, total: float):
        self.progress, self.total, self.done = progress, float(total), 0.0

    def __call__(self, work: float, description: str):
        if self.progress is not None and self.total > 0:
            adv = min(work, self.total - self.done) / self.total
            self.done += work
            self.progress(max(adv, 0.0), description)

    def finish(self, description: str):
        if self.progress is not None and self.done < self.total:
            self.progress((self.total - self.done) / self.total, description)
            self.done = self.total


#: Work estimate of one run in steps: the fixed cost (dispatch, transfers) as this many steps.
RUN_OVERHEAD = 4000


def write_figure(fig, out_dir: Path, name: str) -> list[Path]:
    """`NAME.png` and `NAME.pdf` in `out_dir`, each written atomically; an existing file is replaced
    only in a folder gnipy created or when asked (:func:`gnipy.experiments.report.save_figure`)."""
    from .report import save_figure

    return save_figure(fig, out_dir, name, dpi=150)


def new_figure(width: float, height: float):
    """A matplotlib Figure of `width` x `height` inches with constrained layout, made with the
    object-oriented API (no pyplot): no global backend or state is touched."""
    require("matplotlib", extra="plots")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def format_h(h: float) -> str:
    """A step size as the figures label it (3 significant digits)."""
    return f"{h:.3g}"

