"""Define your own nonholonomic system in a few lines, integrate it with the GNI, print a summary
and write the trajectory to a netCDF file.

The system: a skate (a knife edge) on the plane, held near the origin by a spring. Coordinates
(x, y, θ): position and heading; the blade cannot slide sideways, −sin θ ẋ + cos θ ẏ = 0.
Nothing else is needed: the metric, the projectors, the discrete Legendre transforms and the
Jacobians come from automatic differentiation.

    python examples/define_your_own_system.py [OUTPUT_DIR]

The output directory is the first argument, else $GNIPY_EXAMPLES_OUT, else a new temporary one.
"""

import os
import sys
import tempfile
from pathlib import Path

import jax.numpy as jnp
import numpy as np

import gnipy
from gnipy.io import write_netcdf

out = Path(sys.argv[1] if len(sys.argv) > 1 else os.environ.get("GNIPY_EXAMPLES_OUT") or tempfile.mkdtemp())
out.mkdir(parents=True, exist_ok=True)

# ---- the whole set-up ---------------------------------------------------------------------
m, J, k = 1.0, 0.2, 1.0  # mass, moment of inertia about the vertical, spring constant


def lagrangian(q, v):  # l(q, v) = kinetic - potential
    return 0.5 * m * (v[0] ** 2 + v[1] ** 2) + 0.5 * J * v[2] ** 2 - 0.5 * k * (q[0] ** 2 + q[1] ** 2)


def constraints(q):  # one row per constraint one-form: mu(q) v = 0
    return jnp.array([[-jnp.sin(q[2]), jnp.cos(q[2]), 0.0]])


skate = gnipy.System(lagrangian, constraints, coordinates=("x", "y", "theta"), name="skate-on-a-spring",
                     params={"m": m, "J": J, "k": k})
# -------------------------------------------------------------------------------------------

# start at (1, 0) heading along y with speed 0.5, turning at rate 1 (on the constraint)
sol = gnipy.simulate(skate, "gni-midpoint", q0=[1.0, 0.0, np.pi / 2], v0=[0.0, 0.5, 1.0],
                     h=0.01, t_final=20.0, save_every=10)
print(sol.summary())

energy = np.asarray(sol.energy)
residual = np.asarray(sol.constraint_residual)
print(f"energy drift: {np.max(np.abs(energy - energy[0])):.3e}")
print(f"max constraint residual: {np.max(np.abs(residual)):.3e}")

path = write_netcdf(sol, out / "skate.nc", attrs={"example": "define_your_own_system.py"}, overwrite=True)
print(f"written: {path}")
