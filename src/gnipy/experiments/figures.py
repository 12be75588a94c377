"""The figures of paper §7.4 (the rolling ball on a rotating table), reproduced.

Each figure is one call, `figure_N(out_dir, quick, progress=None) -> FigureResult`, which runs the
experiment, writes `figureN.png` (dpi 150) and `figureN.pdf` into `out_dir`, and returns what was
run (caption), the fitted orders (metrics), the per-h errors (table) and the findings (notes).

- :func:`figure_1`: the homogeneous ball (example 1), errors against the exact solution as functions
  of h, GNI (the paper's $l_d = h\\,l(q_k, \\Delta, \\omega_k)$, i.e. Euler A, with the Cayley map)
  against the discrete Lagrange–d'Alembert method of [IMMM] (method `dla`).
- :func:`figure_2`: the contact point's path for h = 0.1 and 10000 steps, against the exact circle.
- :func:`figure_3`: example 2, errors against a fine GNI run, for two ways of starting the GNI: the
  paper's start (constraints at node 0 with forward differences, then $p^+_1 = FL^+$,
  :func:`paper_start`) and the momentum start $p^+_0 = \\mathbb{G}v_0$.

**Runs.** Every run is one call of :func:`gnipy.simulate`, which checks the initial condition and
saves only the nodes a figure measures (`SaveAt(ts=...)`). Runs that save as many nodes share one
compiled program whatever their h and step count: all GNI runs from an initial condition of
Figures 1 and 3 (the examples' Systems differ only in parameter values), all DLA runs, both runs of
Figure 2 (the h/2 run saves every second node), and all runs of Figure 3 that continue from the
paper's start (`state0=`, the GNI state at node 1). The slopes are :func:`gnipy.analysis.fitted_order`
with `stop_at_minimum=True` (no point past the smallest error: round-off, not truncation).

**Layout.** Figures 1 and 2 live here, Figure 3 in :mod:`~gnipy.experiments.figure3`, what they share (the runs,
slopes, error measures, progress feed and writer) in :mod:`~gnipy.experiments.figure_tools`.

**Progress.** `progress(advance, description)` is called as work proceeds; the advances of one
figure add up to 1.0 (the caller scales them to its bar).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..analysis.orders import ROUND_OFF
from ..discrete_lagrangians import EulerA
from ..integrators.comparators import DiscreteLagrangeDAlembert
from ..integrators.gni import GNI
from ..models import rolling_ball as rb
from ..saveat import SaveAt
from .figure3 import figure_3, paper_start
from .figure_tools import (RUN_OVERHEAD, FigureProgress, FigureResult, Progress, asymptotic_order, ball_errors, format_h,
                           new_figure, observed_order, run_saved_nodes, write_figure)

__all__ = ["FIGURES", "FigureResult", "figure_1", "figure_2", "figure_3", "paper_start"]


# ------------------------------------------------------------------------------------------------
# Figure 1: convergence of the homogeneous ball against the exact solution
# ------------------------------------------------------------------------------------------------
def figure_1(out_dir: Path, quick: bool, progress: Progress = None) -> FigureResult:
    """Paper Fig. 1: errors in position, angular velocity and energy against the exact solution
    (example 1, total time 10), GNI (Euler A $l_d$, Cayley) against DLA [IMMM], log-log in h."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    system = rb.build_system(rb.DEFAULT_PARAMS)
    p = system.parameters
    q0, v0 = system.defaults
    T, n_saves = 10.0, 10
    # quick: only the five smallest h (DLA's velocity orders are asymptotic at every h since its group
    # constraint uses dτ⁻¹_σ σ/h; with σ/h, before issue 29, a large O(h²) term hid them above h ≈ 0.01)
    Ns = [640 * 2**j for j in range(5)] if quick else [40 * 2**j for j in range(12)]
    hs = [T / N for N in Ns]
    t_save = T * np.arange(1, n_saves + 1) / n_saves
    x_ex, v_ex = rb.exact(p, q0, v0, t_save)
    save = SaveAt(ts=t_save)
    methods = {
        "gni": (GNI(EulerA(), start="rest"), "GNI", "-", "o"),
        "dla": (DiscreteLagrangeDAlembert(), "DLA [IMMM]", "--", "s"),
    }
    work = FigureProgress(progress, len(methods) * sum(N + RUN_OVERHEAD for N in Ns))
    errors: dict[str, list[tuple[float, float, float]]] = {k: [] for k in methods}
    table: list[dict] = []
    for key, (method, *_rest) in methods.items():
        for N, h in zip(Ns, hs):
            x, v = run_saved_nodes(system, method, h, N, save, q0, v0)
            e = ball_errors(x, v, x_ex, v_ex, p)
            errors[key].append(e)
            table.append({"method": key, "h": h, "steps": N, "error_position": e[0], "error_omega": e[1],
                          "error_energy": e[2]})
            work(N + RUN_OVERHEAD, f"figure 1: {key} h = {format_h(h)}")
    metrics = _figure_1_metrics(errors, hs)
    fig, title = _figure_1_plot(methods, errors, hs, metrics)
    files = write_figure(fig, out_dir, "figure1")
    work.finish("figure 1: done")
    caption = _figure_1_caption(T, n_saves, Ns, hs, quick)
    notes = _figure_1_notes(metrics, hs)
    metrics["runtime_s"] = time.perf_counter() - t_start
    return FigureResult("figure1", title, caption, files, metrics, table, notes)


_QUANTITIES = ("position", "omega", "energy")
_YLABELS = ("max error in position $(x, y)$", "max error in angular velocity $\\omega$", "max error in energy")


def _figure_1_metrics(errors: dict[str, list], hs: list[float]) -> dict[str, float]:
    """The fitted slopes (all h, the finest 3) and the errors at the smallest h, by method and quantity."""
    metrics: dict[str, float] = {}
    for key in errors:
        arr = np.array(errors[key])
        for i, qn in enumerate(_QUANTITIES):
            metrics[f"{key}_order_{qn}"] = observed_order(hs, arr[:, i])
            metrics[f"{key}_order_{qn}_fine"] = asymptotic_order(hs, arr[:, i])
            metrics[f"{key}_error_{qn}_smallest_h"] = float(arr[-1, i])
    return metrics


def _figure_1_plot(methods: dict, errors: dict[str, list], hs: list[float], metrics: dict[str, float]):
    """The figure of Fig. 1 (a panel per quantity, a curve per method) and its title."""
    fig = new_figure(13.5, 4.2)
    axes = fig.subplots(1, 3)
    for i, (ax, qn, yl) in enumerate(zip(axes, _QUANTITIES, _YLABELS)):
        for key, (_, label, ls, mk) in methods.items():
            arr = np.array(errors[key])[:, i]
            ax.loglog(hs, arr, ls=ls, marker=mk, ms=4, label=f"{label}: slope {metrics[f'{key}_order_{qn}']:.2f} "
                      f"(finest 3: {metrics[f'{key}_order_{qn}_fine']:.2f})")
        ax.set_xlabel("time step $h$")
        ax.set_ylabel(yl)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    title = "Figure 1 — homogeneous rolling ball (§7.4, example 1): errors against the exact solution"
    fig.suptitle(title + "\nsolid: GNI with the paper's $l_d = h\\,l(q_k, \\Delta, \\omega_k)$ (Euler A) and Cayley; "
                 "dashed: discrete Lagrange–d'Alembert [IMMM]", fontsize=10)
    return fig, title


def _figure_1_caption(T: float, n_saves: int, Ns: list[int], hs: list[float], quick: bool) -> str:
    """The caption of Fig. 1."""
    return (
        "Rolling ball on a rotating table (paper §7.4, model rolling-ball, example 1): homogeneous ball "
        "I1 = I2 = I3 = 2/3, m = r = Ω = 1, (x0, y0, ẋ0, ẏ0) = (1, 1, 1, 1), ω0 = (0, 2, 0), R0 = I, "
        f"total time {T:g}. Time steps h = 10/N for N = {Ns[0]}, {Ns[1]}, ..., {Ns[-1]} "
        f"(h from {format_h(hs[0])} to {format_h(hs[-1])}). Solid: the GNI with the paper's discrete Lagrangian "
        "l_d = h l(q_k, (q_{k+1} − q_k)/h, ω_k) (Euler A) and the Cayley retraction; dashed: the discrete "
        "Lagrange–d'Alembert method of [IMMM] (gnipy method dla: p⁺_k − p⁻_k = μᵀλ_k with the constraint "
        "imposed at the step's midpoint). Errors are taken against the exact solution (circular motion of "
        f"the contact point at rate κ = IΩ/(I + mr²) = 0.4; rolling_ball.exact) at {n_saves} evenly spaced "
        "nodes t = 1, 2, ..., 10, as the maximum over those nodes of the Euclidean norm of the error in "
        "(x, y), in ω, and of the absolute error in the energy E = ½m(ẋ² + ẏ²) + ½Σ Iᵢωᵢ². Velocities are "
        "the ones each method reports: the GNI's v̄_k = 𝔾⁻¹(p⁻_k + p⁺_k)/2 (on the constraints), DLA's "
        "𝔾⁻¹p⁺_k. Slopes in the legends: least squares of log error against log h over the points above "
        f"round-off (error > {ROUND_OFF:g} and not past the smallest error); 'finest 3': the same over the "
        "three smallest of those h."
        + (" Quick run: only the five smallest h of the full run's range." if quick else "")
    )


def _figure_1_notes(metrics: dict[str, float], hs: list[float]) -> list[str]:
    """The findings of Fig. 1: the GNI's order 2, DLA's orders, the errors at the smallest h."""
    return [
        "With V = 0 and a constant metric the paper's Euler A l_d equals the trapezoid and midpoint l_d, so "
        "this GNI is the reduced RATTLE, a symmetric method: order 2 in position, ω and energy "
        f"(fitted {metrics['gni_order_position']:.2f}, {metrics['gni_order_omega']:.2f}, "
        f"{metrics['gni_order_energy']:.2f}), higher than the order 1 that the consistency argument "
        "after the five equations of §7.4 suggests.",
        f"DLA: positions converge with order {metrics['dla_order_position_fine']:.2f} over the finest h (2 "
        "expected: a symmetric two-step scheme). Its reported velocity 𝔾⁻¹p⁺_k is the post-impulse value "
        "FL⁺ of the previous step, ≈ v(t_k − h/2): ω and energy carry an O(h) error, slopes "
        f"{metrics['dla_order_omega_fine']:.2f} and {metrics['dla_order_energy_fine']:.2f} over the finest h "
        f"(1 expected); over all h the slopes are {metrics['dla_order_position']:.2f}, "
        f"{metrics['dla_order_omega']:.2f}, {metrics['dla_order_energy']:.2f}.",
        f"At the smallest h ({format_h(hs[-1])}) the position errors are "
        f"{metrics['gni_error_position_smallest_h']:.2e} (GNI) and {metrics['dla_error_position_smallest_h']:.2e} "
        "(DLA).",
    ]


# ------------------------------------------------------------------------------------------------
# Figure 2: the contact point's path for h = 0.1
# ------------------------------------------------------------------------------------------------
def figure_2(out_dir: Path, quick: bool, progress: Progress = None) -> FigureResult:
    """Paper Fig. 2: the contact point $(x_k, y_k)$ of the homogeneous ball for h = 0.1 and 10000
    steps (quick: 1000), with the table's centre and the exact circle."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    system = rb.build_system(rb.DEFAULT_PARAMS)
    p = system.parameters
    q0, v0 = system.defaults
    h, steps = 0.1, (1000 if quick else 10000)
    work = FigureProgress(progress, 3 * steps + 2 * RUN_OVERHEAD)
    method = GNI(EulerA(), start="rest")
    path, v_path = run_saved_nodes(system, method, h, steps, SaveAt(steps=True), q0, v0)  # nodes 0 .. steps
    work(steps + RUN_OVERHEAD, "figure 2: GNI h = 0.1")
    # the same total time with h/2 (not plotted): the distance from the circle should fall by 2² = 4
    # (saved at every second node, i.e. at the times of the h run: as many nodes, the same program)
    x2, _ = run_saved_nodes(system, method, h / 2, 2 * steps, SaveAt(every=2), q0, v0)
    x2 = x2[1:]
    work(2 * steps + RUN_OVERHEAD, "figure 2: GNI h = 0.05")
    centre, radius, kappa = _exact_circle(p, q0, v0)
    metrics, table = _figure_2_metrics(p, q0, v0, h, steps, path, v_path, x2)
    fig, title = _figure_2_plot(path, q0, h, steps, centre, radius)
    files = write_figure(fig, out_dir, "figure2")
    work.finish("figure 2: done")
    caption = (
        "Position (x_k, y_k) of the contact point of the homogeneous ball (paper §7.4, example 1: "
        "I1 = I2 = I3 = 2/3, m = r = Ω = 1, (x0, y0, ẋ0, ẏ0) = (1, 1, 1, 1), ω0 = (0, 2, 0)), GNI with the "
        f"paper's l_d (Euler A) and Cayley, h = {h:g}, {steps} steps (total time {h * steps:g}); every node "
        "is plotted. The cross marks the centre of the rotating table (0, 0). Grey: the exact path, the "
        f"circle of centre ({centre.real:.4g}, {centre.imag:.4g}) = z0 + iż0/κ and radius |ż0|/κ = {radius:.4g}, "
        "κ = IΩ/(I + mr²) = 0.4. Metric: the maximum over all nodes of | |z_k − c| − radius |; the same run "
        f"with h = {h / 2:g} over the same time (not plotted) checks that this distance is O(h²)."
        + (" Quick run (1000 steps instead of the paper's 10000)." if quick else "")
    )
    notes = _figure_2_notes(metrics, h, steps)
    metrics["runtime_s"] = time.perf_counter() - t_start
    return FigureResult("figure2", title, caption, files, metrics, table, notes)


def _exact_circle(p, q0, v0) -> tuple[complex, float, float]:
    """`(centre, radius, kappa)`: the exact motion of the contact point, z = x + iy, runs round a
    circle at rate κ = IΩ/(I + mr²)."""
    kappa = p["I1"] * p["Omega"] / (p["I1"] + p["m"] * p["r"] ** 2)
    z0, dz0 = complex(*q0), complex(v0[0], v0[1])
    return z0 + 1j * dz0 / kappa, abs(dz0) / kappa, kappa


def _figure_2_metrics(p, q0, v0, h: float, steps: int, path, v_path, x2) -> tuple[dict[str, float], list[dict]]:
    """The metrics of Fig. 2 (distances from the exact circle, with h and h/2; the discrete angular
    rate; the Jacobi integral's drift) and its table (every tenth of the run)."""
    t = h * np.arange(steps + 1)
    centre, radius, kappa = _exact_circle(p, q0, v0)
    z = path[:, 0] + 1j * path[:, 1]
    dist = np.abs(np.abs(z - centre) - radius)
    z2 = x2[:, 0] + 1j * x2[:, 1]
    dist_half_h = float(np.max(np.abs(np.abs(z2 - centre) - radius)))
    jacobi = rb.jacobi_integral(p, path[1:], v_path[1:])
    J0 = float(rb.jacobi_integral(p, q0, v0))
    x_ex, _ = rb.exact(p, q0, v0, t)
    pos_err = np.linalg.norm(path - x_ex, axis=1)
    # the discrete angular rate about the exact centre (unwrapped angle, least squares in t)
    angle = np.unwrap(np.angle(z - centre))
    kappa_h = float(np.polyfit(t, angle, 1)[0])
    half = len(dist) // 2
    metrics = {
        "h": h,
        "steps": float(steps),
        "t_final": h * steps,
        "radius": radius,
        "kappa": kappa,
        "kappa_discrete": kappa_h,
        "max_distance_from_exact_circle": float(np.max(dist)),
        "relative_max_distance_from_exact_circle": float(np.max(dist) / radius),
        "max_distance_half_h": dist_half_h,
        "distance_ratio_h_over_half_h": float(np.max(dist) / dist_half_h),
        "max_distance_first_half": float(np.max(dist[:half])),
        "max_distance_second_half": float(np.max(dist[half:])),
        "max_distance_from_table_centre": float(np.max(np.abs(z))),
        "final_position_error": float(pos_err[-1]),
        "jacobi_drift": float(np.max(np.abs(jacobi - J0))),
    }
    table = [
        {"t": float(t[k]), "x": float(path[k, 0]), "y": float(path[k, 1]), "distance_from_exact_circle": float(dist[k]),
         "position_error": float(pos_err[k])}
        for k in np.linspace(0, steps, 11).astype(int)
    ]
    return metrics, table


def _figure_2_plot(path, q0, h: float, steps: int, centre: complex, radius: float):
    """The figure of Fig. 2 (the discrete path, the exact circle, the table's centre) and its title."""
    fig = new_figure(6.4, 6.0)
    ax = fig.subplots()
    th = np.linspace(0.0, 2 * np.pi, 721)
    ax.plot(centre.real + radius * np.cos(th), centre.imag + radius * np.sin(th), color="0.6", lw=3.0,
            label=f"exact circle (radius {radius:.4g})")
    ax.plot(path[:, 0], path[:, 1], ".", ms=1.0, color="C0", label=f"GNI contact point, h = {h:g}, {steps} steps")
    ax.plot([0.0], [0.0], "x", color="k", ms=10, mew=2, label="centre of the rotating table")
    ax.plot([q0[0]], [q0[1]], "o", color="C3", ms=5, label="start (1, 1)")
    ax.set_aspect("equal")
    ax.set_xlabel("$x$")
    ax.set_ylabel("$y$")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="center")
    title = f"Figure 2 — contact point of the homogeneous ball, h = {h:g}, {steps} steps"
    ax.set_title(title, fontsize=9)
    return fig, title


def _figure_2_notes(metrics: dict[str, float], h: float, steps: int) -> list[str]:
    """The findings of Fig. 2: on the circle (order 2), the Jacobi integral, the phase error, the
    table's centre."""
    return [
        f"The discrete path stays on the exact circle to within {metrics['max_distance_from_exact_circle']:.2e} "
        f"({metrics['relative_max_distance_from_exact_circle']:.1e} of the radius) over {steps} steps; "
        f"first half {metrics['max_distance_first_half']:.2e}, second half "
        f"{metrics['max_distance_second_half']:.2e} (no secular drift off the circle). With h/2 over the same "
        f"time the largest distance is {metrics['max_distance_half_h']:.2e}, "
        f"{metrics['distance_ratio_h_over_half_h']:.2f} times smaller (4 for order 2).",
        f"The Jacobi integral J = E − mΩ(xẏ − yẋ), conserved by the continuous motion, varies by at most "
        f"{metrics['jacobi_drift']:.2e} along the discrete path (the energy E itself is not conserved: the "
        "table does work on the ball).",
        f"The motion along the circle has a phase error: the discrete angular rate about the centre is "
        f"{metrics['kappa_discrete']:.8f} against κ = {metrics['kappa']:g}, so the position error at "
        f"t = {h * steps:g} is {metrics['final_position_error']:.3g} although the path lies on the circle.",
        "The contact point never reaches the table's centre: the ball circles a point away from it "
        f"(largest distance from (0, 0): {metrics['max_distance_from_table_centre']:.4g}).",
    ]

#: The figures by name.
FIGURES: dict[str, Callable[..., FigureResult]] = {"figure1": figure_1, "figure2": figure_2, "figure3": figure_3}
