"""The report writer (gnipy.experiments.report) and the reproduction driver with stub stages
(gnipy.experiments.reproduce): Markdown and a self-contained HTML page with the figures embedded,
atomic writes, pass/fail, and the command's exit code."""

import base64
import dataclasses
import re
from html.parser import HTMLParser
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from gnipy.experiments import reproduce as rp
from gnipy.experiments.report import write_report
from gnipy.experiments.theorems import Erratum, Row


@dataclasses.dataclass
class Fig:  # the fields of figures.FigureResult
    name: str
    title: str
    caption: str
    files: list
    metrics: dict
    table: list
    notes: list


def _png(path: Path) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1.0, 0.8))
    FigureCanvasAgg(fig)
    fig.subplots().plot([0, 1], [1, 0])
    fig.savefig(path, dpi=30)
    return path


def _figure(out: Path, k: int) -> Fig:
    png = _png(out / f"figure{k}.png")
    pdf = out / f"figure{k}.pdf"
    pdf.write_bytes(b"%PDF-1.4 stub")
    return Fig(f"figure{k}", f"Figure {k} — synthetic", f"Caption {k} with | a pipe and <b>markup</b>.",
               [png, pdf], {"order_position": 2.0004, "runtime_s": 0.5},
               [{"h": 0.1, "error_position": 1.5e-3}, {"h": 0.05, "error_position": 3.7e-4, "extra": "x"}],
               [f"note {k}: slope 2"])


ROWS = [
    Row("Euler A converges with order 1", "Theorem 5.1", "order 1", "order 0.99", True, "particle [SDD2]"),
    Row("the energy is conserved", "§4", "0 drift", "3e-3", False, "a deliberately failing row"),
]
ERRATA = [Erratum("§7.4 (RBb)", "+2Q*Π", "−2Q*Π", "printed 0.92, corrected 1.7e-15", 0.92,
                  {"printed_residual": 0.92, "corrected_residual": 1.7e-15})]
META = {"gnipy_version": "0.1.0", "date": "2024-01-01T00:00:00", "machine": "test box", "mode": "quick",
        "runtime_s": 12.34, "stage_runtimes_s": {"Figure 1": 1.0}}


class _Resources(HTMLParser):
    """Collects every URL-valued attribute and the tags used."""

    def __init__(self):
        super().__init__()
        self.urls, self.tags = [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        for name, value in attrs:
            if name in ("src", "href", "srcset", "data", "poster", "action") and value is not None:
                self.urls.append((tag, name, value))


def test_markdown_and_self_contained_html(tmp_path):
    figs = [_figure(tmp_path, 1), _figure(tmp_path, 2)]
    md, html = write_report(tmp_path, figs, ROWS, ERRATA, META)
    assert md == tmp_path / "report.md" and html == tmp_path / "report.html"

    text = md.read_text(encoding="utf-8")
    assert text.startswith("# ")
    for s in ["gnipy version", "0.1.0", "test box", "quick", "12.3 s", "Figure 1 — synthetic",
              "![figure1](figure1.png)", "figure2.pdf", "note 2: slope 2", "0.0015", "Theorem 5.1", "**PASS**",
              "**FAIL**", "1 of 2", "§7.4 (RBb)", "−2Q*Π", "printed 0.92, corrected 1.7e-15"]:
        assert s in text, s
    # table rows have as many cells as the header
    for block in re.findall(r"((?:^\|.*\|\n)+)", text, flags=re.MULTILINE):
        lines = block.strip().splitlines()
        counts = {len(re.split(r"(?<!\\)\|", ln)) for ln in lines}
        assert len(counts) == 1, lines

    page = html.read_text(encoding="utf-8")
    parser = _Resources()
    parser.feed(page)
    assert not {"script", "link", "iframe", "object", "embed"} & set(parser.tags)
    imgs = [u for tag, _, u in parser.urls if tag == "img"]
    assert len(imgs) == 2
    for k, uri in enumerate(imgs, 1):
        assert uri.startswith("data:image/png;base64,")
        assert base64.b64decode(uri.split(",", 1)[1]) == (tmp_path / f"figure{k}.png").read_bytes()
    for _, _, url in parser.urls:
        assert not re.match(r"^\s*(https?:)?//", url, flags=re.IGNORECASE), url
    assert "http://" not in page and "https://" not in page
    assert "@import" not in page and "url(" not in page  # the CSS pulls nothing in
    # text is escaped, verdicts are shown
    assert "&lt;b&gt;markup&lt;/b&gt;" in page and "<b>markup</b>" not in page
    assert 'class="pass">PASS' in page and 'class="fail">FAIL' in page
    assert "[SDD2]" in page and "Evidence value" in page
    # the written files are whole (no temporary files left behind)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_rewrite_replaces_atomically(tmp_path):
    # a folder write_report creates carries gnipy's marker: a rerun replaces the report there
    out = tmp_path / "out"
    write_report(out, [], ROWS, ERRATA, META)
    assert (out / ".gnipy-owned").is_file()
    fig = _figure(out, 1)
    write_report(out, [fig], ROWS, ERRATA, META)
    md, html = write_report(out, [fig], ROWS[:1], ERRATA, dict(META, machine="other box"))
    assert "other box" in md.read_text(encoding="utf-8") and "other box" in html.read_text(encoding="utf-8")
    assert "1 of 1" in md.read_text(encoding="utf-8")
    assert [p.name for p in out.iterdir() if p.suffix == ".tmp"] == []


def test_rewrite_in_a_foreign_folder_needs_overwrite(tmp_path):
    """A folder gnipy did not create (no marker): an existing report is not replaced unless asked."""
    from gnipy.files import OutputError

    fig = _figure(tmp_path, 1)
    md, _ = write_report(tmp_path, [fig], ROWS, ERRATA, META)
    before = md.read_bytes()
    with pytest.raises(OutputError, match="report.md exists"):
        write_report(tmp_path, [fig], ROWS[:1], ERRATA, dict(META, machine="other box"))
    assert md.read_bytes() == before
    write_report(tmp_path, [fig], ROWS[:1], ERRATA, dict(META, machine="other box"), overwrite=True)
    assert "other box" in md.read_text(encoding="utf-8")
    assert [p.name for p in tmp_path.iterdir() if p.suffix == ".tmp"] == []


def test_missing_png_is_reported_not_fatal(tmp_path):
    fig = Fig("figure9", "Figure 9", "c", [tmp_path / "nothere.png"], {}, [], [])
    _, html = write_report(tmp_path / "sub", [fig], ROWS, [], META)
    assert "Image missing" in html.read_text(encoding="utf-8")


# ------------------------------------------------------------------------------------------------
# reproduce() with stub stages
# ------------------------------------------------------------------------------------------------
def _stub_figures(fail_second=False):
    def make(k):
        def figure(out_dir, quick, progress=None):
            assert quick is True
            progress(0.5, f"figure {k}: half")
            progress(0.5, f"figure {k}: done")
            if fail_second and k == 2:
                raise RuntimeError("stub failure")
            return _figure(Path(out_dir), k)

        return figure

    return {f"figure_{k}": make(k) for k in (1, 2, 3)}


@pytest.fixture
def stubs(monkeypatch):
    state = {"rows": ROWS[:1], "fail_second": False}

    def theorem_table(quick, progress=None):
        progress(1.0, "theorems: done")
        return list(state["rows"])

    def errata_rows(quick, progress=None):
        progress(1.0, "errata: done")
        return list(ERRATA)

    def struggle_figures(out_dir, quick, progress=None):
        progress(1.0, "struggles: done")
        return [_figure(Path(out_dir), 4)]

    import gnipy.experiments.struggles as st
    import gnipy.experiments.theorems as th

    monkeypatch.setattr(st, "struggle_figures", struggle_figures)
    monkeypatch.setattr(th, "theorem_table", theorem_table)
    monkeypatch.setattr(th, "errata_rows", errata_rows)
    monkeypatch.setattr(rp, "_figure_functions", lambda: _stub_figures(state["fail_second"]))
    return state


def test_reproduce_writes_the_report(tmp_path, stubs, capsys):
    path = rp.reproduce(tmp_path / "out", quick=True)
    assert path == tmp_path / "out" / "report.html" and path.exists()
    assert (tmp_path / "out" / "report.md").exists()
    page = path.read_text(encoding="utf-8")
    # the paper's three figures and the section "Where the GNI struggles" (one stub figure here)
    assert page.count("data:image/png;base64,") == 4 and "quick" in page
    assert "<h2>Where the GNI struggles</h2>" in page
    assert "## Where the GNI struggles" in (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    out = capsys.readouterr().out
    assert "PASS" in out and "1 of 1 theorem rows pass" in out and "report.html" in out


def _app():
    app = typer.Typer()
    from gnipy.cli.reproduce import reproduce as command

    app.command("reproduce")(command)

    @app.command("other")
    def other():  # a second command, so that typer keeps the subcommand name
        pass

    return app


def test_command_exit_codes(tmp_path, stubs):
    runner = CliRunner()
    res = runner.invoke(_app(), ["reproduce", "--quick", "--out", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "a" / "report.html").exists()

    stubs["rows"] = ROWS  # one failing theorem row
    res = runner.invoke(_app(), ["reproduce", "--quick", "--out", str(tmp_path / "b")])
    assert res.exit_code == 1, res.output
    assert "FAIL" in res.output and (tmp_path / "b" / "report.html").exists()

    stubs["rows"], stubs["fail_second"] = ROWS[:1], True  # a stage raises: the others still report
    res = runner.invoke(_app(), ["reproduce", "--quick", "--out", str(tmp_path / "c")])
    assert res.exit_code == 1, res.output
    page = (tmp_path / "c" / "report.html").read_text(encoding="utf-8")
    assert "stub failure" in page and page.count("data:image/png;base64,") == 3


def test_command_help_is_the_docstring():
    res = CliRunner().invoke(_app(), ["reproduce", "--help"])
    assert res.exit_code == 0
    assert "--out" in res.output and "--quick" in res.output and "Reproduce the paper" in res.output
