"""Section 11 of the suite: optimal control against CasADi + IPOPT on the same discretization
(issue 34, point 1).

The worked problems of the control guide (`gni control --example NAME`), at two resolutions each
(the same horizon): the sleigh steering at K = 80 and 320 steps, the ball-plate problem at K = 60
and 120. For gnipy, each case runs with each optimizer (SLSQP, the default, and IPOPT with the
exact Hessian, `optimizer="ipopt"`, on single shooting, and IPOPT with every step a segment,
`segments = steps`: sparse derivatives) in fresh processes (`solve(check_continuous=False)`: the
discrete problem only, as CasADi solves it; the continuous check a user gets by default is timed
apart):

- **cold**: a fresh process, no compilation cache: the first solve (tracing, XLA compilation and
  the SQP), then the same solve again in that process (the programs reused: the solve itself);
- **warm cache**: a fresh process with JAX's persistent compilation cache, filled by the cold
  run (`gnipy.compilation.enable_compilation_cache`, a private temporary folder): the first solve;
- the continuous check's time (the reference run of the optimal controls), in the cold process.

**CasADi + IPOPT** solves both problems on the same discretization, written by hand from the
GNI's definition, two ways: **simultaneous** (every node's state, and every step's unknowns where
the step is implicit, NLP unknowns; the step's equations constraints) and **single** shooting (the
controls the only unknowns, the states by the steps: gnipy's transcription), with IPOPT's exact
Hessian from CasADi's automatic differentiation.

*The sleigh*: its metric is constant and its constraint linear, so a GNI step is explicit
(the consistent start $p^+_0 = Mv_0 - \\tfrac h2\\mu^T\\lambda_0$, the reflection
$p^- = p^+ - 2\\mu^T(\\mu M^{-1}\\mu^T)^{-1}\\mu M^{-1}p^+$, then $q_{k+1} = q_k + hM^{-1}(p^- + f^-)$,
$p^+_{k+1} = M(q_{k+1} - q_k)/h + f^+$ with the trapezoid's $f^\\pm = \\tfrac h2 Bu_k$).

*The ball-plate problem*: the rolling ball on $\\mathbb{R}^2\\times SO(3)$ with $\\Omega = 0$,
$\\mathbb{G} = \\mathrm{diag}(m, m, I_1, I_2, I_3)$, $\\mu = [[1, 0, 0, -r, 0], [0, 1, r, 0, 0]]$,
$\\Pi = 0$, the inputs $F = Bu$ on $(\\dot x, \\dot y)$. The trapezoid's
$l_d = h\\,l(z/h)$ (l does not depend on the base point) on the step's unknowns
$z_k = (\\Delta x_k, \\sigma_k)$, $x_{k+1} = x_k + \\Delta x_k$ and $R_{k+1} = \\mathrm{cay}(\\sigma_k)R_k$
(the Cayley map; ω the space angular velocity, so R is reconstructed on the left). The start
$p^+_0 = \\mathbb{G}v_0 - \\tfrac h2\\mu^T\\lambda_0$ with $\\lambda_0 = C^{-1}(c - \\mu\\mathbb{G}^{-1}F_0)$,
$C = \\mu\\mathbb{G}^{-1}\\mu^T$, $F_0 = \\mathrm{ad}^*_\\omega I\\omega + Bu_0$ (the first input); a step: the
reflection $p^-_k = p^+_k - 2\\mu^TC^{-1}\\mu\\mathbb{G}^{-1}p^+_k$, the implicit forced transform
$FL^-(z_k) - f^- = p^-_k$ with $FL^- = (m\\Delta x/h,\\ (\\mathrm{dcay}^{-1}_\\sigma)^T I\\sigma/h)$,
$\\mathrm{dcay}^{-1}_\\sigma = I - \\hat\\sigma/2 + \\sigma\\sigma^T/4$, then
$p^+_{k+1} = p^-_k + f^- + f^+ + (0, \\hat\\sigma^T I\\sigma/h)$ ($FL^+ - FL^-$ in closed form, as gnipy
forms it), $f^\\pm = \\tfrac h2 Bu_k$. The target: x, y and the reported velocity
$\\bar v_K = \\mathbb{G}^{-1}(p^+_K - \\mu^TC^{-1}\\mu\\mathbb{G}^{-1}p^+_K)$ (gnipy's `Solution.v`) at their
values, and $\\log(R_{target}^TR_K) = 0$ (the principal log). Simultaneous: $x_k, R_k$ (its nine
entries), $p^+_k$ and $z_k$ unknowns; single shooting: each step's equations solved by CasADi's
Newton `rootfinder` from gnipy's first guess $z = h\\bar v_k$ (its derivatives by the implicit
function theorem). The cost is gnipy's,
$\\sum_k \\tfrac w2 h|u_k|^2 + \\tfrac s2\\sum_k|u_{k+1} - u_k|^2/h$; the unknowns' first guess is
the warm start and its run.

Checked before it is timed: the transcription's final state (x, the reported velocity, R) for
gnipy's optimal controls equals gnipy's `simulate` to 1e-12. Its optimum: on the sleigh it must
equal gnipy's to 1e-10 (relative); the ball-plate problem has several local optima (at 60 steps
from the warm start gnipy's SLSQP stops at 22.12, its IPOPT with the exact Hessian reaches 15.67),
so CasADi's is recorded with the gnipy optima it equals to 1e-9, or none. Times: building the NLP
(`nlpsol`, with the warm start's run for the simultaneous first guess) and solving it, in this
process.

    python -m benchmarks --sections control     # this section (not in the default run: needs casadi)
    python -m benchmarks.control                # its numbers, printed
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: the cases: (problem, steps); the horizon is the worked problem's
CASES = (("sleigh-steering", 80), ("sleigh-steering", 320), ("ball-plate", 60), ("ball-plate", 120))

#: gnipy's optimizers, each measured on every case: SLSQP and IPOPT on single shooting, and IPOPT
#: with every step a segment (`segments = steps`, gnipy.control.step_shooting: sparse derivatives)
OPTIMIZERS = ("slsqp", "ipopt", "ipopt-steps")

#: the optimizers' names in the table
OPTIMIZER_NAMES = {"slsqp": "SLSQP", "ipopt": "IPOPT", "ipopt-steps": "IPOPT, every step a segment"}

#: issue 34's targets: gnipy's wall time (first solve, warm cache) at most this multiple of CasADi's
#: (building and solving), and its solve at most CasADi's
TARGET_WALL_RATIO, TARGET_SOLVE_RATIO = 2.0, 1.0


def problem_text(name: str, steps: int) -> str:
    """The worked problem `name` at `steps` steps over its own horizon."""
    from gnipy.control.problems import worked_problem

    return worked_problem(name, steps)


_CHILD = r'''
import json, sys, time
t0 = time.perf_counter()
spec = json.loads(sys.argv[1])
if spec["cache"]:
    from gnipy.compilation import enable_compilation_cache
    enable_compilation_cache(spec["cache"], min_compile_seconds=0.0)
from gnipy.control import load_problem
from benchmarks.control import problem_text
import dataclasses
prob = load_problem(problem_text(spec["name"], spec["steps"]))
optimizer, _, every = spec["optimizer"].partition("-")
prob = dataclasses.replace(prob, optimizer=optimizer, segments=prob.steps if every else 1)
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


def gnipy_child(name: str, steps: int, cache: str | None, continuous: bool, optimizer: str = "slsqp") -> dict:
    """One fresh process solving the case with `optimizer` (see the module docstring)."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    env.pop("GNIPY_COMPILATION_CACHE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *filter(None, [env.get("PYTHONPATH")])])
    spec = dict(name=name, steps=steps, cache=cache, continuous=continuous, optimizer=optimizer)
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(spec)], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=1800, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"child process exited with {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    out = json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("{")][-1])
    out["process_s"] = time.perf_counter() - t
    return out


def _ipopt(name: str, nlp: dict, t: float, transcription: str, **bounds) -> dict:
    """Build CasADi's IPOPT for `nlp` and solve it (`bounds`: x0, lbx, ubx, lbg, ubg); the build is
    timed from `t` (when the transcription began). IPOPT's options: tol 1e-12 and bound_relax_factor 0
    (IPOPT relaxes the bounds by 1e-8 by default, which lowered the cost of the sleigh's 18 saturated
    controls by 2e-9: the same problem as gnipy's, to the last digits)."""
    import casadi as ca

    solver = ca.nlpsol(name, "ipopt", nlp, {"ipopt.print_level": 0, "print_time": False, "ipopt.tol": 1e-12,
                                            "ipopt.bound_relax_factor": 0.0})
    build_s = time.perf_counter() - t
    t = time.perf_counter()
    sol = solver(**bounds)
    solve_s = time.perf_counter() - t
    stats = solver.stats()
    return dict(transcription=transcription, build_s=build_s, solve_s=solve_s, iterations=int(stats["iter_count"]),
                success=bool(stats["success"]), cost=float(sol["f"]), miss=float(np.max(np.abs(np.asarray(sol["g"])))))


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
    out = _ipopt("sleigh", {"x": x, "f": 0.5 * h * ca.sumsqr(U), "g": g}, t, transcription, x0=x0, lbx=lbx, ubx=ubx,
                 lbg=lbg, ubg=ubg)
    if u_gnipy is not None:  # the transcription checked: its final state for gnipy's controls
        import gnipy

        u = np.asarray(u_gnipy, dtype=float).reshape(K, -1)
        run = gnipy.simulate(prob.system, "gni-trapezoid", prob.q0, prob.v0, h=h, steps=K, controls=u)
        ours = np.asarray(ca.evalf(ca.substitute(final_state(U), U, ca.DM(u[:, 0])))).ravel()
        out["transcription_error"] = float(np.max(np.abs(ours - np.asarray(run.q[-1]))))
    return out


def casadi_ball_plate(steps: int, u_gnipy=None, transcription: str = "simultaneous") -> dict:
    """The ball-plate problem at `steps` steps on CasADi + IPOPT (module docstring), with the
    numbers :func:`casadi_sleigh` returns. The GNI step on $\\mathbb{R}^2\\times SO(3)$ is implicit
    (the Cayley map's $\\mathrm{dcay}^{-1}_\\sigma$ in $FL^-$). `transcription`: `"simultaneous"`
    (every node's state $(x_k, R_k, p^+_k)$ and every step's unknowns $z_k = (\\Delta x_k, \\sigma_k)$
    NLP unknowns, the step's equations constraints) or `"single"` (the controls the only unknowns;
    each step's equations solved by CasADi's Newton `rootfinder`, its derivatives by the implicit
    function theorem, as gnipy's single shooting does with its own Newton iteration). Both are
    built from the same step's equations, and the check (`u_gnipy`) runs them (by the
    rootfinder) against gnipy's `simulate`: x, the reported velocity and R at the last node."""
    import casadi as ca

    from gnipy.control import load_problem

    prob = load_problem(problem_text("ball-plate", steps))
    p = {k: float(v) for k, v in prob.system.args.items()}
    m, r, Om = p["m"], p["r"], p["Omega"]
    inertia = ca.DM([p["I1"], p["I2"], p["I3"]])
    h, K = float(prob.h), int(prob.steps)
    w, s = float(prob.effort), float(prob.smoothness)
    B = ca.DM(np.asarray(prob.system.force.B, dtype=float))  # (5, 2): the [inputs] gains
    nu = B.shape[1]
    G = ca.diag(ca.vertcat(m, m, inertia))  # the metric of l = ½ m|ẋ|² + ½ Σ I_i ω_i²: constant
    Ginv = ca.diag(1 / ca.vertcat(m, m, inertia))
    mu = ca.DM([[1, 0, 0, -r, 0], [0, 1, r, 0, 0]])  # (Cona), (Conb): constant rows
    Cinv = ca.inv(mu @ Ginv @ mu.T)
    q0, v0 = ca.DM(np.asarray(prob.q0, dtype=float)), ca.DM(np.asarray(prob.v0, dtype=float))
    R0 = np.eye(3) if prob.R0 is None else np.asarray(prob.R0, dtype=float).reshape(3, 3)
    R_target = ca.DM(np.asarray(prob.target["R"], dtype=float))
    lo, hi = (np.full(nu, -np.inf), np.full(nu, np.inf)) if prob.bounds is None else prob.bounds
    lo, hi = np.broadcast_to(lo, (nu,)), np.broadcast_to(hi, (nu,))

    def hat(a):
        return ca.vertcat(ca.horzcat(0, -a[2], a[1]), ca.horzcat(a[2], 0, -a[0]), ca.horzcat(-a[1], a[0], 0))

    def cay(a):  # the Cayley map on SO(3) (Appendix): I + 4/(4 + |a|²) (â + â²/2)
        A = hat(a)
        return ca.DM.eye(3) + 4 / (4 + ca.dot(a, a)) * (A + 0.5 * A @ A)

    def Pi(x):  # Π = 𝔾Y, Y = (−Ω y, Ω x, 0, 0, 0): the table's turning (zero here, Ω = 0)
        return G @ ca.vertcat(-Om * x[1], Om * x[0], 0, 0, 0)

    def hidden(x, pp):  # Q*(p⁺ − Π) = μᵀC⁻¹μ𝔾⁻¹(p⁺ − Π), the GNI's hidden impulse
        return mu.T @ (Cinv @ (mu @ Ginv @ (pp - Pi(x))))

    def start(u0):
        # gni-trapezoid's consistent start p⁺_0 = 𝔾v_0 − (h/2)μᵀλ_0, λ_0 the continuous multiplier at
        # (b_0, v_0) with the first input: λ = C⁻¹(c − μ𝔾⁻¹F), F = ad*_ω(Iω) + Bu_0 (the
        # Lagrangian does not depend on the base point), c = μ D_vY (μ constant)
        om = v0[2:]
        F = ca.vertcat(0, 0, ca.cross(inertia * om, om)) + B @ u0
        c = mu @ ca.vertcat(-Om * v0[1], Om * v0[0], 0, 0, 0)
        lam = Cinv @ (c - mu @ Ginv @ F)
        return G @ v0 - 0.5 * h * mu.T @ lam

    def legendre_minus(z):
        # FL⁻ of the trapezoid l_d = h l(z/h) (l does not depend on the base point, so both of its
        # terms are equal and ∇ᴸ_R l_d = 0): (𝔾_x Δx/h, (dcay⁻¹_σ)ᵀ Iσ/h),
        # dcay⁻¹_σ = I − σ̂/2 + σσᵀ/4 (Appendix)
        dx, sig = z[:2], z[2:]
        dtinv = ca.DM.eye(3) - 0.5 * hat(sig) + 0.25 * sig @ sig.T
        return ca.vertcat(m * dx / h, dtinv.T @ (inertia * sig / h))

    def jump(z):
        # FL⁺ − FL⁻ = (0, ad_σᵀ Iσ/h): dcay⁻¹_{−σ} − dcay⁻¹_σ = σ̂ in closed form, as gnipy
        # forms p⁺_{k+1} = p⁻_k + (FL⁺ − FL⁻) (no cancellation of the two transforms)
        sig = z[2:]
        return ca.vertcat(0, 0, hat(sig).T @ (inertia * sig / h))

    def step_residual(z, pm, u):
        # the forced transform FL⁻(z) − f⁻ = p⁻_k, trapezoid's f⁻ = (h/2)Bu_k (F = Bu does not depend
        # on the point nor on the step's velocity z/h)
        return legendre_minus(z) - 0.5 * h * B @ u - pm

    def reflect(x, pp):  # (Comb): p⁻ = p⁺ − 2Q*(p⁺ − Π)
        return pp - 2 * hidden(x, pp)

    def advance(x, R, pp, z, u):
        # x_{k+1} = x_k + Δx, R_{k+1} = cay(σ_k)R_k (ω the space angular velocity: reconstruction
        # "right"), p⁺_{k+1} = FL⁺ + f⁺ = p⁻ + f⁻ + (FL⁺ − FL⁻) + f⁺, f± = (h/2)Bu_k
        return x + z[:2], cay(z[2:]) @ R, reflect(x, pp) + h * B @ u + jump(z)

    def node_velocity(x, pp):  # the reported v̄ = 𝔾⁻¹p̄, p̄ = p⁺ − Q*(p⁺ − Π): gnipy's Solution.v
        return Ginv @ (pp - hidden(x, pp))

    def log_so3(A):
        # gnipy's principal log (angle θ ≤ π, axis from the skew part), smooth at the identity where the
        # optimum puts it: θ/sin θ by the series of atan(t)/t in t = tan θ near 0
        a = 0.5 * ca.vertcat(A[2, 1] - A[1, 2], A[0, 2] - A[2, 0], A[1, 0] - A[0, 1])  # sin θ · axis
        cth, s2 = 0.5 * (ca.trace(A) - 1), ca.dot(a, a)
        near = ca.logic_and(cth > 0.5, s2 < 1e-3 * cth ** 2)
        t2 = s2 / ca.if_else(near, cth ** 2, 1)
        series = 0
        for j in reversed(range(7)):
            series = series * t2 + (-1) ** j / (2 * j + 1)
        s_far = ca.sqrt(ca.if_else(near, 1, s2))
        return ca.if_else(near, series / ca.if_else(near, cth, 1), ca.atan2(s_far, cth) / s_far) * a

    def terminal(x, R, pp):
        # gnipy's terminal_residual: x, y, then ẋ, ẏ minus their targets, then log(R_targetᵀR)
        v = node_velocity(x, pp)
        xt = ca.DM([prob.target[k] for k in ("x", "y")])
        vt = ca.DM([prob.target[k] for k in ("dx", "dy")])
        return ca.vertcat(x - xt, v[:2] - vt, log_so3(R_target.T @ R))

    # the pieces of a step as CasADi Functions (SX inside), R as vec(R) (9,): inlined in the simultaneous
    # transcription's SX expressions, called as whole nodes of single shooting's MX graph (whose
    # derivatives, with the step's arithmetic as scalar MX nodes, took 21 s to build at K = 120)
    xS, RS, pS, zS, pmS, uS = (ca.SX.sym(nm, k) for nm, k in (("x", 2), ("R", 9), ("p", 5), ("z", 5), ("pm", 5),
                                                             ("u", nu)))
    start_f = ca.Function("start", [uS], [start(uS)])
    before_f = ca.Function("before", [xS, pS], [reflect(xS, pS), h * node_velocity(xS, pS)])  # p⁻, and z's guess
    x1, R1, p1 = advance(xS, ca.reshape(RS, 3, 3), pS, zS, uS)
    advance_f = ca.Function("advance", [xS, RS, pS, zS, uS], [x1, ca.vec(R1), p1])
    terminal_f = ca.Function("terminal", [xS, RS, pS], [terminal(xS, ca.reshape(RS, 3, 3), pS)])
    # the step's equations FL⁻(z) − f⁻ = p⁻ solved by Newton's method (CasADi's rootfinder) from gnipy's
    # first guess z = h v̄_k (GroupSpace.initial_guess): the runs (warm start, check) and single shooting
    F = ca.Function("F", [zS, ca.vertcat(pmS, uS)], [step_residual(zS, pmS, uS)])
    newton = ca.rootfinder("step", "newton", F, {"abstol": 1e-14, "abstolStep": 1e-16, "max_iter": 50,
                                                  "error_on_fail": False})

    def run(U):
        # every node's (x, vec R, p⁺) and every step's z from the start, for the controls U (K, nu) (DM or MX)
        x, R, pp = q0, ca.vec(ca.DM(R0)), start_f(U[0, :].T)
        xs, Rs, ps, zz = [x], [R], [pp], []
        for k in range(K):
            u = U[k, :].T
            pm, guess = before_f(x, pp)
            z = newton(guess, ca.vertcat(pm, u))
            x, R, pp = advance_f(x, R, pp, z, u)
            xs.append(x), Rs.append(R), ps.append(pp), zz.append(z)
        return xs, Rs, ps, zz

    def final_state(U):  # the run's last node: x, v̄, R (as gnipy's simulate reports it)
        xs, Rs, ps, _ = run(ca.DM(U))
        return np.concatenate([np.asarray(xs[-1]).ravel(), np.asarray(node_velocity(xs[-1], ps[-1])).ravel(),
                               np.asarray(ca.reshape(Rs[-1], 3, 3)).ravel()])

    u_start = np.asarray(prob.controls0, dtype=float).reshape(K, nu)
    t = time.perf_counter()
    if transcription == "single":
        u_flat = ca.MX.sym("u", K * nu)
        U = ca.reshape(u_flat, nu, K).T  # row k: u_k
        xs, Rs, ps, _ = run(U)
        x_all, x0 = u_flat, u_start.ravel()
        g = terminal_f(xs[-1], Rs[-1], ps[-1])
        lbx, ubx = np.tile(lo, K), np.tile(hi, K)
    else:
        u_flat = ca.SX.sym("u", K * nu)
        U = ca.reshape(u_flat, nu, K).T
        X, Rv, P, Z = (ca.SX.sym("x", 2, K + 1), ca.SX.sym("R", 9, K + 1), ca.SX.sym("p", 5, K + 1),
                       ca.SX.sym("z", 5, K))
        parts = [X[:, 0] - q0, Rv[:, 0] - ca.vec(ca.DM(R0)), P[:, 0] - start_f(U[0, :].T)]
        for k in range(K):
            u = U[k, :].T
            pm, _ = before_f(X[:, k], P[:, k])
            x1, R1, p1 = advance_f(X[:, k], Rv[:, k], P[:, k], Z[:, k], u)
            parts += [F(Z[:, k], ca.vertcat(pm, u)), X[:, k + 1] - x1, Rv[:, k + 1] - R1, P[:, k + 1] - p1]
        parts.append(terminal_f(X[:, K], Rv[:, K], P[:, K]))
        g = ca.vertcat(*parts)
        x_all = ca.vertcat(u_flat, ca.vec(X), ca.vec(Rv), ca.vec(P), ca.vec(Z))
        # the states and steps of the warm start's run: the unknowns' first guess
        runs = run(ca.DM(u_start))
        x0 = np.concatenate([u_start.ravel(), *(np.asarray(ca.horzcat(*part)).ravel(order="F") for part in runs)])
        n = x_all.shape[0] - K * nu
        lbx = np.concatenate([np.tile(lo, K), np.full(n, -np.inf)])
        ubx = np.concatenate([np.tile(hi, K), np.full(n, np.inf)])
    cost = 0.5 * w * h * ca.sumsqr(U) + 0.5 * s / h * ca.sumsqr(U[1:, :] - U[:-1, :])
    lbg = ubg = np.zeros(g.shape[0])
    out = _ipopt("ball_plate", {"x": x_all, "f": cost, "g": g}, t, transcription, x0=x0, lbx=lbx, ubx=ubx,
                 lbg=lbg, ubg=ubg)
    if u_gnipy is not None:  # the transcription checked: its final state for gnipy's controls
        import gnipy

        u = np.asarray(u_gnipy, dtype=float).reshape(K, nu)
        sim = gnipy.simulate(prob.system, "gni-trapezoid", prob.q0, prob.v0, R0=R0, h=h, steps=K, controls=u)
        theirs = np.concatenate([np.asarray(sim.q[-1]), np.asarray(sim.v[-1]), np.asarray(sim.R[-1]).ravel()])
        out["transcription_error"] = float(np.max(np.abs(final_state(u) - theirs)))
    return out


def measure(cases=CASES) -> dict:
    """Every case: gnipy with each optimizer, cold and from a warm cache; CasADi where transcribed,
    its transcription checked against gnipy's `simulate` (an error otherwise) and its optimum
    against gnipy's: on the sleigh it must be gnipy's SLSQP optimum (which is IPOPT's there); on the
    ball-plate problem, which has several local optima, the gnipy optima it equals are recorded
    (`matches`, a list of optimizers) and none is no error."""
    results = {}
    for name, steps in cases:
        row = {}
        for optimizer in OPTIMIZERS:
            with tempfile.TemporaryDirectory(prefix="gnipy-bench-cache-") as d:
                os.chmod(d, 0o700)
                cold = gnipy_child(name, steps, None, continuous=True, optimizer=optimizer)
                gnipy_child(name, steps, d, continuous=False, optimizer=optimizer)  # fills the cache
                warm = gnipy_child(name, steps, d, continuous=False, optimizer=optimizer)
            row[optimizer] = dict(cold=cold, warm=warm)
        cold = row["slsqp"]["cold"]
        transcribe = {"sleigh-steering": casadi_sleigh, "ball-plate": casadi_ball_plate}.get(name)
        if transcribe is not None:
            row["casadi_single"] = transcribe(steps, cold["controls"], "single")
            row["casadi"] = ca = transcribe(steps, cold["controls"], "simultaneous")
            # the transcription is the same discretization (both transcriptions' runs checked)
            for run in (ca, row["casadi_single"]):
                if not run["transcription_error"] <= 1e-12:
                    raise RuntimeError(f"{name}/{steps}: the CasADi transcription ({run['transcription']}) differs "
                                       f"from gnipy's simulate by {run['transcription_error']:.3g}")
            for run in (ca, row["casadi_single"]):
                run["matches"] = [o for o in OPTIMIZERS if run["success"] and abs(
                    run["cost"] - row[o]["cold"]["cost"]) <= 1e-9 * abs(row[o]["cold"]["cost"])]
            # on the sleigh both solvers reach its one optimum; the ball-plate problem has several (at 60
            # steps SLSQP stops at 22.12 from the warm start, IPOPT with the exact Hessian reaches 15.67),
            # so there CasADi's optimum is only recorded, with the gnipy optima it equals
            if name == "sleigh-steering" and not (
                    ca["success"] and abs(ca["cost"] - cold["cost"]) <= 1e-10 * abs(cold["cost"])):
                raise RuntimeError(f"{name}/{steps}: CasADi's optimum {ca['cost']!r} (success {ca['success']}) is not "
                                   f"gnipy's {cold['cost']!r}")
        for optimizer in OPTIMIZERS:
            for r in row[optimizer].values():
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


def _optimum(ca) -> str:
    """CasADi's optimum for the notes, with the gnipy optima it equals (:func:`measure`'s `matches`)."""
    text = f"{ca['cost']:.12g}" + ("" if ca["success"] else " (no success)")
    if "matches" not in ca:
        return text
    found = [OPTIMIZER_NAMES.get(o, o) for o in ca["matches"]]
    return text + (f" = gnipy's {' and '.join(found)} optimum" if found else ", none of gnipy's optima")


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
        "tol 1e-12, no bound relaxation) on the same discretization of both problems, transcribed by hand "
        "(benchmarks/control.py; checked against gnipy's `simulate` to 1e-12 before its times count, and its "
        "optimum against gnipy's: on the sleigh it must be gnipy's to 1e-10; the ball-plate problem has several "
        "local optima, and the notes say which of gnipy's optimizers' optima CasADi's equals, to 1e-9) two ways: "
        "**simultaneous** (every node's state and, where the step is implicit, every step's unknowns NLP unknowns: "
        "the sparse NLP IPOPT is made for) and **single** shooting (gnipy's transcription; the ball-plate's implicit "
        "steps solved by CasADi's Newton rootfinder); building the NLP and solving it. The continuous "
        "check, which a user's solve adds by default, is timed apart. Each number is one measurement (one process "
        "each for gnipy; CasADi in this process), not a median.",
        ["case", "optimizer", "gnipy cold (s)", "gnipy warm cache (s)", "gnipy solve (s)", "iterations",
         "CasADi simultaneous: build + solve (s), iterations", "CasADi single: build + solve (s), iterations", "notes"],
        background_load=load)
    with rep.case(sec, "control"):
        m = measure()
        results["control"] = m
        for case, r in m.items():
            best = _best(r)
            for optimizer in OPTIMIZERS:
                cold, warm = r[optimizer]["cold"], r[optimizer]["warm"]
                notes = (f"optimum {cold['cost']:.12g}" + ("" if cold["success"] else " (no success)")
                         + f"; continuous check {g(cold['continuous_s'])} s")
                if best:
                    ca = r["casadi"]
                    notes += f"; CasADi's optimum {_optimum(ca)}"
                    single = r.get("casadi_single")
                    if single and abs(single["cost"] - ca["cost"]) > 1e-9 * abs(ca["cost"]):
                        notes += f", single shooting's {_optimum(single)}"
                    notes += (f" (transcription error {g(ca['transcription_error'])}); gnipy / fastest CasADi: "
                              f"warm cache {g(warm['first_s'] / (best['build_s'] + best['solve_s']))}×, solve "
                              f"{g(cold['second_s'] / best['fastest_solve_s'])}×")

                def cell(ca):
                    return f"{g(ca['build_s'])} + {g(ca['solve_s'])}, {ca['iterations']}" if ca else "not transcribed"

                rep.row(sec, [case, OPTIMIZER_NAMES[optimizer], g(cold["first_s"]), g(warm["first_s"]), g(cold["second_s"]),
                              cold["iterations"], cell(r.get("casadi")), cell(r.get("casadi_single")), notes],
                        f"{case} ({optimizer}): gnipy cold {g(cold['first_s'])} s, warm cache {g(warm['first_s'])} s, "
                        f"solve {g(cold['second_s'])} s" + (f"; fastest CasADi {g(best['build_s'])} + "
                                                            f"{g(best['solve_s'])} s" if best else ""))
    rep.close(sec)


def control_targets(results: dict, how_far, g) -> list[list[str]]:
    """The summary rows of this section (see :func:`benchmarks.run.targets`): gnipy's faster
    optimizer on the case against the faster of CasADi's transcriptions."""
    r = results.get("control")
    if not r:
        return []
    rows = []
    for case, row in r.items():
        best = _best(row)
        if not best:
            continue
        opt = min(OPTIMIZERS, key=lambda o: row[o]["warm"]["first_s"])
        ratio = row[opt]["warm"]["first_s"] / (best["build_s"] + best["solve_s"])
        met, far = how_far(ratio, TARGET_WALL_RATIO, False)
        rows.append([f"control ≤ {TARGET_WALL_RATIO:g}× CasADi's wall time, warm cache: {case} ({opt})",
                     f"{g(ratio)}×", met, far])
        opt = min(OPTIMIZERS, key=lambda o: row[o]["cold"]["second_s"])
        ratio = row[opt]["cold"]["second_s"] / best["fastest_solve_s"]
        met, far = how_far(ratio, TARGET_SOLVE_RATIO, False)
        rows.append([f"control solve ≤ CasADi's solve: {case} ({opt})", f"{g(ratio)}×", met, far])
    return rows


if __name__ == "__main__":
    print(json.dumps(measure(), indent=1))
