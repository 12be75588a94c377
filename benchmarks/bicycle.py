"""Section 10 of the suite: the Whipple bicycle in gnipy and as the SymPy/PyDy tools simulate it
(issue 32, points 5 and 6).

One bicycle, written once: SymBRiM's Whipple bicycle (Moore's coordinates, knife-edge wheels, the
front contact a holonomic constraint) with the benchmark's parameters (Meijaard et al. 2007), as a
`sympy.physics.mechanics` System. Two ways to simulate it:

- **PyDy + SciPy**, as the bicycle-dynamics community does: Kane's equations from
  `System.form_eoms(constraint_solver="CRAMER")` (the dependent speeds and the pitch chosen as
  SymBRiM's examples do), their
  right-hand side compiled by PyDy's code generator (`generate_ode_function`, Cython), integrated by
  SciPy's `solve_ivp(DOP853)`; nothing keeps the holonomic constraint but the tolerance.
- **gnipy**: `gnipy.from_sympy` of the same System (the Lagrangian and the constraints, differentiated
  by JAX), `simulate` with `dla` and `sgni-trapezoid` at h = 0.01 (XLA backend; compilation excluded,
  reported apart); `dla` on the native backend; and `dla` on a batch of :data:`BATCH` pushes at once
  (one vmapped program, XLA), its time per trajectory.

The motion: the benchmark bicycle rolling upright at 5 m/s (inside its self-stable speed range)
pushed into a roll rate of 0.5 rad/s; its weave decays. The **reference** is DOP853 at rtol = atol
= 1e-12 on PyDy's right-hand side (its own accuracy estimated against rtol 1e-11); gnipy's
continuous reference (Dopri8 on gnipy's equations) is compared with it as the agreement of the
two tools. Errors are the largest difference of the eight coordinates at the saved times (every
0.1 s) up to T; **PyDy at matched accuracy** is the loosest DOP853 tolerance (atol = rtol) whose
error is at most gnipy's; times are the median of `reps` warm calls, per simulated second. The
energy error is over a long run (T_long), where the constraint residual of the front contact is
read too. Issue 32's target, a step of at most 5 µs, is read on the native backend as the marginal
cost of a step in `simulate`: :data:`STEP_S` steps against 1, only the final state saved.

    python -m benchmarks --sections bicycle     # this section (not in the default run: the [bench] extra)
    python -m benchmarks.bicycle                # its numbers, printed
"""

from __future__ import annotations

import time

import numpy as np

#: the motion: speed (m/s), roll rate pushed (rad/s), the step, the horizons (s), the save interval
SPEED, ROLL_RATE, H, T, T_LONG, SAVE = 5.0, 0.5, 0.01, 10.0, 100.0, 0.1
METHODS = ("dla", "sgni-trapezoid")
#: the members of the batch run (dla): pushes from 0.5 to 1.5 times ROLL_RATE, the nominal one first
BATCH = 1024


def symbrim_bicycle():
    """SymBRiM's Whipple bicycle as a `sympy.physics.mechanics` System, with Kane's choice of
    independent coordinates and speeds (SymBRiM's examples: the pitch and u1, u2, u3, u5, u8
    dependent), gravity, and the benchmark's parameters in Moore's set: `(system, values)`, values a
    dict symbol -> float."""
    import sympy as sp
    import symbrim as sb

    from gnipy.models.whipple_bicycle import moore_parameters

    bicycle = sb.WhippleBicycle("bicycle")
    bicycle.front_frame = sb.RigidFrontFrame("front_frame")
    bicycle.rear_frame = sb.RigidRearFrame("rear_frame")
    bicycle.front_wheel = sb.KnifeEdgeWheel("front_wheel")
    bicycle.rear_wheel = sb.KnifeEdgeWheel("rear_wheel")
    bicycle.front_tire = sb.NonHolonomicTire("front_tire")
    bicycle.rear_tire = sb.NonHolonomicTire("rear_tire")
    bicycle.ground = sb.FlatGround("ground")
    bicycle.define_all()
    system = bicycle.to_system()
    system.apply_uniform_gravity(-sp.Symbol("g") * bicycle.ground.get_normal(bicycle.ground.origin))
    system.q_ind = [*bicycle.q[:4], *bicycle.q[5:]]
    system.q_dep = [bicycle.q[4]]
    system.u_ind = [bicycle.u[3], *bicycle.u[5:7]]
    system.u_dep = [*bicycle.u[:3], bicycle.u[4], bicycle.u[7]]
    values = moore_parameters()
    return system, {sp.Symbol(k): float(v) for k, v in values.items()}


def initial_state(gnipy_bicycle):
    """The pushed upright motion in Moore's coordinates, in the order of `gnipy_bicycle.coordinates`
    (`(q0, v0)`, v0 projected onto the constraints by gnipy): the hand-written model's upright state
    (gnipy.models.whipple_bicycle.upright) with the pitch offset by λ and the rear wheel's angle
    measured from the rear frame (Moore's), and the roll rate pushed."""
    from gnipy.models import whipple_bicycle as wb
    from gnipy.system_checks import project_velocity

    q, qdot = wb.upright(None, SPEED)
    qdot = qdot.copy()
    qdot[3] = ROLL_RATE
    moore_q = {f"bicycle_q{i + 1}": x for i, x in enumerate(q)}
    moore_v = {f"bicycle_q{i + 1}": x for i, x in enumerate(qdot)}
    moore_q["bicycle_q5"] = q[4] + wb.BENCHMARK["lam"]
    moore_q["bicycle_q6"], moore_v["bicycle_q6"] = q[5] - q[4], qdot[5] - qdot[4]
    names = gnipy_bicycle.coordinates
    q0 = np.array([moore_q[n] for n in names])
    v0 = np.array([moore_v[n] for n in names])
    return q0, np.asarray(project_velocity(gnipy_bicycle, q0, v0))


def _error(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))))


def _median_time(fn, reps):
    fn()
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times))


def measure(reps: int = 3, long: bool = True) -> dict:
    """The section's numbers (see the module docstring)."""
    from scipy.integrate import solve_ivp

    import importlib

    try:
        from pydy.codegen.ode_function_generators import generate_ode_function
        importlib.import_module("Cython")  # PyDy's Cython generator: only its presence is checked
        importlib.import_module("symbrim")
    except ImportError as e:
        raise ImportError(f"the bicycle section needs {e.name}: pip install '.[bench]'") from e

    import gnipy

    out: dict = {}
    t = time.perf_counter()
    system, values = symbrim_bicycle()
    bicycle = gnipy.from_sympy(system, params=values, name="symbrim-whipple")
    out["from_sympy_s"] = time.perf_counter() - t
    t = time.perf_counter()
    # Cramer's rule for the dependent speeds, as SymBRiM recommends: with SymPy's default (LU) the
    # expressions are a third longer (the forcing 405,242 operations against 319,471, the mass matrix
    # 971,704 against 720,077) and a call of PyDy's Cython function takes 10 ms at the pushed upright
    # state (and gives NaN where a pivot vanishes), against 14 µs (measured on the 2-core machine)
    system.form_eoms(constraint_solver="CRAMER")
    out["kane_s"] = time.perf_counter() - t
    constants = sorted(values, key=str)
    t = time.perf_counter()
    rhs = generate_ode_function(system.forcing_full, system.q, system.u, constants,
                                mass_matrix=system.mass_matrix_full, generator="cython")
    out["pydy_codegen_s"] = time.perf_counter() - t
    p = np.array([values[c] for c in constants])

    q0, v0 = initial_state(bicycle)
    names = list(bicycle.coordinates)
    q_order = [names.index(str(s).replace("(t)", "")) for s in system.q]
    u_order = [names.index(str(s).replace("(t)", "").replace("_u", "_q")) for s in system.u]
    x0 = np.concatenate([q0[q_order], v0[u_order]])
    nq = len(q_order)

    def pydy(t_final, rtol, atol=None):
        grid = np.linspace(0.0, t_final, int(round(t_final / SAVE)) + 1)
        sol = solve_ivp(lambda tt, x: rhs(x, tt, p), (0.0, t_final), x0, method="DOP853", rtol=rtol,
                        atol=rtol if atol is None else atol, t_eval=grid)
        assert sol.success, sol.message
        q = np.empty((grid.size, nq))
        q[:, q_order] = sol.y[:nq].T
        v = np.empty((grid.size, nq))
        v[:, u_order] = sol.y[nq:].T
        return q, v, sol.nfev

    ref_q, _, ref_nfev = pydy(T, 1e-12)
    loose_q, _, _ = pydy(T, 1e-11)
    out["reference"] = {"nfev": ref_nfev, "self_error": _error(ref_q, loose_q)}
    every = int(round(SAVE / H))
    cont = gnipy.simulate(bicycle, "reference", q0, v0, h=SAVE, t_final=T)
    out["agreement"] = _error(np.asarray(cont.q), ref_q)

    energy = bicycle.energy
    phi = bicycle.phi

    def drift(q, v):
        import jax
        import jax.numpy as jnp

        e = np.asarray(jax.vmap(energy)(jnp.asarray(q), jnp.asarray(v)))
        f = np.asarray(jax.vmap(phi)(jnp.asarray(q)))
        return float(np.max(np.abs(e - e[0])) / abs(e[0])), float(np.max(np.abs(f)))

    out["gnipy"] = {}
    for method in METHODS:
        t = time.perf_counter()
        sol = gnipy.simulate(bicycle, method, q0, v0, h=H, t_final=T, save_every=every)
        first = time.perf_counter() - t
        wall = _median_time(lambda m=method: gnipy.simulate(bicycle, m, q0, v0, h=H, t_final=T, save_every=every)
                            .q.block_until_ready(), reps)
        row = {"first_s": first, "per_second": wall / T, "error": _error(np.asarray(sol.q), ref_q),
               "healthy": bool(sol.healthy)}
        if long:
            sol_long = gnipy.simulate(bicycle, method, q0, v0, h=H, t_final=T_LONG, save_every=every)
            row["energy"], row["phi"] = drift(np.asarray(sol_long.q), np.asarray(sol_long.v))
        out["gnipy"][method] = row

    # dla on the native backend (one trajectory; its build, minutes on an empty cache, is the first call)
    t = time.perf_counter()
    sol = gnipy.simulate(bicycle, "dla", q0, v0, h=H, t_final=T, save_every=every, backend="native")
    first = time.perf_counter() - t
    wall = _median_time(lambda: gnipy.simulate(bicycle, "dla", q0, v0, h=H, t_final=T, save_every=every,
                                               backend="native").q.block_until_ready(), reps)
    out["native"] = {"first_s": first, "per_second": wall / T, "error": _error(np.asarray(sol.q), ref_q),
                     "healthy": bool(sol.healthy)}
    # the marginal cost of a step (the target's measure): STEP_S steps and 1 step, only the final
    # state saved, the same compiled loop; (median(STEP_S) - median(1)) / (STEP_S - 1), and the call
    def native_run(steps):
        return gnipy.simulate(bicycle, "dla", q0, v0, h=H, steps=steps, save_every=steps, backend="native")

    many = _median_time(lambda: native_run(STEP_S).q.block_until_ready(), reps)
    one = _median_time(lambda: native_run(1).q.block_until_ready(), reps)
    out["native"].update(step_us=(many - one) / (STEP_S - 1) * 1e6, call_ms=one * 1e3,
                         step_healthy=bool(native_run(STEP_S).healthy))

    # a batch: BATCH pushes spread around the nominal one (member 0), one vmapped program; the
    # time per trajectory is the batch's wall time over BATCH (the cost of an ensemble: Monte
    # Carlo over the push, a sweep over a parameter)
    pushes = ROLL_RATE * np.linspace(0.5, 1.5, BATCH)
    pushes = np.concatenate([[ROLL_RATE], pushes[1:]])
    roll = names.index("bicycle_q4")
    v_batch = np.repeat(v0[None], BATCH, axis=0)
    v_batch[:, roll] = v0[roll] - ROLL_RATE + pushes  # v0 holds the nominal push (projected: roll is independent)
    q_batch = np.repeat(q0[None], BATCH, axis=0)

    def batch():
        return gnipy.simulate(bicycle, "dla", q_batch, v_batch, h=H, t_final=T, save_every=every, project_v0=True)

    t = time.perf_counter()
    sol = batch()
    first = time.perf_counter() - t
    wall = _median_time(lambda: batch().q.block_until_ready(), reps)
    out["batch"] = {"members": BATCH, "first_s": first, "per_second": wall / T / BATCH,
                    "error": _error(np.asarray(sol.q[0]), ref_q), "healthy": bool(sol.healthy)}  # every member's verdicts

    # PyDy at matched accuracy: the loosest rtol (halving in log10 between 1e-12 and 1e-3) whose
    # error is at most gnipy's dla error
    target = out["gnipy"]["dla"]["error"]
    lo, hi = -12.0, -3.0  # log10 rtol: lo meets the target, hi does not (checked below)
    if _error(pydy(T, 10.0**hi)[0], ref_q) <= target:
        lo = hi
    else:
        for _ in range(12):
            mid = 0.5 * (lo + hi)
            if _error(pydy(T, 10.0**mid)[0], ref_q) <= target:
                lo = mid
            else:
                hi = mid
    rtol = 10.0**lo
    q_m, _, nfev = pydy(T, rtol)
    wall = _median_time(lambda: pydy(T, rtol), reps)
    row = {"rtol": rtol, "nfev": nfev, "per_second": wall / T, "error": _error(q_m, ref_q)}
    if long:
        q_l, v_l, _ = pydy(T_LONG, rtol)
        row["energy"], row["phi"] = drift(q_l, v_l)
    out["pydy"] = row
    return out


def bench_bicycle(cfg, rep, results: dict, load) -> None:
    """The section (see the module docstring)."""
    from benchmarks.run import g

    reps = 5 if cfg.name == "full" else 2
    sec = rep.open(
        "bicycle", "10. The Whipple bicycle: gnipy against PyDy + SciPy (issue 32)",
        f"SymBRiM's Whipple bicycle (benchmark parameters), upright at {SPEED:g} m/s pushed to a roll rate of "
        f"{ROLL_RATE:g} rad/s. PyDy: Kane's equations (`System.form_eoms(constraint_solver='CRAMER')`), right-hand side by "
        f"`pydy.codegen.ode_function_generators.generate_ode_function(generator='cython')`, SciPy DOP853. gnipy: "
        f"`gnipy.from_sympy` of the same System, `simulate(method, h={H:g})` on XLA, compilation excluded. Error: the "
        f"largest difference of the 8 coordinates every {SAVE:g} s up to T = {T:g} s against DOP853 at rtol = atol = "
        f"1e-12; time per simulated second: median of {reps} warm calls; energy (relative) and front-contact "
        f"residual |φ| over T = {T_LONG:g} s.",
        ["how", "error (T = 10 s)", "s per simulated s", "energy error (T = 100 s)", "max |φ| (T = 100 s)", "notes"],
        background_load=load)
    with rep.case(sec, "bicycle"):
        m = measure(reps)
        results["bicycle"] = m
        for method, r in m["gnipy"].items():
            rep.row(sec, [f"gnipy {method}, h = {H:g}", g(r["error"]), g(r["per_second"]), g(r["energy"]), g(r["phi"]),
                          f"first call {g(r['first_s'])} s (compilation); "
                          + ("healthy" if r["healthy"] else "flagged by its run-time verdicts")],
                    f"gnipy {method}: error {g(r['error'])}, {g(r['per_second'])} s per simulated s")
        r = m["native"]
        rep.row(sec, [f"gnipy dla, h = {H:g}, native backend", g(r["error"]), g(r["per_second"]), "", "",
                      f"first call {g(r['first_s'])} s (lowering and LLVM; its object code cached after); "
                      + ("healthy" if r["healthy"] else "flagged by its run-time verdicts")],
                f"gnipy dla native: error {g(r['error'])}, {g(r['per_second'])} s per simulated s")
        if "step_us" in r:
            rep.note(sec, f"gnipy dla on the native backend, one step: {g(r['step_us'])} µs (the marginal cost in "
                          f"`simulate` of {STEP_S:,} steps with only the final state saved, against 1 step; "
                          f"{'healthy' if r['step_healthy'] else 'flagged by its run-time verdicts'}); a call "
                          f"of 1 step: {g(r['call_ms'])} ms. The rows above include each call and the observation of "
                          f"its {int(round(T / SAVE))} saved nodes.")
        r = m["batch"]
        rep.row(sec, [f"gnipy dla, h = {H:g}, a batch of {r['members']:,} pushes (per trajectory)", g(r["error"]),
                      g(r["per_second"]), "", "",
                      f"one vmapped program; first call {g(r['first_s'])} s; "
                      f"{'every member healthy' if r['healthy'] else 'flagged by its run-time verdicts'}; "
                      f"error of the nominal member"],
                f"gnipy dla batch: {g(r['per_second'])} s per simulated s per trajectory")
        r = m["pydy"]
        rep.row(sec, [f"PyDy + DOP853, rtol = atol = {r['rtol']:.2g}", g(r["error"]), g(r["per_second"]), g(r["energy"]),
                      g(r["phi"]), f"{r['nfev']:,} evaluations"],
                f"PyDy + DOP853 at matched accuracy: {g(r['per_second'])} s per simulated s")
        rep.note(sec, f"set-up: `gnipy.from_sympy` {g(m['from_sympy_s'])} s; Kane's equations {g(m['kane_s'])} s; PyDy's "
                      f"Cython code generation {g(m['pydy_codegen_s'])} s. The reference (DOP853, rtol 1e-12) took "
                      f"{m['reference']['nfev']:,} evaluations; its distance to rtol 1e-11: {g(m['reference']['self_error'])}. "
                      f"gnipy's continuous reference (Dopri8 on gnipy's equations) against it: {g(m['agreement'])}.")
    rep.close(sec)


#: issue 32's target: a bicycle step at most this many microseconds
TARGET_STEP_US = 5.0
#: the steps of the native run whose marginal cost per step is measured against it
STEP_S = 2000


def bicycle_targets(results: dict, how_far, g) -> list[list[str]]:
    """The summary rows of this section (see :func:`benchmarks.run.targets`)."""
    r = results.get("bicycle")
    if not r:
        return []
    rows = []
    for method, row in r["gnipy"].items():
        us = row["per_second"] / (1.0 / H) * 1e6
        met, far = how_far(us, TARGET_STEP_US, False)
        rows.append([f"Whipple bicycle step ≤ {TARGET_STEP_US:g} µs: {method} (XLA, in simulate)", f"{g(us)} µs/step",
                     met, far])
    if "native" in r:
        us = r["native"]["per_second"] / (1.0 / H) * 1e6
        met, far = how_far(us, TARGET_STEP_US, False)
        rows.append([f"Whipple bicycle step ≤ {TARGET_STEP_US:g} µs: dla (native, in simulate, with the call and "
                     f"{int(round(T / SAVE))} saved nodes a call)", f"{g(us)} µs/step", met, far])
        if "step_us" in r["native"]:
            us = r["native"]["step_us"]
            met, far = how_far(us, TARGET_STEP_US, False)
            rows.append([f"Whipple bicycle step ≤ {TARGET_STEP_US:g} µs: dla (native, in simulate, the marginal "
                         f"step over {STEP_S:,} steps)", f"{g(us)} µs/step", met, far])
    if "batch" in r:
        us = r["batch"]["per_second"] / (1.0 / H) * 1e6
        met, far = how_far(us, TARGET_STEP_US, False)
        rows.append([f"Whipple bicycle step ≤ {TARGET_STEP_US:g} µs: dla in a batch of {r['batch']['members']:,} "
                     f"(XLA, per member-step)", f"{g(us)} µs/step", met, far])
    ratio = r["pydy"]["per_second"] / r["gnipy"]["dla"]["per_second"]
    met, far = how_far(ratio, 1.0, True)
    rows.append(["gnipy (dla) faster than PyDy + DOP853 at matched accuracy: Whipple bicycle",
                 f"PyDy/gnipy = {g(ratio)}", met, far])
    if "native" in r:
        ratio = r["pydy"]["per_second"] / r["native"]["per_second"]
        met, far = how_far(ratio, 1.0, True)
        rows.append(["gnipy (dla, native) faster than PyDy + DOP853 at matched accuracy: Whipple bicycle",
                     f"PyDy/gnipy = {g(ratio)}", met, far])
    if "batch" in r:
        ratio = r["pydy"]["per_second"] / r["batch"]["per_second"]
        met, far = how_far(ratio, 1.0, True)
        rows.append([f"gnipy (dla, a batch of {r['batch']['members']:,}) faster per trajectory than PyDy + DOP853 "
                     f"at matched accuracy: Whipple bicycle", f"PyDy/gnipy = {g(ratio)}", met, far])
    return rows


def main() -> int:
    m = measure()
    for method, r in m["gnipy"].items():
        print(f"gnipy {method}: {r}")
    print(f"pydy: {m['pydy']}")
    print({k: v for k, v in m.items() if k not in ("gnipy", "pydy")})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
