"""Long runs streamed to a file in chunks, with checkpoints and resume.

:func:`simulate_to_file` integrates like :func:`gnipy.simulate` but never holds more than one chunk
of saved nodes in memory: every `chunk_steps` steps, the chunk's nodes and the integrator's state
at its end are committed to a *part file*; at the end the parts are concatenated (streamed, one
part at a time, through dask) into the destination netCDF file. Memory is therefore bounded by one
chunk, whatever the number of steps.

**Files.** While the run is under way, the parts live in the directory `PATH.parts/` next to the
destination: `spec.json` (what is being computed) and `part_000000.nc`, `part_000001.nc`, ...
Each part is written atomically (temporary name, then rename), so a part file either is complete
or does not exist; the destination file appears, also atomically, only when every part is done,
and the parts directory is then removed. No file is ever half-written, whenever the process dies.

**Resume.** With `resume=True`, a run whose `PATH.parts/` exists continues after its last complete
part, from the integrator state stored in that part (float64, exact). The continuation runs the
same compiled chunks as an uninterrupted run, so the result is identical to the last bit. The
stored spec must equal the requested one (model, method, h, steps, stride, chunk length, initial
condition, parameters); a mismatch is an error that names the differing field.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import uuid
from collections.abc import Callable, Mapping
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .diagnostics import StreamedVerdicts, conserved_quantity, energy_is_invariant, saved_node_diagnostics
from .integrators.base import Integrator, MethodError
from .models.registry import registered_invariants
from .io import OutputError, write_netcdf
from .io import check_writable
from .simulate import MAX_STEPS, _init_one, _integrate, default_initial_condition, resolve_steps
from .solution import RESULT_SOLVER_FAILED, SolverFailure
from .system import System, SystemError

__all__ = ["simulate_to_file", "StreamResult", "parts_directory", "DEFAULT_CHUNK_NODES"]

#: Saved nodes per chunk when `chunk_steps` is not given.
DEFAULT_CHUNK_NODES = 10_000


@dataclass(frozen=True)
class StreamResult:
    """What :func:`simulate_to_file` did.

    Attributes:
        path: the destination file.
        complete: False when the call stopped early (`stop_after_chunks`): the destination is not
            written, the parts directory holds the chunks done so far (resume continues).
        nodes: saved nodes written.
        steps: steps computed in total (including those of earlier, interrupted runs).
        chunks: number of chunks; `chunks_resumed`: how many came from an earlier run.
        result: 0 on success, 1 if a step failed (the file then ends at the last good node).
        failed_step: the failed step, or -1.
        energy_error: max |E − E₀| over the saved nodes.
        constraint_residual: max |μ(v − Y)| over the saved nodes.
        iterations: total Newton iterations and the maximum per step.
        final_q, final_v: the last saved node.
        warnings: the run-time warnings (:meth:`gnipy.Solution.warnings`; the verdicts are also
            file attributes).
    """

    path: Path
    complete: bool
    nodes: int
    steps: int
    chunks: int
    chunks_resumed: int
    result: int
    failed_step: int
    energy_error: float
    constraint_residual: float
    iterations: tuple[int, int]
    final_q: np.ndarray
    final_v: np.ndarray
    warnings: list = dataclasses.field(default_factory=list)


def parts_directory(path) -> Path:
    """The directory of part files of a streamed run writing `path` (`PATH.parts`)."""
    path = Path(os.fspath(path))
    return path.with_name(path.name + ".parts")


def _atomic_write(path: Path, write) -> None:
    """`write(tmp)` to a temporary name beside `path`, flushed to disk, then renamed to `path`."""
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        write(tmp)
        with open(tmp, "rb") as f:  # on disk before it counts as done
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except FileNotFoundError:
            pass
        raise


def _part_path(parts: Path, c: int) -> Path:
    return parts / f"part_{c:06d}.nc"


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
    attrs: Mapping[str, Any] | None = None,
    progress: Callable[[int, int], None] | None = None,
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
        resume: continue an interrupted run of the same spec from its last complete part.
        attrs: extra global attributes for the file.
        progress: called as `progress(steps_done, steps_total)` after every chunk.
        stop_after_chunks: stop (without writing the destination) after computing this many
            chunks in this call: for tests of interruption and resume.

    Returns:
        A :class:`StreamResult`.

    Raises:
        SystemError, MethodError: bad arguments (named).
        OutputError: the destination or its parts directory cannot be written, or a resumed
            run's spec differs.
        SolverFailure: a step failed and `throw` is True.
    """
    import xarray as xr

    from .compilation import release_compiled_programs_if_needed
    from .methods import get_method
    from .reference import ContinuousReference

    release_compiled_programs_if_needed()
    if not isinstance(system, System):
        raise SystemError(f"system: expected a gnipy.System, got {type(system).__name__}")
    if method is None:  # as simulate: the model's measured default
        from .models.registry import default_method_for

        method = default_method_for(system.name if isinstance(system, System) else "")
    if isinstance(method, str):
        method = get_method(method)
    if isinstance(method, ContinuousReference):
        raise MethodError("method: the continuous reference is not streamed; use gnipy.simulate")
    if not isinstance(method, Integrator):
        raise MethodError(f"method: expected an integrator or a method name, got {type(method).__name__}")
    h, steps = resolve_steps(h, steps, t_final)
    if isinstance(save_every, bool) or int(save_every) != save_every or save_every < 1:
        raise SystemError(f"save_every: must be a positive integer, got {save_every!r}")
    save_every = int(min(save_every, steps))
    if chunk_steps is None:
        chunk_steps = save_every * DEFAULT_CHUNK_NODES
    if isinstance(chunk_steps, bool) or int(chunk_steps) != chunk_steps or chunk_steps < 1:
        raise SystemError(f"chunk_steps/--checkpoint-every: must be a positive integer, got {chunk_steps!r}")
    chunk_steps = int(chunk_steps)
    if chunk_steps > MAX_STEPS:
        raise SystemError(f"chunk_steps/--checkpoint-every: at most {MAX_STEPS} steps per chunk, got {chunk_steps}")
    if chunk_steps % save_every:
        raise SystemError(
            f"chunk_steps/--checkpoint-every: {chunk_steps} is not a multiple of the save stride {save_every}"
        )
    chunk_steps = min(chunk_steps, steps + (-steps) % save_every)
    t0 = float(t0)
    if not math.isfinite(t0):
        raise SystemError(f"t0: must be finite, got {t0!r}")
    q0, v0, R0 = default_initial_condition(system, q0, v0, R0)
    b0, v0 = system.check(q0, v0, R0=R0, project_v0=project_v0)
    method.check(system, b0)
    method = method.prepare(system, b0)
    energy_invariant = energy_is_invariant(system, b0)
    attrs = dict(attrs or {})
    gni_family = type(method).hidden_momentum is not Integrator.hidden_momentum
    attrs["conserved"] = conserved_quantity(system, b0, gni_family=gni_family,
                                            invariants=registered_invariants(system.name))

    path = check_writable(path)

    n_chunks = -(-steps // chunk_steps)
    spec = {
        # the part files' layout: `time` holds the times (parts of an earlier layout are not resumed)
        "layout": "time-coordinate",
        "system": system.name, "params": dict(system.params), "method": method.name, "h": h, "steps": steps,
        "save_every": save_every, "chunk_steps": chunk_steps, "t0": t0,
        "q0": np.asarray(system.space.coordinates(b0)).tolist(), "v0": np.asarray(v0).tolist(),
        "R0": None if system.group is None else np.asarray(system.space.orientation(b0)).ravel().tolist(),
    }
    parts = parts_directory(path)
    done = 0
    if resume and (parts / "spec.json").is_file():
        try:
            stored = json.loads((parts / "spec.json").read_text())
        except (OSError, ValueError) as e:
            raise OutputError(f"--resume: cannot read {parts / 'spec.json'}: {e}") from e
        for key, value in spec.items():
            if stored.get(key) != json.loads(json.dumps(value)):
                raise OutputError(
                    f"--resume: the interrupted run in {parts} has a different {key} "
                    f"({stored.get(key)!r}, requested {value!r}); rerun without --resume to start afresh"
                )
        while done < n_chunks and _part_path(parts, done).is_file():
            done += 1
    else:
        shutil.rmtree(parts, ignore_errors=True)
        try:
            parts.mkdir()
            _atomic_write(parts / "spec.json", lambda tmp: tmp.write_text(json.dumps(spec, indent=1)))
        except OSError as e:
            raise OutputError(f"cannot write {parts}: {e.strerror or e}") from e
    resumed = done

    hj = np.float64(h)  # as in simulate (the same compiled program)
    core = system.without_metadata()
    state = _init_one(method, core, b0, np.asarray(v0, dtype=np.float64), hj)
    leaves, treedef = jax.tree_util.tree_flatten(state)
    if done:
        with xr.open_dataset(_part_path(parts, done - 1)) as last:
            leaves = [jnp.asarray(last[f"state_{i}"].values).reshape(np.shape(x)) for i, x in enumerate(leaves)]
            if int(last.attrs["result"]) != 0:  # the interrupted run had already failed: nothing to add
                done = n_chunks
        state = jax.tree_util.tree_unflatten(treedef, leaves)

    failed_step = -1
    computed = 0
    for c in range(done, n_chunks):
        if stop_after_chunks is not None and computed >= stop_after_chunks:
            return _partial_result(path, parts, c, steps, n_chunks, resumed)
        k_start = c * chunk_steps
        length = min(chunk_steps, steps - k_start)
        n_blocks, remainder = divmod(length, save_every)
        b, v, p, energy, residual, fail_k, fail_res, its, state, diag = _integrate(
            method, core, state, hj, n_blocks, np.int32(save_every), np.int32(remainder), bool(remainder),
        )
        k_local = np.concatenate([np.arange(n_blocks + 1) * save_every, [length] if remainder else []]).astype(np.int64)
        fail_k = int(fail_k)
        keep = np.ones(len(k_local), dtype=bool)
        if c > 0:
            keep[0] = False  # the chunk's first node is the previous chunk's last
        if fail_k >= 0:
            keep &= k_local <= fail_k
            failed_step = k_start + fail_k
        q, R = system.space.coordinates(b), system.space.orientation(b)
        ds = _chunk_dataset(system, q, v, p, energy, residual, R, keep, t0 + h * (k_start + k_local), k_start + k_local)
        if diag is not None:  # the GNI family's diagnostics at the nodes (as Solution.to_xarray writes them)
            diag = saved_node_diagnostics(core, b, v, p, diag, h)
            for name, a in zip(("hidden_momentum", "hidden_momentum_expected", "energy_plus"), diag):
                ds[name] = (("time",), np.asarray(a)[keep])
        for i, leaf in enumerate(jax.tree_util.tree_leaves(state)):
            a = np.asarray(leaf)
            ds[f"state_{i}"] = (tuple(f"state_{i}_d{j}" for j in range(a.ndim)), a)
        its = np.asarray(its)
        ds.attrs.update(
            result=RESULT_SOLVER_FAILED if fail_k >= 0 else 0, failed_step=failed_step,
            residual=float(fail_res), iterations_total=int(its[0]), iterations_max=int(its[1]),
        )
        try:
            _atomic_write(_part_path(parts, c), ds.to_netcdf)
        except OSError as e:
            raise OutputError(f"cannot write {_part_path(parts, c)}: {e.strerror or e}") from e
        computed += 1
        if progress is not None:
            progress(min(steps, k_start + length), steps)
        if fail_k >= 0:
            n_chunks = c + 1
            break

    return _finish(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant)


def _merge(files, nodes, path, system, method, h, steps, result, stats, n_chunks, attrs) -> None:
    import xarray as xr

    from .io import _NODE_ATTRS, _STEP_ATTRS, _time_attrs, cf_attributes
    from .solution import set_variable_attrs
    from .system import describe_orientations

    ds = xr.open_mfdataset([str(f) for f in files], combine="nested", concat_dim="time", data_vars="minimal",
                           coords="minimal", compat="override", parallel=False)
    try:
        ds = ds.drop_vars([v for v in ds.data_vars if v.startswith("state_")])
        for var in ds.variables.values():  # the parts' `coordinates` ("step"): xarray lists the merged ones
            var.encoding.pop("coordinates", None)
        # the parts hold `time` (the times) and `step`; the node index runs over the whole run
        ds = ds.assign_coords(node=("time", np.arange(nodes, dtype=np.int64), dict(_NODE_ATTRS)))
        ds["time"].attrs.update(_time_attrs())
        ds["step"].attrs.update(_STEP_ATTRS)
        ds = ds.assign_coords(coordinate=list(system.coordinates), velocity=list(system.velocities),
                              constraint=np.arange(ds.sizes["constraint"]))
        set_variable_attrs(ds)
        ds.attrs = {
            **cf_attributes(system.name, method.name),
            "model": system.name, "method": method.name, "h": float(h), "steps": int(steps), "start": "p+ = G v0",
            "result": int(result), "newton_iterations_total": int(sum(s["it_tot"] for s in stats)),
            "newton_iterations_max": int(max(s["it_max"] for s in stats)), "streamed_chunks": int(n_chunks),
            "params": json.dumps(dict(system.params)),
            **{f"param_{k}": float(v) for k, v in system.params},
        }
        if system.group is not None:
            ds.attrs["orientation"] = describe_orientations(system)
        write_netcdf(ds, path, attrs=dict(attrs or {}))
    finally:
        ds.close()


def _chunk_dataset(system, q, v, p, energy, residual, R, keep, times, steps):
    """The part file of one chunk: its nodes along `time` (the times), with their step indices."""
    import xarray as xr

    data = {
        "q": (("time", "coordinate"), np.asarray(q)[keep]),
        "v": (("time", "velocity"), np.asarray(v)[keep]),
        "p": (("time", "velocity"), np.asarray(p)[keep]),
        "energy": (("time",), np.asarray(energy)[keep]),
        "constraint_residual": (("time", "constraint"), np.asarray(residual)[keep]),
    }
    if R is not None:
        data["R"] = (("time", "i", "j"), np.asarray(R)[keep])
    return xr.Dataset(data, coords={"time": times[keep], "step": ("time", np.asarray(steps, np.int64)[keep])})


def _partial_result(path, parts, c, steps, n_chunks, resumed):
    return StreamResult(
        path=path, complete=False, nodes=0, steps=0, chunks=n_chunks, chunks_resumed=resumed, result=0, failed_step=-1,
        energy_error=float("nan"), constraint_residual=float("nan"), iterations=(0, 0),
        final_q=np.zeros(0), final_v=np.zeros(0),
    )


def _finish(path, parts, n_chunks, resumed, steps, method, system, h, t0, attrs, throw, energy_invariant=False):
    """Concatenate the parts (streamed through dask: one part in memory at a time) into `path`."""
    import xarray as xr

    files = [_part_path(parts, c) for c in range(n_chunks)]
    stats = []
    verdicts = StreamedVerdicts(h, h * steps, energy_invariant)
    for f in files:
        with xr.open_dataset(f) as d:
            e = d["energy"].values
            kinetic = 0.5 * np.sum(d["v"].values * d["p"].values, axis=-1)
            hidden = (d["hidden_momentum"].values, d["hidden_momentum_expected"].values) if "hidden_momentum" in d else (None, None)
            verdicts.update(d["time"].values, e, kinetic, *hidden)
            stats.append(dict(result=int(d.attrs["result"]), failed=int(d.attrs["failed_step"]),
                              residual=float(d.attrs["residual"]), it_tot=int(d.attrs["iterations_total"]),
                              it_max=int(d.attrs["iterations_max"]), e_min=float(e.min()) if e.size else np.inf,
                              e_max=float(e.max()) if e.size else -np.inf,
                              res=float(np.max(np.abs(d["constraint_residual"].values), initial=0.0)),
                              e0=float(e[0]) if e.size else np.nan, q=d["q"].values[-1:], v=d["v"].values[-1:],
                              n=int(d.sizes["time"])))
    e0 = stats[0]["e0"]
    energy_error = max(max(abs(s["e_max"] - e0), abs(s["e_min"] - e0)) for s in stats if s["n"])
    result = max(s["result"] for s in stats)
    failed_step = next((s["failed"] for s in stats if s["result"]), -1)
    nodes = sum(s["n"] for s in stats)
    import dask

    # dask's synchronous scheduler: one part in memory at a time, and no concurrent HDF5 calls
    # (the netCDF library is not thread-safe; threaded reads of several parts can crash it)
    attrs = dict(attrs or {}, **verdicts.attrs(method.name, system.name))
    with dask.config.set(scheduler="synchronous"):
        _merge(files, nodes, path, system, method, h, steps, result, stats, n_chunks, attrs)
    shutil.rmtree(parts, ignore_errors=True)
    last = stats[-1]
    out = StreamResult(
        path=path, complete=True, nodes=nodes, steps=steps if result == 0 else failed_step, chunks=n_chunks, chunks_resumed=resumed,
        result=result, failed_step=failed_step, energy_error=float(energy_error),
        constraint_residual=max(s["res"] for s in stats),
        iterations=(int(sum(s["it_tot"] for s in stats)), int(max(s["it_max"] for s in stats))),
        final_q=np.asarray(last["q"][-1]), final_v=np.asarray(last["v"][-1]),
        warnings=verdicts.warnings(method.name, system.name),
    )
    if result and throw:
        s = next(s for s in stats if s["result"])
        raise SolverFailure(
            f"{method.name}: step {failed_step} (t = {t0 + h * failed_step:.6g} -> {t0 + h * (failed_step + 1):.6g}) "
            f"failed: the solve did not converge or gave a non-finite value (residual {s['residual']:.3e}); "
            f"{path} holds the run up to the last good node",
            step=failed_step, time=t0 + h * failed_step, residual=s["residual"], solution=None,
        )
    return out
