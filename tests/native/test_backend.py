"""`simulate(..., backend=)`: the native loop gives the XLA loop's results to round-off (the
independent formulation: the same method compiled by XLA), on every method but the continuous
reference, on an affine model and a group model, and on one zoo model per other structure; which
backend runs, and why, is recorded; what the native loop does not do falls back to XLA with a
reason.

Why representatives suffice: the native loop lowers the step's jaxpr primitive by primitive. That
every primitive of every zoo model × method step has a lowering rule is checked without compiling
(tests/native/test_primitives.py), and each rule against NumPy or XLA (tests/native/test_lowering.py);
what a whole run adds is the loop, the method's state and control flow, and the configuration space,
so each method runs once (on the turning table: affine, R^n; the group methods on Suslov: SO(3)),
and each other structure once (ZOO_CASES), not every model × method (a compiled composition costs
about 10 s of CPU on XLA)"""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.errors import InputError
from gnipy.native.backend import NATIVE_MIN_STEPS

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

STEPS = 10_000


def _pair(system, method, **kw):
    a = gnipy.simulate(system, method, backend="xla", **kw)
    b = gnipy.simulate(system, method, backend="native", **kw)
    assert a.backend == "xla" and b.backend == "native"
    return a, b


#: The Solution's arrays both backends fill (the GNI family's node diagnostics are computed in the
#: native run's own program, and by a program of their own after an XLA run)
COMPARED = ("q", "v", "p", "energy", "R", "constraint_residual", "hidden_momentum", "hidden_expected", "energy_plus")


def _difference(a, b, names=COMPARED):
    """The largest difference between two runs' nodes, relative to max(1, the values' size)."""
    out = 0.0
    for name in names:
        x, y = getattr(a, name), getattr(b, name)
        if x is None or not np.size(x):
            continue
        x, y = np.asarray(x), np.asarray(y)
        out = max(out, float(np.max(np.abs(x - y))) / max(1.0, float(np.max(np.abs(x)))))
    return out


def _assert_agree_or_floor(system, method, a, b, **kw):
    """Native within 1e-12 of XLA, or — where the run amplifies round-off — within 10× of how far
    the XLA run itself moves when its initial condition changes by one unit in the last place."""
    err = _difference(a, b)
    if err <= 1e-12:
        return
    floor = 0.0
    for ulp in (1 + 2.0**-52, 1 - 2.0**-53):
        moved = gnipy.simulate(system, method, np.asarray(a.q[0]) * ulp, np.asarray(a.v[0]) * ulp, backend="xla",
                               project_v0=True, **kw)
        floor = max(floor, _difference(a, moved))
    assert err <= 10 * floor, (err, floor)


def _assert_agree(a, b, tol=1e-12):
    for name in COMPARED:
        x, y = getattr(a, name), getattr(b, name)
        if x is None:
            assert y is None
            continue
        x, y = np.asarray(x), np.asarray(y)
        assert x.shape == y.shape
        if not x.size:
            continue
        scale = max(1.0, float(np.max(np.abs(x))))
        err = float(np.max(np.abs(x - y))) / scale
        assert err <= tol, (name, err)
    np.testing.assert_array_equal(np.asarray(a.t), np.asarray(b.t))
    assert a.success and b.success


#: The structures the method tests below (the turning table: affine, R^n; Suslov: SO(3)) do not
#: cover, one zoo model each, with every default method: linear constraints on R^n (the Chaplygin
#: sleigh, with its default, Kahan–Li's composition of mp: the default of seven models), SE(2)
#: (the sleigh on SE(2), with its default, the discrete gradient), constraints that depend on the
#: orientation R on SO(3) (Veselova, with its default, Suzuki's composition of gni-trapezoid).
#: Constraints that depend on R on R² × SO(3), with an affine part: the Chaplygin sphere of
#: test_shortened_last_step_backward_run_states_and_continuation, with gni-trapezoid (its default,
#: Suzuki's composition of it, has the same primitives, tests/native/test_primitives.py, and takes
#: about 10 s of CPU to compile on XLA).
ZOO_CASES = [(model, gnipy.get_model(model).default_method)
             for model in ("chaplygin-sleigh", "chaplygin-sleigh-se2", "veselova")]
#: The methods on the turning table, one per step code: of methods whose steps are one code with
#: other constants, one runs here: gni-euler-a for gni-euler-b (the GNI's step with the mirror
#: discrete Lagrangian, explicit like it on this model), rattle for euler-a and euler-b
#: (paper_schemes._kick_drift_kick with another sign), and Yoshida's 3-stage composition of
#: gni-trapezoid for Suzuki's 5 stages (Composition.step with the same base and other
#: coefficients; Suzuki's runs on Veselova, Kahan–Li's of mp on the sleigh, ZOO_CASES). Not here:
#: the continuous reference (not run natively), and what runs on Suslov below (rat, sgni-midpoint).
AFFINE_METHODS = ["gni-euler-a", "gni-trapezoid", "gni-midpoint", "sgni-trapezoid", "euler-ab", "shake", "rattle",
                  "dla", "mp", "discrete-gradient", "yoshida4-gni-trapezoid"]
#: The methods on Suslov (SO(3)): those with a group step of their own (gni-trapezoid on a group
#: runs on the Chaplygin sphere, ZOO_CASES; the compositions' step does not depend on the space).
GROUP_METHODS = ["gni-midpoint", "sgni-midpoint", "dla", "discrete-gradient", "rat"]
#: The methods written for linear constraints on R^n only (they refuse the two models above): on the knife edge.
LINEAR_METHODS = ["sister"]
#: the methods whose step is another's with other constants (AFFINE_METHODS)
SAME_STEP_AS = {"gni-euler-b": "gni-euler-a", "euler-a": "rattle", "euler-b": "rattle"}


def test_the_cases_cover_every_method_every_default_and_every_structure():
    zoo_methods = {method for _, method in ZOO_CASES}
    run = set(AFFINE_METHODS) | set(GROUP_METHODS) | set(LINEAR_METHODS) | zoo_methods
    assert set(gnipy.method_names()) - {"reference"} == run | set(SAME_STEP_AS)
    assert set(SAME_STEP_AS.values()) <= run
    from gnipy.integrators.paper_schemes import _TildeScheme

    for method, stand_in in SAME_STEP_AS.items():  # one class (or two of the paper's tilde schemes), one base
        a, b = gnipy.get_method(method), gnipy.get_method(stand_in)
        assert type(a) is type(b) or isinstance(a, _TildeScheme) and isinstance(b, _TildeScheme), method
        assert type(getattr(a, "base", None)) is type(getattr(b, "base", None)), method
    assert {gnipy.get_model(m).default_method for m in gnipy.model_names()} <= run
    systems = [gnipy.make_system(m)
               for m in [m for m, _ in ZOO_CASES] + ["rotating-table-ball", "suslov", "chaplygin-sphere"]]
    kinds = {(type(s.group).__name__ if s.group is not None else "R^n", s.is_affine, s.depends_on_orientation)
             for s in systems}
    assert {("R^n", False, False), ("R^n", True, False), ("SE2", False, False), ("SO3", False, False),
            ("SO3", True, True), ("SO3", False, True)} <= kinds


@pytest.mark.slow
@pytest.mark.parametrize(("model", "method"), ZOO_CASES)
def test_zoo_structures_equal_xla(model, method):
    s = gnipy.make_system(model)
    kw = dict(h=0.01, steps=STEPS, save_every=1000)
    a, b = _pair(s, method, **kw)
    _assert_agree_or_floor(s, method, a, b, **kw)


@pytest.mark.parametrize("method", AFFINE_METHODS)
def test_methods_on_an_affine_model_equal_xla(method):
    s = gnipy.make_system("rotating-table-ball")
    a, b = _pair(s, method, h=0.01, steps=STEPS, save_every=2500)
    _assert_agree(a, b)


@pytest.mark.parametrize("method", GROUP_METHODS)
def test_methods_on_a_group_model_equal_xla(method):
    s = gnipy.make_system("suslov")
    kw = dict(h=0.01, steps=STEPS, save_every=2500)
    a, b = _pair(s, method, **kw)
    _assert_agree_or_floor(s, method, a, b, **kw)


@pytest.mark.parametrize("method", LINEAR_METHODS)
def test_methods_on_a_linear_model_equal_xla(method):
    s = gnipy.make_system("knife-edge")
    for other in ("rotating-table-ball", "suslov"):  # why they run here: the affine and the group model refuse them
        with pytest.raises(gnipy.MethodError):
            gnipy.simulate(gnipy.make_system(other), method, h=0.01, steps=2)
    # t <= 20: the sister method dissipates the energy, out of its band (a warning) from t = 25 on
    a, b = _pair(s, method, h=0.01, steps=2000, save_every=500)
    _assert_agree(a, b)


def _chain_lagrangian(q, v):
    # eight coupled pendulum angles, the metric depending on the neighbours' angles
    weight = 1.0 + 0.3 * jnp.cos(jnp.roll(q, 1))
    return 0.5 * jnp.sum(weight * v**2) + jnp.sum(jnp.cos(q))


def _chain_mu(q):
    # five rows v_j − ½ sin(q_{j+3}) v_{j+3}: full rank (unit pivots in columns 0..4)
    rows = [jnp.zeros(8).at[j].set(1.0).at[j + 3].add(-0.5 * jnp.sin(q[j + 3])) for j in range(5)]
    return jnp.stack(rows)


def test_a_step_with_more_unknowns_than_the_unrolled_inverse_equals_xla():
    """DLA on 8 coordinates with 5 constraints solves for 13 unknowns, above
    gnipy.linalg.UNROLL_MAX: the chord iteration factors its Jacobian (gnipy.linalg.lu_factor),
    substitutes at each iteration and keeps the factors from step to step (the Whipple bicycle's
    path); native and XLA agree."""
    from gnipy.linalg import LU_UNROLL_MAX, UNROLL_MAX

    assert UNROLL_MAX < 8 + 5 <= LU_UNROLL_MAX
    s = gnipy.System(_chain_lagrangian, _chain_mu, n=8, name="pendulum-chain")
    q0 = np.linspace(0.1, 0.8, 8)
    v0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.4, -0.3, 0.2])  # projected onto the constraints
    a, b = _pair(s, "dla", q0=q0, v0=v0, project_v0=True, h=0.01, steps=2000, save_every=500)
    _assert_agree(a, b)
    assert a.healthy and b.healthy
    # above 12 unknowns DLA keeps its Jacobian's factors and last solution in its state: a run
    # continued from a final state equals the run made at once, bit for bit, on both backends
    solver, h_solver, w, h_w = b.final_state.jacobian
    assert len(solver) == 3 and w.shape == (13,) and float(h_w) == 0.01
    for backend in ("native", "xla"):
        first = gnipy.simulate(s, "dla", q0=q0, v0=v0, project_v0=True, h=0.01, steps=1500, save_every=500,
                               backend=backend)
        rest = gnipy.simulate(s, "dla", h=0.01, steps=500, save_every=500, state0=first.final_state, t0=15.0,
                              backend=backend)
        whole = a if backend == "xla" else b
        np.testing.assert_array_equal(np.asarray(rest.q[-1]), np.asarray(whole.q[-1]))
        np.testing.assert_array_equal(np.asarray(rest.p[-1]), np.asarray(whole.p[-1]))


@pytest.mark.slow
def test_shortened_last_step_backward_run_states_and_continuation():
    s = gnipy.make_system("chaplygin-sphere")
    a, b = _pair(s, "gni-trapezoid", h=0.01, t_final=7.255, saveat=gnipy.SaveAt(every=100, states=True))
    _assert_agree(a, b)
    for x, y in zip(jax.tree_util.tree_leaves(a.states), jax.tree_util.tree_leaves(b.states)):
        np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=0, atol=1e-12)
    # back again (the symmetric method's exact inverse), from the native run's final state
    back = gnipy.simulate(s, "gni-trapezoid", h=-0.01, steps=725, state0=b.final_state, t0=7.25, backend="native",
                          save_every=725)
    back_x = gnipy.simulate(s, "gni-trapezoid", h=-0.01, steps=725, state0=b.final_state, t0=7.25, backend="xla",
                            save_every=725)
    _assert_agree(back_x, back)
    # a run continued from a state equals one run
    first = gnipy.simulate(s, "gni-trapezoid", h=0.01, steps=300, backend="native", save_every=300)
    rest = gnipy.simulate(s, "gni-trapezoid", h=0.01, steps=200, state0=first.final_state, t0=3.0, backend="native",
                          save_every=200)
    whole = gnipy.simulate(s, "gni-trapezoid", h=0.01, steps=500, backend="native", save_every=500)
    np.testing.assert_array_equal(np.asarray(rest.q[-1]), np.asarray(whole.q[-1]))


@pytest.mark.slow
def test_batch_of_initial_conditions_equals_xla_member_by_member():
    s = gnipy.make_system("rolling-ball")
    q0, v0 = (np.asarray(x, dtype=float) for x in s.defaults[:2])
    rng = np.random.default_rng(3)
    q = q0 + 0.05 * rng.standard_normal((11, q0.size))
    v = np.broadcast_to(v0, (11, v0.size))
    a, b = _pair(s, "gni-trapezoid", q0=q, v0=v, h=0.01, steps=3000, save_every=500, project_v0=True)
    _assert_agree(a, b)
    # each member gets the bits of its own single run (11 = 8 or 4 in vector lanes + the rest alone)
    for j in (0, 4, 10):
        single = gnipy.simulate(s, "gni-trapezoid", q[j], v[j], h=0.01, steps=3000, save_every=500, backend="native",
                                project_v0=True)
        np.testing.assert_array_equal(np.asarray(b.q[j]), np.asarray(single.q))
        np.testing.assert_array_equal(np.asarray(b.R[j]), np.asarray(single.R))


@pytest.mark.slow
def test_parameter_batch_is_one_program_equal_to_xla_and_to_single_runs():
    """A batch of systems (parameter values) runs native with the values as inputs of one program:
    equal to the XLA batch to round-off, and member by member the bits of each system's own
    single native run (whose values are constants in its program)."""
    from gnipy.native.backend import native_loop

    omegas = np.linspace(0.4, 1.6, 11)  # 11 = vector lanes (8 or 4) + members alone
    systems = gnipy.model_systems("rolling-ball", Omega=omegas)
    a = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=3000, save_every=500, backend="xla")
    b = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=3000, save_every=500, backend="native")
    assert a.backend == "xla" and b.backend == "native"
    _assert_agree(a, b)
    np.testing.assert_array_equal(np.asarray(b.member_params["Omega"]), omegas)
    for j in (0, 4, 10):
        single = gnipy.simulate(systems[j], "gni-trapezoid", h=0.01, steps=3000, save_every=500, backend="native")
        np.testing.assert_array_equal(np.asarray(b.q[j]), np.asarray(single.q))
        np.testing.assert_array_equal(np.asarray(b.R[j]), np.asarray(single.R))
        # the energy is observed on XLA, which compiles the two programs differently (values as
        # constants or as inputs): a few units in the last place
        np.testing.assert_allclose(np.asarray(b.energy[j]), np.asarray(single.energy), rtol=1e-14, atol=0)
    # one program for every value: other values of the same model reuse it
    state = b.final_state
    first = jax.tree_util.tree_map(lambda x: x[0], state)
    from gnipy.methods import get_method

    m = get_method("gni-trapezoid")
    one = native_loop(m, systems[0].without_metadata(), first, batch=True, params=True)
    other = native_loop(m, gnipy.model_systems("rolling-ball", Omega=[7.0])[0].without_metadata(), first, batch=True,
                        params=True)
    assert one is other
    assert native_loop(m, systems[0].without_metadata(), first, batch=True) is not one  # values as constants


def test_parameter_batch_with_a_failed_member():
    """A member that fails stops there (NaN after its failed step) on both backends, at the same step."""
    def lagrangian(c, q, v):  # V = log(c − x): undefined for x ≥ c, the force 1/(c − x) pushes x there
        return 0.5 * v @ v - jnp.log(c - q[0])

    def mu(q):
        return jnp.array([[0.0, 0.0, 1.0]])

    def wall(c):
        return gnipy.System(jax.tree_util.Partial(lagrangian, jnp.asarray(c)), mu, n=3, name="wall")

    systems = [wall(c) for c in (1e4, 1.0, 1e5)]
    out = []
    for backend in ("xla", "native"):
        sol = gnipy.simulate(systems, "gni-midpoint", [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=200, save_every=3,
                             throw=False, backend=backend)
        assert sol.backend == backend
        out.append(sol)
    a, b = out
    np.testing.assert_array_equal(np.asarray(a.failed_steps), np.asarray(b.failed_steps))
    assert int(b.failed_steps[1]) > 0 and int(b.failed_steps[0]) == -1
    np.testing.assert_allclose(np.asarray(b.q), np.asarray(a.q), rtol=0, atol=1e-12)
    assert np.all(np.isnan(np.asarray(b.q[1, -1])))


def _wall_system():
    # V = log(1 − x): undefined for x ≥ 1, and the force 1/(1 − x) pushes the particle there
    return gnipy.System(lambda q, v: 0.5 * v @ v - jnp.log1p(-q[0]), lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3,
                        name="wall")


def test_failed_step_is_the_same_on_both_backends():
    s = _wall_system()
    errs = []
    for backend in ("xla", "native"):
        with pytest.raises(gnipy.SolverFailure) as exc:
            gnipy.simulate(s, "gni-midpoint", [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=200, save_every=3,
                           backend=backend)
        errs.append(exc.value)
    assert errs[0].step == errs[1].step > 0
    assert errs[0].solution.q.shape == errs[1].solution.q.shape
    np.testing.assert_allclose(np.asarray(errs[1].solution.q), np.asarray(errs[0].solution.q), rtol=0, atol=1e-12)
    part = gnipy.simulate(s, "gni-midpoint", [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=200, throw=False,
                          backend="native")
    assert part.result == 1 and part.failed_step == errs[0].step and len(part.t) == part.failed_step + 1


@pytest.mark.slow
def test_auto_chooses_by_run_length_and_records_it():
    s = gnipy.make_system("vertical-disk")
    short = gnipy.simulate(s, "gni-midpoint", h=0.01, steps=100, save_every=100)
    assert short.backend == "xla"
    long = gnipy.simulate(s, "gni-midpoint", h=0.01, steps=NATIVE_MIN_STEPS, save_every=NATIVE_MIN_STEPS)
    assert long.backend == "native"
    # the choice depends on the run alone: a short run after a long one is on XLA again
    again = gnipy.simulate(s, "gni-midpoint", h=0.01, steps=100, save_every=100)
    assert again.backend == "xla"
    np.testing.assert_array_equal(np.asarray(again.q), np.asarray(short.q))
    # a batch counts its members' steps
    q = np.tile(np.asarray(short.q[0]), (NATIVE_MIN_STEPS // 100, 1))
    v = np.tile(np.asarray(short.v[0]), (NATIVE_MIN_STEPS // 100, 1))
    assert gnipy.simulate(s, "gni-midpoint", q, v, h=0.01, steps=100, save_every=100).backend == "native"
    # the Solution's files say it
    assert long.to_xarray().attrs["backend"] == "native"


def test_progress_is_reported_on_the_native_backend():
    seen = []
    s = gnipy.make_system("knife-edge")
    sol = gnipy.simulate(s, "gni-trapezoid", h=0.01, steps=5000, save_every=50, backend="native",
                         progress=lambda done, total: seen.append((done, total)))
    assert sol.backend == "native"
    assert len(seen) >= 10 and seen[-1] == (5000, 5000)
    assert all(a[0] <= b[0] for a, b in zip(seen, seen[1:]))
    ref = gnipy.simulate(s, "gni-trapezoid", h=0.01, steps=5000, save_every=50, backend="native")
    np.testing.assert_array_equal(np.asarray(sol.q), np.asarray(ref.q))


def test_what_runs_on_xla_says_why():
    s = gnipy.make_system("chaplygin-sleigh")
    forced = s.with_force(lambda q, v, u, t: jnp.array([0.0, 0.0, u[0]]), inputs=1)
    with pytest.warns(RuntimeWarning, match="forced"):
        sol = gnipy.simulate(forced, "gni-trapezoid", h=0.1, steps=10, controls=np.ones((10, 1)), backend="native")
    assert sol.backend == "xla"
    # a run traced by a JAX transformation (jax.jit here: jax.grad's trace takes the same way, and
    # costs five times the compilation)
    v0 = jnp.asarray(gnipy.get_model("chaplygin-sleigh").v0)
    with pytest.warns(RuntimeWarning, match="transformation"):
        q = jax.jit(lambda v0: gnipy.simulate(s, "gni-trapezoid", v0=v0, h=0.1, steps=5, backend="native").q)(v0)
    plain = gnipy.simulate(s, "gni-trapezoid", v0=v0, h=0.1, steps=5, backend="xla")
    np.testing.assert_allclose(np.asarray(q), np.asarray(plain.q), rtol=0, atol=1e-13)
    # a primitive the native lowering does not know: XLA runs, and the warning names it
    cum = gnipy.System(lambda q, v: 0.5 * v @ v - 0.5 * jnp.cumsum(q)[-1] ** 2, lambda q: jnp.array([[1.0, -1.0]]),
                       n=2, name="cumsum")
    with pytest.warns(RuntimeWarning, match="cumsum"):
        sol = gnipy.simulate(cum, "gni-trapezoid", [0.1, 0.2], [1.0, 1.0], h=0.1, steps=10, backend="native")
    assert sol.backend == "xla" and sol.success
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert gnipy.simulate(cum, "gni-trapezoid", [0.1, 0.2], [1.0, 1.0], h=0.1, steps=10).backend == "xla"


def test_bad_backend_is_named():
    s = gnipy.make_system("knife-edge")
    with pytest.raises(InputError, match="backend: expected one of 'auto', 'xla', 'native', got 'llvm'"):
        gnipy.simulate(s, h=0.1, steps=3, backend="llvm")
