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

A module each: the figures of a run and of a convergence study (:mod:`~gnipy.plots.run_figures`),
those of optimal control and identification (:mod:`~gnipy.plots.control_figures`), and what they
share, the Dataset a figure reads and the atomic save among it (:mod:`~gnipy.plots.figure_parts`).
The functions below are importable from `gnipy.plots` itself.
"""

# imported in the order the reference page lists them (mkdocstrings: members in source order)
from ..analysis.orders import ROUND_OFF, fit_points, fitted_order
from .figure_parts import as_dataset
from .run_figures import (
    plot_path,
    plot_energy_error,
    plot_constraint_residual,
    plot_hidden_momentum,
    plot_solution,
    plot_convergence,
    plot_stability,
)
from .control_figures import plot_controls, plot_control, plot_fit

__all__ = [
    "as_dataset",
    "plot_path",
    "plot_energy_error",
    "plot_constraint_residual",
    "plot_hidden_momentum",
    "plot_solution",
    "plot_convergence",
    "plot_stability",
    "plot_controls",
    "plot_control",
    "plot_fit",
    "fitted_order",
    "fit_points",
    "ROUND_OFF",
]
