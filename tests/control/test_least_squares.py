"""The least-squares problem of a fit (`gnipy.control.least_squares`): how a held or estimated
`v0` is moved onto the constraints. The reference is the closed-form smallest change."""

import jax.numpy as jnp
import numpy as np

import gnipy
from gnipy.control.least_squares import admissible_velocity


def test_a_held_velocity_is_moved_onto_the_constraints_independently_of_the_masses():
    """The disk's constraints ẋ = r cosφ θ̇, ẏ = r sinφ θ̇ at φ = 0: the smallest change of
    (1, 0, 1, 1) is θ̇ = (r + 1)/(r² + 1), ẋ = r θ̇ (minimize (ẋ - 1)² + (θ̇ - 1)²), whatever the
    masses; an admissible velocity is kept."""
    v = jnp.array([1.0, 0.0, 1.0, 1.0])
    for m, I_rot in ((1.0, 1.0), (10.0, 0.1)):
        s = gnipy.make_system("vertical-disk", m=m, r=0.9, I_rot=I_rot)
        out = np.asarray(admissible_velocity(s, jnp.zeros(4), v))
        th = (0.9 + 1.0) / (0.81 + 1.0)
        np.testing.assert_allclose(out, [0.9 * th, 0.0, 1.0, th], rtol=1e-14)
        s1 = gnipy.make_system("vertical-disk", m=m, r=1.0, I_rot=I_rot)
        np.testing.assert_allclose(np.asarray(admissible_velocity(s1, jnp.zeros(4), v)), v, rtol=0, atol=1e-15)
