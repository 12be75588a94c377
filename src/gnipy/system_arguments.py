"""The arguments of :class:`gnipy.System`, checked: the user's functions, the dimension and names
of the coordinates and velocities, the configuration space (:mod:`gnipy.spaces`: $\\mathbb{R}^n$,
or $\\mathbb{R}^n \\times G$ with its retraction and reconstruction), the provenance (parameters,
default initial condition) and the inputs of a force. Each error names its argument.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .errors import InputError
from .inputs import provenance_number
from .spaces import EuclideanSpace, GroupSpace

__all__ = ["check_functions", "dimension", "configuration_space", "velocity_names", "provenance", "inputs_count",
           "Args", "system_args", "scalar_args", "takes_args_last"]


def check_functions(lagrangian, constraints, affine, force, holonomic=None) -> None:
    """The user's functions are callables (`affine`, `force` and `holonomic` may be None, and
    `constraints` too when `holonomic` is given)."""
    if not callable(lagrangian):
        raise InputError(f"lagrangian: expected a callable l(q, v), got {type(lagrangian).__name__}")
    if holonomic is not None and not callable(holonomic):
        raise InputError(f"holonomic: expected a callable phi(q) or None, got {type(holonomic).__name__}")
    if constraints is None and holonomic is None:
        raise InputError("constraints: expected a callable mu(q) (None only with holonomic=phi)")
    if constraints is not None and not callable(constraints):
        raise InputError(f"constraints: expected a callable mu(q), got {type(constraints).__name__}")
    if affine is not None and not callable(affine):
        raise InputError(f"affine: expected a callable Y(q) or None, got {type(affine).__name__}")


def dimension(n, coordinates: Sequence[str] | None, group) -> tuple[int, tuple[str, ...]]:
    """`(n, coordinates)`: the dimension of the Euclidean factor (from `coordinates` when `n` is
    None; 0 by default with a group) and the coordinates' names (default `q0, q1, ...`)."""
    if n is None and coordinates is None:
        if group is None:
            raise InputError("n: give the dimension n of the configuration space (or coordinates=...)")
        n = 0
    if n is None:
        n = len(tuple(coordinates))
    if isinstance(n, bool) or int(n) != n or n < (1 if group is None else 0):
        raise InputError(f"n: expected a {'positive' if group is None else 'non-negative'} integer, got {n!r}")
    n = int(n)
    if coordinates is None:
        coordinates = tuple(f"q{i}" for i in range(n))
    coordinates = tuple(str(c) for c in coordinates)
    if len(coordinates) != n:
        raise InputError(f"coordinates: expected {n} names, got {len(coordinates)}")
    return n, coordinates


def configuration_space(n: int, group, retraction, depends_on_orientation, reconstruction):
    """`(space, group_velocity_names)`: $\\mathbb{R}^n$ (:class:`~gnipy.spaces.EuclideanSpace`), or
    $\\mathbb{R}^n \\times G$ (:class:`~gnipy.spaces.GroupSpace`) with the retraction (a name or a
    :class:`~gnipy.retractions.Retraction`) and the reconstruction ("left" or "right")."""
    if reconstruction not in ("left", "right"):
        raise InputError(f"reconstruction: expected 'left' or 'right', got {reconstruction!r}")
    if group is None:
        if depends_on_orientation:
            raise InputError("depends_on_orientation: only meaningful with a group")
        if reconstruction != "left":
            raise InputError("reconstruction: only meaningful with a group")
        return EuclideanSpace(n), ()
    from .lie_groups import MatrixLieGroup
    from .retractions import Retraction, get_retraction

    if not isinstance(group, MatrixLieGroup):
        raise InputError(f"group: expected a gnipy.lie_groups group (e.g. SO3()), got {type(group).__name__}")
    if isinstance(retraction, str):
        try:
            retraction = get_retraction(retraction)
        except ValueError as e:
            raise InputError(str(e)) from e
    if not isinstance(retraction, Retraction):
        raise InputError(f"retraction: expected 'cayley', 'exp' or a Retraction, got {retraction!r}")
    if reconstruction == "right" and depends_on_orientation:
        raise InputError(
            "reconstruction: 'right' (R from the space velocity, dR/dt = hat(xi) R) is for reduced "
            "systems only; a system that depends on the orientation (depends_on_orientation=True) "
            "needs the left-trivialized equations, reconstruction='left'"
        )
    names = tuple(getattr(group, "velocity_names", None) or (f"xi{i}" for i in range(group.dim)))
    return GroupSpace(n, group, retraction, reconstruction), names


def velocity_names(velocities, coordinates: tuple[str, ...], group_names: tuple[str, ...], dim: int):
    """The names of the N velocity components (default `d<coordinate>` then the group's)."""
    if velocities is None:
        velocities = tuple(f"d{c}" for c in coordinates) + tuple(group_names)
    velocities = tuple(str(c) for c in velocities)
    if len(velocities) != dim:
        raise InputError(f"velocities: expected {dim} names, got {len(velocities)}")
    return velocities


def provenance(params, defaults) -> tuple[tuple, tuple | None]:
    """`(params, defaults)` as stored: the parameters as `(name, number)` pairs, the default initial
    condition as tuples of floats (of traced numbers where the parameters are traced)."""
    params = tuple((str(k), provenance_number(v)) for k, v in (params or {}).items())
    if defaults is not None:
        defaults = tuple(None if d is None else tuple(provenance_number(x) for x in jnp.ravel(jnp.asarray(d)))
                         if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(d))
                         else tuple(float(x) for x in np.ravel(d)) for d in defaults)
    return params, defaults


@jax.tree_util.register_pytree_node_class
class Args(dict):
    """A System's named parameters (:attr:`gnipy.System.args`): a dict of float64 arrays, the
    functions read `args["m"]`. A pytree whose leaves are the values (keys in sorted order); hashed
    and compared by identity, as functions are, so that a System holding it can be hashed (e.g. a
    bound method of it under `jax.jit`) and never compares arrays element-wise."""

    __hash__ = object.__hash__
    __eq__ = object.__eq__
    __ne__ = object.__ne__

    def tree_flatten(self):
        keys = tuple(sorted(self))
        return tuple(self[k] for k in keys), keys

    @classmethod
    def tree_unflatten(cls, keys, children):
        return cls(zip(keys, children))


def system_args(args) -> dict | None:
    """The named parameters `args` of a System (a mapping of names to numbers or arrays) as a dict of
    float64 arrays, checked (finite unless traced); None stays None."""
    from .inputs import is_text_or_bool

    if args is None:
        return None
    if not isinstance(args, Mapping):
        raise InputError(f"args: expected a mapping of parameter names to numbers or arrays, got "
                         f"{type(args).__name__}")
    out = Args()
    for k, v in args.items():
        if not isinstance(k, str) or not k.isidentifier():
            raise InputError(f"args: parameter names must be Python names, got {k!r}")
        if is_text_or_bool(v):
            raise InputError(f"args: parameter {k!r} must be a number or an array of numbers, got {v!r}")
        if isinstance(v, jax.core.Tracer):
            out[k] = v
            continue
        try:  # checked in NumPy: inside a trace (jax.jit) jnp would make even a constant a tracer
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"args: parameter {k!r} must be a number or an array of numbers, got {v!r}") from e
        if not np.all(np.isfinite(a)):
            raise InputError(f"args: parameter {k!r} must be finite, got {v!r}")
        out[k] = jnp.asarray(a)
    return out


def takes_args_last(f, count: int) -> bool:
    """Whether `f` takes the named parameters as its `count`-th positional argument: it takes `*args`,
    or it needs `count` positional arguments (it cannot be called with one fewer). False when its
    signature cannot be read: a force is then called without them."""
    import inspect

    try:
        signature = inspect.signature(f)
    except (TypeError, ValueError):
        return False
    if any(p.kind is p.VAR_POSITIONAL for p in signature.parameters.values()):
        return True
    try:
        signature.bind(*range(count))
    except TypeError:
        return False
    try:
        signature.bind(*range(count - 1))
    except TypeError:
        return True
    return False


def scalar_args(args) -> dict:
    """The scalar entries of named parameters (what the provenance `params` record of them)."""
    return {k: v for k, v in (args or {}).items() if jnp.ndim(v) == 0}


def inputs_count(force, inputs) -> int:
    """The number of inputs of `force` (a callable F(q, v, u, t) or None), checked."""
    if force is not None and not callable(force):
        raise InputError(f"force: expected a callable F(q, v, u, t) or None, got {type(force).__name__}")
    if isinstance(inputs, bool) or int(inputs) != inputs or inputs < 0:
        raise InputError(f"inputs: expected a non-negative integer, got {inputs!r}")
    if inputs and force is None:
        raise InputError(f"inputs: {int(inputs)} inputs but no force=; the inputs act through F(q, v, u, t)")
    return int(inputs)
