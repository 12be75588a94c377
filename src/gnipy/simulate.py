"""The simulation driver :func:`simulate`: arguments checked, the run planned (:mod:`gnipy.saveat`)
and stepped by the one loop (:mod:`gnipy.stepping`), the result assembled (:class:`gnipy.Solution`).

Repeated calls are cheap: what depends only on the system, the method and the initial condition
(the checks, the method's preparation, the diagnostics' sentences) is kept per call signature
(:mod:`gnipy.preparation`), and the compiled programs are shared between runs whose numbers of
saved nodes fall in one bucket (:func:`gnipy.preparation.node_bucket`). Under a JAX transformation (`jax.grad`, `jax.jacrev`, `jax.jacfwd`, `jax.jit`;
:mod:`gnipy.transformed`) the run is differentiable: the loop has static trip counts in blocks
(checkpointed for long runs) and the implicit steps are differentiated by the implicit function
theorem. Batches of initial conditions or systems run vmapped (:mod:`gnipy.ensembles`).
"""

from __future__ import annotations

from .integrators.base import Integrator
from . import monitor
from .integration import solve
from .problem import Problem
from .run_arguments import (MAX_STEPS, MAX_TOTAL_STEPS, MIN_STEP_SIZE, default_initial_condition, resolve_run,
                            resolve_steps)
from .saveat import SaveAt
from .solution import Solution

__all__ = ["simulate", "resolve_steps", "resolve_run", "SaveAt", "MAX_STEPS", "MAX_TOTAL_STEPS", "MIN_STEP_SIZE",
           "default_initial_condition"]


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
            the method that qualifies on 16 of the 17 zoo models by the atlas's rule (`gni-trapezoid`
            fails it on the Chaplygin sleighs, Suslov and the differential-drive robot; the sgni let
            the robot's heading drift from its wheels' angles), or the next of
            `gnipy.registry.FALLBACK_METHODS` that can run the system.
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
            failure's member, step, time and residual). Under a JAX transformation, where `True`
            raises the failure at run time, `False` leaves the saved nodes after the failed step
            and the final state NaN instead: that is the only sign of it there (`sol.result` is
            fixed when the program is traced and says nothing of its run), and the compiled program
            has no host callback, so JAX's persistent cache can keep it. With `"strict"`, also raise
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
    its named parameters, :attr:`~gnipy.System.args`, are array leaves, replaced by
    `system.with_args(m=m)` inside the differentiated function; so are `jax.tree_util.Partial`
    arguments of its functions; see the systems guide). Under a transformation the run uses static trip counts in checkpointed blocks
    and the implicit steps' solves are differentiated by the implicit function theorem; `steps`
    must then be given (or `t_final` with a concrete `h`). Inside `jax.jit` the values of the
    initial condition cannot be checked (shapes are); a failed step raises at run time.

    Runs whose numbers of saved nodes fall in one bucket (16 or fewer; then quarter octaves,
    :func:`gnipy.preparation.node_bucket`) share their compiled program (the step count, h and
    the parameter values are traced): convergence studies and parameter scans compile once.

    Raises:
        InputError: bad arguments or initial conditions (the message names the argument and,
            in a batch, the member).
        MethodError: a method that cannot integrate this system.
        SolverFailure: a step did not converge (step index, time, residual in the message; in
            a batch, the first failing member).
    """
    problem = Problem.of(system, method, q0, v0, R0=R0, h=h, steps=steps, t_final=t_final, saveat=saveat,
                         save_every=save_every, t0=t0, state0=state0, project_v0=project_v0, throw=throw,
                         progress=progress, controls=controls, backend=backend, monitor0=monitor0,
                         check_every_node=check_every_node)
    sol = solve(problem)
    return sol if problem.traced else monitor.announce(sol, problem.strict)  # the warning names the caller
