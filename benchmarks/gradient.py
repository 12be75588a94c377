"""Reverse-mode gradient of a 10⁴-step rolling-ball run against the forward run (issue 13).

Run: `python benchmarks/gradient.py`. Prints the medians of 5 timings (after compilation) of the
forward run (`gnipy.simulate`, last node saved), the same run under `jax.jit` (the differentiable
loop, checkpointed blocks), and `jax.grad` of a scalar of the last node with respect to v0, their
ratio, and the peak resident memory of the process.
"""

import resource
import statistics
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


def main():
    system = gnipy.make_system("rolling-ball")
    q0, v0 = system.defaults[0], jnp.asarray(system.defaults[1])
    saveat = gnipy.SaveAt(t1=True)

    def loss(v):
        sol = gnipy.simulate(system, "gni-trapezoid", q0, v, h=0.01, steps=STEPS, saveat=saveat)
        return jnp.sum(sol.q[-1] ** 2) + jnp.sum(sol.R[-1, 0])

    forward = median_time(lambda: gnipy.simulate(system, "gni-trapezoid", q0, v0, h=0.01, steps=STEPS,
                                                 saveat=saveat).q)
    traced = median_time(lambda f=jax.jit(loss): f(v0))
    grad = median_time(lambda g=jax.jit(jax.grad(loss)): g(v0))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"rolling ball, gni-trapezoid, {STEPS} steps, h = 0.01")
    print(f"  forward run (simulate)            {forward * 1e3:8.2f} ms")
    print(f"  forward run under jax.jit         {traced * 1e3:8.2f} ms")
    print(f"  reverse-mode gradient (jax.grad)  {grad * 1e3:8.2f} ms   ratio to the forward run {grad / forward:.2f}")
    print(f"  peak resident memory of the process {peak:.0f} MiB")


if __name__ == "__main__":
    main()
