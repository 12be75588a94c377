"""The documentation: the site builds with `mkdocs build --strict` (every page, every API page
generated from the docstrings, every internal link and anchor). That its code runs as written is
tests/test_doc_examples.py."""

import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def test_site_builds_strict(tmp_path):
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings_handlers.python")
    site = tmp_path / "site"
    res = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(site)],
        cwd=ROOT, check=False, capture_output=True, text=True, timeout=300,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    assert "WARNING" not in res.stderr, res.stderr
    for page in ["index.html", "getting-started/index.html", "theory/index.html", "user-guide/cli/index.html",
                 "api/gnipy/index.html", "api/plots/index.html", "api/io/index.html", "api/lie_groups/index.html",
                 "api/retractions/index.html", "api/integrators/index.html", "api/models/index.html"]:
        assert (site / page).is_file(), page
    # the API pages hold the generated reference, not just their headings
    api = (site / "api" / "gnipy" / "index.html").read_text()
    for name in ["gnipy.System", "gnipy.simulate.simulate", "gnipy.Solution", "gnipy.get_model"]:
        assert f'id="{name}"' in api, name
    assert 'id="gnipy.plots.plot_convergence"' in (site / "api" / "plots" / "index.html").read_text()
    assert 'id="gnipy.io.write_netcdf"' in (site / "api" / "io" / "index.html").read_text()


def _python_blocks(page: pathlib.Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)


def test_every_page_is_in_the_nav():
    nav = (ROOT / "mkdocs.yml").read_text()
    for page in DOCS.rglob("*.md"):
        assert str(page.relative_to(DOCS)) in nav, page


def test_cli_page_covers_every_command():
    from gnipy.cli import app

    text = (DOCS / "user-guide" / "cli.md").read_text()
    for command in app.registered_commands:
        name = command.name or command.callback.__name__
        assert f"gni {name}" in text, name


def test_getting_started_repeats_the_readme_quick_start():
    """The README's examples (run with every other block in tests/test_doc_examples.py) appear
    on the getting-started page as they are in the README."""
    readme = _python_blocks(ROOT / "README.md")
    page = _python_blocks(DOCS / "getting-started.md")
    assert readme and all(block in page for block in readme)
