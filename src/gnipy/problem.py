"""One run, checked once: :class:`Problem`.

A :class:`Problem` is what :func:`gnipy.simulate` is asked to do, validated in one place (every
argument named in its error) and resolved: the system (driven by its controls when forced), the
method (its exact inverse when h < 0), the initial condition (the system's documented one where
none is given), the time grid (`steps` full steps of `h` and a shortened last step), the save
plan (:mod:`gnipy.saveat`), what to do on failure, the backend asked for. :func:`gnipy.integrate`
runs it; `simulate(system, method, q0, v0, h=..., ...)` is `integrate(Problem.of(system, method,
q0, v0, h=..., ...))`. Streamed runs (:func:`gnipy.simulate_to_file`) run their chunks as
Problems; sweeps, fits and control run theirs through :func:`gnipy.simulate`.

A Problem is frozen: build another with :meth:`Problem.of` (or `dataclasses.replace` for a field
that needs no new check, such as `progress`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .errors import InputError, MethodError
from .inputs import concrete_value, flag, is_traced, positive_integer
from .integrators.base import Integrator
from .integrators.reversal import backward
from .run_arguments import (MAX_STEPS, default_initial_condition, real_argument, resolve_run, whole_steps)
from .saveat import SaveAt, Schedule, schedule
from .system import System

__all__ = ["Problem", "resolve_method"]


@dataclasses.dataclass(frozen=True, eq=False)
class Problem:
    """A run of :func:`gnipy.integrate`, every argument checked (build it with :meth:`of`).

    Attributes:
        system: the System that runs (driven by `controls` when forced; the first member of a
            parameter batch).
        systems: the members of a parameter batch (a sequence of Systems that differ only in
            parameter values), or None for one system.
        method: the integrator that runs (for h < 0 its exact inverse,
            :func:`gnipy.integrators.reversal.backward`), or the continuous reference.
        q0, v0, R0: the initial condition, the system's documented defaults filling what was not
            given (None with `state0`); arrays with a leading axis for a batch.
        state0: the integrator state the run continues from, or None.
        h: the step size (a tracer under a JAX transformation).
        steps: the number of full steps.
        partial: the shortened last step as a fraction of h (0 when there is none).
        t0: the initial time.
        saveat: which nodes are saved.
        plan: the saved nodes (:class:`gnipy.saveat.Schedule`).
        times: the saved nodes' times (None under a transformation: they are computed in the run).
        project_v0: project v0 onto the constraints instead of refusing it.
        throw: raise :class:`~gnipy.SolverFailure` when a step fails.
        strict: also raise :class:`~gnipy.QualitativeFailure` when the verdicts leave their bands.
        progress: False/None, True (a progress bar) or a callable(steps_done, steps_total).
        backend: the backend asked for: "auto", "xla" or "native".
        monitor0: the verdicts of the run `state0` ends (with `state0`), or None.
        check_every_node: check the verdicts at every node (True) or at the saved nodes.
        traced: the run is under a JAX transformation (`jax.grad`, `jax.jit`, ...).
        batch_size: the number of members of a batch, or None for one trajectory.
    """

    system: System
    systems: tuple[System, ...] | None
    method: Any
    q0: Any
    v0: Any
    R0: Any
    state0: Any
    h: Any
    steps: int
    partial: float
    t0: Any
    saveat: SaveAt
    plan: Schedule
    times: np.ndarray | None
    project_v0: bool
    throw: bool
    strict: bool
    progress: Any
    backend: str
    monitor0: Any
    check_every_node: bool
    traced: bool
    batch_size: int | None

    @property
    def total_steps(self) -> int:
        """The steps of the run, the shortened last one included."""
        return self.steps + (1 if self.partial else 0)

    @property
    def batched(self) -> bool:
        """Whether the run is a batch (of initial conditions or of systems)."""
        return self.batch_size is not None

    @classmethod
    def of(cls, system, method=None, q0=None, v0=None, *, R0=None, h, steps=None, t_final=None, saveat=None,
           save_every=None, t0=0.0, state0=None, project_v0=False, throw=True, progress=False, controls=None,
           backend="auto", monitor0=None, check_every_node=True) -> "Problem":
        """The Problem of `simulate(system, method, q0, v0, ...)`, with the same arguments and
        defaults (documented there); every argument checked here, errors naming it."""
        from .native.backend import check_backend

        backend = check_backend(backend)
        project_v0 = flag("project_v0", project_v0)
        strict, throw = _throw(throw)
        system, systems = _systems(system)
        method = resolve_method(system, method)
        saveat = _saveat(saveat, save_every)
        if progress is not False and progress is not None and progress is not True and not callable(progress):
            raise InputError(f"progress: expected True, False or a callable(steps_done, steps_total), got {progress!r}")
        _check_controls(system, systems, controls)
        every = flag("check_every_node", check_every_node)
        common = dict(saveat=saveat, project_v0=project_v0, throw=throw, strict=strict, progress=progress,
                      backend=backend, monitor0=monitor0, check_every_node=every)
        if is_traced(system if systems is None else systems, q0, v0, R0, h, t0, state0,
                     None if callable(controls) else controls):
            return _traced(system, systems, method, q0, v0, R0, h, steps, t_final, t0, state0, controls, common)
        return _concrete(system, systems, method, q0, v0, R0, h, steps, t_final, t0, state0, controls, common)


def _throw(throw) -> tuple[bool, bool]:
    """`(strict, throw)` from the `throw` argument."""
    strict = isinstance(throw, str) and throw == "strict"
    if not strict and not isinstance(throw, (bool, np.bool_)):
        raise InputError(f"throw: expected True, False or 'strict', got {throw!r}")
    return strict, True if strict else bool(throw)


def _systems(system) -> tuple[System, tuple[System, ...] | None]:
    """`(system, systems)`: the system that runs and the members of a parameter batch (None for one
    system). Members whose dimensions or group differ are refused here, naming the first such
    member, before their initial conditions are stacked (the full check of their structure is
    :func:`gnipy.ensembles.stack_systems`)."""
    if isinstance(system, (list, tuple)):
        systems = tuple(system)
        if not systems:
            raise InputError("system: an empty sequence of systems")
        if not all(isinstance(s, System) for s in systems):
            bad = next(i for i, s in enumerate(systems) if not isinstance(s, System))
            raise InputError(f"system[{bad}]: expected a gnipy.System, got {type(systems[bad]).__name__}")

        def kind(s):
            return (s.n, s.dim, None if s.group is None else type(s.group).__name__)

        def say(s):
            k = kind(s)
            return f"{s.name or 'an unnamed system'!r} (n = {k[0]}, {k[1]} velocities, group {k[2] or 'none'})"

        for i, s in enumerate(systems[1:], 1):
            if kind(s) != kind(systems[0]):
                raise InputError(f"system[{i}]: is {say(s)}, system[0] is {say(systems[0])}; a sequence of systems "
                                 "is a parameter batch (the same system with other parameter values): run different "
                                 "systems in separate calls")
        return systems[0], systems
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System or a sequence of them, got {type(system).__name__}")
    return system, None


def resolve_method(system, method):
    """The method object of a run of `system`: `method` itself (an integrator or the continuous
    reference), the one it names, or the system's default when None (its model's measured default,
    :func:`gnipy.registry.default_method_for`); :class:`~gnipy.MethodError` naming `method` otherwise."""
    from .methods import shared_method
    from .reference import ContinuousReference

    if method is None:
        from .registry import default_method_for

        method = default_method_for(system.model, system)
    if isinstance(method, str):
        method = shared_method(method)
    if not isinstance(method, (Integrator, ContinuousReference)):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    return method


def _saveat(saveat, save_every) -> SaveAt:
    if saveat is not None and save_every is not None:
        raise InputError("saveat/save_every: give one of them (save_every=K is saveat=SaveAt(every=K))")
    if saveat is None:
        return SaveAt(every=1 if save_every is None else positive_integer("save_every", save_every))
    if not isinstance(saveat, SaveAt):
        raise InputError(f"saveat: expected a gnipy.SaveAt, got {type(saveat).__name__}")
    return saveat


def _check_controls(system, systems, controls) -> None:
    """Controls are for one forced system with inputs, and required there."""
    from .forcing import drive

    if systems is None and system.is_forced:
        if controls is None and system.inputs:
            drive(system, controls, 1.0, 0.0, None)  # the error that names `controls`
    elif controls is not None:
        raise InputError(
            "controls: the system has no force to drive (give System(..., force=F, inputs=m) or system.with_force(F, m))"
            if systems is None else "controls: batches of forced systems are not supported; run the members one at a time")
    elif systems is not None and any(s.is_forced for s in systems):
        raise InputError("system: batches of forced systems are not supported; run the members one at a time")


def _concrete(system, systems, method, q0, v0, R0, h, steps, t_final, t0, state0, controls, common) -> Problem:
    """The Problem of a run outside JAX transformations: every value known and checked."""
    from .ensembles import is_batch
    from .forcing import check_forced_run, drive
    from .reference import ContinuousReference

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
    reference = isinstance(method, ContinuousReference)
    if partial and not getattr(method, "can_change_step", reference):
        raise InputError(
            f"t_final: t_final - t0 is {n + partial:.6g} steps of h = {h!r}, and {method.name} cannot shorten its last "
            f"step; choose h = {(t_final - t0) / (n + 1)!r} ({n + 1} steps) or t_final = {t0 + (n + 1) * h!r}"
        )
    saveat = common["saveat"]
    plan = schedule(saveat, n, partial, h=h, t0=t0)
    if state0 is not None and (q0 is not None or v0 is not None or R0 is not None):
        raise InputError("state0: give either state0 or the initial condition q0/v0/R0, not both")
    if state0 is not None and hasattr(method, "continue_from"):
        state0 = method.continue_from(system, state0)  # e.g. a batch member's state (no kept Jacobian)
    if state0 is None:
        q0, v0, R0 = default_initial_condition(systems if systems and len(systems) > 1 else system, q0, v0, R0)
    batched = systems is not None or (state0 is None and is_batch(system, q0, v0, R0))
    _check_continuation(reference, batched, state0, saveat, common["monitor0"])
    return Problem(system=system, systems=systems, method=method, q0=q0, v0=v0, R0=R0, state0=state0, h=h, steps=n,
                   partial=partial, t0=t0, plan=plan, times=plan.times(t0, h), traced=False,
                   batch_size=_batch_size(systems, system, q0, v0, R0) if batched else None, **common)


def _check_continuation(reference: bool, batched: bool, state0, saveat: SaveAt, monitor0) -> None:
    """A run continued from a state (`state0`, `monitor0`) is one trajectory of an integrator; the
    continuous reference runs one trajectory and has no integrator state."""
    if reference:
        if batched:
            raise MethodError("method: the continuous reference runs one trajectory at a time; pass one system and one initial condition")
        if state0 is not None or saveat.states:
            raise MethodError("method: the continuous reference has no integrator state (state0, saveat.states)")
    if batched:
        if state0 is not None:
            raise InputError("state0: continuing from a state is for single trajectories")
        if monitor0 is not None:
            raise InputError("monitor0: continuing a run's verdicts is for single trajectories (with state0)")


def _batch_size(systems, system, q0, v0, R0) -> int:
    """The number of members of a batched run."""
    if systems is not None and len(systems) > 1:
        return len(systems)
    sizes = [np.shape(x)[0] for x in (q0, v0) if x is not None and np.ndim(x) == 2]
    if R0 is not None and np.ndim(R0) == 3:
        sizes.append(np.shape(R0)[0])
    return max(sizes, default=1)


def _traced(system, systems, method, q0, v0, R0, h, steps, t_final, t0, state0, controls, common) -> Problem:
    """The Problem of a run under a JAX transformation: the values are checked where they are
    known at trace time (`jax.grad` outside `jit`); shapes otherwise."""
    from .forcing import check_forced_run, drive
    from .reference import ContinuousReference

    if system.is_forced:
        system = drive(system, controls, h, t0, steps)
        # the checks of an untransformed call, where the values are known at trace time
        h_c, t0_c = concrete_value(h), concrete_value(t0)
        if h_c is not None and t0_c is not None:
            _, n_c, part_c = resolve_run(h_c, steps, t_final, float(t0_c), backward=True)
            check_forced_run(system, float(h_c), n_c + (1 if part_c else 0))
    method = backward(method, h, system)
    if systems is not None and len(systems) > 1:
        raise InputError("system: under a JAX transformation, batch with jax.vmap over one system's parameters")
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference (scipy) cannot be differentiated or traced; use an integrator")
    h_c, t0_c = concrete_value(h), concrete_value(t0)
    if h_c is None and steps is None:
        raise InputError("steps: h is traced (jax.jit), so the number of steps cannot follow from t_final; give steps")
    t0_num = 0.0 if t0_c is None else real_argument("t0", t0_c, positive=False)
    if h_c is not None:
        hv, n, partial = resolve_run(h_c, steps, t_final, t0_num, backward=True)
    else:
        hv, n, partial = None, whole_steps(steps), 0.0
    if partial and not method.can_change_step:
        raise InputError(f"t_final: not a whole number of steps of h, and {method.name} cannot shorten its last step")
    plan = schedule(common["saveat"], n, partial, h=hv, t0=t0_num)
    if state0 is None:
        if (q0 is None or v0 is None) and is_traced(system.lagrangian, system.constraints, system.affine, system.force,
                                                                  system.args):
            # the defaults were computed from the parameters' values: their derivative is not in them
            raise InputError(
                "q0/v0: the system's parameters are traced (differentiated or inside jax.jit), and its default "
                "initial condition was computed from their values without their derivatives; give q0 and v0 "
                "(as functions of the parameters where they depend on them)"
            )
        q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    return Problem(system=system, systems=None, method=method, q0=q0, v0=v0, R0=R0, state0=state0, h=h, steps=n,
                   partial=partial, t0=t0, plan=plan, times=None, traced=True, batch_size=None, **common)
