"""The simulation driver: jit-compiled `lax.scan` over any one-step method, with a save stride."""

from __future__ import annotations

import math
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .integrators.base import Integrator, MethodError
from .solution import RESULT_SOLVER_FAILED, Solution, SolverFailure
from .system import System, SystemError

__all__ = ["simulate", "resolve_steps"]


def resolve_steps(h, steps=None, t_final=None) -> tuple[float, int]:
    """Validate `h` and exactly one of `steps`, `t_final`; return `(h, steps)`.

    With `t_final`, the number of steps is `round(t_final / h)`; `t_final` must be a multiple of `h`
    to within 1e-9 relative.
    """
    try:
        h = float(h)
    except (TypeError, ValueError) as e:
        raise SystemError(f"h: expected a positive number, got {h!r}") from e
    if not math.isfinite(h) or h <= 0:
        raise SystemError(f"h: the step size must be a positive finite number, got {h!r}")
    if (steps is None) == (t_final is None):
        raise SystemError("steps/t_final: give exactly one of steps and t_final")
    if t_final is not None:
        try:
            t_final = float(t_final)
        except (TypeError, ValueError) as e:
            raise SystemError(f"t_final: expected a positive number, got {t_final!r}") from e
        if not math.isfinite(t_final) or t_final <= 0:
            raise SystemError(f"t_final: must be a positive finite number, got {t_final!r}")
        steps = round(t_final / h)
        if steps < 1 or abs(steps * h - t_final) > 1e-9 * t_final:
            raise SystemError(f"t_final: {t_final!r} is not a whole number of steps of h = {h!r}")
    if isinstance(steps, bool) or int(steps) != steps or steps < 1:
        raise SystemError(f"steps: must be a positive integer, got {steps!r}")
    return h, int(steps)


def _tree_finite(tree) -> jax.Array:
    leaves = [jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(x)]
    return jnp.all(jnp.stack(leaves)) if leaves else jnp.asarray(True)


@eqx.filter_jit
def _integrate(method, system, state0, h, n_blocks: int, block: int, remainder: int):
    """Run `n_blocks * block + remainder` steps, observing every `block` steps and at the end."""
    int_t = jnp.int32

    def one_step(carry, _):
        state, k, fail_k, fail_res, it_tot, it_max = carry
        new, info = method.step(system, state, h)
        ok = info.ok & _tree_finite(new) & (fail_k < 0)
        newly_failed = (~ok) & (fail_k < 0)
        state = jax.tree_util.tree_map(lambda a, b: jnp.where(ok, a, b), new, state)
        res = jnp.where(jnp.isfinite(info.residual), info.residual, jnp.inf)
        fail_k = jnp.where(newly_failed, k, fail_k)
        fail_res = jnp.where(newly_failed, res, fail_res)
        it = jnp.where(ok, info.iterations, 0).astype(int_t)
        return (state, k + 1, fail_k, fail_res, it_tot + it, jnp.maximum(it_max, it)), None

    def block_scan(carry, length):
        carry, _ = jax.lax.scan(one_step, carry, None, length=length)
        return carry

    def observe(state):
        return method.observe(system, state, h)

    carry = (state0, jnp.asarray(0, int_t), jnp.asarray(-1, int_t), jnp.asarray(0.0), jnp.asarray(0, int_t),
             jnp.asarray(0, int_t))
    obs0 = observe(state0)

    def outer(carry, _):
        carry = block_scan(carry, block)
        return carry, observe(carry[0])

    carry, obs = jax.lax.scan(outer, carry, None, length=n_blocks)
    obs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), obs0, obs)
    if remainder:
        carry = block_scan(carry, remainder)
        last = observe(carry[0])
        obs = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b[None]]), obs, last)
    b, v, p = obs
    energy = jax.vmap(system.energy)(b, v)
    residual = jax.vmap(system.constraint_residual)(b, v)
    _, _, fail_k, fail_res, it_tot, it_max = carry
    return b, v, p, energy, residual, fail_k, fail_res, jnp.stack([it_tot, it_max])


def simulate(
    system: System,
    method: Integrator | str = "gni-trapezoid",
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
    """Integrate a nonholonomic system.

    Arguments:
        system: the :class:`~gnipy.System`.
        method: an integrator object (e.g. `GNI(Midpoint())`) or a method name (see
            :func:`~gnipy.method_names`), including `"reference"` for the continuous reference.
        q0, v0: the initial coordinates and velocity (default: the system's documented ones); on
            $\\mathbb{R}^n \\times G$, `q0` holds x and `v0` the velocity $(\\dot x, \\xi)$.
        R0: the initial orientation on $\\mathbb{R}^n \\times G$ (default: the system's, or the identity).
        h: step size (> 0); the reference saves at the same times.
        steps / t_final: the number of steps, or the final time (a whole number of steps).
        save_every: the save stride K: nodes 0, K, 2K, ... and always the last one are saved.
        t0: initial time.
        project_v0: project `v0` onto the constraints instead of raising when it violates them.
        throw: raise :class:`~gnipy.SolverFailure` if a step fails; with `False`, return the
            solution up to the last good saved node with `result = 1`.

    Returns:
        A :class:`~gnipy.Solution`.

    Raises:
        SystemError: bad arguments or initial conditions (the message names the argument).
        MethodError: a method that cannot integrate this system.
        SolverFailure: a step did not converge (step index, time, residual in the message).
    """
    from .methods import get_method
    from .reference import ContinuousReference

    if not isinstance(system, System):
        raise SystemError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if isinstance(method, str):
        method = get_method(method)
    if not isinstance(method, (Integrator, ContinuousReference)):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    h, steps = resolve_steps(h, steps, t_final)
    if isinstance(save_every, bool) or int(save_every) != save_every or save_every < 1:
        raise SystemError(f"save_every: must be a positive integer, got {save_every!r}")
    save_every = int(min(save_every, steps))
    try:
        t0 = float(t0)
    except (TypeError, ValueError) as e:
        raise SystemError(f"t0: expected a number, got {t0!r}") from e
    if not math.isfinite(t0):
        raise SystemError(f"t0: must be finite, got {t0!r}")
    if q0 is None and system.n == 0:
        q0 = ()
    if q0 is None or v0 is None:
        if system.defaults is None:
            raise SystemError(f"q0/v0: the system {system.name!r} has no default initial condition; give q0 and v0")
        q0 = system.defaults[0] if q0 is None else q0
        v0 = system.defaults[1] if v0 is None else v0
        if R0 is None and len(system.defaults) > 2:
            R0 = system.defaults[2]
    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)

    n_blocks, remainder = divmod(steps, save_every)
    k_saved = np.concatenate([np.arange(n_blocks + 1) * save_every, [steps] if remainder else []]).astype(np.int64)
    times = t0 + h * k_saved

    if isinstance(method, ContinuousReference):
        return method.solve(system, b0, jnp.asarray(v0), times, h=h)

    method.check(system, b0)
    method = method.prepare(system, b0)
    hj = jnp.asarray(h)
    state0 = method.init(system, b0, jnp.asarray(v0), hj)
    b, v, p, energy, residual, fail_k, fail_res, its = _integrate(
        method, system, state0, hj, n_blocks, save_every, remainder
    )
    q, R = system.space.coordinates(b), system.space.orientation(b)
    fail_k = int(fail_k)
    meta = dict(system=system.name, method=method.name, h=h, coordinates=system.coordinates,
                velocities=system.velocities, params=system.params)
    if fail_k < 0:
        return Solution(jnp.asarray(times), q, v, p, energy, residual, its, R=R, **meta)
    good = int(np.searchsorted(k_saved, fail_k, side="right"))  # saved nodes with index <= fail_k
    partial = Solution(
        jnp.asarray(times[:good]), q[:good], v[:good], p[:good], energy[:good], residual[:good], its,
        R=None if R is None else R[:good], result=RESULT_SOLVER_FAILED, failed_step=fail_k, **meta,
    )
    msg = (
        f"{method.name}: step {fail_k} (t = {t0 + h * fail_k:.6g} -> {t0 + h * (fail_k + 1):.6g}) failed: "
        f"the solve did not converge or gave a non-finite value (residual {float(fail_res):.3e})"
    )
    if throw:
        raise SolverFailure(msg, step=fail_k, time=t0 + h * fail_k, residual=float(fail_res), solution=partial)
    return partial

