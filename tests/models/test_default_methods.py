"""Each model's default method (gnipy.models.default_methods, chosen by
gnipy.experiments.method_choice) works on its model: a long run raises no run-time warning and
keeps the model's registered invariants (numbers from the invariants and the continuous reference)."""

import numpy as np
import pytest

import gnipy
from gnipy.experiments.method_choice import INVARIANT_TOL, _invariant_values
from gnipy.models.default_methods import DEFAULT_METHODS


def test_every_model_has_a_measured_default():
    assert set(DEFAULT_METHODS) == set(gnipy.model_names())
    for name, (method, reason) in DEFAULT_METHODS.items():
        assert method in gnipy.method_names(), name
        assert gnipy.get_model(name).default_method == method and "h = 0.01" in reason


@pytest.mark.parametrize("name", gnipy.model_names())
def test_default_method_runs_long_without_warning(name):
    spec = gnipy.get_model(name)
    params = spec.resolve_params()
    sol = gnipy.simulate(spec.system(), h=0.02, t_final=100.0, save_every=10)  # no method: the model's
    assert sol.method == spec.default_method
    assert sol.result == 0 and sol.warnings() == []
    for key, values in _invariant_values(spec, params, sol).items():
        if np.all(np.isfinite(values)):
            scale = max(float(np.max(np.abs(values))), 1e-6)  # as method_choice._drift
            assert np.max(np.abs(values - values[0])) / scale <= INVARIANT_TOL, key
