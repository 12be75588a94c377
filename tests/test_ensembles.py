"""Ensembles: `simulate` over batches of initial conditions and of parameter values (vmap).

Checks against exact solutions (each member converges at order 2 to its own exact solution), against
single runs of the same member, and the batch's error handling (sizes, the member named in
messages, failures of single members).

The rolling ball's parameter batch has three members, ball_batch's batch size and loop, and shares
its compiled program. Measured on the shared 2-core machine (`pytest -n 0 --durations=0` on this
file alone, other jobs running, so noisy to a few seconds): 36.6 s → 33.6 s (that test: 5.5 → 0.4 s).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import GNI, Midpoint, System
from gnipy.ensembles import member_initial_conditions, model_systems, stack_systems
from gnipy.io import read_netcdf, write_netcdf
from gnipy.models import rolling_ball

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

MOMENTS = np.array([0.4, 2.0 / 3.0, 1.0])  # equal moments I1 = I2 = I3 = I per member: exact circle
OMEGAS = np.array([1.0, 0.5, 2.0])
T_FINAL = 2.0


@pytest.fixture(scope="module")
def ball_batch():
    """Three balls (different I and Ω) from three initial conditions, at h and h/2, saving only
    the last node (both runs share one compilation)."""
    systems = model_systems("rolling-ball", I1=MOMENTS, I2=MOMENTS, I3=MOMENTS, Omega=OMEGAS)
    q0 = np.array([[1.0, 1.0], [0.5, -0.2], [-1.0, 0.3]])
    w = np.array([[0.0, 2.0, 0.0], [0.3, -0.4, 1.0], [-1.0, 0.5, 0.2]])
    v0 = np.array([rolling_ball.velocity_from_constraints(s.parameters, q, wi) for s, q, wi in zip(systems, q0, w)])
    runs = {}
    for h in (0.02, 0.01):
        steps = round(T_FINAL / h)
        runs[h] = gnipy.simulate(systems, "gni-trapezoid", q0, v0, h=h, steps=steps, save_every=steps)
    return systems, q0, v0, runs


def test_batch_shapes_and_metadata(ball_batch):
    systems, _, _, runs = ball_batch
    sol = runs[0.01]
    assert sol.batch_size == 3
    assert sol.q.shape == (3, 2, 2) and sol.v.shape == (3, 2, 5) and sol.R.shape == (3, 2, 3, 3)
    assert sol.t.shape == (2,) and float(sol.t[-1]) == pytest.approx(T_FINAL)
    np.testing.assert_array_equal(np.asarray(sol.results), 0)
    np.testing.assert_array_equal(sol.member_params["Omega"], OMEGAS)
    np.testing.assert_array_equal(sol.member_params["I2"], MOMENTS)
    assert sol.valid.all()


def test_each_member_converges_to_its_exact_solution_at_order_2(ball_batch):
    systems, q0, v0, runs = ball_batch
    errors = {}
    for h, sol in runs.items():
        err = []
        for i, s in enumerate(systems):
            q_ex, v_ex = rolling_ball.exact(s.parameters, q0[i], v0[i], np.array([T_FINAL]))
            err.append(np.max(np.abs(np.asarray(sol.q[i, -1]) - q_ex[0])) + np.max(np.abs(np.asarray(sol.v[i, -1]) - v_ex[0])))
        errors[h] = np.array(err)
    slopes = np.log2(errors[0.02] / errors[0.01])
    assert np.all(errors[0.01] > 1e-9)  # above round-off: the slopes mean something
    np.testing.assert_allclose(slopes, 2.0, atol=0.1)


def test_members_equal_single_runs(ball_batch):
    systems, q0, v0, runs = ball_batch
    sol = runs[0.02]
    for i in (0, 2):
        one = gnipy.simulate(systems[i], "gni-trapezoid", q0[i], v0[i], h=0.02, steps=100, save_every=100)
        m = sol.member(i)
        np.testing.assert_allclose(np.asarray(m.q), np.asarray(one.q), rtol=0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(m.R), np.asarray(one.R), rtol=0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(m.p), np.asarray(one.p), rtol=0, atol=1e-13)
        assert dict(m.params)["Omega"] == OMEGAS[i]


def test_batch_of_initial_conditions_broadcasts_one_system():
    particle = gnipy.make_system("nonholonomic-particle")
    q0 = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.5]])
    v0 = np.array([1.0, 0.0, 1.0])  # shared; projected onto each member's constraints
    sol = gnipy.simulate(particle, "gni-midpoint", q0, v0, h=0.1, steps=10, project_v0=True)
    assert sol.batch_size == 2 and sol.q.shape == (2, 11, 3)
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-14
    for i in range(2):
        one = gnipy.simulate(particle, "gni-midpoint", q0[i], v0, h=0.1, steps=10, project_v0=True)
        np.testing.assert_allclose(np.asarray(sol.q[i]), np.asarray(one.q), rtol=0, atol=1e-14)


@pytest.mark.parametrize(
    "name, params",
    [
        # the README's parameter batch (Omega from 0 to 1), three members: the batch size and the loop
        # of ball_batch (two saved nodes), whose compiled program it shares (9 s of CPU otherwise)
        ("rolling-ball", {"Omega": np.linspace(0.0, 1.0, 3)}),
        ("chaplygin-top", {"r": np.array([0.5, 1.0, 2.0])}),  # R-dependent constraints, default R0 ≠ I
    ],
)
def test_parameter_batch_starts_each_member_from_its_own_default(name, params):
    """Without q0/v0, every member of a parameter batch starts from its own documented initial
    condition (`System.defaults`, built for its parameter values), on its own constraints; the first
    member's default would violate the others' constraints."""
    systems = model_systems(name, **params)
    sol = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=1)
    residual = np.abs(np.asarray(sol.constraint_residual[:, 0]))
    assert residual.max() <= 1e-12, residual
    for i, s in enumerate(systems):
        q0, v0, *R0 = s.defaults
        np.testing.assert_array_equal(np.asarray(sol.q[i, 0]), q0)
        np.testing.assert_allclose(np.asarray(sol.v[i, 0]), v0, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(np.asarray(sol.R[i, 0]).ravel(), R0[0] if R0 else np.eye(3).ravel())
        # the failure this replaces: the first member's default initial velocity is off member i's constraints
        if i:
            b0 = s.check(q0, None, R0=R0[0] if R0 else None)[0]
            assert np.max(np.abs(np.asarray(s.constraint_residual(b0, np.asarray(systems[0].defaults[1]))))) > 1e-3


def test_member_initial_conditions_fill_only_what_is_missing():
    systems = model_systems("veselova", I1=[1.0, 1.5])  # on SO(3) alone: q0 is empty
    q0, v0, R0 = member_initial_conditions(systems, None, None, None)
    assert q0.shape == (2, 0) and v0.shape == (2, 3) and R0 is None
    given = np.array([[0.0, 0.0, 1.0]])
    q0, v0, R0 = member_initial_conditions(systems, None, given, np.eye(3))
    assert q0.shape == (2, 0) and v0 is given and R0.shape == (3, 3)


def test_batch_to_xarray_and_netcdf(ball_batch, tmp_path):
    sol = ball_batch[3][0.01]
    ds = sol.to_xarray()
    assert ds["q"].dims == ("member", "time", "coordinate")
    assert ds["R"].dims == ("member", "time", "i", "j")
    assert ds["result"].dims == ("member",) and ds["valid"].dims == ("member", "time")
    np.testing.assert_array_equal(ds["param_Omega"].values, OMEGAS)
    path = write_netcdf(sol, tmp_path / "batch.nc")
    back = read_netcdf(path)
    np.testing.assert_array_equal(back["q"].values, np.asarray(sol.q))
    assert "member" in sol.summary() or "members" in sol.summary()


# ---------------------------------------------------------------------------------------------
# errors and failures
# ---------------------------------------------------------------------------------------------
def _wall_system():
    # V = log(1 − x): undefined for x ≥ 1, and the force 1/(1 − x) pushes the particle there
    return System(lambda q, v: 0.5 * v @ v - jnp.log1p(-q[0]), lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3, name="wall")


def test_failed_member_is_reported_and_truncated():
    s = _wall_system()
    q0 = np.array([[0.5, 0.0, 0.0], [-5.0, 0.0, 0.0]])  # member 0 hits the wall within 0.5 time units
    v0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    sol = gnipy.simulate(s, GNI(Midpoint()), q0, v0, h=0.1, steps=20, save_every=2, throw=False)
    assert sol.result == 1
    np.testing.assert_array_equal(np.asarray(sol.results), [1, 0])
    k = int(sol.failed_steps[0])
    assert 0 < k < 20 and int(sol.failed_steps[1]) == -1
    m0, m1 = sol.member(0), sol.member(1)
    assert m0.result == 1 and m0.failed_step == k
    assert float(m0.t[-1]) <= 0.1 * k + 1e-12 and len(m1.t) == 11
    assert np.all(np.asarray(m0.q)[:, 0] < 1.0) and np.all(np.isfinite(np.asarray(m0.q)))
    np.testing.assert_array_equal(sol.valid[0], np.arange(11) * 2 <= k)
    # past its failure a member is NaN (never its last good state repeated), everywhere
    valid = sol.valid
    for name in ("q", "v", "p", "energy", "constraint_residual", "hidden_momentum", "energy_plus"):
        a = np.asarray(getattr(sol, name))
        assert np.all(np.isnan(a[~valid])), name
        assert np.all(np.isfinite(a[valid])), name
    # the failure's step, time and residual are kept per member, and in the file
    (f,) = sol.failures()
    assert f["member"] == 0 and f["step"] == k and f["time"] == pytest.approx(0.1 * k)
    assert np.isfinite(f["residual"]) and f["residual"] > 0
    assert np.isnan(float(sol.failed_residuals[1]))
    assert m0.failed_residual == f["residual"] and "member 0: step" in sol.summary()
    ds = sol.to_xarray()
    assert float(ds["failed_residual"][0]) == f["residual"] and np.isnan(float(ds["failed_residual"][1]))
    with pytest.raises(gnipy.SolverFailure, match=r"member 0 of 2: step \d+ .*residual"):
        gnipy.simulate(s, GNI(Midpoint()), q0, v0, h=0.1, steps=20, save_every=2)


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        ({"q0": np.zeros((2, 3)), "v0": np.zeros((3, 3))}, r"batch: the batch sizes differ"),
        ({"q0": np.zeros((2, 2)), "v0": np.zeros((2, 3))}, r"q0: expected vectors of length 3"),
        ({"q0": np.zeros((2, 3)), "v0": np.array([[1.0, 0, 0], [0, 0, 1.0]])}, r"v0\[1\]: the initial velocity violates"),
        ({"q0": np.array([[0.0, 0, 0], [np.nan, 0, 0]]), "v0": np.zeros(3)}, r"q0\[1\]: contains NaN"),
        ({"q0": np.zeros((2, 3, 1)), "v0": np.zeros(3)}, r"q0: expected a vector of length 3, got shape \(2, 3, 1\)"),
    ],
)
def test_batch_bad_input_names_argument_and_member(kwargs, pattern):
    particle = gnipy.make_system("nonholonomic-particle")  # constraint ż = y ẋ
    with pytest.raises(gnipy.InputError, match=pattern):
        gnipy.simulate(particle, "gni-trapezoid", h=0.1, steps=2, **kwargs)


def test_batch_rotations_checked_per_member():
    ball = gnipy.make_system("rolling-ball")
    R = np.stack([np.eye(3), np.diag([1.0, 1.0, -1.0])])
    with pytest.raises(gnipy.InputError, match=r"R0\[1\]: not a rotation"):
        gnipy.simulate(ball, "gni-trapezoid", R0=R, h=0.1, steps=2)


def test_systems_must_share_structure():
    a = gnipy.make_system("nonholonomic-particle")
    b = gnipy.make_system("contact-oscillator")
    with pytest.raises(gnipy.InputError, match=r"system\[1\]: a batch of systems must differ only in the values"):
        stack_systems([a, b])
    with pytest.raises(gnipy.InputError, match=r"system\[1\]: expected a gnipy.System"):
        gnipy.simulate([a, "x"], "gni-trapezoid", h=0.1, steps=2)
    with pytest.raises(gnipy.InputError, match=r"params: parameter arrays have different lengths"):
        model_systems("rolling-ball", m=[1.0, 2.0], r=[1.0, 2.0, 3.0])
    with pytest.raises(gnipy.InputError, match=r"unknown parameter 'mass'"):
        model_systems("rolling-ball", mass=[1.0, 2.0])


def test_a_batch_of_different_functions_is_refused_not_run_as_the_first():
    """A batch of systems with other Lagrangians or constraints (plain functions, whose values a
    pytree's structure does not compare) ran every member as system[0] (issue 12, defect 1)."""
    def mu(q):
        return jnp.array([[jnp.sin(q[2]), -jnp.cos(q[2]), 0.0]])

    def mu2(q):
        return jnp.array([[jnp.cos(q[2]), jnp.sin(q[2]), 0.0]])

    def l1(q, v):
        return 0.5 * v @ v

    def l2(q, v):
        return v @ v - q[0]

    q0, v0 = np.zeros(3), np.array([0.0, 0.0, 1.0])
    base = System(l1, mu, n=3)
    for other, what in ((System(l2, mu, n=3), "l2"), (System(l1, mu2, n=3), "mu2")):
        with pytest.raises(gnipy.InputError, match=rf"system\[1\]: a batch of systems .* another function \({what} here"):
            gnipy.simulate([base, other], "gni-midpoint", q0, v0, h=0.1, steps=5)
    # a parameter held as a Python float (not an array leaf) would be silently batched as system[0]'s
    def l_m(m, q, v):
        return 0.5 * m * v @ v

    def scaled(m):
        return System(jax.tree_util.Partial(l_m, m), mu, n=3)

    with pytest.raises(gnipy.InputError, match=r"system\[1\].*Python-number parameter"):
        gnipy.simulate([scaled(1.0), scaled(2.0)], "gni-midpoint", q0, v0, h=0.1, steps=5)
    # the same function with array parameters is a batch, and each member is its own trajectory
    sols = gnipy.simulate([scaled(jnp.asarray(1.0)), scaled(jnp.asarray(2.0))], "gni-midpoint",
                          np.array([0.0, 0.0, 0.0]), np.array([1.0, 0.0, 1.0]), h=0.1, steps=5)
    for i, m in enumerate((1.0, 2.0)):
        one = gnipy.simulate(scaled(jnp.asarray(m)), "gni-midpoint", np.zeros(3), np.array([1.0, 0.0, 1.0]),
                             h=0.1, steps=5)
        np.testing.assert_allclose(np.asarray(sols.q[i]), np.asarray(one.q), rtol=0, atol=1e-14)


def test_reference_is_not_batched():
    particle = gnipy.make_system("nonholonomic-particle")
    with pytest.raises(gnipy.MethodError, match="one trajectory at a time"):
        gnipy.simulate([particle, particle], "reference", h=0.1, steps=2)
