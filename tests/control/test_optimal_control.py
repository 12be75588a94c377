"""Discrete optimal control on the GNI's steps (gnipy.control): the worked problems meet their
targets when their controls are re-simulated independently with `simulate`, the returned point is
a KKT point by an independent check (central differences), and bad problems are refused."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy import simulate
from gnipy.control.optimal_control import solve_optimal_control
from gnipy.control.problems import WORKED_PROBLEMS, load_problem, write_control_result


@pytest.fixture(scope="module")
def solved():
    out = {}
    for name in WORKED_PROBLEMS:
        problem = load_problem(name)
        # the continuous system is checked once (the ball), each check compiles the reference
        out[name] = (problem, problem.solve(check_continuous=name == "ball-plate"))
    return out


def _resimulate(problem, controls):
    return simulate(problem.system, problem.method, problem.q0, problem.v0, R0=problem.R0, h=problem.h,
                    steps=problem.steps, controls=controls)


@pytest.mark.parametrize("name", list(WORKED_PROBLEMS))
def test_worked_problem_meets_its_target_when_resimulated(solved, name):
    problem, result = solved[name]
    assert result.success, result.message
    sol = _resimulate(problem, np.asarray(result.controls))
    assert sol.success
    coords, vels = list(sol.coordinates), list(sol.velocities)
    misses = []
    for key, value in problem.target.items():
        if key == "R":
            misses.append(np.max(np.abs(np.asarray(sol.R[-1]) - np.asarray(value))))
        elif key in coords:
            misses.append(abs(float(sol.q[-1, coords.index(key)]) - value))
        else:
            misses.append(abs(float(sol.v[-1, vels.index(key)]) - value))
    assert max(misses) <= 1e-8, dict(zip(problem.target, misses))
    # the nonholonomic constraints hold along the controlled run
    assert float(np.max(np.abs(sol.constraint_residual))) <= 1e-13


def test_sleigh_steering_respects_its_torque_bound_and_uses_it(solved):
    problem, result = solved["sleigh-steering"]
    u = np.asarray(result.controls)
    lo, hi = problem.bounds
    assert np.all(u >= lo) and np.all(u <= hi)
    # the bound is active: the unbounded optimum would need a larger torque
    assert result.active_bounds > 0 and np.max(np.abs(u)) == hi
    assert result.bound_multipliers_ok and result.kkt_residual <= 1e-6


def test_ball_plate_turns_the_ball_by_a_quarter_about_the_vertical(solved):
    problem, result = solved["ball-plate"]
    # the continuous ball driven by the same held inputs ends near the target: within the GNI's
    # error at h = 0.1 (a second-order method, errors of order h² times the motion's scale)
    assert 0 < result.continuous_miss <= 0.05
    sol = result.solution
    R = np.asarray(sol.R[-1])
    # back at the origin and at rest, yet turned: the holonomy of rolling (a closed path of the centre)
    assert np.allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-8)
    assert np.max(np.abs(np.asarray(sol.q[len(sol.q) // 2]))) > 0.1  # the centre went round a loop


def test_ball_plate_solution_is_a_kkt_point_by_central_differences(solved):
    """Independent check of optimality: the gradient of the cost by hand (effort h w u, smoothness
    (s/h) DᵀD u with D the step differences), the target's Jacobian by central differences of
    re-simulations; then ∇J + J_gᵀλ = 0 for a λ (no bounds)."""
    problem, result = solved["ball-plate"]
    U = np.asarray(result.controls)
    K, m = U.shape
    R_target = np.asarray(problem.target["R"])

    def g(Uflat):
        sol = _resimulate(problem, Uflat.reshape(K, m))
        Rf = np.asarray(sol.R[-1])
        rot = 0.5 * (R_target.T @ Rf - Rf.T @ R_target)  # ≈ hat(log) near the target
        return np.concatenate([np.asarray(sol.q[-1]), np.asarray(sol.v[-1, :2]), [rot[2, 1], rot[0, 2], rot[1, 0]]])

    x = U.ravel()
    eps = 1e-6
    Jg = np.stack([(g(x + eps * e) - g(x - eps * e)) / (2 * eps) for e in np.eye(x.size)], axis=1)
    D = np.diff(np.eye(K), axis=0)  # (K-1, K): u_{k+1} - u_k
    grad = (problem.h * problem.effort * U + problem.smoothness / problem.h * (D.T @ D @ U)).ravel()
    lam = np.linalg.lstsq(Jg.T, -grad, rcond=None)[0]
    assert np.max(np.abs(grad + Jg.T @ lam)) <= 1e-6 * max(1.0, np.max(np.abs(grad)))
    # the derivative the solver used (reverse mode through the GNI's implicit steps on R² × SO(3))
    # is the central differences' (at the target log(R_tᵀR) and the skew part agree to first order)
    assert np.max(np.abs(result.target_jacobian - Jg)) <= 1e-7 * np.max(np.abs(Jg))


def test_problem_errors_name_the_entry():
    base = tomllib.loads(WORKED_PROBLEMS["sleigh-steering"])
    cases = [
        ({**base, "horizon": {"h": -1.0, "steps": 10}}, "horizon.h"),
        ({**base, "horizon": {"h": 0.1, "steps": 0}}, "horizon.steps"),
        ({**base, "inputs": {"torque": {"dphi": 1.0}}}, "unknown velocity 'dphi'"),
        ({**base, "system": {"model": "no-such-model"}}, "system.model"),
        ({**base, "target": {"z": 1.0}}, "target: unknown name 'z'"),
        ({**base, "solver": {"bounds": [1.0, -1.0]}}, "bounds"),
        ({**base, "extra": {}}, "unknown section"),
        ({k: v for k, v in base.items() if k != "horizon"}, "[horizon]"),
    ]
    for data, words in cases:
        with pytest.raises(gnipy.InputError, match=None) as info:
            load_problem(data).solve() if "bounds" in words or "target" in words else load_problem(data)
        assert words in str(info.value), (words, str(info.value))


def test_unforced_system_and_bad_warm_start_are_refused():
    sleigh = gnipy.make_system("chaplygin-sleigh")
    with pytest.raises(gnipy.InputError, match="system: an optimal-control problem needs inputs"):
        solve_optimal_control(sleigh, {"x": 1.0}, h=0.1, steps=10)
    problem = load_problem("sleigh-steering")
    with pytest.raises(gnipy.InputError, match="controls0"):
        solve_optimal_control(problem.system, problem.target, h=0.1, steps=10, q0=problem.q0, v0=problem.v0,
                              controls0=np.zeros((9, 1)))
    with pytest.raises(gnipy.InputError, match="steps"):
        solve_optimal_control(problem.system, problem.target, h=0.1, steps=0)


def test_gni_control_cli_writes_the_run_and_its_inputs(tmp_path, solved):
    from gnipy.cli import app

    runner = CliRunner()
    printed = runner.invoke(app, ["control", "--example", "sleigh-steering", "--print"])
    assert printed.exit_code == 0
    assert tomllib.loads(printed.output) == tomllib.loads(WORKED_PROBLEMS["sleigh-steering"])
    # the problem from a file, on a coarser grid (h = 0.1: 40 steps)
    text = WORKED_PROBLEMS["sleigh-steering"].replace("h = 0.05\nsteps = 80", "h = 0.1\nsteps = 40")
    assert "steps = 40" in text
    (tmp_path / "short.toml").write_text(text)
    out, fig = tmp_path / "short.nc", tmp_path / "short.png"
    res = runner.invoke(app, ["control", str(tmp_path / "short.toml"), "--out", str(out), "--plot", str(fig)])
    assert res.exit_code == 0, res.output
    assert "target residual" in res.output and fig.stat().st_size > 0
    ds = xr.open_dataset(out)
    assert ds.attrs["control_success"] == 1 and ds["u"].shape == (40, 1)
    assert list(ds["input"].values) == ["torque"]
    problem = load_problem(text)
    sol = _resimulate(problem, ds["u"].values)
    assert np.max(np.abs(np.asarray(sol.q[-1]) - [1.0, 0.5, 0.0])) <= 1e-8
    assert np.array_equal(np.asarray(sol.q), ds["q"].values)
    u_short = ds["u"].values
    ds.close()
    # issue 34: that result as the warm start of a problem file, on the same grid (the inputs
    # themselves) and on the worked grid (h = 0.05: each earlier input held over two of its steps)
    warm = "[warm_start]\namplitude = [1.0]\nphase = [0.0]\nperiods = 1.0"
    assert warm in text
    (tmp_path / "again.toml").write_text(text.replace(warm, '[warm_start]\nfile = "short.nc"'))
    same = load_problem(tmp_path / "again.toml")  # relative to the problem file's folder
    np.testing.assert_array_equal(same.controls0, u_short)
    fine_text = WORKED_PROBLEMS["sleigh-steering"].replace(warm, '[warm_start]\nfile = "short.nc"')
    (tmp_path / "fine.toml").write_text(fine_text)
    fine = load_problem(tmp_path / "fine.toml")
    np.testing.assert_array_equal(fine.controls0, np.repeat(u_short, 2, axis=0))
    for entry, message in (('file = "missing.nc"', "no such file"), ('file = "short.toml"', "cannot read"),
                           ('file = "short.nc"\nperiods = 2.0', "periods")):
        (tmp_path / "bad.toml").write_text(text.replace(warm, "[warm_start]\n" + entry))
        with pytest.raises(gnipy.InputError, match="warm_start"):
            load_problem(tmp_path / "bad.toml")
    # no --out, unknown example: usage errors naming the option
    assert runner.invoke(app, ["control", "--example", "nope", "--out", str(out)]).exit_code == 2
    assert "--out" in runner.invoke(app, ["control", "--example", "ball-plate"]).output


def test_control_result_file_round_trip(tmp_path, solved):
    problem, result = solved["ball-plate"]
    path = tmp_path / "ball.nc"
    write_control_result(result, problem, path)
    ok, _ = gnipy.verify_netcdf(path)
    assert ok
    with xr.open_dataset(path) as ds:
        assert np.array_equal(ds["u"].values, np.asarray(result.controls))
        assert list(ds["input"].values) == ["ax", "ay"]
        assert float(ds.attrs["control_target_residual"]) == result.target_residual
        assert "ball-plate" in ds.attrs["control_problem_file"]


def test_multiple_shooting_finds_the_single_shooting_optimum(solved):
    """Two segments (the state at the boundary an unknown, its defect a constraint) reach the same
    discrete optimum as single shooting: the same cost and controls, the target met."""
    problem, one = solved["sleigh-steering"]
    kw = dict(h=problem.h, steps=problem.steps, q0=problem.q0, v0=problem.v0, controls0=problem.controls0,
              bounds=problem.bounds, check_continuous=False)
    two = solve_optimal_control(problem.system, problem.target, segments=2, **kw)
    assert one.success and two.success, (one.message, two.message)
    assert abs(one.cost - two.cost) <= 1e-8 * one.cost
    assert np.max(np.abs(one.controls - two.controls)) <= 1e-5
    with pytest.raises(gnipy.InputError, match="segments"):
        solve_optimal_control(problem.system, problem.target, segments=0, **kw)


class ReachedComputation(Exception):
    """A refusal came too late: a simulation was reached."""


def _tripwire(*args, **kwargs):
    raise ReachedComputation("reached a computation")


def test_arguments_are_strict_and_the_memory_is_bounded_before_anything_is_computed(monkeypatch):
    """Issue 28 (D6, D9): a string or a boolean is not a number, anywhere; a problem beyond the
    memory bound (the SQP's matrices grow as (K·m)²) is refused naming steps, max_bytes=None lifts
    the bound. Every refusal comes before the first simulation (a tripwire)."""
    import gnipy.control.shooting as shooting

    monkeypatch.setattr(shooting, "simulate", _tripwire)
    p = load_problem("sleigh-steering")
    ball = load_problem("ball-plate")
    base = dict(h=p.h, steps=p.steps, q0=p.q0, v0=p.v0, controls0=p.controls0, bounds=p.bounds)
    cases = [
        (dict(effort=True), "effort: expected a number, got bool"), (dict(effort="1"), "effort: expected a number"),
        (dict(smoothness=np.bool_(True)), "smoothness:"), (dict(smoothness=-1.0), "smoothness: must be >= 0"),
        (dict(h=True), "h: expected a number"), (dict(h="0.05"), "h: expected a number"), (dict(h=1e-320), "h:"),
        (dict(steps=80.0), "steps:"), (dict(steps=True), "steps:"), (dict(steps="80"), "steps:"),
        (dict(max_iterations=True), "max_iterations:"), (dict(max_iterations=0), "max_iterations:"),
        (dict(max_iterations=10**7), "max_iterations: must be an integer from 1 to 1,000,000"),
        (dict(segments=True), "segments:"), (dict(segments=81), "segments:"),
        (dict(bounds=("-1.5", 1.5)), "bounds: lower"), (dict(bounds=(True, 2.0)), "bounds: lower"),
        (dict(bounds=(2.0, 1.0)), "bounds: need lower < upper"), (dict(bounds="ab"), "bounds:"),
        (dict(target_tol="1e-10"), "target_tol:"), (dict(kkt_tol=0.0), "kkt_tol:"), (dict(t0=True), "t0:"),
        (dict(check_continuous="no"), "check_continuous:"), (dict(project_v0="no"), "project_v0:"),
        (dict(input_names="t"), "input_names:"), (dict(input_names=[1]), "input_names:"),
        (dict(controls0=np.ones((80, 1), dtype=bool)), "controls0:"), (dict(controls0=[["1"]] * 80), "controls0:"),
        (dict(max_bytes="lots"), "max_bytes:"), (dict(max_bytes=True), "max_bytes:"),
        (dict(progress="yes"), "progress:"),
        (dict(steps=10**8, controls0=None), "steps: 100,000,000 steps x 1 input"),
    ]
    for kw, words in cases:
        with pytest.raises(gnipy.InputError) as info:
            solve_optimal_control(p.system, p.target, **(base | kw))
        assert str(info.value).startswith(words), (kw, str(info.value))
    assert "pass max_bytes=None" in str(info.value)
    for target, words in [({"x": True}, "target: 'x': expected a number"), ({"x": "1"}, "target: 'x'")]:
        with pytest.raises(gnipy.InputError, match=words):
            solve_optimal_control(p.system, target, **base)
    with pytest.raises(gnipy.InputError, match="target: 'R'"):
        solve_optimal_control(ball.system, {"R": [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]}, h=0.1, steps=10)
    with pytest.raises(ReachedComputation):  # max_bytes=None: past the bound, to the first simulation
        solve_optimal_control(p.system, p.target, **(base | dict(steps=10**5, controls0=None, max_bytes=None)))


def test_progress_count_never_passes_its_total():
    """Issue 28 (D9): the iterations count on across SLSQP, the trust-constr fallback and SLSQP
    again; the total reported is the most the solve can still take, raised when the fallback
    starts (it showed 70/60)."""
    p = load_problem("sleigh-steering")
    calls, plain = [], []
    result = solve_optimal_control(p.system, p.target, h=0.2, steps=20, q0=p.q0, v0=p.v0, controls0=p.controls0[::4],
                                   bounds=p.bounds, max_iterations=2, check_continuous=False,
                                   progress=lambda i, cost, miss, total: calls.append((i, total)))
    assert [i for i, _ in calls] == list(range(1, len(calls) + 1)) and len(calls) == result.iterations
    assert len(calls) > 2 and calls[0][1] == 2  # SLSQP stopped at its cap of 2: the fallback ran
    assert all(i <= total for i, total in calls), calls
    assert calls[-1][1] <= 2 + 2 * 2  # no more than the stages' caps
    solve_optimal_control(p.system, p.target, h=0.2, steps=20, q0=p.q0, v0=p.v0, controls0=p.controls0[::4],
                          bounds=p.bounds, max_iterations=2, check_continuous=False,
                          progress=lambda i, cost, miss: plain.append(i))  # three arguments still work
    assert plain == [i for i, _ in calls]


def test_an_unreachable_target_is_no_kkt_point_in_the_summary():
    """Issue 34: a point that misses the target is not feasible, so its stationarity residual and its
    bound multipliers' signs say nothing of optimality: the summary says so instead of quoting them
    (it read "KKT 2.9e-12 ... multipliers of the right sign" at a miss of 8.8)."""
    p = load_problem("sleigh-steering")
    far = {"x": 10.0, "y": 0.5, "theta": 0.0}  # 10 m in 4 s with |tau| <= 0.05: out of reach
    result = solve_optimal_control(p.system, far, h=0.2, steps=20, q0=p.q0, v0=p.v0, controls0=p.controls0[::4] * 0.05,
                                   bounds=(-0.05, 0.05), max_iterations=5, check_continuous=False)
    assert not result.success and result.target_residual > 1.0
    text = result.summary()
    assert "NOT converged" in text and "no KKT point: the target is missed by" in text
    assert "sign" not in text and "KKT residual (free controls)" not in text


def test_a_redundant_target_is_detected_solved_for_its_independent_part_and_checked_whole():
    """Issue 34: a target whose components are dependent (here a fourth component, 2(x - 1), that the
    first fixes) has a constraint Jacobian of rank 3 of 4 for every control: SLSQP's subproblem is
    singular. The dependent component is found before the solve, the SQP solves for the independent
    ones, and the whole target is checked at the end: the optimum is that of the target without the
    redundant component (an independent formulation of the same problem), to round-off."""
    import jax.numpy as jnp

    p = load_problem("sleigh-steering")
    kw = dict(h=0.2, steps=20, q0=p.q0, v0=p.v0, controls0=p.controls0[::4], bounds=p.bounds, check_continuous=False)
    plain = solve_optimal_control(p.system, {"x": 1.0, "y": 0.5, "theta": 0.0}, **kw)
    redundant = solve_optimal_control(p.system, lambda b, v: jnp.stack([b[0] - 1.0, b[1] - 0.5, b[2], 2.0 * (b[0] - 1.0)]),
                                      **kw)
    assert plain.success and not plain.redundant_components and plain.target_rank == 3
    assert redundant.success and len(redundant.redundant_components) == 1
    assert redundant.redundant_components[0] in ("g[0]", "g[3]")
    assert redundant.target_residual < 1e-12 and abs(redundant.cost - plain.cost) < 1e-10
    np.testing.assert_allclose(redundant.controls, plain.controls, rtol=0, atol=1e-8)
    assert "redundant target" in redundant.summary() and "redundant target" in redundant.message


def test_the_zero_warm_start_reaches_the_worked_optimum():
    """Issue 34: with no warm start (zeros) the sleigh at rest cannot turn its torque into forward motion
    to first order, and SLSQP's subproblem is singular there; the trust-constr fallback leaves that
    point and the solve reaches the same optimum as from the documented warm start (on the worked
    problem's horizon at 20 steps: at its 80 the fallback takes 8-27 s here, the same path)."""
    p = load_problem("sleigh-steering")
    kw = dict(h=0.2, steps=20, q0=p.q0, v0=p.v0, bounds=p.bounds, check_continuous=False)
    result = solve_optimal_control(p.system, p.target, controls0=p.controls0[::4], **kw)
    cold = solve_optimal_control(p.system, p.target, controls0=None, **kw)
    assert result.success and cold.success, cold.message
    assert cold.message.startswith("SLSQP failed (Singular matrix C")  # the fallback was needed
    assert abs(cold.cost - result.cost) < 1e-9 * result.cost
    np.testing.assert_allclose(cold.controls, result.controls, rtol=0, atol=1e-6)


def test_a_multistart_reuses_the_compiled_problem_and_lists_the_optima():
    """Issue 34: `starts=N` solves from the warm start and N - 1 random starts and returns the best; on
    the sleigh every converged start reaches the one optimum of the warm start's solve (the sleigh's
    steering optimum appears global: IPOPT found it from 12 of 16 starts), listed once with its count.
    The iterations count on across the starts and never pass their total."""
    p = load_problem("sleigh-steering")
    kw = dict(h=0.2, steps=20, q0=p.q0, v0=p.v0, controls0=p.controls0[::4], bounds=p.bounds, check_continuous=False)
    one = solve_optimal_control(p.system, p.target, **kw)
    calls = []
    many = solve_optimal_control(p.system, p.target, starts=4, progress=lambda i, c, m, t: calls.append((i, t)), **kw)
    assert one.success and many.success and not one.local_optima and many.starts == 4
    assert len(many.local_optima) == 1 and 2 <= many.local_optima[0][1] <= 4
    assert abs(many.local_optima[0][0] - one.cost) < 1e-9 * one.cost and abs(many.cost - one.cost) < 1e-9 * one.cost
    assert [i for i, _ in calls] == list(range(1, len(calls) + 1)) and len(calls) == many.iterations
    assert all(i <= t for i, t in calls)
    assert "multistart: 1 distinct local optimum" in many.summary()
    for bad in (0, 1.5, True, "2"):
        with pytest.raises(gnipy.InputError, match="starts"):
            solve_optimal_control(p.system, p.target, starts=bad, **kw)
    with pytest.raises(gnipy.InputError, match="starts"):
        solve_optimal_control(p.system, p.target, starts=2, segments=2, **kw)


def test_a_value_that_is_not_finite_at_an_iterate_stops_the_solve_with_a_solver_failure():
    """The compiled runs leave NaN nodes after a failed step (simulate(..., throw=False) under a
    transformation: no host callback, so JAX's persistent cache keeps the programs); the SQP's host
    side turns a value that is not finite into a SolverFailure that says what to do, never NaN
    handed to SciPy."""
    import jax.numpy as jnp

    from gnipy.control.sqp import AtPoint

    def fn(x):
        return jnp.sum(x) * jnp.array([1.0, jnp.nan]), jnp.ones((2, x.size))

    at = AtPoint(fn, "constraints and their Jacobian")
    with pytest.raises(gnipy.SolverFailure, match="constraints and their Jacobian are not finite.*smaller h"):
        at.first(np.array([0.5, -2.0]))
    finite = AtPoint(lambda x: (x**2, 2 * x), "cost and its gradient")
    np.testing.assert_array_equal(finite.first(np.array([3.0])), [9.0])
    np.testing.assert_array_equal(finite.second(np.array([3.0])), [6.0])  # the same point: computed once
