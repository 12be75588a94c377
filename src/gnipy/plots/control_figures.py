"""The figures of optimal control and identification: the inputs of a controlled run
(:func:`plot_controls`), the figure of a controlled run (:func:`plot_control`) and that of a fit
(:func:`plot_fit`)."""

from __future__ import annotations

import numpy as np

from ..extras import require
from .figure_parts import as_dataset, is_se2, item_names, new_axes, save_figure
from .run_figures import plot_path


def _control_dataset(obj):
    """The result Dataset of a controlled run: a :class:`gnipy.control.ControlResult` (its
    solution and controls), or a Dataset with the inputs `u` (a file of `gni control`)."""
    xr = require("xarray", extra="plots")

    if hasattr(obj, "controls") and hasattr(obj, "solution"):
        ds = obj.solution.to_xarray()
        K, m = np.shape(obj.controls)
        ds["u"] = xr.DataArray(np.asarray(obj.controls, dtype=float), dims=("control_step", "input"))
        t = np.asarray(ds["time"].values, dtype=float)
        names = list(getattr(obj, "input_names", ()) or [f"u{j}" for j in range(m)])
        return ds.assign_coords(control_step=np.arange(K), input=names,
                                control_time=("control_step", t[:K]))
    ds = as_dataset(obj)
    if "u" not in ds:
        raise ValueError("not a controlled run: the Dataset has no inputs u (a file of gni control)")
    return ds


def plot_controls(obj, ax=None):
    """The inputs $u_k$ against time, drawn as held over each step.

    Arguments:
        obj: a :class:`gnipy.control.ControlResult`, or the Dataset of a `gni control` file.
        ax: the matplotlib axes to draw on (default: a new figure).

    Returns:
        The axes.
    """
    ds = _control_dataset(obj)
    ax = new_axes(ax)
    t = np.asarray(ds["time"].values, dtype=float)
    u = np.asarray(ds["u"].values, dtype=float)
    names = [str(n) for n in ds["input"].values] if "input" in ds.coords else [f"u{j}" for j in range(u.shape[1])]
    K = u.shape[0]
    for j in range(u.shape[1]):
        ax.step(t[: K + 1], np.append(u[:, j], u[-1, j]), where="post", lw=1.2, label=names[j])
    ax.set_xlabel("t")
    ax.set_ylabel("input")
    ax.legend(loc="best", fontsize="small")
    ax.set_title("inputs (held over each step)", fontsize="medium")
    ax.grid(True, alpha=0.3)
    return ax


def plot_control(obj, path=None, *, title: str | None = None, overwrite: bool = False):
    """The figure of a controlled run: the configuration path, the inputs, the velocities and, on
    $\\mathbb{R}^n\\times G$, the angle turned by the orientation, $|\\log(R_0^{-1}R(t))|$.

    Arguments:
        obj: a :class:`gnipy.control.ControlResult`, or the Dataset of a `gni control` file.
        path: where to save it (None: not saved); written atomically.
        title: the figure title (default: model, method, steps).
        overwrite: replace an existing regular file at `path`.

    Returns:
        The `matplotlib.figure.Figure`.
    """
    Figure = require("matplotlib.figure", extra="plots").Figure

    ds = _control_dataset(obj)
    has_R = "R" in ds and np.asarray(ds["R"].values).shape[-1] == 3 and not is_se2(np.asarray(ds["R"].values))
    fig = Figure(figsize=(5 * (4 if has_R else 3), 4.4), layout="constrained")
    axes = fig.subplots(1, 4 if has_R else 3)
    plot_path(ds, axes[0])
    axes[0].set_title("configuration path", fontsize="medium")
    plot_controls(ds, axes[1])
    t = np.asarray(ds["time"].values, dtype=float)
    v = np.asarray(ds["v"].values, dtype=float)
    for j, name in enumerate(item_names(ds, "velocity", v.shape[-1], "v")):
        axes[2].plot(t, v[:, j], lw=1.1, label=name)
    axes[2].set_xlabel("t")
    axes[2].set_ylabel("velocity")
    axes[2].legend(loc="best", fontsize="small")
    axes[2].set_title("velocities", fontsize="medium")
    axes[2].grid(True, alpha=0.3)
    if has_R:
        R = np.asarray(ds["R"].values, dtype=float)
        rel = np.einsum("ji,tjk->tik", R[0], R)
        angle = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)))
        axes[3].plot(t, angle, lw=1.2)
        axes[3].set_xlabel("t")
        axes[3].set_ylabel("degrees")
        axes[3].set_title("angle turned, |log(R₀ᵀR)|", fontsize="medium")
        axes[3].grid(True, alpha=0.3)
    if title is None:
        a = ds.attrs
        parts = [str(a[k]) for k in ("control_problem", "model", "method") if a.get(k)]
        parts.append(f"{np.asarray(ds['u']).shape[0]} steps")
        title = ", ".join(parts)
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path, overwrite)
    return fig


def plot_fit(result, path=None, *, title: str | None = None, overwrite: bool = False):
    """The figure of a fit (:func:`gnipy.fit`): each observed variable, observed (points) and
    fitted (the fitted run's nodes), and the residuals model − observed against time (divided by
    sigma when it was given).

    Arguments:
        result: a :class:`gnipy.control.FitResult`.
        path: where to save it (None: not saved); written atomically.
        title: the figure title (default: the system, method and reduced chi²).
        overwrite: replace an existing regular file at `path`.

    Returns:
        The `matplotlib.figure.Figure`.

    Raises:
        InputError: a flagged result with no fitted run (the model not valid at the estimate).
    """
    Figure = require("matplotlib.figure", extra="plots").Figure

    obs = result.observations
    sol = result.solution
    if sol is None:
        from ..errors import InputError

        raise InputError(f"result: the fit has no fitted run to draw ({result.message})")
    names = list(obs.variables)
    coords, vels = list(sol.coordinates), list(sol.velocities)
    t_obs = np.asarray(obs.times, dtype=float)
    t = np.asarray(sol.t, dtype=float)
    k = len(names)
    fig = Figure(figsize=(4.6 * (k + 1), 4.2), layout="constrained")
    axes = fig.subplots(1, k + 1)
    for j, name in enumerate(names):
        ax = axes[j]
        model = np.asarray(sol.q)[:, coords.index(name)] if name in coords else np.asarray(sol.v)[:, vels.index(name)]
        ax.plot(t, model, lw=1.2, label="fitted")
        ax.plot(t_obs, np.asarray(obs.values, dtype=float)[:, j], ".", ms=4, color="C3", label="observed")
        ax.set_xlabel("t")
        ax.set_title(name, fontsize="medium")
        ax.legend(loc="best", fontsize="small")
        ax.grid(True, alpha=0.3)
    ax = axes[-1]
    res = np.asarray(result.residuals, dtype=float)
    weighted = None
    if result.sigma_known:  # sigma given to fit() or held by the observations: the weighted residuals
        w = np.asarray(result.weighted_residuals(), dtype=float)
        if w.size == res.size:
            weighted = np.where(np.isnan(res), np.nan, w.reshape(res.shape))
    for j, name in enumerate(names):
        ax.plot(t_obs, res[:, j] if weighted is None else weighted[:, j], ".", ms=4, label=name)
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("t")
    ax.set_title("residuals (model − observed)" + (" / sigma" if weighted is not None else ""), fontsize="medium")
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)
    if title is None:
        title = f"fit of {sol.system} with {result.method}: reduced chi² = {result.reduced_chi2:.3g}"
    if title:
        fig.suptitle(title)
    if path is not None:
        save_figure(fig, path, overwrite)
    return fig
