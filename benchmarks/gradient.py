"""Reverse-mode gradient of a 10⁴-step rolling-ball run against the forward run (issue 13).

Run: `python benchmarks/gradient.py`. In each of 5 fresh processes (the 2-core VM runs a process
fast or slow for its whole life), the medians of 5 timings after compilation of the forward run
(`gnipy.simulate`, last node saved), the same run under `jax.jit` (the differentiable loop), and
`jax.grad` of a scalar of the last node with respect to v0, with the steps' residuals kept (the
default at this length) and with the blocks checkpointed (forced); then the median over the
processes of each, the ratios to the forward run, and the largest peak resident memory.
"""

import json
import resource
import statistics
import subprocess
import sys
import time

import jax
import jax.numpy as jnp

import gnipy

STEPS = 10_000


def median_time(fn, repeat=5):
    fn()  # compile
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def measure():
    from gnipy import stepping

    system = gnipy.make_system("rolling-ball")
    q0, v0 = system.defaults[0], jnp.asarray(system.defaults[1])
    saveat = gnipy.SaveAt(t1=True)

    def loss(v):
        sol = gnipy.simulate(system, "gni-trapezoid", q0, v, h=0.01, steps=STEPS, saveat=saveat)
        return jnp.sum(sol.q[-1] ** 2) + jnp.sum(sol.R[-1, 0])

    out = {"forward": median_time(lambda: gnipy.simulate(system, "gni-trapezoid", q0, v0, h=0.01, steps=STEPS,
                                                         saveat=saveat).q)}
    out["jit"] = median_time(lambda f=jax.jit(loss): f(v0))
    out["grad"] = median_time(lambda g=jax.jit(jax.grad(loss)): g(v0))
    out["peak_kept"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    stepping.GRADIENT_MEMORY_BYTES = 0
    out["grad_checkpointed"] = median_time(lambda g=jax.jit(jax.grad(loss)): g(v0))
    return out


def main(processes: int = 5):
    if "--child" in sys.argv:
        print(json.dumps(measure()))
        return
    runs = [json.loads(subprocess.run([sys.executable, __file__, "--child"], check=True, capture_output=True,
                                      text=True).stdout.splitlines()[-1]) for _ in range(processes)]
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    fwd = med["forward"]
    print(f"rolling ball, gni-trapezoid, {STEPS} steps, h = 0.01; medians over {processes} fresh processes")
    print(f"  forward run (simulate)                     {fwd * 1e3:8.2f} ms")
    print(f"  forward run under jax.jit                  {med['jit'] * 1e3:8.2f} ms")
    print(f"  reverse-mode gradient, residuals kept      {med['grad'] * 1e3:8.2f} ms   ratio {med['grad'] / fwd:.2f}")
    print(f"  reverse-mode gradient, blocks checkpointed {med['grad_checkpointed'] * 1e3:8.2f} ms   ratio "
          f"{med['grad_checkpointed'] / fwd:.2f}")
    print(f"  peak resident memory (residuals kept)      {max(r['peak_kept'] for r in runs):.0f} MiB")
    print("  per process, gradient/forward: " + ", ".join(f"{r['grad'] / r['forward']:.2f}" for r in runs))


if __name__ == "__main__":
    main()
