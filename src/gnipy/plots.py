"""Plots of simulations and convergence studies (matplotlib, no display needed).

Every function takes either a :class:`~gnipy.Solution` or the `xarray.Dataset` of a result file
(`Solution.to_xarray()`, or `xarray.open_dataset("run.nc")` on a file that `gni run` wrote), so a
file can be plotted long after the run:

    import xarray as xr
    from gnipy import plots

    plots.plot_solution(xr.open_dataset("disk.nc"), "disk.png")

The figures are `matplotlib.figure.Figure` objects created without `pyplot`: nothing is shown,
no global figure state is kept, and no interactive backend is needed (PNG, PDF and SVG output
go through Agg). Functions that draw on one panel take an optional `ax`; without it they create a
figure of their own and return the axes.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .analysis.orders import ROUND_OFF, fit_points, fitted_order

__all__ = [
    "as_dataset",
    "plot_path",
    "plot_energy_error",
    "plot_constraint_residual",
    "plot_solution",
    "plot_convergence",
    "fitted_order",
    "fit_points",
    "ROUND_OFF",
]


# Residuals that are exactly zero are drawn at this level on the logarithmic axis.
_ZERO_LEVEL = 1e-18


def as_dataset(obj):
    """The `xarray.Dataset` of a :class:`~gnipy.Solution` (via `to_xarray`), or `obj` itself.

    A result file of the earlier layout (the times in a variable `t`, `time` the node index) is
    returned in the present one (:func:`gnipy.io.upgrade_layout`).

    Raises:
        TypeError: `obj` is neither a Solution nor a Dataset.
        ValueError: the Dataset has no times (a float coordinate `time`, or a variable `t`): it is
            not a gnipy result.
    """
    import xarray as xr

    from .io import upgrade_layout
    from .solution import Solution

    if isinstance(obj, Solution):
        return obj.to_xarray()
    if isinstance(obj, xr.Dataset):
        obj = upgrade_layout(obj)
        if "time" not in obj.coords or obj["time"].dtype.kind != "f":
            raise ValueError("the dataset has no times (coordinate 'time'): not a gnipy result file")
        return obj
    raise TypeError(f"expected a gnipy.Solution or an xarray.Dataset, got {type(obj).__name__}")


def _new_axes(ax, figsize=(5.5, 4.5)):
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig.add_subplot()


def _title(ds, what: str) -> str:
    model = ds.attrs.get("model")
    method = ds.attrs.get("method")
    head = ", ".join(str(x) for x in (model, method) if x)
    return f"{head}: {what}" if head else what


def _names(ds, dim: str, n: int, prefix: str) -> list[str]:
    if dim in ds.coords and ds.sizes.get(dim, -1) == n:
        return [str(x) for x in ds[dim].values]
    return [f"{prefix}{i}" for i in range(n)]


def _is_se2(R: np.ndarray) -> bool:
    """A (T, 3, 3) array of SE(2) matrices (last row 0, 0, 1)?"""
    return R.ndim == 3 and R.shape[1:] == (3, 3) and np.allclose(R[:, 2, :], [0.0, 0.0, 1.0], atol=1e-12)


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
    ax = _new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    q = np.asarray(ds["q"].values, dtype=float) if "q" in ds else np.zeros((len(t), 0))
    names = _names(ds, "coordinate", q.shape[-1], "q")
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
        if _is_se2(R):
            x, y, xl, yl = R[:, 0, 2], R[:, 1, 2], "x", "y"
            what, equal = "position in the plane", True
        else:
            x, y, xl, yl = R[:, 0, -1], R[:, 1, -1], "(R e₃)₁", "(R e₃)₂"
            what, equal = "body axis R e₃ (seen from above)", True
    else:
        ax.text(0.5, 0.5, "no configuration coordinates", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(_title(ds, "configuration path"))
        return ax
    ax.plot(x, y, lw=1.2)
    ax.plot(x[:1], y[:1], "o", color="C2", label="start")
    ax.plot(x[-1:], y[-1:], "x", color="C3", label="end")
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    if equal:
        ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize="small")
    ax.set_title(_title(ds, what), fontsize="medium")
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
    ax = _new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    e = np.asarray(ds["energy"].values, dtype=float)
    ax.plot(t, e - e[0], lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel("E − E₀")
    ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
    ax.set_title(_title(ds, "energy error"), fontsize="medium")
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
    ax = _new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    r = np.asarray(ds["constraint_residual"].values, dtype=float)
    r = np.abs(r).max(axis=-1) if r.ndim == 2 and r.shape[-1] else np.zeros_like(t)
    ax.semilogy(t, np.maximum(r, _ZERO_LEVEL), lw=1.2)
    ax.set_xlabel("t")
    ax.set_ylabel("max |μ(q)(v − Y)|")
    ax.set_title(_title(ds, "constraint residual"), fontsize="medium")
    ax.grid(True, which="both", alpha=0.3)
    return ax


def plot_solution(obj, path=None, *, title: str | None = None, overwrite: bool = False):
    """A three-panel figure: configuration path, energy error, constraint residual.

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
    from matplotlib.figure import Figure

    ds = as_dataset(obj)
    fig = Figure(figsize=(15, 4.6), layout="constrained")
    axes = fig.subplots(1, 3)
    plot_path(ds, axes[0])
    plot_energy_error(ds, axes[1])
    plot_constraint_residual(ds, axes[2])
    for ax, what in zip(axes, ["configuration path", "energy error E − E₀", "constraint residual"]):
        ax.set_title(what, fontsize="medium")
    if title is None:
        a = ds.attrs
        parts = [str(a[k]) for k in ("model", "method") if a.get(k)]
        if "h" in a:
            parts.append(f"h = {float(a['h']):g}")
        if "steps" in a:
            parts.append(f"{int(a['steps'])} steps")
        title = ", ".join(parts)
    if title:
        fig.suptitle(title)
    if path is not None:
        _save(fig, path, overwrite)
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
        guides: orders p of dashed reference lines C·hᵖ (through the middle of the data).
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
    ax = _new_axes(ax, figsize=(6.5, 5))
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
            for j, p in enumerate(guides):
                ax.loglog(grid, em * (grid / hm) ** p, ls="--", color="0.5", lw=0.9,
                          dashes=(4 + 2 * j, 2 + j), label=f"$O(h^{{{p:g}}})$")
    ax.set_xlabel("h")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    if title:
        ax.set_title(title, fontsize="medium")
    if path is not None:
        _save(fig, path, overwrite)
    return fig


def _save(fig, path, overwrite: bool = False) -> Path:
    """Write `fig` to `path` atomically (the old file stays whole if writing fails; never through a
    link or into a special file): :func:`gnipy.files.atomic_savefig`."""
    from .files import atomic_savefig

    return atomic_savefig(fig, Path(os.fspath(path)), overwrite=overwrite, argument="path", dpi=110)
