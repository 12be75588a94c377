"""The hand-written Numba GNI steps (benchmarks/numba_gni.py) compute what numpy_gni and gnipy compute.

numba_gni is the speed limit of the native-backend benchmark (issue 16); here it is only checked
for agreement, never timed: 1000 steps at h = 0.01 against numpy_gni (the same formulas, SciPy's
root finder) and against gnipy itself (the paper's start p⁺₀ = p̄₀, as numpy_gni), and the batched
(prange) runs against the single-trajectory runs member by member.
"""

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


@pytest.fixture(scope="module")
def numba_final():
    """numba_gni's final node after STEPS steps, per case."""
    return {name: (c := numba_gni.CASES[name]).observe(c.run(c.initial_state(), H, STEPS)) for name in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_initial_state_matches_numpy_gni(name):
    case = numba_gni.CASES[name]
    state = numpy_gni.get_case(case.numpy_case, case.method).initial_state()
    flat = np.concatenate([np.ravel(a) for a in state])
    np.testing.assert_array_equal(case.initial_state(), flat)


@pytest.mark.parametrize("name", NAMES)
def test_matches_numpy_gni(name, numba_final):
    case = numba_gni.CASES[name]
    ref = numpy_gni.run(case.numpy_case, STEPS, H, method=case.method)
    ours = numba_final[name]
    for key in ("q", "v", "p"):
        assert _rel(ours[key], ref[key]) <= 1e-9, key
    if ref["R"] is None:
        assert ours["R"] is None
    else:
        assert _rel(ours["R"], ref["R"]) <= 1e-9
        np.testing.assert_allclose(ours["R"] @ ours["R"].T, np.eye(3), atol=1e-13)  # Cayley keeps R in SO(3)


@pytest.mark.parametrize("name", NAMES)
def test_matches_gnipy(name, numba_final):
    case = numba_gni.CASES[name]
    system, q0, v0, R0 = _gnipy_case(name)
    sol = gnipy.simulate(system, paper_method(case.method), q0, v0, R0=R0, h=H, steps=STEPS, save_every=STEPS)
    ours = numba_final[name]
    for key in ("q", "v", "p"):
        assert _rel(ours[key], getattr(sol, key)[-1]) <= 1e-9, key
    if sol.R is not None:
        assert _rel(ours["R"], sol.R[-1]) <= 1e-9


@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_single_runs(name):
    case = numba_gni.CASES[name]
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


@pytest.mark.parametrize("name", NAMES)
def test_failed_newton_gives_nan(name):
    # a NaN start cannot meet Newton's stopping test: the step reports failure as NaN, never silently
    case = numba_gni.CASES[name]
    out = case.run(np.full(case.size, np.nan), H, 3)
    assert np.all(np.isnan(out))


def test_general_kernels_match_the_cases():
    # run_ball / run_oscillator (parameters as arguments) are the cases' kernels with their parameters
    for name, args in (
        ("rolling-ball-ex2", (numba_gni.EX2_PARAMS, False)),
        ("chaplygin-sphere", (numba_gni.CHAPLYGIN_PARAMS, True)),
        ("contact-oscillator", (numba_gni.OSCILLATOR_EPS,)),
    ):
        case = numba_gni.CASES[name]
        single, batch = (
            (numba_gni.run_ball, numba_gni.run_ball_batch)
            if case.size == 16
            else (numba_gni.run_oscillator, numba_gni.run_oscillator_batch)
        )
        s0 = case.initial_state()
        expected = case.run(s0, H, 50)
        np.testing.assert_array_equal(single(s0, H, 50, *args), expected)
        np.testing.assert_array_equal(batch(np.stack([s0, s0]), H, 50, *args), np.stack([expected, expected]))
    assert numba_gni.get_case("rolling_ball_ex2") is numba_gni.CASES["rolling-ball-ex2"]
