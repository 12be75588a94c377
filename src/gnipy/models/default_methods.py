"""Each zoo model's default method, chosen from measurements (:mod:`gnipy.experiments.method_choice`).

One long run per model and method (h = 0.01, T = 200) against the continuous reference: position
error, drift of the energy and invariants, the run-time verdicts. The table below is the outcome of
`python -m gnipy.experiments.method_choice` (rerun it after changing a method or a model); the
full measurement table is in the models guide of the documentation. `gni models` prints it.
"""

from __future__ import annotations

__all__ = ["DEFAULT_METHODS", "FALLBACK_METHOD"]

#: The default for systems that are not zoo models (symmetric, order 2, diagnosed; explicit for a
#: constant metric on R^n).
FALLBACK_METHOD = "gni-trapezoid"

#: model name -> (method, why), from the measurements of gnipy.experiments.method_choice.
DEFAULT_METHODS: dict[str, tuple[str, str]] = {}
