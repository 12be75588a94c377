"""The simulation driver :func:`simulate`: arguments checked, the run planned (:mod:`gnipy.saveat`)
and stepped by the one loop (:mod:`gnipy.stepping`), the result assembled (:class:`gnipy.Solution`).

Repeated calls are cheap: what depends only on the system, the method and the initial condition
(the checks, the method's preparation, the diagnostics' sentences) is kept per call signature
(:mod:`gnipy.preparation`), and the compiled programs are shared between runs that save as many
nodes. Under a JAX transformation (`jax.grad`, `jax.jacrev`, `jax.jacfwd`, `jax.jit`;
:mod:`gnipy.transformed`) the run is differentiable: the loop has static trip counts in blocks
(checkpointed for long runs) and the implicit steps are differentiated by the implicit function
theorem. Batches of initial conditions or systems run vmapped (:mod:`gnipy.ensembles`).
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .errors import InputError, MethodError, SolverFailure
from .inputs import concrete_value, flag, is_traced, positive_integer
from .integrators.base import Integrator
from .integrators.reversal import backward
from .saveat import SaveAt, schedule
from .solution import RESULTS, Solution
from .ensembles import is_batch, simulate_batch
from .preparation import prepare
from .stepping import Progress
from . import monitor
from .diagnostics import DIAGNOSTIC_ARRAYS, diagnostic_fields, energy_is_invariant
from .forcing import check_forced_run, drive
from .system import System, describe_orientations
from .run_arguments import (MAX_STEPS, MAX_TOTAL_STEPS, MIN_STEP_SIZE, default_initial_condition, real_argument,
                            resolve_run, resolve_steps)
from .transformed import simulate_traced

__all__ = ["simulate", "resolve_steps", "resolve_run", "SaveAt", "MAX_STEPS", "MAX_TOTAL_STEPS", "MIN_STEP_SIZE",
           "default_initial_condition"]


def _check_same_system(systems) -> None:
    """A sequence of systems is a parameter batch: the same system with other parameter values.
    Members whose dimensions or group differ are refused here, naming the first such member, before
    their initial conditions are stacked (the full check of their structure is
    :func:`gnipy.ensembles.stack_systems`)."""
    def kind(s):
        return (s.n, s.dim, None if s.group is None else type(s.group).__name__)

    def say(s):
        k = kind(s)
        return f"{s.name or 'an unnamed system'!r} (n = {k[0]}, {k[1]} velocities, group {k[2] or 'none'})"

    for i, s in enumerate(systems[1:], 1):
        if kind(s) != kind(systems[0]):
            raise InputError(f"system[{i}]: is {say(s)}, system[0] is {say(systems[0])}; a sequence of systems is "
                             "a parameter batch (the same system with other parameter values): run different systems "
                             "in separate calls")


def simulate(
    system,
    method: Integrator | str | None = None,
    q0=None,
    v0=None,
    *,
    R0=None,
    h,
    steps: int | None = None,
    t_final: float | None = None,
    saveat: SaveAt | None = None,
    save_every: int | None = None,
    t0: float = 0.0,
    state0=None,
    project_v0: bool = False,
    throw: bool = True,
    progress=False,
    controls=None,
    backend: str = "auto",
    monitor0=None,
    check_every_node: bool = True,
) -> Solution:
    """Integrate a nonholonomic system, or an ensemble of them.

    Arguments:
        system: the :class:`~gnipy.System`; or a sequence of Systems that differ only in parameter
            values (a parameter batch, e.g. :func:`gnipy.model_systems`).
        method: an integrator object (e.g. `GNI(Midpoint())`) or a method name (see
            :func:`~gnipy.method_names`), including `"reference"` for the continuous reference.
            Default: for a system the zoo built, its model's measured default
            (`gnipy.get_model(system.model).default_method`, shown by `gni models`); for other
            systems (a System written by hand, whatever its `name`) `"sgni-trapezoid"` (`gnipy.registry.FALLBACK_METHOD`),
            the method that qualifies on every zoo model by the atlas's rule (`gni-trapezoid` fails it
            on the Chaplygin sleighs and Suslov), or the next of `gnipy.registry.FALLBACK_METHODS`
            that can run the system.
        q0, v0: the initial coordinates and velocity (default: the system's documented ones); on
            $\\mathbb{R}^n \\times G$, `q0` holds x and `v0` the velocity $(\\dot x, \\xi)$.
            Arrays with a leading batch axis, (B, n) and (B, N), run B trajectories at once.
        R0: the initial orientation on $\\mathbb{R}^n \\times G$ (default: the system's, or the
            identity); (k, k), or (B, k, k) for a batch.
        h: step size; h < 0 runs backward in time (`t_final` before `t0`): a method symmetric on
            the system (`method.symmetric_on(system)`) then runs its exact inverse
            $\\sigma\\circ\\Phi_{h}\\circ\\sigma$ (:mod:`gnipy.integrators.reversal`), so that N steps
            forward and N back return to the start to round-off. Any other method is refused with an
            :class:`~gnipy.InputError` (`h: ...`) that lists the methods symmetric on the system
            (its formula at h < 0 is not the inverse of its forward steps); under `jax.jit`, with a
            traced h of unknown sign, its steps fail at run time if h is negative. The continuous
            `"reference"` integrates backward directly.
        steps / t_final: the number of steps, or the final time. When `t_final - t0` is not a
            whole number of steps, the last step is shortened to end at `t_final` where the method
            allows it (`method.can_change_step`: the GNI family rescales its hidden impulse to
            the new step); other methods raise an error that says how to choose h.
        saveat: which nodes to save, a :class:`~gnipy.SaveAt` (every K steps, given times, first
            and/or last, every node; optionally the integrator states). Default: every node.
        save_every: shorthand for `saveat=SaveAt(every=save_every)`.
        t0: initial time.
        state0: start from this integrator state (`Solution.final_state` of an earlier run of the
            same method and system) instead of `q0, v0`; with `t0` its time. A long run is then a
            loop of calls: `sol = simulate(..., state0=sol.final_state, t0=float(sol.t[-1]))`.
        project_v0: project `v0` onto the constraints instead of raising when it violates them.
        throw: raise :class:`~gnipy.SolverFailure` if a step fails; with `False`, return the
            solution up to the last good saved node with `result = RESULTS.solve_failed` (in a batch:
            a failed member's nodes after its failure are NaN; :meth:`Solution.failures` gives each
            failure's member, step, time and residual). With `"strict"`, also raise
            :class:`~gnipy.QualitativeFailure` when the steps converged but the motion went
            qualitatively wrong (see Returns).
        progress: `True` shows a progress bar (rich) updated as the steps advance; a callable is
            called as `progress(steps_done, steps_total)` instead.
        controls: the inputs u of a forced system with inputs (`System(..., force=F, inputs=m)`,
            :mod:`gnipy.forcing`): an array (steps, m) of per-step values, held over each step
            (zero-order hold; (steps,) when m = 1), or a function `u(t)` -> (m,). Differentiable
            like the other arguments (the gradient of a cost with respect to the controls is how
            :func:`gnipy.control.solve_optimal_control` steers). A forced system runs forward in
            time (h > 0); a batch of initial conditions shares its controls, and a sequence of
            forced systems (a parameter batch) is refused.
        backend: which compiler runs the step loop: `"xla"` (JAX's), `"native"` (the method's step
            compiled to scalar machine code by LLVM, :mod:`gnipy.native`; 8–10× faster per step on
            the CPU, the same results to round-off) or `"auto"` (default: native on the CPU for runs
            of at least :data:`gnipy.native.backend.NATIVE_MIN_STEPS` trajectory-steps, when the
            step lowers; otherwise XLA). Forced systems and runs under a JAX transformation
            (gradients) run on XLA. `Solution.backend` says which ran.
        monitor0: with `state0`, the final `Solution.monitor` of the run this call continues, so
            that the verdicts (:mod:`gnipy.monitor`: every node checked) are those of the whole
            run rather than of this call alone.
        check_every_node: check the verdicts at every node (the default). `False` checks the saved
            nodes only, on XLA (the native loop always checks every node): the check is then not
            compiled into the loop (0.5-2.5 s per GNI-family program) nor run (BENCHMARKS.md), a
            failure between saved nodes can be missed, and `sol.health` says so.

    Returns:
        A :class:`~gnipy.Solution` (`sol.success`, `sol.result`, `sol.message` say how it ended). For a
        batch (B members: the batch size of the systems and of the initial conditions, which
        broadcast against each other) the arrays carry a leading member axis, `sol.member(i)` is
        the i-th trajectory, and `sol.results`, `sol.failed_steps` hold each member's result code and
        failed step.

        Every node of the run is checked, whatever is saved (:mod:`gnipy.monitor`): when the
        steps converged but a verdict left its band (the GNI's hidden momentum outside its O(h)
        band, a conserved energy drifting away; :mod:`gnipy.diagnostics`), a
        :class:`~gnipy.QualitativeFailureWarning` names the time, the quantity and what to use
        instead, and `sol.healthy` is False (`sol.success` says only that every step converged).

    **Differentiation.** `jax.grad`, `jax.jacrev` and `jax.jacfwd` of a function of the solution
    work with respect to `q0`, `v0`, `h`, `t0` and the system's parameters (a System is a pytree:
    its parameters are array leaves of its functions, e.g. `jax.tree_util.Partial` arguments; a
    model's are reached by building the system inside the differentiated function, see the
    systems guide). Under a transformation the run uses static trip counts in checkpointed blocks
    and the implicit steps' solves are differentiated by the implicit function theorem; `steps`
    must then be given (or `t_final` with a concrete `h`). Inside `jax.jit` the values of the
    initial condition cannot be checked (shapes are); a failed step raises at run time.

    Runs that save as many nodes share their compiled program (the step count, h and the
    parameter values are traced): convergence studies and parameter scans compile once.

    Raises:
        InputError: bad arguments or initial conditions (the message names the argument and,
            in a batch, the member).
        MethodError: a method that cannot integrate this system.
        SolverFailure: a step did not converge (step index, time, residual in the message; in
            a batch, the first failing member).
    """
    from .compilation import release_compiled_programs_if_needed
    from .reference import ContinuousReference

    release_compiled_programs_if_needed()
    from .native.backend import check_backend

    backend = check_backend(backend)
    project_v0 = flag("project_v0", project_v0)
    strict = isinstance(throw, str) and throw == "strict"
    if not strict and not isinstance(throw, (bool, np.bool_)):
        raise InputError(f"throw: expected True, False or 'strict', got {throw!r}")
    throw = True if strict else bool(throw)
    systems = None
    if isinstance(system, (list, tuple)):
        systems = list(system)
        if not systems:
            raise InputError("system: an empty sequence of systems")
        if not all(isinstance(s, System) for s in systems):
            bad = next(i for i, s in enumerate(systems) if not isinstance(s, System))
            raise InputError(f"system[{bad}]: expected a gnipy.System, got {type(systems[bad]).__name__}")
        system = systems[0]
        _check_same_system(systems)
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System or a sequence of them, got {type(system).__name__}")
    method = _method(system, method)
    if saveat is not None and save_every is not None:
        raise InputError("saveat/save_every: give one of them (save_every=K is saveat=SaveAt(every=K))")
    if saveat is None:
        saveat = SaveAt(every=1 if save_every is None else positive_integer("save_every", save_every))
    elif not isinstance(saveat, SaveAt):
        raise InputError(f"saveat: expected a gnipy.SaveAt, got {type(saveat).__name__}")
    if progress is not False and progress is not None and progress is not True and not callable(progress):
        raise InputError(f"progress: expected True, False or a callable(steps_done, steps_total), got {progress!r}")
    if systems is None and system.is_forced:
        if controls is None and system.inputs:
            drive(system, controls, 1.0, 0.0, None)  # the error that names `controls`
    elif controls is not None:
        raise InputError(
            "controls: the system has no force to drive (give System(..., force=F, inputs=m) or system.with_force(F, m))"
            if systems is None else "controls: batches of forced systems are not supported; run the members one at a time")
    elif systems is not None and any(s.is_forced for s in systems):
        raise InputError("system: batches of forced systems are not supported; run the members one at a time")

    traced = is_traced(system if systems is None else systems, q0, v0, R0, h, t0, state0,
                     None if callable(controls) else controls)
    if traced:
        if system.is_forced:
            system = drive(system, controls, h, t0, steps)
            # the checks of an untransformed call, where the values are known at trace time
            h_c, t0_c = concrete_value(h), concrete_value(t0)
            if h_c is not None and t0_c is not None:
                _, n_c, part_c = resolve_run(h_c, steps, t_final, float(t0_c), backward=True)
                check_forced_run(system, float(h_c), n_c + (1 if part_c else 0))

        method = backward(method, h, system)
        if backend == "native":
            from .native.backend import choose

            choose(backend, system, method, trajectory_steps=0, traced=True)  # the warning: XLA runs
        return simulate_traced(system, systems, method, q0, v0, R0, h, steps, t_final, saveat, t0, state0,
                                project_v0, throw)

    t0 = real_argument("t0", t0, positive=False)
    h, n, partial = resolve_run(h, steps, t_final, t0, backward=True)
    if system.is_forced:
        system = drive(system, controls, h, t0, None)
        check_forced_run(system, h, n + (1 if partial else 0))
    method = backward(method, h, system)
    if n > MAX_STEPS:
        raise InputError(
            f"steps: at most {MAX_STEPS} steps per call (the step counters are int32), got {n}; "
            "continue the run from sol.final_state (state0=), or stream it with gnipy.simulate_to_file"
        )
    if partial and not getattr(method, "can_change_step", isinstance(method, ContinuousReference)):
        raise InputError(
            f"t_final: t_final - t0 is {n + partial:.6g} steps of h = {h!r}, and {method.name} cannot shorten its last "
            f"step; choose h = {(t_final - t0) / (n + 1)!r} ({n + 1} steps) or t_final = {t0 + (n + 1) * h!r}"
        )
    plan = schedule(saveat, n, partial, h=h, t0=t0)
    times = plan.times(t0, h)

    if state0 is not None and (q0 is not None or v0 is not None or R0 is not None):
        raise InputError("state0: give either state0 or the initial condition q0/v0/R0, not both")
    q0, v0, R0 = (q0, v0, R0) if state0 is not None else default_initial_condition(
        systems if systems and len(systems) > 1 else system, q0, v0, R0)
    meta = dict(system=system.name, method=method.name, h=h, coordinates=system.coordinates,
                velocities=system.velocities, params=system.params,
                start=getattr(method, "start_label", "continuous"),
                method_settings=tuple(method.settings().items()) if isinstance(method, Integrator) else ())
    reporter = Progress(progress, n + (1 if partial else 0))
    from .native.backend import choose

    B = None if state0 is not None else _batch_size(systems, system, q0, v0, R0)
    use, _ = choose(backend, system, method, trajectory_steps=(n + (1 if partial else 0)) * (B or 1))
    meta["backend"] = use

    batched = systems is not None or (state0 is None and is_batch(system, q0, v0, R0))
    if batched or isinstance(method, ContinuousReference):
        meta["orientation"] = describe_orientations(systems or [system])
    if isinstance(method, ContinuousReference):
        if batched:
            raise MethodError("method: the continuous reference runs one trajectory at a time; pass one system and one initial condition")
        if state0 is not None or saveat.states:
            raise MethodError("method: the continuous reference has no integrator state (state0, saveat.states)")
        b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
        with reporter:
            sol = method.solve(system, b0, jnp.asarray(v0), times, h=h, t0=t0)
        return monitor.announce(sol, strict)
    if batched:
        if state0 is not None:
            raise InputError("state0: continuing from a state is for single trajectories")
        if monitor0 is not None:
            raise InputError("monitor0: continuing a run's verdicts is for single trajectories (with state0)")
        with reporter:
            sol = simulate_batch(systems or [system], method, q0, v0, R0, h, n, partial, plan, times, t0, project_v0,
                                 throw, meta, reporter, backend, flag("check_every_node", check_every_node))
        return monitor.announce(sol, strict)

    prep = prepare(system, method, q0, v0, R0, project_v0, state0)
    if "orientation" not in prep.cache:
        prep.cache["orientation"] = describe_orientations([system])
        prep.cache["energy_invariant"] = energy_is_invariant(system, prep.b0)
    meta["orientation"] = prep.cache["orientation"]
    meta["method_settings"] = tuple(prep.method.settings().items())  # prepared: e.g. whether the step is explicit
    watch0 = monitor.start(monitor0, state0, h, n + partial, t0, prep.cache["energy_invariant"])
    every = flag("check_every_node", check_every_node)
    with reporter:
        out = None
        if use == "native":
            out = prep.run_native(state0, h, plan.lengths, plan.tail, partial * h, times, partial=bool(partial),
                                  save_final=plan.save_final, save_states=saveat.states, monitor0=watch0,
                                  progress_stride=reporter.stride if reporter.active else None)
            if out is None:
                meta["backend"] = "xla"
                if backend == "native":
                    warnings.warn(f"backend='native': running on XLA, because the step does not lower: "
                                  f"{prep.cache['native']}", RuntimeWarning, stacklevel=2)
        if out is None:
            out = prep.run(state0, h, plan.lengths, plan.tail, partial * h, times, partial=bool(partial),
                           save_final=plan.save_final, save_states=saveat.states, progress=reporter.active,
                           progress_stride=reporter.stride, monitor0=watch0 if every else None)
        if reporter.active:
            jax.block_until_ready(out)
    meta |= diagnostic_fields(system, prep.core, prep.b0, (out["b"], out["v"], out["p"], out["hidden"]), h,
                             cached=prep.cache, prepared=(prep, out.get("padded")),
                             conserves_energy=bool(getattr(method, "conserves_energy", False)), times=times)
    fail_k = int(out["fail_k"])
    q = out["q"]
    common = dict(iterations=out["iterations"], R=out["R"], final_state=out["final_state"], states=out["states"],
                  monitor=None if out["monitor"] is None else np.asarray(out["monitor"]), **meta)
    if fail_k < 0:
        return monitor.announce(Solution.of(t=out["t"], q=q, v=out["v"], p=out["p"], energy=out["energy"],
                                    constraint_residual=out["residual"], **common), strict)
    good = int(np.searchsorted(np.asarray(plan.nodes), fail_k, side="right"))  # saved nodes with index <= fail_k
    cut = {k: (None if common.get(k) is None else jax.tree_util.tree_map(lambda a: a[:good], common[k]))
           for k in ("R", "states", *DIAGNOSTIC_ARRAYS)}
    fail_res = float(out["fail_res"])
    partial_sol = Solution(
        jnp.asarray(times[:good]), q[:good], out["v"][:good], out["p"][:good], out["energy"][:good],
        out["residual"][:good], **(common | cut), result=RESULTS.solve_failed, failed_step=fail_k,
        failed_residual=fail_res,
    )
    t_fail = float(times[-1]) if fail_k >= n else t0 + h * fail_k
    t_next = t0 + h * (n + partial) if fail_k >= n else t_fail + h
    msg = (f"{method.name}: step {fail_k} (t = {t_fail:.6g} -> {t_next:.6g}) failed: "
           f"{RESULTS.solve_failed.message} (residual {fail_res:.3e})")
    if throw:
        raise SolverFailure(msg, step=fail_k, time=t_fail, residual=fail_res, solution=partial_sol)
    return partial_sol


def _batch_size(systems, system, q0, v0, R0) -> int | None:
    """The number of members of a batched run (None for one trajectory)."""
    if systems is not None and len(systems) > 1:
        return len(systems)
    if not is_batch(system, q0, v0, R0):
        return None
    sizes = [np.shape(x)[0] for x in (q0, v0) if x is not None and np.ndim(x) == 2]
    if R0 is not None and np.ndim(R0) == 3:
        sizes.append(np.shape(R0)[0])
    return max(sizes, default=1)


def _method(system, method):
    from .methods import get_method
    from .reference import ContinuousReference

    if method is None:
        from .registry import default_method_for

        method = default_method_for(system.model, system)
    if isinstance(method, str):
        method = get_method(method)
    if not isinstance(method, (Integrator, ContinuousReference)):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    return method
