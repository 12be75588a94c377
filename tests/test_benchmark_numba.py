"""The hand-written Numba GNI steps (benchmarks/numba_gni.py) compute what numpy_gni and gnipy compute.

numba_gni is the speed limit of the native-backend benchmark (issue 16); here it is only checked
for agreement, never timed: 1000 steps at h = 0.01 against numpy_gni (the same formulas, SciPy's
root finder) and against gnipy itself (the paper's start p⁺₀ = p̄₀, as numpy_gni), the batched
(prange) runs against the single-trajectory runs member by member. Both generations are checked:
the current kernels (`CASES`, issue 35) and the first version kept as the old baseline
(`LEGACY_CASES`), and the current kernels' three solvers against each other and against the first
version (the same scheme: they must agree to round-off).

Tolerances (relative, max over the node's q, v, p, R after 1000 steps): gnipy 1e-12 (measured:
≤ 1.6e-14 for the current kernels, ≤ 5.5e-14 for the first version); numpy_gni 1e-11 (measured
≤ 8.7e-13: numpy_gni's own round-off, SciPy's `root` stops at a relative tolerance of 1e-12); the
solvers and versions between themselves 1e-13 (measured ≤ 7e-15).
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
VERSIONS = {"v2": numba_gni.CASES, "v1": numba_gni.LEGACY_CASES}
GNIPY_TOL, NUMPY_TOL, ROUNDOFF_TOL = 1e-12, 1e-11, 1e-13


def _rel(a, b):
    """Largest absolute difference relative to the size of the reference array `b`."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)


def _gnipy_case(name):
    """(system, q0, v0, R0) of gnipy's model for a case (as in test_benchmark_baselines.py)."""
    if name == "rolling-ball-ex2":
        system, q0, v0 = example_2()
        return system, q0, v0, None
    spec = gnipy.get_model(name)
    q0, v0 = spec.initial_condition(spec.params)
    return spec.system(), q0, v0, spec.R0


def _general_run(name):
    """(run, batch, model args) of the general kernel of a case."""
    case = numba_gni.CASES[name]
    args = numba_gni._MODEL_ARGS[name]
    if case.size == 16:
        return numba_gni.run_ball, numba_gni.run_ball_batch, args
    return numba_gni.run_oscillator, numba_gni.run_oscillator_batch, args


@functools.lru_cache(maxsize=None)
def _final(version, name):
    """numba_gni's final node after STEPS steps (the version's kernel)."""
    case = VERSIONS[version][name]
    return case.observe(case.run(case.initial_state(), H, STEPS))


@functools.lru_cache(maxsize=None)
def _numpy_ref(name):
    case = numba_gni.CASES[name]
    return numpy_gni.run(case.numpy_case, STEPS, H, method=case.method)


@functools.lru_cache(maxsize=None)
def _gnipy_ref(name):
    case = numba_gni.CASES[name]
    system, q0, v0, R0 = _gnipy_case(name)
    return gnipy.simulate(system, paper_method(case.method), q0, v0, R0=R0, h=H, steps=STEPS, save_every=STEPS)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", NAMES)
def test_initial_state_matches_numpy_gni(name, version):
    case = VERSIONS[version][name]
    state = numpy_gni.get_case(case.numpy_case, case.method).initial_state()
    flat = np.concatenate([np.ravel(a) for a in state])
    np.testing.assert_array_equal(case.initial_state(), flat)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", NAMES)
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


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", NAMES)
def test_matches_gnipy(name, version):
    sol = _gnipy_ref(name)
    ours = _final(version, name)
    for key in ("q", "v", "p"):
        assert _rel(ours[key], getattr(sol, key)[-1]) <= GNIPY_TOL, key
    if sol.R is not None:
        assert _rel(ours["R"], sol.R[-1]) <= GNIPY_TOL


@pytest.mark.parametrize("name", NAMES)
def test_solvers_and_versions_agree_to_roundoff(name):
    # the same scheme solved three ways (and by the first version, to 1e-14): the same trajectory
    # up to round-off, so the stopping rules stop at round-off
    case = numba_gni.CASES[name]
    s0 = case.initial_state()
    v1 = numba_gni.LEGACY_CASES[name].run(s0, H, STEPS)
    finals = {solver: numba_gni.count_iterations(name, H, STEPS, solver=solver)[1] for solver in numba_gni.SOLVERS}
    for solver, out in finals.items():
        assert np.all(np.isfinite(out)), solver
        assert _rel(out, v1) <= ROUNDOFF_TOL, solver
    # the case's run is the general kernel with the case's solver, bit for bit
    np.testing.assert_array_equal(case.run(s0, H, STEPS), finals[numba_gni.CASE_SOLVER[name]])


@pytest.mark.parametrize("name", NAMES)
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


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_single_runs(name, version):
    case = VERSIONS[version][name]
    s0 = case.initial_state()
    rng = np.random.default_rng(16)
    states = np.tile(s0, (5, 1))
    # perturb the positions and momenta (not R, which must stay a rotation)
    cols = [0, 1, 11, 12, 13, 14, 15] if case.size == 16 else list(range(6))
    states[1:, cols] += 0.05 * rng.standard_normal((4, len(cols)))
    batch = case.run_batch(states, H, 200)
    assert batch.shape == states.shape
    for i in range(len(states)):
        single = case.run(states[i], H, 200)
        assert np.all(np.isfinite(single))
        np.testing.assert_allclose(batch[i], single, rtol=0, atol=1e-14 * np.max(np.abs(single)))
    assert np.any(batch[1] != batch[0])  # the members are different trajectories


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("name", NAMES)
def test_failed_newton_gives_nan(name, version):
    # a NaN start cannot meet Newton's stopping test: the step reports failure as NaN, never silently
    case = VERSIONS[version][name]
    out = case.run(np.full(case.size, np.nan), H, 3)
    assert np.all(np.isnan(out))
    if version == "v2":
        for solver in numba_gni.SOLVERS:
            its, out = numba_gni.count_iterations(name, H, 3, solver=solver, state0=np.full(case.size, np.nan))
            assert np.all(np.isnan(out)) and its == numba_gni.NEWTON_MAXITER, solver


@pytest.mark.parametrize("name", ["chaplygin-sphere", "contact-oscillator"])
def test_rest_is_a_fixed_point(name):
    # at rest (no table rotation for the sphere, q = 0 for the oscillator) the first guess solves
    # the step exactly: every solver must accept a zero increment (the chord's contraction
    # estimate 0/0 must not turn it into a failure)
    case = numba_gni.CASES[name]
    s0 = case.initial_state()
    if case.size == 16:
        s0[11:] = 0.0
    else:
        s0[:] = 0.0
    for solver in numba_gni.SOLVERS:
        np.testing.assert_array_equal(numba_gni.count_iterations(name, H, 10, solver=solver, state0=s0)[1], s0)
    np.testing.assert_array_equal(numba_gni.LEGACY_CASES[name].run(s0, H, 10), s0)


def test_general_kernels_match_the_cases():
    # run_ball / run_oscillator (parameters as arguments) are the cases' kernels with their parameters
    for name in NAMES:
        case, legacy = numba_gni.CASES[name], numba_gni.LEGACY_CASES[name]
        single, batch, args = _general_run(name)
        single_v1, batch_v1 = (
            (numba_gni.run_ball_v1, numba_gni.run_ball_batch_v1)
            if case.size == 16
            else (numba_gni.run_oscillator_v1, numba_gni.run_oscillator_batch_v1)
        )
        s0 = case.initial_state()
        expected, expected_v1 = case.run(s0, H, 50), legacy.run(s0, H, 50)
        np.testing.assert_array_equal(single(s0, H, 50, *args), expected)
        np.testing.assert_array_equal(batch(np.stack([s0, s0]), H, 50, *args), np.stack([expected, expected]))
        np.testing.assert_array_equal(single_v1(s0, H, 50, *args), expected_v1)
        np.testing.assert_array_equal(batch_v1(np.stack([s0, s0]), H, 50, *args), np.stack([expected_v1] * 2))
    assert numba_gni.get_case("rolling_ball_ex2") is numba_gni.CASES["rolling-ball-ex2"]
    assert numba_gni.get_case("rolling_ball_ex2", legacy=True) is numba_gni.LEGACY_CASES["rolling-ball-ex2"]
    assert numba_gni.LEGACY_CASES["chaplygin-sphere"]._run is numba_gni.run_chaplygin_sphere_v1
    assert numba_gni.CASES["chaplygin-sphere"]._run is numba_gni.run_chaplygin_sphere
