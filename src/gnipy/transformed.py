"""`gnipy.simulate` under a JAX transformation (`jax.grad`, `jax.jacrev`, `jax.jacfwd`, `jax.jit`):
the values are checked where they are known at trace time, and the run is differentiable (static
trip counts in blocks, :func:`gnipy.stepping.run_nodes_checkpointed`; the implicit steps' solves
differentiated by the implicit function theorem, :func:`gnipy.integrators.base.implicit_solve`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .errors import InputError, MethodError
from .inputs import concrete_value as _concrete, is_traced
from .preparation import prepare
from .run_arguments import default_initial_condition, real_argument, resolve_run, whole_steps
from .saveat import schedule
from .solution import Solution
from .stepping import run_nodes_checkpointed

__all__ = ["simulate_traced"]


def _concrete_tree(tree):
    """`tree` with every tracer replaced by its concrete value, or None if one has none."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    out = []
    for x in leaves:
        c = _concrete(x)
        if c is None:
            return None
        out.append(c)
    return jax.tree_util.tree_unflatten(treedef, out)




def simulate_traced(system, systems, method, q0, v0, R0, h, steps, t_final, saveat, t0, state0, project_v0, throw):
    """`simulate` under a JAX transformation: the values are checked where they are known now
    (`jax.grad`/`jax.jacfwd` outside `jit`), the run is differentiable (static trip counts in
    checkpointed blocks, :func:`gnipy.stepping.run_nodes_checkpointed`)."""
    from .reference import ContinuousReference
    from .system import project_velocity

    if systems is not None and len(systems) > 1:
        raise InputError("system: under a JAX transformation, batch with jax.vmap over one system's parameters")
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference (scipy) cannot be differentiated or traced; use an integrator")
    if not throw:
        raise InputError("throw: under a JAX transformation a failed step is raised at run time (throw=True)")
    h_c, t0_c = _concrete(h), _concrete(t0)
    if h_c is None and steps is None:
        raise InputError("steps: h is traced (jax.jit), so the number of steps cannot follow from t_final; give steps")
    t0_num = 0.0 if t0_c is None else real_argument("t0", t0_c, positive=False)
    if h_c is not None:
        hv, n, partial = resolve_run(h_c, steps, t_final, t0_num, backward=True)
    else:
        hv, n, partial = None, whole_steps(steps), 0.0
    if partial and not method.can_change_step:
        raise InputError(f"t_final: not a whole number of steps of h, and {method.name} cannot shorten its last step")
    plan = schedule(saveat, n, partial, h=hv, t0=t0_num)
    if state0 is None:
        if (q0 is None or v0 is None) and is_traced(system.lagrangian, system.constraints, system.affine, system.force):
            # the defaults were computed from the parameters' values: their derivative is not in them
            raise InputError(
                "q0/v0: the system's parameters are traced (differentiated or inside jax.jit), and its default "
                "initial condition was computed from their values without their derivatives; give q0 and v0 "
                "(as functions of the parameters where they depend on them)"
            )
        q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    concrete = _concrete_tree((system, q0, v0, R0, state0))
    core = system.without_metadata()
    if concrete is not None:  # the full checks on the values, as in an untransformed call
        c_sys, c_q0, c_v0, c_R0, c_state0 = concrete
        prep = prepare(c_sys, method, c_q0, c_v0, c_R0, project_v0, c_state0)
        prepared = prep.method
    else:  # inside jit: shapes only; the implicit path (the explicit one is an optimization)
        import dataclasses

        from .integrators.gni import GNI

        prepared = dataclasses.replace(method, explicit=False) if isinstance(method, GNI) and method.explicit is None else method
    hj = jnp.asarray(h, jnp.float64)
    if state0 is None:
        b0 = _traced_point(system, q0, R0)
        v0 = jnp.asarray(v0, jnp.float64)
        if v0.shape != (system.dim,):
            raise InputError(f"v0: expected {system.dim} components, got shape {v0.shape}")
        if project_v0:
            v0 = project_velocity(core, b0, v0)
        state0 = prepared.init(core, b0, v0, hj)
    h_last = hj * partial
    out = run_nodes_checkpointed(prepared, core, state0, hj, plan.lengths, plan.tail, h_last, partial=bool(partial),
                                 save_final=plan.save_final, save_states=saveat.states)
    k = np.asarray(plan.nodes, dtype=np.float64)
    if plan.save_final:
        k[-1] = n + partial
    times = jnp.asarray(t0, jnp.float64) + hj * k
    q = eqx.error_if(system.space.coordinates(out["b"]), out["fail_k"] >= 0,
                     f"{method.name}: a step failed (its solve did not converge or gave a non-finite value)")
    return Solution(
        times, q, out["v"], out["p"], out["energy"], out["residual"], iterations=out["iterations"],
        R=system.space.orientation(out["b"]), final_state=out["final_state"], states=out["states"],
        system=system.name, method=method.name, h=float(hv) if hv is not None else float("nan"),
        coordinates=system.coordinates, velocities=system.velocities, params=system.params,
        start=method.start_label, method_settings=tuple(method.settings().items()),
    )


def _traced_point(system, q0, R0):
    from .spaces import Point

    x = jnp.asarray(q0, jnp.float64).reshape(-1) if system.n else jnp.zeros(0)
    if x.shape != (system.n,):
        raise InputError(f"q0: expected {system.n} coordinates, got shape {jnp.shape(q0)}")
    if system.group is None:
        return x
    k = system.group.matrix_size
    R = jnp.eye(k) if R0 is None else jnp.asarray(R0, jnp.float64).reshape(k, k)
    return Point(x, R)
