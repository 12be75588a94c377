"""The figures of a run (its configuration path, energy error, constraint residual, hidden
momentum, and all of them together: :func:`plot_solution`), of a convergence study
(:func:`plot_convergence`) and of the stability of a family of steady motions
(:func:`plot_stability`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..analysis.orders import ROUND_OFF, fitted_order
from ..extras import require
from .figure_parts import ZERO_LEVEL, as_dataset, is_se2, item_names, new_axes, panel_title, save_figure


def plot_path(obj, ax=None):
    """The configuration path.

    What is drawn depends on the configuration space:

    - two or more coordinates: the second against the first (for the rolling models the contact
      point (x, y) on the plane; equal scales when they are called x and y);
    - one coordinate: the coordinate against time;
    - no coordinates, on SE(2): the position (the translation part of R);
    - no coordinates, on SO(3): the path of the body's third axis R e₃, seen from above.

    The start is marked with a circle, the end with a cross.

    Arguments:
        obj: a :class:`~gnipy.Solution` or a result `xarray.Dataset`.
        ax: the matplotlib axes to draw on (default: a new figure).

    Returns:
        The axes.
    """
    ds = as_dataset(obj)
    ax = new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    q = np.asarray(ds["q"].values, dtype=float) if "q" in ds else np.zeros((len(t), 0))
    names = item_names(ds, "coordinate", q.shape[-1], "q")
    equal = False
    if q.shape[-1] >= 2:
        x, y, xl, yl = q[:, 0], q[:, 1], names[0], names[1]
        equal = (xl, yl) == ("x", "y")
        what = "configuration path"
    elif q.shape[-1] == 1:
        x, y, xl, yl = t, q[:, 0], "t", names[0]
        what = f"{names[0]}(t)"
    elif "R" in ds:
        R = np.asarray(ds["R"].values, dtype=float)
        if is_se2(R):
            x, y, xl, yl = R[:, 0, 2], R[:, 1, 2], "x", "y"
            what, equal = "position in the plane", True
        else:
            x, y, xl, yl = R[:, 0, -1], R[:, 1, -1], "(R e₃)₁", "(R e₃)₂"
            what, equal = "body axis R e₃ (seen from above)", True
    else:
        ax.text(0.5, 0.5, "no configuration coordinates", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(panel_title(ds, "configuration path"))
        return ax
    ax.plot(x, y, lw=1.2)
    ax.plot(x[:1], y[:1], "o", color="C2", label="start")
    ax.plot(x[-1:], y[-1:], "x", color="C3", label="end")
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    if equal:
        # equal scales by the axes' box: with adjustable="datalim" the limits widen only at drawing,
        # after a constrained layout has placed the axes for the narrower tick labels, and the y
        # label went off the figure (gni control --plot on the sleigh: its "y" was cut at the edge);
        # a path much longer one way than the other keeps free scales (a box would be a thin strip)
        spans = np.ptp(x), np.ptp(y)
        if min(spans) > 0 and max(spans) <= 4 * min(spans):
            ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="best", fontsize="small")
    ax.set_title(panel_title(ds, what), fontsize="medium")
    ax.grid(True, alpha=0.3)
    return ax


def plot_energy_error(obj, ax=None):
    """The energy error E(t) − E(0) against time (E = ½vᵀ𝔾v + V, the reported velocity).

    For conservative systems with linear constraints the GNI keeps it bounded; with affine
    constraints (a turning table) the energy changes physically, and the plot shows that change.

    Arguments:
        obj: a :class:`~gnipy.Solution` or a result `xarray.Dataset`.
        ax: the matplotlib axes to draw on (default: a new figure).

    Returns:
        The axes.
    """
    ds = as_dataset(obj)
    ax = new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    e = np.asarray(ds["energy"].values, dtype=float)
    ax.plot(t, e - e[0], lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel("E − E₀")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
    ax.set_title(panel_title(ds, "energy error"), fontsize="medium")
    ax.grid(True, alpha=0.3)
    return ax


def plot_constraint_residual(obj, ax=None):
    """The constraint residual max_j |μ(q)(v − Y(q))|_j against time, on a logarithmic scale.

    The GNI satisfies the constraints at every node to round-off; residuals that are exactly zero
    are drawn at 1e-18.

    Arguments:
        obj: a :class:`~gnipy.Solution` or a result `xarray.Dataset`.
        ax: the matplotlib axes to draw on (default: a new figure).

    Returns:
        The axes.
    """
    ds = as_dataset(obj)
    ax = new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    r = np.asarray(ds["constraint_residual"].values, dtype=float)
    r = np.abs(r).max(axis=-1) if r.ndim == 2 and r.shape[-1] else np.zeros_like(t)
    ax.semilogy(t, np.maximum(r, ZERO_LEVEL), lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel("max |μ(q)(v − Y)|")
    ax.set_title(panel_title(ds, "constraint residual"), fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    return ax


def plot_hidden_momentum(obj, ax=None):
    """The GNI family's hidden momentum $|p^+ - \\bar p|/|\\bar p|$ at the saved nodes against
    time, on a logarithmic scale, with its O(h) band (:func:`gnipy.diagnostics.hidden_momentum_band`,
    from the saved nodes) and the time its verdict fired (the run's every-node check).

    Arguments:
        obj: a :class:`~gnipy.Solution` or a result `xarray.Dataset` of a GNI-family run (with the
            variables `hidden_momentum` and `hidden_momentum_expected`).
        ax: the matplotlib axes to draw on (default: a new figure).

    Returns:
        The axes.
    """
    from ..diagnostics import hidden_momentum_band

    ds = as_dataset(obj)
    if "hidden_momentum" not in ds:
        raise ValueError("plot_hidden_momentum: the run has no hidden momentum (only the GNI family carries one)")
    ax = new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    r = np.asarray(ds["hidden_momentum"].values, dtype=float)
    e = (np.asarray(ds["hidden_momentum_expected"].values, dtype=float) if "hidden_momentum_expected" in ds
         else np.zeros_like(r))
    # a node at rest under a force (r = e = inf) is not judged (gnipy.diagnostics.judged_ratio): a gap;
    # an infinite or NaN ratio that is judged (out of band) is drawn at the top, with a marker
    r = np.where(np.isposinf(r) & np.isposinf(e), np.nan, np.where(np.isnan(r), np.inf, r))
    finite = np.isfinite(r)
    top = 10.0 * (float(np.max(r[finite])) if finite.any() else 1.0)
    ax.semilogy(t, np.where(finite, np.maximum(r, ZERO_LEVEL), np.nan), lw=1.1, label="|p⁺ − p̄| / |p̄|")
    if np.any(np.isposinf(r)):
        ax.semilogy(t[np.isposinf(r)], np.full(int(np.sum(np.isposinf(r))), top), "^", color="C3",
                    label="infinite or NaN (out of band)")
    if "hidden_momentum_expected" in ds and "h" in ds.attrs:
        ax.semilogy(t, hidden_momentum_band(t, e, float(ds.attrs["h"])), lw=0.9, ls="--", color="0.4",
                    label="its O(h) band")
    ax.set_xlabel("t")
    ax.set_ylabel("|p⁺ − p̄| / |p̄|")
    ax.set_title(panel_title(ds, "hidden momentum"), fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    return ax


def _verdict_times(ds) -> list[tuple[float, str]]:
    """`(time, what)` of each verdict out of band recorded in the run's attributes."""
    out = []
    for key, what in (("hidden_momentum_first_time", "hidden momentum out of band"),
                      ("energy_drift_first_time", "energy out of band")):
        try:
            t = float(ds.attrs[key])
        except (KeyError, TypeError, ValueError):
            continue
        if np.isfinite(t):
            out.append((t, what))
    return out


def plot_solution(obj, path=None, *, title: str | None = None, overwrite: bool = False):
    """The figure of a run: configuration path, energy error, constraint residual and, for the GNI
    family, the hidden momentum with its band (:func:`plot_hidden_momentum`); the time a verdict
    went out of band (the run's warning) is marked on every panel against time, and named in the
    title.

    Arguments:
        obj: a :class:`~gnipy.Solution` or a result `xarray.Dataset`.
        path: where to save the figure (the format follows the suffix: .png, .pdf, .svg, ...);
            None: do not save. The file is written atomically (:func:`gnipy.files.atomic_savefig`).
        title: the figure title (default: model, method and step size).
        overwrite: replace an existing regular file at `path` (without it, an existing file is an
            :class:`~gnipy.files.OutputError`, as for every file gnipy writes). A symbolic link,
            directory or special file at `path` is always refused.

    Returns:
        The `matplotlib.figure.Figure`.
    """
    Figure = require("matplotlib.figure", extra="plots").Figure

    ds = as_dataset(obj)
    hidden = "hidden_momentum" in ds
    fig = Figure(figsize=(20 if hidden else 15, 4.6), layout="constrained")
    axes = fig.subplots(1, 4 if hidden else 3)
    plot_path(ds, axes[0])
    plot_energy_error(ds, axes[1])
    plot_constraint_residual(ds, axes[2])
    names = ["configuration path", "energy error E − E₀", "constraint residual"]
    if hidden:
        plot_hidden_momentum(ds, axes[3])
        names.append("hidden momentum (GNI)")
    for ax, what in zip(axes, names):
        ax.set_title(what, fontsize="medium")
    verdicts = _verdict_times(ds)
    for ax in axes[1:]:
        for (t_out, what), ls in zip(verdicts, (":", "-.")):
            ax.axvline(t_out, color="C3", lw=1.0, ls=ls)
    for (t_out, what), ls in zip(verdicts, (":", "-.")):  # named once, on the energy panel
        axes[1].annotate(f"{what}, t = {t_out:.4g}", (t_out, 1.0), xycoords=("data", "axes fraction"),
                         xytext=(-3, -4), textcoords="offset points", rotation=90, va="top", ha="right",
                         fontsize="small", color="C3")
    if title is None:
        a = ds.attrs
        parts = [str(a[k]) for k in ("model", "method") if a.get(k)]
        if "h" in a:
            parts.append(f"h = {float(a['h']):g}")
        if "steps" in a:
            parts.append(f"{int(a['steps'])} steps")
        title = ", ".join(parts)
        if verdicts:
            title += f": QUALITATIVELY WRONG from t = {min(t for t, _ in verdicts):.4g} (the run's warning)"
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path, overwrite)
    return fig


def plot_convergence(
    h,
    errors: Mapping[str, Any],
    path=None,
    *,
    guides: Sequence[float] = (1, 2),
    floor: float = ROUND_OFF,
    title: str | None = None,
    ylabel: str = "error at the final time",
    ax=None,
    overwrite: bool = False,
):
    """A log-log plot of errors against step sizes, with the fitted slopes in the legend.

    Arguments:
        h: the step sizes: one array for all methods, or a mapping method → array.
        errors: method name → errors (same length as its step sizes).
        path: where to save the figure (None: do not save); written atomically.
        guides: orders p of reference lines C·hᵖ (through the middle of the data), each in a line
            style of its own and named at its right end.
        floor: the round-off level below which points are not used in the fit
            (see :func:`fitted_order`); such points are drawn with open markers.
        title: the axes title.
        ylabel: the label of the error axis.
        ax: the matplotlib axes to draw on (default: a new figure).
        overwrite: replace an existing regular file at `path` (without it, an existing file is an
            error; never a link or special file).

    Returns:
        The `matplotlib.figure.Figure`.
    """
    ax = new_axes(ax, figsize=(6.5, 5))
    fig = ax.figure
    all_h, all_e = [], []
    for i, (name, err) in enumerate(errors.items()):
        hs = np.asarray(h[name] if isinstance(h, Mapping) else h, dtype=float)
        err = np.asarray(err, dtype=float)
        if hs.shape != err.shape:
            raise ValueError(f"plot_convergence: {name!r} has {err.size} errors for {hs.size} step sizes")
        order = fitted_order(hs, err, floor)
        label = f"{name} (slope {order:.2f})" if np.isfinite(order) else f"{name} (no fit)"
        good = np.isfinite(err) & (err > floor)
        shown = np.isfinite(err) & (err > 0)
        color = f"C{i % 10}"
        ax.loglog(hs[shown], err[shown], "-", color=color, lw=1, alpha=0.6)
        ax.loglog(hs[good], err[good], "o", color=color, label=label)
        if np.any(shown & ~good):
            ax.loglog(hs[shown & ~good], err[shown & ~good], "o", mfc="none", color=color)
        all_h.append(hs[good])
        all_e.append(err[good])
    if all_h and sum(a.size for a in all_h):
        hh, ee = np.concatenate(all_h), np.concatenate(all_e)
        lo, hi = hh.min(), hh.max()
        if hi > lo:
            hm, em = np.sqrt(lo * hi), np.exp(np.mean(np.log(ee)))
            grid = np.geomspace(lo, hi, 20)
            styles = (("--", "0.35"), (":", "0.45"), ("-.", "0.55"), ((0, (5, 1, 1, 1, 1, 1)), "0.65"))
            for j, p in enumerate(guides):
                ls, color = styles[j % len(styles)]
                ax.loglog(grid, em * (grid / hm) ** p, ls=ls, color=color, lw=1.1, label=f"$O(h^{{{p:g}}})$")
                # each guide named at its end too: two grey lines of a legend are easily confused
                ax.annotate(f"$h^{{{p:g}}}$", (grid[-1], em * (grid[-1] / hm) ** p), xytext=(3, 0),
                            textcoords="offset points", va="center", fontsize="small", color=color)
    ax.set_xlabel("h")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title, fontsize="medium")
    if path is not None:
        save_figure(fig, path, overwrite)
    return fig


def plot_stability(curve, path=None, *, xlabel: str = "parameter", title: str | None = None, ax=None,
                   overwrite: bool = False):
    """The eigenvalues of a family of steady motions against its parameter
    (:func:`gnipy.analysis.stability_curve`), as Meijaard et al. (2007, Fig. 3) draw the benchmark
    bicycle's against its speed: real parts as solid lines, imaginary parts (their absolute values)
    dashed, zero eigenvalues left out, the unstable values shaded and each change of stability
    marked with its value.

    Arguments:
        curve: a :class:`~gnipy.analysis.linearization.StabilityCurve`.
        path: where to save the figure (None: do not save); written atomically.
        xlabel: the parameter's name on the horizontal axis (e.g. "speed v (m/s)").
        title: the axes title.
        ax: the matplotlib axes to draw on (default: a new figure).
        overwrite: replace an existing regular file at `path`.

    Returns:
        The `matplotlib.figure.Figure`.
    """
    ax = new_axes(ax, figsize=(6.5, 4.5))
    fig = ax.figure
    x = np.asarray(curve.values, dtype=float)
    eig = np.asarray(curve.eigenvalues)
    real = np.where(eig == 0, np.nan, eig.real)
    imag = np.where((eig == 0) | (eig.imag == 0), np.nan, np.abs(eig.imag))
    ax.plot(x, real, ".-", color="C0", lw=1, ms=3)
    ax.plot(x, imag, ".--", color="C1", lw=1, ms=3)
    ax.plot([], [], "-", color="C0", label="real part")
    ax.plot([], [], "--", color="C1", label="|imaginary part|")
    ax.axhline(0.0, color="0.5", lw=0.8)
    unstable = ~np.asarray(curve.stable, dtype=bool)
    for i in np.flatnonzero(unstable):
        lo = x[i] if i == 0 else 0.5 * (x[i - 1] + x[i])
        hi = x[i] if i == x.size - 1 else 0.5 * (x[i] + x[i + 1])
        ax.axvspan(lo, hi, color="C3", alpha=0.08, lw=0)
    for value in curve.transitions:
        ax.axvline(value, color="C3", lw=1, ls=":")
        ax.annotate(f"{value:.6g}", (value, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12),
                    textcoords="offset points", color="C3", fontsize=8)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("eigenvalues (1/s)")
    ax.set_title(title or "eigenvalues of the steady motions (unstable: shaded)")
    ax.legend(loc="best", fontsize=8)
    if path is not None:
        save_figure(fig, path, overwrite=overwrite)
    return fig
