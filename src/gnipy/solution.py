"""The result of a simulation: saved nodes, diagnostics and solver statistics."""

from __future__ import annotations

import dataclasses
import datetime as _dt
import enum
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .extras import require
from .errors import SolverFailure
from .monitor import verdicts_out

__all__ = ["Solution", "SolverFailure", "RESULTS", "RESULT_SUCCESS", "RESULT_SOLVER_FAILED", "set_variable_attrs"]


class RESULTS(enum.IntEnum):
    """How a run ended (diffrax's `RESULTS`, scipy's `status`): the integer stored as
    `Solution.result` and in files, with a readable :attr:`message`.

    - `successful` (0): every step converged.
    - `solve_failed` (1): a step's implicit solve did not converge or gave a non-finite value;
      the solution stops at the last good saved node.
    """

    successful = 0
    solve_failed = 1

    @property
    def message(self) -> str:
        """What the code means, in words."""
        return _MESSAGES[self]


_MESSAGES = {
    RESULTS.successful: "every step converged",
    RESULTS.solve_failed: "the solve did not converge or gave a non-finite value",
}

RESULT_SUCCESS = int(RESULTS.successful)
RESULT_SOLVER_FAILED = int(RESULTS.solve_failed)



def set_variable_attrs(ds) -> None:
    """Give the variables of a result dataset their attributes, in place: `long_name` and `units`
    as :mod:`gnipy.schema` states them (where not set already), and on `q`, `v`, `p` the names
    of their components (attribute `components`, from the `coordinate` and `velocity` coordinates).
    (:func:`gnipy.schema.apply`.)"""
    from . import schema

    schema.apply(ds)


class Solution(eqx.Module):
    """Saved nodes of a trajectory and their diagnostics.

    Attributes:
        t: times, shape (T,).
        q: coordinates, (T, n) (the Euclidean part x on $\\mathbb{R}^n \\times G$).
        v: reported velocities, (T, n) (for the GNI $\\bar v = \\mathbb{G}^{-1}\\bar p$, see docs/conventions.md).
        p: reported momenta, (T, n).
        energy: $\\tfrac12 v^T\\mathbb{G}v + V$, (T,).
        constraint_residual: $\\mu(q)(v - Y(q))$, then $\\varphi(q)$ (:meth:`gnipy.System.constraint_residual`).
        iterations: total and maximum Newton iterations per step, `(total, max)`.
        R: orientations $R_k$ on $\\mathbb{R}^n \\times G$, (T, k, k) (reconstructed
            $R_{k+1} = R_k\\tau(h\\xi_k)$, paper §7.2 Remark, or $\\tau(h\\xi_k)R_k$ for a system with
            `reconstruction="right"`; :attr:`orientation` says which), else None.
        result: how the run ended, a :class:`RESULTS` code (an int: 0 on success, 1 if a step failed;
            then the arrays stop at the last good node; in a batch: 1 if any member failed).
            :attr:`success` and :attr:`message` say it in words.
        failed_step: index of the first failed step, or -1 (in a batch: the earliest).
        failed_residual: the residual of the failed step's solve (NaN when no step failed).
        results, failed_steps, failed_residuals: in a batch, each member's result code, failed
            step (-1 if none) and the residual of its failed solve (NaN if none), (B,); None for
            a single trajectory.
        member_params: in a parameter batch, each member's parameter values, name -> (B,).
        member_iterations: in a batch, each member's total and maximum Newton iterations, (B, 2).
        final_state: the integrator's state after the last step (continue the run with
            `simulate(..., state0=sol.final_state, t0=float(sol.t[-1]))`); None for the reference.
        states: the integrator's states at the saved nodes when asked (`SaveAt(states=True)`).
        hidden_momentum: the GNI family's hidden momentum $\\|p^+ - \\bar p\\|/\\|\\bar p\\|$ (norms in
            $\\mathbb{G}^{-1}$) at each saved node, (T,); None for other methods
            (:mod:`gnipy.diagnostics`; its verdict is :attr:`hidden_verdict`).
        hidden_expected: the size it should have, $\\frac{|h|}2\\|\\mu^T\\lambda\\|/\\|\\bar p\\|$, (T,).
        energy_plus: the energy of the post-momentum, $\\tfrac12 p^{+T}\\mathbb{G}^{-1}p^+ + V$ (the
            quantity of the paper's energy theorem), (T,); None for other methods.
        conserved: which quantity the motion (or the scheme) conserves, a sentence.
        energy_invariant: whether the energy is a constant of the motion (linear constraints): then
            a drift of the reported energy is diagnosed (:attr:`energy_verdict`).
        orientation: what R is (how it was reconstructed, and whether it is a physical attitude),
            a sentence (:attr:`gnipy.System.orientation_description`); empty on $\\mathbb{R}^n$.
        backend: which compiler ran the step loop: `"xla"` or `"native"` (:mod:`gnipy.native`).
        monitor: the verdicts' running values, checked at every node of the run whatever was
            saved (:mod:`gnipy.monitor`), (S,) or (B, S); pass it as `monitor0` to continue the
            run. None where the run was not monitored (under a JAX transformation, the
            continuous reference): the verdicts then read the saved nodes.
        member_conserved: in a batch, each member's own :attr:`conserved` sentence.
        start: how the first node was set up (e.g. the GNI's consistent start
            `p+ = G v0 - (h/2) mu^T lambda0`; :attr:`gnipy.integrators.base.Integrator.start_label`).
        method_settings: the method's parameters, `(name, value)` pairs
            (:meth:`gnipy.integrators.base.Integrator.settings`): what ran beyond its name.
        system, method, h, coordinates: metadata.

    **Batches.** A solution of B trajectories (from :func:`gnipy.simulate` with batched
    initial conditions or systems) has a leading member axis on `q, v, p, energy,
    constraint_residual, R` (`t` is shared). A failed member's saved nodes after its failed
    step are NaN (never a repeated last state): read members through :meth:`member` (truncated
    at the failure) or mask with :attr:`valid`; :meth:`failures` lists them.
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
    failed_residual: float = eqx.field(static=True, default=float("nan"))
    system: str = eqx.field(static=True, default="system")
    method: str = eqx.field(static=True, default="method")
    h: float = eqx.field(static=True, default=float("nan"))
    coordinates: tuple[str, ...] = eqx.field(static=True, default=())
    velocities: tuple[str, ...] = eqx.field(static=True, default=())
    params: tuple[tuple[str, float], ...] = eqx.field(static=True, default=())
    start: str = eqx.field(static=True, default="(q0, v0) as given")
    results: jax.Array | None = None
    failed_steps: jax.Array | None = None
    failed_residuals: jax.Array | None = None
    member_params: dict | None = None
    member_iterations: jax.Array | None = None
    final_state: Any = None
    states: Any = None
    hidden_momentum: jax.Array | None = None
    hidden_expected: jax.Array | None = None
    energy_plus: jax.Array | None = None
    conserved: str = eqx.field(static=True, default="")
    orientation: str = eqx.field(static=True, default="")
    energy_invariant: bool = eqx.field(static=True, default=False)
    backend: str = eqx.field(static=True, default="xla")
    monitor: Any = None
    method_settings: tuple[tuple[str, Any], ...] = eqx.field(static=True, default=())
    member_conserved: tuple[str, ...] | None = eqx.field(static=True, default=None)

    @classmethod
    def of(cls, **fields) -> "Solution":
        """The Solution with these fields (the others at their defaults), built without equinox's
        per-field checks: what :func:`gnipy.simulate` calls on every run (equinox's constructor
        costs about 0.1 ms, a fifth of a repeated call's overhead, measured). Same result as
        `Solution(**fields)`."""
        sol = object.__new__(cls)
        for f in _FIELDS:
            object.__setattr__(sol, f.name, fields.pop(f.name) if f.name in fields else f.default)
        if fields:
            raise TypeError(f"Solution.of: unknown fields {sorted(fields)}")
        return sol

    @property
    def energy_verdict(self):
        """The :class:`~gnipy.diagnostics.EnergyVerdict` where the energy is a constant of the motion
        (None otherwise, and for a batch: read it per member). From every node of the run when it
        was monitored (:attr:`monitor`), else from the saved nodes."""
        from .diagnostics import energy_verdict

        if self.batch_size is not None:
            return None
        if self.monitor is not None:
            from .monitor import energy_verdict as from_monitor

            return from_monitor(self.monitor)
        if not self.energy_invariant:
            return None
        with np.errstate(over="ignore", invalid="ignore"):  # a run that blew up: inf/NaN nodes
            kinetic = 0.5 * np.sum(np.asarray(self.v) * np.asarray(self.p), axis=-1)
        return energy_verdict(self.t, self.energy, kinetic)

    @property
    def hidden_verdict(self):
        """The :class:`~gnipy.diagnostics.HiddenMomentumVerdict` of a GNI-family run (None for other
        methods; for a batch, read it per member: ``sol.member(i).hidden_verdict``). From every
        node of the run when it was monitored (:attr:`monitor`), else from the saved nodes."""
        from .diagnostics import hidden_momentum_verdict

        if self.hidden_momentum is None or self.batch_size is not None:
            return None
        if self.monitor is not None:
            from .monitor import hidden_verdict

            return hidden_verdict(self.monitor, self.t)
        return hidden_momentum_verdict(self.t, self.hidden_momentum, self.hidden_expected, self.h)

    @property
    def success(self) -> bool:
        """Whether every step converged (in a batch: of every member)."""
        return int(self.result) == RESULT_SUCCESS

    @property
    def message(self) -> str:
        """How the run ended, in words (with the failed step and time when one failed)."""
        code = RESULTS(int(self.result))
        if code == RESULTS.successful:
            return code.message
        fails = self.failures()
        if not fails:
            return code.message
        f = fails[0]
        who = "" if f["member"] is None else f"member {f['member']}: "
        more = f" ({len(fails)} members failed)" if len(fails) > 1 else ""
        return f"{who}step {f['step']} (t = {f['time']:.6g}) failed: {code.message} (residual {f['residual']:.3e}){more}"

    @property
    def batch_size(self) -> int | None:
        """The number of members of a batch, or None for a single trajectory."""
        return None if self.results is None else int(np.shape(self.results)[0])

    @property
    def valid(self):
        """Which saved nodes are computed, (T,) or (B, T): False after a member's failed step."""
        k = np.rint((np.asarray(self.t) - float(self.t[0])) / self.h).astype(np.int64) if self.h > 0 else None
        if self.results is None:
            return np.ones(len(self.t), dtype=bool)
        fs = np.asarray(self.failed_steps)
        return (fs[:, None] < 0) | (k[None, :] <= fs[:, None])

    def member(self, i: int) -> "Solution":
        """The i-th trajectory of a batch as a Solution (stopping at its last good node if it failed)."""
        B = self.batch_size
        if B is None:
            raise ValueError("member: this solution is a single trajectory, not a batch")
        if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not -B <= i < B:
            raise IndexError(f"member: index {i!r} out of range for a batch of {B}")
        i = int(i) % B
        good = int(np.sum(self.valid[i]))
        params = self.params
        if self.member_params is not None:
            params = tuple((k, float(np.asarray(v)[i])) for k, v in self.member_params.items())
        fs = int(np.asarray(self.failed_steps)[i])
        its = self.iterations if self.member_iterations is None else self.member_iterations[i]
        fr = float("nan") if self.failed_residuals is None else float(np.asarray(self.failed_residuals)[i])

        def row(a):
            return None if a is None else a[i, :good]

        conserved = self.conserved if self.member_conserved is None else self.member_conserved[i]
        watch = None if self.monitor is None else np.asarray(self.monitor)[i]
        invariant = self.energy_invariant
        if watch is not None:
            from .monitor import energy_verdict as from_monitor

            invariant = from_monitor(watch) is not None
        return Solution(
            self.t[:good], self.q[i, :good], self.v[i, :good], self.p[i, :good], self.energy[i, :good],
            self.constraint_residual[i, :good], its,
            R=row(self.R),
            result=int(np.asarray(self.results)[i]), failed_step=fs, failed_residual=fr, system=self.system,
            method=self.method,
            h=self.h, coordinates=self.coordinates, velocities=self.velocities, params=params, start=self.start,
            method_settings=self.method_settings,
            hidden_momentum=row(self.hidden_momentum), hidden_expected=row(self.hidden_expected),
            energy_plus=row(self.energy_plus), conserved=conserved,
            orientation=self.orientation, energy_invariant=invariant, backend=self.backend, monitor=watch,
        )

    def failures(self) -> list[dict[str, Any]]:
        """The failed steps: one dict per failed member (a single trajectory: at most one) with
        `member` (None for a single trajectory), `step`, `time` (the failed step's start) and
        `residual` (of its solve)."""
        t0 = float(self.t[0]) if len(self.t) else 0.0
        if self.batch_size is None:
            if self.failed_step < 0:
                return []
            return [dict(member=None, step=self.failed_step, time=t0 + self.h * self.failed_step,
                         residual=self.failed_residual)]
        fs = np.asarray(self.failed_steps)
        fr = np.full(fs.shape, np.nan) if self.failed_residuals is None else np.asarray(self.failed_residuals)
        return [dict(member=int(i), step=int(fs[i]), time=t0 + self.h * int(fs[i]), residual=float(fr[i]))
                for i in np.flatnonzero(fs >= 0)]

    @property
    def steps(self) -> int:
        """Number of steps from the first to the last saved node."""
        if np.isnan(self.h) or self.h == 0:
            return len(self.t) - 1
        return int(round((float(self.t[-1]) - float(self.t[0])) / self.h))

    def to_xarray(self, attrs: dict[str, Any] | None = None):
        """An `xarray.Dataset` with the coordinate `time` (the times $t_k$, CF attributes), beside it
        `node(time)` (the saved-node index) and `step(time)` (the step index k), the variables
        `q(time, coordinate)`, `v(time, velocity)`, `p(time, velocity)`, `energy(time)`,
        `constraint_residual(time, constraint)` (and `R(time, i, j)`, the GNI diagnostics), and
        CF and provenance attributes (:mod:`gnipy.io`). A batch has a leading `member` axis. The
        dimensions and the variables' attributes are those :mod:`gnipy.schema` states."""
        xr = require("xarray", extra="files")

        from . import schema

        lead = () if self.batch_size is None else ("member",)
        n, N, m = self.q.shape[-1], self.v.shape[-1], self.constraint_residual.shape[-1]
        coords = list(self.coordinates) if len(self.coordinates) == n else [f"q{i}" for i in range(n)]
        vel = list(self.velocities) if len(self.velocities) == N else [f"v{i}" for i in range(N)]
        names = ("q", "v", "p", "energy", "constraint_residual", *(("R",) if self.R is not None else ()))
        ds = xr.Dataset(
            {name: (schema.dims(name, lead), np.asarray(getattr(self, name))) for name in names},
            coords={**self._time_coords(), "coordinate": coords, "velocity": vel, "constraint": np.arange(m)},
        )
        if self.batch_size is not None:
            ds = self._batch_to_xarray(ds)
        return self._with_attrs(self._add_diagnostics(ds, lead), attrs)

    def _time_coords(self) -> dict:
        """`time` (the times), `node` and `step` (:func:`gnipy.schema.time_coordinates`)."""
        from .schema import time_coordinates

        return time_coordinates(np.asarray(self.t), self.h)

    def _add_diagnostics(self, ds, lead: tuple[str, ...] = ()):
        """The GNI family's diagnostics as variables, after the `lead` dimensions (their
        attributes: :func:`set_variable_attrs`); returns `ds`."""
        from . import schema

        if self.energy_plus is not None:
            for name, a in (("energy_plus", self.energy_plus), ("hidden_momentum", self.hidden_momentum),
                            ("hidden_momentum_expected", self.hidden_expected)):
                ds[name] = (schema.dims(name, lead), np.asarray(a))
        return ds

    def _batch_to_xarray(self, ds):
        """`ds` (the batch's saved nodes, along `member`) with the `member` coordinate and how each
        member's run ended: `result`, `failed_step`, `failed_residual`, `valid`, and the
        per-member parameters `param_NAME`."""
        from . import schema

        lead = ("member",)
        ds = ds.assign_coords(member=np.arange(self.batch_size))
        residuals = (np.full(self.batch_size, np.nan) if self.failed_residuals is None
                     else np.asarray(self.failed_residuals, dtype=np.float64))
        for name, a in (("result", self.results), ("failed_step", self.failed_steps),
                        ("failed_residual", residuals), ("valid", self.valid)):
            ds[name] = (schema.dims(name, lead), np.asarray(a))
        for k, v in (self.member_params or {}).items():
            ds[f"param_{k}"] = (lead, np.asarray(v), schema.param_attrs(k))
        return ds

    def _with_attrs(self, ds, attrs):
        """The variables' attributes, the global CF and provenance attributes of a result dataset
        (and the caller's `attrs`)."""
        from .version import __version__
        from .file_attributes import cf_attributes

        set_variable_attrs(ds)
        created = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
        ds.attrs.update(cf_attributes(self.system, self.method, created=created))
        ds.attrs.update(
            {
                "gnipy_version": __version__, "model": self.system, "method": self.method, "h": float(self.h),
                "steps": int(self.steps), "start": self.start, "result": int(self.result), "backend": self.backend,
                "newton_iterations_total": int(np.asarray(self.iterations)[0]),
                "newton_iterations_max": int(np.asarray(self.iterations)[1]),
                "created": created,
            }
        )
        if self.batch_size is None and self.failed_step >= 0:
            ds.attrs.update(failed_step=int(self.failed_step), failed_residual=float(self.failed_residual),
                            failed_time=float(self.t[0]) + self.h * self.failed_step if len(self.t) else float("nan"))
        for k, v in self.params:
            ds.attrs[f"param_{k}"] = float(v)
        if self.conserved:
            ds.attrs["conserved"] = self.conserved
        if self.method_settings:
            import json

            ds.attrs["method_settings"] = json.dumps(dict(self.method_settings), sort_keys=True)
        if self.R is not None and self.orientation:
            ds.attrs["orientation"] = self.orientation
        ds.attrs.update(self._verdict_attrs())
        if attrs:
            ds.attrs.update(attrs)
        return ds

    def _verdict_attrs(self) -> dict:
        """The verdicts as file attributes."""
        attrs = {}
        for kind, prefix, largest in (("hidden", "hidden_momentum", "max_ratio"), ("energy", "energy_drift", "max_drift")):
            verdicts, out, first = verdicts_out(self, kind)
            if not verdicts:
                continue
            attrs[f"{prefix}_verdict"] = "in band" if not out else "out of band"
            attrs[f"{prefix}_max"] = max(getattr(v, largest) for v in verdicts.values())
            if out:
                attrs[f"{prefix}_first_time"] = verdicts[first].first_time
                attrs[f"{prefix}_warning"] = verdicts[first].warning(self.method, self.system)
                if self.batch_size is not None:
                    attrs[f"{prefix}_members_out_of_band"] = len(out)
        attrs["health"] = "healthy" if self.healthy else ("failed" if not self.success else "qualitatively wrong")
        return attrs

    @property
    def healthy(self) -> bool:
        """Whether the run can be trusted: every step converged (:attr:`success`) and every
        verdict stayed in band, at every node of the run (of every member of a batch). A run that
        converged but whose motion went qualitatively wrong is successful and not healthy; its
        :meth:`warnings` say from when and what to use instead."""
        return self.success and not any(verdicts_out(self, kind)[1] for kind in ("hidden", "energy"))

    @property
    def health(self) -> str:
        """:attr:`healthy` in words: what went wrong first, or that nothing did."""
        if not self.success:
            return f"FAILED: {self.message}"
        texts = []
        for kind, what in (("hidden", "the hidden momentum left its O(h) band"),
                           ("energy", "the conserved energy drifted out of its band")):
            verdicts, out, first = verdicts_out(self, kind)
            if out:
                who = f" (member {first}; {len(out)} of {self.batch_size} members)" if self.batch_size is not None else ""
                texts.append(f"{what} at t = {verdicts[first].first_time:.6g}{who}")
        if texts:
            return "QUALITATIVELY WRONG: " + "; ".join(texts)
        checked = "every node checked" if self.monitor is not None else "saved nodes checked"
        return f"healthy: every step converged, every verdict in band ({checked})"

    def warnings(self) -> list[str]:
        """The run-time warnings of this solution: the GNI's hidden momentum out of its O(h) band,
        and an energy that the motion conserves drifting away (:mod:`gnipy.diagnostics`)."""
        texts = []
        for kind in ("hidden", "energy"):
            verdicts, out, first = verdicts_out(self, kind)
            if not out:
                continue
            text = verdicts[first].warning(self.method, self.system)
            if self.batch_size is not None:
                text = f"{len(out)} of {self.batch_size} members (first: member {first}): " + text
            texts.append(text)
        return texts

    def _diagnostic_lines(self) -> list[str]:
        lines = []
        if self.energy_plus is not None and self.batch_size is None:
            ep = np.asarray(self.energy_plus)
            lines.append(f"  energy of p+: initial {ep[0]:.12g}, max |E+ - E+0| = {np.max(np.abs(ep - ep[0])):.3e}")
        verdicts, out, _ = verdicts_out(self, "hidden")
        if verdicts and not out:
            lines.append(f"  hidden momentum |p+ - p̄|/|p̄|: max {max(v.max_ratio for v in verdicts.values()):.3e}, "
                         "in its O(h) band")
        if self.conserved:
            lines.append(f"  conserved: {self.conserved}")
        lines.extend("  " + w for w in self.warnings())
        return lines

    def summary(self) -> str:
        """A short human-readable summary: how healthy the run is first, then what ran, its
        energy and constraints, and the warnings of :meth:`warnings`."""
        from .solution_text import summary

        return summary(self)

    def _repr_html_(self) -> str:
        """The solution as an HTML table (Jupyter): its health first, what ran, how it ended, the
        diagnostics."""
        from .solution_text import html

        return html(self)


_FIELDS = dataclasses.fields(Solution)
