"""The simulation driver: save stride, solver failures, the Solution object."""

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import GNI, Midpoint, System

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False


@pytest.fixture(scope="module")
def particle():
    return gnipy.make_system("nonholonomic-particle")


def test_save_stride_keeps_nodes_and_last(particle):
    full = gnipy.simulate(particle, "gni-trapezoid", h=0.05, steps=23)
    strided = gnipy.simulate(particle, "gni-trapezoid", h=0.05, steps=23, save_every=5)
    idx = [0, 5, 10, 15, 20, 23]
    np.testing.assert_allclose(strided.t, 0.05 * np.array(idx), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(strided.q), np.asarray(full.q)[idx])
    np.testing.assert_array_equal(np.asarray(strided.v), np.asarray(full.v)[idx])
    assert strided.steps == 23 and full.q.shape == (24, 3)


def test_t_final_and_default_initial_condition(particle):
    s = gnipy.simulate(particle, "gni-trapezoid", h=0.25, t_final=2.0)
    assert s.t.shape == (9,) and float(s.t[-1]) == 2.0
    np.testing.assert_array_equal(np.asarray(s.q[0]), gnipy.get_model("nonholonomic-particle").q0)
    np.testing.assert_allclose(np.asarray(s.v[0]), gnipy.get_model("nonholonomic-particle").v0, atol=1e-15)


def test_to_xarray(particle):
    s = gnipy.simulate(particle, "gni-midpoint", h=0.1, steps=10)
    ds = s.to_xarray()
    assert ds["q"].dims == ("time", "coordinate")
    assert ds["v"].dims == ("time", "velocity")
    assert ds["constraint_residual"].dims == ("time", "constraint")
    assert list(ds["coordinate"].values) == ["x", "y", "z"]
    assert ds.attrs["method"] == "gni-midpoint" and ds.attrs["steps"] == 10
    assert ds.attrs["param_k"] == 1.0
    np.testing.assert_array_equal(ds["energy"].values, np.asarray(s.energy))


def _wall_system():
    # V = log(1 − x): undefined for x ≥ 1, and the force 1/(1 − x) pushes the particle there
    return System(
        lambda q, v: 0.5 * v @ v - jnp.log1p(-q[0]),
        lambda q: jnp.array([[0.0, 0.0, 1.0]]),
        n=3,
        name="wall",
    )


def test_solver_failure_stops_with_step_and_residual():
    s = _wall_system()
    with pytest.raises(gnipy.SolverFailure, match=r"step \d+ \(t = .*residual") as exc:
        gnipy.simulate(s, GNI(Midpoint()), [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=200, save_every=3)
    err = exc.value
    assert err.step > 0
    part = err.solution
    assert part.result == 1 and part.failed_step == err.step
    assert np.all(np.isfinite(np.asarray(part.q)))
    # no padding: every saved node lies at or before the last good step
    assert float(part.t[-1]) <= 0.1 * err.step + 1e-12
    assert np.all(np.asarray(part.q)[:, 0] < 1.0)


def test_throw_false_returns_truncated_solution():
    s = _wall_system()
    part = gnipy.simulate(s, GNI(Midpoint()), [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], h=0.1, steps=200, throw=False)
    assert part.result == 1
    assert len(part.t) == part.failed_step + 1
    assert np.all(np.isfinite(np.asarray(part.energy)))


def test_under_jit_throw_false_leaves_nan_after_the_failed_step_and_no_host_callback():
    """Under a transformation a failed step raises at run time (eqx.error_if, a host callback that
    keeps JAX's persistent cache from storing the program); with throw=False the saved nodes after
    it are NaN instead, those before it the concrete run's, and the program has no callback."""
    import jax

    s = _wall_system()
    q0, v0 = jnp.asarray([0.5, 0.0, 0.0]), jnp.asarray([1.0, 0.0, 0.0])
    part = gnipy.simulate(s, GNI(Midpoint()), q0, v0, h=0.1, steps=40, throw=False)
    k = part.failed_step
    assert 0 < k < 40

    def run(q0, throw):
        return gnipy.simulate(s, GNI(Midpoint()), q0, v0, h=0.1, steps=40, throw=throw).q

    quiet = jax.jit(lambda q: run(q, False))
    q = np.asarray(quiet(q0))
    np.testing.assert_allclose(q[:k + 1], np.asarray(part.q), rtol=0, atol=1e-13)
    assert np.all(np.isnan(q[k + 1:]))
    assert "callback" not in quiet.lower(q0).as_text()
    assert "callback" in jax.jit(lambda q: run(q, True)).lower(q0).as_text()


def test_a_repeated_call_naming_its_method_checks_its_start_once(particle, monkeypatch):
    """A method name gives one integrator per process (`gnipy.methods.shared_method`), so repeated
    calls that name it share the checked start and the compiled programs of the first
    (gnipy.preparation): `System.check` runs once for two calls, and both give the same bits."""
    from gnipy.methods import get_method, shared_method

    assert shared_method("gni-trapezoid") is shared_method("gni-trapezoid")
    assert get_method("gni-trapezoid") is not get_method("gni-trapezoid")  # get_method: a fresh one
    calls = []
    check = System.check
    monkeypatch.setattr(System, "check", lambda self, *a, **k: calls.append(1) or check(self, *a, **k))
    q0, v0 = np.array([0.31, -0.27, 0.123456789]), np.array([0.7, 0.2, -0.45])  # a start no other test uses
    a, b = (gnipy.simulate(particle, "gni-trapezoid", q0, v0, h=0.05, steps=7, project_v0=True) for _ in range(2))
    assert len(calls) == 1
    np.testing.assert_array_equal(np.asarray(a.q), np.asarray(b.q))
    np.testing.assert_array_equal(np.asarray(a.hidden_momentum), np.asarray(b.hidden_momentum))


def test_calls_from_threads_that_name_one_method_share_its_start_safely(particle):
    """Threads that name one method share one integrator, and so one prepared start per initial
    condition (gnipy.preparation, which sets a start's parts before the one that says it is made,
    and changes its caches under a lock): threads started at once, with the interpreter switching
    threads every microsecond, all succeed and give the bits of the others at the same h."""
    import sys
    import threading

    n, rounds, errors, results = 8, 12, [], {}
    starts = [np.array([0.1 + 0.01 * r, -0.2, 0.05 * r]) for r in range(rounds)]
    v0 = np.array([0.3, 0.1, -0.2])

    def work(i, r, barrier):
        try:
            barrier.wait(timeout=60)
            sol = gnipy.simulate(particle, "gni-midpoint", starts[r], v0, h=0.05 * (1 + i % 2), steps=5,
                                 project_v0=True, backend="native")
            results[(i, r)] = np.asarray(sol.q)
        except Exception as e:  # noqa: BLE001 -- reported below with its thread
            errors.append((i, r, repr(e)))

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    try:
        for r in range(rounds):
            barrier = threading.Barrier(n)
            threads = [threading.Thread(target=work, args=(i, r, barrier)) for i in range(n)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
    finally:
        sys.setswitchinterval(interval)
    assert errors == []
    for r in range(rounds):
        for i in range(2, n):
            np.testing.assert_array_equal(results[(i, r)], results[(i % 2, r)])
