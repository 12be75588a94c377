"""Running a sweep: :func:`run_sweep` and its report."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import time
import uuid
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from ..extras import check, require
from .. import files
from ..errors import InputError, QualitativeFailureWarning
from . import plan as _plan
from .cluster import DEFAULT_CONNECT_TIMEOUT, Cluster, default_workers, scheduler_address
from .errors import SweepError, SweepFailure
from .grid import grid_columns
from .integrity import resume
from .ownership import check_out
from .store import create_store, open_group, read_done, write_chunk
from .task import run_chunk

__all__ = ["SweepReport", "run_sweep"]

# failed members listed in a SweepReport
_FAILURES_LISTED = 5


@dataclasses.dataclass(frozen=True)
class SweepReport:
    """What :func:`run_sweep` did.

    Attributes:
        path: the store.
        members: the number of members of the sweep (grid points).
        chunks: the number of chunks of the sweep.
        chunks_computed: chunks computed (and written) by this run.
        chunks_skipped: chunks found done (and intact) in the store and not recomputed.
        chunks_remaining: chunks still not done (non-zero only when `max_chunks` stopped
            the run).
        failed_members: members whose run failed (`result = 1`) over all done chunks.
        wall_time: seconds for the whole call (cluster start, compilation and writes
            included).
        members_computed: members computed by this run (padding excluded).
        steps: the number of steps per member.
        chunk_size: the number of members per (full) chunk.
        spec: the sweep's specification (as stored in the store's `sweep_spec`
            attribute).
        chunks_repaired: chunks flagged done but found damaged (unreadable, or their data
            differ from their checksum), and so not skipped (a :class:`SweepWarning` named
            each).
        failures: the first failed members (at most 5), each a dict: `member` (its index),
            `grid` (its grid values, name -> value), `step`, `time` (the failed step and its
            start time) and `residual` (of the failed solve; NaN when not reported).
        unhealthy_members: members whose steps converged but whose motion went qualitatively
            wrong (a verdict out of band at some node; the store's `healthy` is False), over all
            done chunks; a :class:`~gnipy.QualitativeFailureWarning` says how many.
    """

    path: Path
    members: int
    chunks: int
    chunks_computed: int
    chunks_skipped: int
    chunks_remaining: int
    failed_members: int
    wall_time: float
    members_computed: int
    steps: int
    chunk_size: int
    spec: dict = dataclasses.field(repr=False, compare=False)
    chunks_repaired: int = 0
    failures: tuple = dataclasses.field(default=(), repr=False, compare=False)
    unhealthy_members: int = 0

    @property
    def complete(self) -> bool:
        """Whether every chunk of the sweep is done."""
        return self.chunks_remaining == 0

    @property
    def member_steps_per_second(self) -> float:
        """Member-steps computed per second of wall time in this run."""
        return self.members_computed * self.steps / self.wall_time if self.wall_time > 0 else float("nan")


class _Progress:
    """The progress of a run: a rich bar on a terminal (`progress=True`) and/or the caller's
    `progress(chunks_done, chunks_total[, description])`."""

    def __init__(self, progress, total: int, done: int):
        require("rich", extra="sweeps")
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn
        from rich.progress import TimeElapsedColumn, TimeRemainingColumn

        self.callback = progress if callable(progress) else None
        self.total, self.done = total, done
        console = Console(stderr=True)
        self.bar = Progress(
            SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
            TextColumn("chunks"), TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TimeRemainingColumn(),
            console=console, transient=True, disable=not (progress is True and console.is_terminal),
        )
        self.task = None

    def __enter__(self):
        self.bar.__enter__()
        self.task = self.bar.add_task("starting the cluster", total=self.total - self.done, rate="")
        return self

    def __exit__(self, *exc):
        return self.bar.__exit__(*exc)

    def describe(self, text: str) -> None:
        self.bar.update(self.task, description=text)
        if self.callback is not None:
            self.callback(self.done, self.total, text)

    def advance(self, rate: str | None) -> None:
        self.done += 1
        self.bar.update(self.task, advance=1, **({} if rate is None else {"rate": rate}))
        if self.callback is not None:
            self.callback(self.done, self.total)


def run_sweep(
    model: str,
    grid,
    *,
    out,
    h: float,
    steps: int | None = None,
    t_final: float | None = None,
    method: str | None = None,
    save_every: int | None = None,
    set_params: Mapping[str, float] | None = None,
    project_v0: bool = True,
    chunk_size: int = 1000,
    scheduler: str | None = None,
    workers: int | None = None,
    client=None,
    overwrite: bool = False,
    max_chunks: int | None = None,
    progress: bool | Callable[..., None] = True,
    max_bytes: int | None = _plan.DEFAULT_MAX_BYTES,
    connect_timeout: float = DEFAULT_CONNECT_TIMEOUT,
) -> SweepReport:
    """Run a parameter sweep on a dask.distributed cluster and write it to a zarr store.

    Arguments:
        model: a model name (see :func:`gnipy.model_names`), or the user's system as
            `"path/to/file.py:NAME"` or `"package.module:NAME"` (:func:`gnipy.get_model`; the workers
            load it again, and refuse a file changed since the sweep was planned). Sweeping its
            parameters needs a System whose functions take them as `args`
            (:class:`gnipy.System`), so that the members run as one batch.
        grid: the grid axes: `"NAME=linspace(START, STOP, COUNT)"` or `"NAME=START:STOP:COUNT"`
            strings, :class:`GridAxis` objects, or a mapping `{name: (start, stop, count)}`; NAME
            is a parameter, `q0.<coordinate>` or `v0.<velocity>`. The sweep is their Cartesian
            product (C order); the store's dimension of `q0.x` is `q0_x` (`GridAxis.dim`).
        out: the zarr store (a directory, e.g. `"sweep.zarr"`); its parent must exist.
        h: the step size.
        steps / t_final: the number of steps, or the final time (a whole number of
            steps).
        method: a method name (see :func:`gnipy.method_names`; not `"reference"`); default: the
            model's measured default.
        save_every: the save stride (nodes 0, K, 2K, ... and the last); default `steps`:
            the initial and the last node only.
        set_params: fixed values of other parameters (the rest keep the model's
            defaults).
        project_v0: project each member's initial velocity onto its constraints (on by
            default: a v0 grid, or parameters that change the constraints, move v0 off
            them).
        chunk_size: the most members per task; a chunk is a block of the grid, one zarr chunk
            of the store (the last axes whole as far as they fit, see
            :class:`~gnipy.sweep.grid.ChunkLayout`), so it may hold fewer. The last chunk of
            each row of blocks is padded on input to the chunk size, so that every chunk runs
            the same compiled program.
        scheduler: an existing cluster's scheduler: its address (`"tcp://host:8786"`,
            `"tls://..."`, `"inproc://..."`, `"host:8786"`) or a scheduler file (JSON, as
            written by `dask scheduler --scheduler-file`); its workers need gnipy installed.
            The address is checked and the connection made before the store is created.
        workers: the size of the local cluster started when neither `scheduler` nor
            `client` is given (one single-threaded worker process each; default: the
            number of cores).
        client: an existing `distributed.Client` to use (it is not closed).
        overwrite: replace an existing store at `out` and start afresh: only a store gnipy
            created, holding nothing else at its top level.
        max_chunks: compute at most this many chunks and stop (the store stays
            resumable): for runs under a time limit, and to test resumption.
        progress: True: a progress bar (chunks done, members/s) on stderr when it is a
            terminal; False: none; a callable: called as `progress(chunks_done, chunks_total)`
            after each chunk (and with a third argument, what runs, when that changes).
        max_bytes: the largest estimated store size (bytes, uncompressed) accepted when a
            store is created; default :data:`DEFAULT_MAX_BYTES` (100 GiB); None: no bound.
            (The free space of the file system, and this machine's memory for one chunk,
            are checked whatever it is.)
        connect_timeout: seconds to wait for the connection to `scheduler` (default 10).

    Returns:
        A :class:`SweepReport`.

    Running the same sweep again on an existing store resumes it: the chunks done are read
    back and their checksums compared; the intact ones are skipped, the damaged ones
    recomputed (with a :class:`SweepWarning`). If the store holds a different sweep,
    :class:`SweepError` names the field that differs.

    Raises:
        SweepError: bad input (the message starts with the argument: `grid:`, `out:`,
            `scheduler:`, ...), a sweep over the size bounds, a scheduler that cannot be
            reached, a store whose metadata or arrays are damaged or that an earlier gnipy
            wrote, or a member whose parameters or initial condition are not acceptable.
        gnipy.InputError: bad `h`, `steps`, `t_final` or model name.
        gnipy.MethodError: a method that cannot integrate this model.
        gnipy.files.OutputError: the store cannot be created or written.
        SweepFailure: a chunk failed on the cluster (e.g. a worker died), or the local
            cluster did not start.
    """
    check("dask", "distributed", "zarr", "xarray", "rich", extra="sweeps")  # before anything is written
    t_start = time.perf_counter()
    workers, max_chunks = _check_arguments(project_v0=project_v0, overwrite=overwrite, scheduler=scheduler,
                                           client=client, workers=workers, max_chunks=max_chunks, max_bytes=max_bytes,
                                           connect_timeout=connect_timeout, progress=progress)
    address = None if scheduler is None else scheduler_address(scheduler)
    # one writer per store: a second sweep on `out` is refused at once (files.output_lock)
    with files.output_lock(out, argument="out") if isinstance(out, (str, os.PathLike)) else contextlib.nullcontext():
        path, mode = check_out(out, overwrite)
        creating = mode != "resume"
        plan = _plan.make_plan(
            model, grid, method=method, h=h, steps=steps, t_final=t_final, save_every=save_every,
            set_params=set_params, project_v0=project_v0, chunk_size=chunk_size,
            max_bytes=max_bytes if creating else None,
            disk=(path.parent if str(path.parent) else Path(".")) if creating else None,
        )
        # temporaries of runs killed while creating or replacing this store
        files.clean_stale_temporaries(path)
        todo, skipped, repaired = _chunks_to_do(path, plan, creating, max_chunks)
        computed = members = 0
        if todo:
            with _Progress(progress, plan.chunks, skipped) as bar:
                bar.describe(f"sweep {plan.spec['model']}: starting the cluster")
                with Cluster(client, address, workers or default_workers(), connect_timeout, scheduler) as c:
                    if creating:
                        create_store(path, plan, mode)
                    computed, members = _compute(path, plan, todo, c, bar)
        return _report(path, plan, t_start, computed=computed, skipped=skipped, repaired=repaired, members=members)


def _check_arguments(*, project_v0, overwrite, scheduler, client, workers, max_chunks, max_bytes, connect_timeout,
                     progress) -> tuple[int | None, int | None]:
    """Check the arguments of :func:`run_sweep` that say how it runs (each error names its
    argument); returns `(workers, max_chunks)` checked."""
    for name, value in (("project_v0", project_v0), ("overwrite", overwrite)):
        if not isinstance(value, (bool, np.bool_)):
            raise SweepError(f"{name}: expected True or False, got {value!r}")
    if scheduler is not None and client is not None:
        raise SweepError("scheduler: give either a scheduler address or a client")
    if workers is not None:
        workers = _plan.positive_int("workers", workers)
        if scheduler is not None or client is not None:
            raise SweepError("workers: sets the size of a local cluster; it cannot be used with an existing cluster")
    if max_chunks is not None:
        max_chunks = _plan.positive_int("max_chunks", max_chunks)
    if max_bytes is not None and (isinstance(max_bytes, bool) or not isinstance(
            max_bytes, (int, float, np.integer, np.floating)) or not max_bytes > 0):
        raise SweepError(f"max_bytes: must be a positive number of bytes or None, got {max_bytes!r}")
    if (isinstance(connect_timeout, bool) or not isinstance(connect_timeout, (int, float))
            or not (math.isfinite(connect_timeout) and connect_timeout > 0)):
        raise SweepError(f"connect_timeout: must be a positive number of seconds, got {connect_timeout!r}")
    if not (isinstance(progress, bool) or callable(progress)):
        raise SweepError(f"progress: expected True, False or a callable, got {progress!r}")
    return workers, max_chunks


def _chunks_to_do(path: Path, plan, creating: bool, max_chunks: int | None) -> tuple[list[int], int, int]:
    """`(todo, skipped, repaired)`: the chunks to compute in this run (at most `max_chunks`), the
    chunks found done and intact in the store, and those flagged done but damaged."""
    repaired = 0
    if creating:
        done = np.zeros(plan.chunks, dtype=bool)
    else:
        done, repaired = resume(path, plan)
    todo = [int(i) for i in np.flatnonzero(~done)]
    skipped = plan.chunks - len(todo)
    if max_chunks is not None:
        todo = todo[:max_chunks]
    return todo, skipped, repaired


def _report(path: Path, plan, t_start: float, *, computed: int, skipped: int, repaired: int,
            members: int) -> SweepReport:
    """The :class:`SweepReport` of a run, read from the store; warns when members went
    qualitatively wrong."""
    group, _ = open_group(path, "out")
    arrays = {k: group[k] for k in ("chunk_done", "result", "failed_step", "failed_time", "failed_residual",
                                    "healthy")}
    done = read_done("out", path, arrays, plan.chunks)
    failed, failures = _failures(arrays, plan, done)
    unhealthy = int(np.sum(~np.asarray(arrays["healthy"][...]).reshape(-1).astype(bool)
                           & (np.asarray(arrays["result"][...]).reshape(-1) == 0)
                           & plan.layout.member_mask(done).reshape(-1)))
    if unhealthy:
        warnings.warn(QualitativeFailureWarning(
            f"sweep of {plan.spec['model']} with {plan.spec['method']}: {unhealthy} of {plan.members} members "
            "converged but went QUALITATIVELY WRONG (a verdict left its band; see the store's variables "
            f"healthy, hidden_momentum_first_time and energy_drift_first_time in {path})"), stacklevel=3)
    return SweepReport(
        path=path,
        members=plan.members,
        chunks=plan.chunks,
        chunks_computed=computed,
        chunks_skipped=skipped,
        chunks_remaining=int(np.sum(~done)),
        failed_members=failed,
        wall_time=time.perf_counter() - t_start,
        members_computed=members,
        steps=plan.spec["steps"],
        chunk_size=plan.chunk,
        spec=plan.spec,
        chunks_repaired=repaired,
        failures=failures,
        unhealthy_members=unhealthy,
    )


def _failures(arrays, plan, done: np.ndarray):
    """`(count, first)`: the failed members of the done chunks and the first few of them."""
    result = np.asarray(arrays["result"][...]).reshape(-1)
    failed = np.flatnonzero((result != 0) & plan.layout.member_mask(done).reshape(-1))
    first = failed[:_FAILURES_LISTED]
    out = []
    if len(first):
        cols = grid_columns(plan.axes, first)
        where = np.unravel_index(first, plan.layout.shape)
        fields = {k: np.asarray(arrays[f"failed_{k}"].get_coordinate_selection(where))
                  for k in ("step", "time", "residual")}
        for j, m in enumerate(first):
            out.append({
                "member": int(m),
                "grid": {name: float(v[j]) for name, v in cols.items()},
                "step": int(fields["step"][j]),
                "time": float(fields["time"][j]),
                "residual": float(fields["residual"][j]),
            })
    return int(len(failed)), tuple(out)


def _compute(path, plan, todo, c, bar: _Progress) -> tuple[int, int]:
    """Submit the chunks `todo` to the client `c`, write each as it completes; returns
    `(chunks, members)` computed."""
    require("distributed", extra="sweeps")
    from distributed import as_completed

    from ..integrators.base import MethodError

    name = f"sweep {plan.spec['model']}"
    computed = members_done = 0
    bar.describe(f"{name}: compiling")
    token = uuid.uuid4().hex[:8]
    futures = {}
    for i in todo:
        a, b = plan.member_range(i)
        f = c.submit(run_chunk, plan.spec, a, plan.columns(i), b - a, key=f"gnipy-sweep-{token}-chunk-{i}",
                     pure=False)
        futures[f] = i
    # (time, members) at the first completed chunk: the rate is measured from there, after the compilation
    first = None
    try:
        for f in as_completed(list(futures), loop=c.loop):
            i = futures[f]
            try:
                result = f.result()
            except (InputError, MethodError):
                raise  # bad input (a member's parameters, the method)
            except Exception as e:  # noqa: BLE001 - a worker died, ...
                a, b = plan.member_range(i)
                raise SweepFailure(f"chunk {i} (members {a}..{b - 1}) failed on the cluster: "
                                   f"{type(e).__name__}: {e}") from e
            try:
                write_chunk(path, plan, i, result)
            except OSError as e:
                raise files.OutputError(f"cannot write chunk {i} to {str(path)!r}: {e.strerror or e}") from None
            del futures[f]
            f.release()
            computed += 1
            a, b = plan.member_range(i)
            members_done += b - a
            now = time.perf_counter()
            rate = None
            if first is None:
                first = (now, members_done)
                bar.describe(name)
            elif now > first[0]:
                rate = f"{(members_done - first[1]) / (now - first[0]):,.0f} members/s"
            bar.advance(rate)
    finally:
        for f in futures:
            f.cancel()
    return computed, members_done
