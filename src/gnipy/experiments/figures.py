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

**Progress.** `progress(advance, description)` is called as work proceeds; the advances of one
figure add up to 1.0 (the caller scales them to its bar).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..analysis.orders import ROUND_OFF, fit_points, fitted_order
from ..compilation import jit
from ..discrete_lagrangians import EulerA
from ..integrators.comparators import DiscreteLagrangeDAlembert
from ..integrators.gni import GNI, GNIState
from ..models import rolling_ball as rb
from ..saveat import SaveAt
from ..simulate import simulate
from ..spaces import Point

__all__ = ["FIGURES", "FigureResult", "figure_1", "figure_2", "figure_3", "paper_start"]

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
def _order(hs, errors, floor: float = ROUND_OFF) -> float:
    """The fitted slope (:func:`gnipy.analysis.fitted_order` with `stop_at_minimum=True`)."""
    return fitted_order(hs, errors, floor, stop_at_minimum=True)


def _fine_order(hs, errors, floor: float = ROUND_OFF, points: int = 3) -> float:
    """The slope over the `points` smallest h among the fitted points (the asymptotic order)."""
    hs, errors = np.asarray(hs, dtype=np.float64), np.asarray(errors, dtype=np.float64)
    keep = fit_points(hs, errors, floor, stop_at_minimum=True)
    finest = np.argsort(hs[keep])[:points]
    return _order(hs[keep][finest], errors[keep][finest], floor)


def _run(system, method, h: float, steps: int, saveat: SaveAt, q0=None, v0=None, *, state0=None, t0: float = 0.0):
    """`(x, v)` at the saved nodes of one :func:`gnipy.simulate` call, as numpy arrays (v is the
    velocity the method reports: the GNI's $\\bar v_k$, DLA's $\\mathbb{G}^{-1}p^+_k$)."""
    sol = simulate(system, method, q0, v0, h=h, steps=steps, saveat=saveat, state0=state0, t0=t0)
    return np.asarray(sol.q), np.asarray(sol.v)


def paper_start(system, q0, omega0, h: float, R0=None) -> GNIState:
    """The paper's start of example 2 (§7.4): the GNI state at node 1.

    $(x_1, y_1)$ solve the two-point (forward-difference) version of the last two equations of §7.4,
    i.e. the constraints (Cona), (Conb) at node 0:
    $(x_1 - x_0)/h + \\Omega y_0 - r\\omega^0_2 = 0$, $(y_1 - y_0)/h - \\Omega x_0 + r\\omega^0_1 = 0$;
    $\\sigma_0 = h\\omega^0$ and $R_1$ from $\\sigma_0$ by the model's reconstruction
    ($\\mathrm{cay}(\\sigma_0)R_0$ for `rolling-ball`, :meth:`~gnipy.spaces.GroupSpace.advance`); the post-momentum is
    $p^+_1 = FL^+(b_0, (x_1 - x_0, \\sigma_0))$ with the paper's $l_d = h\\,l(q_k, \\Delta, \\omega_k)$
    (Euler A), computed by the space's `legendre_plus`. The GNI continues from $(b_1, p^+_1)$:
    `gnipy.simulate(system, GNI(EulerA()), state0=paper_start(...), t0=h, ...)`.
    """
    p = system.parameters
    r, W = p["r"], p["Omega"]
    x0, y0 = (float(c) for c in q0)
    w = np.asarray(omega0, dtype=np.float64)
    dx1 = h * (r * w[1] - W * y0)  # x_1 − x_0
    dy1 = h * (W * x0 - r * w[0])
    R0 = jnp.eye(3) if R0 is None else jnp.asarray(R0, jnp.float64).reshape(3, 3)
    b0 = Point(jnp.asarray([x0, y0]), R0)
    z = jnp.asarray([dx1, dy1, *(h * w)])  # the step unknowns: increments (gnipy.spaces)
    return _start_from_step(system, b0, z, jnp.asarray(h, jnp.float64))


@jit
def _start_from_step(system, b0, z, h):
    """The GNI state at node 1 after the step `z` from `b0`: $(b_1, p^+_1 = FL^+(b_0, z))$ with the
    Euler A $l_d$ (jit-compiled: evaluated eagerly, the gradients cost seconds of small compiles)."""
    ld = EulerA()

    def l_d(b, zz):
        return ld(system, b, zz, h)

    p1 = system.space.legendre_plus(l_d, b0, z)
    return GNIState(system.space.advance(b0, z), p1, jnp.zeros_like(b0.x))


def _energy(p, v):
    """$E = \\tfrac12 m(\\dot x^2 + \\dot y^2) + \\tfrac12\\sum_i I_i\\omega_i^2$ along the last axis."""
    inertia = np.array([p["I1"], p["I2"], p["I3"]])
    return 0.5 * p["m"] * (v[..., 0] ** 2 + v[..., 1] ** 2) + 0.5 * np.sum(inertia * v[..., 2:] ** 2, axis=-1)


def _errors(x, v, x_ref, v_ref, p):
    """Max over the saved nodes of |(x, y) − ref|₂, |ω − ref|₂ and |E − E_ref|."""
    return (
        float(np.max(np.linalg.norm(x - x_ref, axis=-1))),
        float(np.max(np.linalg.norm(v[:, 2:] - v_ref[:, 2:], axis=-1))),
        float(np.max(np.abs(_energy(p, v) - _energy(p, v_ref)))),
    )


class _Progress:
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


# Work estimate of one run in steps: the fixed cost (dispatch, transfers) as this many steps.
_RUN_OVERHEAD = 4000


def _write(fig, out_dir: Path, name: str) -> list[Path]:
    """`NAME.png` and `NAME.pdf` in `out_dir`, each written atomically; an existing file is replaced
    only in a folder gnipy created or when asked (:func:`gnipy.experiments.report.save_figure`)."""
    from .report import save_figure

    return save_figure(fig, out_dir, name, dpi=150)


def _new_figure(width: float, height: float):
    # the object-oriented API (no pyplot): no global backend or state is touched
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _fmt_h(h: float) -> str:
    return f"{h:.3g}"


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
    # quick: only the small h, where DLA's orders are asymptotic (its O(h) velocity term dominates
    # its large O(h²) term only for h below about 0.01)
    Ns = [640 * 2**j for j in range(5)] if quick else [40 * 2**j for j in range(12)]
    hs = [T / N for N in Ns]
    t_save = T * np.arange(1, n_saves + 1) / n_saves
    x_ex, v_ex = rb.exact(p, q0, v0, t_save)
    save = SaveAt(ts=t_save)
    methods = {
        "gni": (GNI(EulerA()), "GNI", "-", "o"),
        "dla": (DiscreteLagrangeDAlembert(), "DLA [IMMM]", "--", "s"),
    }
    work = _Progress(progress, len(methods) * sum(N + _RUN_OVERHEAD for N in Ns))
    errors: dict[str, list[tuple[float, float, float]]] = {k: [] for k in methods}
    table: list[dict] = []
    for key, (method, *_rest) in methods.items():
        for N, h in zip(Ns, hs):
            x, v = _run(system, method, h, N, save, q0, v0)
            e = _errors(x, v, x_ex, v_ex, p)
            errors[key].append(e)
            table.append({"method": key, "h": h, "steps": N, "error_position": e[0], "error_omega": e[1],
                          "error_energy": e[2]})
            work(N + _RUN_OVERHEAD, f"figure 1: {key} h = {_fmt_h(h)}")

    quantities = ("position", "omega", "energy")
    metrics: dict[str, float] = {}
    for key in methods:
        arr = np.array(errors[key])
        for i, qn in enumerate(quantities):
            metrics[f"{key}_order_{qn}"] = _order(hs, arr[:, i])
            metrics[f"{key}_order_{qn}_fine"] = _fine_order(hs, arr[:, i])
            metrics[f"{key}_error_{qn}_smallest_h"] = float(arr[-1, i])

    fig = _new_figure(13.5, 4.2)
    axes = fig.subplots(1, 3)
    ylabels = ("max error in position $(x, y)$", "max error in angular velocity $\\omega$", "max error in energy")
    for i, (ax, qn, yl) in enumerate(zip(axes, quantities, ylabels)):
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
    files = _write(fig, out_dir, "figure1")
    work.finish("figure 1: done")

    caption = (
        "Rolling ball on a rotating table (paper §7.4, model rolling-ball, example 1): homogeneous ball "
        "I1 = I2 = I3 = 2/3, m = r = Ω = 1, (x0, y0, ẋ0, ẏ0) = (1, 1, 1, 1), ω0 = (0, 2, 0), R0 = I, "
        f"total time {T:g}. Time steps h = 10/N for N = {Ns[0]}, {Ns[1]}, ..., {Ns[-1]} "
        f"(h from {_fmt_h(hs[0])} to {_fmt_h(hs[-1])}). Solid: the GNI with the paper's discrete Lagrangian "
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
    notes = [
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
        f"{metrics['dla_order_omega']:.2f}, {metrics['dla_order_energy']:.2f}, because for h above about 0.01 a "
        "large O(h²) error (the same in position) dominates the O(h) one.",
        f"At the smallest h ({_fmt_h(hs[-1])}) the position errors are "
        f"{metrics['gni_error_position_smallest_h']:.2e} (GNI) and {metrics['dla_error_position_smallest_h']:.2e} "
        "(DLA).",
    ]
    metrics["runtime_s"] = time.perf_counter() - t_start
    return FigureResult("figure1", title, caption, files, metrics, table, notes)


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
    work = _Progress(progress, 3 * steps + 2 * _RUN_OVERHEAD)
    method = GNI(EulerA())
    path, v_path = _run(system, method, h, steps, SaveAt(steps=True), q0, v0)  # nodes 0 .. steps
    work(steps + _RUN_OVERHEAD, "figure 2: GNI h = 0.1")
    # the same total time with h/2 (not plotted): the distance from the circle should fall by 2² = 4
    # (saved at every second node, i.e. at the times of the h run: as many nodes, the same program)
    x2, _ = _run(system, method, h / 2, 2 * steps, SaveAt(every=2), q0, v0)
    x2 = x2[1:]
    work(2 * steps + _RUN_OVERHEAD, "figure 2: GNI h = 0.05")
    t = h * np.arange(steps + 1)

    # the exact motion: z = x + iy runs round a circle at rate κ = IΩ/(I + mr²)
    kappa = p["I1"] * p["Omega"] / (p["I1"] + p["m"] * p["r"] ** 2)
    z0, dz0 = complex(*q0), complex(v0[0], v0[1])
    centre = z0 + 1j * dz0 / kappa
    radius = abs(dz0) / kappa
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

    fig = _new_figure(6.4, 6.0)
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
    files = _write(fig, out_dir, "figure2")
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
    notes = [
        f"The discrete path stays on the exact circle to within {metrics['max_distance_from_exact_circle']:.2e} "
        f"({metrics['relative_max_distance_from_exact_circle']:.1e} of the radius) over {steps} steps; "
        f"first half {metrics['max_distance_first_half']:.2e}, second half "
        f"{metrics['max_distance_second_half']:.2e} (no secular drift off the circle). With h/2 over the same "
        f"time the largest distance is {dist_half_h:.2e}, {metrics['distance_ratio_h_over_half_h']:.2f} times "
        "smaller (4 for order 2).",
        f"The Jacobi integral J = E − mΩ(xẏ − yẋ), conserved by the continuous motion, varies by at most "
        f"{metrics['jacobi_drift']:.2e} along the discrete path (the energy E itself is not conserved: the "
        "table does work on the ball).",
        f"The motion along the circle has a phase error: the discrete angular rate about the centre is "
        f"{kappa_h:.8f} against κ = {kappa:g}, so the position error at t = {h * steps:g} is "
        f"{metrics['final_position_error']:.3g} although the path lies on the circle.",
        "The contact point never reaches the table's centre: the ball circles a point away from it "
        f"(largest distance from (0, 0): {metrics['max_distance_from_table_centre']:.4g}).",
    ]
    metrics["runtime_s"] = time.perf_counter() - t_start
    return FigureResult("figure2", title, caption, files, metrics, table, notes)


# ------------------------------------------------------------------------------------------------
# Figure 3: example 2, two starts, against a fine GNI run
# ------------------------------------------------------------------------------------------------
CAPTION_SLOPES = (1.0, 1.0, 2.0)  # Fig. 3's caption: dotted lines h, h, h²
_MATCH_TOL = 0.3


def _figure_3_steps(quick: bool) -> tuple[list[int], int]:
    """Step counts over T = 15: the runs (multiples of 10, h from 0.15 down) and the reference."""
    if quick:
        return [100, 200, 400, 800, 1600, 3000], 30_000  # h 0.15 .. 5e-3; reference h = 5e-4
    ratio = (15.0 / 8.4e-5 / 100.0) ** (1.0 / 11.0)  # 12 values, h from 0.15 to 8.4e-5
    Ns = sorted({10 * round(10 * ratio**j) for j in range(12)})
    return Ns, 555_560  # reference h = 15/555560 ≈ 2.69998e-5


def figure_3(out_dir: Path, quick: bool, progress: Progress = None) -> FigureResult:
    """Paper Fig. 3: example 2, errors in position, angular velocity and energy against a fine GNI
    run, for the paper's start and for the momentum start, with guide lines of slopes 1, 1, 2."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    system, q0, v0 = rb.example_2()
    p = system.parameters
    omega0 = np.asarray(rb.EXAMPLE_2["omega0"], dtype=np.float64)
    T, n_saves = 15.0, 10
    Ns, N_ref = _figure_3_steps(quick)
    hs = [T / N for N in Ns]
    h_ref = T / N_ref
    method = GNI(EulerA())
    save = SaveAt(ts=T * np.arange(1, n_saves + 1) / n_saves)
    starts = {
        "paper": ("(a) paper's start", "-", "o"),
        "momentum": ("(b) momentum start", "--", "s"),
    }

    def run(start, N):
        h = T / N
        if start == "paper":  # from the state at node 1 (time h)
            return _run(system, method, h, N - 1, save, state0=paper_start(system, q0, omega0, h), t0=h)
        return _run(system, method, h, N, save, q0, v0)

    # full runs also measure everything against the continuous reference solver (Dopri8, tol 1e-12)
    continuous = not quick
    work = _Progress(progress, len(starts) * (N_ref + sum(Ns) + (len(Ns) + 1) * _RUN_OVERHEAD)
                     + (N_ref if continuous else 0))
    if continuous:
        x_cont, v_cont = (a[1:] for a in _run(system, "reference", T / n_saves, n_saves, SaveAt(steps=True), q0, v0))
        work(N_ref, "figure 3: continuous reference")
    errors_cont: dict[str, np.ndarray] = {}
    quantities = ("position", "omega", "energy")
    errors: dict[str, np.ndarray] = {}
    refs = {}
    table: list[dict] = []
    for start in starts:
        x_ref, v_ref = run(start, N_ref)
        refs[start] = (x_ref, v_ref)
        work(N_ref + _RUN_OVERHEAD, f"figure 3: {start} start, reference h = {_fmt_h(h_ref)}")
        errs, errs_cont = [], []
        for N, h in zip(Ns, hs):
            x, v = run(start, N)
            e = _errors(x, v, x_ref, v_ref, p)
            errs.append(e)
            row = {"start": start, "h": h, "steps": N, "error_position": e[0], "error_omega": e[1],
                   "error_energy": e[2]}
            if continuous:
                ec = _errors(x, v, x_cont, v_cont, p)
                errs_cont.append(ec)
                row.update(error_position_vs_continuous=ec[0], error_omega_vs_continuous=ec[1],
                           error_energy_vs_continuous=ec[2])
            table.append(row)
            work(N + _RUN_OVERHEAD, f"figure 3: {start} start, h = {_fmt_h(h)}")
        errors[start] = np.array(errs)
        if continuous:
            errors_cont[start] = np.array(errs_cont)

    metrics: dict[str, float] = {"h_reference": h_ref}
    # the yardstick's own error, where it is known (full runs: against the continuous solution): errors
    # within 3 times of it measure the reference, not the run, and are left out of the fits
    floors = {(start, qn): ROUND_OFF for start in starts for qn in quantities}
    if continuous:
        for start in starts:
            ref_err = _errors(refs[start][0], refs[start][1], x_cont, v_cont, p)
            for i, qn in enumerate(quantities):
                metrics[f"{start}_reference_error_{qn}_vs_continuous"] = ref_err[i]
                floors[start, qn] = max(ROUND_OFF, 3.0 * ref_err[i])
                metrics[f"{start}_start_order_{qn}_vs_continuous"] = _order(hs, errors_cont[start][:, i])
                metrics[f"{start}_start_order_{qn}_vs_continuous_fine"] = _fine_order(hs, errors_cont[start][:, i])
    for start in starts:
        for i, qn in enumerate(quantities):
            floor = floors[start, qn]
            metrics[f"{start}_start_order_{qn}"] = _order(hs, errors[start][:, i], floor)
            metrics[f"{start}_start_order_{qn}_fine"] = _fine_order(hs, errors[start][:, i], floor)
            metrics[f"{start}_start_points_fitted_{qn}"] = float(fit_points(hs, errors[start][:, i], floor, stop_at_minimum=True).sum())
    # how far apart the two references are (both converge to the continuous solution)
    gap = _errors(refs["paper"][0], refs["paper"][1], refs["momentum"][0], refs["momentum"][1], p)
    for i, qn in enumerate(quantities):
        metrics[f"reference_gap_{qn}"] = gap[i]

    def matches(start):
        # judged on the asymptotic slopes (the three smallest fitted h), as the caption's guide lines are
        return all(
            abs(metrics[f"{start}_start_order_{qn}_fine"] - s) <= _MATCH_TOL
            for qn, s in zip(quantities, CAPTION_SLOPES)
        )

    matching = [s for s in starts if matches(s)]
    metrics["paper_start_matches_caption"] = float(matches("paper"))
    metrics["momentum_start_matches_caption"] = float(matches("momentum"))

    rows = [("fine GNI run", errors, "")] + ([("continuous solution", errors_cont, "_vs_continuous")] if continuous else [])
    fig = _new_figure(13.5, 4.2 * len(rows))
    axes = np.atleast_2d(fig.subplots(len(rows), 3))
    ylabels = ("max error in position $(x, y)$", "max error in angular velocity $\\omega$", "max error in energy")
    hs_arr = np.asarray(hs)
    for r, (against, errs_by_start, suffix) in enumerate(rows):
        for i, (ax, qn, yl, slope) in enumerate(zip(axes[r], quantities, ylabels, CAPTION_SLOPES)):
            for start, (label, ls, mk) in starts.items():
                ax.loglog(hs, errs_by_start[start][:, i], ls=ls, marker=mk, ms=4,
                          label=f"{label}: slope {metrics[f'{start}_start_order_{qn}{suffix}']:.2f} "
                          f"(finest 3: {metrics[f'{start}_start_order_{qn}{suffix}_fine']:.2f})")
                if not suffix and continuous:
                    ax.axhline(metrics[f"{start}_reference_error_{qn}_vs_continuous"], ls=ls, color="0.6", lw=0.8)
            # the caption's dotted guide C h^s, drawn above the curves at the largest h
            top = max(errs_by_start[s][0, i] for s in starts)
            C = 2.0 * top / hs_arr[0] ** slope
            ax.loglog(hs_arr, C * hs_arr**slope, ":", color="k", label=f"$\\propto h^{{{slope:g}}}$ (caption's guide)")
            ax.set_xlabel("time step $h$")
            ax.set_ylabel(yl)
            ax.set_title(f"against the {against}", fontsize=8)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6.5)
    title = "Figure 3 — rolling ball, example 2 (I = (1, 1.1, 1.2)): errors against a fine GNI run"
    fig.suptitle(title + "\n(a) paper's start: $(x_1, y_1)$ from the constraints at node 0, $\\sigma_0 = h\\omega^0$, "
                 "$p^+_1 = FL^+$;  (b) momentum start $p^+_0 = \\mathbb{G}v_0$;  dotted: $h$, $h$, $h^2$"
                 + ("; grey: the fine runs' own errors" if continuous else ""), fontsize=10)
    files = _write(fig, out_dir, "figure3")
    work.finish("figure 3: done")

    caption = (
        "Rolling ball on a rotating table (paper §7.4), example 2: I = (1, 1.1, 1.2), m = 3, r = 1, Ω = 0.2, "
        "(x0, y0) = (1, 0), ω⁰ = (−0.2, 0, 0.4), R0 = I; GNI with the paper's l_d (Euler A) and the Cayley map; "
        f"total time {T:g}; h = 15/N for N = {', '.join(str(N) for N in Ns)} (h from {_fmt_h(hs[0])} to "
        f"{_fmt_h(hs[-1])}, decreasing geometrically). Errors against a reference GNI run with the same start and "
        f"h = 15/{N_ref} ≈ {h_ref:.4g}" + (" (quick run: a coarser reference than the paper's 2.7e-5)" if quick
                                             else " (the paper's h ≈ 2.7e-5)")
        + f", taken at the {n_saves} nodes t = 1.5, 3, ..., 15 as the maximum of the Euclidean norm of the error in "
        "(x, y), in ω (the GNI's reported v̄_k), and of the absolute error in the energy "
        "E = ½m(ẋ² + ẏ²) + ½Σ Iᵢωᵢ². Two starts: (a) the paper's: (x1, y1) from the constraints at node 0 with "
        "forward differences, (x1 − x0)/h + Ωy0 − rω⁰₂ = 0, (y1 − y0)/h − Ωx0 + rω⁰₁ = 0, σ0 = hω⁰, "
        "R1 = cay(σ0), and the GNI continued from node 1 with p⁺₁ = FL⁺(x0, x1, σ0) (GroupSpace.legendre_plus "
        "of the Euler A l_d); (b) the momentum start p⁺₀ = 𝔾v0 with v0 = (0, 0.4, −0.2, 0, 0.4) from the "
        "constraints (gnipy.simulate's start). Dotted: multiples of h, h and h², the caption's guides. Slopes: "
        "least squares of log error against log h over the points with error above a floor and not past the "
        f"smallest error (round-off), the floor being {ROUND_OFF:g}"
        + (" or 3 times the fine run's own error against the continuous solution, whichever is larger"
           if continuous else "")
        + "; 'finest 3': the same over the three smallest of those h."
        + (" Bottom row: the same runs against the continuous reference solver (Dopri8, tolerance 1e-12) at the "
           "same nodes; grey lines in the top row: the fine GNI runs' own errors against it." if continuous else "")
    )
    fmt = "{:.2f}".format

    def orders(start, suffix=""):
        return ", ".join(fmt(metrics[f"{start}_start_order_{qn}{suffix}"]) for qn in quantities)

    if matching == ["paper"]:
        verdict = "the paper's start (a) matches the caption's slopes (1, 1, 2); the momentum start (b) does not"
    elif matching == ["momentum"]:
        verdict = "the momentum start (b) matches the caption's slopes (1, 1, 2); the paper's start (a) does not"
    elif matching:
        verdict = "both starts match the caption's slopes (1, 1, 2)"
    else:
        verdict = "neither start matches the caption's slopes (1, 1, 2)"
    notes = [
        f"Fitted slopes against the fine GNI run (position, ω, energy): paper's start (a) {orders('paper')}; "
        f"momentum start (b) {orders('momentum')}. Over the three smallest fitted h: (a) "
        f"{orders('paper', '_fine')}, (b) {orders('momentum', '_fine')}.",
        f"Comparison with the caption: {verdict} (judged on the slopes over the three smallest fitted h, "
        f"tolerance ±{_MATCH_TOL:g} on each).",
        "Why the start matters: the GNI with this l_d is the reduced RATTLE (a symmetric one-step map on "
        "(b_k, p⁺_k)), order 2 from a consistent start. Its own first step from p⁺₀ = 𝔾v0 solves "
        "(dτ⁻¹_σ)ᵀIσ/h = Iω⁰, i.e. σ0 = hω⁰ − (h²/2)I⁻¹(ω⁰ × Iω⁰) + O(h³), while the paper's start takes "
        "σ0 = hω⁰: an O(h²) change of σ0 that changes p⁺₁ = FL⁺ ≈ Iσ0/h by O(h), an O(h) error carried to the "
        "end (ω⁰ × Iω⁰ = (0, 0.016, 0) here). The (x1, y1) of the paper's start coincide with the GNI's own "
        "first step (both give x1 = x0 + hẋ0). The perturbation leaves the energy unchanged to first order "
        "(ω⁰·(ω⁰ × Iω⁰) = 0), so the O(h) part of the energy error has a small constant and the energy "
        "converges with slope 2 over the caption's range.",
        f"The two fine runs (h = {h_ref:.3g}) differ by {gap[0]:.2e} in position, {gap[1]:.2e} in ω and "
        f"{gap[2]:.2e} in energy at the saved nodes.",
    ]
    if continuous:
        notes.append(
            "Against the continuous reference solver (Dopri8, tolerance 1e-12) the fine GNI runs are off by "
            + "; ".join(
                f"{start} start {metrics[f'{start}_reference_error_position_vs_continuous']:.2e} in position, "
                f"{metrics[f'{start}_reference_error_omega_vs_continuous']:.2e} in ω, "
                f"{metrics[f'{start}_reference_error_energy_vs_continuous']:.2e} in energy"
                for start in starts
            )
            + f". For the momentum start (order 2) that is far more than its truncation error at h = {h_ref:.3g} "
            "(about 1e-10, extrapolating the bottom row): the fine run is limited by accumulated round-off, not by "
            "h. A likely source: the step unknown x_{k+1} is stored in absolute terms, so each step rounds it by "
            "about eps·|x|, and FL⁺ = m(x_{k+1} − x_k)/h turns that into a momentum error eps·|x|·m/h that is "
            "never damped. Errors within 3 times the fine run's own error are therefore left out of the top "
            "row's fits. Slopes against the continuous solution (position, ω, energy): "
            + "; ".join(f"{start} start {orders(start, '_vs_continuous')} (finest 3: "
                        f"{orders(start, '_vs_continuous_fine')})" for start in starts)
            + ": the paper's start is first order in position and ω, and its energy slope falls from 2 towards 1 "
            "at errors below about 1e-6, under the fine GNI run's own error, which is why the caption's "
            "comparison shows slope 2 for the energy."
        )
    metrics["runtime_s"] = time.perf_counter() - t_start
    return FigureResult("figure3", title, caption, files, metrics, table, notes)


#: The figures by name.
FIGURES: dict[str, Callable[..., FigureResult]] = {"figure1": figure_1, "figure2": figure_2, "figure3": figure_3}
