"""Ensembles: batches of initial conditions and of parameter values, run as one vmapped program.

:func:`gnipy.simulate` accepts a batch of initial conditions (arrays with a leading batch axis)
and a batch of systems (a sequence of :class:`~gnipy.System` objects that differ only in parameter
values, e.g. from :func:`model_systems`). This module holds what that needs:

- :func:`stack_systems`: one System whose array leaves carry a leading batch axis;
- :func:`model_systems`: the systems of a registered model for arrays of parameter values;
- :func:`broadcast_initial_conditions`: validate and broadcast q0, v0, R0 to a batch;
- :func:`check_batch`: the checks of :meth:`System.check` for every member at once
  (positive-definite metric, full-rank constraints, v0 on the constraints), compiled and
  vectorized: checking 10⁵ members one by one would take minutes.
"""

from __future__ import annotations

import warnings

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .compilation import jit
from .sharding import member_devices, pad_members, shard_map
from .spaces import Point
from .errors import InputError
from .inputs import real_array, refuse_text_or_bool
from .run_arguments import member_initial_conditions
from .solution import Solution
from .stepping import run_nodes
from .system import System

__all__ = ["stack_systems", "model_systems", "broadcast_initial_conditions", "check_batch", "member_initial_conditions",
           "member_params"]


def stack_systems(systems: Sequence[System]) -> System:
    """Stack systems that differ only in the values of their array leaves (their parameters).

    Returns:
        A System (without `params`/`defaults` metadata) whose array leaves have a leading axis of
        length `len(systems)`; run it with `eqx.filter_vmap(..., in_axes=eqx.if_array(0))`.

    Raises:
        InputError: an empty sequence, a member that is not a System, or members with different
            structure (other functions, groups, names or array shapes).
    """
    systems = list(systems)
    if not systems:
        raise InputError("system: an empty sequence of systems")
    for i, s in enumerate(systems):
        if not isinstance(s, System):
            raise InputError(f"system[{i}]: expected a gnipy.System, got {type(s).__name__}")
    cores = [s.without_metadata() for s in systems]
    # one flattening per member (a batch may hold 10⁴ systems): its leaves, and which are arrays
    flat0, treedef0 = jax.tree_util.tree_flatten(cores[0])
    mask0 = [eqx.is_array(x) for x in flat0]
    columns: list[list] = [[] for m in mask0 if m]
    for i, c in enumerate(cores):
        flat, treedef = jax.tree_util.tree_flatten(c)
        why = _member_difference(flat, treedef, flat0, treedef0, mask0)
        if why is not None:
            raise InputError(
                f"system[{i}]: a batch of systems must differ only in the values of array parameters "
                f"(the same model, functions and dimensions as system[0]), but {why}. Build the members "
                "from one function with the parameters as JAX arrays (System(l, mu, args={...}), as the "
                "zoo models and gnipy.model_systems do), or simulate the systems one at a time"
            )
        for col, x in zip(columns, (x for x, m in zip(flat, mask0) if m)):
            col.append(np.asarray(x))
    # stacked by NumPy, then one transfer per leaf: jnp.stack of B arrays compiles an XLA program
    # with B operands (measured: 96 s for B = 10,000 on the 2-core machine, 0.5 s this way)
    stacked = iter([jnp.asarray(np.stack(col)) for col in columns])
    return jax.tree_util.tree_unflatten(treedef0, [next(stacked) if m else x for x, m in zip(flat0, mask0)])


def _member_difference(flat, treedef, flat0, treedef0, mask0) -> str | None:
    """Why a member (its leaves `flat` and `treedef`) cannot be stacked with system[0] (`flat0`,
    `treedef0`, `mask0` which leaves are arrays), or None."""
    if treedef != treedef0 or [eqx.is_array(x) for x in flat] != mask0:
        return "its structure (functions, group, retraction or parameter leaves) differs"
    if any(np.shape(a) != np.shape(b) for a, b, m in zip(flat, flat0, mask0) if m):
        return "its parameter arrays have other shapes"
    # The non-array leaves (the functions, Python numbers) must be the same: a treedef does not
    # compare them, and stacking keeps system[0]'s, so another Lagrangian, constraint or
    # Python-float parameter would silently run as system[0]'s.
    for a, b, m in zip(flat, flat0, mask0):
        if not m and not _same_static(a, b):
            return f"it has another {_describe_static(a, b)}"
    return None


def _same_static(a, b) -> bool:
    if a is b:
        return True
    try:
        same = a == b
        return bool(same) if isinstance(same, (bool, np.bool_)) else False
    except Exception:  # noqa: BLE001 - an object that cannot be compared: not the same
        return False


def _describe_static(a, b) -> str:
    if callable(a):
        def name(f):
            return getattr(f, "__name__", type(f).__name__)
        return f"function ({name(a)} here, {name(b)} in system[0])"
    if isinstance(a, (int, float, complex, np.number)):
        return f"Python-number parameter ({a!r} here, {b!r} in system[0]; not a JAX array, so it cannot be batched)"
    return f"non-array leaf of type {type(a).__name__}"


def model_systems(name: str, **params) -> list[System]:
    """The systems of the registered model `name` for arrays of parameter values.

    Arguments:
        name: a model name (see :func:`gnipy.model_names`), the user's system as `"FILE.py:NAME"`
            (:func:`gnipy.get_model`), or a :class:`~gnipy.registry.ModelSpec`.
        **params: parameter values; scalars and 1-D arrays, broadcast against each other
            (the others keep their defaults).

    Returns:
        A list of Systems, one per member, for :func:`gnipy.simulate`.

    Raises:
        InputError: an unknown model or parameter, non-finite values, arrays of different lengths.
    """
    from .registry import ModelSpec, get_model

    spec = name if isinstance(name, ModelSpec) else get_model(name)
    arrays = {}
    for k, v in params.items():
        refuse_text_or_bool(f"params: parameter {k!r}", v, "numbers")
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"params: parameter {k!r} must be numbers, got {v!r}") from e
        if a.ndim > 1:
            raise InputError(f"params: parameter {k!r} must be a scalar or a 1-D array, got shape {a.shape}")
        arrays[k] = np.atleast_1d(a)
    sizes = {len(a) for a in arrays.values() if len(a) != 1}
    if len(sizes) > 1:
        raise InputError(f"params: parameter arrays have different lengths {sorted(sizes)}")
    size = sizes.pop() if sizes else 1
    out = []
    for i in range(size):
        member = {k: float(a[0] if len(a) == 1 else a[i]) for k, a in arrays.items()}
        out.append(spec.system(**member))
    return out


def _batch_size_of(name: str, a: np.ndarray, single_ndim: int) -> int | None:
    if a.ndim == single_ndim:
        return None
    if a.ndim == single_ndim + 1:
        return a.shape[0]
    raise InputError(f"{name}: expected {single_ndim} or {single_ndim + 1} dimensions, got shape {a.shape}")


def _orientations(system: System, R0):
    """`(R, batch size or None)`: R0 as a (k, k) matrix or a (B, k, k) batch of them (None when
    not given or on R^n)."""
    if system.group is None:
        if R0 is not None:
            raise InputError("R0: this system has no group part")
        return None, None
    if R0 is None:
        return None, None
    R = real_array("R0", R0)
    k = system.group.matrix_size
    if R.shape in ((k, k), (k * k,)):
        return R.reshape(k, k), None
    if R.ndim == 3 and R.shape[1:] == (k, k):
        return R, R.shape[0]
    if R.ndim == 2 and R.shape[1] == k * k:
        return R.reshape(-1, k, k), R.shape[0]
    raise InputError(f"R0: expected a {k}x{k} matrix or a batch of them, got shape {R.shape}")


def _check_orientations(system: System, R, B: int):
    """R broadcast to (B, k, k) (the identity when not given), each a finite element of the group."""
    k = system.group.matrix_size
    if R is None:
        R = np.asarray(system.group.identity(), dtype=np.float64)
    if R.ndim == 2:
        R = np.broadcast_to(R, (B, k, k))
    bad = ~np.all(np.isfinite(R), axis=(1, 2))
    if bad.any():
        raise InputError(f"R0[{int(np.argmax(bad))}]: contains NaN or infinite values")
    bad = ~system.group.is_element(R)  # e.g. rotation matrices on SO(3)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"R0[{i}]: {system.group.why_not_element(R[i])}")
    return R


def broadcast_initial_conditions(system: System, q0, v0, R0, size: int | None):
    """Validate shapes and finiteness and broadcast to a batch.

    Arguments:
        system: the (first) System, for the dimensions.
        q0: (n,) or (B, n); v0: (N,) or (B, N); R0: None, (k, k), (k·k,), (B, k, k) or (B, k·k).
        size: the batch size from the systems, or None.

    Returns:
        `(B, q0, v0, R0)` with leading axis B on all three (R0 None on R^n).

    Raises:
        InputError: naming the argument (and the member) that is wrong.
    """
    n, N = system.n, system.dim

    def as_array(name, x):
        return real_array(name, x)

    q0 = as_array("q0", q0)
    v0 = as_array("v0", v0)
    sizes = {"system": size, "q0": _batch_size_of("q0", q0, 1), "v0": _batch_size_of("v0", v0, 1)}
    R, sizes["R0"] = _orientations(system, R0)
    given = {k: s for k, s in sizes.items() if s is not None}
    if len(set(given.values())) > 1:
        desc = ", ".join(f"{k}: {s}" for k, s in given.items())
        raise InputError(f"batch: the batch sizes differ ({desc})")
    B = next(iter(given.values())) if given else 1
    if B < 1:
        raise InputError("batch: the batch is empty")
    q0 = np.broadcast_to(q0, (B, *q0.shape[-1:])) if q0.ndim == 1 else q0
    v0 = np.broadcast_to(v0, (B, *v0.shape[-1:])) if v0.ndim == 1 else v0
    if q0.shape[1] != n:
        raise InputError(f"q0: expected vectors of length {n}, got shape {q0.shape}")
    if v0.shape[1] != N:
        raise InputError(f"v0: expected vectors of length {N}, got shape {v0.shape}")
    for name, a in (("q0", q0), ("v0", v0)):
        bad = ~np.all(np.isfinite(a), axis=1)
        if bad.any():
            raise InputError(f"{name}[{int(np.argmax(bad))}]: contains NaN or infinite values")
    if system.group is not None:
        R = _check_orientations(system, R, B)
    return B, q0, v0, R


@jit
def _batch_diagnostics(system, batched: bool, b0, v0):
    def one(s, b, v):
        G = s.metric(b)
        eig = jnp.linalg.eigvalsh(0.5 * (G + G.T))
        asym = jnp.max(jnp.abs(G - G.T))
        mu = s.mu(b)
        sv = jnp.linalg.svd(mu, compute_uv=False)
        Y = s.Y(b)
        res = mu @ (v - Y)
        from .system import project_velocity

        return dict(
            eig_min=eig[0], eig_max=eig[-1], asym=asym, gmax=jnp.max(jnp.abs(G)),
            finite=jnp.all(jnp.isfinite(G)) & jnp.all(jnp.isfinite(mu)) & jnp.all(jnp.isfinite(Y)),
            sv_min=sv[-1], sv_max=sv[0], res=jnp.max(jnp.abs(res)),
            scale=jnp.maximum(1.0, jnp.maximum(jnp.max(jnp.abs(v)), jnp.max(jnp.abs(Y)))),
            projected=project_velocity(s, b, v),
        )

    return eqx.filter_vmap(one, in_axes=(eqx.if_array(0) if batched else None, 0, 0))(system, b0, v0)


def check_batch(system: System, batched: bool, q0, v0, R0, *, project_v0: bool = False, tol: float = 1e-10):
    """The checks of :meth:`System.check` for every member of a batch, vectorized.

    Arguments:
        system: a System, or stacked systems (`batched=True`) from :func:`stack_systems`.
        q0, v0, R0: arrays with a leading batch axis (from :func:`broadcast_initial_conditions`).
        project_v0: project each v0 onto its constraints instead of raising.

    Returns:
        `(b0, v0)` batched (b0 a :class:`~gnipy.spaces.Point` of batched arrays on R^n × G).

    Raises:
        InputError: naming the first failing member, e.g. `v0[17]: ... violates the constraints`.
    """
    b0 = jnp.asarray(q0) if system.group is None else Point(jnp.asarray(q0), jnp.asarray(R0))
    d = {k: np.asarray(x) for k, x in _batch_diagnostics(system, batched, b0, jnp.asarray(v0)).items()}
    which = "member"

    def first(mask):
        return int(np.argmax(mask))

    bad = ~d["finite"]
    if bad.any():
        raise InputError(f"{which} {first(bad)}: the metric, mu(q0) or Y(q0) is not finite at q0[{first(bad)}]")
    bad = d["asym"] > tol * np.maximum(1.0, d["gmax"])
    if bad.any():
        raise InputError(f"lagrangian: the metric d²l/dv² is not symmetric at q0[{first(bad)}]")
    bad = d["eig_min"] <= tol * np.maximum(1.0, d["eig_max"])
    if bad.any():
        i = first(bad)
        raise InputError(
            f"lagrangian: the metric d²l/dv² is not positive definite at q0[{i}] "
            f"(smallest eigenvalue {d['eig_min'][i]:.3e})"
        )
    bad = d["sv_min"] <= 1e-10 * np.maximum(1.0, d["sv_max"])
    if bad.any():
        i = first(bad)
        raise InputError(f"constraints: mu(q0[{i}]) is rank deficient (smallest singular value {d['sv_min'][i]:.3e})")
    bad = d["res"] > tol * d["scale"]
    if bad.any():
        if not project_v0:
            i = first(bad)
            raise InputError(
                f"v0[{i}]: the initial velocity violates the constraints mu(q0)(v0 - Y(q0)) = 0 "
                f"(residual {d['res'][i]:.3e}); pass project_v0=True to project it"
            )
        v0 = np.where(bad[:, None], d["projected"], v0)
    return b0, jnp.asarray(v0)


def member_params(systems: Sequence[System]) -> dict[str, np.ndarray]:
    """The parameters of each member as arrays (for provenance), `{}` if the systems have none."""
    names = [k for k, _ in systems[0].params]
    out = {k: np.empty(len(systems)) for k in names}
    for i, s in enumerate(systems):
        p = dict(s.params)
        for k in names:
            out[k][i] = p.get(k, np.nan)
    return out


# ------------------------------------------------------------------------------------------------
# The batched run of gnipy.simulate
# ------------------------------------------------------------------------------------------------
@jit
def _run_batch(method, system, system_batched: bool, state0, h, lengths, tail, h_last, partial: bool,
               save_final: bool, save_states: bool, progress: bool, progress_stride, monitor0, devices: tuple = ()):
    """:func:`gnipy.stepping.run_nodes` vmapped over the members (states, monitors, and systems when
    batched); with several `devices` (:func:`member_devices`), the members split into one chunk
    per device, each chunk vmapped on its own (no communication between them)."""
    def one(s, st, mon):
        return run_nodes(method, s, st, h, lengths, tail, h_last, partial=partial, save_final=save_final,
                         save_states=save_states, progress=progress, progress_stride=progress_stride, monitor0=mon)

    def members(s, st, mon):
        return eqx.filter_vmap(one, in_axes=(eqx.if_array(0) if system_batched else None, 0, 0))(s, st, mon)

    if not devices:
        return members(system, state0, monitor0)
    from jax.sharding import Mesh, PartitionSpec

    B = jax.tree_util.tree_leaves(state0)[0].shape[0]
    n = len(devices)
    padded = -(-B // n) * n
    state0, monitor0 = pad_members((state0, monitor0), B, padded)
    arrays, static = eqx.partition(system, eqx.is_array)
    if system_batched:
        arrays = pad_members(arrays, B, padded)
    chunk, whole = PartitionSpec("members"), PartitionSpec()
    specs = (jax.tree_util.tree_map(lambda _: chunk if system_batched else whole, arrays), chunk, chunk)
    run = shard_map()(lambda a, st, mon: members(eqx.combine(a, static), st, mon),
                      mesh=Mesh(np.array(devices), ("members",)), in_specs=specs, out_specs=chunk)
    out = run(arrays, state0, monitor0)
    return jax.tree_util.tree_map(lambda a: a[:B], out)


@jit
def _init_batch(method, system, system_batched: bool, b0, v0, h):
    return eqx.filter_vmap(
        lambda s, b, v: method.init(s, b, v, h), in_axes=(eqx.if_array(0) if system_batched else None, 0, 0)
    )(system, b0, v0)


def is_batch(system: System, q0, v0, R0) -> bool:
    """Whether the initial conditions carry a leading batch axis."""
    try:
        q = np.asarray(q0)
        v = np.asarray(v0)
    except (TypeError, ValueError):
        return False  # let System.check name the bad argument
    if q.ndim == 2 or v.ndim == 2:
        return True
    if system.group is not None and R0 is not None:
        try:
            R = np.asarray(R0, dtype=np.float64)
        except (TypeError, ValueError):
            return False
        k = system.group.matrix_size
        return R.ndim == 3 or (R.ndim == 2 and R.shape != (k, k) and R.shape[-1] == k * k)
    return False


def simulate_batch(problem, reporter, backend: str) -> Solution:
    """The batched run of a :class:`gnipy.Problem` (B members: initial conditions and/or systems),
    one vmapped program on `backend` ("xla" or "native"); a failed member's nodes after its failure
    are NaN (:func:`gnipy.assembly.assemble`)."""
    from .assembly import assemble, labels
    from .diagnostics import diagnostic_fields, scheme_energy
    from .system import describe_orientations

    systems = list(problem.systems or [problem.system])
    system, h, partial, plan = systems[0], problem.h, problem.partial, problem.plan
    size = len(systems) if len(systems) > 1 else None
    B, q0, v0, R0 = broadcast_initial_conditions(system, problem.q0, problem.v0, problem.R0, size)
    # the full checks (mechanical type, dimensions) once, on the first member; the value checks
    # (metric, rank, v0 on the constraints) for every member, vectorized
    system.check(q0[0], None, R0=None if R0 is None else R0[0])
    sys_batched = len(systems) > 1
    core = stack_systems(systems) if sys_batched else system.without_metadata()
    b0, v0 = check_batch(core, sys_batched, q0, v0, R0, project_v0=problem.project_v0)
    first_b0 = jax.tree_util.tree_map(lambda a: a[0], b0)
    method = problem.method
    method.validate(system, first_b0)
    method = method.prepare(system, first_b0)
    # what a method keeps only to make steps cheaper (DLA's Jacobian) is left out: under vmap one
    # member's renewal of it is every member's, so that the SymBRiM bicycle's batch of 1,024 took
    # 2.25 µs a member step with it, 1.64 without (BENCHMARKS.md, section 10)
    method = method.memoryless()
    hj = np.float64(h)
    state0 = _init_batch(method, core, sys_batched, b0, v0, hj)
    scheme = scheme_energy(method)
    monitor0, conservation = _batch_monitor(problem, system, core, sys_batched, b0, method, state0, B)
    out = None
    if backend == "native":
        out = _run_native_batch(problem, systems, core, sys_batched, method, state0, monitor0, reporter)
        if out is None:
            backend = "xla"
    if out is None:
        out = _run_batch(method, core, sys_batched, state0, hj, np.asarray(plan.lengths, np.int32),
                         np.int32(plan.tail), np.float64(partial * h), bool(partial), plan.save_final, False,
                         reporter.active, np.int32(reporter.stride), monitor0 if problem.check_every_node else None,
                         member_devices() if B > 1 else ())
    if reporter.active:
        jax.block_until_ready(out)
    fields = labels(problem, method, backend) | {"orientation": describe_orientations(systems)}
    fields |= diagnostic_fields(system, core, first_b0, (out["b"], out["v"], out["p"], out["hidden"]), h,
                                batched_system=sys_batched, batch=True, scheme=scheme,
                                times=problem.times)
    fields |= conservation
    if sys_batched:
        fields |= {"params": (), "member_params": member_params(systems)}
    return assemble(problem, out, fields)


def _batch_monitor(problem, system, core, sys_batched, b0, method, state0, B):
    """The members' monitors at the start (:mod:`gnipy.monitor`), and each member's own sentence on
    what its motion conserves (the fields `conserved`, `energy_invariant`, `member_conserved`)."""
    from .diagnostics import member_conservation, scheme_energy
    from .monitor import initial
    from .registry import registered_invariants

    hj = np.float64(problem.h)
    gni_family = jax.eval_shape(lambda: method.hidden_momentum(
        system.without_metadata(), jax.tree_util.tree_map(lambda a: a[0], state0), hj)) is not None
    conserved, invariant = member_conservation(system, core, sys_batched, b0, gni_family=gni_family,
                                               invariants=registered_invariants(system.model),
                                               scheme=scheme_energy(method))
    monitor0 = initial(problem.h, (problem.steps + problem.partial) * problem.h, problem.t0, energy_applies=invariant,
                       members=B)
    same = all(c == conserved[0] for c in conserved)
    return monitor0, dict(conserved=conserved[0] if same else "differs by member: see Solution.member(i).conserved",
                          energy_invariant=bool(np.any(invariant)), member_conserved=None if same else conserved)


def _run_native_batch(problem, systems, core, sys_batched, method, state0, monitor0, reporter):
    """The batch on the native loop, or None (after a warning when native was asked for) where the
    step does not lower."""
    from .native.backend import native_loop, run_native

    plan, h, partial = problem.plan, problem.h, problem.partial
    # a batch of systems: their parameter values are inputs of one program (native_loop's params)
    example = systems[0].without_metadata() if sys_batched else core
    loop = native_loop(method, example, jax.tree_util.tree_map(lambda a: a[0], state0), batch=True,
                       params=sys_batched)
    if hasattr(loop, "run"):
        return run_native(loop, method, core, state0, np.float64(h), plan.lengths, plan.tail, partial * h,
                          partial=bool(partial), save_final=plan.save_final, save_states=False, monitor0=monitor0,
                          batched=True, system_batched=sys_batched,
                          progress_stride=reporter.stride if reporter.active else None)
    if problem.backend == "native":
        warnings.warn(f"backend='native': running on XLA, because the step does not lower: {loop}",
                      RuntimeWarning, stacklevel=5)
    return None
