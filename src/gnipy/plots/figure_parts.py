"""What the figures of :mod:`gnipy.plots` share: the Dataset a figure reads (:func:`as_dataset`),
new axes, panel titles, the names of coordinates and inputs, and the atomic save of a figure.

matplotlib and xarray are imported when first needed (:func:`gnipy.extras.require`), not with
this module.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..extras import require

#: Residuals that are exactly zero are drawn at this level on the logarithmic axis.
ZERO_LEVEL = 1e-18


def as_dataset(obj):
    """The `xarray.Dataset` of a :class:`~gnipy.Solution` (via `to_xarray`), or `obj` itself.

    A result file of the earlier layout (the times in a variable `t`, `time` the node index) is
    returned in the present one (:func:`gnipy.io.upgrade_layout`).

    Raises:
        TypeError: `obj` is neither a Solution nor a Dataset.
        ValueError: the Dataset has no times (a float coordinate `time`, or a variable `t`): it is
            not a gnipy result.
    """
    xr = require("xarray", extra="plots")

    from ..io import upgrade_layout
    from ..solution import Solution

    if isinstance(obj, Solution):
        return obj.to_xarray()
    if isinstance(obj, xr.Dataset):
        obj = upgrade_layout(obj)
        if "time" not in obj.coords or obj["time"].dtype.kind != "f":
            raise ValueError("the dataset has no times (coordinate 'time'): not a gnipy result file")
        return obj
    raise TypeError(f"expected a gnipy.Solution or an xarray.Dataset, got {type(obj).__name__}")


def new_axes(ax, figsize=(5.5, 4.5)):
    """`ax` itself, or where it is None the axes of a new figure of size `figsize` (inches,
    constrained layout), made without `pyplot`."""
    if ax is not None:
        return ax
    Figure = require("matplotlib.figure", extra="plots").Figure

    fig = Figure(figsize=figsize, layout="constrained")
    return fig.add_subplot()


def panel_title(ds, what: str) -> str:
    """The title of a panel: `what`, after the run's model and method when the Dataset's attributes
    name them (`disk, gni-midpoint: energy error`)."""
    model = ds.attrs.get("model")
    method = ds.attrs.get("method")
    head = ", ".join(str(x) for x in (model, method) if x)
    return f"{head}: {what}" if head else what


def item_names(ds, dim: str, n: int, prefix: str) -> list[str]:
    """The names of the `n` entries along `dim` (the coordinate `dim` of the Dataset when it has
    `n` of them), else `prefix` numbered from 0 (`q0`, `q1`, ...)."""
    if dim in ds.coords and ds.sizes.get(dim, -1) == n:
        return [str(x) for x in ds[dim].values]
    return [f"{prefix}{i}" for i in range(n)]


def is_se2(R: np.ndarray) -> bool:
    """A (T, 3, 3) array of SE(2) matrices (last row 0, 0, 1)?"""
    return R.ndim == 3 and R.shape[1:] == (3, 3) and np.allclose(R[:, 2, :], [0.0, 0.0, 1.0], atol=1e-12)


def save_figure(fig, path, overwrite: bool = False) -> Path:
    """Write `fig` to `path` atomically (the old file stays whole if writing fails; never through a
    link or into a special file): :func:`gnipy.files.atomic_savefig`."""
    from ..files import atomic_savefig

    return atomic_savefig(fig, Path(os.fspath(path)), overwrite=overwrite, argument="path", dpi=110)
