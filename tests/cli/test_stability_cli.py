"""`gni stability`: the eigenvalues of a user's family of steady motions against a parameter, at the
command line, against the closed form of the upright rolling disk.

The system is a file of the user's (the uniform disk of tests/sympy_models.py, built with
sympy.physics.mechanics through gnipy.from_sympy), whose default initial condition is the upright
rolling at the spin rate `spin`. Reference values (tests/analysis/test_linearization.py): the lean
mode's eigenvalues ±λ with λ² = (m g R − C(C + mR²)Ω²/A)/(A + mR²), real below the critical spin
Ω_c = √(g/3R) and imaginary above it.
"""

from __future__ import annotations

import csv
import os

import numpy as np
import pytest
from typer.testing import CliRunner

from gnipy.cli import app
from user_system_files import write_source

runner = CliRunner()
M, R, G = 1.0, 0.5, 9.81
A, C = M * R ** 2 / 4, M * R ** 2 / 2
CRITICAL_SPIN = np.sqrt(G / (3 * R))

DISK = '''
import numpy as np
import gnipy
from sympy_models import rolling_disk_system


def disk(spin: float = 4.0, R: float = 0.5):
    """A uniform disk rolling upright and straight at the spin rate `spin`."""
    return gnipy.from_sympy(rolling_disk_system(), params={"m": 1.0, "R": R, "g": 9.81}, name="rolling-disk",
                            defaults=(np.zeros(5), np.array([R * spin, 0.0, 0.0, 0.0, spin])))
'''


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("stability")
    os.chmod(path, 0o755)
    write_source(path / "disk.py", DISK)
    return path


@pytest.fixture(scope="module")
def study(folder):
    """One command: five spin rates around the critical one, and two methods' maps at h = 0.05."""
    res = invoke("stability", f"{folder / 'disk.py'}:disk", "--over", "spin=1:5:5", "--methods",
                 "gni-midpoint,dla", "--h", "0.05", "--out", folder / "out")
    return res, folder / "out"


def _lambda(spin):
    return np.sqrt(complex((M * G * R - C * (C + M * R ** 2) * spin ** 2 / A) / (A + M * R ** 2)))


def test_the_critical_spin_and_the_eigenvalues_are_the_closed_form(study):
    res, out = study
    assert res.exit_code == 0, res.output
    changes = [line for line in res.output.splitlines() if line.startswith("change: ")]
    assert len(changes) == 1 and changes[0].endswith("(becomes stable)")
    spin = float(changes[0].split("=")[1].split()[0])
    assert abs(spin - CRITICAL_SPIN) < 1e-8 * CRITICAL_SPIN  # bisection to 1e-10 of the span, printed to 10 digits
    assert f"stable: spin in [{spin:.10g}, 5]" in res.output
    with open(out / "stability.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [float(r["spin"]) for r in rows] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert [r["stable"] for r in rows] == ["False", "False", "True", "True", "True"]
    for r in rows:
        lam = _lambda(float(r["spin"]))
        found = [complex(float(r[f"eigenvalue{k}_real"]), float(r[f"eigenvalue{k}_imag"]))
                 for k in (1, 2, 3, 4) if r[f"eigenvalue{k}_real"] != ""]
        pair = np.sort_complex(np.array([z for z in found if z != 0]))
        np.testing.assert_allclose(pair, np.sort_complex(np.array([lam, -lam])), rtol=1e-10)
        np.testing.assert_allclose(float(r["growth_rate"]), max(0.0, lam.real), rtol=1e-10, atol=1e-12)
    assert (out / "stability.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_methods_maps_are_reported_against_the_motions_stability(study):
    res, out = study
    with open(out / "stability.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    for method in ("gni-midpoint", "dla"):
        for r in rows:
            lam = _lambda(float(r["spin"]))
            growth = float(r[f"{method}_growth_rate"])
            if lam.real > 0:  # falling: the map's growth approximates λ (second-order methods, h = 0.05)
                assert abs(growth - lam.real) < 0.05 * lam.real, (method, r["spin"], growth)
            # the verdict in the file is the growth against MAP_GROWTH_TOL
            assert r[f"{method}_stable"] == str(growth <= 1e-5)
        agree = [r[f"{method}_stable"] == r["stable"] for r in rows]
        line = next(x for x in res.output.splitlines() if x.startswith(f"method {method}:"))
        assert ("keeps the stability at every value" in line) == all(agree), line


@pytest.mark.parametrize("args, option, words", [
    (["--over", "mass=1:2:3"], "--over", "not a parameter"),
    (["--over", "spin=1:2:1"], "--over", "COUNT = 1"),
    (["--over", "spin=2:1:3"], "--over", "increasing"),
    (["--over", "spin"], "--over", "expected NAME="),
    (["--over", "spin=1:2:3", "--set", "spin=2"], "--set", "set it there"),
    (["--over", "spin=1:2:3", "--set", "mass=2"], "--set", "unknown parameter 'mass'"),
    (["--over", "spin=1:2:3", "--methods", "dla", "--h", "-1"], "--h", ""),
    (["--over", "spin=1:2:3", "--methods", "no-such-method"], "--methods", "no-such-method"),
])
def test_bad_options_are_named(folder, tmp_path, args, option, words):
    res = invoke("stability", f"{folder / 'disk.py'}:disk", *args, "--out", tmp_path / "o")
    assert res.exit_code == 2, res.output
    assert option in res.output and words in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()


def test_a_model_on_a_group_is_refused(tmp_path):
    res = invoke("stability", "chaplygin-sphere", "--over", "m=1:2:3", "--out", tmp_path / "o")
    assert res.exit_code == 2 and "R^n only" in res.output, res.output


def test_a_state_that_is_not_a_steady_motion_names_the_value(folder, tmp_path):
    # a lean of 0.1 rad is not a steady motion of the disk rolling straight
    res = invoke("stability", f"{folder / 'disk.py'}:disk", "--over", "spin=1:2:2", "--q0", "0,0,0,0.1,0",
                 "--out", tmp_path / "o")
    assert res.exit_code == 2, res.output
    assert "--q0/--v0: at spin = 1:" in res.output and "steady motion" in res.output, res.output
