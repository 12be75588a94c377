"""Bounds on a fit's estimated quantities (`gnipy.control.bounds`): the defaults and checks, the
change of variables against its own inverse and central differences, and fits that end at a
bound or leave a model's valid region (flagged results, never exceptions). The data's true
parameter (k = 1.5) is the reference."""

import math

import jax
import numpy as np
import pytest

import gnipy
from gnipy.control import Observations, fit
from gnipy.control.bounds import fit_bounds
from gnipy.errors import InputError

H, STEPS = 0.05, 60
K = np.arange(2, STEPS + 1, 2)


def test_the_zoo_models_masses_inertias_and_lengths_are_positive_by_default():
    names = ("I", "a", "q0.x")
    b = fit_bounds(None, gnipy.get_model("chaplygin-sleigh").positive, names, [1.2, 0.5, 0.0])
    assert b.bounded == {"I": (0.0, math.inf)}
    assert fit_bounds({"I": None}, ("m", "I"), names, [1.2, 0.5, 0.0]).bounded == {}
    with pytest.raises(InputError, match="bounds: the initial guess -1.0 of 'I' .*positive by default"):
        fit_bounds(None, ("m", "I"), names, [-1.0, 0.5, 0.0])
    with pytest.raises(InputError, match="bounds: 'b' is not an estimated quantity"):
        fit_bounds({"b": (0, 1)}, (), names, [1.2, 0.5, 0.0])
    with pytest.raises(InputError, match="lower bound of 'a' must be below"):
        fit_bounds({"a": (1, 0)}, (), names, [1.2, 0.5, 0.0])
    with pytest.raises(InputError, match="must be a number or None"):
        fit_bounds({"a": ("0", 1)}, (), names, [1.2, 0.5, 0.0])


@pytest.mark.parametrize("pair", [(0.0, None), (None, 2.0), (0.0, 2.0), (None, None)])
def test_the_change_of_variables_is_inside_the_bounds_and_inverts(pair):
    b = fit_bounds({"a": pair}, (), ("a",), [0.7])
    z0 = b.internal([0.7])
    assert float(b.quantities(z0)[0]) == pytest.approx(0.7, rel=1e-14)
    lo, hi = (-math.inf if pair[0] is None else pair[0]), (math.inf if pair[1] is None else pair[1])
    for z in np.linspace(-50, 50, 101):
        y = float(b.quantities(np.array([z]))[0])
        assert lo <= y <= hi
        # dy/dz against a central difference
        d = (float(b.quantities(np.array([z + 1e-6]))[0]) - float(b.quantities(np.array([z - 1e-6]))[0])) / 2e-6
        assert b.derivative(np.array([z]))[0] == pytest.approx(d, rel=1e-5, abs=1e-6)


def particle(p):
    """The nonholonomic particle, declared valid for k <= 1.2 only (a user's model with a valid
    region: it refuses other values when built from numbers, as a model's own checks do)."""
    if not isinstance(p["k"], jax.core.Tracer) and float(p["k"]) > 1.2:
        raise InputError(f"k: this model is valid for k <= 1.2, got {float(p['k'])}")
    return gnipy.make_system("nonholonomic-particle", k=p["k"])


@pytest.fixture(scope="module")
def particle_data():
    """x and y of the particle with k = 1.5 (outside the model's valid region), every other node."""
    run = gnipy.simulate(gnipy.make_system("nonholonomic-particle", k=1.5), "gni-trapezoid", (1.0, 1.0, 0.0),
                         (1.0, 0.0, 1.0), h=H, steps=STEPS)
    return Observations(H * K, np.asarray(run.q)[K][:, :2], ("x", "y"))


def particle_fit(data, **kw):
    return fit(particle, data, params={"k": 1.0}, h=H, q0=(1.0, 1.0, 0.0), v0=(1.0, 0.0, 1.0),
               method="gni-trapezoid", **kw)


def test_a_fit_that_leaves_the_valid_region_is_flagged_not_raised(particle_data):
    """Without bounds the estimate is the data's k = 1.5, where the model refuses to be built: a
    flagged result with no fitted run, not an exception."""
    res = particle_fit(particle_data)
    assert res.params["k"] == pytest.approx(1.5, rel=1e-6)
    assert not res.success and res.solution is None and np.all(np.isnan(res.residuals))
    assert "not valid at the estimate (k = 1.5)" in res.message and "valid for k <= 1.2" in res.message
    assert "bounds=" in res.message and "the model" in res.summary()
    with pytest.raises(InputError, match="no fitted run"):
        gnipy.plots.plot_fit(res)


def test_an_estimate_pressed_against_its_bound_is_flagged(particle_data):
    """With k <= 1.2 the fit stays in the valid region and says that the data push beyond it."""
    res = particle_fit(particle_data, bounds={"k": (None, 1.2)})
    assert res.solution is not None and res.solution.success
    assert res.params["k"] <= 1.2 and res.params["k"] == pytest.approx(1.2, rel=1e-3)
    assert not res.success and res.at_bound == {"k": 1.2} and res.bounds == {"k": (-math.inf, 1.2)}
    assert "at a bound: k = 1.2" in res.message and "at its bound 1.2" in res.summary()
