"""Where the GNI struggles: the measured failures of the GNI family, with the run-time diagnostic
that reports each one and a method that works there.

Three cases, each against the continuous reference (Dopri8 at tolerance 1e-12):

1. The Chaplygin sleigh (`chaplygin-sleigh`, gni-trapezoid, h = 0.05): the GNI's hidden momentum
   $p^+ - \\bar p$ leaves its O(h) value and grows exponentially, drains the energy of the reported
   motion and sends the sleigh round looping petals; :mod:`gnipy.diagnostics` calls it out of band
   (at t ≈ 16 from the default consistent start, at t ≈ 2.6 from the paper's rest start), while the
   energy is still within 1%. `dla` follows
   the reference.
2. The Suslov problem (`suslov`, gni-midpoint, h = 0.01): the same mechanism on SO(3).
3. The first-order GNIs on the contact oscillator (`contact-oscillator`, gni-euler-a and
   gni-euler-b, h = 0.05): their hidden momentum stays consistent with the state, but the state
   gains energy step after step (gni-euler-b's is 28 times its initial value by t = 100); the energy
   verdict reports it.
   The symmetric gni-trapezoid keeps the energy to 5e-3.

:func:`struggle_figures` makes the three figures (PNG and PDF) with their numbers, for the report of
`gni reproduce` and for the methods guide of the documentation (`python -m
gnipy.experiments.struggles docs/user-guide/figures` regenerates those).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..extras import require
from ..errors import verdicts_reported_by_caller

__all__ = ["struggle_figures", "sleigh_figure", "suslov_figure", "oscillator_figure", "STRUGGLES"]

Progress = Callable[[float, str], None] | None


def _run(model: str, method: str, h: float, t_final: float, every: int):
    import gnipy

    with verdicts_reported_by_caller():  # the struggles are shown on purpose, with their verdicts
        return gnipy.simulate(gnipy.make_system(model), method, h=h, t_final=t_final, save_every=every, throw=False)


def _hidden_panel(ax, sol, label: str, color: str) -> None:
    """The hidden-momentum ratio, its band, and the time the verdict fires."""
    from ..diagnostics import hidden_momentum_band

    t = np.asarray(sol.t)
    ax.semilogy(t, np.maximum(np.asarray(sol.hidden_momentum), 1e-16), color=color, lw=1.0,
                label=f"{label}: |p⁺ − p̄|/|p̄|")
    ax.semilogy(t, hidden_momentum_band(t, sol.hidden_expected, sol.h), color=color, lw=0.8, ls="--",
                label=f"{label}: its O(h) band")
    ax.set_ylim(bottom=1e-6)
    v = sol.hidden_verdict
    if not v.in_band:
        ax.axvline(v.first_time, color=color, lw=0.8, ls=":")
        ax.annotate(f"out of band, t = {v.first_time:.3g}", (v.first_time, ax.get_ylim()[0]), rotation=90,
                    fontsize=7, va="bottom", ha="right", color=color)
    ax.set_xlabel("t")
    ax.set_ylabel("hidden momentum")
    ax.legend(fontsize=7)


def _energy_and_diagnostic(fig, axes, runs, gni, label: str, out_dir: Path, name: str, title: str) -> list[Path]:
    """The shared panels of the sleigh and Suslov figures (energy of each run, the GNI's hidden
    momentum with its band), the title, and the files."""
    for sol, run_label, color, ls in runs:
        axes[1].plot(np.asarray(sol.t), np.asarray(sol.energy), color=color, ls=ls, label=f"{run_label}: energy")
    axes[1].set_xlabel("t")
    axes[1].set_ylabel("energy E")
    axes[1].set_title("energy (a constant of the motion)")
    axes[1].legend(fontsize=7)
    _hidden_panel(axes[2], gni, label, "tab:red")
    axes[2].set_title("the diagnostic")
    fig.suptitle(title)
    fig.tight_layout()
    files = _save(fig, Path(out_dir), name)
    plt = require("matplotlib.pyplot", extra="plots")

    plt.close(fig)
    return files


def _save(fig, out_dir: Path, name: str) -> list[Path]:
    """`NAME.png` and `NAME.pdf` in `out_dir`, each written atomically (through gnipy.files:
    :func:`gnipy.experiments.report.save_figure`)."""
    from .report import save_figure

    try:
        return save_figure(fig, out_dir, name, dpi=110)
    except BaseException:  # a failed write (a full disk): the pyplot figure is not left open
        plt = require("matplotlib.pyplot", extra="plots")

        plt.close(fig)
        raise


def _figure_result(**fields):
    from .figures import FigureResult

    return FigureResult(**fields)


def sleigh_figure(out_dir: Path, quick: bool, progress: Progress = None):
    """Case 1: the Chaplygin sleigh (see the module docstring)."""
    plt = require("matplotlib.pyplot", extra="plots")

    t0 = time.perf_counter()
    h, T = 0.05, (30.0 if quick else 60.0)
    every = 1
    gni = _run("chaplygin-sleigh", "gni-trapezoid", h, T, every)
    ref = _run("chaplygin-sleigh", "reference", h, T, every)
    dla = _run("chaplygin-sleigh", "dla", h, T, every)
    if progress:
        progress(0.8, "struggles: sleigh run")
    t = np.asarray(gni.t)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    runs = ((ref, "reference", "k", "-"), (gni, "gni-trapezoid", "tab:red", "-"), (dla, "dla", "tab:blue", "--"))
    for sol, label, color, ls in runs:
        q = np.asarray(sol.q)
        axes[0].plot(q[:, 0], q[:, 1], color=color, lw=1.0 if sol is not ref else 2.0, label=label, ls=ls)
    axes[0].set_xlabel("x")
    axes[0].set_ylabel("y")
    axes[0].set_title("path of the sleigh")
    axes[0].legend(fontsize=7)
    axes[1].plot(t, np.asarray(gni.energy_plus), color="tab:orange", ls=":", label="gni-trapezoid: energy of p⁺")
    files = _energy_and_diagnostic(fig, axes, runs, gni, "gni-trapezoid", out_dir, "struggles_sleigh",
                                   f"Chaplygin sleigh, h = {h:g}: the GNI's hidden momentum takes over")
    v = gni.hidden_verdict
    err = lambda s: float(np.max(np.abs(np.asarray(s.q) - np.asarray(ref.q))))  # noqa: E731
    e = np.asarray(gni.energy)
    metrics = {
        "verdict_first_time": v.first_time, "gni_position_error": err(gni), "dla_position_error": err(dla),
        "gni_min_energy_over_E0": float(np.min(e) / e[0]),
        "gni_energy_error_at_verdict": float(np.max(np.abs(e[t <= v.first_time] - e[0])) / e[0]),
        "gni_energy_plus_drift": float(np.max(np.abs(np.asarray(gni.energy_plus) - gni.energy_plus[0])) / e[0]),
        "dla_energy_error": float(np.max(np.abs(np.asarray(dla.energy) - e[0])) / e[0]),
        "runtime_s": time.perf_counter() - t0,
    }
    notes = [
        f"The verdict fires at t = {v.first_time:.3g}, while the reported energy is still within "
        f"{metrics['gni_energy_error_at_verdict']:.1e} of its value; later it falls to "
        f"{metrics['gni_min_energy_over_E0']:.1e} E0 and the path loops. The energy of p⁺ stays conserved "
        f"({metrics['gni_energy_plus_drift']:.0e}): the hidden momentum holds what the reported motion lost.",
        f"Position error against the reference over t ≤ {T:g}: gni-trapezoid {metrics['gni_position_error']:.2g}, "
        f"dla {metrics['dla_position_error']:.2g}. A smaller h only delays the failure (at h = 0.001 the verdict "
        "fires at t ≈ 29 and the energy is drained by t ≈ 41; from the paper's rest start p⁺₀ = p̄₀ at t ≈ 2.8 "
        "and 14, measured with gnipy.GNI(start='rest')).",
    ]
    return _figure_result(
        name="struggles_sleigh", title="Where the GNI struggles 1: the Chaplygin sleigh", caption=(
            f"chaplygin-sleigh (m = I = 1, a = 0.5; q0 = 0, v0 = (1, 0.5, 1)), h = {h:g}, t ≤ {T:g}: "
            "gni-trapezoid (RATTLE's steps from the consistent start; every GNI variant behaves alike), dla and the continuous "
            "reference. Right: the hidden-momentum ratio r = |p⁺ − p̄|/|p̄| and its O(h) band "
            "(gnipy.diagnostics)."),
        files=files, metrics=metrics, table=[], notes=notes)


def suslov_figure(out_dir: Path, quick: bool, progress: Progress = None):
    """Case 2: the Suslov problem (see the module docstring)."""
    plt = require("matplotlib.pyplot", extra="plots")

    t0 = time.perf_counter()
    h, T = 0.01, (60.0 if quick else 200.0)
    every = 10
    gni = _run("suslov", "gni-midpoint", h, T, every)
    ref = _run("suslov", "reference", h, T, every)
    dla = _run("suslov", "dla", h, T, every)
    if progress:
        progress(0.8, "struggles: suslov run")
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    runs = ((ref, "reference", "k", "-"), (gni, "gni-midpoint", "tab:red", "-"), (dla, "dla", "tab:blue", "--"))
    for sol, label, color, ls in runs:
        axes[0].plot(np.asarray(sol.t), np.asarray(sol.v)[:, 0], color=color, ls=ls, lw=1.0, label=f"{label}: ω₁")
    axes[0].set_xlabel("t")
    axes[0].set_ylabel("ω₁")
    axes[0].set_title("body angular velocity ω₁")
    axes[0].legend(fontsize=7)
    files = _energy_and_diagnostic(fig, axes, runs, gni, "gni-midpoint", out_dir, "struggles_suslov",
                                   f"Suslov problem, h = {h:g}: the same mechanism on SO(3)")
    v = gni.hidden_verdict
    e, er = np.asarray(gni.energy), np.asarray(ref.energy)
    metrics = {
        "verdict_first_time": v.first_time,
        "gni_energy_error": float(np.max(np.abs(e - er[0])) / er[0]),
        "dla_energy_error": float(np.max(np.abs(np.asarray(dla.energy) - er[0])) / er[0]),
        "gni_velocity_error": float(np.max(np.abs(np.asarray(gni.v) - np.asarray(ref.v)))),
        "dla_velocity_error": float(np.max(np.abs(np.asarray(dla.v) - np.asarray(ref.v)))),
        "runtime_s": time.perf_counter() - t0,
    }
    notes = [f"The verdict fires at t = {v.first_time:.3g}; over t ≤ {T:g} the GNI's relative energy error reaches "
             f"{metrics['gni_energy_error']:.2g} (dla: {metrics['dla_energy_error']:.1e}), its angular velocity error "
             f"{metrics['gni_velocity_error']:.2g} (dla: {metrics['dla_velocity_error']:.1e})."]
    return _figure_result(
        name="struggles_suslov", title="Where the GNI struggles 2: the Suslov problem", caption=(
            f"suslov (the default inertia and constraint vector; ω0 = (1, 0.5, 0)), h = {h:g}, t ≤ {T:g}: "
            "gni-midpoint (every GNI variant and rat behave alike), dla and the reference."),
        files=files, metrics=metrics, table=[], notes=notes)


def oscillator_figure(out_dir: Path, quick: bool, progress: Progress = None):
    """Case 3: the first-order GNIs on the contact oscillator (see the module docstring)."""
    plt = require("matplotlib.pyplot", extra="plots")

    t0 = time.perf_counter()
    h, T = 0.05, 100.0
    runs = {m: _run("contact-oscillator", m, h, T, 1) for m in ("gni-euler-a", "gni-euler-b", "gni-trapezoid")}
    if progress:
        progress(0.8, "struggles: oscillator runs")
    colors = {"gni-euler-a": "tab:red", "gni-euler-b": "tab:purple", "gni-trapezoid": "tab:green"}
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    table = []
    for m, sol in runs.items():
        e = np.asarray(sol.energy)
        axes[0].semilogy(np.asarray(sol.t), np.maximum(np.abs(e - e[0]) / e[0], 1e-16), color=colors[m], lw=1.0,
                         label=m)
        ev = sol.energy_verdict
        if not ev.in_band:
            axes[0].axvline(ev.first_time, color=colors[m], ls=":", lw=0.8)
        axes[1].semilogy(np.asarray(sol.t), np.maximum(np.asarray(sol.hidden_momentum), 1e-16), color=colors[m],
                         lw=0.6, label=f"{m}: |p⁺ − p̄|/|p̄|")
        hv = sol.hidden_verdict
        table.append({"method": m, "failed at step": sol.failed_step if sol.result else "—",
                      "energy verdict": "in band" if ev.in_band else f"out of band at t = {ev.first_time:.4g}",
                      "hidden-momentum verdict": "in band" if hv.in_band else f"out of band at t = {hv.first_time:.4g}",
                      "max |E − E0|/E0": f"{float(np.nanmax(np.abs(e - e[0]) / e[0])):.2e}"})
    axes[0].set_xlabel("t")
    axes[0].set_ylabel("|E − E₀| / E₀")
    axes[0].set_title("relative energy error (dotted: the energy verdict)")
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("t")
    axes[1].set_ylabel("|p⁺ − p̄| / |p̄|")
    axes[1].set_title("hidden momentum")
    axes[1].legend(fontsize=7)
    fig.suptitle(f"Contact oscillator, h = {h:g}: the first-order GNIs gain energy step after step")
    fig.tight_layout()
    files = _save(fig, Path(out_dir), "struggles_oscillator")
    plt.close(fig)
    metrics = {"runtime_s": time.perf_counter() - t0}
    notes = ["The Euler GNIs' hidden momentum stays consistent with their state; the state itself gains energy "
             "step after step (first order, not symmetric). The energy verdict reports it long before the energy has grown by orders of magnitude; "
             "the symmetric gni-trapezoid keeps the energy bounded."]
    return _figure_result(
        name="struggles_oscillator", title="Where the GNI struggles 3: the Euler GNIs on the contact oscillator",
        caption=(f"contact-oscillator (ε = 0.3; q0 = (1, 1, 1), v0 = (−1, 1, 1)), h = {h:g}, t ≤ {T:g}: the relative "
                 "energy error of gni-euler-a, gni-euler-b and gni-trapezoid (the energy is a constant of the motion), "
                 "and their hidden momentum."),
        files=files, metrics=metrics, table=table, notes=notes)


STRUGGLES: dict[str, Callable] = {"sleigh": sleigh_figure, "suslov": suslov_figure, "oscillator": oscillator_figure}


def struggle_figures(out_dir: Path, quick: bool, progress: Progress = None) -> list:
    """The three figures of "Where the GNI struggles" (FigureResult objects), written to `out_dir`."""
    from .report import ensure_output_dir

    out_dir = ensure_output_dir(out_dir)
    out = []
    for i, fn in enumerate(STRUGGLES.values()):
        out.append(fn(out_dir, quick, None))
        if progress:
            progress(1.0 / len(STRUGGLES), f"struggles: {i + 1} of {len(STRUGGLES)}")
    return out


if __name__ == "__main__":
    for fig in struggle_figures(Path(sys.argv[1] if len(sys.argv) > 1 else "."), quick=False):
        print(fig.title)
        for n in fig.notes:
            print("  ", n)
        for row in fig.table:
            print("  ", row)
