"""Runs backward in time (h < 0) and the exact reversibility of the symmetric methods.

A symmetric method's backward run is the exact inverse of its forward run
(gnipy.integrators.reversal): N steps forward and N back return to the start to round-off. The
round trips run forward and back through one compiled program each (h traced); the runs with a
negative h known in advance (the static Reversed) are checked on representatives further down.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.compilation import jit as gnipy_jit
from gnipy.integrators.reversal import Reversed

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

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


# the GNI on every kind of space, each by one of its two discrete Lagrangians (the reflection σ and
# the step's structure are the GNI's own, the l_d enters only through the step): the trapezoid on
# linear and affine constraints and on a group where l depends on R (chaplygin-top, where the
# midpoint is not symmetric), the midpoint on R^n and on a group where it is symmetric with the
# Cayley map (rolling-ball); the other methods on the first model they apply to. Of the
# compositions, which all run the same Composition.step (substeps, and for a GNI base the impulse
# rescaling of GNI.change_step, which does not depend on the discrete Lagrangian) with palindromic
# coefficients, one per kind of base: yoshida4-gni-trapezoid (a GNI) and kahanli6-mp (not a GNI).
# suzuki4-gni-trapezoid differs from the first only by its coefficients, yoshida4-gni-midpoint by a
# base whose own round trips are run here; their coefficients are checked to be palindromic in
# test_compositions_are_palindromic. Each pair compiles its own program (1-7 s on the 2-core machine),
# so the GNI meets linear constraints on R^n once (by the midpoint; the trapezoid on affine ones,
# which contain them with Y = 0), and of the SGNI, whose two members differ in the same way as the
# GNI's, sgni-trapezoid runs (sgni-midpoint's exact reversibility is also
# tests/integrators/test_gni_variants.py's, on three structures). Measured (noisy, the machine
# shared): 55 s before; the cases kept took 52 s of that run (72 s measured afterwards, loaded).
ROUND_TRIP_COMPOSITIONS = ("yoshida4-gni-trapezoid", "kahanli6-mp")
ROUND_TRIP_LEFT_OUT = ("sgni-midpoint",)
GNI_MODELS = {"gni-trapezoid": ("rotating-table-ball", "chaplygin-top"),
              "gni-midpoint": ("contact-oscillator", "rolling-ball")}
CASES = [(method, model) for method in _symmetric_methods()
         if method in ROUND_TRIP_COMPOSITIONS or not isinstance(gnipy.get_method(method), gnipy.Composition)
         if method not in ROUND_TRIP_LEFT_OUT
         for model in (GNI_MODELS[method] if method in GNI_MODELS else _applicable(method)[:1])]
#: the heavy top's GNI compiles for ~7 s: marked slow (`pytest -m "not slow"` skips it)
CASES = [pytest.param(*case, marks=pytest.mark.slow) if case[1] == "chaplygin-top" else case for case in CASES]


def test_the_symmetric_methods_are_the_expected_ones():
    names = set(_symmetric_methods())
    assert {"gni-trapezoid", "gni-midpoint", "mp", "rattle", "yoshida4-gni-trapezoid", "kahanli6-mp"} <= names
    assert {"suzuki4-gni-trapezoid", "yoshida4-gni-midpoint"} <= names
    assert set(GNI_MODELS) == {m for m in names if m.startswith("gni-")}
    for method, models in GNI_MODELS.items():  # the round trips' models are ones the method is symmetric on
        assert set(models) <= set(_applicable(method)), method
    for not_symmetric in ("gni-euler-a", "gni-euler-b", "euler-a", "euler-b", "dla", "shake"):
        assert not gnipy.get_method(not_symmetric).symmetric


def test_compositions_are_palindromic():
    """Every composition scheme's substep fractions are palindromic and sum to 1: a composition of a
    symmetric method with them is symmetric (Hairer–Lubich–Wanner §II.4), whence the round trips of
    one composition per kind of base suffice."""
    from gnipy.integrators import COMPOSITIONS

    assert set(COMPOSITIONS) >= {"yoshida4", "suzuki4", "yoshida6", "kahanli6"}
    for scheme, (_, gammas, _) in COMPOSITIONS.items():
        assert tuple(gammas) == tuple(reversed(gammas)), scheme
        assert abs(sum(gammas) - 1.0) <= 1e-15, scheme
    for name in _symmetric_methods():
        method = gnipy.get_method(name)
        if isinstance(method, gnipy.Composition):
            assert method.symmetric and method.base.symmetric, name


def _round_trip(model, method, h=0.05, n=100):
    """N steps forward and N back through one compiled program, from the method's own start at the
    model's default initial condition: h is traced (jax.jit), so simulate runs a symmetric method as
    Reversed(dynamic=True), its steps with h < 0 being σ∘Φ_{−h}∘σ — the same method.reverse and
    method.step as a run with a negative h known in advance (Reversed, the static wrapper, is run
    in test_plain_negative_step_of_the_gni_is_not_its_inverse and test_backward_run_follows_the_backward_flow)."""
    system = gnipy.make_system(model)
    q0, v0, *R0 = system.defaults
    b0, v0 = system.check(q0, v0, R0=R0[0] if R0 else None)
    m = gnipy.get_method(method).prepare(system, b0)
    core = system.without_metadata()
    h = np.float64(h)  # the same argument types both ways: one compiled program
    # gnipy's jit: its compiler options, as simulate's own programs (half the compile time of jax.jit)
    state0 = gnipy_jit(lambda b, v, h: m.init(core, b, v, h))(b0, np.asarray(v0, np.float64), h)
    run = gnipy_jit(lambda h, state, t0: gnipy.simulate(system, method, h=h, steps=n, state0=state, t0=t0,
                                                       saveat=gnipy.SaveAt(t0=True, t1=True, states=True)))
    fwd = run(h, state0, np.float64(0.0))
    back = run(-h, fwd.final_state, np.float64(fwd.t[-1]))
    return state0, fwd, back


@pytest.mark.parametrize("method,model", CASES)
def test_forward_then_back_returns_to_the_start(method, model):
    """100 steps forward and 100 back return to the start to round-off, the whole integrator state
    included: every symmetric method (one composition per kind of base, sgni-trapezoid for the SGNI,
    see CASES), the GNI on every kind of space."""
    start, fwd, back = _round_trip(model, method)
    assert float(fwd.t[-1]) == pytest.approx(5.0, abs=1e-12) and float(back.t[-1]) == pytest.approx(0.0, abs=1e-12)
    scale = max(1.0, float(np.max(np.abs(fwd.q[-1]), initial=0.0)))
    moved = [np.max(np.abs(fwd.q[-1] - fwd.q[0]), initial=0.0)] + ([] if fwd.R is None else [np.max(np.abs(fwd.R[-1] - fwd.R[0]))])
    assert max(moved) > 1e-3  # the test is not vacuous
    assert float(np.max(np.abs(back.q[-1] - fwd.q[0]))) <= 1e-12 * scale
    assert float(np.max(np.abs(back.v[-1] - fwd.v[0]))) <= 1e-12 * scale
    if fwd.R is not None:
        assert float(np.max(np.abs(back.R[-1] - fwd.R[0]))) <= 1e-12
    # the whole integrator state comes back, hidden impulse included
    for a, b, c in zip(jax.tree_util.tree_leaves(back.final_state), jax.tree_util.tree_leaves(fwd.states),
                       jax.tree_util.tree_leaves(start)):
        if a is not None and jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating):
            np.testing.assert_array_equal(np.asarray(b)[0], np.asarray(c))  # the saved start is state0
            assert float(np.max(np.abs(np.asarray(a) - np.asarray(b)[0]), initial=0.0)) <= 1e-12 * scale


def test_midpoint_with_cayley_on_an_orientation_dependent_system_is_not_symmetric():
    """The midpoint orientation R τ(σ/2) seen from the end, R τ(σ) τ(−σ/2), is another point for the
    Cayley retraction: where l depends on R (the heavy top's potential) the method says so, and a run
    with h < 0 is refused."""
    top = gnipy.make_system("chaplygin-top")
    m = gnipy.get_method("gni-midpoint")
    assert m.symmetric and top.depends_on_orientation and top.lagrangian_depends_on("orientation")
    assert m.symmetric_on(top) == (top.space.retraction.name == "exp")
    assert gnipy.get_method("gni-trapezoid").symmetric_on(top)
    with pytest.raises(gnipy.InputError, match=r"^h: .*'gni-midpoint' is not symmetric on 'chaplygin-top'"):
        gnipy.integrators.reversal.backward(m, -0.1, top)


# (model, method) pairs measured symmetric (N = 50 steps of h = 0.05 forward and back return to the
# start to 1e-15) that the parametrized test above does not reach: on SO(3) where only the constraints
# depend on R (the midpoint with Cayley is symmetric there); Euler A where l does not depend on the
# base point (every l_d is then h l(Δq/h)), here on SE(2); short runs, one compile each way
MEASURED_SYMMETRIC = [
    ("chaplygin-sphere", "gni-midpoint"),
    ("chaplygin-sleigh-se2", "gni-euler-a"),
]
# and measured not symmetric: the step at -h (conjugated by σ) misses the start by 0.02 to 3
# (chaplygin-top with gni-midpoint: 9e-5, l depends on R through the potential)
MEASURED_NOT_SYMMETRIC = [
    ("chaplygin-top", "gni-midpoint"),
    ("contact-oscillator", "gni-euler-a"),
    ("contact-oscillator", "euler-a"),
    ("contact-oscillator", "euler-ab"),
    ("contact-oscillator", "dla"),
    ("contact-oscillator", "shake"),
]


def _round_trip_miss(model, method, n=20):
    """N steps forward and N back through one compiled program (:func:`_round_trip`, the way back as
    Reversed(dynamic=True)) from the method's start: the distance of (q, v, R) from the start, and
    how far R moved."""
    _, fwd, back = _round_trip(model, method, n=n)
    miss = [np.max(np.abs(back.q[-1] - fwd.q[0]), initial=0.0), np.max(np.abs(back.v[-1] - fwd.v[0])),
            np.max(np.abs(back.R[-1] - fwd.R[0]))]
    return float(max(miss)), float(np.max(np.abs(fwd.R[-1] - fwd.R[0])))


def test_symmetric_on_agrees_with_the_measurement():
    """symmetric_on (no runs) says what the measured round trips say, on the cases it was fixed for."""
    for model, method in MEASURED_SYMMETRIC:
        assert gnipy.get_method(method).symmetric_on(gnipy.make_system(model)), (model, method)
    for model, method in MEASURED_NOT_SYMMETRIC:
        assert not gnipy.get_method(method).symmetric_on(gnipy.make_system(model)), (model, method)
    sphere = gnipy.make_system("chaplygin-sphere")
    assert sphere.depends_on_orientation and not sphere.lagrangian_depends_on("orientation")
    assert sphere.space.retraction.name == "cayley" and sphere.lagrangian_depends_on("configuration") is False
    for method in ("sgni-midpoint", "yoshida4-gni-midpoint"):  # the same l_d
        assert gnipy.get_method(method).symmetric_on(sphere)
    assert gnipy.get_method("gni-midpoint").symmetric_on(gnipy.make_system("veselova"))  # its constraints only
    sleigh = gnipy.make_system("chaplygin-sleigh")
    for method in ("gni-euler-a", "gni-euler-b", "euler-a", "euler-b", "euler-ab"):  # l = ½vᵀMv, M constant
        assert gnipy.get_method(method).symmetric_on(sleigh)
    assert not gnipy.get_method("gni-euler-a").symmetric  # in general it is not


@pytest.mark.parametrize("model,method", MEASURED_SYMMETRIC)
def test_measured_symmetric_pairs_return_to_the_start(model, method):
    miss, moved = _round_trip_miss(model, method)
    assert miss <= 1e-11 and moved > 0.1


def test_h_negative_refused_for_a_method_not_symmetric_on_the_system():
    """simulate refuses h < 0 before compiling anything, naming h, the method, the system, why, and
    the methods symmetric there."""
    top = gnipy.make_system("chaplygin-top")
    with pytest.raises(gnipy.InputError) as e:
        gnipy.simulate(top, "gni-midpoint", h=-0.05, steps=10)
    msg = str(e.value)
    assert msg.startswith("h: ") and "'gni-midpoint'" in msg and "'chaplygin-top'" in msg and "not symmetric" in msg
    listed = msg.split("exact inverse: ")[1]
    assert "gni-trapezoid" in listed and "sgni-trapezoid" in listed and "gni-midpoint," not in listed
    assert gnipy.integrators.reversal.symmetric_methods(top) == [
        "gni-trapezoid", "sgni-trapezoid", "yoshida4-gni-trapezoid", "suzuki4-gni-trapezoid"]
    oscillator = gnipy.make_system("contact-oscillator")
    for method in ("gni-euler-a", "euler-a", "dla"):
        with pytest.raises(gnipy.InputError, match=rf"^h: .*'{method}' is not symmetric on 'contact-oscillator'.*"
                                                   r"exact inverse: gni-trapezoid, gni-midpoint, .*\bmp\b"):
            gnipy.simulate(oscillator, method, h=-0.05, t_final=-1.0)
    # a state continued backward is refused the same way
    with pytest.raises(gnipy.InputError, match="^h: "):
        gnipy.integrators.reversal.backward(gnipy.get_method("gni-euler-a"), -0.05, oscillator)
    # where it is symmetric (l does not depend on the base point) it runs its inverse
    assert isinstance(gnipy.integrators.reversal.backward(gnipy.get_method("gni-euler-a"), -0.05,
                                                          gnipy.make_system("chaplygin-sleigh")), Reversed)
    reference = gnipy.get_method("reference")  # integrates backward itself
    assert gnipy.integrators.reversal.backward(reference, -0.05, oscillator) is reference


def test_plain_negative_step_of_the_gni_is_not_its_inverse():
    """Without the reflection σ the backward steps start from the wrong impulse (why Reversed exists)."""
    system = gnipy.make_system("contact-oscillator")
    m = gnipy.get_method("gni-trapezoid")
    fwd = gnipy.simulate(system, m, h=0.05, steps=100, saveat=gnipy.SaveAt(t1=True))
    run = gnipy_jit(lambda s: jax.lax.scan(lambda c, _: (m.step(system.without_metadata(), c, -0.05)[0], None), s,
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
    for method in ("gni-midpoint", "mp"):
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
    with pytest.raises(gnipy.InputError, match="^h: .*'dla' is not symmetric"):
        gnipy.integrators.reversal.backward(gnipy.get_method("dla"), -0.1)


def test_traced_negative_step_of_a_method_not_symmetric_fails_at_run_time():
    """A traced h's sign is known only in the compiled program: a method that is not symmetric runs
    forward (h > 0) and its steps fail when h < 0 (ForwardOnly), as a forced system's do."""
    system = gnipy.make_system("contact-oscillator")
    q0, v0 = jnp.array([1.0, 1.0, 1.0]), jnp.array([-1.0, 1.0, 1.0])

    @jax.jit
    def run(h, q0, v0):
        return gnipy.simulate(system, "dla", q0, v0, h=h, steps=5, saveat=gnipy.SaveAt(t1=True)).q[-1]

    q = np.asarray(run(0.05, q0, v0))
    assert np.all(np.isfinite(q)) and np.max(np.abs(q - np.asarray(q0))) > 1e-3
    with pytest.raises(Exception, match="step failed"):
        jax.block_until_ready(run(-0.05, q0, v0))
