"""System construction and validation: every bad input gets a clear error naming the argument."""

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import System, InputError


def _particle(**kw):
    return System(
        lambda q, v: 0.5 * v @ v - 0.5 * (q[0] ** 2 + q[1] ** 2),
        lambda q: jnp.array([[-q[1], 0.0, 1.0]]),
        n=3,
        **kw,
    )


def test_derived_quantities_match_hand_computation():
    # l = ½(1+x²)ẋ² + ½ẏ² + ½ż² − V: metric diag(1+x², 1, 1), V = x y
    sys_ = System(
        lambda q, v: 0.5 * (1 + q[0] ** 2) * v[0] ** 2 + 0.5 * v[1] ** 2 + 0.5 * v[2] ** 2 - q[0] * q[1],
        lambda q: jnp.array([[-q[1], 0.0, 1.0]]),
        lambda q: jnp.array([q[1], 0.0, 0.0]),
        n=3,
    )
    q = jnp.array([0.5, -2.0, 1.0])
    v = jnp.array([1.0, 2.0, 3.0])
    G = np.diag([1.25, 1.0, 1.0])
    np.testing.assert_allclose(sys_.metric(q), G, rtol=0, atol=1e-15)
    assert float(sys_.potential(q)) == pytest.approx(-1.0, abs=1e-15)
    np.testing.assert_allclose(sys_.potential_gradient(q), [-2.0, 0.5, 0.0], atol=1e-15)
    np.testing.assert_allclose(sys_.momentum(q, v), G @ np.asarray(v), atol=1e-15)
    np.testing.assert_allclose(sys_.Pi(q), G @ np.array([-2.0, 0.0, 0.0]), atol=1e-15)
    # μ(v − Y) = −y(ẋ − y) + ż = 2(1 + 2) + 3
    np.testing.assert_allclose(sys_.constraint_residual(q, v), [9.0], atol=1e-14)
    assert float(sys_.energy(q, v)) == pytest.approx(0.5 * 1.25 + 0.5 * 4 + 0.5 * 9 - 1.0, abs=1e-14)
    assert not sys_.has_constant_metric(q)
    assert _particle().has_constant_metric(q)


def test_lagrangian_not_quadratic_in_v():
    bad = System(lambda q, v: 0.25 * jnp.sum(v**4) + 0.5 * v @ v, lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3)
    with pytest.raises(InputError, match=r"lagrangian: not of mechanical type"):
        bad.check(jnp.zeros(3), jnp.array([1.0, 1.0, 0.0]))


def test_lagrangian_with_linear_term():
    bad = System(lambda q, v: 0.5 * v @ v + q[0] * v[1], lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3)
    with pytest.raises(InputError, match=r"linear term"):
        bad.check(jnp.array([1.0, 0.0, 0.0]), jnp.array([1.0, 1.0, 0.0]))


def test_indefinite_and_singular_metric():
    indefinite = System(lambda q, v: 0.5 * (v[0] ** 2 - v[1] ** 2 + v[2] ** 2), lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3)
    with pytest.raises(InputError, match=r"not positive definite"):
        indefinite.check(jnp.zeros(3), jnp.zeros(3))
    singular = System(lambda q, v: 0.5 * (v[0] ** 2 + v[2] ** 2), lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3)
    with pytest.raises(InputError, match=r"not positive definite"):
        singular.check(jnp.zeros(3), jnp.zeros(3))


def test_rank_deficient_constraints():
    bad = System(lambda q, v: 0.5 * v @ v, lambda q: jnp.array([[1.0, q[1], 0.0], [2.0, 2 * q[1], 0.0]]), n=3)
    with pytest.raises(InputError, match=r"constraints: mu\(q0\) is rank deficient"):
        bad.check(jnp.ones(3), jnp.zeros(3))


def test_too_many_constraints_and_wrong_shape():
    full = System(lambda q, v: 0.5 * v @ v, lambda q: jnp.eye(2), n=2)
    with pytest.raises(InputError, match=r"constraints:"):
        full.check(jnp.zeros(2), jnp.zeros(2))
    wrong = System(lambda q, v: 0.5 * v @ v, lambda q: jnp.ones((1, 2)), n=3)
    with pytest.raises(InputError, match=r"shape"):
        wrong.check(jnp.zeros(3), jnp.zeros(3))


def test_no_constraints_is_a_clear_error():
    """mu(q) of shape (0, N) gave an IndexError (issue 12, defect 13)."""
    none = System(lambda q, v: 0.5 * v @ v, lambda q: jnp.zeros((0, 3)), n=3)
    with pytest.raises(InputError, match=r"constraints: mu\(q0\) has no rows \(shape \(0, 3\)\)"):
        gnipy.simulate(none, "gni-midpoint", np.zeros(3), np.ones(3), h=0.1, steps=3)


def test_float32_mode_is_named_not_blamed_on_the_lagrangian():
    """With jax_enable_x64 turned off after import, the Lagrangian was refused as 'not of
    mechanical type' (issue 12, defect 13); the message now names the setting."""
    import jax

    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(InputError, match=r"jax_enable_x64: gnipy computes in float64"):
            gnipy.simulate(_particle(), "gni-trapezoid", [0.0, 1.0, 0.0], [1.0, 0.0, 1.0], h=0.1, steps=2)
    finally:
        jax.config.update("jax_enable_x64", True)
    sol = gnipy.simulate(_particle(), "gni-trapezoid", [0.0, 1.0, 0.0], [1.0, 0.0, 1.0], h=0.1, steps=2)
    assert sol.q.dtype == np.float64


def test_initial_velocity_off_constraints_reports_residual():
    s = _particle()
    with pytest.raises(InputError, match=r"v0: .*residual 5\.000e-01"):
        s.check(jnp.array([0.0, 1.0, 0.0]), jnp.array([1.0, 0.0, 0.5]))


def test_project_v0_is_the_metric_orthogonal_projection():
    # affine constraints with a non-identity metric; compare with the KKT solution of
    # min (v − v0)ᵀG(v − v0) subject to μ v = μ Y (an independent formulation)
    Gm = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 1.5]])
    s = System(
        lambda q, v: 0.5 * v @ jnp.asarray(Gm) @ v,
        lambda q: jnp.array([[1.0, q[1], 0.0]]),
        lambda q: jnp.array([0.0, 0.0, q[0]]),
        n=3,
    )
    q0 = np.array([0.7, 2.0, -1.0])
    v0 = np.array([1.0, -0.5, 0.25])
    _, vp = s.check(q0, v0, project_v0=True)
    mu = np.array([[1.0, 2.0, 0.0]])
    Y = np.array([0.0, 0.0, 0.7])
    K = np.block([[Gm, mu.T], [mu, np.zeros((1, 1))]])
    rhs = np.concatenate([Gm @ v0, mu @ Y])
    expected = np.linalg.solve(K, rhs)[:3]
    np.testing.assert_allclose(vp, expected, rtol=1e-13, atol=1e-14)
    assert np.max(np.abs(mu @ (vp - Y))) < 1e-14


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [
        (dict(q0=[0.0, 1.0]), r"q0: expected a vector of length 3"),
        (dict(q0=[0.0, np.nan, 0.0]), r"q0: contains NaN"),
        (dict(v0=[np.inf, 0.0, 0.0]), r"v0: contains NaN or infinite"),
        (dict(h=0.0), r"h: must be nonzero \(h > 0 runs forward in time, h < 0 backward\)"),
        (dict(h=-0.1, steps=None, t_final=1.0), r"t_final: must be before t0 = 0.0 for h = -0.1"),
        (dict(h=float("nan")), r"h: must be a finite number"),
        (dict(steps=0), r"steps: must be a positive integer"),
        (dict(steps=2.5), r"steps: must be a positive integer"),
        (dict(steps=None, t_final=0.005), r"t_final: the run 0.005 is shorter than one step"),
        (dict(saveat=gnipy.SaveAt(every=2), save_every=2), r"saveat/save_every: give one of them"),
        (dict(saveat=gnipy.SaveAt(ts=[0.015])), r"saveat.ts: 0.015 is not a node t0 \+ k h"),
        (dict(saveat=gnipy.SaveAt(ts=[0.5])), r"saveat.ts: 0.5 lies outside the run"),
        (dict(progress="yes"), r"progress: expected True, False or a callable"),
        (dict(steps=None), r"give exactly one of steps and t_final"),
        (dict(save_every=0), r"save_every: must be a positive integer"),
        # issue 12: these gave an OverflowError, or dropped an imaginary part with only a warning
        (dict(h=1e-320, steps=None, t_final=10.0), r"h: 1e-320 is below 2.22507e-308"),
        (dict(h=1e-300, steps=None, t_final=10.0), r"t_final: 10.0 / h = 1e\+301 steps, more than any run"),
        (dict(h=1e-320), r"h: 1e-320 is below"),
        (dict(h=10**400), r"h: expected a number"),
        (dict(h=0.1 + 0j), r"h: expected a real number"),
        (dict(steps=10**20), r"steps: 100000000000000000000 steps is more than any run can take"),
        (dict(steps=None, t_final=1e300), r"t_final: 1e\+300 / h = .* more than any run"),
        (dict(q0=np.array([0.0, 1.0, 0.0]) + 0j), r"q0: expected 3 real numbers, got complex values"),
        (dict(v0=np.array([1.0, 0.0, 1.0]) + 1e-3j), r"v0: expected 3 real numbers, got complex values"),
        (dict(q0=np.zeros((2, 3)) + 1j), r"q0: expected real numbers, got complex values"),
    ],
)
def test_simulate_rejects_bad_arguments(kwargs, pattern):
    args = dict(q0=[0.0, 1.0, 0.0], v0=[1.0, 0.0, 1.0], h=0.01, steps=10)
    args.update(kwargs)
    with pytest.raises(InputError, match=pattern):
        gnipy.simulate(_particle(), "gni-trapezoid", **args)


def test_unknown_method_and_model():
    with pytest.raises(gnipy.MethodError, match=r"method: unknown method 'nope'"):
        gnipy.simulate(_particle(), "nope", [0.0, 1.0, 0.0], [1.0, 0.0, 1.0], h=0.1, steps=1)
    with pytest.raises(InputError, match=r"model: unknown model 'nope'"):
        gnipy.make_system("nope")
    with pytest.raises(InputError, match=r"unknown parameter 'kk'"):
        gnipy.make_system("nonholonomic-particle", kk=1.0)


def test_constructor_errors():
    with pytest.raises(InputError, match=r"lagrangian: expected a callable"):
        System(1.0, lambda q: q, n=2)
    with pytest.raises(InputError, match=r"n: give the dimension"):
        System(lambda q, v: 0.0, lambda q: q)
    with pytest.raises(InputError, match=r"coordinates: expected 3 names"):
        System(lambda q, v: 0.0, lambda q: q, n=3, coordinates=("x", "y"))
