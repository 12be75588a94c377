"""Which quantities a fit determines (`gnipy.control.fit_result.uncertainties`' rule, through
`gnipy.fit`), on a disk whose physics fixes only a combination of them.

The vertical disk (`vertical-disk`) driven from rest by a torque u on its rolling angle θ obeys
$(m r^2 + I_{rot})\\ddot\\theta = u$ and $x = r\\theta$ (φ stays 0): observed in θ alone, its motion
fixes $m r^2 + I_{rot}$ and nothing else; observed in x too, it fixes r as well. At h = 0.05 the
GNI's discrete motion depends on m and I_rot apart at the level of its discretization error,
which the rule must not take for information. The references are this physics (which quantities
and which combination, whose gradient $(r^2, 2mr, 1)$ at the estimate is the expected combination)
and the data's true parameters; none is taken from an earlier fit.
"""

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.control import Observations, fit

H, STEPS = 0.05, 60
TRUE = {"m": 1.0, "r": 1.0, "I_flip": 1.0, "I_rot": 1.0}
K = np.arange(2, STEPS + 1, 2)
U = (1.0 + 0.5 * np.sin(0.3 * np.arange(STEPS)))[:, None]
REST = np.zeros(4)


def build(p):
    """The vertical disk with a torque on its rolling angle (a user's build: no default bounds)."""
    return gnipy.make_system("vertical-disk", **p).with_force(
        lambda q, v, u, t: jnp.array([0.0, 0.0, 0.0, u[0]]), inputs=1)


@pytest.fixture(scope="module")
def truth():
    run = gnipy.simulate(build({k: jnp.float64(v) for k, v in TRUE.items()}), "gni-trapezoid", REST, REST, h=H,
                         steps=STEPS, controls=U)
    return np.asarray(run.q)[K]


def disk_fit(values, variables, params, fixed, **kw):
    return fit(build, Observations(H * K, values, variables), params=params, fixed=fixed, h=H, q0=REST, v0=REST,
               controls=U, method="gni-trapezoid", **kw)


def test_a_split_seen_only_through_the_discretization_error_is_not_determined(truth):
    """sigma = 1e-6: the noise alone would call m and I_rot determined (their split moves the
    discrete predictions by hundreds of sigmas); the discretization's part says it is an artefact,
    and the data determine m r² + I_rot, reported with gradient (r², 1) = (1, 1) (r = 1)."""
    sigma = 1e-6
    noise = sigma * np.random.default_rng(1).standard_normal((K.size, 1))
    res = disk_fit(truth[:, 3:4] + noise, ("theta",), {"m": 0.8, "I_rot": 1.2}, {"r": 1.0, "I_flip": 1.0},
                   sigma=sigma)
    assert res.rank == 2 and res.determined == 1
    assert not res.identifiable.any() and np.all(np.isinf(res.stderr))
    # the noise alone would have determined the split: its singular value is far above 1 sigma
    S = np.linalg.svd(res.jacobian * np.abs(res.values)[None, :], compute_uv=False)
    assert S[1] > 10.0
    assert res.discretization > 10.0  # in sigmas: the discretization error is far above the noise
    (combo,) = res.combinations
    assert set(combo.coefficients) == {"m", "I_rot"}
    np.testing.assert_allclose([combo.coefficients["m"], combo.coefficients["I_rot"]], [1.0, 1.0], rtol=1e-4)
    # m + I_rot = 2 in the data, within the combination's stated error
    assert abs(res.params["m"] + res.params["I_rot"] - 2.0) < 5 * combo.stderr
    assert "do not determine m, I_rot" in res.message and "they determine" in res.message


def test_the_combination_of_a_radius_and_an_inertia_is_the_gradient_of_m_r2_plus_I(truth):
    """m = 1 held, r and I_rot estimated from θ: the determined combination is the gradient
    (2 m r, 1) of m r² + I_rot at the estimate, normalized."""
    noise = 1e-3 * np.random.default_rng(2).standard_normal((K.size, 1))
    res = disk_fit(truth[:, 3:4] + noise, ("theta",), {"r": 0.8, "I_rot": 1.2}, {"m": 1.0, "I_flip": 1.0},
                   sigma=1e-3)
    assert not res.identifiable.any()
    (combo,) = res.combinations
    r = res.params["r"]
    grad = np.array([2 * 1.0 * r, 1.0])
    np.testing.assert_allclose([combo.coefficients["r"], combo.coefficients["I_rot"]], grad / np.abs(grad).max(),
                               rtol=1e-4)


def test_a_quantity_the_data_do_fix_stays_identifiable_beside_those_they_do_not(truth):
    """x and θ observed: x = r θ fixes r; m and I_rot only through m r² + I_rot."""
    sigma = 1e-4
    noise = sigma * np.random.default_rng(3).standard_normal((K.size, 2))
    res = disk_fit(truth[:, [0, 3]] + noise, ("x", "theta"), {"m": 0.8, "r": 1.1, "I_rot": 1.2}, {"I_flip": 1.0},
                   sigma=sigma)
    ident = dict(zip(res.names, res.identifiable))
    assert ident == {"m": False, "r": True, "I_rot": False}
    assert abs(res.params["r"] - 1.0) < 5 * res.standard_errors["r"]
    (combo,) = res.combinations
    r = res.params["r"]
    np.testing.assert_allclose([combo.coefficients["m"], combo.coefficients["I_rot"]],
                               np.array([r * r, 1.0]) / max(r * r, 1.0), rtol=1e-4)
