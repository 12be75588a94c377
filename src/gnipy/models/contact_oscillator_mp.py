"""The contact oscillator in McLachlan–Perlmutter's experimental set-up (2006, §5.2).

The system is that of `contact-oscillator`: $q = (x, y, z)$,

$$l = \\tfrac12|\\dot q|^2 - \\tfrac12\\big(|q|^2 + \\varepsilon x^2 z^2\\big), \\qquad
\\dot x + y\\dot z = 0,$$

with the invariants $H = \\tfrac12(|\\dot q|^2 + |q|^2 + \\varepsilon x^2z^2)$ and
$H_y = \\tfrac12(y^2 + \\dot y^2)$ (the constraint force $\\lambda(1, 0, y)$ has no y-component, so y
is a free harmonic oscillator, $y(t) = \\sqrt{2H_y}\\sin t$ from $y_0 = 0$).

What differs is the initial condition. McLachlan–Perlmutter study a family of orbits on one energy
level, started on the Poincaré section $y = 0$, $\\dot y > 0$:

$$H = 1.5,\\quad H_y = 0.5:\\qquad y_0 = 0,\\ \\dot y_0 = \\sqrt{2H_y} = 1,\\ \\dot z_0 = 0,\\
\\dot x_0 = -y_0\\dot z_0 = 0,\\ x_0 = \\sqrt{\\frac{2(H - H_y) - z_0^2 - \\dot z_0^2}{1 + \\varepsilon z_0^2}},$$

with $z_0$ on the grid $\\sqrt2\\,(-0.9, -0.7, \\dots, 0.9)$ (:data:`Z0_GRID`), and a time step
$h = 2\\sin(\\pi/N)$ (:func:`poincare_step`) for which the Störmer–Verlet discretization of the y
oscillator (what RATTLE and `gni-trapezoid` do to y) has period exactly N steps, so that every N-th
node lies on the section. The default initial condition is the grid point $z_0 = 0.1\\sqrt2$
(:data:`Z0_DEFAULT`), with $\\varepsilon = 0.3$.

Source and what is confirmed: R. McLachlan and M. Perlmutter, *Integrators for nonholonomic
mechanical systems*, J. Nonlinear Sci. 16 (2006) 283–328, §5.2 (the model, "a nonlinear
perturbation of the contact oscillator"). The numbers of the set-up (H = 1.5, H_y = 0.5, the z₀
grid, h = 2 sin(π/N), ε = 0.3) are those of O. Verdier's implementation of this example in odelab
(`odelab/system/nonholonomic/contactoscillator.py`, `ContactOscillator.initial_sin`, `time_step`;
`tests/scheme/test_cvt.py`), which cites MP §5.2; the paper's text itself could not be consulted
here, so the values are as odelab writes them. `contact-oscillator` keeps the same equations with
another initial condition, $q_0 = (1, 1, 1)$, $\\dot q_0 = (-1, 1, 1)$ ($H = 3.15$, $H_y = 1$),
which is not this set-up.
"""

from __future__ import annotations

import math

import numpy as np

from ..system import System
from ..registry import ModelSpec, register
from .contact_oscillator import constraints_args, lagrangian_args, total_energy, y_energy

__all__ = ["MODEL", "Z0_GRID", "Z0_DEFAULT", "ENERGY", "ENERGY_Y", "setup_initial_condition", "poincare_step"]

#: The energy levels of the set-up.
ENERGY, ENERGY_Y = 1.5, 0.5
#: The starting heights z₀ of the orbits: √2·(−0.9, −0.7, …, 0.9).
Z0_GRID = tuple(float(z) for z in np.linspace(-0.9, 0.9, 10) * np.sqrt(2.0))
#: The default orbit: z₀ = 0.1·√2 (Z0_GRID[5]).
Z0_DEFAULT = Z0_GRID[5]


def setup_initial_condition(epsilon: float, z0: float = Z0_DEFAULT, *, H: float = ENERGY, H_y: float = ENERGY_Y,
                            zdot0: float = 0.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The set-up's initial condition on the section y = 0, ẏ > 0 (module docstring):
    `((x0, 0, z0), (0, √(2H_y), ż0))` (ẋ₀ = −y₀ż₀ = 0), with $x_0 > 0$ fixed by the energy H.

    Raises:
        ValueError: when the energy H is too small for (z0, ż0, H_y).
    """
    rest = 2.0 * (H - H_y) - z0**2 - zdot0**2
    if rest < 0:
        raise ValueError(f"H = {H:g} is below the energy of z0 = {z0:g}, zdot0 = {zdot0:g}, H_y = {H_y:g}")
    x0 = math.sqrt(rest / (1.0 + epsilon * z0**2))
    y0 = 0.0
    return (x0, y0, float(z0)), (-y0 * zdot0 + 0.0, math.sqrt(2.0 * H_y), float(zdot0))


def poincare_step(N: int) -> float:
    """$h = 2\\sin(\\pi/N)$: the step for which Störmer–Verlet on $\\ddot y = -y$ has period N steps
    (its rotation angle θ per step solves $\\cos\\theta = 1 - h^2/2$; θ = 2π/N)."""
    return 2.0 * math.sin(math.pi / N)


def _default_ic(p):
    return setup_initial_condition(float(p["epsilon"]))


def _build(p):
    return System(
        lagrangian_args,
        constraints_args,
        coordinates=("x", "y", "z"),
        name="contact-oscillator-mp",
        args=p,
        params=p,
        defaults=_default_ic(p),
    )


_DEFAULTS = {"epsilon": 0.3}

MODEL = register(
    ModelSpec(
        name="contact-oscillator-mp",
        description="the contact oscillator in McLachlan–Perlmutter's §5.2 set-up (H = 1.5, H_y = 0.5, on y = 0)",
        build=_build,
        params=_DEFAULTS,
        coordinates=("x", "y", "z"),
        q0=_default_ic(_DEFAULTS)[0],
        v0=_default_ic(_DEFAULTS)[1],
        default_ic=_default_ic,
        invariants={"H": total_energy, "H_y": y_energy},
        notes=__doc__,
    )
)
