"""The one assembly of a :class:`gnipy.Solution` from a run's nodes: :func:`assemble`.

Every path of :func:`gnipy.integrate` (one trajectory on XLA or native, a batch, a run under a
JAX transformation) hands the stepping loop's output (:mod:`gnipy.stepping`: the saved nodes, the
failure, the monitor) and the run's labels (:func:`labels`) to :func:`assemble`, so that every
path returns the same fields. What differs is what a failure leaves:

- one trajectory: the nodes up to the last good one, `result = RESULTS.solve_failed`, and with
  `throw` a :class:`~gnipy.SolverFailure` that carries them;
- a batch: every member's nodes, a failed member's NaN after its failed step (never its last state
  repeated), each member's result code, failed step and residual;
- under a transformation: the failure is raised at run time (`equinox.error_if`); with `throw=False`
  the saved nodes after the failed step are NaN instead (no run-time error).

The diagnostics (:mod:`gnipy.diagnostics`: the GNI family's hidden momentum, the conserved
quantity's sentence) are computed by the path that has what they need and passed in `fields`;
under a transformation the per-node arrays are not computed (they would add the continuous
multiplier, which costs as much to compile as a step, to every differentiated program) and the
sentences are those of the concrete system when it is known at trace time.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .errors import SolverFailure
from .integrators.base import Integrator
from .solution import RESULTS, Solution

__all__ = ["assemble", "labels"]

#: The Solution fields that hold per-node arrays of the GNI family's diagnostics.
_NODE_DIAGNOSTICS = ("hidden_momentum", "hidden_expected", "energy_plus")


def labels(problem, prepared, backend: str) -> dict:
    """What a Solution says about its run: the system's name, coordinates, velocities and
    parameters, the method's name and how it started, the settings of `prepared` (the method as
    prepared for the run: e.g. whether the step is explicit), `h`, the backend that ran."""
    system, method = problem.system, problem.method
    h = problem.h
    if problem.traced:
        h = _concrete(h)
        h = float("nan") if h is None else float(h)
    return dict(system=system.name, method=method.name, h=h, coordinates=system.coordinates,
                velocities=system.velocities, params=system.params,
                start=getattr(method, "start_label", "continuous"),
                method_settings=_settings(prepared),
                backend=backend)


def _settings(prepared) -> tuple:
    """The prepared method's settings as pairs. Called through the class: an equinox Module's
    bound method is a Module built on every access (about 35 µs), and every run reads these."""
    return tuple(type(prepared).settings(prepared).items()) if isinstance(prepared, Integrator) else ()


def _concrete(x):
    from .inputs import concrete_value

    return concrete_value(x)


def assemble(problem, out: dict, fields: dict) -> Solution:
    """The Solution of `problem` from the loop's output `out` (the keys of
    :func:`gnipy.stepping.run_nodes`: `b, v, p, energy, residual, iterations, final_state, states,
    monitor, fail_k, fail_res`) and `fields` (:func:`labels` and the diagnostics).

    Raises:
        SolverFailure: a step failed and `problem.throw` (one trajectory: its step, time and
            residual; a batch: the first failed member's, and how many failed).
    """
    if problem.traced:
        return _traced(problem, out, fields)
    if problem.batched:
        return _batch(problem, out, fields)
    return _single(problem, out, fields)


def _single(problem, out, fields) -> Solution:
    space = problem.system.space
    if "q" in out:  # computed inside the run's program (gnipy.preparation)
        q, R = out["q"], out["R"]
    else:
        q, R = space.coordinates(out["b"]), space.orientation(out["b"])
    common = dict(iterations=out["iterations"], R=R, final_state=out["final_state"], states=out["states"],
                  monitor=None if out["monitor"] is None else np.asarray(out["monitor"]), **fields)
    fail_k = int(out["fail_k"])
    times = problem.times
    if fail_k < 0:
        t = out["t"] if out.get("t") is not None else jnp.asarray(times)  # the program's copy: no transfer
        return Solution.of(t=t, q=q, v=out["v"], p=out["p"], energy=out["energy"],
                           constraint_residual=out["residual"], **common)
    good = int(np.searchsorted(np.asarray(problem.plan.nodes), fail_k, side="right"))  # saved nodes with index <= fail_k
    cut = {k: (None if common.get(k) is None else jax.tree_util.tree_map(lambda a: a[:good], common[k]))
           for k in ("R", "states", *_NODE_DIAGNOSTICS)}
    fail_res = float(out["fail_res"])
    partial_sol = Solution(
        jnp.asarray(times[:good]), q[:good], out["v"][:good], out["p"][:good], out["energy"][:good],
        out["residual"][:good], **(common | cut), result=RESULTS.solve_failed, failed_step=fail_k,
        failed_residual=fail_res,
    )
    h, t0, n, partial = problem.h, problem.t0, problem.steps, problem.partial
    t_fail = float(times[-1]) if fail_k >= n else t0 + h * fail_k
    t_next = t0 + h * (n + partial) if fail_k >= n else t_fail + h
    msg = (f"{fields['method']}: step {fail_k} (t = {t_fail:.6g} -> {t_next:.6g}) failed: "
           f"{RESULTS.solve_failed.message} (residual {fail_res:.3e})")
    if problem.throw:
        raise SolverFailure(msg, step=fail_k, time=t_fail, residual=fail_res, solution=partial_sol)
    return partial_sol


def _batch(problem, out, fields) -> Solution:
    space = problem.system.space
    q, R = space.coordinates(out["b"]), space.orientation(out["b"])
    v, p, energy, residual = out["v"], out["p"], out["energy"], out["residual"]
    fail_k = np.asarray(out["fail_k"])
    failed = fail_k >= 0
    fail_res = np.where(failed, np.asarray(out["fail_res"], dtype=np.float64), np.nan)
    results = np.where(failed, int(RESULTS.solve_failed), int(RESULTS.successful)).astype(np.int32)
    k_saved = np.asarray(problem.plan.nodes)
    fields = dict(fields)
    if failed.any():  # a failed member is NaN after its failed step, never its last state repeated
        valid = ~failed[:, None] | (k_saved[None, :] <= fail_k[:, None])

        def blank(a):
            if a is None:
                return None
            a = np.array(a, dtype=np.float64)
            a[~valid] = np.nan
            return jnp.asarray(a)

        q, v, p, energy, residual, R = (blank(a) for a in (q, v, p, energy, residual, R))
        fields |= {k: blank(fields[k]) for k in _NODE_DIAGNOSTICS if fields.get(k) is not None}
    its = np.asarray(out["iterations"])
    sol = Solution(
        jnp.asarray(problem.times), q, v, p, energy, residual, jnp.asarray([its[:, 0].sum(), its[:, 1].max()]), R=R,
        result=RESULTS.solve_failed if failed.any() else RESULTS.successful,
        failed_step=int(fail_k[failed].min()) if failed.any() else -1,
        results=jnp.asarray(results), failed_steps=jnp.asarray(fail_k), failed_residuals=jnp.asarray(fail_res),
        member_iterations=jnp.asarray(its), final_state=out["final_state"],
        monitor=None if out["monitor"] is None else np.asarray(out["monitor"]), **fields,
    )
    if failed.any() and problem.throw:
        i = int(np.argmax(failed))
        k = int(fail_k[i])
        h, t0 = problem.h, problem.t0
        msg = (
            f"{fields['method']}: member {i} of {problem.batch_size}: step {k} (t = {t0 + h * k:.6g} -> "
            f"{t0 + h * (k + 1):.6g}) failed: {RESULTS.solve_failed.message} (residual {float(fail_res[i]):.3e}); "
            f"{int(failed.sum())} member(s) failed"
        )
        raise SolverFailure(msg, step=k, time=t0 + h * k, residual=float(fail_res[i]), solution=sol)
    return sol


def _traced(problem, out, fields) -> Solution:
    system, plan = problem.system, problem.plan
    hj = jnp.asarray(problem.h, jnp.float64)
    k = np.asarray(plan.nodes, dtype=np.float64)
    if plan.save_final:
        k[-1] = problem.steps + problem.partial
    times = jnp.asarray(problem.t0, jnp.float64) + hj * k
    q, R = system.space.coordinates(out["b"]), system.space.orientation(out["b"])
    v, p, energy, residual = out["v"], out["p"], out["energy"], out["residual"]
    states, final_state = out["states"], out["final_state"]
    if problem.throw:
        q = eqx.error_if(q, out["fail_k"] >= 0,
                         f"{fields['method']}: a step failed (its solve did not converge or gave a non-finite value)")
    else:
        # no run-time error: the saved nodes after the failed step are NaN, as a batch's failed member's.
        # A program without eqx.error_if's host callback can be kept in JAX's persistent cache
        # (gnipy.control's compiled constraints: a fresh process then compiles nothing again)
        after = (out["fail_k"] >= 0) & (jnp.asarray(k) > out["fail_k"])

        def blank(a, bad=after):
            if a is None or not jnp.issubdtype(a.dtype, jnp.inexact):
                return a
            return jnp.where(jnp.reshape(bad, jnp.shape(bad) + (1,) * (a.ndim - jnp.ndim(bad))), jnp.nan, a)

        q, R, v, p, energy, residual = (blank(a) for a in (q, R, v, p, energy, residual))
        states = jax.tree_util.tree_map(blank, states)
        final_state = jax.tree_util.tree_map(lambda a: blank(a, out["fail_k"] >= 0), final_state)
    return Solution(times, q, v, p, energy, residual, iterations=out["iterations"], R=R,
                    final_state=final_state, states=states, **fields)
