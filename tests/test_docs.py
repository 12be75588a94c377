"""The documentation: the site builds with `mkdocs build --strict` (every page, every API page
generated from the docstrings, every internal link and anchor), and its code runs as written."""

import pathlib
import re
import subprocess
import sys

import numpy as np
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
    """The README's examples run in tests/test_readme.py; the getting-started page shows them as
    they are there."""
    readme = _python_blocks(ROOT / "README.md")
    page = _python_blocks(DOCS / "getting-started.md")
    assert readme and all(block in page for block in readme)


def test_systems_page_code_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    page = DOCS / "user-guide" / "systems.md"
    namespace: dict = {}
    for block in _python_blocks(page):
        exec(compile(block, str(page), "exec"), namespace)  # noqa: S102
    R = np.asarray(namespace["sol"].R[-1])
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    disk = namespace["disk"]
    assert disk.name == "my-disk"


def test_files_page_code_runs_on_a_result_file(tmp_path, monkeypatch):
    """The reading and plotting examples, on a file with the layout `gni run` writes."""
    import gnipy
    from gnipy.io import write_netcdf

    T = 6
    t = np.linspace(0.0, 0.5, T)
    q = np.stack([np.cos(t), np.sin(t), t, t], axis=1)
    sol = gnipy.Solution(t, q, q, q, 1.0 + 1e-6 * t, np.zeros((T, 2)), np.array([0, 0], dtype=np.int32),
                         system="vertical-disk", method="gni-midpoint", h=0.1,
                         coordinates=("x", "y", "phi", "theta"), params=(("m", 1.0),))
    write_netcdf(sol, tmp_path / "disk.nc")
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in _python_blocks(DOCS / "user-guide" / "files.md"):
        exec(compile(block, "files.md", "exec"), namespace)  # noqa: S102
    namespace["ds"].close()
    assert (tmp_path / "disk.png").is_file()


def test_performance_page_code_runs(tmp_path, monkeypatch):
    """Ensembles (initial conditions, parameters) and a streamed run, as the page shows them."""
    monkeypatch.chdir(tmp_path)
    page = DOCS / "user-guide" / "performance.md"
    namespace: dict = {}
    for block in _python_blocks(page):
        exec(compile(block, str(page), "exec"), namespace)  # noqa: S102
    sol = namespace["sol"]
    assert sol.batch_size == 50 and sol.q.shape == (50, 1001, 2)
    np.testing.assert_allclose(sol.member_params["Omega"], np.linspace(0.0, 1.0, 50))
    assert namespace["first"].q.shape == (21, 2)
    assert namespace["result"].nodes == 20001 and (tmp_path / "ball.nc").is_file()
