"""What a streamed run returns (:class:`StreamResult`), and the result of a run whose
destination is already complete, read from the file (:mod:`gnipy.streaming`)."""

from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..extras import require
from ..files import OutputError, as_output_error
from ..solution import SolverFailure

#: The global attribute of a streamed result file that holds its spec (JSON).
SPEC_ATTR = "stream_spec"
#: Nodes read or written at a time when a finished destination is summarized.
_SLICE_NODES = 65_536


@dataclass(frozen=True)
class StreamResult:
    """What :func:`simulate_to_file` did.

    Attributes:
        path: the destination file.
        complete: False when the call stopped early (`stop_after_chunks`): the destination is not
            written, the parts directory holds the chunks done so far (resume continues).
        nodes: saved nodes written.
        steps: steps computed in total (including those of earlier, interrupted runs).
        chunks: number of chunks; `chunks_resumed`: how many came from an earlier run (all of
            them when the destination was already complete).
        result: 0 on success, 1 if a step failed (the file then ends at the last good node).
        failed_step: the failed step, or -1.
        energy_error: max |E − E₀| over the saved nodes.
        constraint_residual: max |μ(v − Y)| over the saved nodes.
        iterations: total Newton iterations and the maximum per step.
        final_q, final_v: the last saved node.
        warnings: the run-time warnings (:meth:`gnipy.Solution.warnings`; the verdicts are also
            file attributes), and those about checkpoints that did not verify and were computed
            again.
        healthy: every step converged and every verdict stayed in band, at every node of the
            whole run (:attr:`gnipy.Solution.healthy`; the file's `health` attribute).
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
    healthy: bool = True


def solver_failure(method: str, failed_step: int, t0: float, h: float, residual: float, path: Path) -> SolverFailure:
    """The :class:`SolverFailure` of a streamed run whose step `failed_step` failed (`path` holds the run
    up to the last good node)."""
    return SolverFailure(
        f"{method}: step {failed_step} (t = {t0 + h * failed_step:.6g} -> {t0 + h * (failed_step + 1):.6g}) "
        f"failed: the solve did not converge or gave a non-finite value (residual {residual:.3e}); "
        f"{path} holds the run up to the last good node",
        step=failed_step, time=t0 + h * failed_step, residual=residual, solution=None,
    )


def finished_result(path: Path, spec: dict, method, system, h, t0, throw, overwrite, note) -> StreamResult | None:
    """The result of a run whose destination `path` is complete and holds `spec`; None when it
    holds another run (or is not a streamed result). A damaged one is an error, unless
    `overwrite` (then None: it is computed again)."""
    netCDF4 = require("netCDF4", extra="files")

    from ..io import verify_netcdf

    try:
        with netCDF4.Dataset(os.fspath(path), "r") as nc:
            stored = nc.__dict__.get(SPEC_ATTR)
    except Exception as e:  # noqa: BLE001
        if overwrite:
            return None
        raise OutputError(f"path: {path} exists but cannot be read as netCDF ({type(e).__name__}: {e}); it is not a "
                          "finished run to resume: pass overwrite=True to replace it") from None
    try:
        if stored is None or json.loads(str(stored)) != spec:
            return None
    except ValueError:
        return None
    try:
        ok, message = verify_netcdf(path)
    except OutputError as e:
        ok, message = False, str(e)
    if not ok:
        if overwrite:
            note(f"{path} was the finished result of this run but is damaged ({message}); computing it again")
            return None
        raise OutputError(f"path: {path} is the finished result of this run but it is DAMAGED: {message}; "
                          "rerun with overwrite=True to compute it again")
    try:
        with netCDF4.Dataset(os.fspath(path), "r") as nc:
            nc.set_auto_maskandscale(False)
            a = nc.__dict__
            n = len(nc.dimensions["time"])
            e0 = float(nc.variables["energy"][0])
            e_err, res = 0.0, 0.0
            for i in range(0, n, _SLICE_NODES):
                e = np.asarray(nc.variables["energy"][i:i + _SLICE_NODES])
                e_err = max(e_err, abs(float(e.max()) - e0), abs(float(e.min()) - e0))
                r = np.asarray(nc.variables["constraint_residual"][i:i + _SLICE_NODES])
                res = max(res, float(np.max(np.abs(r), initial=0.0)))
            final_q, final_v = np.asarray(nc.variables["q"][n - 1]), np.asarray(nc.variables["v"][n - 1])
            result = int(a.get("result", 0))
            failed = int(a.get("failed_step", -1)) if result else -1
            residual = float(a.get("failed_residual", np.nan))
            chunks = int(a.get("streamed_chunks", 0))
            iterations = (int(a.get("newton_iterations_total", 0)), int(a.get("newton_iterations_max", 0)))
            warnings = [str(a[k]) for k in ("hidden_momentum_warning", "energy_drift_warning") if k in a]
            steps = int(a["steps"]) if not result else failed
            healthy = str(a.get("health", "")) == "healthy"
    except Exception as e:  # noqa: BLE001
        raise as_output_error(e, path, "read") or OutputError(f"cannot read {path}: {type(e).__name__}: {e}") from None
    out = StreamResult(
        path=path, complete=True, nodes=n, steps=steps, chunks=chunks, chunks_resumed=chunks, result=result,
        failed_step=failed, energy_error=e_err, constraint_residual=res, iterations=iterations,
        final_q=final_q, final_v=final_v, warnings=warnings, healthy=healthy,
    )
    if result and throw:
        raise solver_failure(method.name, failed, t0, h, residual, path)
    return out


def partial_result(path, parts, c, steps, n_chunks, resumed, notes=()):
    """The :class:`StreamResult` of a run stopped before its destination was written (`complete=False`)."""
    return StreamResult(
        path=path, complete=False, nodes=0, steps=0, chunks=n_chunks, chunks_resumed=resumed, result=0, failed_step=-1,
        energy_error=float("nan"), constraint_residual=float("nan"), iterations=(0, 0),
        final_q=np.zeros(0), final_v=np.zeros(0), warnings=list(notes), healthy=False,
    )
