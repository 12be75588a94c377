"""The scripts in examples/ run as documented (each in a fresh interpreter) and print sane results."""

import csv
import os
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"
PNG = b"\x89PNG\r\n\x1a\n"


def run_example(name: str, out: pathlib.Path, *, via_env: bool = False) -> str:
    env = dict(os.environ)
    args = [sys.executable, str(EXAMPLES / name)]
    if via_env:
        env["GNIPY_EXAMPLES_OUT"] = str(out)
    else:
        env.pop("GNIPY_EXAMPLES_OUT", None)
        args.append(str(out))
    res = subprocess.run(args, check=False, capture_output=True, text=True, timeout=240, env=env, cwd=out.parent)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    return res.stdout


def number(output: str, label: str) -> float:
    m = re.search(re.escape(label) + r"\s*([-+0-9.eE]+|nan)", output)
    assert m, f"{label!r} not in output:\n{output}"
    return float(m.group(1))


def test_define_your_own_system(tmp_path):
    out = tmp_path / "out"
    text = run_example("define_your_own_system.py", out, via_env=True)
    assert "skate-on-a-spring with gni-midpoint" in text
    assert number(text, "max constraint residual:") < 1e-12
    assert number(text, "energy drift:") < 1e-3  # the GNI's energy error stays small (h = 0.01)
    ds = xr.load_dataset(out / "skate.nc")
    assert ds.attrs["model"] == "skate-on-a-spring" and ds.attrs["method"] == "gni-midpoint"
    assert ds.attrs["param_J"] == 0.2 and ds.sizes["time"] == 201
    assert list(ds["coordinate"].values) == ["x", "y", "theta"]
    np.testing.assert_allclose(ds["q"].values[0], [1.0, 0.0, np.pi / 2])


def test_define_your_own_system_setup_is_short():
    text = (EXAMPLES / "define_your_own_system.py").read_text()
    setup = text.split("# ---- the whole set-up")[1].split("# ----")[0]
    lines = [line for line in setup.splitlines()[1:] if line.strip() and not line.strip().startswith("#")]
    assert len(lines) < 15, lines


def test_rolling_ball(tmp_path):
    text = run_example("rolling_ball.py", tmp_path)
    assert number(text, "max contact-point error vs exact:") < 1e-2  # O(h²), h = 0.05, t = 20
    assert number(text, "max Jacobi integral drift:") < 1e-2
    assert number(text, "max constraint residual:") < 1e-12
    assert number(text, "max |R^T R - I|:") < 1e-12
    for name in ["rolling_ball_path.png", "rolling_ball.png"]:
        assert (tmp_path / name).read_bytes()[:8] == PNG
    ds = xr.load_dataset(tmp_path / "rolling_ball.nc")
    assert ds.attrs["model"] == "rolling-ball" and ds["R"].dims == ("time", "i", "j")


def test_convergence_study(tmp_path):
    text = run_example("convergence_study.py", tmp_path)
    orders = {m.group(1): (float(m.group(2)), int(m.group(3)))
              for m in re.finditer(r"order (\S+): ([-0-9.]+) \(expected (\d+)\)", text)}
    assert set(orders) == {"gni-euler-a", "gni-trapezoid"}
    for name, (fitted, expected) in orders.items():
        assert abs(fitted - expected) < 0.2, (name, fitted, expected)
    assert orders["gni-euler-a"][1] == 1 and orders["gni-trapezoid"][1] == 2
    with open(tmp_path / "convergence.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 8 and all(float(r["error"]) > 0 for r in rows)
    assert (tmp_path / "convergence.png").read_bytes()[:8] == PNG


@pytest.mark.parametrize("name", sorted(p.name for p in EXAMPLES.glob("*.py")))
def test_every_example_has_usage_in_its_docstring(name):
    text = (EXAMPLES / name).read_text()
    assert text.startswith('"""') and f"python examples/{name}" in text
