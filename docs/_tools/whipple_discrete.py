"""The discrete maps of three methods on the Whipple bicycle (gnipy.models.whipple_bicycle) about its
upright straight motion at 5 m/s, against the continuous eigenvalues (gnipy.linearize): the table
of docs/user-guide/models.md, "Which methods keep the self-stable motion". Run:
`python docs/_tools/whipple_discrete.py` (about 5 minutes on 2 cores: each Jacobian of a step is
taken op by op)."""

import numpy as np

import gnipy
from gnipy.analysis import discrete_linearization
from gnipy.models import whipple_bicycle as wb

if __name__ == "__main__":
    bicycle = wb.build()
    q, v = wb.upright(None, 5.0)
    continuous = gnipy.linearize(bicycle, q, v).nonzero_eigenvalues
    print("continuous:", np.round(continuous, 5))
    print("| method | h | castering | weave | capsize | growth rate of the map |")
    print("|---|---|---|---|---|---|")
    for method in ("gni-trapezoid", "sgni-trapezoid", "dla"):
        for h in (0.01, 0.005):
            d = discrete_linearization(bicycle, method, q, v, h)
            capsize, weave, _, castering = d.nearest(continuous)
            print(f"| `{method}` | {h} | {castering.real:.5f} | {weave.real:.5f} ± {abs(weave.imag):.5f}i | "
                  f"{capsize.real:.5f} | {d.growth_rate:+.3g} |", flush=True)
