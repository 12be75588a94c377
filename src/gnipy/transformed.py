"""`gnipy.simulate` under a JAX transformation (`jax.grad`, `jax.jacrev`, `jax.jacfwd`, `jax.jit`):
the values are checked where they are known at trace time, and the run is differentiable (static
trip counts in blocks, :func:`gnipy.stepping.run_nodes_checkpointed`; the implicit steps' solves
differentiated by the implicit function theorem, :func:`gnipy.integrators.base.implicit_solve`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .errors import InputError
from .inputs import concrete_value as _concrete
from .integrators.base import Integrator
from .preparation import prepare
from .solution import Solution
from .stepping import run_nodes_checkpointed
from .system import project_velocity

__all__ = ["simulate_traced", "traced_point", "traced_method"]


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




@eqx.filter_jit
def _run(method, system, b0, v0, state0, h, lengths: tuple, tail: int, h_last, *, project: bool, partial: bool,
         save_final: bool, save_states: bool) -> dict:
    """The start (from `state0`, else `method.init` at `(b0, v0)`, `v0` projected with `project`)
    and :func:`gnipy.stepping.run_nodes_checkpointed`, as one compiled program. Under an outer
    `jax.jit` it is part of that program; under `jax.grad` and the like called outside `jit`,
    JAX would otherwise run the steps primitive by primitive, compiling each again at every call
    (measured, the sleigh, 40 steps, a gradient outside `jit` on the quiet 2-core machine: 1.9 s a
    call after the first, 0.04 s this way; the first call 10 s, 4.2 s this way).
    gnipy's compiler options cannot be given to a nested program: `jax.jit(jax.grad(f))` compiles
    with XLA's defaults unless the caller passes them (docs: gradients guide)."""
    if state0 is None:
        if project:
            v0 = project_velocity(system, b0, v0)
        state0 = method.init(system, b0, v0, h)
    return run_nodes_checkpointed(method, system, state0, h, lengths, tail, h_last, partial=partial,
                                  save_final=save_final, save_states=save_states)


def simulate_traced(problem) -> Solution:
    """A :class:`gnipy.Problem` under a JAX transformation: the values are checked where they are
    known now (`jax.grad`/`jax.jacfwd` outside `jit`), the run is differentiable (static trip
    counts in checkpointed blocks, :func:`gnipy.stepping.run_nodes_checkpointed`)."""
    from .assembly import assemble, labels
    from .system import describe_orientations

    system, method, plan = problem.system, problem.method, problem.plan
    q0, v0, R0, state0 = problem.q0, problem.v0, problem.R0, problem.state0
    concrete = _concrete_tree((system, q0, v0, R0, state0))
    core = system.without_metadata()
    fields = {}
    if concrete is not None:  # the full checks on the values, as in an untransformed call
        c_sys, c_q0, c_v0, c_R0, c_state0 = concrete
        prep = prepare(c_sys, method, c_q0, c_v0, c_R0, problem.project_v0, c_state0)
        prepared = prep.method
        if _concrete(problem.h) is not None and _concrete(problem.t0) is not None:
            # every value known (jax.grad outside jit): not inside a jit trace, whose nested
            # compiled programs the sentences' checks could not call
            fields = _sentences(c_sys, prep, method)
    else:  # inside jit: shapes only
        prepared = traced_method(method)
    hj = jnp.asarray(problem.h, jnp.float64)
    b0 = None
    if state0 is None:
        b0 = traced_point(system, q0, R0)
        v0 = jnp.asarray(v0, jnp.float64)
        if v0.shape != (system.dim,):
            raise InputError(f"v0: expected {system.dim} components, got shape {v0.shape}")
    out = _run(prepared, core, b0, v0, state0, hj, plan.lengths, plan.tail, hj * problem.partial,
               project=bool(problem.project_v0), partial=bool(problem.partial), save_final=plan.save_final,
               save_states=problem.saveat.states)
    fields = labels(problem, prepared, "xla") | {"orientation": describe_orientations([system])} | fields
    return assemble(problem, out, fields)


def _sentences(system, prep, method) -> dict:
    """The diagnostics' sentences of a run whose system is known at trace time (what is conserved,
    whether the energy is a constant of the motion), kept per call signature as in an untransformed
    run; the per-node arrays are not computed under a transformation (:mod:`gnipy.assembly`)."""
    from .diagnostics import conserved_quantity, energy_is_invariant, scheme_energy
    from .registry import registered_invariants

    scheme = scheme_energy(method)
    gni_family = type(prep.method).hidden_momentum is not Integrator.hidden_momentum
    key = ("traced-sentences", gni_family, scheme)
    if key not in prep.cache:
        prep.cache[key] = {
            "conserved": conserved_quantity(system, prep.b0, gni_family=gni_family,
                                            invariants=registered_invariants(system.model),
                                            scheme=scheme),
            "energy_invariant": energy_is_invariant(system, prep.b0)}
    return dict(prep.cache[key])


def traced_method(method):
    """The method a run inside `jax.jit` takes, whose system is not known at trace time: a GNI that
    decides between its explicit and implicit step from the system (`explicit=None`) takes the
    implicit path (the explicit one is an optimization that needs the values)."""
    import dataclasses

    from .integrators.gni import GNI

    return dataclasses.replace(method, explicit=False) if isinstance(method, GNI) and method.explicit is None else method


def traced_point(system, q0, R0):
    """The base point of a traced run's start: the coordinates `q0` and, on R^n x G, `R0` (the
    identity when None); InputError naming `q0` for the wrong number of coordinates."""
    from .spaces import Point

    x = jnp.asarray(q0, jnp.float64).reshape(-1) if system.n else jnp.zeros(0)
    if x.shape != (system.n,):
        raise InputError(f"q0: expected {system.n} coordinates, got shape {jnp.shape(q0)}")
    if system.group is None:
        return x
    k = system.group.matrix_size
    R = jnp.eye(k) if R0 is None else jnp.asarray(R0, jnp.float64).reshape(k, k)
    return Point(x, R)
