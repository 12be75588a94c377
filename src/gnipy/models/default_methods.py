"""Each zoo model's default method: the recommendation of the method atlas (`gni atlas`,
:mod:`gnipy.experiments.atlas`, by the rule of :func:`gnipy.experiments.method_choice.choose`).

Every applicable method runs once per model at h = 0.01 for 10⁵ steps (10⁶ on three models) and is
measured against the continuous reference over t <= 200: position error, drift of the energy and
the registered invariants over the whole run, the run-time verdicts. This module is written by the
full atlas (`gni atlas --out DIR` writes `DIR/default_methods.py`; copy it here after changing a
method or a model); the atlas guide of the documentation shows the measurements. `gni models`
prints the table.
"""

from __future__ import annotations

from ..registry import FALLBACK_METHOD, set_default_methods

__all__ = ["DEFAULT_METHODS", "FALLBACK_METHOD"]

#: model name -> (method, why), the method atlas's recommendations (gnipy.experiments.atlas).
DEFAULT_METHODS: dict[str, tuple[str, str]] = {
    "chaplygin-sleigh": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.6e-11, invariants to 3.2e-14"
        "; next discrete-gradient 2.5e-05, dla 7.6e-04"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, euler-a, euler-b, euler-ab, shake, rattle, yoshida4-gni-trapezoid, suzuki4-gni-trapezoid",
    ),
    "chaplygin-sleigh-se2": (
        "discrete-gradient",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.3e-03, invariants to 2.0e-16"
        "; next sgni-trapezoid 1.5e-03, sgni-midpoint 1.5e-03"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, rat, yoshida4-gni-trapezoid, suzuki4-gni-trapezoid",
    ),
    "chaplygin-sphere": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 3.3e-06, invariants to 4.0e-10"
        "; next yoshida4-gni-trapezoid 2.4e-04, dla 7.9e-02",
    ),
    "chaplygin-top": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.3e-06, invariants to 5.5e-10"
        "; next yoshida4-gni-trapezoid 9.2e-05, dla 3.6e-02"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "contact-oscillator": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 6.9e-11, invariants to 8.3e-14"
        "; next suzuki4-gni-trapezoid 5.7e-09, yoshida4-gni-trapezoid 3.0e-07"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "contact-oscillator-gauge": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 4.0e-09, invariants to 9.4e-10"
        "; next yoshida4-gni-trapezoid 1.8e-07, dla 1.8e-03"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "contact-oscillator-mp": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 10000, error over t <= 200): 4.9e-12, invariants to 8.5e-14"
        "; next suzuki4-gni-trapezoid 6.1e-09, yoshida4-gni-trapezoid 2.8e-07"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "differential-drive": (
        "dla",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.9e-02, invariants to 3.9e-05"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, sgni-trapezoid, sgni-midpoint, discrete-gradient, yoshida4-gni-trapezoid, suzuki4-gni-trapezoid",
    ),
    "knife-edge": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 8.0e-11, invariants to 6.6e-10"
        "; next suzuki4-gni-trapezoid 1.0e-07, yoshida4-gni-trapezoid 3.3e-06"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "nonholonomic-particle": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 10000, error over t <= 200): 5.3e-11, invariants to 1.3e-13"
        "; next suzuki4-gni-trapezoid 5.1e-08, yoshida4-gni-trapezoid 5.7e-07"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "nonholonomic-particle-gauge": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 3.9e-07, invariants to 1.5e-08"
        "; next yoshida4-gni-trapezoid 2.4e-05, gni-midpoint 4.4e-03"
        "; disqualified: gni-euler-a, gni-euler-b, discrete-gradient",
    ),
    "rolling-ball": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.0e-04, invariants to 1.6e-07"
        "; next yoshida4-gni-trapezoid 7.0e-03, discrete-gradient 1.5e-01",
    ),
    "rolling-disk": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 2.9e-09, invariants to 2.9e-12"
        "; next yoshida4-gni-trapezoid 2.2e-08, discrete-gradient 5.5e-04"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "rotating-table-ball": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 5.7e-12, invariants to 2.0e-13"
        "; next yoshida4-gni-trapezoid 9.3e-10, suzuki4-gni-trapezoid 9.4e-10",
    ),
    "suslov": (
        "discrete-gradient",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 1.8e-03, invariants to 5.5e-15"
        "; next sgni-midpoint 3.6e-03, sgni-trapezoid 3.6e-03"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, rat, yoshida4-gni-trapezoid, suzuki4-gni-trapezoid",
    ),
    "vertical-disk": (
        "kahanli6-mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 10000, error over t <= 200): 4.5e-13, invariants to 3.7e-10"
        "; next suzuki4-gni-trapezoid 4.7e-09, yoshida4-gni-trapezoid 4.8e-08",
    ),
    "veselova": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 or below 1e-09 broken by the rule (h = 0.01, T = 1000, error over t <= 200): 7.0e-08, invariants to 6.6e-11"
        "; next yoshida4-gni-trapezoid 5.1e-06, sgni-trapezoid 9.1e-03",
    ),
}

set_default_methods(DEFAULT_METHODS)
