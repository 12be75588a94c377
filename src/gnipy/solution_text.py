"""The text of a :class:`gnipy.Solution`: its summary (`sol.summary()`, what `print` users read)
and its HTML table (Jupyter), both leading with the run's health."""

from __future__ import annotations

import html as _html

import numpy as np

__all__ = ["summary", "html"]


def summary(sol) -> str:
    """`sol.summary()` (:meth:`gnipy.Solution.summary`)."""
    if sol.batch_size is not None:
        e = np.asarray(sol.energy)
        valid = sol.valid
        dev = np.where(valid, np.abs(e - e[:, :1]), 0.0)
        r = np.abs(np.asarray(sol.constraint_residual))
        r = np.where(valid[..., None], r, 0.0) if r.size else r
        failures = sol.failures()
        lines = [
            f"{sol.system} with {sol.method}: {sol.batch_size} members, h = {sol.h:g}, {sol.steps} steps, "
            f"t = {float(sol.t[0]):g} .. {float(sol.t[-1]):g}",
            f"  health: {sol.health}",
            f"  failed members: {len(failures)}",
        ]
        for f in failures[:5]:
            lines.append(f"    member {f['member']}: step {f['step']} (t = {f['time']:.6g}) failed, "
                         f"residual {f['residual']:.3e}; NaN after it")
        if len(failures) > 5:
            lines.append(f"    ... and {len(failures) - 5} more")
        return "\n".join([
            *lines,
            f"  max |E - E0| over members = {np.max(dev):.3e}",
            f"  max constraint residual = {np.max(r) if r.size else 0.0:.3e}",
            f"  Newton iterations: total {int(np.asarray(sol.iterations)[0])}, max per step {int(np.asarray(sol.iterations)[1])}",
            *sol._diagnostic_lines(),
        ])
    e = np.asarray(sol.energy)
    r = np.asarray(sol.constraint_residual)
    lines = [
        f"{sol.system} with {sol.method}: h = {sol.h:g}, {sol.steps} steps, t = {float(sol.t[0]):g} .. {float(sol.t[-1]):g}",
        f"  health: {sol.health}",
        f"  final q = {np.array2string(np.asarray(sol.q[-1]), precision=6)}",
        f"  energy: initial {e[0]:.12g}, max |E - E0| = {np.max(np.abs(e - e[0])):.3e} (at the saved nodes)",
        f"  max constraint residual = {np.max(np.abs(r)) if r.size else 0.0:.3e}",
        f"  Newton iterations: total {int(np.asarray(sol.iterations)[0])}, max per step {int(np.asarray(sol.iterations)[1])}",
        *sol._diagnostic_lines(),
    ]
    return "\n".join(lines)

def html(sol) -> str:
    """`sol._repr_html_()`: the HTML table of a Solution (Jupyter)."""
    esc = _html.escape
    batch = sol.batch_size
    rows = [("health", sol.health), ("system", sol.system), ("method", sol.method), ("h", f"{sol.h:g}"),
            ("steps", f"{sol.steps}"),
            ("t", f"{float(sol.t[0]):g} .. {float(sol.t[-1]):g} ({len(sol.t)} saved nodes)" if len(sol.t) else "none"),
            ("members", str(batch)) if batch is not None else None,
            ("result", f"{'success' if sol.success else 'FAILED'}: {sol.message}")]
    e = np.asarray(sol.energy)
    r = np.abs(np.asarray(sol.constraint_residual))
    if e.size and batch is None:
        with np.errstate(over="ignore", invalid="ignore"):
            drift = np.max(np.abs(e - e[0]))
        rows.append(("energy", f"initial {e[0]:.12g}, max |E − E0| = {drift:.3e}"))
    if r.size:
        rows.append(("constraint residual", f"max {np.nanmax(r):.3e}"))
    rows.append(("Newton iterations", f"total {int(np.asarray(sol.iterations)[0])}, "
                                      f"max per step {int(np.asarray(sol.iterations)[1])}"))
    if sol.conserved:
        rows.append(("conserved", sol.conserved))
    body = "".join(f"<tr><th style='text-align:left'>{esc(k)}</th><td style='text-align:left'>{esc(v)}</td></tr>"
                   for k, v in (row for row in rows if row is not None))
    warn = "".join(f"<li>{esc(w)}</li>" for w in sol.warnings())
    warn = f"<p><b>Warnings</b></p><ul>{warn}</ul>" if warn else ""
    return f"<div><p><b>gnipy.Solution</b></p><table>{body}</table>{warn}</div>"
