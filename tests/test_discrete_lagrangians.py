"""Discrete Lagrangians and their Legendre transforms against hand-derived formulas."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import GNI, CustomDiscreteLagrangian, EulerA, EulerB, Midpoint, Trapezoid

M = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 3.0]])


def V(q):
    return jnp.sin(q[0]) * q[1] + 0.5 * q[2] ** 2


def _system():
    return gnipy.System(
        lambda q, v: 0.5 * v @ jnp.asarray(M) @ v - V(q),
        lambda q: jnp.array([[-q[1], 0.0, 1.0]]),
        n=3,
    )


@pytest.mark.parametrize(
    ("ld", "minus", "plus"),
    [
        # (LagEuler), (Verlet) and the midpoint rule: FL⁻ = −∂l_d/∂q0, FL⁺ = ∂l_d/∂q1
        (EulerA(), lambda d, q0, q1, h, g: M @ d + h * g(q0), lambda d, q0, q1, h, g: M @ d),
        (EulerB(), lambda d, q0, q1, h, g: M @ d, lambda d, q0, q1, h, g: M @ d - h * g(q1)),
        (Trapezoid(), lambda d, q0, q1, h, g: M @ d + h / 2 * g(q0), lambda d, q0, q1, h, g: M @ d - h / 2 * g(q1)),
        (Midpoint(), lambda d, q0, q1, h, g: M @ d + h / 2 * g((q0 + q1) / 2),
         lambda d, q0, q1, h, g: M @ d - h / 2 * g((q0 + q1) / 2)),
    ],
)
def test_legendre_transforms_match_hand_formulas(ld, minus, plus):
    s = _system()
    rng = np.random.default_rng(3)
    q0, q1 = rng.standard_normal(3), rng.standard_normal(3)
    h = 0.1
    d = (q1 - q0) / h
    g = lambda q: np.asarray(jax.grad(V)(jnp.asarray(q)))  # noqa: E731

    def fn(a, b):
        return ld(s, a, b, h)

    dq = jnp.asarray(q1 - q0)  # the step unknown is the increment (gnipy.spaces)
    fm = np.asarray(s.space.legendre_minus(fn, jnp.asarray(q0), dq))
    fp = np.asarray(s.space.legendre_plus(fn, jnp.asarray(q0), dq))
    np.testing.assert_allclose(np.asarray(s.space.legendre_jump(fn, jnp.asarray(q0), dq)), fp - fm, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(fm, minus(d, q0, q1, h, g), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(fp, plus(d, q0, q1, h, g), rtol=1e-13, atol=1e-13)


def test_custom_discrete_lagrangian_and_explicit_flag():
    s = _system()
    q0, v0 = [0.3, 1.0, 0.0], [1.0, 0.5, 1.0]

    def trapezoid_by_hand(a, b, h):
        d = (b - a) / h
        return h * 0.5 * d @ jnp.asarray(M) @ d - h / 2 * (V(a) + V(b))

    kw = dict(h=0.05, steps=200, save_every=200)
    ref = gnipy.simulate(s, GNI(Trapezoid()), q0, v0, **kw)
    newton = gnipy.simulate(s, GNI(Trapezoid(), explicit=False), q0, v0, **kw)
    custom = gnipy.simulate(s, GNI(CustomDiscreteLagrangian(trapezoid_by_hand)), q0, v0, **kw)
    custom_explicit = gnipy.simulate(s, GNI(CustomDiscreteLagrangian(trapezoid_by_hand, explicit=True)), q0, v0, **kw)
    assert int(ref.iterations[1]) == 1 and int(custom_explicit.iterations[1]) == 1  # one linear solve
    assert int(newton.iterations[1]) >= 2 and int(custom.iterations[1]) >= 2  # Newton iterations
    for other in (newton, custom, custom_explicit):
        np.testing.assert_allclose(np.asarray(other.q), np.asarray(ref.q), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(other.v), np.asarray(ref.v), rtol=1e-12, atol=1e-12)
