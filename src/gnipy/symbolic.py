"""Systems from SymPy: :func:`from_sympy` builds a :class:`~gnipy.System` from a model written with
SymPy, in either of two forms.

- **The plain form**: a Lagrangian expression, the coordinates, the constraint expressions and the
  parameters' values. The coordinates are plain symbols (then `speeds` names the symbols of their
  velocities) or `sympy.physics.mechanics.dynamicsymbols` (then the velocities are their time
  derivatives, as `sympy.physics.mechanics` writes them).
- **A `sympy.physics.mechanics.System`**: its bodies (particles and rigid bodies, with their
  `potential_energy`; the kinetic energy is formed from the time derivatives of their mass
  centres' positions and of their orientations, not from the velocities stored on their points,
  which a model made for Kane's method may store with the constraints already imposed), its
  loads and actuators, its kinematic differential equations (u = q̇, or any relation linear in u
  and q̇: the kinetic energy, the loads and the constraints are rewritten in q̇), its holonomic
  constraints and its nonholonomic constraints.
- **A `sympy.physics.mechanics.LagrangesMethod`**: its Lagrangian, coordinates, `forcelist`, and
  holonomic and nonholonomic constraints.

**Loads.** A constant force on a point (gravity, `System.apply_uniform_gravity`) becomes the
potential $-F\\cdot r$ from the System's `fixed_point`, so that a model without other loads is
unforced and keeps the energy behaviour of the methods. Every other load (a force that depends on
q, u, t or an input; a torque on a frame; the loads of an actuator: `LinearSpring`,
`LinearDamper`, `TorqueActuator`, ...) becomes the generalized force
$F_j = \\sum F\\cdot\\partial v_P/\\partial\\dot q_j + \\sum\\tau\\cdot\\partial\\omega_B/\\partial\\dot q_j$
(the virtual work of the Lagrange–d'Alembert principle with forcing, :mod:`gnipy.forcing`),
and the System is forced (`force(q, v, u, t, args)`). The plain form takes the generalized forces
as `forces`. The functions of time that a controller sets (motor torques) are named in `inputs`:
they become the System's inputs, in that order (`controls=` of :func:`gnipy.simulate`, the
inputs of :mod:`gnipy.control`). A spring written as a load is a force, not a potential: give its
potential energy to a body (`potential_energy`) to keep the system unforced.

What gnipy integrates is $l(q, \\dot q) = T - V$ on $\\mathbb{R}^n$ ($q$ the coordinates in the
order given, or the System's `q`; the velocities are $\\dot q$) with the constraints
$c(q, \\dot q) = 0$, which must be affine in $\\dot q$: $c = \\mu(q)\\dot q + c_0(q)$. gnipy writes
them as $\\mu(q)(\\dot q - Y(q)) = 0$ with $\\mu = \\partial c/\\partial\\dot q$ and
$Y = -\\mu^T(\\mu\\mu^T)^{-1}c_0$ (the shortest vector with $\\mu Y = -c_0$). Only $\\mu Y$ enters
the equations (the constraint set; in the GNI, $Q^*\\Pi = \\mu^T C^{-1}\\mu Y$), so any other choice
gives the same motion; tests/test_symbolic.py holds the rotating-table ball built from SymPy equal
to the zoo's, whose $Y$ is another, with four methods. A constraint with $c_0 \\equiv 0$ for every
row makes the system linear (`is_affine` False). Holonomic constraints $\\varphi(q) = 0$ (the plain
form's `holonomic`, a mechanics System's `holonomic_constraints`) become the System's `holonomic`
(:mod:`gnipy.holonomic`); a mechanics System's velocity constraints then are its nonholonomic
ones only, since gnipy adds the derivatives $d\\varphi\\,\\dot q = 0$ itself.

The parameters (the symbols that are neither coordinates nor velocities) become the System's
`args`, named by their symbols' names: `jax.grad` reaches them, `with_args` changes them, and
batches, sweeps, `fit` and control set them by name, as for any System.

**How the expressions become JAX functions.** With `sympy2jax` (P. Kidger's converter, from the
JAX/equinox ecosystem): it walks the expression tree and maps each SymPy node to a `jax.numpy`
function (identical subtrees are evaluated once). No source code is generated or executed, unlike
`sympy.lambdify`, which prints Python source and `exec`s it: what runs is JAX operations on the
expression's own nodes, and a function SymPy cannot map (an undefined function, a derivative left
in an expression) is refused by name when the System is built.

What the conversion refuses, each with an :class:`~gnipy.InputError` naming the argument:
a velocity constraint without velocities (a holonomic constraint: give it as `holonomic`), a
holonomic constraint with velocities, a function of time in a load that is not named in `inputs`
(or an input in the Lagrangian or the constraints), kinematic equations that are not linear in u
with coefficients in q, explicit time dependence of the Lagrangian or the constraints, a
Lagrangian that is not of mechanical type (quadratic in the velocities, with no linear term), a
constraint that is not affine in the velocities, a symbol whose value is not given (or a value for
a symbol the model does not have), coordinates declared with assumptions on their values
(`positive=True`: SymPy may already have simplified `Abs(x)` to `x`), the imaginary unit, and a
`KanesMethod` (its equations are in the speeds with the velocity constraints already imposed; the
GNI needs the Lagrangian of the unconstrained system: give the bodies, loads and constraints as a
mechanics System).

**Models written by others.** SymBRiM's Whipple bicycle (the `symbrim` package, bicycle–rider
models for `sympy.physics.mechanics`), converted by :func:`from_sympy` with the benchmark's
parameters, gives the accelerations of Basu-Mandal et al. (2007) Table 1 to 1.1e-12, as
:mod:`gnipy.models.whipple_bicycle` does (tests/test_symbolic.py); its conversion takes about 6 s.
Which constraint rows have no velocities, and whether there is an affine part, is decided by
evaluating the expressions at random points in 30-digit arithmetic (:func:`gnipy.symbolic_mechanics.is_zero`), not by
`sympy.simplify`, which took minutes on that bicycle's constraints.

Conversions are cached (:func:`_functions`): Systems made from the same expressions share their
functions, differ only in `args`, and so run as one batch (a sweep over a parameter of a function
that calls :func:`from_sympy` each time).
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping, Sequence
from typing import Any

import jax.numpy as jnp

from .errors import InputError
from .extras import require
from .inputs import real_number
from .linalg import solve_spd
from .symbolic_mechanics import from_lagranges_method, from_mechanics_system, is_zero
from .system import System

__all__ = ["from_sympy"]


def _sympy():
    return require("sympy", extra="sympy")


def from_sympy(
    model: Any,
    coordinates: Sequence[Any] | None = None,
    *,
    speeds: Sequence[Any] | None = None,
    constraints: Sequence[Any] = (),
    holonomic: Sequence[Any] = (),
    forces: Sequence[Any] = (),
    inputs: Sequence[Any] = (),
    params: Mapping[Any, float] | None = None,
    name: str = "sympy-system",
    coordinate_names: Sequence[str] | None = None,
    defaults: tuple | None = None,
) -> System:
    """A :class:`~gnipy.System` on $\\mathbb{R}^n$ from a SymPy model (module docstring).

    Arguments:
        model: the Lagrangian, a SymPy expression in the coordinates, their velocities and the
            parameters (the plain form); a `sympy.physics.mechanics.System`; or a
            `sympy.physics.mechanics.LagrangesMethod` (its Lagrangian, coordinates, loads and
            constraints).
        coordinates: the plain form's coordinates q, SymPy symbols or `dynamicsymbols`, in the
            order of the System's q. Not given with a mechanics System (its `q` is used).
        speeds: the plain form's velocity symbols, one per coordinate, when the coordinates are
            plain symbols; default: the coordinates' time derivatives (for `dynamicsymbols`).
        constraints: the plain form's constraint expressions c(q, q̇) (each = 0), affine in the
            velocities. Not given with a mechanics System (its nonholonomic constraints are used).
        holonomic: the plain form's holonomic constraints φ(q) (each = 0), expressions in the
            coordinates and parameters (:mod:`gnipy.holonomic`). Not given with a mechanics System
            (its `holonomic_constraints` are used).
        forces: the plain form's generalized forces, one expression per coordinate (the virtual
            work is $\\sum_j F_j\\,\\delta q_j$), in the coordinates, the velocities, the time
            `t` (`dynamicsymbols._t`), the `inputs` and the parameters. Not given with a mechanics
            System or a LagrangesMethod (their loads are used).
        inputs: the symbols (usually `dynamicsymbols`) of the forces that a controller chooses:
            the System's inputs u, in this order (`controls=` of :func:`gnipy.simulate`, the
            inputs of :mod:`gnipy.control`). Every other function of time in a load is refused.
        params: the value of every other symbol of the model: `{symbol or name: float}`. They
            become the System's `args`, named by the symbols' names.
        name: the System's name (in reports and files).
        coordinate_names: the coordinates' names (default: the symbols' names, a dynamicsymbol
            `x(t)` giving `x`).
        defaults: an optional default initial condition `(q0, v0)`.

    Returns:
        The System, with `lagrangian(q, v, args)`, `constraints(q, args)` (None without
        nonholonomic constraints), `holonomic(q, args)` with holonomic constraints, when the
        constraints are affine `affine(q, args)`, and with forces `force(q, v, u, t, args)` and
        `len(inputs)` inputs.

    Raises:
        InputError: on what the conversion cannot take (module docstring), naming the argument.
        MissingExtra: without SymPy or sympy2jax (`pip install 'gnipy[sympy]'`).
    """
    sp = _sympy()
    me = require("sympy.physics.mechanics", extra="sympy")
    if isinstance(model, (me.System, me.LagrangesMethod)):
        kind = "mechanics System" if isinstance(model, me.System) else "LagrangesMethod"
        if (coordinates is not None or speeds is not None or _sequence(constraints, "constraints")
                or _sequence(holonomic, "holonomic") or _sequence(forces, "forces")):
            raise InputError(f"from_sympy: coordinates, speeds, constraints, holonomic and forces are read from the "
                             f"{kind}; do not pass them too")
        read = from_mechanics_system if isinstance(model, me.System) else from_lagranges_method
        lagrangian, coordinates, speeds, constraints, holonomic, forces = read(model)
    elif isinstance(model, me.KanesMethod):
        raise InputError("from_sympy: model is a KanesMethod, whose equations are written in the speeds u with the "
                         "velocity constraints already imposed; the GNI discretizes the Lagrangian of the "
                         "unconstrained system with the constraints beside it. Give the same bodies, loads and "
                         "constraints as a sympy.physics.mechanics.System (System(frame, fixed_point), add_bodies, "
                         "add_loads, add_holonomic_constraints, add_nonholonomic_constraints) or a LagrangesMethod")
    elif isinstance(model, sp.Basic):
        if coordinates is None:
            raise InputError("from_sympy: coordinates is needed with a Lagrangian expression (the symbols of q)")
        lagrangian = sp.sympify(model)
    else:
        raise InputError(f"from_sympy: model must be a SymPy expression (the Lagrangian), a "
                         f"sympy.physics.mechanics.System or a LagrangesMethod, not {type(model).__name__}")
    constraints = _sequence(constraints, "constraints")
    holonomic = _sequence(holonomic, "holonomic")
    forces = _sequence(forces, "forces")
    q, qd, names = _coordinates_and_speeds(coordinates, speeds, coordinate_names)
    n = len(q)
    if forces and len(forces) != n:
        raise InputError(f"from_sympy: forces has {len(forces)} entries for {n} coordinates (one generalized force "
                         f"per coordinate)")
    exprs = {"model": sp.sympify(lagrangian), **{f"constraints[{i}]": sp.sympify(c) for i, c in enumerate(constraints)},
             **{f"holonomic[{i}]": sp.sympify(c) for i, c in enumerate(holonomic)}}
    force_exprs = {f"forces[{i}]": sp.sympify(f) for i, f in enumerate(forces)}
    us = _inputs(inputs, q, qd)
    _check_symbols({**exprs, **force_exprs}, [*q, *us], qd)
    # plain symbols in place of q and q̇ (dynamicsymbols are applied functions of t); no symbol of
    # the model has these names (_check_symbols)
    qs, vs = _internal_symbols(n)
    swap = {**dict(zip(qd, vs)), **dict(zip(q, qs))}  # xreplace matches q̇ = Derivative(q(t), t) before q(t)
    for where, e in exprs.items():
        for i, u in enumerate(us):
            if e.has(u):
                raise InputError(f"from_sympy: {where} involves inputs[{i}] = {u}: inputs enter the forces only")
    L, *rest = (_substituted(e, swap, where) for where, e in exprs.items())
    cons, hol = rest[:len(constraints)], rest[len(constraints):]
    time = _time_symbol(params)
    input_symbols, t_internal = _internal_inputs(len(us))
    force_swap = {**swap, **dict(zip(us, input_symbols)), **({time: t_internal} if time is not None else {})}
    F = [_substituted(e, force_swap, where) for where, e in force_exprs.items()]
    if F and all(f == 0 for f in F):
        F = []
    if us and not F:
        raise InputError("from_sympy: inputs are given but the model has no forces for them to enter")
    for i, (u, s_) in enumerate(zip(us, input_symbols)):
        if not any(f.has(s_) for f in F):
            raise InputError(f"from_sympy: inputs[{i}] = {u} does not appear in the forces")
    if not cons and not hol:
        raise InputError("from_sympy: constraints: no constraint given (nonholonomic, or holonomic); gnipy "
                         "integrates constrained systems")
    for i, c in enumerate(hol):
        if c.free_symbols & set(vs):
            raise InputError(f"from_sympy: holonomic[{i}] = {holonomic[i]} involves the velocities: a holonomic "
                             "constraint is a function of the coordinates (give a velocity constraint as constraints)")
    values = _parameters(params, [L, *cons, *hol, *F], set(qs) | set(vs) | set(input_symbols) | {t_internal})
    try:
        lagrangian_fn, constraints_fn, affine_fn, holonomic_fn, force_fn = _functions(
            L, tuple(cons), tuple(hol), n, tuple(F), len(us))
    except InputError as e:  # say it in the model's own symbols
        user = ({f"{_INTERNAL}q{i}": str(c) for i, c in enumerate(q)} | {f"{_INTERNAL}v{i}": str(v) for i, v in enumerate(qd)}
                | {f"{_INTERNAL}u{i}": str(u) for i, u in enumerate(us)} | {f"{_INTERNAL}t": "t"})
        raise InputError(re.sub(rf"\b{_INTERNAL}([qvu]\d+|t)\b", lambda m: user[m.group(0)], str(e))) from None
    return System(lagrangian_fn, constraints_fn, affine_fn, holonomic=holonomic_fn, coordinates=names, name=name,
                  args=values, defaults=defaults, force=force_fn, inputs=len(us))


def _inputs(inputs, q, qd) -> list:
    """The `inputs` argument checked: distinct symbols or dynamicsymbols, not coordinates or speeds."""
    sp = _sympy()
    us = _sequence(inputs, "inputs")
    for i, u in enumerate(us):
        if not (isinstance(u, sp.Symbol) or (isinstance(u, sp.core.function.AppliedUndef) and len(u.args) == 1)):
            raise InputError(f"from_sympy: inputs[{i}] = {u} is neither a symbol nor a dynamicsymbol")
        if u in q or u in qd:
            raise InputError(f"from_sympy: inputs[{i}] = {u} is a coordinate or a speed")
    if len(set(us)) != len(us):
        raise InputError("from_sympy: inputs repeats a symbol")
    return us


def _time_symbol(params):
    """The symbol of time in the forces: `dynamicsymbols._t` (the symbol `t`), unless `params` gives
    a parameter named t."""
    me = require("sympy.physics.mechanics", extra="sympy")
    if not isinstance(params, Mapping):  # None, or not a mapping (which _parameters refuses by name)
        return me.dynamicsymbols._t
    named = {k if isinstance(k, str) else getattr(k, "name", None) for k in params}
    return None if "t" in named else me.dynamicsymbols._t


def _internal_inputs(m: int):
    """The plain symbols that stand for the inputs and for the time inside the conversion."""
    sp = _sympy()
    return [sp.Symbol(f"{_INTERNAL}u{k}", real=True) for k in range(m)], sp.Symbol(f"{_INTERNAL}t", real=True)


def _internal_symbols(n: int):
    """The plain symbols that stand for q and q̇ inside the conversion."""
    sp = _sympy()
    return ([sp.Symbol(f"{_INTERNAL}q{i}", real=True) for i in range(n)],
            [sp.Symbol(f"{_INTERNAL}v{i}", real=True) for i in range(n)])


#: the prefix of the names of :func:`_internal_symbols` (a model's own symbols may not start with it)
_INTERNAL = "gnipy_"


@functools.lru_cache(maxsize=64)
def _functions(L, cons: tuple, hol: tuple, n: int, forces: tuple = (), m: int = 0):
    """The System's functions `(lagrangian, constraints or None, affine or None, holonomic or None,
    force or None)` of the substituted
    expressions (in `gnipy_q{i}`, `gnipy_v{i}` and the parameters' symbols), made once per model:
    Systems converted from the same expressions share the function objects, so that they differ
    only in `args` and run as one batch (a sweep's members, a fit's trials), as those of one
    hand-written System's `with_args` do."""
    sp = _sympy()
    qs, vs = _internal_symbols(n)
    _check_mechanical_type(sp, L, vs)
    mu, c0 = _affine_parts(sp, cons, vs)
    affine = any(not is_zero(sp, c) for c in c0)

    s2j = require("sympy2jax", extra="sympy")
    qnames, vnames = [s.name for s in qs], [s.name for s in vs]

    def converted(expressions, where):
        try:
            return s2j.SymbolicModule(expressions, make_array=False)
        except KeyError as e:
            raise InputError(f"from_sympy: {where}: a function gnipy cannot convert to JAX: {e.args[0]}") from None

    L_fn = converted(L, "model")
    mu_rows = [converted(list(row), f"constraints[{i}]") for i, row in enumerate(mu)]
    c0_fn = converted(list(c0), "constraints") if affine else None
    phi_fn = converted(list(hol), "holonomic") if hol else None
    force_fn = converted(list(forces), "forces") if forces else None
    unames = [s.name for s in _internal_inputs(m)[0]]
    tname = _internal_inputs(0)[1].name

    def mu_at(q, args):
        values = values_at(q, None, args)
        return _matrix([row(**values) for row in mu_rows])

    def values_at(q, v, args):
        out = dict(args)
        out.update({name: q[i] for i, name in enumerate(qnames)})
        if v is not None:
            out.update({name: v[i] for i, name in enumerate(vnames)})
        return out

    def sympy_lagrangian(q, v, args):
        return jnp.asarray(L_fn(**values_at(q, v, args)), dtype=jnp.float64)

    def sympy_constraints(q, args):
        return mu_at(q, args)

    def sympy_affine(q, args):
        m = mu_at(q, args)
        c = jnp.stack([jnp.asarray(x, dtype=jnp.float64) * jnp.ones_like(q[0]) for x in c0_fn(**values_at(q, None, args))])
        return -m.T @ solve_spd(m @ m.T, c)  # μμᵀ is symmetric positive definite (μ of full rank)

    def sympy_holonomic(q, args):
        return jnp.stack([jnp.asarray(x, dtype=jnp.float64) * jnp.ones_like(q[0])
                          for x in phi_fn(**values_at(q, None, args))])

    def sympy_force(q, v, u, t, args):
        values = values_at(q, v, args)
        values.update({name: u[k] for k, name in enumerate(unames)})
        values[tname] = t
        zero = jnp.zeros_like(q[0] * v[0])
        return jnp.stack([jnp.asarray(x, dtype=jnp.float64) + zero for x in force_fn(**values)])

    return (sympy_lagrangian, sympy_constraints if cons else None, (sympy_affine if affine else None),
            sympy_holonomic if hol else None, sympy_force if forces else None)


def _matrix(rows) -> jnp.ndarray:
    """The nested list of a converted matrix (entries are JAX scalars or Python numbers) as float64."""
    entries = [jnp.asarray(x, dtype=jnp.float64) for row in rows for x in row]
    shape = jnp.broadcast_shapes(*(e.shape for e in entries))
    return jnp.stack([jnp.broadcast_to(e, shape) for e in entries]).reshape(len(rows), len(rows[0]), *shape)


def _sequence(value, argument: str) -> list:
    """`value` as a list: a sequence (list, tuple, SymPy matrix) of expressions, not one expression."""
    sp = _sympy()
    if isinstance(value, (sp.Basic, str)) and not isinstance(value, sp.MatrixBase):
        raise InputError(f"from_sympy: {argument} must be a sequence (a list of expressions), not one "
                         f"expression: write [{value}]")
    try:
        return list(value)
    except TypeError:
        raise InputError(f"from_sympy: {argument} must be a sequence, not {type(value).__name__}") from None


#: assumptions that would let SymPy rewrite an expression for some values of a coordinate or a
#: velocity only (e.g. Abs(x) -> x for a positive x), which the numbers then break
_VALUE_ASSUMPTIONS = ("positive", "negative", "nonnegative", "nonpositive", "zero", "nonzero", "integer")


def _coordinates_and_speeds(coordinates, speeds, coordinate_names):
    sp = _sympy()
    q = _sequence(coordinates, "coordinates")
    if not q:
        raise InputError("from_sympy: coordinates is empty")
    for i, c in enumerate(q):
        if not (isinstance(c, sp.Symbol) or (isinstance(c, sp.core.function.AppliedUndef) and len(c.args) == 1)):
            raise InputError(f"from_sympy: coordinates[{i}] = {c} is neither a symbol nor a dynamicsymbol")
    if len(set(q)) != len(q):
        raise InputError("from_sympy: coordinates repeats a symbol")
    if speeds is None:
        if not all(isinstance(c, sp.core.function.AppliedUndef) for c in q):
            raise InputError("from_sympy: speeds is needed when the coordinates are plain symbols "
                             "(or give dynamicsymbols, whose time derivatives are the velocities)")
        qd = [c.diff(c.args[0]) for c in q]
    else:
        qd = _sequence(speeds, "speeds")
        if len(qd) != len(q):
            raise InputError(f"from_sympy: speeds has {len(qd)} entries for {len(q)} coordinates")
        for i, v in enumerate(qd):
            if not isinstance(v, (sp.Symbol, sp.Derivative)) or v in q:
                raise InputError(f"from_sympy: speeds[{i}] = {v} must be a symbol that is not a coordinate")
        if len(set(qd)) != len(qd):
            raise InputError("from_sympy: speeds repeats a symbol")
    for argument, symbols in (("coordinates", q), ("speeds", qd)):
        for i, c in enumerate(symbols):
            if isinstance(c, sp.Symbol) and any(getattr(c, f"is_{a}") is not None for a in _VALUE_ASSUMPTIONS):
                raise InputError(f"from_sympy: {argument}[{i}] = {c} carries an assumption on its values (positive, "
                                 f"integer, ...), under which SymPy may have simplified the model (Abs(x) -> x) in a "
                                 f"way that other values break; declare it without one, or real=True")
    if coordinate_names is None:
        names = tuple(str(c.func) if isinstance(c, sp.core.function.AppliedUndef) else c.name for c in q)
    else:
        names = tuple(str(x) for x in coordinate_names)
        if len(names) != len(q):
            raise InputError(f"from_sympy: coordinate_names has {len(names)} entries for {len(q)} coordinates")
    return q, qd, names


def _check_symbols(exprs, q, qd) -> None:
    """A free symbol of the model named like a coordinate or a velocity but not that symbol (declared
    with other assumptions), or with the conversion's own prefix, is refused: it would be a parameter."""
    sp = _sympy()
    own = {str(c): c for c in (*q, *qd) if isinstance(c, sp.Symbol)}
    for where, e in exprs.items():
        for s in e.free_symbols:
            if s.name in own and s != own[s.name]:
                raise InputError(f"from_sympy: {where}: the symbol {s} is not the coordinate or speed {s} (declared "
                                 f"with other assumptions?): use the same symbol object")
            if s.name.startswith(_INTERNAL):
                raise InputError(f"from_sympy: {where}: the symbol {s}: names that start with {_INTERNAL!r} are "
                                 f"gnipy's own in the conversion; rename it")


def _substituted(expr, swap, where):
    """`expr` with q and q̇ replaced by plain symbols; refused where a function of time is left."""
    sp = _sympy()
    out = expr.xreplace(swap)
    left = out.atoms(sp.Derivative) | out.atoms(sp.core.function.AppliedUndef)
    if left:
        back = {v: k for k, v in swap.items()}
        names = ", ".join(sorted(str(a.xreplace(back)) for a in left))
        raise InputError(f"from_sympy: {where}: {names} is not a coordinate, a velocity or a function gnipy can "
                         f"evaluate (undefined functions and accelerations are not supported; a function of time that a "
                         f"controller sets is an input: name it in inputs=[...], it may enter the forces only)")
    return out


def _parameters(params, exprs, known) -> dict[str, float]:
    """`{name: value}` of every free symbol that is not a coordinate or a velocity."""
    sp = _sympy()
    if params is not None and not isinstance(params, Mapping):
        raise InputError(f"from_sympy: params must be a mapping {{symbol or name: value}}, not {type(params).__name__}")
    given = {}
    for key, value in dict(params or {}).items():
        if not isinstance(key, (sp.Symbol, str)):
            raise InputError(f"from_sympy: params: a key must be a symbol or a name, not {key!r}")
        name = key.name if isinstance(key, sp.Symbol) else key
        if name in given:
            raise InputError(f"from_sympy: params gives {name!r} twice")
        if not name.isidentifier():
            raise InputError(f"from_sympy: params: {name!r} is not a Python name, which gnipy's args need (it names "
                             f"the parameter in --set, sweeps and fits): rename the symbol")
        given[name] = real_number(f"from_sympy: params[{name!r}]", value)
    if any(e.has(sp.I) for e in exprs):
        raise InputError("from_sympy: the model holds the imaginary unit I; gnipy's systems are real")
    free = sorted({s.name for e in exprs for s in e.free_symbols if s not in known})
    unknown = sorted(set(given) - set(free))
    if unknown:
        raise InputError(f"from_sympy: params: {', '.join(unknown)} is not a symbol of the model")
    if "t" in free and "t" not in given:
        raise InputError("from_sympy: the model depends on t explicitly (a rheonomic system), which gnipy does "
                         "not integrate; if t is a parameter, give its value in params")
    missing = [name for name in free if name not in given]
    if missing:
        raise InputError(f"from_sympy: params: no value for {', '.join(missing)}")
    return {name: given[name] for name in free}


def _check_mechanical_type(sp, L, vs) -> None:
    try:
        poly = sp.Poly(sp.expand(L), *vs)
    except sp.PolynomialError:
        raise InputError("from_sympy: the Lagrangian is not a polynomial in the velocities; gnipy needs one of "
                         "mechanical type, l = ½ q̇ᵀ G(q) q̇ − V(q)") from None
    degrees = {sum(m) for m in poly.monoms()}
    if not degrees <= {0, 2}:
        raise InputError(f"from_sympy: the Lagrangian has terms of degree {sorted(degrees - {0, 2})} in the "
                         f"velocities; gnipy needs one of mechanical type, l = ½ q̇ᵀ G(q) q̇ − V(q)")


def _affine_parts(sp, cons, vs):
    """μ = ∂c/∂q̇ (rows) and c₀ = c(q, 0), after checking that each c is affine in q̇ and involves
    the velocities."""
    rows, c0 = [], []
    for i, c in enumerate(cons):
        row = [sp.diff(c, v) for v in vs]
        if any(entry.free_symbols & set(vs) for entry in row):
            row = [sp.simplify(entry) for entry in row]
            if any(entry.free_symbols & set(vs) for entry in row):
                raise InputError(f"from_sympy: constraints[{i}] is not affine in the velocities: {c}")
        if all(is_zero(sp, entry) for entry in row):
            raise InputError(f"from_sympy: constraints[{i}] = {c} does not involve the velocities: a "
                             f"holonomic constraint; give it as holonomic=[...] (gnipy keeps it exactly)")
        rows.append(row)
        c0.append(c.xreplace(dict.fromkeys(vs, 0)))
    return rows, c0
