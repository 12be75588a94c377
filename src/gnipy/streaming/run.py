"""The run (:mod:`gnipy.streaming`): :func:`simulate_to_file` integrates chunk by chunk,
commits a part after every chunk, resumes from the last good part, and merges the parts into
the destination."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..extras import check
from ..diagnostics import conserved_quantity, energy_is_invariant, scheme_energy
from .. import monitor
from ..errors import InputError, QualitativeFailureWarning
from ..inputs import finite_number, flag, positive_integer
from ..files import (
    OutputError,
    atomic_write,
    atomic_write_text,
    check_destination,
    clean_stale_temporaries,
    is_owned_dir,
    output_lock,
    remove_owned_dir,
)
from ..integrators.base import Integrator, MethodError
from ..registry import registered_invariants
from ..saveat import SaveAt
from ..compilation import jit
from ..run_arguments import MAX_STEPS, default_initial_condition, resolve_steps
from ..integration import solve
from ..problem import Problem, resolve_method
from ..solution import RESULT_SOLVER_FAILED
from ..system import System
from .interrupts import DeferredInterrupt
from .merge import merge_parts
from .parts import (
    CHUNK_ATTR,
    OWN_FILES,
    SPEC_HASH_ATTR,
    ChunkPlan,
    clean_own_temporaries,
    part_path,
    prepare_parts,
    storable_array,
    verify_parts,
    write_part,
    parts_directory,
)
from .result import StreamResult, finished_result, partial_result
from .size import DEFAULT_MAX_BYTES, check_size

#: Saved nodes per chunk when `chunk_steps` is not given.
DEFAULT_CHUNK_NODES = 10_000


@jit
def _init_one(method, system, b0, v0, h):
    return method.init(system, b0, v0, h)


@dataclass
class _Run:
    """The checked arguments of a streamed run, and what follows from them."""

    system: System
    method: Integrator  # checked and prepared for the initial condition
    b0: Any
    v0: Any
    h: float
    steps: int
    save_every: int
    chunk_steps: int
    t0: float
    energy_invariant: bool
    gni_family: bool
    attrs: dict  # the destination's extra global attributes
    spec: dict  # as written to spec.json
    canonical: dict  # the spec after a JSON round trip (as read back from spec.json)
    spec_hash: str

    @property
    def n_chunks(self) -> int:
        return -(-self.steps // self.chunk_steps)


def simulate_to_file(
    system: System,
    method: Integrator | str | None = None,
    q0=None,
    v0=None,
    *,
    path,
    R0=None,
    h,
    steps: int | None = None,
    t_final: float | None = None,
    save_every: int = 1,
    chunk_steps: int | None = None,
    t0: float = 0.0,
    project_v0: bool = False,
    throw: bool = True,
    resume: bool = False,
    overwrite: bool = False,
    max_bytes: int | None = DEFAULT_MAX_BYTES,
    attrs: Mapping[str, Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
    notice: Callable[[str], None] | None = None,
    stop_after_chunks: int | None = None,
) -> StreamResult:
    """Integrate like :func:`gnipy.simulate`, streaming the saved nodes to a netCDF file in chunks.

    Arguments:
        system, method, q0, v0, R0, h, steps, t_final, save_every, t0, project_v0: as for
            :func:`gnipy.simulate` (one trajectory; the continuous reference is not streamed).
        path: the destination netCDF file (written atomically when the run completes).
        chunk_steps: steps per chunk, a multiple of `save_every` (default: the steps of
            :data:`DEFAULT_CHUNK_NODES` saved nodes). Memory holds one chunk; a checkpoint
            (part file) is written after every chunk.
        throw: raise :class:`~gnipy.SolverFailure` when a step fails (the file is still written,
            up to the last good node, with `result = 1`); with False, return the result.
        resume: continue an interrupted run of the same spec from its last good part (every
            part is verified first), or return the result of a finished one whose destination
            verifies.
        overwrite: replace an existing regular file at `path` (never a link, directory or
            special file).
        max_bytes: the largest destination to write, in bytes (default
            :data:`DEFAULT_MAX_BYTES`, 64 GiB); a larger estimate, or one that does not fit in
            the free disk space, is refused before anything is computed. None lifts both checks.
        attrs: extra global attributes for the file (a `save_every` among them is recorded as
            the stride used, `min(save_every, steps)`).
        progress: called as `progress(steps_done, steps_total)` after every chunk.
        notice: called with each warning about the checkpoints (a part that did not verify and
            is computed again) as it happens; they are also in :attr:`StreamResult.warnings`.
        stop_after_chunks: stop (without writing the destination) after computing this many
            chunks in this call: for tests of interruption and resume.

    Returns:
        A :class:`StreamResult`.

    Raises:
        InputError, MethodError: bad arguments (named).
        OutputError: the destination or its parts directory cannot be written (or is not
            gnipy's to write), the estimated output is too large, a resumed run's spec differs or
            its `spec.json` cannot be read, or a finished destination is damaged.
        SolverFailure: a step failed and `throw` is True.
        KeyboardInterrupt: SIGINT; the parts written so far stay for `resume=True`.
    """
    check("netCDF4", "xarray", extra="files")  # before anything is computed or written
    from ..compilation import release_compiled_programs_if_needed

    release_compiled_programs_if_needed()
    project_v0, throw = flag("project_v0", project_v0), flag("throw", throw)
    resume, overwrite = flag("resume", resume), flag("overwrite", overwrite)
    run = _checked_run(system, method, q0, v0, R0, h=h, steps=steps, t_final=t_final, save_every=save_every,
                       chunk_steps=chunk_steps, t0=t0, project_v0=project_v0, max_bytes=max_bytes, attrs=attrs)
    notes: list[str] = []

    def note(message: str) -> None:
        notes.append(message)
        if notice is not None:
            notice(message)

    # --- the destination: locked from here on (a second writer of `path` is refused at once) ---
    given = path
    finished = Path(os.fspath(given)).expanduser() if isinstance(given, (str, os.PathLike)) else None
    with output_lock(finished, argument="path") if finished is not None else contextlib.nullcontext():
        if resume and finished is not None and finished.is_file() and not finished.is_symlink():
            done_already = _finished_run(finished, run, throw, overwrite, note)
            if done_already is not None:
                return _announce(done_already, run.method, run.system)
        path = check_destination(given, overwrite=overwrite, argument="path")
        parts = parts_directory(path)
        if max_bytes is not None:  # how large the output gets
            check_size(run.system, run.b0, run.steps, run.save_every, run.n_chunks, run.gni_family, path, parts,
                       max_bytes)
        clean_stale_temporaries(path)
        resuming = prepare_parts(parts, path, resume, note)
        plan, state, watch, resumed, n_chunks = _start(run, parts, resuming, progress, note)
        stopped_at, n_chunks = _compute_chunks(run, plan, parts, state, watch, resumed, n_chunks, progress,
                                               stop_after_chunks)
        if stopped_at is not None:  # stop_after_chunks: no destination
            return partial_result(path, parts, stopped_at, run.steps, n_chunks, resumed, notes)
        result = merge_parts(path, parts, n_chunks, resumed, run.steps, run.method, run.system, run.h, run.t0,
                             run.attrs, throw, run.energy_invariant, overwrite=overwrite, plan=plan, spec=run.canonical,
                             notes=notes)
        return _announce(result, run.method, run.system)


# ------------------------------------------------------------------------------------------
# The arguments
# ------------------------------------------------------------------------------------------
def _checked_run(system, method, q0, v0, R0, *, h, steps, t_final, save_every, chunk_steps, t0, project_v0, max_bytes,
                 attrs) -> _Run:
    """The arguments of :func:`simulate_to_file` checked (each error names its argument), the
    method prepared, and the run's spec."""
    method = _checked_method(system, method)
    h, steps = resolve_steps(h, steps, t_final)  # steps <= MAX_TOTAL_STEPS
    save_every = min(positive_integer("save_every", save_every), steps)
    chunk_steps = _checked_chunk_steps(chunk_steps, save_every, steps)
    if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, float, np.integer))
                                  or not max_bytes >= 0):
        raise InputError(f"max_bytes: expected a number of bytes >= 0 or None, got {max_bytes!r}")
    t0 = finite_number("t0", t0)
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
    method.validate(system, b0)
    method = method.prepare(system, b0)
    energy_invariant = energy_is_invariant(system, b0)
    attrs = dict(attrs or {})
    if "save_every" in attrs:  # the stride used (a larger one than the run saves only its ends)
        attrs["save_every"] = save_every
    gni_family = type(method).hidden_momentum is not Integrator.hidden_momentum
    attrs["conserved"] = conserved_quantity(system, b0, gni_family=gni_family,
                                            invariants=registered_invariants(system.model),
                                            scheme=scheme_energy(method))
    spec = {
        # the part files' layout: `time` holds the times (parts of an earlier layout are not resumed)
        "layout": "time-coordinate",
        "system": system.name, "params": dict(system.params), "method": method.name, "h": h, "steps": steps,
        "save_every": save_every, "chunk_steps": chunk_steps, "t0": t0,
        "q0": np.asarray(system.space.coordinates(b0)).tolist(), "v0": np.asarray(v0).tolist(),
        "R0": None if system.group is None else np.asarray(system.space.orientation(b0)).ravel().tolist(),
    }
    if system.origin is not None:  # a user's system: how to rebuild it, and its source's SHA-256
        spec["origin"] = {"reference": system.origin[0], "source_sha256": system.origin[1]}
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in (system.args or {}).items() if np.ndim(v) > 0}
    if arrays:  # named parameters that are arrays (the scalars are in params): their values' SHA-256
        digest = hashlib.sha256()
        for k in sorted(arrays):
            digest.update(f"{k}{arrays[k].shape}".encode() + np.ascontiguousarray(arrays[k]).tobytes())
        spec["array_args_sha256"] = "sha256:" + digest.hexdigest()
    canonical = json.loads(json.dumps(spec))
    spec_text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    spec_hash = "sha256:" + hashlib.sha256(spec_text.encode()).hexdigest()
    return _Run(system=system, method=method, b0=b0, v0=v0, h=h, steps=steps, save_every=save_every,
                chunk_steps=chunk_steps, t0=t0, energy_invariant=energy_invariant, gni_family=gni_family, attrs=attrs,
                spec=spec, canonical=canonical, spec_hash=spec_hash)


def _checked_method(system, method) -> Integrator:
    """The integrator of the run: `system` checked (a System, not forced), `method` resolved (None:
    the model's default; a name) and checked (an integrator, not the continuous reference)."""
    from ..reference import ContinuousReference

    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if system.is_forced:
        # a resumed run is matched to its interrupted one by the model's name and parameters, which
        # do not describe a force, and the chunks take no controls: run it with gnipy.simulate
        raise InputError("system: a forced system (System(..., force=F)) is not streamed to a file; run it with "
                         "gnipy.simulate (controls=...) and write the Solution with gnipy.write_netcdf")
    method = resolve_method(system, method)  # as simulate: None is the model's measured default
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference is not streamed; use gnipy.simulate")
    return method


def _checked_chunk_steps(chunk_steps, save_every: int, steps: int) -> int:
    """The steps per chunk: `chunk_steps` checked (None: :data:`DEFAULT_CHUNK_NODES` saved nodes), at
    most the run's steps rounded up to a whole save block."""
    if chunk_steps is None:
        chunk_steps = save_every * DEFAULT_CHUNK_NODES
    chunk_steps = positive_integer("chunk_steps", chunk_steps)
    if chunk_steps > MAX_STEPS:
        raise InputError(f"chunk_steps: at most {MAX_STEPS} steps per chunk, got {chunk_steps}")
    if chunk_steps % save_every:
        raise InputError(
            f"chunk_steps: {chunk_steps} is not a multiple of the save stride {save_every}"
        )
    return min(chunk_steps, steps + (-steps) % save_every)


# ------------------------------------------------------------------------------------------
# Starting and resuming
# ------------------------------------------------------------------------------------------
def _finished_run(finished: Path, run: _Run, throw: bool, overwrite: bool, note) -> StreamResult | None:
    """The result of the finished run of this spec at `finished`, whose parts directory (left by a
    process killed after the rename) is removed; None when `finished` is not such a run."""
    done_already = finished_result(finished, run.canonical, run.method, run.system, run.h, run.t0, throw, overwrite,
                                   note)
    if done_already is not None:
        clean_stale_temporaries(done_already.path)
        finished_parts = parts_directory(done_already.path)
        if is_owned_dir(finished_parts):  # left by a process killed after the rename
            clean_own_temporaries(finished_parts)
            remove_owned_dir(finished_parts, OWN_FILES)
    return done_already


def _start(run: _Run, parts: Path, resuming: bool, progress, note) -> tuple:
    """Where the chunks start: `(plan, state, watch, done, n_chunks)`, the chunk plan, the
    integrator state and the run's verdicts (:mod:`gnipy.monitor`) to continue from, the chunks
    already done (their parts verified when `resuming`), and the number of chunks of the run
    (fewer when a resumed part had failed). A fresh run writes its `spec.json`."""
    hj = np.float64(run.h)  # as in simulate (the same compiled program)
    core = run.system.without_metadata()
    state = _init_one(run.method, core, run.b0, np.asarray(run.v0, dtype=np.float64), hj)
    leaves, treedef = jax.tree_util.tree_flatten(state)
    plan = ChunkPlan(steps=run.steps, save_every=run.save_every, chunk_steps=run.chunk_steps, t0=run.t0, h=run.h,
                     spec_hash=run.spec_hash, leaves=[np.asarray(x) for x in leaves],
                     group=run.system.group is not None)
    done, last, n_chunks = 0, None, run.n_chunks
    if resuming:
        _check_stored_spec(parts, run.canonical)
        done, last, n_chunks = verify_parts(parts, plan, n_chunks, note)
        if last is not None:
            leaves = [jnp.asarray(a) for a in last["leaves"]]
        if done and progress is not None:
            progress(min(run.steps, done * run.chunk_steps), run.steps)
    else:
        atomic_write_text(parts / "spec.json", json.dumps(run.spec, indent=1), checked=True)
    state = jax.tree_util.tree_unflatten(treedef, leaves)
    # the verdicts of the whole run, every node checked (gnipy.monitor), carried from chunk to chunk
    watch = (np.asarray(last["data"]["monitor"], dtype=np.float64) if last is not None
             else monitor.initial(run.h, run.h * run.steps, run.t0, energy_applies=run.energy_invariant))
    return plan, state, watch, done, n_chunks


def _check_stored_spec(parts: Path, canonical: dict) -> None:
    """Refuse to resume the interrupted run in `parts` unless its `spec.json` reads and is `canonical`."""
    try:
        stored = json.loads((parts / "spec.json").read_text(encoding="utf-8"))
        if not isinstance(stored, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        raise OutputError(
            f"resume: cannot read {parts / 'spec.json'} ({e}): the interrupted run's spec is damaged; "
            "rerun with resume=False to start afresh"
        ) from None
    for key, value in canonical.items():
        if stored.get(key) != value:
            raise OutputError(
                f"resume: the interrupted run in {parts} has a different {key} "
                f"({stored.get(key)!r}, requested {value!r}); rerun with resume=False to start afresh"
            )
    extra = sorted(set(stored) - set(canonical))
    if extra:  # e.g. the interrupted run was of a user's system (origin), this one of another
        raise OutputError(
            f"resume: the interrupted run in {parts} has a different spec (it records {extra[0]!r}, this run "
            "does not); rerun with resume=False to start afresh"
        )


# ------------------------------------------------------------------------------------------
# The chunks
# ------------------------------------------------------------------------------------------
def _compute_chunks(run: _Run, plan: ChunkPlan, parts: Path, state, watch, done: int, n_chunks: int, progress,
                    stop_after_chunks) -> tuple[int | None, int]:
    """Compute the chunks from `done` on, committing a part after each; stop after a failed chunk.
    Returns `(stopped_at, n_chunks)`: the chunk not computed because of `stop_after_chunks` (None:
    all were), and the number of chunks of the run."""
    computed = 0
    for c in range(done, n_chunks):
        if stop_after_chunks is not None and computed >= stop_after_chunks:
            return c, n_chunks
        k_start, length, *_ = plan.chunk(c)
        state, watch, fail_k, variables, part_attrs = _compute_chunk(run, plan, c, state, watch)
        with DeferredInterrupt() as interrupt:
            atomic_write(part_path(parts, c), lambda tmp: write_part(tmp, variables, part_attrs), checked=True)
        if interrupt.pending:  # Ctrl-C while the part was written: it is committed, stop here
            raise KeyboardInterrupt
        computed += 1
        if progress is not None:
            progress(min(run.steps, k_start + length), run.steps)
        if fail_k >= 0:
            return None, c + 1
    return None, n_chunks


def _compute_chunk(run: _Run, plan: ChunkPlan, c: int, state, watch) -> tuple:
    """Chunk `c`: one call of the driver, continuing from the previous chunk's `state` and verdicts
    `watch`. Returns `(state, watch, fail_k, variables, attrs)`: the final state and verdicts, the
    failed step within the chunk (-1: none), and the part's variables and attributes."""
    k_start, length, n_blocks, remainder, k_local, keep = plan.chunk(c)
    # not announced: one warning for the whole run, when it is merged
    sol = solve(Problem.of(run.system, run.method, h=run.h, steps=length, saveat=SaveAt(every=run.save_every),
                           state0=state, t0=plan.times(k_start, np.zeros(1))[0], throw=False, monitor0=watch,
                           check_every_node=True))
    state, watch = sol.final_state, np.asarray(sol.monitor)
    fail_k, fail_res, its = sol.failed_step, sol.failed_residual, sol.iterations
    failed_step = -1
    keep = keep[: len(sol.t)]  # a failed chunk stops at its last good node
    if fail_k >= 0:
        # may keep no node: the step after the previous part's last failed
        keep &= k_local[: len(sol.t)] <= fail_k
        failed_step = k_start + fail_k
    k_local = k_local[: len(sol.t)]
    variables = _part_variables(sol, plan, k_start, k_local, keep)
    variables["monitor"] = (("monitor_slot",), watch)
    for i, leaf in enumerate(jax.tree_util.tree_leaves(state)):
        a = storable_array(leaf)
        variables[f"state_{i}"] = (tuple(f"state_{i}_d{j}" for j in range(a.ndim)), a)
    its = np.asarray(its)
    part_attrs = {
        "result": RESULT_SOLVER_FAILED if fail_k >= 0 else 0, "failed_step": failed_step,
        "residual": float(fail_res), "iterations_total": int(its[0]), "iterations_max": int(its[1]),
        CHUNK_ATTR: c, SPEC_HASH_ATTR: plan.spec_hash, "backend": sol.backend,
    }
    return state, watch, fail_k, variables, part_attrs


def _part_variables(sol, plan: ChunkPlan, k_start: int, k_local: np.ndarray, keep: np.ndarray) -> dict:
    """The variables along `time` of a part: the nodes `keep` of the chunk's Solution `sol`."""
    variables = {
        "time": (("time",), plan.times(k_start, k_local)[keep]),
        "step": (("time",), (k_start + k_local)[keep]),
        "q": (("time", "coordinate"), np.asarray(sol.q)[keep]),
        "v": (("time", "velocity"), np.asarray(sol.v)[keep]),
        "p": (("time", "velocity"), np.asarray(sol.p)[keep]),
        "energy": (("time",), np.asarray(sol.energy)[keep]),
        "constraint_residual": (("time", "constraint"), np.asarray(sol.constraint_residual)[keep]),
    }
    if sol.R is not None:
        variables["R"] = (("time", "i", "j"), np.asarray(sol.R)[keep])
    # the GNI family's diagnostics at the nodes (as Solution.to_xarray writes them)
    if sol.hidden_momentum is not None:
        for name, a in zip(("hidden_momentum", "hidden_momentum_expected", "energy_plus"),
                           (sol.hidden_momentum, sol.hidden_expected, sol.energy_plus)):
            variables[name] = (("time",), np.asarray(a)[keep])
    return variables


def _announce(result: StreamResult, method, system) -> StreamResult:
    """`result`, after one :class:`~gnipy.QualitativeFailureWarning` when its steps converged but
    a verdict left its band (as :func:`gnipy.simulate` warns)."""
    if result.complete and not result.result and not result.healthy:
        texts = [w.removeprefix("WARNING: ") for w in result.warnings if w.startswith("WARNING: ")]
        warnings.warn(QualitativeFailureWarning(
            f"{system.name} with {method.name}: QUALITATIVELY WRONG ({result.path}, attribute 'health').\n"
            + "\n".join(texts)), stacklevel=3)
    return result
