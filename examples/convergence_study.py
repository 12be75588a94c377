"""A small convergence study: the GNI with the Euler A (order 1) and trapezoid (order 2) discrete
Lagrangians on the knife edge on an inclined plane, against its exact solution.

For each method and step size h = T/N the script integrates to T = 1, measures the error of the
configuration at T, and fits the order as the least-squares slope of log(error) against log(h)
(Theorem 5.1 of the paper: 1 for Euler A, 2 for the trapezoid). Gravity makes V ≠ 0, so the two
discrete Lagrangians differ (with V = 0 and a constant metric they coincide).

It writes the errors to convergence.csv and a log-log plot to convergence.png. The command line
does the same, compiling each method once for all step sizes:

    gni convergence knife-edge --methods gni-euler-a,gni-trapezoid --h-max 0.1 --h-min 0.0125 --count 4 --out DIR

    python examples/convergence_study.py [OUTPUT_DIR]

The output directory is the first argument, else $GNIPY_EXAMPLES_OUT, else a new temporary one.
"""

import csv
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

import gnipy
from gnipy.plots import fitted_order, plot_convergence

out = Path(sys.argv[1] if len(sys.argv) > 1 else os.environ.get("GNIPY_EXAMPLES_OUT") or tempfile.mkdtemp())
out.mkdir(parents=True, exist_ok=True)

spec = gnipy.get_model("knife-edge")
params = dict(spec.params)
system = spec.build(params)
q0, v0 = spec.initial_condition(params)
T = 1.0
step_counts = [10, 20, 40, 80]
q_exact, _ = spec.exact(params, q0, v0, np.array([0.0, T]))

h = np.array([T / n for n in step_counts])
errors = {}
for method in ["gni-euler-a", "gni-trapezoid"]:
    errors[method] = np.array([
        np.max(np.abs(np.asarray(gnipy.simulate(system, method, q0, v0, h=T / n, steps=n, save_every=n).q[-1])
                      - q_exact[-1]))
        for n in step_counts
    ])

print(f"knife-edge, error |q(T) - q_exact(T)| at T = {T:g}")
print("      h  " + "  ".join(f"{name:>14}" for name in errors))
for i, hi in enumerate(h):
    print(f"{hi:8.4f}  " + "  ".join(f"{errors[name][i]:14.3e}" for name in errors))
for name, err in errors.items():
    expected = gnipy.get_method(name).order
    print(f"order {name}: {fitted_order(h, err):.3f} (expected {expected})")

with open(out / "convergence.csv", "w", newline="") as f:
    writer = csv.writer(f)
    writer.writerow(["method", "h", "error"])
    for name, err in errors.items():
        writer.writerows([name, repr(float(hi)), repr(float(e))] for hi, e in zip(h, err))
plot_convergence(h, errors, out / "convergence.png", guides=(1, 2), title="knife edge: GNI convergence",
                 overwrite=True)
print(f"written: {out / 'convergence.csv'}")
print(f"written: {out / 'convergence.png'}")
