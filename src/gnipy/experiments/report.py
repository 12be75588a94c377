"""The reproduction report: one Markdown file and one self-contained HTML page.

:func:`write_report` writes `report.md` (figures linked as the PNG files next to it) and
`report.html` (PNG figures embedded as base64 data URIs, inline CSS, no script and no external
resource: the page can be mailed or archived alone). Both hold the provenance (gnipy version, date,
machine, quick or full run, run time), each figure with its caption, table and notes, the theorem
table with pass/fail, and the errata. Files are written atomically (a temporary file in the same
folder, then `os.replace`: :func:`gnipy.files.atomic_write_text`), so a reader never sees half a
report, and a failed write (a full disk) leaves an earlier report as it was.

**Output folders** (shared by the figures of :mod:`~gnipy.experiments.figures` and
:mod:`~gnipy.experiments.struggles`). A folder that does not exist is created with gnipy's marker (:func:`gnipy.files.make_owned_dir`); in such a folder
gnipy replaces its own files on a rerun. In a folder gnipy did not create, an existing file of the
same name is replaced only when asked (`overwrite=True`, `gni reproduce --overwrite`, or inside
:func:`overwriting`); a symbolic link or special file is never written through.
"""

from __future__ import annotations

import base64
import html
import math
import contextlib
import contextvars
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["write_report", "REPORT_TITLE", "PAPER", "ensure_output_dir", "may_replace", "overwriting",
           "save_figure"]

REPORT_TITLE = "gnipy: reproduction of the Geometric Nonholonomic Integrator paper"
PAPER = ('S. Ferraro, F. Jiménez, D. Martín de Diego, "New developments on the Geometric Nonholonomic '
         'Integrator", Nonlinearity 28 (2015) 871–900, arXiv:1312.1587')

# provenance keys shown first, in this order, with their labels; other keys of `meta` follow
_META_LABELS = {
    "gnipy_version": "gnipy version",
    "date": "date",
    "machine": "machine",
    "mode": "mode",
    "runtime_s": "run time",
    "stage_runtimes_s": "run time per stage",
    "python": "Python",
    "jax_version": "JAX",
    "command": "command",
}


def _fmt(x: Any) -> str:
    """Numbers in a compact form (3 significant digits, scientific for small and large)."""
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, int):
        return str(x)
    if isinstance(x, float):
        if math.isnan(x) or math.isinf(x):
            return str(x)
        if x == 0.0:
            return "0"
        if 1e-3 <= abs(x) < 1e5:
            return f"{x:.4g}"
        return f"{x:.3e}"
    try:  # numpy scalars
        import numpy as np

        if isinstance(x, np.generic):
            return _fmt(x.item())
    except ImportError:  # pragma: no cover
        pass
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_fmt(v) for v in x) + "]"
    return str(x)


def _fmt_meta(key: str, value: Any) -> str:
    seconds = key.endswith("_s")
    if isinstance(value, Mapping):
        return ", ".join(f"{k}: {_fmt_meta(key, v)}" for k, v in value.items())
    if seconds and isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{value:.1f} s"
    return _fmt(value)


def meta_items(meta: Mapping[str, Any]) -> list[tuple[str, str]]:
    """`(label, text)` of each provenance entry of `meta`, the known keys first in their order."""
    items = [(label, _fmt_meta(k, meta[k])) for k, label in _META_LABELS.items() if k in meta]
    items += [(k.removesuffix("_s").replace("_", " "), _fmt_meta(k, v)) for k, v in meta.items() if k not in _META_LABELS]
    return items


def _columns(rows: Sequence[Mapping[str, Any]]) -> list[str]:
    cols: list[str] = []
    for row in rows:
        for k in row:
            if k not in cols:
                cols.append(k)
    return cols


def _pass_text(passed: bool) -> str:
    return "PASS" if passed else "FAIL"


# ------------------------------------------------------------------------------------------------
# Markdown
# ------------------------------------------------------------------------------------------------
def _md_cell(x: Any) -> str:
    text = x if isinstance(x, str) else _fmt(x)
    return " ".join(str(text).split()).replace("|", "\\|")


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> list[str]:
    """The lines of a Markdown table (numbers formatted as the reports show them, `|` escaped)."""
    lines = ["| " + " | ".join(_md_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in rows]
    return lines


STRUGGLES_INTRO = ("Measured failures of the GNI family beyond the paper's examples, each with the run-time "
                   "diagnostic that reports it (gnipy.diagnostics) and a method that works there.")


def _md_figure(out_dir: Path, fig) -> list[str]:
    """One figure (image, other files, caption, table, metrics, notes) as Markdown lines."""
    lines = [f"### {fig.title}", ""]
    for f in fig.files:
        if Path(f).suffix.lower() == ".png":
            rel = Path(os.path.relpath(Path(f), out_dir)).as_posix()
            lines += [f"![{fig.name}]({rel})", ""]
    others = [Path(f).name for f in fig.files if Path(f).suffix.lower() != ".png"]
    if others:
        lines += ["Also: " + ", ".join(f"[{n}]({n})" for n in others), ""]
    lines += [f"*{' '.join(str(fig.caption).split())}*", ""]
    if fig.table:
        lines += markdown_table(_columns(fig.table), ([row.get(c, "") for c in _columns(fig.table)] for row in fig.table))
        lines += [""]
    if fig.metrics:
        lines += ["Metrics:", ""]
        lines += markdown_table(["metric", "value"], fig.metrics.items())
        lines += [""]
    if fig.notes:
        lines += [f"- {' '.join(str(n).split())}" for n in fig.notes] + [""]
    return lines


def _markdown(out_dir: Path, figures, theorems, errata, meta, struggles=()) -> str:
    n_pass = sum(bool(r.passed) for r in theorems)
    lines = [f"# {REPORT_TITLE}", "", f"Paper: {PAPER}.", "", "## Provenance", ""]
    lines += markdown_table(["", ""], meta_items(meta))
    summary = (f"**Theorem table: {n_pass} of {len(theorems)} claims pass.** "
               f"Errata measured: {len(errata)}. Figures: {len(figures)}.")
    lines += ["", summary, ""]

    lines += ["## Figures", ""]
    for fig in figures:
        lines += _md_figure(out_dir, fig)
    if struggles:
        lines += ["## Where the GNI struggles", "", STRUGGLES_INTRO, ""]
        for fig in struggles:
            lines += _md_figure(out_dir, fig)

    lines += ["## Theorems", "", f"{n_pass} of {len(theorems)} pass.", ""]
    lines += markdown_table(["#", "claim", "paper", "expected", "measured", "result"],
                       ([i, r.claim, r.paper_ref, r.expected, r.measured, f"**{_pass_text(r.passed)}**"]
                        for i, r in enumerate(theorems, 1)))
    lines += ["", "How each claim was measured:", ""]
    lines += [f"{i}. {' '.join(str(r.detail).split())}" for i, r in enumerate(theorems, 1)]
    lines += ["", "## Errata", ""]
    for i, e in enumerate(errata, 1):
        lines += [f"### {i}. {e.location}", "",
                  f"- **Printed:** {' '.join(str(e.printed).split())}",
                  f"- **Corrected:** {' '.join(str(e.corrected).split())}",
                  f"- **Measured:** {' '.join(str(e.measurement).split())}",
                  f"- **Evidence value:** {_fmt(e.evidence_value)}", ""]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------------
# HTML
# ------------------------------------------------------------------------------------------------
#: The style sheet of the HTML reports.
REPORT_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 0 auto;
       max-width: 1100px; padding: 1.5em; color: #1d1d1f; line-height: 1.45; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 2em; border-bottom: 1px solid #bbb; }
h3 { font-size: 1.08em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: .8em 0; font-size: .86em; }
th, td { border: 1px solid #ccc; padding: .25em .5em; vertical-align: top; text-align: left; }
th { background: #f0f0f3; }
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
.pass { color: #0a6b1f; font-weight: bold; }
.fail { color: #b00020; font-weight: bold; }
.caption { font-style: italic; color: #333; }
.detail { color: #444; font-size: .92em; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
.summary { font-size: 1.05em; padding: .5em .8em; background: #f6f6f8; border-left: 4px solid #666; }
.erratum { border-left: 3px solid #999; padding: .2em .9em; margin: 1em 0; background: #fafafa; }
.small { font-size: .85em; color: #555; }
"""


def _e(x: Any) -> str:
    return html.escape(x if isinstance(x, str) else _fmt(x))


def html_table(header: Sequence[str], rows: Iterable[Sequence[Any]], raw_last: bool = False) -> list[str]:
    """The lines of an HTML table, its cells escaped (the last column as given with `raw_last`), numbers
    right-aligned."""
    out = ["<table>", "<tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>"]
    for row in rows:
        cells = []
        for j, c in enumerate(row):
            if raw_last and j == len(row) - 1:
                cells.append(f"<td>{c}</td>")
            elif isinstance(c, (int, float)) and not isinstance(c, bool):
                cells.append(f'<td class="num">{_e(c)}</td>')
            else:
                cells.append(f"<td>{_e(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return out


def png_data_uri(path: Path) -> str | None:
    """The PNG image `path` as a `data:` URI (for a self-contained page), None when it cannot be read."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _html_figure(fig) -> list[str]:
    """One figure as HTML, its PNG images embedded."""
    parts = [f"<h3>{_e(fig.title)}</h3>"]
    for f in fig.files:
        if Path(f).suffix.lower() == ".png":
            uri = png_data_uri(Path(f))
            if uri is None:
                parts.append(f'<p class="fail">Image missing: {_e(Path(f).name)}</p>')
            else:
                parts.append(f'<figure><img alt="{_e(fig.name)}" src="{uri}"></figure>')
    others = [Path(f).name for f in fig.files if Path(f).suffix.lower() != ".png"]
    if others:
        parts.append(f'<p class="small">Also written next to this report: {_e(", ".join(others))}.</p>')
    parts.append(f'<p class="caption">{_e(fig.caption)}</p>')
    if fig.table:
        cols = _columns(fig.table)
        parts += html_table(cols, ([row.get(c, "") for c in cols] for row in fig.table))
    if fig.metrics:
        parts += html_table(["metric", "value"], fig.metrics.items())
    if fig.notes:
        parts.append("<ul>" + "".join(f"<li>{_e(n)}</li>" for n in fig.notes) + "</ul>")
    return parts


def _html(out_dir: Path, figures, theorems, errata, meta, struggles=()) -> str:
    n_pass = sum(bool(r.passed) for r in theorems)
    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             f"<title>{_e(REPORT_TITLE)}</title>", f"<style>{REPORT_CSS}</style>", "</head>", "<body>",
             f"<h1>{_e(REPORT_TITLE)}</h1>", f"<p>Paper: {_e(PAPER)}.</p>"]
    status = "pass" if n_pass == len(theorems) else "fail"
    parts.append(f'<p class="summary">Theorem table: <span class="{status}">{n_pass} of {len(theorems)} claims '
                 f"pass</span>. Errata measured: {len(errata)}. Figures: {len(figures)}.</p>")
    parts += ["<h2>Provenance</h2>"] + html_table(["item", "value"], meta_items(meta))

    parts.append("<h2>Figures</h2>")
    for fig in figures:
        parts += _html_figure(fig)
    if struggles:
        parts += ["<h2>Where the GNI struggles</h2>", f"<p>{_e(STRUGGLES_INTRO)}</p>"]
        for fig in struggles:
            parts += _html_figure(fig)

    parts += ["<h2>Theorems</h2>", f"<p>{n_pass} of {len(theorems)} pass.</p>"]
    parts += html_table(
        ["#", "claim", "paper", "expected", "measured", "result"],
        ([i, r.claim, r.paper_ref, r.expected, r.measured,
          f'<span class="{"pass" if r.passed else "fail"}">{_pass_text(r.passed)}</span>']
         for i, r in enumerate(theorems, 1)),
        raw_last=True,
    )
    parts.append("<p>How each claim was measured:</p><ol class=\"detail\">"
                 + "".join(f"<li>{_e(r.detail)}</li>" for r in theorems) + "</ol>")

    parts.append("<h2>Errata</h2>")
    for i, e in enumerate(errata, 1):
        parts.append(
            f'<div class="erratum"><h3>{i}. {_e(e.location)}</h3>'
            f"<p><b>Printed:</b> {_e(e.printed)}</p><p><b>Corrected:</b> {_e(e.corrected)}</p>"
            f"<p><b>Measured:</b> {_e(e.measurement)}</p><p><b>Evidence value:</b> {_e(e.evidence_value)}</p></div>"
        )
    parts += ["</body>", "</html>"]
    return "\n".join(parts) + "\n"


# ------------------------------------------------------------------------------------------------
# Output folders and files (through gnipy.files)
# ------------------------------------------------------------------------------------------------
_OVERWRITE: contextvars.ContextVar[bool] = contextvars.ContextVar("gnipy_experiments_overwrite", default=False)


@contextlib.contextmanager
def overwriting(flag: bool = True):
    """Within this context, the experiments' writers replace existing files of their names even in a
    folder gnipy did not create (`gni reproduce --overwrite`)."""
    token = _OVERWRITE.set(bool(flag))
    try:
        yield
    finally:
        _OVERWRITE.reset(token)


def may_replace(out_dir) -> bool:
    """Whether the experiments may replace their own existing files in `out_dir`: it is a folder
    gnipy created (:func:`gnipy.files.is_owned_dir`), or :func:`overwriting` is on."""
    from ..files import is_owned_dir

    return _OVERWRITE.get() or is_owned_dir(out_dir)


def ensure_output_dir(out_dir, purpose: str = "gni reproduce: figures and report") -> Path:
    """`out_dir` as a Path, created with gnipy's marker if it does not exist (its missing parents as
    plain folders). Raises :class:`gnipy.files.OutputError` if it cannot be, or is not a folder."""
    from ..files import OutputError, make_owned_dir

    out_dir = Path(out_dir)
    if out_dir.is_dir():
        return out_dir
    if os.path.lexists(out_dir):
        raise OutputError(f"out_dir: {out_dir} exists and is not a directory")
    try:
        out_dir.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"out_dir: cannot create {out_dir.parent}: {e.strerror or e}") from None
    return make_owned_dir(out_dir, purpose)


def save_figure(fig, out_dir, name: str, dpi: float) -> list[Path]:
    """Write `fig` as `out_dir/NAME.png` (at `dpi`) and `out_dir/NAME.pdf`, each atomically
    (:func:`gnipy.files.atomic_savefig`), replacing earlier files as :func:`may_replace` allows."""
    from ..files import atomic_savefig

    out_dir = ensure_output_dir(out_dir)
    replace = may_replace(out_dir)
    files = [out_dir / f"{name}.png", out_dir / f"{name}.pdf"]
    atomic_savefig(fig, files[0], overwrite=replace, argument="out_dir", dpi=dpi)
    atomic_savefig(fig, files[1], overwrite=replace, argument="out_dir")
    return files


def write_report(out_dir, figures: Sequence, theorems: Sequence, errata: Sequence,
                 meta: Mapping[str, Any], struggles: Sequence = (), *,
                 overwrite: bool | None = None) -> tuple[Path, Path]:
    """Write `report.md` and the self-contained `report.html` into `out_dir`.

    Arguments:
        out_dir: the folder (created if missing); the figures' PNG files are linked from the
            Markdown relative to it and embedded in the HTML.
        figures: :class:`~gnipy.experiments.figures.FigureResult` objects (or anything with their
            fields: name, title, caption, files, metrics, table, notes).
        theorems: :class:`~gnipy.experiments.theorems.Row` objects.
        errata: :class:`~gnipy.experiments.theorems.Erratum` objects.
        meta: provenance, e.g. `gnipy_version`, `date`, `machine`, `mode`, `runtime_s` (shown first,
            in that order), then any other keys.
        struggles: the figures of the section "Where the GNI struggles"
            (:mod:`gnipy.experiments.struggles`), after the paper's figures.
        overwrite: replace existing `report.md` / `report.html`; None (the default): in a folder
            gnipy created, or inside :func:`overwriting` (see the module docstring).

    Raises:
        gnipy.files.OutputError: a file could not be written (a full disk: an earlier report stays as
            it was), or exists and may not be replaced.

    Returns:
        `(md_path, html_path)`.
    """
    from ..files import atomic_write_text

    out_dir = ensure_output_dir(out_dir)
    replace = may_replace(out_dir) if overwrite is None else bool(overwrite)
    md_path, html_path = out_dir / "report.md", out_dir / "report.html"
    md, page = (_markdown(out_dir, figures, theorems, errata, meta, struggles),
                _html(out_dir, figures, theorems, errata, meta, struggles))
    atomic_write_text(md_path, md, overwrite=replace, argument="out_dir")
    atomic_write_text(html_path, page, overwrite=replace, argument="out_dir")
    return md_path, html_path
