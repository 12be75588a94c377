"""Each zoo model's default method, chosen from measurements (:mod:`gnipy.experiments.method_choice`).

One long run per model and method (h = 0.01, T = 200) against the continuous reference: position
error, drift of the energy and invariants, the run-time verdicts. The table below is the outcome of
`python -m gnipy.experiments.method_choice` (rerun it after changing a method or a model); the
full measurement table is in the models guide of the documentation. `gni models` prints it.
"""

from __future__ import annotations

from ..registry import FALLBACK_METHOD, set_default_methods

__all__ = ["DEFAULT_METHODS", "FALLBACK_METHOD"]

#: model name -> (method, why), from the measurements of gnipy.experiments.method_choice.
DEFAULT_METHODS: dict[str, tuple[str, str]] = {
    "chaplygin-sleigh": (
        "dla",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 7.6e-04, invariants to 8.6e-06"
        "; next mp 2.5e-03"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, euler-a, euler-b, euler-ab, shake, rattle",
    ),
    "chaplygin-sleigh-se2": (
        "dla",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 4.7e-03, invariants to 2.5e-05"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, rat",
    ),
    "chaplygin-sphere": (
        "gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 9.8e-02, invariants to 1.4e-05"
        "; next dla 7.9e-02, gni-euler-a 9.8e-02",
    ),
    "chaplygin-top": (
        "gni-midpoint",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 5.4e-02, invariants to 2.9e-04"
        "; next dla 3.6e-02, gni-trapezoid 5.8e-02"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "contact-oscillator": (
        "rattle",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 1.3e-03, invariants to 1.0e-04"
        "; next shake 1.3e-03, gni-trapezoid 1.3e-03"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "contact-oscillator-gauge": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 4.0e-09, invariants to 3.4e-10"
        "; next kahanli6-gni-trapezoid 6.2e-08, yoshida4-gni-trapezoid 1.8e-07"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "contact-oscillator-mp": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 6.1e-09, invariants to 4.8e-10"
        "; next kahanli6-gni-trapezoid 4.3e-08, yoshida4-gni-trapezoid 2.8e-07"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "knife-edge": (
        "euler-ab",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 3.9e-03, invariants to 5.5e-04"
        "; next mp 7.8e-03, dla 7.9e-03"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "nonholonomic-particle": (
        "mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 1.2e-03, invariants to 2.7e-05"
        "; next euler-ab 2.9e-03, gni-midpoint 4.3e-03"
        "; disqualified: gni-euler-a, gni-euler-b, euler-a, euler-b",
    ),
    "nonholonomic-particle-gauge": (
        "suzuki4-gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 3.9e-07, invariants to 3.0e-09"
        "; next kahanli6-gni-trapezoid 1.0e-06, yoshida4-gni-trapezoid 2.4e-05"
        "; disqualified: gni-euler-a, gni-euler-b",
    ),
    "rolling-ball": (
        "gni-midpoint",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 6.0e-01, invariants to 1.7e-05"
        "; next rat 6.0e-01, gni-euler-a 6.0e-01",
    ),
    "rotating-table-ball": (
        "euler-ab",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 2.9e-04, invariants to 4.3e-06"
        "; next mp 5.6e-04, dla 5.6e-04",
    ),
    "suslov": (
        "dla",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 7.7e-03, invariants to 4.3e-06"
        "; disqualified: gni-euler-a, gni-euler-b, gni-trapezoid, gni-midpoint, rat",
    ),
    "vertical-disk": (
        "mp",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 1.7e-05, invariants to 3.1e-13"
        "; next euler-ab 6.2e-04, dla 1.3e-03",
    ),
    "veselova": (
        "gni-trapezoid",
        "best error against the reference among the methods without warnings, ties within a factor 1.5 broken by the rule (h = 0.01, T = 200): 9.8e-03, invariants to 5.6e-06"
        "; next dla 9.2e-03, gni-euler-a 9.8e-03",
    ),
}

set_default_methods(DEFAULT_METHODS)
