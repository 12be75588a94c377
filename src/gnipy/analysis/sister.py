r"""Sister systems: a nonholonomic constraint replaced by holonomic ones, switched (the paper's open
question 3, §Conclusions).

A *sister* of a nonholonomic system (Ruina, Rep. Math. Phys. 42 (1998) 91–100; Coleman and Holmes,
Regul. Chaotic Dyn. 4 (1999) 55–77, "the discrete Chaplygin sleigh") keeps its Lagrangian and
replaces each constraint $\mu(q)\dot q = 0$ by a sequence of holonomic ones. At the switch times
$t_k = k\tau$ a new holonomic constraint $\varphi_k(q) = 0$ is engaged, chosen through the present
configuration $q_k = q(t_k)$ and tangent there to the constraint distribution:

$$\varphi_k(q_k) = 0, \qquad d\varphi_k(q_k) = \mu(q_k)\ \ (\text{up to an invertible factor on the rows}),$$

and held until $t_{k+1}$. Between switches the motion is holonomic (smooth, energy-conserving);
at a switch the new constraint engages, a bilateral constraint whose velocity condition
$d\varphi_k(q_k)\dot q = 0$ is the nonholonomic one at $q_k$. The impact it defines is therefore
*plastic*: the velocity is projected $\mathbb{G}$-orthogonally onto $\mathcal D(q_k)$,
$v^+ = P(q_k)v^-$ (a perfectly inelastic impulse $\mu^T\Lambda$; Coleman–Holmes's peg insertion),
which loses the energy $\tfrac12|Q(q_k)v^-|^2_{\mathbb{G}}$. An elastic law
($v^+ = (P - Q)v^-$, the GNI's reflection (Comb)) would leave a velocity off the engaged
constraint, which a holonomic phase cannot hold: the plastic law is the sister system's own.

Two choices of $\varphi_k$:

- the **rail** (default, any system on $\mathbb{R}^n$): the constraint frozen at the switch,
  $\varphi_k(q) = \mu(q_k)(q - q_k)$, a straight track laid along the allowed directions at $q_k$
  (for the knife edge: a rail along the blade's heading at the switch, on which the blade slides
  and about whose contact point it may turn);
- a **peg** or any other `constraint(q, anchor)` the user gives: for the Chaplygin sleigh, the
  contact point's lateral position measured in the body frame, $n(\theta)\cdot(x_c(q) - x_c(q_k))$
  (a peg fixed in the plane at the contact point, sliding in a slot along the body's axis:
  Coleman–Holmes's construction).

:func:`sister_trajectory` simulates the sister system to the reference solver's accuracy (each
phase with diffrax's Dopri8 at tolerance 1e-12, then projected onto $\varphi_k = 0$). As
$\tau \to 0$ the sister motion approaches the nonholonomic one; the energy lost per unit time is
$O(\tau)$ (each impact removes $O(\tau^2)$: the velocity drifts $O(\tau)$ off $\mathcal D$ during
a phase, as $\mathcal D$ turns).

:func:`sister_method` is the discrete method built from the construction, one switch per step: the
plastic impact at $q_k$, then one step of RATTLE (the constrained discrete Euler–Lagrange equations
of Marsden–West, Acta Numerica 10 (2001) §3.5, with the trapezoid $l_d$) on the engaged
constraint $\varphi_k$, ending with the velocity tangent to $\varphi_k = 0$:

$$p_k + D_1L_d(q_k, q_{k+1}) + d\varphi_k(q_k)^T\Lambda_k = 0,\quad \varphi_k(q_{k+1}) = 0,\qquad
  p^-_{k+1} = D_2L_d(q_k, q_{k+1}) + d\varphi_k(q_{k+1})^T\Lambda'_k,\quad
  d\varphi_k(q_{k+1})\,\mathbb{G}^{-1}p^-_{k+1} = 0,$$

$$p_{k+1} = P^*(q_{k+1})\,p^-_{k+1}.$$

The GNI is the same picture with a *free* (unconstrained) discrete flow between the nodes and an
*elastic* impact at each node: $p^-_k = (P^* - Q^*)p^+_k$ (Comb), $FL^-(q_k, q_{k+1}) = p^-_k$. How
the two relate is measured in :mod:`gnipy.experiments.open_questions`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..compilation import jit
from ..equations import lagrange_dalembert_acceleration
from ..errors import InputError
from ..holonomic import project_state
from ..inputs import real_number
from ..integrators.sister import SisterMethod
from ..projectors import projectors
from ..solution import SolverFailure
from ..system import System

__all__ = ["SisterRun", "sister_phase", "sister_trajectory", "sister_method", "rail"]


def _rail(system, q, anchor):
    return system.nonholonomic_mu(anchor) @ (q - anchor)


def _phase_lagrangian(system, q, v, args):
    return system.L(q, v)


def _phase_constraint(constraint, q, args):
    return constraint(q, args["anchor"])


def rail(system) -> Callable:
    """The rail constraint of `system`: `constraint(q, anchor) = mu(anchor) (q - anchor)`, the
    constraint frozen at the switch point (a `jax.tree_util.Partial`: runs of one system share
    their compilation)."""
    return jax.tree_util.Partial(_rail, system)


@dataclass(frozen=True)
class SisterRun:
    """A sister motion (:func:`sister_trajectory`) or a run of the sister method
    (:func:`sister_method`), saved at the switches.

    Attributes:
        t: the switch times $t_k$, (K + 1,).
        q, v: the configuration and the velocity just after each impact (the velocity on
            $\\mathcal D(q_k)$), (K + 1, n).
        energy: the energy there, (K + 1,).
        lost: the energy each impact removed, (K + 1,) (0 at the start, where the initial velocity
            is already on the constraints).
        constraint: the largest |φ_k(q)| at the end of each phase (the holonomic constraint kept),
            (K + 1,).
        tau: the time between switches (the step of the sister method).
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    energy: np.ndarray
    lost: np.ndarray
    constraint: np.ndarray
    tau: float


def _check(system, q0, v0, tau, t_final, constraint, name: str = "tau"):
    """The checked `(q0, v0, K, constraint)` of a sister run."""
    if not isinstance(system, System) or system.group is not None:
        raise InputError("system: a sister system needs a System on R^n (a group part has no rail)")
    if system.affine is not None or system.holonomic is not None or system.force is not None:
        raise InputError("system: sister systems are built for linear nonholonomic constraints without "
                         "holonomic constraints or forces")
    try:
        q0, v0 = np.asarray(q0, dtype=np.float64), np.asarray(v0, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("q0, v0: expected arrays of real numbers") from None
    if q0.shape != (system.n,) or v0.shape != (system.dim,) or not (np.isfinite(q0).all() and np.isfinite(v0).all()):
        raise InputError(f"q0, v0: expected {system.n} finite coordinates and {system.dim} finite velocities, got "
                         f"shapes {q0.shape} and {v0.shape}")
    q0, v0 = jnp.asarray(q0), jnp.asarray(v0)
    tau = real_number(name, tau, lower=0.0, strict=True)
    t_final = real_number("t_final", t_final, lower=0.0, strict=True)
    count = t_final / tau
    K = int(round(count))
    if K < 1 or abs(count - K) > 1e-9 * max(1.0, count):
        raise InputError(f"{name}: t_final = {t_final!r} must be a whole number of switch intervals {name} = {tau!r}")
    constraint = rail(system) if constraint is None else constraint
    mu0 = np.asarray(system.nonholonomic_mu(q0))
    value = np.asarray(constraint(q0, q0))
    rows = np.asarray(jax.jacfwd(lambda q: constraint(q, q0))(q0))
    if value.shape != (mu0.shape[0],) or np.abs(value).max() > 1e-12:
        raise InputError("constraint: constraint(q, anchor) must vanish at q = anchor, one entry per "
                         f"nonholonomic constraint ({mu0.shape[0]}); got {value!r}")
    # its rows must span the constraints' rows at the anchor (the same velocity condition)
    joint = np.linalg.matrix_rank(np.vstack([mu0, rows]), tol=1e-9 * max(1.0, np.abs(mu0).max()))
    if joint != mu0.shape[0] or np.linalg.matrix_rank(rows, tol=1e-9) != mu0.shape[0]:
        raise InputError("constraint: its differential at the anchor must have the rows of the constraints "
                         "mu(anchor) (the holonomic constraint tangent to the distribution there)")
    G = system.metric(q0)
    P, _ = projectors(G, jnp.asarray(mu0))
    if float(jnp.max(jnp.abs(P @ v0 - v0))) > 1e-9 * max(1.0, float(jnp.max(jnp.abs(v0)))):
        raise InputError("v0: the initial velocity is not on the constraints mu(q0) v0 = 0")
    return q0, v0, K, constraint


def sister_phase(system, constraint=None) -> System:
    """The holonomic system of one phase: `system`'s Lagrangian, no nonholonomic constraint, and the
    holonomic constraint `constraint(q, anchor)` (default the rail, :func:`rail`) with the switch
    point as the parameter `args["anchor"]` (so that every phase shares one compilation)."""
    constraint = rail(system) if constraint is None else constraint
    Partial = jax.tree_util.Partial
    return System(Partial(_phase_lagrangian, system), None, holonomic=Partial(_phase_constraint, constraint),
                  coordinates=system.coordinates, velocities=system.velocities, name=f"{system.name}-sister",
                  args={"anchor": np.zeros(system.n)})


def _impact(system, q, v):
    """The plastic impact at q: `(v+, energy lost)`, v+ the G-orthogonal projection of v onto the distribution."""
    G = system.metric(q)
    P, _ = projectors(G, system.nonholonomic_mu(q))
    w = P @ v
    return w, 0.5 * (v @ G @ v - w @ G @ w)


@jit
def _sister_flow(system, phase, q0, v0, tau, K: int):
    import diffrax  # ~0.15 s to import: only when a sister runs

    def rhs(t, y, args):
        ph, = args
        q, v = y[:system.n], y[system.n:]
        a, _ = lagrange_dalembert_acceleration(ph, q, v)
        return jnp.concatenate([v, a])

    controller = diffrax.PIDController(rtol=1e-12, atol=1e-12)

    def one(carry, _):
        q, v = carry
        ph = eqx.tree_at(lambda s: s.args, phase, {"anchor": q})
        sol = diffrax.diffeqsolve(diffrax.ODETerm(rhs), diffrax.Dopri8(), t0=0.0, t1=tau, dt0=None,
                                  y0=jnp.concatenate([q, v]), args=(ph,), stepsize_controller=controller,
                                  max_steps=100_000, throw=False)
        y = sol.ys[-1]
        q1, v1 = project_state(ph, y[:system.n], y[system.n:])
        kept = jnp.max(jnp.abs(ph.phi(y[:system.n])))
        ok = (sol.result == diffrax.RESULTS.successful) & jnp.all(jnp.isfinite(y))
        w, lost = _impact(system, q1, v1)
        return (q1, w), (q1, w, system.energy(q1, w), lost, kept, ok, jnp.nan)

    _, out = jax.lax.scan(one, (q0, v0), None, length=K)
    return out


def _run(system, q0, v0, K, tau, out) -> SisterRun:
    q, v, energy, lost, kept, ok, residual = (np.asarray(a) for a in out)
    if not ok.all():
        k = int(np.argmin(ok))
        raise SolverFailure(f"sister: the phase from t = {k * tau:.6g} to {(k + 1) * tau:.6g} failed (non-finite "
                            "values, the solver's step cap, or the step's Newton solve)", step=k, time=k * tau,
                            residual=float(residual[k]))
    z = lambda a, first: np.concatenate([np.asarray(first)[None], a])
    e0 = float(system.energy(q0, v0))
    return SisterRun(t=tau * np.arange(K + 1), q=z(q, q0), v=z(v, v0), energy=z(energy, e0),
                     lost=z(lost, 0.0), constraint=z(kept, 0.0), tau=float(tau))


def sister_trajectory(system, q0, v0, *, tau: float, t_final: float, constraint=None) -> SisterRun:
    """The sister motion of `system` from `(q0, v0)`: a holonomic phase of length `tau` on the
    constraint `constraint(q, anchor)` through each switch point (default the rail, :func:`rail`),
    then the plastic impact onto the distribution; `t_final` a whole number of phases.

    Each phase is integrated with diffrax's Dopri8 at tolerance 1e-12 (the continuous reference's
    solver) and projected onto $\\varphi_k = 0$ and its velocity constraint at its end. Raises
    InputError on a system that is not on $\\mathbb{R}^n$ with linear constraints, a `constraint`
    that is not tangent to the distribution at the anchor; :class:`~gnipy.SolverFailure` on a failed phase."""
    core = system.without_metadata()
    q0, v0, K, constraint = _check(core, q0, v0, tau, t_final, constraint)
    phase = sister_phase(core, constraint).without_metadata()
    out = _sister_flow(core, phase, q0, v0, jnp.asarray(float(tau)), K)
    return _run(core, q0, v0, K, tau, out)


@jit
def _sister_steps(system, method, q0, v0, h, K: int):
    def one(state, _):
        new, info, p_minus = method.advance(system, state, h)
        q1, p1 = new.b, new.p
        w = system.velocity(q1, p1)
        lost = 0.5 * (p_minus @ system.velocity(q1, p_minus) - p1 @ w)
        kept = jnp.max(jnp.abs(method.engaged(system, q1, state.b)))
        return new, (q1, w, system.energy(q1, w), lost, kept, info.ok, info.residual)

    _, out = jax.lax.scan(one, method.init(system, q0, v0, h), None, length=K)
    return out


def sister_method(system, q0, v0, *, h: float, t_final: float, constraint=None) -> SisterRun:
    """The sister method: one switch per step of size `h` (the module docstring's equations), from
    `(q0, v0)` to `t_final` (a whole number of steps). Each step is a Newton solve for
    $(q_{k+1}, \\Lambda_k)$; the run stops with :class:`~gnipy.SolverFailure` (step, time, residual) at a
    step that fails."""
    core = system.without_metadata()
    q0, v0, K, constraint = _check(core, q0, v0, h, t_final, constraint, "h")
    out = _sister_steps(core, SisterMethod(constraint), q0, v0, jnp.asarray(float(h)), K)
    return _run(core, q0, v0, K, h, out)
