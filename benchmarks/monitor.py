"""Section 8 of the suite: what checking every node costs (issue 29, :mod:`gnipy.monitor`).

Every `simulate` run checks the verdicts (the GNI's hidden momentum against its O(h) band, a
conserved energy against its drift band) at every node, whatever is saved: the loop carries a
small vector and evaluates the node diagnostics (the continuous multiplier λ, a few solves in
$\\mathbb{G}$) before each step. This section times the same loop with and without that check,
on both backends: µs per step, the marginal cost (median(S) − median(1))/(S − 1) of S steps, each
loop compiled once and called `reps` times in this process (interleaved: a ratio is measured on
one machine state).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

#: (case of benchmarks.run.build, method)
MONITOR_CASES = (
    ("rolling_ball_ex2", "gni-trapezoid"),
    ("chaplygin_sphere", "gni-trapezoid"),
    ("contact_oscillator", "gni-midpoint"),
    ("chaplygin_sleigh", "dla"),
)


def _loops(system, method_name, q0, v0, h):
    """`{(backend, watched): run(S)}` for one case: the XLA loop (:func:`gnipy.stepping.run_nodes`)
    and the native loop, each with and without the monitor."""
    import jax
    import jax.numpy as jnp

    from gnipy import monitor
    from gnipy.methods import get_method
    from gnipy.native.backend import native_loop
    from gnipy.native.program import build_loop
    from gnipy.preparation import prepare
    from gnipy.stepping import initial_carry, loop_step, run_nodes

    prep = prepare(system, get_method(method_name), q0, v0, None, False, None)
    method, core = prep.method, prep.core
    state0 = method.init(core, prep.b0, jnp.asarray(prep.v0), h)
    watch0 = monitor.initial(h, h, 0.0)
    runs = {}
    for watched in (False, True):
        @jax.jit
        def xla(state, n, mon=watch0 if watched else None):
            return run_nodes(method, core, state, h, jnp.zeros(0, jnp.int32), n, h, partial=False,
                             save_final=False, monitor0=mon)["final_state"]

        runs[("xla", watched)] = lambda S, f=xla: jax.block_until_ready(f(state0, np.int32(S)))
    loop = native_loop(method, core, state0)  # the monitored loop that simulate runs
    leaves = [np.ravel(np.asarray(x, np.float64)) for x in jax.tree_util.tree_leaves(state0)]
    flat = np.concatenate(leaves)
    counters = np.array([0.0, -1.0, 0.0, 0.0, 0.0])
    bare = build_loop(loop_step(method, core), initial_carry(state0), h)
    carries = {True: np.concatenate([flat, counters, watch0]), False: np.concatenate([flat, counters])}
    for watched, lp in ((False, bare), (True, loop)):
        runs[("native", watched)] = lambda S, lp=lp, c=carries[watched]: lp.run(c, h, np.array([S], np.int32))
    return runs


def _per_step(run, S: int, reps: int) -> float:
    run(S)  # compile / warm
    big, one = [], []
    for _ in range(reps):
        t = time.perf_counter()
        run(S)
        big.append(time.perf_counter() - t)
        t = time.perf_counter()
        run(1)
        one.append(time.perf_counter() - t)
    return (statistics.median(big) - statistics.median(one)) / (S - 1) * 1e6


def bench_monitor(cfg, rep, results: dict, load) -> None:
    """The section: µs/step without and with the monitor, XLA and native, and the ratio."""
    from benchmarks.run import H, build, g, initial_state

    S = 20_000 if cfg.name == "full" else 4_000
    sec = rep.open(
        "monitor", "8. Checking every node: the cost of the verdicts (issue 29)",
        f"µs per step of the same loop without and with the every-node check ({S:,} steps, the marginal "
        f"cost (median(S) − median(1))/(S − 1), {cfg.reps} repetitions), h = {H}; ratio = with / without.",
        ["case", "method", "XLA bare", "XLA checked", "ratio", "native bare", "native checked", "ratio"],
        background_load=load)
    for name, method in MONITOR_CASES:
        with rep.case(sec, f"{name} {method}"):
            system, q0, v0 = build(name)
            q0, v0 = initial_state(system, q0, v0)
            runs = _loops(system, method, q0, v0, H)
            t = {k: _per_step(r, S, cfg.reps) for k, r in runs.items()}
            results.setdefault("monitor", {})[name] = t
            rep.row(sec, [name, method, g(t[("xla", False)]), g(t[("xla", True)]),
                          f"{t[('xla', True)] / t[('xla', False)]:.2f}", g(t[("native", False)]),
                          g(t[("native", True)]), f"{t[('native', True)] / t[('native', False)]:.2f}"],
                    f"{name} {method}: XLA {t[('xla', False)]:.3g} -> {t[('xla', True)]:.3g} µs/step, native "
                    f"{t[('native', False)]:.3g} -> {t[('native', True)]:.3g} µs/step")
    rep.close(sec)
