"""What `gni run` and `gni demo` print and store: the summary table of a run and the attributes
of its file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .output import console, safe, table, warn

__all__ = ["attrs_for", "run_report", "streamed_report"]


def _params_text(spec, params) -> str:
    return f"{spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())})"


def run_report(title: str, spec, params, sol, exact, drifts, seconds: float, out: Path | str | None,
               note: str | None = None) -> None:
    """Print the summary of an in-memory run: final state, energy, constraint residual, invariant
    drifts, errors against the exact solution (`exact`, a :class:`~gnipy.analysis.ExactErrors` or
    None), the hidden momentum, the time; then the run's warnings on stderr."""
    import numpy as np

    e = np.asarray(sol.energy)
    r = np.asarray(sol.constraint_residual)
    t = table(title=title, show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column(overflow="fold")
    t.add_row("health", sol.health)
    t.add_row("model", _params_text(spec, params))
    span = f"t = {float(sol.t[0]):g} .. {float(sol.t[-1]):g}"
    t.add_row("method", f"{sol.method}, h = {sol.h:g}, {sol.steps} steps, {span}")
    t.add_row("final q", ", ".join(f"{c} = {x:.10g}" for c, x in zip(spec.coordinates, np.asarray(sol.q[-1]))))
    vnames = sol.velocities or tuple(f"d{c}" for c in spec.coordinates)
    t.add_row("final v", ", ".join(f"{c} = {x:.10g}" for c, x in zip(vnames, np.asarray(sol.v[-1]))))
    t.add_row("energy", f"initial {e[0]:.12g}, max |E - E0| = {np.max(np.abs(e - e[0])):.3e} (at the saved nodes)")
    t.add_row("constraint residual", f"max |mu(q)(v - Y)| = {np.max(np.abs(r)) if r.size else 0.0:.3e}")
    for name, d in drifts.items():
        t.add_row(f"invariant {name}", f"max drift {d:.3e}")
    if exact is not None:
        t.add_row("error vs exact", f"max |q - q_exact| = {exact.max_error_q:.3e}, "
                  f"max |v - v_exact| = {exact.max_error_v:.3e}")
    if sol.energy_plus is not None:
        ep = np.asarray(sol.energy_plus)
        t.add_row("energy of p+", f"initial {ep[0]:.12g}, max |E+ - E+0| = {np.max(np.abs(ep - ep[0])):.3e}")
    verdict = sol.hidden_verdict
    if verdict is not None and verdict.in_band:
        t.add_row("hidden momentum", f"max |p+ - p̄|/|p̄| = {verdict.max_ratio:.3e}, in its O(h) band")
    if sol.conserved:
        t.add_row("conserved", sol.conserved)
    t.add_row("time", f"{seconds:.2f} s (including compilation)")
    if note:
        t.add_row("note", note)
    con = console()
    con.print(t)
    for warning in sol.warnings():  # the run-time diagnostics (gnipy.diagnostics): never silent
        warn(warning)
    if out is not None:
        con.print(f"written: {safe(out)}", markup=False)


def streamed_report(spec, params, method: str, h, result, seconds: float, out) -> None:
    """Print the summary of a streamed run (`result`: what :func:`gnipy.streaming.simulate_to_file`
    returns) and its warnings."""
    import numpy as np

    t = table(title="gni run (streamed)", show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column(overflow="fold")
    health = ("healthy: every step converged, every verdict in band (every node checked)" if result.healthy
              else "FAILED: a step did not converge" if result.result else "QUALITATIVELY WRONG (see the warnings)")
    t.add_row("health", health)
    t.add_row("model", _params_text(spec, params))
    t.add_row("method", f"{method}, h = {float(h):g}, {result.steps} steps, {result.nodes} saved nodes, "
              f"{result.chunks} chunks ({result.chunks_resumed} from an earlier run)")
    t.add_row("final q", ", ".join(f"{c} = {x:.10g}" for c, x in zip(spec.coordinates, np.asarray(result.final_q))))
    t.add_row("energy", f"max |E - E0| = {result.energy_error:.3e}")
    t.add_row("constraint residual", f"max |mu(q)(v - Y)| = {result.constraint_residual:.3e}")
    t.add_row("time", f"{seconds:.2f} s (including compilation)")
    con = console()
    con.print(t)
    for warning in result.warnings:  # the run-time diagnostics, as for in-memory runs
        warn(warning)
    con.print(f"written: {safe(out)}", markup=False)


def origin_attrs(spec) -> dict[str, str]:
    """For a user's system (:func:`gnipy.registry.model_from_function`), the file attributes
    `model_reference` (how to rebuild it) and `model_source_sha256`; none for a zoo model."""
    if spec.origin is None:
        return {}
    return {"model_reference": spec.origin[0], "model_source_sha256": spec.origin[1] or ""}


def attrs_for(spec, params, sol, q0, v0, exact, drifts, extra: dict[str, Any]) -> dict[str, Any]:
    """The attributes `gni run` adds to a result file: the initial condition, the coordinates, the
    invariant drifts and the errors against the exact solution, and `extra`."""
    attrs: dict[str, Any] = {
        "q0": list(q0),
        "v0": list(v0),
        "coordinates": ",".join(spec.coordinates),
        "t_final": float(sol.t[-1]),
        **extra,
    }
    attrs.update(origin_attrs(spec))
    for name, d in drifts.items():
        attrs[f"invariant_drift_{name}"] = d
    if exact is not None:
        attrs["max_error_q_vs_exact"] = exact.max_error_q
        attrs["max_error_v_vs_exact"] = exact.max_error_v
    return attrs
