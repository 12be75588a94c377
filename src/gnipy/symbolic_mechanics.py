"""Reading `sympy.physics.mechanics` models for :func:`gnipy.from_sympy`: the Lagrangian, the
constraints and the generalized forces of a mechanics `System` or a `LagrangesMethod`, in the
coordinates and their time derivatives (what :mod:`gnipy.symbolic` then converts to JAX), and the
test that an expression is identically zero that both use."""

from __future__ import annotations

import math
import random

from .errors import InputError
from .extras import require

__all__ = ["from_mechanics_system", "from_lagranges_method", "kinetic_energy", "is_zero"]


def _sympy():
    return require("sympy", extra="sympy")


def kinetic_energy(sp, body, frame, origin):
    """The kinetic energy of `body` in `frame` from the time derivatives of its mass centre's position
    (from the System's fixed point `origin`) and of its orientation: the unconstrained velocities.

    Not `body.kinetic_energy(frame)`, which uses the velocities stored on the points: a model built
    for Kane's method may store them with the constraints already imposed (SymBRiM's tires set the
    contact point's velocity to zero, so the rear contact point's coordinates x, y then do not enter
    the kinetic energy at all and its metric is singular), whereas the Lagrangian of the
    Lagrange–d'Alembert principle is the unconstrained one."""
    if body.mass == 0:
        return sp.Integer(0)
    try:
        r = body.masscenter.pos_from(origin)
    except ValueError as e:  # no path of positions from the System's fixed point
        raise InputError(f"from_sympy: model: the kinetic energy of {body.name} needs the position of its mass "
                         f"centre {body.masscenter} from the System's fixed point {origin}: {e}") from None
    v = r.dt(frame)
    T = body.mass * v.dot(v) / 2
    if hasattr(body, "central_inertia"):  # a rigid body (a particle has none)
        w = body.frame.ang_vel_in(frame)
        T += w.dot(body.central_inertia.dot(w)) / 2
    return T


def is_zero(sp, expr) -> bool:
    """Whether `expr` is identically zero: structurally, else by its values at three random points
    (every free symbol in [0.5, 1.5], a fixed seed) in 30-digit arithmetic, each within 1e-20 of 0.
    An analytic expression that is not identically zero vanishes on a set of measure zero, so this
    errs with probability zero; `sympy.simplify`, which proves it, took 12 s an entry on the
    constraints of SymBRiM's Whipple bicycle (and minutes in all)."""
    expr = sp.sympify(expr)
    if expr == 0:
        return True
    symbols = sorted(expr.free_symbols, key=str)
    rng = random.Random(20071955)
    for _ in range(3):
        point = {x: sp.Float(rng.uniform(0.5, 1.5), 30) for x in symbols}
        value = expr.evalf(30, subs=point)
        if not value.is_number:
            return False
        z = complex(value)
        if not (math.isfinite(z.real) and math.isfinite(z.imag)) or abs(z) > 1e-20:
            return False  # a value that is not small, or none (0/0 at that point): not shown to be zero
    return True


def from_mechanics_system(system):
    """(Lagrangian, coordinates, speeds, constraints, holonomic constraints, generalized forces) of a
    `sympy.physics.mechanics.System`, in q and q̇."""
    sp = _sympy()
    me = require("sympy.physics.mechanics", extra="sympy")
    q = list(system.q)
    u = list(system.u)
    t = me.dynamicsymbols._t
    qd = [c.diff(t) for c in q]
    to_qd = _speeds_in_qdot(sp, system, q, u, qd, t)
    frame, origin = system.frame, system.fixed_point
    try:
        T = sum((kinetic_energy(sp, body, frame, origin) for body in system.bodies), sp.Integer(0))
    except ValueError as e:  # a position or an orientation that is not defined
        raise InputError(f"from_sympy: model: the kinetic energy cannot be formed: {e}") from None
    V = sum((sp.sympify(body.potential_energy) for body in system.bodies), sp.Integer(0))
    moving = []
    for load in [*system.loads, *(load for actuator in system.actuators for load in actuator.to_loads())]:
        if isinstance(load, me.Force) and not any(load.force.diff(x, frame) != 0 for x in (*q, *u, *qd, t)):
            # a constant force (gravity): the potential −F·r, so that an unforced system keeps its energy
            V -= load.force.dot(_position(load.point, origin))
        else:
            moving.append(load)
    L = (T - V).xreplace(to_qd)
    forces = _generalized_forces(sp, me, moving, frame, qd, to_qd,
                                 lambda point: _position(point, origin).dt(frame))
    # the nonholonomic constraints, or the velocity constraints when set by hand; with holonomic
    # constraints only the nonholonomic ones (the velocity constraints then hold dφ/dt too, which
    # gnipy adds itself from φ)
    holonomic = [sp.sympify(c) for c in system.holonomic_constraints]
    velocity = system.nonholonomic_constraints if holonomic else system.velocity_constraints
    constraints = [sp.sympify(c).xreplace(to_qd) for c in velocity]
    return L, q, None, constraints, holonomic, forces


def from_lagranges_method(method):
    """(Lagrangian, coordinates, speeds, constraints, holonomic constraints, generalized forces) of a
    `sympy.physics.mechanics.LagrangesMethod`: its Lagrangian, its `forcelist` as generalized forces
    (the loads' partial velocities from the velocities set on their points, as LagrangesMethod
    forms them), its holonomic and its nonholonomic constraints."""
    sp = _sympy()
    me = require("sympy.physics.mechanics", extra="sympy")
    q = list(method.q)
    qd = list(method._qdots)  # noqa: SLF001 (LagrangesMethod keeps q̇ there; no public name)
    holonomic = list(method._hol_coneqs)  # noqa: SLF001 (the holonomic constraints as given)
    constraints = list(method.coneqs)[len(holonomic):]  # the nonholonomic ones follow dφ/dt
    loads = list(method._forcelist or [])  # noqa: SLF001
    if loads and method.inertial is None:
        raise InputError("from_sympy: model: the LagrangesMethod has loads but no frame (frame=N): the loads' "
                         "generalized forces need the inertial frame")
    loads = [me.Force(*x) if isinstance(x[0], me.Point) else me.Torque(*x) for x in loads]
    forces = _generalized_forces(sp, me, loads, method.inertial, qd, {}, lambda point: point.vel(method.inertial))
    return sp.sympify(method._L[0]), q, None, constraints, holonomic, forces  # noqa: SLF001


def _speeds_in_qdot(sp, system, q, u, qd, t) -> dict:
    """`{u_k: expression in q and q̇}` from the kinematic differential equations (linear in u)."""
    if set(u) == set(qd) or not u:
        return {}
    if len(system.kdes) != len(u):
        raise InputError(f"from_sympy: model: {len(system.kdes)} kinematic differential equations for "
                         f"{len(u)} speeds u; gnipy needs u in terms of q̇")
    try:
        A, b = sp.linear_eq_to_matrix(list(system.kdes), u)
    except ValueError as e:  # sympy.solvers.solveset.NonlinearError
        raise InputError(f"from_sympy: model: the kinematic differential equations are not linear in u ({e})") from None
    if A.has(*qd) or A.has(t) or is_zero(sp, A.det()):
        raise InputError("from_sympy: model: the kinematic differential equations do not give u as a "
                         "function of q and q̇ (linear in u, with coefficients that depend on q only)")
    return dict(zip(u, list(A.LUsolve(b))))


def _position(point, origin):
    try:
        return point.pos_from(origin)
    except ValueError as e:  # no path of positions from the System's fixed point
        raise InputError(f"from_sympy: model: the load on {point} needs its position from the System's fixed point "
                         f"{origin}: {e}") from None


def _generalized_forces(sp, me, loads, frame, qd, to_qd, velocity) -> list:
    """The generalized forces $F_j = \\sum F\\cdot\\partial v_P/\\partial\\dot q_j +
    \\sum \\tau\\cdot\\partial\\omega_B/\\partial\\dot q_j$ of `loads` (forces on points, torques on
    frames), in q, q̇, t and the inputs: the virtual work $\\sum_j F_j\\,\\delta q_j$ of the
    Lagrange–d'Alembert principle with forcing (:mod:`gnipy.forcing`). `velocity(point)` is the
    point's velocity in `frame`; u is rewritten in q̇ by `to_qd`. An empty list without loads."""
    if not loads:
        return []
    out = [sp.Integer(0)] * len(qd)
    for load in loads:
        if isinstance(load, me.Torque):
            vector, rate = load.torque, load.frame.ang_vel_in(frame)
        else:
            vector, rate = load.force, velocity(load.point)
        vector = vector.xreplace(to_qd) if to_qd else vector
        rate = rate.xreplace(to_qd) if to_qd else rate
        for j, v in enumerate(qd):
            out[j] += vector.dot(rate.diff(v, frame))
    return out
