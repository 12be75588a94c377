"""The simulation driver: jit-compiled `lax.scan` over any one-step method, with a save stride."""

from __future__ import annotations

import math
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .integrators.base import Integrator, MethodError
from .solution import RESULT_SOLVER_FAILED, Solution, SolverFailure
from .errors import InputError
from .system import System, describe_orientations

__all__ = ["simulate", "resolve_steps", "MAX_STEPS", "MAX_TOTAL_STEPS", "MIN_STEP_SIZE"]

#: Most steps in one `simulate` call (the compiled loop counts steps in int32).
MAX_STEPS = 2**31 - 1

#: The most steps of any run, streamed ones included (t = t0 + k h needs k exact in float64).
MAX_TOTAL_STEPS = 2**53

#: The smallest step size accepted: the smallest normal float64 (below it, precision is lost).
MIN_STEP_SIZE = float(np.finfo(np.float64).tiny)


def resolve_steps(h, steps=None, t_final=None) -> tuple[float, int]:
    """Validate `h` and exactly one of `steps`, `t_final`; return `(h, steps)`.

    With `t_final`, the number of steps is `round(t_final / h)`; `t_final` must be a multiple of `h`
    to within 1e-9 relative.
    """
    if isinstance(h, (complex, np.complexfloating)):
        raise InputError(f"h: expected a positive real number, got {h!r}")
    try:
        h = float(h)
    except (TypeError, ValueError, OverflowError) as e:
        raise InputError(f"h: expected a positive number, got {h!r}") from e
    if not math.isfinite(h) or h <= 0:
        raise InputError(f"h: the step size must be a positive finite number, got {h!r}")
    if h < MIN_STEP_SIZE:
        raise InputError(
            f"h: {h!r} is below {MIN_STEP_SIZE:g}, where float64 loses its precision (subnormal numbers; "
            "the time t0 + k h and the momenta divided by h would be meaningless)"
        )
    if (steps is None) == (t_final is None):
        raise InputError("steps/t_final: give exactly one of steps and t_final")
    if t_final is not None:
        if isinstance(t_final, (complex, np.complexfloating)):
            raise InputError(f"t_final: expected a positive real number, got {t_final!r}")
        try:
            t_final = float(t_final)
        except (TypeError, ValueError, OverflowError) as e:
            raise InputError(f"t_final: expected a positive number, got {t_final!r}") from e
        if not math.isfinite(t_final) or t_final <= 0:
            raise InputError(f"t_final: must be a positive finite number, got {t_final!r}")
        ratio = t_final / h
        if not math.isfinite(ratio) or ratio > MAX_TOTAL_STEPS:
            raise InputError(
                f"t_final: {t_final!r} / h = {ratio:.3g} steps, more than any run can take "
                f"(at most {MAX_TOTAL_STEPS:.3g}); choose a larger h or a shorter t_final"
            )
        steps = round(ratio)
        if steps < 1 or abs(steps * h - t_final) > 1e-9 * t_final:
            raise InputError(f"t_final: {t_final!r} is not a whole number of steps of h = {h!r}")
    if isinstance(steps, bool) or isinstance(steps, (complex, np.complexfloating)):
        raise InputError(f"steps: must be a positive integer, got {steps!r}")
    try:
        whole = int(steps) == steps
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"steps: must be a positive integer, got {steps!r}") from None
    if not whole or steps < 1:
        raise InputError(f"steps: must be a positive integer, got {steps!r}")
    if steps > MAX_TOTAL_STEPS:
        raise InputError(
            f"steps: {int(steps)} steps is more than any run can take (at most {MAX_TOTAL_STEPS:.3g}: the "
            "step index must stay exact in float64)"
        )
    return h, int(steps)


def default_initial_condition(system: System, q0, v0, R0):
    """`(q0, v0, R0)` with the system's documented defaults filling what is None; for a sequence of
    systems (a parameter batch), each member's own defaults (see :func:`gnipy.ensembles.member_initial_conditions`)."""
    if isinstance(system, (list, tuple)):
        from .ensembles import member_initial_conditions

        return member_initial_conditions(system, q0, v0, R0)
    if q0 is None and system.n == 0:
        q0 = ()
    if q0 is None or v0 is None:
        if system.defaults is None:
            raise InputError(f"q0/v0: the system {system.name!r} has no default initial condition; give q0 and v0")
        q0 = system.defaults[0] if q0 is None else q0
        v0 = system.defaults[1] if v0 is None else v0
        if R0 is None and len(system.defaults) > 2:
            R0 = system.defaults[2]
    return q0, v0, R0


def _tree_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(x)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


def _integrate_core(method, system, state0, h, n_blocks: int, block, remainder, has_remainder: bool):
    """Run `n_blocks * block + remainder` steps, observing every `block` steps and at the end.

    `block` and `remainder` are traced (only the number of saved nodes fixes the shapes), so runs
    that differ in their step count but save as many nodes share one compilation.
    """
    int_t = jnp.int32

    def one_step(_, carry):
        state, k, fail_k, fail_res, it_tot, it_max = carry
        new, info = method.step(system, state, h)
        ok = info.ok & _tree_finite(new) & (fail_k < 0)
        newly_failed = (~ok) & (fail_k < 0)
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, state)
        res = jnp.where(jnp.isfinite(info.residual), info.residual, jnp.inf)
        fail_k = jnp.where(newly_failed, k, fail_k)
        fail_res = jnp.where(newly_failed, res, fail_res)
        it = jnp.where(ok, info.iterations, 0).astype(int_t)
        return state, k + 1, fail_k, fail_res, it_tot + it, jnp.maximum(it_max, it)

    def block_loop(carry, length):
        return jax.lax.fori_loop(0, length, one_step, carry)

    def observe(state):
        b, v, p = method.observe(system, state, h)
        return b, v, p, method.hidden_momentum(system, state, h)

    carry = (state0, jnp.asarray(0, int_t), jnp.asarray(-1, int_t), jnp.asarray(0.0), jnp.asarray(0, int_t),
             jnp.asarray(0, int_t))

    def outer(carry, i):
        # block 0 has no steps: it observes the initial node (observe is traced once, not twice)
        carry = block_loop(carry, jnp.where(i == 0, 0, block))
        return carry, observe(carry[0])

    carry, obs = jax.lax.scan(outer, carry, jnp.arange(n_blocks + 1, dtype=int_t))
    if has_remainder:
        carry = block_loop(carry, remainder)
        last = observe(carry[0])
        obs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b[None]]), obs, last)
    b, v, p, hidden = obs
    energy = jax.vmap(system.energy)(b, v)
    residual = jax.vmap(system.constraint_residual)(b, v)
    _, _, fail_k, fail_res, it_tot, it_max = carry
    # hidden: the GNI family's p⁺ − p̄ at the saved nodes (None for other methods); what derives from
    # it is computed apart (gnipy.diagnostics.saved_node_diagnostics), not compiled into every run
    return b, v, p, energy, residual, fail_k, fail_res, jnp.stack([it_tot, it_max]), carry[0], hidden


_integrate = jit(_integrate_core)


@jit
def _integrate_batch(method, system, system_batched: bool, state0, h, n_blocks: int, block, remainder,
                     has_remainder: bool):
    """:func:`_integrate_core` vmapped over the members (states, and the systems when batched)."""
    def one(s, st):
        return _integrate_core(method, s, st, h, n_blocks, block, remainder, has_remainder)

    return eqx.filter_vmap(one, in_axes=(eqx.if_array(0) if system_batched else None, 0))(system, state0)


@jit
def _init_batch(method, system, system_batched: bool, b0, v0, h):
    return eqx.filter_vmap(
        lambda s, b, v: method.init(s, b, v, h), in_axes=(eqx.if_array(0) if system_batched else None, 0, 0)
    )(system, b0, v0)


@jit
def _init_one(method, system, b0, v0, h):
    return method.init(system, b0, v0, h)


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
    save_every: int = 1,
    t0: float = 0.0,
    project_v0: bool = False,
    throw: bool = True,
) -> Solution:
    """Integrate a nonholonomic system, or an ensemble of them.

    Arguments:
        system: the :class:`~gnipy.System`; or a sequence of Systems that differ only in parameter
            values (a parameter batch, e.g. :func:`gnipy.model_systems`).
        method: an integrator object (e.g. `GNI(Midpoint())`) or a method name (see
            :func:`~gnipy.method_names`), including `"reference"` for the continuous reference.
            Default: for a zoo model, its measured default (`gnipy.get_model(name).default_method`,
            shown by `gni models`); for other systems `"gni-trapezoid"`.
        q0, v0: the initial coordinates and velocity (default: the system's documented ones); on
            $\\mathbb{R}^n \\times G$, `q0` holds x and `v0` the velocity $(\\dot x, \\xi)$.
            Arrays with a leading batch axis, (B, n) and (B, N), run B trajectories at once.
        R0: the initial orientation on $\\mathbb{R}^n \\times G$ (default: the system's, or the
            identity); (k, k), or (B, k, k) for a batch.
        h: step size (> 0); the reference saves at the same times.
        steps / t_final: the number of steps, or the final time (a whole number of steps).
        save_every: the save stride K: nodes 0, K, 2K, ... and always the last one are saved.
        t0: initial time.
        project_v0: project `v0` onto the constraints instead of raising when it violates them.
        throw: raise :class:`~gnipy.SolverFailure` if a step fails; with `False`, return the
            solution up to the last good saved node with `result = 1` (in a batch: a failed
            member's nodes after its failure are NaN; :meth:`Solution.failures` gives each
            failure's member, step, time and residual).

    Returns:
        A :class:`~gnipy.Solution`. For a batch (B members: the batch size of the systems and
        of the initial conditions, which broadcast against each other) the arrays carry a leading
        member axis, `sol.member(i)` is the i-th trajectory, and `sol.results`,
        `sol.failed_steps` hold each member's result code and failed step.

    Compilation is shared between runs that save the same number of nodes: the step count, h and
    the parameter values are traced, so convergence studies (one saved node per run, varying h)
    and parameter scans compile once.

    Raises:
        InputError: bad arguments or initial conditions (the message names the argument and,
            in a batch, the member).
        MethodError: a method that cannot integrate this system.
        SolverFailure: a step did not converge (step index, time, residual in the message; in
            a batch, the first failing member).
    """
    from .compilation import release_compiled_programs_if_needed
    from .methods import get_method
    from .reference import ContinuousReference

    release_compiled_programs_if_needed()
    systems = None
    if isinstance(system, (list, tuple)):
        systems = list(system)
        if not systems:
            raise InputError("system: an empty sequence of systems")
        if not all(isinstance(s, System) for s in systems):
            bad = next(i for i, s in enumerate(systems) if not isinstance(s, System))
            raise InputError(f"system[{bad}]: expected a gnipy.System, got {type(systems[bad]).__name__}")
        system = systems[0]
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System or a sequence of them, got {type(system).__name__}")
    if method is None:
        from .models.registry import default_method_for

        method = default_method_for(system.name)
    if isinstance(method, str):
        method = get_method(method)
    if not isinstance(method, (Integrator, ContinuousReference)):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    h, steps = resolve_steps(h, steps, t_final)
    if steps > MAX_STEPS:
        raise InputError(
            f"steps: at most {MAX_STEPS} steps per call (the step counters are int32), got {steps}; "
            "stream longer runs with gnipy.simulate_to_file"
        )
    if isinstance(save_every, bool) or int(save_every) != save_every or save_every < 1:
        raise InputError(f"save_every: must be a positive integer, got {save_every!r}")
    save_every = int(min(save_every, steps))
    try:
        t0 = float(t0)
    except (TypeError, ValueError) as e:
        raise InputError(f"t0: expected a number, got {t0!r}") from e
    if not math.isfinite(t0):
        raise InputError(f"t0: must be finite, got {t0!r}")
    q0, v0, R0 = default_initial_condition(systems if systems and len(systems) > 1 else system, q0, v0, R0)

    n_blocks, remainder = divmod(steps, save_every)
    k_saved = np.concatenate([np.arange(n_blocks + 1) * save_every, [steps] if remainder else []]).astype(np.int64)
    times = t0 + h * k_saved
    meta = dict(system=system.name, method=method.name, h=h, coordinates=system.coordinates,
                velocities=system.velocities, params=system.params,
                orientation=describe_orientations(systems or [system]))

    batched = systems is not None or _is_batch(system, q0, v0, R0)
    if batched:
        if isinstance(method, ContinuousReference):
            raise MethodError("method: the continuous reference runs one trajectory at a time; pass one system and one initial condition")
        return _simulate_batch(systems or [system], method, q0, v0, R0, h, steps, save_every, n_blocks, remainder,
                               k_saved, times, t0, project_v0, throw, meta)

    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
    if isinstance(method, ContinuousReference):
        return method.solve(system, b0, jnp.asarray(v0), times, h=h)

    method.check(system, b0)
    method = method.prepare(system, b0)
    hj = np.float64(h)  # NumPy scalars: the compiled call converts them (cheaper than a jnp.asarray each)
    core = system.without_metadata()
    state0 = _init_one(method, core, b0, np.asarray(v0, dtype=np.float64), hj)
    b, v, p, energy, residual, fail_k, fail_res, its, _, hidden = _integrate(
        method, core, state0, hj, n_blocks, np.int32(save_every), np.int32(remainder), bool(remainder),
    )
    meta |= _diagnostic_meta(system, core, b0, (b, v, p, hidden), h)
    q, R = system.space.coordinates(b), system.space.orientation(b)
    fail_k = int(fail_k)
    if fail_k < 0:
        return Solution(jnp.asarray(times), q, v, p, energy, residual, its, R=R, **meta)
    good = int(np.searchsorted(k_saved, fail_k, side="right"))  # saved nodes with index <= fail_k
    meta |= {k: meta[k][:good] for k in _DIAGNOSTIC_ARRAYS if meta.get(k) is not None}
    partial = Solution(
        jnp.asarray(times[:good]), q[:good], v[:good], p[:good], energy[:good], residual[:good], its,
        R=None if R is None else R[:good], result=RESULT_SOLVER_FAILED, failed_step=fail_k,
        failed_residual=float(fail_res), **meta,
    )
    msg = (
        f"{method.name}: step {fail_k} (t = {t0 + h * fail_k:.6g} -> {t0 + h * (fail_k + 1):.6g}) failed: "
        f"the solve did not converge or gave a non-finite value (residual {float(fail_res):.3e})"
    )
    if throw:
        raise SolverFailure(msg, step=fail_k, time=t0 + h * fail_k, residual=float(fail_res), solution=partial)
    return partial


_DIAGNOSTIC_ARRAYS = ("hidden_momentum", "hidden_expected", "energy_plus")


def _diagnostic_meta(system, core, b0, nodes, h, *, batched_system: bool = False, batch: bool = False) -> dict:
    """The Solution's diagnostic fields: the GNI family's hidden momentum, its expected size and
    the energy of p⁺ (:mod:`gnipy.diagnostics`), and the sentence on what is conserved."""
    from .diagnostics import conserved_quantity, energy_is_invariant, saved_node_diagnostics
    from .models.registry import registered_invariants

    diag = None
    if nodes[3] is not None:
        diag = saved_node_diagnostics(core, *nodes, h, batched_system=batched_system, batch=batch)
    out = {"conserved": conserved_quantity(system, b0, gni_family=diag is not None,
                                           invariants=registered_invariants(system.name)),
           "energy_invariant": energy_is_invariant(system, b0)}
    if diag is not None:
        out |= dict(zip(_DIAGNOSTIC_ARRAYS, diag))
    return out


def _is_batch(system: System, q0, v0, R0) -> bool:
    """Whether the initial conditions carry a leading batch axis."""
    try:
        q = np.asarray(q0)
        v = np.asarray(v0)
    except (TypeError, ValueError):
        return False  # let System.check name the bad argument
    if q.ndim == 2 or v.ndim == 2:
        return True
    if system.group is not None and R0 is not None:
        try:
            R = np.asarray(R0, dtype=np.float64)
        except (TypeError, ValueError):
            return False
        k = system.group.matrix_size
        return R.ndim == 3 or (R.ndim == 2 and R.shape != (k, k) and R.shape[-1] == k * k)
    return False


def _simulate_batch(systems, method, q0, v0, R0, h, steps, save_every, n_blocks, remainder, k_saved, times, t0,
                    project_v0, throw, meta):
    from .ensembles import broadcast_initial_conditions, check_batch, member_params, stack_systems

    system = systems[0]
    size = len(systems) if len(systems) > 1 else None
    B, q0, v0, R0 = broadcast_initial_conditions(system, q0, v0, R0, size)
    # the full checks (mechanical type, dimensions) once, on the first member; the value checks
    # (metric, rank, v0 on the constraints) for every member, vectorized
    system.check(q0[0], None, R0=None if R0 is None else R0[0])
    sys_batched = len(systems) > 1
    core = stack_systems(systems) if sys_batched else system.without_metadata()
    b0, v0 = check_batch(core, sys_batched, q0, v0, R0, project_v0=project_v0)
    first_b0 = jax.tree_util.tree_map(lambda a: a[0], b0)
    method.check(system, first_b0)
    method = method.prepare(system, first_b0)
    hj = np.float64(h)
    state0 = _init_batch(method, core, sys_batched, b0, v0, hj)
    b, v, p, energy, residual, fail_k, fail_res, its, _, hidden = _integrate_batch(
        method, core, sys_batched, state0, hj, n_blocks, np.int32(save_every), np.int32(remainder), bool(remainder),
    )
    batch_diag = _diagnostic_meta(system, core, first_b0, (b, v, p, hidden), h, batched_system=sys_batched,
                                  batch=True)
    space = system.space
    q, R = space.coordinates(b), space.orientation(b)
    fail_k = np.asarray(fail_k)
    failed = fail_k >= 0
    fail_res = np.where(failed, np.asarray(fail_res, dtype=np.float64), np.nan)
    results = np.where(failed, RESULT_SOLVER_FAILED, 0).astype(np.int32)
    if failed.any():  # a failed member is NaN after its failed step, never its last state repeated
        valid = ~failed[:, None] | (k_saved[None, :] <= fail_k[:, None])

        def blank(a):
            if a is None:
                return None
            a = np.array(a, dtype=np.float64)
            a[~valid] = np.nan
            return jnp.asarray(a)

        q, v, p, energy, residual, R = (blank(a) for a in (q, v, p, energy, residual, R))
        batch_diag |= {k: blank(batch_diag[k]) for k in _DIAGNOSTIC_ARRAYS if batch_diag.get(k) is not None}
    its = np.asarray(its)
    batch_meta = dict(meta)
    if sys_batched:
        batch_meta["params"] = ()
    sol = Solution(
        jnp.asarray(times), q, v, p, energy, residual, jnp.asarray([its[:, 0].sum(), its[:, 1].max()]), R=R,
        result=RESULT_SOLVER_FAILED if failed.any() else 0, failed_step=int(fail_k[failed].min()) if failed.any() else -1,
        results=jnp.asarray(results), failed_steps=jnp.asarray(fail_k), failed_residuals=jnp.asarray(fail_res),
        member_params=member_params(systems) if sys_batched else None,
        **batch_meta, **batch_diag,
    )
    if failed.any() and throw:
        i = int(np.argmax(failed))
        k = int(fail_k[i])
        msg = (
            f"{method.name}: member {i} of {B}: step {k} (t = {t0 + h * k:.6g} -> {t0 + h * (k + 1):.6g}) failed: "
            f"the solve did not converge or gave a non-finite value (residual {float(fail_res[i]):.3e}); "
            f"{int(failed.sum())} member(s) failed"
        )
        raise SolverFailure(msg, step=k, time=t0 + h * k, residual=float(fail_res[i]), solution=sol)
    return sol
