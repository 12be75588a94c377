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
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..extras import check
from ..diagnostics import conserved_quantity, energy_is_invariant
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
from ..problem import Problem
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
    from ..methods import get_method
    from ..reference import ContinuousReference

    release_compiled_programs_if_needed()
    project_v0, throw = flag("project_v0", project_v0), flag("throw", throw)
    resume, overwrite = flag("resume", resume), flag("overwrite", overwrite)
    if not isinstance(system, System):
        raise InputError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if system.is_forced:
        # a resumed run is matched to its interrupted one by the model's name and parameters, which
        # do not describe a force, and the chunks take no controls: run it with gnipy.simulate
        raise InputError("system: a forced system (System(..., force=F)) is not streamed to a file; run it with "
                         "gnipy.simulate (controls=...) and write the Solution with gnipy.write_netcdf")
    if method is None:  # as simulate: the model's measured default
        from ..registry import default_method_for

        method = default_method_for(system.model, system) if isinstance(system, System) else default_method_for(None)
    if isinstance(method, str):
        method = get_method(method)
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference is not streamed; use gnipy.simulate")
    if not isinstance(method, Integrator):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    h, steps = resolve_steps(h, steps, t_final)  # steps <= MAX_TOTAL_STEPS
    save_every = min(positive_integer("save_every", save_every), steps)
    if chunk_steps is None:
        chunk_steps = save_every * DEFAULT_CHUNK_NODES
    chunk_steps = positive_integer("chunk_steps", chunk_steps)
    if chunk_steps > MAX_STEPS:
        raise InputError(f"chunk_steps: at most {MAX_STEPS} steps per chunk, got {chunk_steps}")
    if chunk_steps % save_every:
        raise InputError(
            f"chunk_steps: {chunk_steps} is not a multiple of the save stride {save_every}"
        )
    chunk_steps = min(chunk_steps, steps + (-steps) % save_every)
    if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, float, np.integer))
                                  or not max_bytes >= 0):
        raise InputError(f"max_bytes: expected a number of bytes >= 0 or None, got {max_bytes!r}")
    t0 = finite_number("t0", t0)
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
    method.check(system, b0)
    method = method.prepare(system, b0)
    energy_invariant = energy_is_invariant(system, b0)
    attrs = dict(attrs or {})
    if "save_every" in attrs:  # the stride used (a larger one than the run saves only its ends)
        attrs["save_every"] = save_every
    gni_family = type(method).hidden_momentum is not Integrator.hidden_momentum
    attrs["conserved"] = conserved_quantity(system, b0, gni_family=gni_family,
                                            invariants=registered_invariants(system.model),
                                            conserves_energy=bool(getattr(method, "conserves_energy", False)))

    n_chunks = -(-steps // chunk_steps)
    spec = {
        # the part files' layout: `time` holds the times (parts of an earlier layout are not resumed)
        "layout": "time-coordinate",
        "system": system.name, "params": dict(system.params), "method": method.name, "h": h, "steps": steps,
        "save_every": save_every, "chunk_steps": chunk_steps, "t0": t0,
        "q0": np.asarray(system.space.coordinates(b0)).tolist(), "v0": np.asarray(v0).tolist(),
        "R0": None if system.group is None else np.asarray(system.space.orientation(b0)).ravel().tolist(),
    }
    canonical = json.loads(json.dumps(spec))
    spec_text = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    spec_hash = "sha256:" + hashlib.sha256(spec_text.encode()).hexdigest()
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
            done_already = finished_result(finished, canonical, method, system, h, t0, throw, overwrite, note)
            if done_already is not None:
                clean_stale_temporaries(done_already.path)
                finished_parts = parts_directory(done_already.path)
                if is_owned_dir(finished_parts):  # left by a process killed after the rename
                    clean_own_temporaries(finished_parts)
                    remove_owned_dir(finished_parts, OWN_FILES)
                return _announce(done_already, method, system)
        path = check_destination(given, overwrite=overwrite, argument="path")
        parts = parts_directory(path)

        # --- how large the output gets ---------------------------------------------------------
        if max_bytes is not None:
            check_size(system, b0, steps, save_every, n_chunks, gni_family, path, parts, max_bytes)

        clean_stale_temporaries(path)
        resuming = prepare_parts(parts, path, resume, note)

        hj = np.float64(h)  # as in simulate (the same compiled program)
        core = system.without_metadata()
        state = _init_one(method, core, b0, np.asarray(v0, dtype=np.float64), hj)
        leaves, treedef = jax.tree_util.tree_flatten(state)
        plan = ChunkPlan(steps=steps, save_every=save_every, chunk_steps=chunk_steps, t0=t0, h=h, spec_hash=spec_hash,
                     leaves=[np.asarray(x) for x in leaves], group=system.group is not None)

        done, last = 0, None
        if resuming:
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
            done, last, n_chunks = verify_parts(parts, plan, n_chunks, note)
            if last is not None:
                leaves = [jnp.asarray(a) for a in last["leaves"]]
            if done and progress is not None:
                progress(min(steps, done * chunk_steps), steps)
        else:
            atomic_write_text(parts / "spec.json", json.dumps(spec, indent=1), checked=True)
        state = jax.tree_util.tree_unflatten(treedef, leaves)
        resumed = done
        # the verdicts of the whole run, every node checked (gnipy.monitor), carried from chunk to chunk
        watch = (np.asarray(last["data"]["monitor"], dtype=np.float64) if last is not None
                 else monitor.initial(h, h * steps, t0, energy_applies=energy_invariant))

        failed_step = -1
        computed = 0
        for c in range(done, n_chunks):
            if stop_after_chunks is not None and computed >= stop_after_chunks:
                return partial_result(path, parts, c, steps, n_chunks, resumed, notes)
            k_start, length, n_blocks, remainder, k_local, keep = plan.chunk(c)
            # the chunk is one call of the driver, continuing from the previous chunk's state
            # not announced: one warning for the whole run, when it is merged
            sol = solve(Problem.of(system, method, h=h, steps=length, saveat=SaveAt(every=save_every), state0=state,
                                   t0=plan.times(k_start, np.zeros(1))[0], throw=False, monitor0=watch,
                                   check_every_node=True))
            state, watch = sol.final_state, np.asarray(sol.monitor)
            fail_k, fail_res, its = sol.failed_step, sol.failed_residual, sol.iterations
            keep = keep[: len(sol.t)]  # a failed chunk stops at its last good node
            if fail_k >= 0:
                # may keep no node: the step after the previous part's last failed
                keep &= k_local[: len(sol.t)] <= fail_k
                failed_step = k_start + fail_k
            k_local = k_local[: len(sol.t)]
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
            variables["monitor"] = (("monitor_slot",), watch)
            for i, leaf in enumerate(jax.tree_util.tree_leaves(state)):
                a = storable_array(leaf)
                variables[f"state_{i}"] = (tuple(f"state_{i}_d{j}" for j in range(a.ndim)), a)
            its = np.asarray(its)
            part_attrs = {
                "result": RESULT_SOLVER_FAILED if fail_k >= 0 else 0, "failed_step": failed_step,
                "residual": float(fail_res), "iterations_total": int(its[0]), "iterations_max": int(its[1]),
                CHUNK_ATTR: c, SPEC_HASH_ATTR: spec_hash, "backend": sol.backend,
            }
            with DeferredInterrupt() as interrupt:
                atomic_write(part_path(parts, c), lambda tmp: write_part(tmp, variables, part_attrs), checked=True)
            if interrupt.pending:  # Ctrl-C while the part was written: it is committed, stop here
                raise KeyboardInterrupt
            computed += 1
            if progress is not None:
                progress(min(steps, k_start + length), steps)
            if fail_k >= 0:
                n_chunks = c + 1
                break

        result = merge_parts(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant,
                         overwrite=overwrite, plan=plan, spec=canonical, notes=notes)
        return _announce(result, method, system)


def _announce(result: StreamResult, method, system) -> StreamResult:
    """`result`, after one :class:`~gnipy.QualitativeFailureWarning` when its steps converged but
    a verdict left its band (as :func:`gnipy.simulate` warns)."""
    if result.complete and not result.result and not result.healthy:
        texts = [w.removeprefix("WARNING: ") for w in result.warnings if w.startswith("WARNING: ")]
        warnings.warn(QualitativeFailureWarning(
            f"{system.name} with {method.name}: QUALITATIVELY WRONG ({result.path}, attribute 'health').\n"
            + "\n".join(texts)), stacklevel=3)
    return result
