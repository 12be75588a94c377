"""The Whipple bicycle (gnipy.models.whipple_bicycle) against the published benchmark of Meijaard,
Papadopoulos, Ruina and Schwab (Proc. R. Soc. A 463 (2007) 1955–1982):

- the linearized equations' matrices M, C₁, K₀, K₂ derived from the nonlinear model by JAX, against
  the paper's eq. (5.4) (14 digits);
- gnipy.linearize of the nonlinear model at the upright motion, against the eigenvalues of the
  paper's matrices; the weave and capsize speeds found by gnipy.stability_curve, against those of
  the paper's matrices (found here by SciPy's brentq on them);
- the nonlinear equations at the state of Basu-Mandal, Chatterjee and Papadopoulos (Proc. R. Soc. A
  463 (2007) 1983–2003) Table 1, against the accelerations published there (13 digits);
- a nonlinear run in the self-stable speed range: dla and sgni-trapezoid follow the continuous
  reference and the weave decays; the GNI leaves its hidden-momentum band (the upright bicycle's
  motion contracts phase volume, which a volume-preserving map cannot follow) and is flagged.
"""

import warnings

import numpy as np
import pytest
from scipy.optimize import brentq

import gnipy
from gnipy.models import whipple_bicycle as wb

#: numerics and the verdicts at the saved nodes: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

PUB = {k: np.array(v) for k, v in wb.PUBLISHED_MATRICES.items()}
G = wb.BENCHMARK["g"]


def _eigenvalues(matrices, v):
    """The eigenvalues of M q̈ + v C₁ q̇ + (g K₀ + v² K₂) q = 0 at speed v, largest real part first."""
    M, C1, K0, K2 = (np.asarray(matrices[k]) for k in ("M", "C1", "K0", "K2"))
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(M, G * K0 + v * v * K2), -v * np.linalg.solve(M, C1)]])
    e = np.linalg.eigvals(A)
    return e[np.lexsort((e.imag, -e.real))]


def _speeds(matrices):
    """Weave and capsize speeds: where the largest real part crosses 0 (SciPy's brentq)."""
    growth = lambda v: np.max(_eigenvalues(matrices, v).real)  # noqa: E731
    return brentq(growth, 4.0, 5.0, xtol=1e-14), brentq(growth, 5.5, 6.5, xtol=1e-14)


@pytest.fixture(scope="module")
def bicycle():
    return wb.build()


def test_linear_matrices_from_the_nonlinear_model_are_the_published_ones(bicycle):
    ours = wb.benchmark_matrices(bicycle)
    for name in ("M", "C1", "K0", "K2"):
        scale = np.max(np.abs(PUB[name]))
        # ≥ 12 significant digits of the largest entry (measured: ≤ 3e-14 absolute)
        assert np.max(np.abs(ours[name] - PUB[name])) < 1e-12 * scale, name
    # and so the weave and capsize speeds, to 12 digits
    np.testing.assert_allclose(_speeds(ours), _speeds(PUB), rtol=1e-12)
    weave, capsize = _speeds(PUB)
    assert 4.29 < weave < 4.30 and 6.02 < capsize < 6.03  # the paper's rounded speeds


def test_linearize_and_stability_curve_give_the_benchmark_eigenvalues_and_speeds(bicycle):
    def steady(v):
        return wb.upright(None, v)

    for v in (0.0, 3.0, 5.0, 8.0):
        lin = gnipy.linearize(bicycle, *steady(v))
        ours = lin.nonzero_eigenvalues
        ours = ours[np.lexsort((ours.imag, -ours.real))]
        np.testing.assert_allclose(ours, _eigenvalues(PUB, v), rtol=0, atol=1e-10)
    curve = gnipy.analysis.stability_curve(bicycle, steady, np.linspace(3.0, 7.0, 9))
    weave, capsize = _speeds(PUB)
    assert len(curve.transitions) == 2
    # stability_curve reads real parts within ZERO_TOL·|J| of 0 as 0, so its transitions sit where
    # the crossing eigenvalue's real part is that small (measured: 2.0e-9 off at the weave speed,
    # 3.6e-8 at the capsize speed, whose eigenvalue crosses slowly); the 12 digits come from
    # benchmark_matrices (test above)
    assert abs(curve.transitions[0] - weave) < 1e-7 and abs(curve.transitions[1] - capsize) < 1e-7


def test_nonlinear_accelerations_are_basu_mandal_table_1(bicycle):
    import jax.numpy as jnp

    from gnipy.compilation import jit
    from gnipy.equations import lagrange_dalembert_acceleration

    table = wb.BASU_MANDAL_TABLE1
    q, qdot = wb.from_basu_mandal(table["q"], table["qdot"])
    # their state satisfies this model's constraints (to the table's 13 digits): the coordinate
    # relations are right, positions and velocities
    assert abs(float(bicycle.phi(jnp.asarray(q))[0])) < 1e-12
    assert np.max(np.abs(np.asarray(bicycle.mu(jnp.asarray(q)) @ qdot))) < 1e-12
    # compiled (op by op, the nested derivatives of the bicycle's kinematics take 11 s here, compiled 5 s)
    acceleration = jit(lambda s, x, xd: lagrange_dalembert_acceleration(s, x, xd)[0])
    accelerations = acceleration(bicycle, jnp.asarray(q), jnp.asarray(qdot))
    theirs = wb.basu_mandal_accelerations(q, qdot, accelerations)
    published = np.array(table["qddot"])
    # the table gives 13 decimals; all nine agree to 2e-12 absolute, so to ≥ 11 significant digits
    # (measured: ≤ 1.3e-12, on the steer acceleration −4.62; 2.3e-13 on the smallest, the pitch's 0.12)
    np.testing.assert_allclose(theirs, published, rtol=0, atol=2e-12)


@pytest.fixture(scope="module")
def runs(bicycle):
    """v = 5 m/s (self-stable) with a roll rate of 0.5 rad/s: the reference over 3 s."""
    q0, v0 = (np.asarray(x, dtype=float) for x in wb.pushed(5.0, 0.5).defaults[:2])
    # pushed's default: the upright motion with the roll rate set, on the constraints
    assert v0[3] == 0.5 and np.max(np.abs(np.asarray(bicycle.constraint_residual(q0, v0)))) < 1e-13
    ref = gnipy.simulate(bicycle, "reference", q0, v0, h=0.05, t_final=3.0)
    return q0, v0, ref


@pytest.mark.parametrize("method", ["dla", "sgni-trapezoid"])
def test_methods_without_hidden_momentum_follow_the_reference_and_the_weave_decays(runs, method):
    q0, v0, ref = runs
    sol = gnipy.simulate(wb.build(), method, q0, v0, h=0.01, t_final=3.0, save_every=5)
    q_ref, q = np.asarray(ref.q), np.asarray(sol.q)
    roll, steer = 3, 6
    # O(h²) at h = 0.01 (measured: 1.9e-4 dla, 4.9e-4 sgni-trapezoid)
    assert np.max(np.abs(q[:, [roll, steer]] - q_ref[:, [roll, steer]])) < 2e-3
    first, last = np.max(np.abs(q_ref[:20, roll])), np.max(np.abs(q_ref[-20:, roll]))
    assert last < 0.5 * first  # the weave decays: self-stable at 5 m/s
    assert np.max(np.abs(np.asarray(sol.constraint_residual)[:, -1])) < 1e-14  # the front contact
    e = np.asarray(sol.energy)
    assert np.max(np.abs(e - e[0])) < 1e-4 * abs(e[0])
    assert sol.healthy and ref.healthy


def test_gni_loses_the_self_stable_motion_and_says_so(bicycle, runs):
    q0, v0, _ = runs
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sol = gnipy.simulate(bicycle, "gni-trapezoid", q0, v0, h=0.01, steps=80, throw=False)
    assert not sol.healthy
    assert any("hidden momentum of gni-trapezoid left its O(h) band" in str(w.message) for w in caught)
