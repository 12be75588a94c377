"""The hand-written Numba GNI steps (benchmarks/numba_gni.py) compute what numpy_gni and gnipy compute.

numba_gni is the speed limit of the native-backend benchmark (issue 16); here it is only checked
for agreement, never timed: 1000 steps at h = 0.01 against numpy_gni (the same formulas, SciPy's
root finder) and against gnipy itself (the paper's start p⁺₀ = p̄₀, as numpy_gni; the composition
starts consistently, as gnipy's compositions always do), the batched (prange) runs against the
single-trajectory runs member by member. Both generations are checked: the current kernels
(`CASES`, issue 35) and the first version kept as the old baseline (`LEGACY_CASES`), and the
current kernels' three solvers against each other and against the first version (the same scheme:
they must agree to round-off). The two cases added for issue 35 point 2 (yoshida4-gni-trapezoid
on the rolling ball ex. 2, sgni-trapezoid on Suslov's problem) have no first version and no
numpy_gni version: they are checked against gnipy (start state and final node) and their solvers
against each other.

Tolerances (relative, max over the node's q, v, p, R after 1000 steps): gnipy 1e-12 (measured:
≤ 1.6e-14 for the current kernels of the first three cases, ≤ 5.5e-14 for the first version,
6.5e-15 for the composition and 4.3e-15 for Suslov); numpy_gni 1e-11 (measured ≤ 8.7e-13:
numpy_gni's own round-off, SciPy's `root` stops at a relative tolerance of 1e-12); the solvers and
versions between themselves 1e-13 (measured ≤ 7e-15).
"""

import functools
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

import gnipy  # noqa: E402
from gnipy.experiments.particle_study import paper_method  # noqa: E402
from gnipy.models.rolling_ball import example_2  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ is not installed

from benchmarks import numba_gni, numpy_gni  # noqa: E402

H, STEPS = 0.01, 1000
NAMES = list(numba_gni.CASES)
#: the cases with a first version (and a numpy_gni version): the first three
LEGACY_NAMES = list(numba_gni.LEGACY_CASES)
#: the cases added after the first version (issue 35 point 2): the composition and Suslov
NEW_NAMES = [name for name in NAMES if name not in numba_gni.LEGACY_CASES]
VERSIONS = {"v2": numba_gni.CASES, "v1": numba_gni.LEGACY_CASES}
#: (name, version) of every kernel
KERNELS = [(name, version) for version, cases in VERSIONS.items() for name in cases]
NUMPY_KERNELS = [(n, v) for n, v in KERNELS if VERSIONS[v][n].numpy_case is not None]
GNIPY_TOL, NUMPY_TOL, ROUNDOFF_TOL = 1e-12, 1e-11, 1e-13


def _rel(a, b):
    """Largest absolute difference relative to the size of the reference array `b`."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def _gnipy_case(name):
    """(system, q0, v0, R0) of gnipy's model for a case (as in test_benchmark_baselines.py)."""
    if name in ("rolling-ball-ex2", "rolling-ball-ex2-yoshida4"):
        system, q0, v0 = example_2()
        return system, q0, v0, None
    spec = gnipy.get_model(name)
    q0, v0 = spec.initial_condition(spec.params)
    return spec.system(), q0, v0, spec.R0


#: the general kernels of each case: (run, batch, run of the first version, its batch)
_GENERAL = {
    "rolling-ball-ex2": (numba_gni.run_ball, numba_gni.run_ball_batch, numba_gni.run_ball_v1,
                         numba_gni.run_ball_batch_v1),
    "chaplygin-sphere": (numba_gni.run_ball, numba_gni.run_ball_batch, numba_gni.run_ball_v1,
                         numba_gni.run_ball_batch_v1),
    "contact-oscillator": (numba_gni.run_oscillator, numba_gni.run_oscillator_batch, numba_gni.run_oscillator_v1,
                           numba_gni.run_oscillator_batch_v1),
    "rolling-ball-ex2-yoshida4": (numba_gni.run_ball_yoshida4, numba_gni.run_ball_yoshida4_batch, None, None),
    "suslov": (numba_gni.run_suslov_general, numba_gni.run_suslov_general_batch, None, None),
}


@functools.lru_cache(maxsize=None)
def _final(version, name):
    """numba_gni's final node after STEPS steps (the version's kernel)."""
    case = VERSIONS[version][name]
    return case.observe(case.run(case.initial_state(H), H, STEPS))


@functools.lru_cache(maxsize=None)
def _numpy_ref(name):
    case = numba_gni.CASES[name]
    return numpy_gni.run(case.numpy_case, STEPS, H, method=case.method)


@functools.lru_cache(maxsize=None)
def _gnipy_ref(name):
    # paper_method: a GNI from rest, as numpy_gni; the composition and sgni are returned as they are
    # (a composition always starts consistently; sgni has no hidden impulse)
    case = numba_gni.CASES[name]
    system, q0, v0, R0 = _gnipy_case(name)
    return gnipy.simulate(system, paper_method(case.method), q0, v0, R0=R0, h=H, steps=STEPS, save_every=STEPS)


def _gnipy_start(name, h):
    """gnipy's own start state (method.init) of a case, flattened as numba_gni's states."""
    import jax.numpy as jnp

    from gnipy.methods import get_method
    from gnipy.preparation import prepare

    system, q0, v0, _ = _gnipy_case(name)
    q0 = np.asarray(q0 if q0 is not None else system.defaults[0], dtype=float)
    v0 = np.asarray(v0 if v0 is not None else system.defaults[1], dtype=float)
    prep = prepare(system, get_method(numba_gni.CASES[name].method), q0, v0, None, False, None)
    st = prep.method.init(prep.core, prep.b0, jnp.asarray(prep.v0), h)
    b, p = st[0], st[1]
    return np.concatenate([np.ravel(b.x), np.ravel(b.R), np.ravel(p)])


@pytest.mark.parametrize("name,version", NUMPY_KERNELS)
def test_initial_state_matches_numpy_gni(name, version):
    case = VERSIONS[version][name]
    state = numpy_gni.get_case(case.numpy_case, case.method).initial_state()
    flat = np.concatenate([np.ravel(a) for a in state])
    np.testing.assert_array_equal(case.initial_state(), flat)


@pytest.mark.parametrize("h", [H, 0.05])
@pytest.mark.parametrize("name", NEW_NAMES)
def test_initial_state_matches_gnipy(name, h):
    # the composition starts with gnipy's consistent impulse for its first substep γ₁h (closed form
    # in numba_gni; measured ≤ 3e-19 absolute, ≤ 5e-16 of the impulse); Suslov with I Ω₀, which
    # gnipy's sgni projects on the constraint (a no-op up to its rounding: 1 ulp of p̄₀ measured)
    ours, theirs = numba_gni.CASES[name].initial_state(h), _gnipy_start(name, h)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-15 * np.max(np.abs(theirs)))
    if name == "rolling-ball-ex2-yoshida4":
        assert np.any(ours != numba_gni.CASES["rolling-ball-ex2"].initial_state())  # p⁺₀ ≠ p̄₀
        hidden = ours[11:] - numba_gni.CASES["rolling-ball-ex2"].initial_state()[11:]
        assert np.max(np.abs(hidden)) > 1e-2 * h  # O(h): the consistent impulse is really there


@pytest.mark.parametrize("name,version", NUMPY_KERNELS)
def test_matches_numpy_gni(name, version):
    ref = _numpy_ref(name)
    ours = _final(version, name)
    for key in ("q", "v", "p"):
        assert _rel(ours[key], ref[key]) <= NUMPY_TOL, key
    if ref["R"] is None:
        assert ours["R"] is None
    else:
        assert _rel(ours["R"], ref["R"]) <= NUMPY_TOL
        np.testing.assert_allclose(ours["R"] @ ours["R"].T, np.eye(3), atol=1e-13)  # Cayley keeps R in SO(3)


@pytest.mark.parametrize("name,version", KERNELS)
def test_matches_gnipy(name, version):
    sol = _gnipy_ref(name)
    ours = _final(version, name)
    for key in ("q", "v", "p"):
        theirs = getattr(sol, key)[-1]
        if np.size(theirs) == 0:  # Suslov has no coordinates x
            assert np.shape(ours[key]) == np.shape(theirs), key
            continue
        assert _rel(ours[key], theirs) <= GNIPY_TOL, key
    if sol.R is not None:
        assert _rel(ours["R"], sol.R[-1]) <= GNIPY_TOL
        np.testing.assert_allclose(ours["R"] @ ours["R"].T, np.eye(3), atol=1e-13)


def test_suslov_keeps_its_constraint():
    # sgni: p̄_{k+1} is on ⟨a, I⁻¹p̄⟩ = 0 at every node (the step restores it, round-off included)
    ours = _final("v2", "suslov")
    assert abs(ours["v"][2]) <= 1e-15 * np.max(np.abs(ours["v"]))  # a = e3


@pytest.mark.parametrize("name", NAMES)
def test_solvers_and_versions_agree_to_roundoff(name):
    # the same scheme solved three ways (and by the first version, to 1e-14, where there is one):
    # the same trajectory up to round-off, so the stopping rules stop at round-off
    case = numba_gni.CASES[name]
    s0 = case.initial_state(H)
    finals = {solver: numba_gni.count_iterations(name, H, STEPS, solver=solver)[1] for solver in numba_gni.SOLVERS}
    legacy = numba_gni.get_case(name, legacy=True)
    ref = finals["newton"] if legacy is None else legacy.run(s0, H, STEPS)
    for solver, out in finals.items():
        assert np.all(np.isfinite(out)), solver
        assert _rel(out, ref) <= ROUNDOFF_TOL, solver
    # the case's run is the general kernel with the case's solver, bit for bit
    np.testing.assert_array_equal(case.run(s0, H, STEPS), finals[numba_gni.CASE_SOLVER[name]])


@pytest.mark.parametrize("name", LEGACY_NAMES)
def test_iteration_counts(name):
    # issue 35: the current kernels stop one iteration earlier than the first version (which
    # iterated until the increment was 1e-14, one iteration past convergence); deterministic
    # (IEEE arithmetic), so the measured means are pinned loosely
    mean = {s: numba_gni.count_iterations(name, H, STEPS, solver=s)[0] for s in numba_gni.SOLVERS}
    legacy, final = numba_gni.count_iterations(name, H, STEPS, legacy=True)
    np.testing.assert_array_equal(
        final, numba_gni.LEGACY_CASES[name].run(numba_gni.CASES[name].initial_state(), H, STEPS)
    )
    assert 2.7 <= legacy <= 3.0
    assert 2.0 <= mean["newton"] <= 2.1  # Newton: one iteration to converge, one to see it
    assert 2.0 <= mean["chord"] <= 3.0  # the chord needs at least two (θ from two increments)
    assert 1.0 <= mean["predicted-newton"] <= mean["newton"]
    assert mean[numba_gni.CASE_SOLVER[name]] <= legacy - 0.5
    if name == "rolling-ball-ex2":
        assert mean["predicted-newton"] == 1.0  # the sweeps leave one Newton iteration at h = 0.01
    with pytest.raises(ValueError, match="solver"):
        numba_gni.count_iterations(name, H, 10, solver="broyden")


@pytest.mark.parametrize("name", NEW_NAMES)
def test_iteration_counts_of_the_new_cases(name):
    # per step: the composition's three substeps summed (as gnipy counts them), so three times a
    # step's (measured: newton 6.0, chord 7.7, predicted-newton 3.0; Suslov 2.0, 2.004, 1.0)
    k = 3 if name == "rolling-ball-ex2-yoshida4" else 1
    mean = {s: numba_gni.count_iterations(name, H, STEPS, solver=s)[0] for s in numba_gni.SOLVERS}
    assert 2.0 * k <= mean["newton"] <= 2.1 * k
    assert 2.0 * k <= mean["chord"] <= 3.0 * k
    assert mean["predicted-newton"] == 1.0 * k
    with pytest.raises(ValueError, match="first version"):
        numba_gni.count_iterations(name, H, 10, legacy=True)
    with pytest.raises(ValueError, match="solver"):
        numba_gni.count_iterations(name, H, 10, solver="broyden")


def _perturbed_states(case, rng, members=5):
    """`members` start states near the case's: positions and momenta perturbed (not R, which must
    stay a rotation); Suslov's Ω in the constraint plane ⟨e3, Ω⟩ = 0, p̄ = IΩ."""
    s0 = case.initial_state(H)
    states = np.tile(s0, (members, 1))
    if case.name == "suslov":
        omega = np.tile(numba_gni._SUSLOV_V0, (members - 1, 1))
        omega[:, :2] += 0.05 * rng.standard_normal((members - 1, 2))
        A00, A11, A22, A01, A02, A12 = numba_gni.SUSLOV_PARAMS[:6]
        inertia = np.array([[A00, A01, A02], [A01, A11, A12], [A02, A12, A22]])
        states[1:, 9:] = omega @ inertia
        return states
    cols = [0, 1, 11, 12, 13, 14, 15] if case.size == 16 else list(range(6))
    states[1:, cols] += 0.05 * rng.standard_normal((members - 1, len(cols)))
    return states


@pytest.mark.parametrize("name,version", KERNELS)
def test_batch_equals_single_runs(name, version):
    case = VERSIONS[version][name]
    states = _perturbed_states(case, np.random.default_rng(16))
    batch = case.run_batch(states, H, 200)
    assert batch.shape == states.shape
    for i in range(len(states)):
        single = case.run(states[i], H, 200)
        assert np.all(np.isfinite(single))
        np.testing.assert_allclose(batch[i], single, rtol=0, atol=1e-14 * np.max(np.abs(single)))
    assert np.any(batch[1] != batch[0])  # the members are different trajectories


@pytest.mark.parametrize("name,version", KERNELS)
def test_failed_newton_gives_nan(name, version):
    # a NaN start cannot meet Newton's stopping test: the step reports failure as NaN, never silently
    case = VERSIONS[version][name]
    out = case.run(np.full(case.size, np.nan), H, 3)
    assert np.all(np.isnan(out))
    if version == "v2":
        k = 3 if name == "rolling-ball-ex2-yoshida4" else 1  # three substeps, each failing
        for solver in numba_gni.SOLVERS:
            its, out = numba_gni.count_iterations(name, H, 3, solver=solver, state0=np.full(case.size, np.nan))
            assert np.all(np.isnan(out)) and its == k * numba_gni.NEWTON_MAXITER, solver


@pytest.mark.parametrize("name", ["chaplygin-sphere", "contact-oscillator", "suslov"])
def test_rest_is_a_fixed_point(name):
    # at rest (no table rotation for the sphere, q = 0 for the oscillator, Ω = 0 for Suslov) the
    # first guess solves the step exactly: every solver must accept a zero increment (the chord's
    # contraction estimate 0/0 must not turn it into a failure)
    case = numba_gni.CASES[name]
    s0 = case.initial_state()
    if case.size == 16:
        s0[11:] = 0.0
    elif case.size == 12:
        s0[9:] = 0.0
    else:
        s0[:] = 0.0
    for solver in numba_gni.SOLVERS:
        np.testing.assert_array_equal(numba_gni.count_iterations(name, H, 10, solver=solver, state0=s0)[1], s0)
    legacy = numba_gni.get_case(name, legacy=True)
    if legacy is not None:
        np.testing.assert_array_equal(legacy.run(s0, H, 10), s0)


def test_general_kernels_match_the_cases():
    # run_ball / run_oscillator / ... (parameters as arguments) are the cases' kernels with their parameters
    for name in NAMES:
        case, legacy = numba_gni.CASES[name], numba_gni.get_case(name, legacy=True)
        single, batch, single_v1, batch_v1 = _GENERAL[name]
        args = numba_gni._MODEL_ARGS[name]
        s0 = case.initial_state(H)
        expected = case.run(s0, H, 50)
        np.testing.assert_array_equal(single(s0, H, 50, *args), expected)
        np.testing.assert_array_equal(batch(np.stack([s0, s0]), H, 50, *args), np.stack([expected, expected]))
        if legacy is None:
            assert single_v1 is None and name not in numba_gni.LEGACY_CASES
            continue
        expected_v1 = legacy.run(s0, H, 50)
        np.testing.assert_array_equal(single_v1(s0, H, 50, *args), expected_v1)
        np.testing.assert_array_equal(batch_v1(np.stack([s0, s0]), H, 50, *args), np.stack([expected_v1] * 2))
    assert numba_gni.get_case("rolling_ball_ex2") is numba_gni.CASES["rolling-ball-ex2"]
    assert numba_gni.get_case("rolling_ball_ex2", legacy=True) is numba_gni.LEGACY_CASES["rolling-ball-ex2"]
    assert numba_gni.get_case("suslov", legacy=True) is None
    assert numba_gni.LEGACY_CASES["chaplygin-sphere"]._run is numba_gni.run_chaplygin_sphere_v1
    assert numba_gni.CASES["chaplygin-sphere"]._run is numba_gni.run_chaplygin_sphere
    with pytest.raises(ValueError, match="case"):
        numba_gni.get_case("no-such-case")


def test_composition_rescales_the_impulse():
    # the triple jump without the rescaling between substeps (ρ = 1) is another scheme: it must
    # differ from the kernel by far more than round-off (the rescaling is really applied), and the
    # consistent start matters likewise
    case = numba_gni.CASES["rolling-ball-ex2-yoshida4"]
    s0 = case.initial_state(H)
    ours = case.run(s0, H, 100)
    s = s0.copy()
    for _ in range(100):  # the same substeps, no rescaling
        for g in numba_gni.YOSHIDA4:
            s = numba_gni.run_ball(s, g * H, 1, numba_gni.EX2_PARAMS, False)
    assert _rel(s, ours) > 1e-8
    rest = case.run(numba_gni.CASES["rolling-ball-ex2"].initial_state(), H, 100)
    assert _rel(rest, ours) > 1e-8
