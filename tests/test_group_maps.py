"""A new group is one file: the retractions, the spaces and the GNI work on a group defined here,
through the generic maps of :class:`gnipy.lie_groups.MatrixLieGroup`, with no change elsewhere.

The group is SO(2), the rotations of the plane ($d = 1$, $k = 2$), written with only what a new
group must implement: `dim`, `matrix_size`, `hat`, `vee`. Expected values come from SO(2)'s
closed forms (it is abelian: $\\mathrm{cay}(w)$ is the rotation by $2\\arctan(w/2)$, so
$\\mathrm{dcay}_w = 1/(1 + w^2/4)$; $\\exp(w)$ is the rotation by $w$ and $\\mathrm{dexp}_w = 1$),
from the definitions (eq:dtaudef), (eq:dtauAd) differentiated automatically, from the other groups'
closed forms (in a product), and from an independent formulation: the knife edge on
$\\mathbb{R}^2\\times SO(2)$ with the exp retraction is the knife edge on $\\mathbb{R}^3$ with the
heading as a coordinate, and its exact solution is known.

Compilation: the module runs `simulate` with the check at saved nodes only (CHECK_EVERY_NODE; it
tests numerics, not verdicts), and the convergence test's run at h/2 saves every second step, so
both Cayley runs save 41 nodes and share one program (the errors are compared at the same times
t = 0, 0.1, ..., 4, where the exact solution is evaluated). Summed test time on the shared 2-core
machine (noisy): 24.1 s (full-suite run) -> about 16.5 s.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.scipy.linalg import block_diag

import gnipy
from gnipy.lie_groups import SO3, MatrixLieGroup, ProductGroup
from gnipy.retractions import Cayley, Exp

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py); the check at
#: every node is tested in test_monitor.py and test_diagnostics.py
CHECK_EVERY_NODE = False


class SO2(MatrixLieGroup):
    """The rotations of the plane, with only the required methods (everything else is generic)."""

    @property
    def dim(self):
        return 1

    @property
    def matrix_size(self):
        return 2

    def hat(self, xi):
        w = jnp.asarray(xi, dtype=jnp.float64)[0]
        return jnp.array([[0.0 * w, -w], [w, 0.0 * w]])

    def vee(self, X):
        return jnp.reshape(0.5 * (X[1, 0] - X[0, 1]), (1,))


def rotation(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


# zero, tiny, moderate and large angles (the Cayley map has no singularity on SO(2))
ANGLES = (0.0, 1e-9, 0.3, -1.7, 5.0)


@pytest.mark.parametrize("w", ANGLES)
def test_generic_cayley_is_the_closed_form(w):
    """Through the base class's matrix formulas (Appendix b): cay(w) = rotation by 2 atan(w/2),
    dcay_w = 1/(1 + w²/4), dcay⁻¹_w = 1 + w²/4, dcay⁻¹_w w = w(1 + w²/4), cay⁻¹(cay(w)) = w, and the
    jump dτ⁻¹_{−w} − dτ⁻¹_w = ad_w = 0."""
    G, cay, xi = SO2(), Cayley(), jnp.array([w])
    q = 1.0 + 0.25 * w * w
    np.testing.assert_allclose(cay.tau(G, xi), rotation(2.0 * np.arctan(0.5 * w)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(cay.dtau(G, xi), [[1.0 / q]], rtol=1e-15)
    np.testing.assert_allclose(cay.dtau_inv(G, xi), [[q]], rtol=1e-15)
    np.testing.assert_allclose(cay.dtau_inv_along(G, xi), [w * q], rtol=1e-15)
    np.testing.assert_allclose(cay.tau_inv(G, cay.tau(G, xi)), [w], rtol=1e-14, atol=1e-24)
    assert np.all(np.asarray(cay.dtau_inv_jump(G, xi)) == 0.0)


@pytest.mark.parametrize("w", ANGLES)
def test_generic_exp_is_the_closed_form(w):
    """Through `expm` and the paper's series (Appendix a): exp(w) = rotation by w and, ad being 0,
    dexp = dexp⁻¹ = 1 exactly; `log` has no generic form, so the exp retraction's τ⁻¹ needs one."""
    G, ex, xi = SO2(), Exp(), jnp.array([w])
    np.testing.assert_allclose(ex.tau(G, xi), rotation(w), rtol=0, atol=4e-15)
    assert float(ex.dtau(G, xi)[0, 0]) == 1.0 and float(ex.dtau_inv(G, xi)[0, 0]) == 1.0
    np.testing.assert_array_equal(ex.dtau_inv_along(G, xi), [w])
    with pytest.raises(NotImplementedError, match="SO2.log"):
        ex.tau_inv(G, ex.tau(G, xi))


@pytest.mark.parametrize("retraction", [Cayley(), Exp()], ids=["cayley", "exp"])
def test_generic_tangents_satisfy_the_definitions(retraction):
    """(eq:dtaudef): dτ_w = (∂τ/∂w τ(w)⁻¹)^∨ by automatic differentiation; dτ⁻¹ is its inverse;
    (eq:dtauAd): dτ_w = Ad_{τ(w)} dτ_{−w} with the generic Ad; no NaN derivatives at 0."""
    G = SO2()
    for w in ANGLES:
        xi = jnp.array([w])
        J = jax.jacfwd(lambda x: retraction.tau(G, x))(xi)[:, :, 0]
        by_definition = G.vee(J @ jnp.linalg.inv(retraction.tau(G, xi)))
        dtau = retraction.dtau(G, xi)
        np.testing.assert_allclose(dtau[:, 0], by_definition, rtol=0, atol=2e-15)
        np.testing.assert_allclose(dtau @ retraction.dtau_inv(G, xi), [[1.0]], rtol=0, atol=2e-15)
        np.testing.assert_allclose(dtau, G.Ad(retraction.tau(G, xi)) @ retraction.dtau(G, -xi), rtol=0, atol=2e-15)
    grads = jax.jacfwd(lambda x: retraction.dtau_inv(G, x))(jnp.zeros(1))
    assert np.all(np.isfinite(np.asarray(grads)))


def test_product_combines_the_new_group_with_closed_forms():
    """SO(2) × SO(3): each retraction's maps are the factors' blocks, the generic SO(2) block beside
    the closed-form SO(3) block."""
    so2, so3 = SO2(), SO3()
    P = ProductGroup(so2, so3)
    xi = jnp.array([0.8, 0.3, -0.5, 1.1])
    for r in (Cayley(), Exp()):
        for f in ("tau", "dtau", "dtau_inv"):
            expected = block_diag(getattr(r, f)(so2, xi[:1]), getattr(r, f)(so3, xi[1:]))
            np.testing.assert_array_equal(getattr(r, f)(P, xi), expected)
        np.testing.assert_array_equal(r.dtau_inv_along(P, xi),
                                      jnp.concatenate([r.dtau_inv_along(so2, xi[:1]), r.dtau_inv_along(so3, xi[1:])]))
    g = Cayley().tau(P, xi)
    np.testing.assert_allclose(Cayley().tau_inv(P, g), xi, rtol=0, atol=1e-15)


# The knife edge: mass M, moment of inertia I, heading θ; the blade does not slip sideways.
M, I = 1.3, 0.7
TH0, OMEGA = 0.4, 0.9
V0 = np.array([np.cos(TH0), np.sin(TH0), OMEGA])  # unit speed along the blade, turning at OMEGA
H, STEPS = 0.1, 40


def _kinetic(v):
    return 0.5 * M * (v[0] ** 2 + v[1] ** 2) + 0.5 * I * v[2] ** 2


def _knife_edge_on_group(retraction):
    """Q = R² × SO(2), v = (ẋ, ẏ, ω): the constraint −sinθ ẋ + cosθ ẏ = 0 reads θ from R."""
    return gnipy.System(lambda x, R, v: _kinetic(v), lambda x, R: jnp.array([[-R[1, 0], R[0, 0], 0.0]]),
                        n=2, group=SO2(), retraction=retraction, depends_on_orientation=True, name="knife-edge-so2")


def _heading(sol):
    R = np.asarray(sol.R)
    return np.arctan2(R[:, 1, 0], R[:, 0, 0])


def _angle_error(a, b):
    return np.max(np.abs(np.angle(np.exp(1j * (a - b)))))


def test_gni_runs_on_the_new_group():
    """The GNI on R² × SO(2) with the exp retraction is the GNI on R³ with θ a coordinate (exp on
    SO(2) adds angles, dexp⁻¹ = 1): the two agree to round-off; with the Cayley retraction it
    converges to the exact solution θ = θ₀ + ωt, (x, y) on a circle of radius 1/ω, at order 2; both
    keep the constraint to round-off."""
    flat = gnipy.System(lambda q, v: _kinetic(v), lambda q: jnp.array([[-jnp.sin(q[2]), jnp.cos(q[2]), 0.0]]),
                        n=3, name="knife-edge-r3")
    R0 = rotation(TH0)
    on_group = gnipy.simulate(_knife_edge_on_group("exp"), "gni-midpoint", np.zeros(2), V0, R0=R0, h=H, steps=STEPS)
    on_r3 = gnipy.simulate(flat, "gni-midpoint", np.array([0.0, 0.0, TH0]), V0, h=H, steps=STEPS)
    assert on_group.success and on_r3.success
    np.testing.assert_allclose(on_group.q, np.asarray(on_r3.q)[:, :2], rtol=0, atol=1e-13)
    np.testing.assert_allclose(on_group.v, on_r3.v, rtol=0, atol=1e-13)
    assert _angle_error(_heading(on_group), np.asarray(on_r3.q)[:, 2]) <= 1e-13

    cayley = _knife_edge_on_group("cayley")
    errors = []
    # both runs save the same 41 nodes (every second step at h/2): one compiled program
    for h, steps, every in ((H, STEPS, 1), (H / 2, 2 * STEPS, 2)):
        sol = gnipy.simulate(cayley, "gni-midpoint", np.zeros(2), V0, R0=R0, h=h, steps=steps, save_every=every)
        assert sol.success
        assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-14
        t = np.asarray(sol.t)
        th = TH0 + OMEGA * t
        xy = np.stack([np.sin(th) - np.sin(TH0), np.cos(TH0) - np.cos(th)], axis=1) / OMEGA
        errors.append(max(_angle_error(_heading(sol), th), np.max(np.abs(np.asarray(sol.q) - xy))))
    assert 3.5 <= errors[0] / errors[1] <= 4.5, errors
