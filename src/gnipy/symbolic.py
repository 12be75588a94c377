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
  constant loads (gravity, `System.apply_uniform_gravity`, and any other
  constant force on a point, whose potential is $-F\\cdot r$ from the system's `fixed_point`), its
  kinematic differential equations (u = q̇, or any relation linear in u and q̇: the kinetic
  energy and the constraints are rewritten in q̇), its holonomic constraints and its nonholonomic
  constraints.

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
holonomic constraint with velocities, loads that are not constant (a force that
depends on q, u or t, a torque, an actuator), kinematic equations that are not linear in u with
coefficients in q, explicit time dependence, a Lagrangian that is not of mechanical type (quadratic
in the velocities, with no linear term), a constraint that is not affine in the velocities, a
symbol whose value is not given (or a value for a symbol the model does not have), coordinates
declared with assumptions on their values (`positive=True`: SymPy may already have simplified
`Abs(x)` to `x`), and the imaginary unit.

**Models written by others.** SymBRiM's Whipple bicycle (the `symbrim` package, bicycle–rider
models for `sympy.physics.mechanics`), converted by :func:`from_sympy` with the benchmark's
parameters, gives the accelerations of Basu-Mandal et al. (2007) Table 1 to 1.1e-12, as
:mod:`gnipy.models.whipple_bicycle` does (tests/test_symbolic.py); its conversion takes about 6 s.
Which constraint rows have no velocities, and whether there is an affine part, is decided by
evaluating the expressions at random points in 30-digit arithmetic (:func:`_is_zero`), not by
`sympy.simplify`, which took minutes on that bicycle's constraints.

Conversions are cached (:func:`_functions`): Systems made from the same expressions share their
functions, differ only in `args`, and so run as one batch (a sweep over a parameter of a function
that calls :func:`from_sympy` each time).
"""

from __future__ import annotations

import functools
import math
import random
import re
from collections.abc import Mapping, Sequence
from typing import Any

import jax.numpy as jnp

from .errors import InputError
from .extras import require
from .inputs import real_number
from .linalg import solve_spd
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
    params: Mapping[Any, float] | None = None,
    name: str = "sympy-system",
    coordinate_names: Sequence[str] | None = None,
    defaults: tuple | None = None,
) -> System:
    """A :class:`~gnipy.System` on $\\mathbb{R}^n$ from a SymPy model (module docstring).

    Arguments:
        model: the Lagrangian, a SymPy expression in the coordinates, their velocities and the
            parameters (the plain form); or a `sympy.physics.mechanics.System`.
        coordinates: the plain form's coordinates q, SymPy symbols or `dynamicsymbols`, in the
            order of the System's q. Not given with a mechanics System (its `q` is used).
        speeds: the plain form's velocity symbols, one per coordinate, when the coordinates are
            plain symbols; default: the coordinates' time derivatives (for `dynamicsymbols`).
        constraints: the plain form's constraint expressions c(q, q̇) (each = 0), affine in the
            velocities. Not given with a mechanics System (its nonholonomic constraints are used).
        holonomic: the plain form's holonomic constraints φ(q) (each = 0), expressions in the
            coordinates and parameters (:mod:`gnipy.holonomic`). Not given with a mechanics System
            (its `holonomic_constraints` are used).
        params: the value of every other symbol of the model: `{symbol or name: float}`. They
            become the System's `args`, named by the symbols' names.
        name: the System's name (in reports and files).
        coordinate_names: the coordinates' names (default: the symbols' names, a dynamicsymbol
            `x(t)` giving `x`).
        defaults: an optional default initial condition `(q0, v0)`.

    Returns:
        The System, with `lagrangian(q, v, args)`, `constraints(q, args)` (None without
        nonholonomic constraints), `holonomic(q, args)` with holonomic constraints, and, when the
        constraints are affine, `affine(q, args)`.

    Raises:
        InputError: on what the conversion cannot take (module docstring), naming the argument.
        MissingExtra: without SymPy or sympy2jax (`pip install 'gnipy[sympy]'`).
    """
    sp = _sympy()
    me = require("sympy.physics.mechanics", extra="sympy")
    if isinstance(model, me.System):
        if (coordinates is not None or speeds is not None or _sequence(constraints, "constraints")
                or _sequence(holonomic, "holonomic")):
            raise InputError("from_sympy: coordinates, speeds, constraints and holonomic are read from the mechanics "
                             "System; do not pass them too")
        lagrangian, coordinates, speeds, constraints, holonomic = _from_mechanics_system(model)
    elif isinstance(model, sp.Basic):
        if coordinates is None:
            raise InputError("from_sympy: coordinates is needed with a Lagrangian expression (the symbols of q)")
        lagrangian = sp.sympify(model)
    else:
        raise InputError(f"from_sympy: model must be a SymPy expression (the Lagrangian) or a "
                         f"sympy.physics.mechanics.System, not {type(model).__name__}")
    constraints = _sequence(constraints, "constraints")
    holonomic = _sequence(holonomic, "holonomic")
    q, qd, names = _coordinates_and_speeds(coordinates, speeds, coordinate_names)
    n = len(q)
    exprs = {"model": sp.sympify(lagrangian), **{f"constraints[{i}]": sp.sympify(c) for i, c in enumerate(constraints)},
             **{f"holonomic[{i}]": sp.sympify(c) for i, c in enumerate(holonomic)}}
    _check_symbols(exprs, q, qd)
    # plain symbols in place of q and q̇ (dynamicsymbols are applied functions of t); no symbol of
    # the model has these names (_check_symbols)
    qs, vs = _internal_symbols(n)
    swap = {**dict(zip(qd, vs)), **dict(zip(q, qs))}  # the velocities first: q̇ contains q
    L, *rest = (_substituted(e, swap, where) for where, e in exprs.items())
    cons, hol = rest[:len(constraints)], rest[len(constraints):]
    if not cons and not hol:
        raise InputError("from_sympy: constraints: no constraint given (nonholonomic, or holonomic); gnipy "
                         "integrates constrained systems")
    for i, c in enumerate(hol):
        if c.free_symbols & set(vs):
            raise InputError(f"from_sympy: holonomic[{i}] = {holonomic[i]} involves the velocities: a holonomic "
                             "constraint is a function of the coordinates (give a velocity constraint as constraints)")
    values = _parameters(params, [L, *cons, *hol], set(qs) | set(vs))
    try:
        lagrangian_fn, constraints_fn, affine_fn, holonomic_fn = _functions(L, tuple(cons), tuple(hol), n)
    except InputError as e:  # say it in the model's own symbols
        user = {f"{_INTERNAL}q{i}": str(c) for i, c in enumerate(q)} | {f"{_INTERNAL}v{i}": str(v) for i, v in enumerate(qd)}
        raise InputError(re.sub(rf"\b{_INTERNAL}[qv]\d+\b", lambda m: user[m.group(0)], str(e))) from None
    return System(lagrangian_fn, constraints_fn, affine_fn, holonomic=holonomic_fn, coordinates=names, name=name,
                  args=values, defaults=defaults)


def _internal_symbols(n: int):
    """The plain symbols that stand for q and q̇ inside the conversion."""
    sp = _sympy()
    return ([sp.Symbol(f"{_INTERNAL}q{i}", real=True) for i in range(n)],
            [sp.Symbol(f"{_INTERNAL}v{i}", real=True) for i in range(n)])


#: the prefix of the names of :func:`_internal_symbols` (a model's own symbols may not start with it)
_INTERNAL = "gnipy_"


@functools.lru_cache(maxsize=64)
def _functions(L, cons: tuple, hol: tuple, n: int):
    """The System's functions `(lagrangian, constraints or None, affine or None, holonomic or None)`
    of the substituted
    expressions (in `gnipy_q{i}`, `gnipy_v{i}` and the parameters' symbols), made once per model:
    Systems converted from the same expressions share the function objects, so that they differ
    only in `args` and run as one batch (a sweep's members, a fit's trials), as those of one
    hand-written System's `with_args` do."""
    sp = _sympy()
    qs, vs = _internal_symbols(n)
    _check_mechanical_type(sp, L, vs)
    mu, c0 = _affine_parts(sp, cons, vs)
    affine = any(not _is_zero(sp, c) for c in c0)

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

    return (sympy_lagrangian, sympy_constraints if cons else None, (sympy_affine if affine else None),
            sympy_holonomic if hol else None)


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
                         f"evaluate (undefined functions, accelerations and inputs that depend on time are not supported)")
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


def _kinetic_energy(sp, body, frame, origin):
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
        if all(_is_zero(sp, entry) for entry in row):
            raise InputError(f"from_sympy: constraints[{i}] = {c} does not involve the velocities: a "
                             f"holonomic constraint; give it as holonomic=[...] (gnipy keeps it exactly)")
        rows.append(row)
        c0.append(c.xreplace(dict.fromkeys(vs, 0)))
    return rows, c0


def _is_zero(sp, expr) -> bool:
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


def _from_mechanics_system(system):
    """(Lagrangian, coordinates, speeds, constraints) of a `sympy.physics.mechanics.System`, in q and q̇."""
    sp = _sympy()
    me = require("sympy.physics.mechanics", extra="sympy")
    if len(system.actuators):
        raise InputError("from_sympy: model: the mechanics System has actuators (springs, dampers, ...), which are "
                         "not supported: only constant forces (gravity), which have a potential")
    q = list(system.q)
    u = list(system.u)
    t = me.dynamicsymbols._t
    qd = [c.diff(t) for c in q]
    # u in terms of q̇, from the kinematic differential equations (linear in u)
    if set(u) == set(qd) or not u:
        to_qd = {}
    else:
        if len(system.kdes) != len(u):
            raise InputError(f"from_sympy: model: {len(system.kdes)} kinematic differential equations for "
                             f"{len(u)} speeds u; gnipy needs u in terms of q̇")
        try:
            A, b = sp.linear_eq_to_matrix(list(system.kdes), u)
        except ValueError as e:  # sympy.solvers.solveset.NonlinearError
            raise InputError(f"from_sympy: model: the kinematic differential equations are not linear in u ({e})") from None
        if A.has(*qd) or A.has(t) or _is_zero(sp, A.det()):
            raise InputError("from_sympy: model: the kinematic differential equations do not give u as a "
                             "function of q and q̇ (linear in u, with coefficients that depend on q only)")
        to_qd = dict(zip(u, list(A.LUsolve(b))))
    frame, origin = system.frame, system.fixed_point
    try:
        T = sum((_kinetic_energy(sp, body, frame, origin) for body in system.bodies), sp.Integer(0))
    except ValueError as e:  # a position or an orientation that is not defined
        raise InputError(f"from_sympy: model: the kinetic energy cannot be formed: {e}") from None
    V = sum((sp.sympify(body.potential_energy) for body in system.bodies), sp.Integer(0))
    for load in system.loads:
        if isinstance(load, me.Torque):
            raise InputError(f"from_sympy: model: a torque on {load.frame} is not supported (only constant forces, "
                             f"which have a potential)")
        F = load.force
        moving = [x for x in (*q, *u, *qd, t) if F.diff(x, frame) != 0] if F != 0 else []
        if moving:
            raise InputError(f"from_sympy: model: the force on {load.point} depends on {moving[0]}; only constant "
                             f"forces (gravity) are supported: they have the potential -F·r")
        try:
            V -= F.dot(load.point.pos_from(origin))
        except ValueError as e:  # no path of positions from the System's fixed point
            raise InputError(f"from_sympy: model: the potential of the force on {load.point} needs its position from "
                             f"the System's fixed point {origin}: {e}") from None
    L = (T - V).xreplace(to_qd)
    # the nonholonomic constraints, or the velocity constraints when set by hand; with holonomic
    # constraints only the nonholonomic ones (the velocity constraints then hold dφ/dt too, which
    # gnipy adds itself from φ)
    holonomic = [sp.sympify(c) for c in system.holonomic_constraints]
    velocity = system.nonholonomic_constraints if holonomic else system.velocity_constraints
    constraints = [sp.sympify(c).xreplace(to_qd) for c in velocity]
    return L, q, None, constraints, holonomic
