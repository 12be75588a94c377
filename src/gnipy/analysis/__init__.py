"""The analysis layer: what is measured on simulations (fitted orders, and more to come here:
diagnostics, invariants, convergence studies), shared by the CLI, the experiments and the tests."""

from .orders import ROUND_OFF, fit_points, fitted_order

__all__ = ["ROUND_OFF", "fit_points", "fitted_order"]
