"""IPOPT as the optimizer of optimal control (gnipy.control.ipopt, `optimizer="ipopt"`): the same
optimum as SLSQP where both converge (two independent solvers meeting at one KKT point), the lower
ball-plate optimum that CasADi + IPOPT found from outside (issue 34: 15.6685271644), an exact
Hessian of the Lagrangian (checked by central differences of the gradient), evaluation failures
handed to IPOPT as such, the SLSQP chain as the fallback, and the option refused or named where it
is wrong."""

from __future__ import annotations

import dataclasses
import re
import sys

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy.control.optimal_control import solve_optimal_control
from gnipy.control.problems import WORKED_PROBLEMS, load_problem

#: the sleigh-steering problem on a coarse grid (20 steps of 0.2: the same horizon), cheap to compile
SMALL = re.sub(r"^h = .*$", "h = 0.2", re.sub(r"^steps = .*$", "steps = 20", WORKED_PROBLEMS["sleigh-steering"],
                                              flags=re.M), flags=re.M)


@pytest.fixture(scope="module")
def small():
    problem = load_problem(SMALL)
    calls = []
    ipopt = dataclasses.replace(problem, optimizer="ipopt").solve(
        check_continuous=False, progress=lambda i, cost, miss, total: calls.append((i, total)))
    return problem, problem.solve(check_continuous=False), ipopt, calls


def test_ipopt_and_slsqp_meet_at_the_same_optimum(small):
    problem, slsqp, ipopt, calls = small
    assert slsqp.success and ipopt.success, (slsqp.message, ipopt.message)
    assert ipopt.optimizer == "ipopt" and slsqp.optimizer == "slsqp"
    assert ipopt.message.startswith("IPOPT: ") and "IPOPT failed" not in ipopt.message
    assert f"iterations: {ipopt.iterations} IPOPT + " in ipopt.summary()
    assert f"iterations: {slsqp.iterations} SQP + " in slsqp.summary()
    assert abs(ipopt.cost - slsqp.cost) <= 1e-9 * slsqp.cost
    np.testing.assert_allclose(ipopt.controls, slsqp.controls, rtol=0, atol=1e-6)
    # the torque bound is active and kept exactly (no bound relaxation): IPOPT's point is at it
    lo, hi = problem.bounds
    assert np.all(ipopt.controls >= lo) and np.all(ipopt.controls <= hi) and ipopt.active_bounds > 0
    assert ipopt.bound_multipliers_ok and ipopt.kkt_residual <= 1e-6 and ipopt.target_residual <= 1e-10
    # one progress call per iteration, counted from 1, never past the total it reports
    assert [i for i, _ in calls] == list(range(1, len(calls) + 1)) and len(calls) == ipopt.iterations > 0
    assert all(i <= total for i, total in calls)


def test_ipopt_finds_the_lower_ball_plate_optimum_that_casadi_found():
    """Issue 34: the ball-plate worked problem (60 steps) has two optima; SLSQP from the documented
    warm start stops at the upper one (22.12), CasADi + IPOPT on an independent transcription
    found 15.6685271644 from 5 of 11 starts. gnipy's IPOPT with the exact Hessian reaches it from
    the warm start."""
    problem = dataclasses.replace(load_problem("ball-plate"), optimizer="ipopt")
    result = problem.solve(check_continuous=False)
    assert result.success, result.message
    assert abs(result.cost - 15.6685271644) <= 1e-9 * 15.6685271644
    assert result.target_residual <= 1e-10 and result.kkt_residual <= 1e-6


def test_the_hessian_of_the_lagrangian_is_the_derivative_of_its_gradient(small):
    """The Hessian IPOPT is given (single shooting's second-order adjoint through the implicit steps)
    against central differences of the Lagrangian's gradient (reverse mode, the SQP's own), at the
    optimum with its multipliers."""
    from gnipy.control.optimal_control import SingleShooting, sqp_problem
    from gnipy.control.control_arguments import control_arguments, terminal_residual

    problem, _, ipopt, _ = small
    a = control_arguments(problem.system, steps=problem.steps, h=problem.h, effort=problem.effort,
                          smoothness=problem.smoothness, t0=0.0, target_tol=1e-10, kkt_tol=1e-6, running_cost=None,
                          segments=1, max_iterations=10, check_continuous=False, project_v0=False,
                          bounds=problem.bounds, progress=False, input_names=None)
    single = SingleShooting.make(problem.system, problem.method, terminal_residual(problem.system, problem.target),
                                 np.asarray(problem.q0), np.asarray(problem.v0), None, a, None)
    F = sqp_problem(single, a, problem.controls0, None, 3).controls
    x, lam, sigma = ipopt.controls.ravel(), np.asarray(ipopt.multipliers), 0.7

    def grad(y):
        return sigma * np.asarray(F.cost_gradient(y)) + np.asarray(F.constraints_jacobian(y)).T @ lam

    H = F.hessian(x, lam, sigma)
    eps = 1e-5
    fd = np.stack([(grad(x + eps * e) - grad(x - eps * e)) / (2 * eps) for e in np.eye(x.size)], axis=1)
    assert np.max(np.abs(H - H.T)) <= 1e-12 * np.max(np.abs(H))
    assert np.max(np.abs(H - fd)) <= 1e-6 * np.max(np.abs(H))


def test_a_failed_evaluation_is_an_evaluation_error_to_ipopt():
    """A step that fails at a trial point (a SolverFailure from the functions) is IPOPT's evaluation
    error, after which it shortens its step; any other error is not swallowed (cyipopt ends some
    callbacks' errors as IPOPT's "unrecoverable error": the error is kept and raised after the
    solve)."""
    import cyipopt

    from gnipy.control.ipopt import _NLP
    from gnipy.control.sqp import Functions

    def failing(*args):
        raise gnipy.SolverFailure("a step failed", step=3, time=0.3, residual=1.0)

    def broken(x):
        raise ValueError("a bug")

    F = Functions(cost=failing, cost_gradient=broken, constraints=failing, constraints_jacobian=failing, hessian=failing)
    nlp = _NLP(cyipopt, F, n=2, d=1, report=None, count=[0])
    for call in (lambda: nlp.objective(np.zeros(2)), lambda: nlp.constraints(np.zeros(2)),
                 lambda: nlp.jacobian(np.zeros(2)), lambda: nlp.hessian(np.zeros(2), np.zeros(1), 1.0)):
        with pytest.raises(cyipopt.CyIpoptEvaluationError):
            call()
    with pytest.raises(ValueError, match="a bug"):
        nlp.gradient(np.zeros(2))
    assert isinstance(nlp.error, ValueError)  # kept: raised after the solve, whatever cyipopt made of it
    rows, cols = nlp.hessianstructure()
    assert np.all(rows >= cols) and rows.size == 3  # the lower triangle of a 2 x 2 Hessian


def test_an_error_in_the_hessian_stops_ipopt_and_is_raised():
    """cyipopt drops an error raised in its Hessian callback (IPOPT would go on with whatever its
    buffer holds); gnipy keeps it, stops IPOPT at its next iteration and raises it after the solve,
    in a real IPOPT solve of a small problem."""
    from gnipy.control.ipopt import solve_ipopt
    from gnipy.control.sqp import Functions, SQPProblem

    calls = []

    def hessian(x, lam, sigma):
        calls.append(1)
        raise ZeroDivisionError("a bug in the Hessian")

    F = Functions(cost=lambda x: float(x @ x), cost_gradient=lambda x: 2 * x,
                  constraints=lambda x: np.array([x[0] + x[1] - 1.0]), constraints_jacobian=lambda x: np.ones((1, 2)),
                  hessian=hessian)
    problem = SQPProblem(controls=F, unknowns=F, single=True, x0=np.zeros(2), x_lo=np.full(2, -np.inf),
                         x_hi=np.full(2, np.inf), lo=np.full(2, -np.inf), hi=np.full(2, np.inf), n_target=1, scale=1.0,
                         hessian=None)
    with pytest.raises(ZeroDivisionError, match="a bug in the Hessian"):
        solve_ipopt(problem, max_iterations=50, target_tol=1e-10, kkt_tol=1e-6, report=None)
    assert len(calls) <= 2  # stopped at the next iteration, not after 50


def test_when_ipopt_fails_the_slsqp_chain_runs_and_the_count_goes_on(small):
    """IPOPT stopped at an iteration cap of 2 is no success: the SLSQP chain runs from the warm start
    (its own fallback included), the message says so, and the progress count goes on from IPOPT's
    without passing its total."""
    problem = small[0]
    calls = []
    result = solve_optimal_control(problem.system, problem.target, h=problem.h, steps=problem.steps, q0=problem.q0,
                                   v0=problem.v0, controls0=problem.controls0, bounds=problem.bounds, max_iterations=2,
                                   check_continuous=False, optimizer="ipopt",
                                   progress=lambda i, cost, miss, total: calls.append((i, total)))
    assert ("IPOPT failed (IPOPT: Maximum number of iterations exceeded" in result.message
            and "; then SLSQP" in result.message) or "the SLSQP chain from the warm start did no better" in result.message
    assert [i for i, _ in calls] == list(range(1, len(calls) + 1)) and len(calls) == result.iterations > 2
    assert all(i <= total for i, total in calls), calls


def test_the_optimizer_is_checked_and_its_missing_package_named(monkeypatch):
    problem = load_problem(SMALL)
    kw = dict(h=problem.h, steps=problem.steps, q0=problem.q0, v0=problem.v0, check_continuous=False)
    for bad in ("IPOPT", "snopt", 1, None):
        with pytest.raises(gnipy.InputError, match="^optimizer: expected one of 'slsqp', 'ipopt'"):
            solve_optimal_control(problem.system, problem.target, optimizer=bad, **kw)
    with pytest.raises(gnipy.InputError, match="^solver.optimizer: expected one of"):
        load_problem(SMALL.replace("[solver]\n", '[solver]\noptimizer = "newton"\n'))
    with pytest.raises(gnipy.InputError, match="^solver.optimizer: expected a string"):
        load_problem(SMALL.replace("[solver]\n", "[solver]\noptimizer = 1\n"))
    assert load_problem(SMALL.replace("[solver]\n", '[solver]\noptimizer = "ipopt"\n')).optimizer == "ipopt"
    monkeypatch.setitem(sys.modules, "cyipopt", None)
    with pytest.raises(gnipy.MissingExtra, match=r"needs cyipopt: pip install 'gnipy\[ipopt\]'$"):
        solve_optimal_control(problem.system, problem.target, optimizer="ipopt", **kw)


def test_gni_control_takes_the_optimizer_and_records_it(tmp_path, small):
    from gnipy.cli import app

    path = tmp_path / "small.toml"
    path.write_text(SMALL, encoding="utf-8")
    out = tmp_path / "ipopt.nc"
    res = CliRunner().invoke(app, ["control", str(path), "--optimizer", "ipopt", "--out", str(out)])
    assert res.exit_code == 0, res.output
    with xr.open_dataset(out) as ds:
        assert ds.attrs["control_optimizer"] == "ipopt"
        assert ds.attrs["control_message"].startswith("IPOPT: ")
        assert abs(float(ds.attrs["control_cost"]) - small[2].cost) <= 1e-12 * small[2].cost
    res = CliRunner().invoke(app, ["control", str(path), "--optimizer", "newton", "--out", str(tmp_path / "x.nc")])
    assert res.exit_code != 0 and "solver.optimizer" in res.output and "newton" in res.output
    assert not (tmp_path / "x.nc").exists()


def test_ipopts_hessian_counts_in_the_memory_bound():
    """The exact Hessian's memory (its dense copies; with a running cost, forward mode over reverse
    mode's tangent per unknown through the steps too) is part of the estimate with IPOPT, and a
    problem beyond the bound is refused before anything is compiled, naming it."""
    from gnipy.control.memory import control_memory

    p = load_problem(SMALL)
    slsqp = control_memory(p.system, 4000, target_size=3)
    ipopt = control_memory(p.system, 4000, target_size=3, optimizer="ipopt")
    assert slsqp["hessian"] == 0 and ipopt["hessian"] > 0
    assert ipopt["total"] == slsqp["total"] + ipopt["hessian"]
    assert control_memory(p.system, 4000, target_size=3, optimizer="ipopt", running_cost=True)["hessian"] > ipopt["hessian"]
    with pytest.raises(gnipy.InputError, match="^steps: 4,000 steps x 1 input.*IPOPT's exact Hessian"):
        solve_optimal_control(p.system, p.target, h=0.001, steps=4000, q0=p.q0, v0=p.v0, optimizer="ipopt",
                              max_bytes=slsqp["total"])
