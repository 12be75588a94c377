"""The continuous reference: the equations of motion of :mod:`gnipy.equations` (λ eliminated),
with the reconstruction $\\dot R = R\\hat\\xi$, integrated with diffrax's 8th-order Dormand–Prince
at tolerance ~1e-12 and returned as a :class:`~gnipy.Solution` (the driver's layer: it runs as the
method `"reference"` of :func:`gnipy.simulate`).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .equations import lagrange_dalembert_acceleration
from .solution import Solution, SolverFailure

__all__ = ["ContinuousReference"]


class ContinuousReference(eqx.Module):
    """High-accuracy solution of the continuous equations (the yardstick of convergence tests).

    Arguments:
        rtol, atol: tolerances of the adaptive controller (default 1e-12).
        max_steps: cap on the number of adaptive steps.
    """

    rtol: float = eqx.field(static=True, default=1e-12)
    atol: float = eqx.field(static=True, default=1e-12)
    max_steps: int = eqx.field(static=True, default=1_000_000)
    name: ClassVar[str] = "reference"
    order: ClassVar[int | None] = None
    #: keeps holonomic constraints: projects onto φ = 0 at every saved time (:mod:`gnipy.holonomic`)
    holonomic: ClassVar[bool] = True

    def solve(self, system, b0, v0, times, *, h=float("nan"), t0=None) -> Solution:
        """Integrate from `t0` (default `times[0]`) and save at `times` (host arrays, monotone; a
        run backward in time when they decrease); returns a Solution.

        `b0` is the base point (`q0` on $\\mathbb{R}^n$, a :class:`~gnipy.spaces.Point` on
        $\\mathbb{R}^n\\times G$), `v0` the velocity on the constraints."""
        times = np.asarray(times, dtype=np.float64)
        start = times[0] if t0 is None else float(t0)
        ts = times if start == times[0] else np.concatenate([[start], times])  # the start is not saved
        # the system without its provenance (the parameters' values as metadata): the compiled
        # solver is shared by runs of other parameter values (their array leaves are traced)
        core = system.without_metadata()
        solve = _solve if system.holonomic is None else _solve_projected
        ys, num_steps, ok = solve(self, core, b0, jnp.asarray(v0), jnp.asarray(ts))
        ys = ys[len(ts) - len(times):]
        meta = dict(system=system.name, method=self.name, h=float(h), coordinates=system.coordinates,
                    params=system.params, start="continuous", orientation=system.orientation_description)
        if not bool(ok):
            raise SolverFailure(
                f"reference: the adaptive solver failed before t = {times[-1]:.6g} (step cap {self.max_steps} "
                "or non-finite values)", step=-1, time=float(times[0]), residual=float("nan"),
            )
        q, R, v, p, energy, res = _nodes(core, ys)
        its = jnp.asarray([int(num_steps), 0], dtype=jnp.int32)
        return Solution(jnp.asarray(times), q, v, p, energy, res, its, R=R, velocities=system.velocities, **meta)


@jit
def _nodes(system, ys):
    """The saved nodes' coordinates, orientations, velocities, momenta, energies and constraint
    residuals from the solver's states (compiled: evaluated eagerly, the metric's Hessian alone
    costs a second of small compilations)."""
    N = system.dim
    space = system.space
    b = jax.vmap(space.unpack)(ys[:, :-N])
    v = ys[:, -N:]
    p = jax.vmap(system.momentum)(b, v)
    energy = jax.vmap(system.energy)(b, v)
    res = jax.vmap(system.constraint_residual)(b, v)
    return space.coordinates(b), space.orientation(b), v, p, energy, res


@jit
def _solve_projected(ref, system, b0, v0, times):
    """:func:`_solve` for a system with holonomic constraints: from each saved time to the next,
    then the state projected onto $\\varphi = 0$ and the velocity constraints
    (:func:`gnipy.holonomic.project_state`), so that the drift of the index-2 equations off
    $\\varphi = 0$ does not add up over the run."""
    from .holonomic import project_state

    space = system.space
    N = v0.shape[0]

    def segment(y, span):
        ys, steps, ok = _solve(ref, system, space.unpack(y[:-N]), y[-N:], span)
        b, v = project_state(system, space.unpack(ys[-1, :-N]), ys[-1, -N:])
        y1 = jnp.concatenate([space.pack(b), v])
        return y1, (y1, steps, ok)

    y0 = jnp.concatenate([space.pack(b0), v0])
    _, (ys, steps, ok) = jax.lax.scan(segment, y0, jnp.stack([times[:-1], times[1:]], axis=1))
    return jnp.concatenate([y0[None], ys]), jnp.sum(steps), jnp.all(ok)


@jit
def _solve(ref, system, b0, v0, times):
    space = system.space
    N = v0.shape[0]

    def rhs(t, y, args):
        b, v = space.unpack(y[:-N]), y[-N:]
        a, _ = lagrange_dalembert_acceleration(system, b, v, t)
        return jnp.concatenate([space.pack_velocity(b, v), a])

    # Land a step on every save time: Dopri8's dense-output interpolant is far less accurate than
    # its steps (errors ~3e-10 at save points on the contact oscillator with rtol = atol = 1e-12).
    # Inputs held over steps jump at the grid times t0 + k h: the steps end there too (the
    # solver restarts its error control across a jump instead of stepping over it)
    jumps = None
    drive = system.drive
    if system.force is not None and drive.values is not None and drive.values.shape[0] > 1:
        jumps = drive.t0 + drive.h * jnp.arange(1, drive.values.shape[0], dtype=jnp.float64)
    import diffrax  # ~0.15 s to import: only when the reference runs

    controller = diffrax.PIDController(rtol=ref.rtol, atol=ref.atol)
    if hasattr(diffrax, "ClipStepSizeController"):  # diffrax >= 0.7
        controller = diffrax.ClipStepSizeController(controller, step_ts=times, jump_ts=jumps)
    else:
        controller = diffrax.PIDController(rtol=ref.rtol, atol=ref.atol, step_ts=times, jump_ts=jumps)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(rhs),
        diffrax.Dopri8(),
        t0=times[0],
        t1=times[-1],
        dt0=None,
        y0=jnp.concatenate([space.pack(b0), v0]),
        saveat=diffrax.SaveAt(ts=times),
        stepsize_controller=controller,
        max_steps=ref.max_steps,
        throw=False,
    )
    ok = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(sol.ys))
    return sol.ys, sol.stats["num_steps"], ok
