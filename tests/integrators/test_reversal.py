"""Runs backward in time (h < 0) and the exact reversibility of the symmetric methods.

A symmetric method's backward run is the exact inverse of its forward run
(gnipy.integrators.reversal): N steps forward and N back return to the start to round-off.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.integrators.reversal import Reversed

# one model per kind of space: linear constraints on R^n, affine constraints, a group R^n x G
MODELS = ("contact-oscillator", "rotating-table-ball", "rolling-ball", "chaplygin-top")
EXTRA = ("yoshida4-gni-midpoint",)  # compositions reached by name only


def _symmetric_methods():
    names = [m for m in gnipy.method_names() if m != "reference" and gnipy.get_method(m).symmetric]
    assert {"sgni-trapezoid", "sgni-midpoint"} <= set(names)
    return names + list(EXTRA)


def _applicable(method):
    m = gnipy.get_method(method)
    out = []
    for model in MODELS:
        spec = gnipy.get_model(model)
        try:
            m.check(spec.system(), np.asarray(spec.q0))
        except gnipy.MethodError:
            continue
        if not m.symmetric_on(spec.system()):
            continue
        out.append(model)
    return out


# the GNI on every kind of space; the other methods (and the compositions, whose substeps are the
# same steps) on the first model they apply to
CASES = [(method, model) for method in _symmetric_methods()
         for model in (_applicable(method) if method.startswith("gni-") else _applicable(method)[:1])]


def test_the_symmetric_methods_are_the_expected_ones():
    names = set(_symmetric_methods())
    assert {"gni-trapezoid", "gni-midpoint", "mp", "rattle", "yoshida4-gni-trapezoid", "kahanli6-mp"} <= names
    for not_symmetric in ("gni-euler-a", "gni-euler-b", "euler-a", "euler-b", "dla", "shake"):
        assert not gnipy.get_method(not_symmetric).symmetric


@pytest.mark.parametrize("method,model", CASES)
def test_forward_then_back_returns_to_the_start(method, model):
    system = gnipy.make_system(model)
    h, n = 0.05, 100
    fwd = gnipy.simulate(system, method, h=h, steps=n, saveat=gnipy.SaveAt(t0=True, t1=True, states=True))
    start = fwd
    back = gnipy.simulate(system, method, h=-h, steps=n, state0=fwd.final_state, t0=float(fwd.t[-1]),
                          saveat=gnipy.SaveAt(t1=True))
    assert float(back.t[-1]) == pytest.approx(0.0, abs=1e-12)
    scale = max(1.0, float(np.max(np.abs(fwd.q[-1]))))
    assert float(np.max(np.abs(back.q[-1] - start.q[0]))) <= 1e-12 * scale
    assert float(np.max(np.abs(back.v[-1] - start.v[0]))) <= 1e-12 * scale
    if start.R is not None:
        assert float(np.max(np.abs(back.R[-1] - start.R[0]))) <= 1e-12
    # the whole integrator state comes back, hidden impulse included
    for a, b in zip(jax.tree_util.tree_leaves(back.final_state), jax.tree_util.tree_leaves(start.states)):
        if a is not None and jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating):
            assert float(np.max(np.abs(np.asarray(a) - np.asarray(b)[0]))) <= 1e-12 * scale


def test_midpoint_with_cayley_on_an_orientation_dependent_system_is_not_symmetric():
    """The midpoint orientation R τ(σ/2) seen from the end, R τ(σ) τ(−σ/2), is another point for the
    Cayley retraction: the method says so, and a backward run is then the method at −h."""
    top = gnipy.make_system("chaplygin-top")
    m = gnipy.get_method("gni-midpoint")
    assert m.symmetric and top.depends_on_orientation
    assert m.symmetric_on(top) == (top.space.retraction.name == "exp")
    assert gnipy.get_method("gni-trapezoid").symmetric_on(top)
    assert not isinstance(gnipy.integrators.reversal.backward(m, -0.1, top), Reversed) or m.symmetric_on(top)


def test_plain_negative_step_of_the_gni_is_not_its_inverse():
    """Without the reflection σ the backward steps start from the wrong impulse (why Reversed exists)."""
    system = gnipy.make_system("contact-oscillator")
    m = gnipy.get_method("gni-trapezoid")
    fwd = gnipy.simulate(system, m, h=0.05, steps=100, saveat=gnipy.SaveAt(t1=True))
    run = jax.jit(lambda s: jax.lax.scan(lambda c, _: (m.step(system.without_metadata(), c, -0.05)[0], None), s,
                                          None, length=100)[0])
    plain = run(fwd.final_state)
    exact = gnipy.simulate(system, m, h=-0.05, steps=100, state0=fwd.final_state, t0=5.0, saveat=gnipy.SaveAt(t1=True))
    q0 = np.array(gnipy.get_model("contact-oscillator").q0)
    assert float(np.max(np.abs(np.asarray(plain.b) - q0))) > 1e-6
    assert float(np.max(np.abs(np.asarray(exact.q[-1]) - q0))) < 1e-12


def test_backward_run_follows_the_backward_flow():
    """Against the continuous reference run backward: order 2 for gni-midpoint and mp."""
    system = gnipy.make_system("contact-oscillator")
    ref = gnipy.simulate(system, "reference", h=-0.25, t_final=-1.0, saveat=gnipy.SaveAt(t1=True))
    for method in ("gni-midpoint", "mp", "euler-a"):
        errs = []
        for h in (0.02, 0.01):
            sol = gnipy.simulate(system, method, h=-h, t_final=-1.0, saveat=gnipy.SaveAt(t1=True))
            assert float(sol.t[-1]) == pytest.approx(-1.0, abs=1e-14)
            errs.append(float(np.max(np.abs(sol.q[-1] - ref.q[-1]))))
        order = np.log2(errs[0] / errs[1])
        assert abs(order - gnipy.get_method(method).order) < 0.25, (method, errs)


def test_backward_saveat_times_and_errors():
    system = gnipy.make_system("contact-oscillator")
    sol = gnipy.simulate(system, "gni-trapezoid", h=-0.1, t_final=-1.0, saveat=gnipy.SaveAt(ts=[-0.5, -1.0]))
    np.testing.assert_allclose(np.asarray(sol.t), [-0.5, -1.0], atol=1e-14)
    with pytest.raises(gnipy.InputError, match="t_final: must be before t0"):
        gnipy.simulate(system, "gni-trapezoid", h=-0.1, t_final=1.0)
    with pytest.raises(gnipy.InputError, match="t_final: must be after t0"):
        gnipy.simulate(system, "gni-trapezoid", h=0.1, t_final=-1.0)
    with pytest.raises(gnipy.InputError, match="h: must be nonzero"):
        gnipy.simulate(system, "gni-trapezoid", h=0.0, steps=3)
    with pytest.raises(gnipy.InputError, match="outside the run"):
        gnipy.simulate(system, "gni-trapezoid", h=-0.1, t_final=-1.0, saveat=gnipy.SaveAt(ts=[0.5]))


def test_traced_negative_step_decides_at_run_time():
    """Under jax.jit h is traced: the sign is decided in the compiled program, with the same result."""
    system = gnipy.make_system("contact-oscillator")
    q0, v0 = jnp.array([1.0, 1.0, 1.0]), jnp.array([-1.0, 1.0, 1.0])
    fwd = gnipy.simulate(system, "gni-midpoint", q0, v0, h=0.05, steps=40, saveat=gnipy.SaveAt(t1=True))

    @jax.jit
    def back(h):
        return gnipy.simulate(system, "gni-midpoint", h=h, steps=40, state0=fwd.final_state,
                              saveat=gnipy.SaveAt(t1=True)).q[-1]

    np.testing.assert_allclose(np.asarray(back(-0.05)), np.asarray(q0), atol=1e-12)
    assert isinstance(gnipy.integrators.reversal.backward(gnipy.get_method("mp"), -0.1), Reversed)
    assert not isinstance(gnipy.integrators.reversal.backward(gnipy.get_method("dla"), -0.1), Reversed)
