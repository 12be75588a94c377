"""The task of a sweep: one chunk of members simulated as one vmapped program, on a worker."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import InputError, QualitativeFailureWarning
from .errors import SweepError
from .grid import describe_member

__all__ = ["run_chunk"]


def member_inputs(job: Mapping[str, Any], columns: Mapping[str, np.ndarray], size: int):
    """`(systems, q0, v0, R0)` for `size` members: a list of Systems when parameters
    vary (else one System), q0 (size, n), v0 (size, N), R0 (k, k) or None."""
    from ..ensembles import model_systems
    from ..models import get_model

    spec = get_model(job["model"])
    if spec.origin is not None and job.get("model_source") != spec.origin[1]:
        raise SweepError(f"model: {job['model']!r} changed since the sweep was planned (its source's SHA-256 is "
                         f"{spec.origin[1]}, the sweep's {job.get('model_source')}); sweep again with the file "
                         "as it is now, into another output path or with overwrite=True")
    base = dict(job["params"])
    pcols = {k: np.asarray(v, dtype=np.float64) for k, v in columns.items() if not k.startswith(("q0.", "v0."))}
    if pcols:
        systems = model_systems(spec, **base, **pcols)  # the spec checked above: not loaded again
        first = systems[0]
    else:
        systems = first = spec.build(dict(spec.params) | base)
    coordinates, velocities = list(spec.coordinates), list(first.velocities)
    n, N = len(coordinates), len(velocities)
    if pcols and spec.default_ic is not None:
        # the default initial condition depends on the parameters: one per member
        ics = [spec.initial_condition(base | {k: float(v[i]) for k, v in pcols.items()}) for i in range(size)]
        q0 = np.array([q for q, _ in ics], dtype=np.float64).reshape(size, n)
        v0 = np.array([v for _, v in ics], dtype=np.float64).reshape(size, N)
    else:
        q, v = spec.initial_condition(dict(spec.params) | base)
        q0 = np.tile(np.asarray(q, dtype=np.float64).reshape(1, n), (size, 1))
        v0 = np.tile(np.asarray(v, dtype=np.float64).reshape(1, N), (size, 1))
    for k, col in columns.items():
        if k.startswith("q0."):
            q0[:, coordinates.index(k[3:])] = col
        elif k.startswith("v0."):
            v0[:, velocities.index(k[3:])] = col
    R0 = None
    if first.group is not None and spec.R0 is not None:
        kk = first.group.matrix_size
        R0 = np.asarray(spec.R0, dtype=np.float64).reshape(kk, kk)
    return systems, q0, v0, R0


def check_member(system, sweep_spec, columns, i, member, q0, v0, R0):
    """System.check for one member (the velocity only when it is not to be projected:
    a projection always succeeds once the metric and the constraints pass)."""
    project = sweep_spec["project_v0"]
    try:
        b0, _ = system.check(q0[i], None if project else v0[i], R0=R0)
    except InputError as e:
        msg = str(e).replace("pass project_v0=True to project it", "sweep with project_v0=True to project it")
        raise SweepError(f"grid: member {member} ({describe_member(columns, i)}): {msg}") from None
    return b0


def run_chunk(job: Mapping[str, Any], first: int, columns: Mapping[str, np.ndarray], size: int
              ) -> dict[str, np.ndarray]:
    """Simulate one chunk of a sweep: the task :func:`gnipy.sweep.run_sweep` sends to the workers.

    Arguments:
        job: the sweep's specification (the `sweep_spec` of the store: model, method, h,
            steps, save_every, params, project_v0, ...).
        first: the index of the chunk's first member in the sweep (for error messages).
        columns: each grid axis's value for every member of the chunk, name -> (B,)
            arrays; B is the chunk size (the last chunk of a row is padded by repeating its last
            member).
        size: the number of real members (the first `size` of the B); the others are
            dropped.

    Returns:
        numpy arrays with a leading member axis of length `size`: `q, v, p, energy,
        constraint_residual, valid, result, failed_step, failed_time, failed_residual`, the
        verdicts of :func:`member_verdicts`, and `R` on Rⁿ × G. A failed member's `q, v, p, energy, constraint_residual, R` are
        NaN after its last good node (where `valid` is False); `failed_time` is the time
        at the start of its failed step and `failed_residual` the residual of the failed
        solve (both NaN for a member that did not fail, and the residual NaN when the
        simulation does not report it).

    Raises:
        SweepError: a member whose parameters or initial condition are not acceptable
            (named by its index in the sweep and its grid values).
    """
    from ..compilation import cache_requested, enable_compilation_cache
    from ..simulate import simulate

    if cache_requested():  # opt-in (see gnipy.compilation): reuse programs compiled by earlier runs
        enable_compilation_cache()
    B = len(next(iter(columns.values())))
    systems, q0, v0, R0 = member_inputs(job, columns, B)
    try:
        with warnings.catch_warnings():  # the sweep says how many members went wrong, once (its report)
            warnings.simplefilter("ignore", QualitativeFailureWarning)
            sol = simulate(systems, job["method"], q0, v0, R0=R0, h=job["h"], steps=job["steps"],
                           save_every=job["save_every"], project_v0=job["project_v0"], throw=False,
                           check_every_node=True)
    except InputError:
        # name the member at fault: check them one by one (only on this error path)
        for i in range(B):
            s = systems[i] if isinstance(systems, list) else systems
            check_member(s, job, columns, i, first + min(i, size - 1), q0, v0, R0)
        raise
    valid = np.asarray(sol.valid, dtype=bool)
    failed_steps = np.asarray(sol.failed_steps, dtype=np.int64)
    failed = failed_steps >= 0

    def blank(a):
        """NaN where the member's node is not valid (after its failed step)."""
        a = np.array(a, dtype=np.float64)
        return np.where(valid.reshape(valid.shape + (1,) * (a.ndim - 2)), a, np.nan)

    # the residual of each member's failed solve, where the simulation reports it
    residuals = getattr(sol, "failed_residuals", None)
    residuals = np.full(B, np.nan) if residuals is None else np.asarray(residuals, dtype=np.float64).reshape(B)
    out = {
        "q": blank(sol.q),
        "v": blank(sol.v),
        "p": blank(sol.p),
        "energy": blank(sol.energy),
        "constraint_residual": blank(sol.constraint_residual),
        "valid": valid,
        "result": np.asarray(sol.results),
        "failed_step": failed_steps.astype(np.int32),
        "failed_time": np.where(failed, float(job["h"]) * failed_steps, np.nan),
        "failed_residual": np.where(failed, residuals, np.nan),
    }
    if sol.R is not None:
        out["R"] = blank(sol.R)
    out["native"] = np.full(B, sol.backend == "native")
    out.update(member_verdicts(sol, B))
    return {k: np.asarray(v)[:size] for k, v in out.items()}


def member_verdicts(sol, B: int) -> dict[str, np.ndarray]:
    """Each member's verdicts from every node of its run (:mod:`gnipy.monitor`): `healthy`, the
    times a verdict left its band (NaN: never) and the largest ratios (NaN: not diagnosed)."""
    from .. import monitor

    rows = np.asarray(sol.monitor, dtype=np.float64).reshape(B, monitor.SIZE)
    gni = sol.hidden_momentum is not None
    hidden = [monitor.hidden_verdict(r) if gni else None for r in rows]
    energy = [monitor.energy_verdict(r) for r in rows]

    def field(verdicts, name):
        return np.array([np.nan if v is None or getattr(v, name) is None else getattr(v, name) for v in verdicts],
                        dtype=np.float64)

    converged = np.asarray(sol.results).reshape(B) == 0
    in_band = np.array([all(v is None or v.in_band for v in pair) for pair in zip(hidden, energy)], dtype=bool)
    return {"healthy": converged & in_band,
            "hidden_momentum_first_time": field(hidden, "first_time"),
            "hidden_momentum_max_band_ratio": field(hidden, "max_band_ratio"),
            "energy_drift_first_time": field(energy, "first_time"),
            "energy_drift_max": field(energy, "max_drift")}
