"""The fixed cost of a repeated `gnipy.simulate` call (issue 13: ≤ 0.5 ms of overhead).

Run: `python benchmarks/overhead.py` (5 fresh processes, the 2-core VM running each fast or slow
for its whole life; the medians over them are printed; a few minutes on 2 cores).

A call's overhead is its wall time less the time its steps take: for a run of S steps,
`overhead = t(S) - S * per_step`, with `per_step` the slope between a 10 010-step and a 10-step run
that save only their last node. Each time is the median of 7 timed blocks of repeated calls with
the same system, method and initial condition (after a warm-up call that compiles), ending with
`jax.block_until_ready` on everything the Solution holds, so asynchronous work is counted.

Cases (rolling ball example 2, h = 0.01):
- `gni-trapezoid`, 10 steps, every node saved (the default): the GNI family also computes its
  hidden-momentum diagnostics at each saved node, counted as overhead here;
- `gni-trapezoid`, 10 steps, last node only (`SaveAt(t1=True)`);
- `dla` (no hidden momentum), 10 steps, every node saved.
"""

import json
import statistics
import subprocess
import sys
import time

import jax

import gnipy

CALLS = 500
BLOCKS = 7


def _ready(sol):
    jax.block_until_ready([x for x in (sol.q, sol.v, sol.p, sol.energy, sol.hidden_momentum, sol.energy_plus)
                           if x is not None])


def per_call(fn, calls: int = CALLS) -> float:
    """Median over BLOCKS blocks of the mean wall time of `calls` calls, in seconds."""
    _ready(fn())
    times = []
    for _ in range(BLOCKS):
        t = time.perf_counter()
        for _ in range(calls):
            sol = fn()
        _ready(sol)
        times.append((time.perf_counter() - t) / calls)
    return statistics.median(times)


def measure() -> list:
    system = gnipy.make_system("rolling-ball")
    last = gnipy.SaveAt(t1=True)
    rows = []
    for method in ("gni-trapezoid", "dla"):
        m = gnipy.get_method(method)
        short = per_call(lambda m=m: gnipy.simulate(system, m, h=0.01, steps=10, saveat=last))
        long = per_call(lambda m=m: gnipy.simulate(system, m, h=0.01, steps=10_010, saveat=last), 10)
        step = (long - short) / 10_000
        every = per_call(lambda m=m: gnipy.simulate(system, m, h=0.01, steps=10))
        rows.append((method, step, every - 10 * step, short - 10 * step))
    return rows


def main(processes: int = 5):
    if "--child" in sys.argv:
        print(json.dumps(measure()))
        return
    runs = [json.loads(subprocess.run([sys.executable, __file__, "--child"], check=True, capture_output=True,
                                      text=True).stdout.splitlines()[-1]) for _ in range(processes)]
    print(f"repeated gnipy.simulate calls, rolling ball example 2, h = 0.01 (per process: median of {BLOCKS} "
          f"blocks of {CALLS} calls; medians over {processes} fresh processes)")
    for i, (method, *_) in enumerate(runs[0]):
        step, every, short = (statistics.median(r[i][j] for r in runs) for j in (1, 2, 3))
        print(f"  {method:14s} per step {step * 1e6:6.2f} us | overhead, 10 steps, every node saved "
              f"{every * 1e3:6.3f} ms | last node only {short * 1e3:6.3f} ms")


if __name__ == "__main__":
    main()
