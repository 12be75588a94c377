"""The result of a simulation: saved nodes, diagnostics and solver statistics."""

from __future__ import annotations

import datetime as _dt
from typing import Any

import equinox as eqx
import jax
import numpy as np

__all__ = ["Solution", "SolverFailure", "RESULT_SUCCESS", "RESULT_SOLVER_FAILED"]

RESULT_SUCCESS = 0
RESULT_SOLVER_FAILED = 1


class SolverFailure(RuntimeError):
    """An implicit step did not converge or produced a non-finite value.

    Attributes: `step` (index of the failed step), `time`, `residual`, and `solution` (the
    solution up to the last good saved node).
    """

    def __init__(self, message: str, *, step: int, time: float, residual: float, solution=None):
        super().__init__(message)
        self.step = step
        self.time = time
        self.residual = residual
        self.solution = solution


class Solution(eqx.Module):
    """Saved nodes of a trajectory and their diagnostics.

    Attributes:
        t: times, shape (T,).
        q: coordinates, (T, n) (the Euclidean part x on $\\mathbb{R}^n \\times G$).
        v: reported velocities, (T, n) (for the GNI $\\bar v = \\mathbb{G}^{-1}\\bar p$, DESIGN §2).
        p: reported momenta, (T, n).
        energy: $\\tfrac12 v^T\\mathbb{G}v + V$, (T,).
        constraint_residual: $\\mu(q)(v - Y(q))$, (T, m).
        iterations: total and maximum Newton iterations per step, `(total, max)`.
        R: orientations $R_k$ on $\\mathbb{R}^n \\times G$, (T, k, k) (reconstructed
            $R_{k+1} = R_k\\tau(h\\xi_k)$, paper §7.2 Remark), else None.
        result: 0 on success, 1 if a step failed (then the arrays stop at the last good node).
        failed_step: index of the first failed step, or -1.
        system, method, h, coordinates: metadata.
    """

    t: jax.Array
    q: jax.Array
    v: jax.Array
    p: jax.Array
    energy: jax.Array
    constraint_residual: jax.Array
    iterations: jax.Array
    R: jax.Array | None = None
    result: int = eqx.field(static=True, default=RESULT_SUCCESS)
    failed_step: int = eqx.field(static=True, default=-1)
    system: str = eqx.field(static=True, default="system")
    method: str = eqx.field(static=True, default="method")
    h: float = eqx.field(static=True, default=float("nan"))
    coordinates: tuple[str, ...] = eqx.field(static=True, default=())
    velocities: tuple[str, ...] = eqx.field(static=True, default=())
    params: tuple[tuple[str, float], ...] = eqx.field(static=True, default=())
    start: str = eqx.field(static=True, default="p+ = G v0")

    @property
    def steps(self) -> int:
        """Number of steps from the first to the last saved node."""
        if np.isnan(self.h) or self.h <= 0:
            return len(self.t) - 1
        return int(round((float(self.t[-1]) - float(self.t[0])) / self.h))

    def to_xarray(self, attrs: dict[str, Any] | None = None):
        """An `xarray.Dataset` with variables `t(time)`, `q(time, coordinate)`,
        `v(time, velocity)`, `p(time, velocity)`, `energy(time)` and
        `constraint_residual(time, constraint)`, plus provenance attributes."""
        import xarray as xr

        from . import __version__

        n = self.q.shape[-1]
        coords = list(self.coordinates) if len(self.coordinates) == n else [f"q{i}" for i in range(n)]
        N = self.v.shape[-1]
        vel = list(self.velocities) if len(self.velocities) == N else [f"v{i}" for i in range(N)]
        m = self.constraint_residual.shape[-1]
        ds = xr.Dataset(
            {
                "t": (("time",), np.asarray(self.t), {"long_name": "time"}),
                "q": (("time", "coordinate"), np.asarray(self.q), {"long_name": "configuration"}),
                "v": (("time", "velocity"), np.asarray(self.v), {"long_name": "reported velocity"}),
                "p": (("time", "velocity"), np.asarray(self.p), {"long_name": "reported momentum"}),
                "energy": (("time",), np.asarray(self.energy), {"long_name": "energy ½vᵀGv + V"}),
                "constraint_residual": (
                    ("time", "constraint"),
                    np.asarray(self.constraint_residual),
                    {"long_name": "constraint residual mu(q)(v - Y(q))"},
                ),
            },
            coords={
                "time": np.arange(len(self.t)),
                "coordinate": coords,
                "velocity": vel,
                "constraint": np.arange(m),
            },
        )
        if self.R is not None:
            ds["R"] = (("time", "i", "j"), np.asarray(self.R), {"long_name": "orientation R (group matrix)"})
        ds.attrs.update(
            {
                "gnipy_version": __version__,
                "model": self.system,
                "method": self.method,
                "h": float(self.h),
                "steps": int(self.steps),
                "start": self.start,
                "result": int(self.result),
                "newton_iterations_total": int(np.asarray(self.iterations)[0]),
                "newton_iterations_max": int(np.asarray(self.iterations)[1]),
                "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
            }
        )
        for k, v in self.params:
            ds.attrs[f"param_{k}"] = float(v)
        if attrs:
            ds.attrs.update(attrs)
        return ds

    def summary(self) -> str:
        """A short human-readable summary."""
        e = np.asarray(self.energy)
        r = np.asarray(self.constraint_residual)
        lines = [
            f"{self.system} with {self.method}: h = {self.h:g}, {self.steps} steps, t = {float(self.t[0]):g} .. {float(self.t[-1]):g}",
            f"  final q = {np.array2string(np.asarray(self.q[-1]), precision=6)}",
            f"  energy: initial {e[0]:.12g}, max |E - E0| = {np.max(np.abs(e - e[0])):.3e}",
            f"  max constraint residual = {np.max(np.abs(r)) if r.size else 0.0:.3e}",
            f"  Newton iterations: total {int(np.asarray(self.iterations)[0])}, max per step {int(np.asarray(self.iterations)[1])}",
        ]
        return "\n".join(lines)
