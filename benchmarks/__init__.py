"""Benchmarks of gnipy against the baselines researchers run today.

Baselines (plain NumPy/SciPy, no JAX, so that timing them does not pay for JAX):

- :mod:`benchmarks.numpy_gni`: the same GNI step as gnipy, hand-written with NumPy and one
  `scipy.optimize.root(method="hybr")` per step, in a Python loop;
- :mod:`benchmarks.continuous`: the continuous Lagrange–d'Alembert(–Poincaré) equations for
  `scipy.integrate.solve_ivp(method="DOP853")`, with a reference solution and a tolerance tuner.

The cases are the paper's rolling ball (example 2, §7.4), the McLachlan–Perlmutter contact
oscillator and the physical Chaplygin sphere (R-dependent constraints, the Lie groupoid case).
"""
