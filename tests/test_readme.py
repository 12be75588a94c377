"""The README's Python examples run as written (the README is the contract)."""

import pathlib
import re

import numpy as np

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert len(blocks) >= 2
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(README), "exec"), namespace)  # noqa: S102
    # the first example writes its file; the second reconstructs orientations
    assert (tmp_path / "particle.nc").exists()
    R = np.asarray(namespace["sol"].R[-1])
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
