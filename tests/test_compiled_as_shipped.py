"""The suite's programs (-O0) and the shipped ones (XLA's defaults) compute the same runs to round-off.

tests/conftest.py compiles the suite's XLA programs without LLVM's optimization passes
(`SUITE_XLA_FLAGS`, with two HLO passes that only move computations off); users' programs are compiled with XLA's defaults, which contract some
multiply-adds and so round differently. Here one model of each structure, each with a different
family of solves, and one batch (a vmapped program) run in this process (-O0) and in a fresh
process compiled as shipped: the two agree to round-off (200 steps: measured ≤ 4e-15), in the
states and in the constraints' residuals, both converge and give the same verdicts; and at least one run
differs in its last bits, which shows that the suite's flag is in effect here (XLA reads its flags
once, when JAX starts its backend, so the flag must be set before anything is computed).
"""

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import SUITE_XLA_FLAGS

#: (model, method, members): one model per structure (R^n linear and affine, SE(2), R^2 x SO(3)),
#: each with another family of solves (the GNI's impulse solve, the discrete Lagrange-d'Alembert
#: constraint, the discrete gradient's); members > 0 is a batch of that many initial conditions
CASES = [
    ("rolling-ball", "gni-trapezoid", 0),
    ("chaplygin-sleigh-se2", "dla", 0),
    ("nonholonomic-particle", "discrete-gradient", 0),
    ("rotating-table-ball", "gni-midpoint", 3),
]
H, STEPS = 0.01, 200

RUN = textwrap.dedent(f"""
    import numpy as np
    import gnipy

    def run(model, method, members):
        spec = gnipy.get_model(model)
        q0, v0 = np.asarray(spec.q0, float), np.asarray(spec.v0, float)
        if members:
            q0 = q0 + 0.01 * np.arange(members)[:, None]
            v0 = np.broadcast_to(v0, (members, v0.size))
        sol = gnipy.simulate(spec.system(), method, q0, v0, project_v0=True, h={H}, steps={STEPS})
        return dict(q=np.asarray(sol.q), v=np.asarray(sol.v), residual=np.asarray(sol.constraint_residual),
                    success=np.asarray(sol.success), healthy=np.asarray(sol.healthy))
""")


def shipped_runs(tmp_path):
    """The runs of :data:`CASES` in a fresh process, compiled with XLA's defaults."""
    out = tmp_path / "shipped.npz"
    script = RUN + textwrap.dedent(f"""
        import warnings
        warnings.simplefilter("ignore")
        results = {{}}
        for i, case in enumerate({CASES!r}):
            for key, value in run(*case).items():
                results[f"{{i}}-{{key}}"] = value
        np.savez({str(out)!r}, **results)
    """)
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split() if f not in SUITE_XLA_FLAGS]
    if flags:
        env["XLA_FLAGS"] = " ".join(flags)
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-4000:]
    with np.load(out) as data:
        return {key: data[key] for key in data.files}


def test_the_suite_compiles_at_o0_unless_asked_otherwise():
    flags = os.environ.get("XLA_FLAGS", "").split()
    shipped = os.environ.get("GNIPY_TEST_SHIPPED_XLA", "").strip() not in ("", "0")
    assert all(f in flags for f in SUITE_XLA_FLAGS) != shipped, flags


@pytest.mark.slow
def test_suite_programs_and_shipped_programs_agree_to_round_off(tmp_path):
    namespace = {}
    exec(RUN, namespace)  # noqa: S102 - this module's own source: the same runs as the fresh process
    shipped = shipped_runs(tmp_path)
    differs = []
    for i, case in enumerate(CASES):
        here = namespace["run"](*case)
        for key in ("success", "healthy"):
            np.testing.assert_array_equal(here[key], shipped[f"{i}-{key}"], err_msg=f"{case} {key}")
        assert np.all(here["success"]), case
        for key in ("q", "v"):
            np.testing.assert_allclose(here[key], shipped[f"{i}-{key}"], rtol=0, atol=1e-12, err_msg=f"{case} {key}")
        np.testing.assert_allclose(here["residual"], shipped[f"{i}-residual"], rtol=0, atol=1e-12, err_msg=f"{case}")
        differs.append(not (np.array_equal(here["q"], shipped[f"{i}-q"]) and np.array_equal(here["v"], shipped[f"{i}-v"])))
    shipped_suite = os.environ.get("GNIPY_TEST_SHIPPED_XLA", "").strip() not in ("", "0")
    # the flag is in effect in this process: some run rounds differently (none when the suite runs as shipped)
    assert any(differs) != shipped_suite, differs
