"""`gni reproduce --quick`, the README's main job in its quick form, end to end through the CLI."""

import re

from typer.testing import CliRunner

from gnipy.cli import app


def test_gni_reproduce_quick(tmp_path):
    out = tmp_path / "report"
    result = CliRunner().invoke(app, ["reproduce", "--out", str(out), "--quick"])
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    for name in ("figure1", "figure2", "figure3"):
        assert (out / f"{name}.png").stat().st_size > 1000
        assert (out / f"{name}.pdf").stat().st_size > 1000
    md = next(out.glob("*.md")).read_text()
    html = next(out.glob("*.html")).read_text()
    assert "data:image/png;base64," in html
    assert not re.search(r"""(src|href)=["']https?://""", html)
    # the theorem table and the errata are in the report, with no failing row
    assert "Theorem 5.2" in md and "Errat" in md
    m = re.search(r"Theorem table: (\d+) of (\d+) claims pass", md)
    assert m and m.group(1) == m.group(2) and int(m.group(2)) >= 10, m
    assert "| FAIL |" not in md
    # where the GNI struggles: the three measured failures, each reported by its diagnostic
    assert "## Where the GNI struggles" in md
    for name in ("struggles_sleigh", "struggles_suslov", "struggles_oscillator"):
        assert (out / f"{name}.png").stat().st_size > 1000
    assert re.search(r"The verdict fires at t = [0-9.]+", md)
    assert "energy verdict" in md and "out of band at t =" in md
