"""Draws docs/user-guide/figures/whipple-bicycle-stability.png: the eigenvalues of the nonlinear
Whipple bicycle (gnipy.models.whipple_bicycle) linearized by gnipy.linearize about its upright
straight motion, against the speed, as Meijaard et al. (2007) Fig. 3, with the weave and capsize
speeds marked. Run: `python docs/_tools/whipple_figure.py` (about a minute)."""

import pathlib

import numpy as np

import gnipy
from gnipy.models import whipple_bicycle as wb

if __name__ == "__main__":
    bicycle = wb.build()
    curve = gnipy.analysis.stability_curve(bicycle, lambda v: wb.upright(None, v), np.linspace(0.0, 10.0, 81))
    print("transitions (weave, capsize):", curve.transitions)
    out = pathlib.Path(__file__).resolve().parents[1] / "user-guide" / "figures" / "whipple-bicycle-stability.png"
    gnipy.plots.plot_stability(curve, out, xlabel="speed v (m/s)", overwrite=True,
                               title="Whipple bicycle (Meijaard 2007 benchmark): eigenvalues against speed")
