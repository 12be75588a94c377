"""One integrate: :func:`integrate` runs a :class:`gnipy.Problem`.

The run goes one of four ways, each to the one stepping loop (:mod:`gnipy.stepping`) and the one
assembly (:func:`gnipy.assembly.assemble`):

- one trajectory: prepared once per call signature (:mod:`gnipy.preparation`: the checks, the
  method's preparation, the diagnostics' sentences are kept), stepped by the native loop
  (:mod:`gnipy.native`) or XLA's;
- a batch of initial conditions or of systems: one vmapped program (:mod:`gnipy.ensembles`);
- under a JAX transformation: static trip counts in checkpointed blocks (:mod:`gnipy.transformed`);
- the continuous reference (:mod:`gnipy.reference`), which has no steps.

The backend (`problem.backend`) is chosen here, once, from the run's arguments
(:func:`gnipy.native.backend.choose`).
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp

from . import monitor
from .diagnostics import diagnostic_fields, energy_is_invariant, scheme_energy
from .problem import Problem
from .solution import Solution
from .stepping import Progress
from .system import describe_orientations

__all__ = ["integrate", "solve"]


def integrate(problem: Problem) -> Solution:
    """Run `problem` (:class:`gnipy.Problem`): the Solution, after a
    :class:`~gnipy.QualitativeFailureWarning` when its steps converged but a verdict left its band
    (raised as :class:`~gnipy.QualitativeFailure` when `problem.strict`). See :func:`gnipy.simulate`
    for what the Solution holds and what is raised."""
    sol = solve(problem)
    # under a transformation the verdicts cannot be read (the nodes are tracers): not announced
    return sol if problem.traced else monitor.announce(sol, problem.strict)


def solve(problem: Problem) -> Solution:
    """Run `problem` without announcing its verdicts (:func:`integrate` does): for drivers that
    announce once for a whole run made of several calls (streamed runs, sweeps)."""
    from .compilation import release_compiled_programs_if_needed
    from .native.backend import choose
    from .reference import ContinuousReference

    if not isinstance(problem, Problem):
        raise TypeError(f"problem: expected a gnipy.Problem, got {type(problem).__name__}")
    release_compiled_programs_if_needed()
    if problem.traced:
        from .transformed import simulate_traced

        if problem.backend == "native":
            choose(problem.backend, problem.system, problem.method, trajectory_steps=0, traced=True)  # the warning
        return simulate_traced(problem)
    reporter = Progress(problem.progress, problem.total_steps)
    if isinstance(problem.method, ContinuousReference):
        return _reference(problem, reporter)
    use, _ = choose(problem.backend, problem.system, problem.method,
                    trajectory_steps=problem.total_steps * (problem.batch_size or 1))
    if problem.batched:
        from .ensembles import simulate_batch

        with reporter:
            return simulate_batch(problem, reporter, use)
    return _single(problem, reporter, use)


def _reference(problem: Problem, reporter) -> Solution:
    """The continuous reference (it builds its Solution itself: :meth:`gnipy.reference.ContinuousReference.solve`)."""
    system = problem.system
    b0, v0 = system.check(problem.q0, problem.v0, R0=problem.R0, project_v0=problem.project_v0)
    with reporter:
        return problem.method.solve(system, b0, jnp.asarray(v0), problem.times, h=problem.h, t0=problem.t0)


def _single(problem: Problem, reporter, use: str) -> Solution:
    """One trajectory, prepared once per call signature, on the native loop or XLA's."""
    from .assembly import assemble, labels
    from .preparation import prepare

    system, h, partial, plan = problem.system, problem.h, problem.partial, problem.plan
    prep = prepare(system, problem.method, problem.q0, problem.v0, problem.R0, problem.project_v0, problem.state0)
    if "energy_invariant" not in prep.cache:  # set last: another thread finding it finds both
        prep.cache["orientation"] = describe_orientations([system])
        prep.cache["energy_invariant"] = energy_is_invariant(system, prep.b0)
    watch0 = monitor.start(problem.monitor0, problem.state0, h, problem.steps + partial, problem.t0,
                           prep.cache["energy_invariant"])
    args = (problem.state0, h, plan.lengths, plan.tail, partial * h, problem.times)
    kwargs = dict(partial=bool(partial), save_final=plan.save_final, save_states=problem.saveat.states)
    with reporter:
        out = None
        if use == "native":
            out = prep.run_native(*args, **kwargs, monitor0=watch0,
                                  progress_stride=reporter.stride if reporter.active else None)
            if out is None:
                use = "xla"
                if problem.backend == "native":
                    warnings.warn(f"backend='native': running on XLA, because the step does not lower: "
                                  f"{prep.cache['native']}", RuntimeWarning, stacklevel=4)
        if out is None:
            out = prep.run(*args, **kwargs, progress=reporter.active, progress_stride=reporter.stride,
                           monitor0=watch0 if problem.check_every_node else None)
        if reporter.active:
            jax.block_until_ready(out)
    key = ("labels", use, float(h))  # the run's labels depend on its start, method, h and backend only
    if key not in prep.cache:
        prep.cache[key] = labels(problem, prep.method, use) | {"orientation": prep.cache["orientation"]}
    fields = dict(prep.cache[key])
    fields |= diagnostic_fields(system, prep.core, prep.b0, (out["b"], out["v"], out["p"], out["hidden"]), h,
                                cached=prep.cache, prepared=(prep, out.get("padded"), out.get("diagnostics")),
                                scheme=scheme_energy(problem.method),
                                times=problem.times)
    return assemble(problem, out, fields)
