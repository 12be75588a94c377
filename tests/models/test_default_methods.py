"""Each model's default method (gnipy.models.default_methods, chosen by
gnipy.experiments.method_choice) works on its model: it accepts the model, and a long run raises
no run-time warning and keeps the model's registered invariants (numbers from the invariants and the
continuous reference; the long runs on one model per structure, LONG_RUN_MODELS).
A system the atlas has not measured (a user's own System) gets the fallback, qualified on 16 of the 17
models (gnipy.registry.FALLBACK_METHOD), or the next of FALLBACK_METHODS that can run it."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import registry
from gnipy.experiments.method_choice import INVARIANT_TOL, registered_invariants_along
from gnipy.models.default_methods import DEFAULT_METHODS


def test_every_model_has_a_measured_default():
    """Every model's default is a method that accepts the model (its check), measured by the atlas."""
    assert set(DEFAULT_METHODS) == set(gnipy.model_names())
    for name, (method, reason) in DEFAULT_METHODS.items():
        assert method in gnipy.method_names(), name
        assert gnipy.get_model(name).default_method == method and "h = 0.01" in reason
        assert registry._can_run(method, gnipy.make_system(name)), (name, method)


#: The long runs: one model per structure the defaults meet, each default method on two of them.
#: R^n with linear constraints (the Chaplygin sleigh, where the GNI's hidden momentum fails) under
#: kahanli6-mp; a cyclic coordinate (the gauge particle, p_w) under suzuki4-gni-trapezoid; the
#: groups under the discrete gradient (the sleigh on SE(2), Suslov on SO(3)); affine constraints
#: (the turning table on R^n under kahanli6-mp, its Jacobi integral, speed and spin) and
#: constraints that depend on the orientation R (the Chaplygin sphere on R² × SO(3) under
#: suzuki4-gni-trapezoid: its Jacobi integral, M·γ, |M|²); the coasting differential-drive robot on
#: R^n under dla (its energy and φ − r(θ_R − θ_L)/2b). The models left out (the contact
#: oscillators, the knife edge, the nonholonomic particle, the vertical disk, the rolling disk, the
#: rolling ball, the Chaplygin top, Veselova) have the default method and the structure of one of these; each was
#: measured with its default by the atlas (h = 0.01, T = 1000: the reason in DEFAULT_METHODS), and
#: the default accepts it (test_every_model_has_a_measured_default). Each long run compiles its
#: own program (3-12 s of CPU with the every-node check that the verdicts need).
LONG_RUN_MODELS = ["chaplygin-sleigh", "nonholonomic-particle-gauge", "chaplygin-sleigh-se2", "suslov",
                   "rotating-table-ball", "chaplygin-sphere", "differential-drive"]


def test_the_long_runs_cover_every_default_method_and_structure():
    """The representatives of test_default_method_runs_long_without_warning: every default method
    that the zoo uses, on R^n and on a group, with and without affine constraints."""
    defaults = {gnipy.get_model(name).default_method for name in gnipy.model_names()}
    assert {gnipy.get_model(name).default_method for name in LONG_RUN_MODELS} == defaults
    systems = {name: gnipy.make_system(name) for name in LONG_RUN_MODELS}
    kinds = {(type(s.group).__name__ if s.group is not None else "R^n", s.is_affine) for s in systems.values()}
    assert {("R^n", False), ("R^n", True), ("SE2", False), ("SO3", False), ("SO3", True)} <= kinds
    assert any(s.depends_on_orientation for s in systems.values())


@pytest.mark.slow
@pytest.mark.parametrize("name", LONG_RUN_MODELS)
def test_default_method_runs_long_without_warning(name):
    spec = gnipy.get_model(name)
    params = spec.resolve_params()
    sol = gnipy.simulate(spec.system(), h=0.02, t_final=100.0, save_every=10)  # no method: the model's
    assert sol.method == spec.default_method
    assert sol.result == 0 and sol.warnings() == []
    for key, values in registered_invariants_along(spec, params, sol).items():
        if np.all(np.isfinite(values)):
            scale = max(float(np.max(np.abs(values))), 1e-6)  # as method_choice._drift
            assert np.max(np.abs(values - values[0])) / scale <= INVARIANT_TOL, key


def _own_sleigh(name="my-sleigh", metric=lambda q: 1.0):
    """The Chaplygin sleigh (m = I = 1, a = 0.5) written directly with gnipy.System, not via the zoo;
    `metric` scales ẋ² (1: the sleigh; a function of q: a metric that is not constant)."""
    return gnipy.System(
        lambda q, v: 0.5 * metric(q) * v[0] ** 2 + 0.5 * v[1] ** 2 + 0.5 * v[2] ** 2,
        lambda q: jnp.stack([-jnp.sin(q[2]), jnp.cos(q[2]), -0.5 * jnp.ones_like(q[2])])[None, :],
        coordinates=("x", "y", "theta"), name=name)


def test_own_system_without_method_runs_the_fallback_and_stays_qualified():
    """Issue 29 (4a): a hand-written sleigh given no method runs the fallback, which stays within
    1e-2 of the continuous reference over T = 200 at h = 0.01 (the atlas measured 1.3e-3) with its
    energy kept, where gni-trapezoid (the old fallback) leaves the reference (error 280) with a warning."""
    system = _own_sleigh()
    kw = dict(q0=(0.0, 0.0, 0.0), v0=(1.0, 0.5, 1.0), h=0.01, t_final=200.0, save_every=100)
    ref = gnipy.simulate(system, "reference", **kw)
    sol = gnipy.simulate(system, **kw)
    assert sol.method == registry.FALLBACK_METHOD == "sgni-trapezoid"
    assert sol.result == 0 and sol.warnings() == []
    np.testing.assert_allclose(np.asarray(sol.t), np.asarray(ref.t), rtol=0, atol=1e-9)
    E, E_ref = np.asarray(sol.energy), np.asarray(ref.energy)
    assert np.max(np.abs(E - E[0])) / np.max(np.abs(E_ref)) <= INVARIANT_TOL
    error = float(np.max(np.abs(np.asarray(sol.q) - np.asarray(ref.q))))
    assert error < 1e-2, error
    with warnings.catch_warnings():  # its hidden-momentum verdict (a warning where the run raises it)
        warnings.simplefilter("ignore")
        old = gnipy.simulate(system, "gni-trapezoid", throw=False, **kw)
    assert old.warnings() and float(np.max(np.abs(np.asarray(old.q) - np.asarray(ref.q)))) > 1.0


def test_default_method_passes_over_methods_that_cannot_run_the_system(monkeypatch):
    """With the System, default_method_for skips a candidate whose check refuses it: the zoo's
    default for a System named like a zoo model but not like it, and the fallbacks in order."""
    curved = _own_sleigh("chaplygin-sleigh", metric=lambda q: 1.0 + q[0] ** 2)  # kahanli6-mp: constant metric only
    assert registry.default_method_for("chaplygin-sleigh") == gnipy.get_model("chaplygin-sleigh").default_method
    assert registry.default_method_for("chaplygin-sleigh", gnipy.make_system("chaplygin-sleigh")) == "kahanli6-mp"
    assert registry.default_method_for("chaplygin-sleigh", curved) == registry.FALLBACK_METHOD
    assert registry.default_method_for("my-sleigh", _own_sleigh()) == registry.FALLBACK_METHOD
    suslov = gnipy.make_system("suslov")  # on SO(3): mp refuses it
    monkeypatch.setattr(registry, "FALLBACK_METHOD", "mp")
    monkeypatch.setattr(registry, "FALLBACK_METHODS", ("mp", "kahanli6-mp", "dla"))
    assert registry.default_method_for("my-suslov", suslov) == "dla"
    assert registry.default_method_for("my-suslov") == "mp"  # without the System: the first
    monkeypatch.setattr(registry, "FALLBACK_METHODS", ("mp",))
    assert registry.default_method_for("my-suslov", suslov) == "mp"  # none can: the first (the run says why)


def test_fallback_is_qualified_on_every_model():
    """The fallback and the methods after it apply to every zoo model (their check accepts each)."""
    for name in gnipy.model_names():
        system = gnipy.make_system(name)
        for method in registry.FALLBACK_METHODS:
            assert registry._can_run(method, system), (name, method)
