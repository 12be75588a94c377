"""Section 11 of the suite: optimal control against CasADi + IPOPT on the same discretization
(issue 34, point 1).

The worked problems of the control guide (`gni control --example NAME`), at two resolutions each
(the same horizon): the sleigh steering at K = 80 and 320 steps, the ball-plate problem at K = 60
and 120. For gnipy, each case runs in fresh processes (`solve(check_continuous=False)`: the
discrete problem only, as CasADi solves it; the continuous check a user gets by default is timed
apart):

- **cold**: a fresh process, no compilation cache: the first solve (tracing, XLA compilation and
  the SQP), then the same solve again in that process (the programs reused: the solve itself);
- **warm cache**: a fresh process with JAX's persistent compilation cache, filled by the cold
  run (`gnipy.compilation.enable_compilation_cache`, a private temporary folder): the first solve;
- the continuous check's time (the reference run of the optimal controls), in the cold process.

**CasADi + IPOPT** solves the sleigh on the same discretization, written by hand from the GNI's
definition: the sleigh's metric is constant and its constraint linear, so a GNI step is explicit
(the consistent start $p^+_0 = Mv_0 - \\tfrac h2\\mu^T\\lambda_0$, the reflection
$p^- = p^+ - 2\\mu^T(\\mu M^{-1}\\mu^T)^{-1}\\mu M^{-1}p^+$, then $q_{k+1} = q_k + hM^{-1}(p^- + f^-)$,
$p^+_{k+1} = M(q_{k+1} - q_k)/h + f^+$ with the trapezoid's $f^\\pm = \\tfrac h2 Bu_k$), transcribed by single shooting (the controls the unknowns) with IPOPT's
exact Hessian from CasADi's automatic differentiation. Checked before it is timed: its final state
for gnipy's optimal controls equals gnipy's `simulate` to 1e-12, and its optimum equals gnipy's to
1e-10 (relative). Times: building the NLP (`nlpsol`) and solving it, in this process. The ball-plate problem
(an implicit Cayley step on SO(3) per step) is not transcribed: its row has gnipy's numbers only.

    python -m benchmarks --sections control     # this section (not in the default run: needs casadi)
    python -m benchmarks.control                # its numbers, printed
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: the cases: (problem, steps); the horizon is the worked problem's
CASES = (("sleigh-steering", 80), ("sleigh-steering", 320), ("ball-plate", 60), ("ball-plate", 120))

#: issue 34's targets: gnipy's wall time (first solve, warm cache) at most this multiple of CasADi's
#: (building and solving), and its solve at most CasADi's
TARGET_WALL_RATIO, TARGET_SOLVE_RATIO = 2.0, 1.0


def problem_text(name: str, steps: int) -> str:
    """The worked problem `name` at `steps` steps over its own horizon."""
    from gnipy.control import WORKED_PROBLEMS

    text = WORKED_PROBLEMS[name]
    k = int(re.search(r"^steps = (\d+)$", text, re.M).group(1))
    h = float(re.search(r"^h = ([0-9.eE+-]+)$", text, re.M).group(1))
    text = re.sub(r"^steps = \d+$", f"steps = {steps}", text, flags=re.M)
    return re.sub(r"^h = [0-9.eE+-]+$", f"h = {h * k / steps!r}", text, flags=re.M)


_CHILD = r'''
import json, sys, time
t0 = time.perf_counter()
spec = json.loads(sys.argv[1])
if spec["cache"]:
    from gnipy.compilation import enable_compilation_cache
    enable_compilation_cache(spec["cache"], min_compile_seconds=0.0)
from gnipy.control import load_problem
from benchmarks.control import problem_text
prob = load_problem(problem_text(spec["name"], spec["steps"]))
t1 = time.perf_counter()
first = prob.solve(check_continuous=False)
t2 = time.perf_counter()
second = prob.solve(check_continuous=False)
t3 = time.perf_counter()
out = dict(load_s=t1 - t0, first_s=t2 - t1, second_s=t3 - t2, cost=first.cost, cost2=second.cost,
           iterations=first.iterations, success=bool(first.success), controls=first.controls.tolist())
if spec["continuous"]:
    t = time.perf_counter()
    from gnipy.simulate import simulate
    from gnipy.saveat import SaveAt
    simulate(prob.system, "reference", prob.q0, prob.v0, R0=prob.R0, h=prob.h, steps=prob.steps,
             controls=first.controls, saveat=SaveAt(t1=True))
    out["continuous_s"] = time.perf_counter() - t
print(json.dumps(out))
'''


def gnipy_child(name: str, steps: int, cache: str | None, continuous: bool) -> dict:
    """One fresh process solving the case (see the module docstring)."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("GNIPY_COMPILATION_CACHE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *filter(None, [env.get("PYTHONPATH")])])
    spec = dict(name=name, steps=steps, cache=cache, continuous=continuous)
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(spec)], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=1800, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"child process exited with {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    out = json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("{")][-1])
    out["process_s"] = time.perf_counter() - t
    return out


def casadi_sleigh(steps: int, u_gnipy=None, transcription: str = "simultaneous") -> dict:
    """The sleigh-steering problem at `steps` steps on CasADi + IPOPT (module docstring): build and
    solve times, IPOPT's iterations, the optimum; checked against gnipy's `simulate` with the
    controls `u_gnipy` (its final state) when given. `transcription`: `"simultaneous"` (every
    step's state an unknown, the step's equations constraints: the sparse NLP IPOPT is made for,
    the usual way to use CasADi) or `"single"` (the controls the only unknowns, the states by the
    explicit recursion: gnipy's transcription)."""
    import casadi as ca

    from gnipy.control import load_problem

    prob = load_problem(problem_text("sleigh-steering", steps))
    p = prob.system.args
    m, I, a = float(p["m"]), float(p["I"]), float(p["a"])
    h, K = float(prob.h), int(prob.steps)
    lo, hi = prob.bounds
    target = ca.DM([prob.target[k] for k in ("x", "y", "theta")])
    Minv = ca.diag(ca.DM([1 / m, 1 / m, 1 / I]))
    M = ca.diag(ca.DM([m, m, I]))
    B = ca.DM([0.0, 0.0, 1.0])
    q0, v0 = ca.DM(np.asarray(prob.q0, dtype=float)), ca.DM(np.asarray(prob.v0, dtype=float))

    def start(u0):
        # gni-trapezoid's consistent start: p+ = G v0 - (h/2) mu^T lambda0, lambda0 the continuous
        # multiplier at (q0, v0) with the first input (mu v' = c, c = theta' (x' cos + y' sin))
        mu = ca.horzcat(-ca.sin(q0[2]), ca.cos(q0[2]), -a)
        c = v0[2] * (v0[0] * ca.cos(q0[2]) + v0[1] * ca.sin(q0[2]))
        lam0 = (c - mu @ Minv @ (B * u0)) / (mu @ Minv @ mu.T)
        return M @ v0 - 0.5 * h * mu.T @ lam0

    def step(q, pp, u):
        mu = ca.horzcat(-ca.sin(q[2]), ca.cos(q[2]), -a)  # the constraint's row at q_k
        lam = (mu @ Minv @ pp) / (mu @ Minv @ mu.T)
        pm = pp - 2 * mu.T @ lam  # the GNI's reflection (Pi = 0: linear constraint)
        f = 0.5 * h * B * u
        q1 = q + h * Minv @ (pm + f)
        return q1, M @ (q1 - q) / h + f

    def final_state(U):
        q, pp = q0, start(U[0])
        for k in range(K):
            q, pp = step(q, pp, U[k])
        return q

    u_start = np.asarray(prob.controls0, dtype=float).reshape(-1)
    t = time.perf_counter()
    U = ca.SX.sym("u", K)
    if transcription == "single":
        x, x0 = U, u_start
        lbx, ubx = np.full(K, float(np.min(lo))), np.full(K, float(np.max(hi)))
        g = final_state(U) - target
        lbg = ubg = np.zeros(3)
    else:
        Q, P = ca.SX.sym("q", 3, K + 1), ca.SX.sym("p", 3, K + 1)
        parts = [Q[:, 0] - q0, P[:, 0] - start(U[0])]
        for k in range(K):
            q1, p1 = step(Q[:, k], P[:, k], U[k])
            parts += [Q[:, k + 1] - q1, P[:, k + 1] - p1]
        parts.append(Q[:, K] - target)
        g = ca.vertcat(*parts)
        x = ca.vertcat(U, ca.vec(Q), ca.vec(P))
        # the states of the warm start's run: the unknowns' first guess
        qs, ps = [q0], [start(u_start[0])]
        for k in range(K):
            qn, pn = step(qs[-1], ps[-1], u_start[k])
            qs.append(ca.evalf(qn))
            ps.append(ca.evalf(pn))
        x0 = np.concatenate([u_start, np.asarray(ca.horzcat(*qs)).ravel(order="F"),
                             np.asarray(ca.horzcat(*ps)).ravel(order="F")])
        n = 6 * (K + 1)
        lbx = np.concatenate([np.full(K, float(np.min(lo))), np.full(n, -np.inf)])
        ubx = np.concatenate([np.full(K, float(np.max(hi))), np.full(n, np.inf)])
        lbg = ubg = np.zeros(g.shape[0])
    nlp = {"x": x, "f": 0.5 * h * ca.sumsqr(U), "g": g}
    # bound_relax_factor 0: IPOPT relaxes the bounds by 1e-8 by default, which lowers the cost of the 18
    # saturated controls by 2e-9 (the same problem as gnipy's, to the last digits)
    solver = ca.nlpsol("sleigh", "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-12,
                                                 "ipopt.bound_relax_factor": 0.0})
    build_s = time.perf_counter() - t
    t = time.perf_counter()
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    solve_s = time.perf_counter() - t
    stats = solver.stats()
    out = dict(transcription=transcription, build_s=build_s, solve_s=solve_s, iterations=int(stats["iter_count"]),
               success=bool(stats["success"]), cost=float(sol["f"]), miss=float(np.max(np.abs(np.asarray(sol["g"])))))
    if u_gnipy is not None:  # the transcription checked: its final state for gnipy's controls
        import gnipy

        u = np.asarray(u_gnipy, dtype=float).reshape(K, -1)
        run = gnipy.simulate(prob.system, "gni-trapezoid", prob.q0, prob.v0, h=h, steps=K, controls=u)
        ours = np.asarray(ca.evalf(ca.substitute(final_state(U), U, ca.DM(u[:, 0])))).ravel()
        out["transcription_error"] = float(np.max(np.abs(ours - np.asarray(run.q[-1]))))
    return out


def measure(cases=CASES) -> dict:
    """Every case: gnipy cold and from a warm cache, CasADi where transcribed."""
    results = {}
    for name, steps in cases:
        with tempfile.TemporaryDirectory(prefix="gnipy-bench-cache-") as d:
            os.chmod(d, 0o700)
            cold = gnipy_child(name, steps, None, continuous=True)
            gnipy_child(name, steps, d, continuous=False)  # fills the cache
            warm = gnipy_child(name, steps, d, continuous=False)
        row = dict(cold=cold, warm=warm)
        if name == "sleigh-steering":
            row["casadi_single"] = casadi_sleigh(steps, cold["controls"], "single")
            row["casadi"] = ca = casadi_sleigh(steps, cold["controls"], "simultaneous")
            # the transcription is the same discretization, and both solvers reach its optimum
            if not ca["transcription_error"] <= 1e-12:
                raise RuntimeError(f"{name}/{steps}: the CasADi transcription differs from gnipy's simulate by "
                                   f"{ca['transcription_error']:.3g}")
            if not (ca["success"] and abs(ca["cost"] - cold["cost"]) <= 1e-10 * abs(cold["cost"])):
                raise RuntimeError(f"{name}/{steps}: CasADi's optimum {ca['cost']!r} (success {ca['success']}) is not "
                                   f"gnipy's {cold['cost']!r}")
        for r in (cold, warm):
            r.pop("controls", None)
        results[f"{name}/{steps}"] = row
    return results


def _best(row) -> dict | None:
    """The faster of CasADi's two transcriptions (build + solve), with the faster solve."""
    runs = [r for r in (row.get("casadi"), row.get("casadi_single")) if r]
    if not runs:
        return None
    best = min(runs, key=lambda r: r["build_s"] + r["solve_s"])
    return dict(best, fastest_solve_s=min(r["solve_s"] for r in runs))


def bench_control(cfg, rep, results: dict, load) -> None:
    """The section (see the module docstring)."""
    from benchmarks.run import g

    sec = rep.open(
        "control", "11. Optimal control: gnipy against CasADi + IPOPT (issue 34)",
        "The control guide's worked problems at two resolutions over their own horizons, the discrete problem only "
        "(`solve(check_continuous=False)`). gnipy in fresh processes: **cold** (no compilation cache: tracing, XLA "
        "compilation and the SQP), **warm cache** (JAX's persistent compilation cache filled by an earlier process: "
        "what a user's second session pays), and **solve** (the same solve again in the cold process: the compiled "
        "programs reused, as for a warm start or another start of a multistart). CasADi 3 + IPOPT (exact Hessian, "
        "tol 1e-12, no bound relaxation) on the same discretization of the sleigh, transcribed by hand "
        "(benchmarks/control.py; checked against gnipy's `simulate` to 1e-12 and gnipy's optimum to 1e-10 before "
        "its times count) two ways: **simultaneous** (every step's state an unknown: the sparse NLP IPOPT is made "
        "for) and **single** shooting (gnipy's transcription); building the NLP and solving it. The continuous "
        "check, which a user's solve adds by default, is timed apart. Each number is one measurement (one process "
        "each for gnipy; CasADi in this process), not a median.",
        ["case", "gnipy cold (s)", "gnipy warm cache (s)", "gnipy solve (s)", "SQP iterations",
         "CasADi simultaneous: build + solve (s), iterations", "CasADi single: build + solve (s), iterations", "notes"],
        background_load=load)
    with rep.case(sec, "control"):
        m = measure()
        results["control"] = m
        for case, r in m.items():
            cold, warm, best = r["cold"], r["warm"], _best(r)
            notes = f"optimum {cold['cost']:.12g}; continuous check {g(cold['continuous_s'])} s"
            if best:
                notes += (f"; IPOPT's optimum {r['casadi']['cost']:.12g} (transcription error "
                          f"{g(r['casadi']['transcription_error'])}); gnipy / fastest CasADi: warm cache "
                          f"{g(warm['first_s'] / (best['build_s'] + best['solve_s']))}×, solve "
                          f"{g(cold['second_s'] / best['fastest_solve_s'])}×")

            def cell(ca):
                return f"{g(ca['build_s'])} + {g(ca['solve_s'])}, {ca['iterations']}" if ca else "not transcribed"

            rep.row(sec, [case, g(cold["first_s"]), g(warm["first_s"]), g(cold["second_s"]), cold["iterations"],
                          cell(r.get("casadi")), cell(r.get("casadi_single")), notes],
                    f"{case}: gnipy cold {g(cold['first_s'])} s, warm cache {g(warm['first_s'])} s, solve "
                    f"{g(cold['second_s'])} s" + (f"; fastest CasADi {g(best['build_s'])} + {g(best['solve_s'])} s"
                                                  if best else ""))
    rep.close(sec)


def control_targets(results: dict, how_far, g) -> list[list[str]]:
    """The summary rows of this section (see :func:`benchmarks.run.targets`): against the faster of
    CasADi's transcriptions."""
    r = results.get("control")
    if not r:
        return []
    rows = []
    for case, row in r.items():
        best = _best(row)
        if not best:
            continue
        ratio = row["warm"]["first_s"] / (best["build_s"] + best["solve_s"])
        met, far = how_far(ratio, TARGET_WALL_RATIO, False)
        rows.append([f"control ≤ {TARGET_WALL_RATIO:g}× CasADi's wall time, warm cache: {case}", f"{g(ratio)}×", met, far])
        ratio = row["cold"]["second_s"] / best["fastest_solve_s"]
        met, far = how_far(ratio, TARGET_SOLVE_RATIO, False)
        rows.append([f"control solve ≤ CasADi's solve: {case}", f"{g(ratio)}×", met, far])
    return rows


if __name__ == "__main__":
    print(json.dumps(measure(), indent=1))
