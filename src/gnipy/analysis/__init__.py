"""The analysis layer: what is measured on simulations, shared by the CLI, the experiments and the
tests.

- the run-time verdicts of a solution (the GNI's hidden momentum, the drift of a conserved
  energy) and which quantity a model conserves, re-exported from :mod:`gnipy.diagnostics` (they
  live with the driver, which computes them as it runs);
- :mod:`gnipy.analysis.invariants`: the drift of a model's invariants, the errors against its
  exact solution;
- :mod:`gnipy.analysis.orders`: the one fitted order of convergence;
- :mod:`gnipy.analysis.convergence`: convergence studies (`gni convergence`);
- :mod:`gnipy.analysis.linearization`: the linear stability of a steady motion (`gnipy.linearize`);
- :mod:`gnipy.analysis.modified_equations`: backward error analysis, the modified vector field
  of a method's one-step map;
- :mod:`gnipy.analysis.sister`: sister systems, a nonholonomic constraint replaced by holonomic
  ones switched every τ with a plastic impact, and the discrete method built from them.
"""

from .convergence import MEASURES, REFERENCE_FLOOR, ConvergenceStudy, convergence_study
from ..diagnostics import (
    ENERGY_BAND,
    HIDDEN_BAND,
    HIDDEN_FLOOR,
    EnergyVerdict,
    HiddenMomentumVerdict,
    conserved_quantity,
    energy_is_invariant,
    energy_theorem_applies,
    energy_verdict,
    hidden_momentum_band,
    hidden_momentum_verdict,
)
from .modified_equations import ModifiedEquations, modified_equations
from .sister import SisterRun, sister_method, sister_trajectory
from .invariants import ExactErrors, exact_errors, invariant_drifts
from .linearization import (DiscreteLinearization, Linearization, StabilityCurve, discrete_linearization, linearize,
                            stability_curve)
from .orders import ROUND_OFF, fit_points, fitted_order

__all__ = [
    "ModifiedEquations",
    "modified_equations",
    "SisterRun",
    "sister_trajectory",
    "sister_method",
    "Linearization",
    "linearize",
    "StabilityCurve",
    "stability_curve",
    "DiscreteLinearization",
    "discrete_linearization",
    "ConvergenceStudy",
    "convergence_study",
    "MEASURES",
    "REFERENCE_FLOOR",
    "ENERGY_BAND",
    "HIDDEN_BAND",
    "HIDDEN_FLOOR",
    "EnergyVerdict",
    "HiddenMomentumVerdict",
    "conserved_quantity",
    "energy_is_invariant",
    "energy_theorem_applies",
    "energy_verdict",
    "hidden_momentum_band",
    "hidden_momentum_verdict",
    "ExactErrors",
    "exact_errors",
    "invariant_drifts",
    "ROUND_OFF",
    "fit_points",
    "fitted_order",
]
