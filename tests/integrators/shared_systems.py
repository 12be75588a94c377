"""Test systems shared by the integrator tests: linear constraints (the registered nonholonomic
particle), affine constraints with a potential (a ball on a rotating table with a spring), and a
position-dependent metric (every GNI variant then takes the implicit Newton path)."""

import dataclasses

import jax.numpy as jnp
import numpy as np

import gnipy

PARTICLE = gnipy.make_system("nonholonomic-particle")  # l = ½|v|² − ½(x²+y²), ż = y ẋ
PARTICLE_Q0 = np.array([1.0, 1.0, 0.0])
PARTICLE_V0 = np.array([1.0, 0.5, 1.0])  # ż = y ẋ

# Ball on a table rotating at rate Ω, q = (x, y, θ1, θ2, θ3), θ̇ = ω:
# l = ½m(ẋ²+ẏ²) + ½I|ω|² − ½k(x²+y²); ẋ − rω₂ + Ωy = 0, ẏ + rω₁ − Ωx = 0; Y = (−Ωy, Ωx, 0, 0, 0).
B_M, B_I, B_R, B_OMEGA, B_K = 1.0, 0.4, 1.0, 0.7, 1.0


def _ball_lagrangian(q, v):
    return 0.5 * B_M * (v[0] ** 2 + v[1] ** 2) + 0.5 * B_I * (v[2:] @ v[2:]) - 0.5 * B_K * (q[0] ** 2 + q[1] ** 2)


def _ball_mu(q):
    return jnp.array([[1.0, 0.0, 0.0, -B_R, 0.0], [0.0, 1.0, B_R, 0.0, 0.0]], dtype=q.dtype)


def _ball_Y(q):
    z = jnp.zeros_like(q[0])
    return jnp.stack([-B_OMEGA * q[1], B_OMEGA * q[0], z, z, z])


BALL = gnipy.System(_ball_lagrangian, _ball_mu, _ball_Y, n=5, name="ball-on-rotating-table-test")
BALL_Q0 = np.array([1.0, 0.5, 0.0, 0.0, 0.0])
_w = np.array([0.3, -0.2, 0.5])
BALL_V0 = np.array([B_R * _w[1] - B_OMEGA * BALL_Q0[1], -B_R * _w[0] + B_OMEGA * BALL_Q0[0], *_w])


# l = ½(1+x²)ẋ² + ½ẏ² + ½ż² − ½(x²+y²), constraint ż = y ẋ
def _curved_lagrangian(q, v):
    return 0.5 * (1.0 + q[0] ** 2) * v[0] ** 2 + 0.5 * (v[1] ** 2 + v[2] ** 2) - 0.5 * (q[0] ** 2 + q[1] ** 2)


def _curved_mu(q):
    return jnp.stack([-q[1], jnp.zeros_like(q[1]), jnp.ones_like(q[1])])[None, :]


CURVED = gnipy.System(_curved_lagrangian, _curved_mu, n=3, name="curved-particle-test")
CURVED_Q0 = np.array([0.5, 1.0, 0.0])
CURVED_V0 = np.array([1.0, 0.3, 1.0])


def cached_runner(cases, h, steps):
    """`run(case, method, start=None)`: a cached `gnipy.simulate` of `steps` steps of size h, every
    node saved; `start` sets a GNI's starting impulse (`"rest"`: the paper's)."""
    cache: dict = {}

    def _run(case, method, start=None):
        if (case, method, start) not in cache:
            system, q0, v0 = cases[case]
            m = method if start is None else dataclasses.replace(gnipy.get_method(method), start=start)
            cache[case, method, start] = gnipy.simulate(system, m, q0, v0, h=h, steps=steps)
        return cache[case, method, start]

    return _run
