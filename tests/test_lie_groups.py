"""Tests of gnipy.lie_groups: the mathematics of each group, checked on random and near-identity samples.

Every expected value comes from an identity (group axioms, $g\\exp(\\xi)g^{-1} = \\exp(\\mathrm{Ad}_g\\xi)$,
Jacobi, ...), from an independent formulation (the matrix exponential `expm`, the generic
base-class implementations), or from automatic differentiation / finite differences of a definition.
To keep compile time small, the identities are evaluated by one jitted, vmapped function whose
result is shared by the tests, on one group: the product SO(3) × SE(2) × R² × E, whose every map
(hat, vee, exp, log, Ad, ad, ad*, inverse, basis) is its factors' own, block by block
(`gnipy.lie_groups.product`). Its samples give every factor's block each magnitude of MAGNITUDES
as its own norm (`group_checks.factorwise_samples`), and relative errors are taken per factor, so
that each factor is checked exactly as on its own; the factors' own facts (SO(3), SE(2), R^n, the
trivial group) are checked separately below.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from group_checks import maxabs as _maxabs
from group_checks import factorwise_relative, factorwise_samples, membership_error, run_once, series_expm
from hypothesis import example, given, settings
from hypothesis import strategies as st
from jax.scipy.linalg import block_diag

import gnipy  # noqa: F401  (float64)
from gnipy.lie_groups import SE2, SO3, MatrixLieGroup, ProductGroup, Rn, TrivialGroup

GROUPS = {
    "SO3": SO3(),
    "SE2": SE2(),
    "R3": Rn(3),
    "SO3xSE2xR2xE": ProductGroup(SO3(), SE2(), Rn(2), TrivialGroup()),
}
#: the group whose identities are checked: every other group of GROUPS is one of its factors
#: (R^n for n = 2; its maps do not depend on n)
PRODUCT = "SO3xSE2xR2xE"


def expm(X):
    """Reference matrix exponential, independent of the groups' closed forms (round-off accurate for
    |X| ≲ 10)."""
    return series_expm(X, squarings=5, terms=18)


# Magnitudes of the algebra samples: exact zero, tiny values (Taylor branches), both sides of each
# branch switch (|θ| = 0.0633 for the SO(3) log, 0.5 and 1 for the series in θ² and (θ/2)²), and
# large values below π (so that log∘exp is the identity).
MAGNITUDES = np.array([0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.06, 0.07, 0.3, 0.49, 0.51, 0.99, 1.01, 2.0, 3.0])
N_DIRECTIONS = 6
N_RANDOM = 32


@functools.cache
def identity_errors(name):
    """Errors of every identity checked per sample, for one product group (numpy arrays, one per
    identity)."""
    group = GROUPS[name]
    d, k = group.dim, group.matrix_size
    e = group.identity()

    def per_sample(xi, eta, zeta, g1, g2, g3):
        X = group.hat(xi)
        def br(a, b):
            return group.vee(group.hat(a) @ group.hat(b) - group.hat(b) @ group.hat(a))

        ad = group.ad
        out = {
            "vee_hat": _maxabs(group.vee(X) - xi),
            "vee_generic": _maxabs(MatrixLieGroup.vee(group, X) - xi),
            "associativity": _maxabs((g1 @ g2) @ g3 - g1 @ (g2 @ g3)),
            "identity": jnp.maximum(_maxabs(group.compose(e, g1) - g1), _maxabs(group.compose(g1, e) - g1)),
            "inverse": jnp.maximum(_maxabs(g1 @ group.inverse(g1) - e), _maxabs(group.inverse(g1) @ g1 - e)),
            "inverse_vs_linalg": _maxabs(group.inverse(g1) - jnp.linalg.inv(g1)),
            "member_element": membership_error(group, g1),
            "member_product": membership_error(group, g1 @ group.inverse(g2)),
            "member_exp": membership_error(group, group.exp(xi)),
            "exp_vs_expm": _maxabs(group.exp(xi) - expm(X)),
            # relative error of log∘exp (|ξ_f| < π), per factor: exercises the log's Taylor branch at tiny |ξ_f|
            "log_exp_rel": factorwise_relative(group, group.log(group.exp(xi)) - xi, xi),
            "exp_log": _maxabs(group.exp(group.log(g1)) - g1),
            "Ad_exp": _maxabs(g1 @ group.exp(eta) @ group.inverse(g1) - group.exp(group.Ad(g1) @ eta)),
            "Ad_generic": _maxabs(group.Ad(g1) - MatrixLieGroup.Ad(group, g1)),
            "Ad_homomorphism": _maxabs(group.Ad(g1 @ g2) - group.Ad(g1) @ group.Ad(g2)),
            "Ad_inverse": _maxabs(group.Ad(group.inverse(g1)) @ group.Ad(g1) - jnp.eye(d)),
            "Ad_of_exp": _maxabs(group.Ad(group.exp(xi)) - expm(ad(xi))),
            "ad_definition": _maxabs(ad(xi) @ eta - br(xi, eta)),
            "ad_generic": _maxabs(ad(xi) - MatrixLieGroup.ad(group, xi)),
            "ad_antisymmetry": _maxabs(ad(xi) @ eta + ad(eta) @ xi),
            "jacobi": _maxabs(ad(xi) @ (ad(eta) @ zeta) + ad(eta) @ (ad(zeta) @ xi) + ad(zeta) @ (ad(xi) @ eta)),
            "ad_star": _maxabs(group.ad_star(xi, eta) - ad(xi).T @ eta),
            # the derivative of Ad_{exp(tξ)} at t = 0 is ad_ξ (automatic differentiation)
            "dAd_dt": _maxabs(jax.jacfwd(lambda t: group.Ad(group.exp(t * eta)))(0.0) - ad(eta)),
        }
        return out

    # samples drawn with numpy (sampling inside jit or eagerly in JAX costs more than the checks);
    # random elements are exp of wide Gaussian vectors (exp is onto for these connected groups)
    rng = np.random.default_rng(sorted(GROUPS).index(name))
    xi, _ = factorwise_samples(group, MAGNITUDES, N_DIRECTIONS, rng)
    n = xi.shape[0]
    eta, zeta = rng.standard_normal((2, n, d))
    def checks(xi, eta, zeta, a):
        out = jax.vmap(per_sample)(xi, eta, zeta, *jax.vmap(jax.vmap(group.exp))(a))
        # in the same compiled program (eagerly, these few calls cost more than the program)
        out["basis"] = _maxabs(group.basis() - jax.vmap(group.hat)(jnp.eye(d)))
        out["identity_shape_ok"] = jnp.asarray(group.identity().shape == (k, k))
        return out

    res = run_once(checks, xi, eta, zeta, 1.5 * rng.standard_normal((3, n, d)))
    res = {key: np.asarray(v) for key, v in res.items()}
    assert res.pop("identity_shape_ok")
    return res


# tolerance of each identity (entries are O(1): random elements have |t| ~ 1, |ξ| ≤ 3)
TOLERANCES = {
    "vee_hat": 0.0,
    "vee_generic": 1e-15,
    "associativity": 1e-14,
    "identity": 0.0,
    "inverse": 1e-14,
    "inverse_vs_linalg": 1e-14,
    "member_element": 1e-14,
    "member_product": 1e-14,
    "member_exp": 1e-14,
    "exp_vs_expm": 1e-14,
    "log_exp_rel": 1e-14,
    "exp_log": 1e-14,
    "Ad_exp": 1e-13,
    "Ad_generic": 1e-14,
    "Ad_homomorphism": 1e-14,
    "Ad_inverse": 1e-14,
    "Ad_of_exp": 1e-13,
    "ad_definition": 1e-15,
    "ad_generic": 1e-15,
    "ad_antisymmetry": 1e-15,
    "jacobi": 1e-14,
    "ad_star": 1e-15,
    "dAd_dt": 1e-15,
}


@pytest.mark.parametrize("identity", sorted(TOLERANCES))
@pytest.mark.parametrize("name", [PRODUCT])
def test_identity(name, identity):
    """Group axioms, membership, exp/log, Ad and ad identities for every sample (incl. ξ = 0, tiny ξ),
    on the product group: each factor (SO(3), SE(2), R², trivial) at every magnitude."""
    err = identity_errors(name)[identity]
    assert np.all(np.isfinite(err)), f"{identity}: non-finite values"
    assert err.max() <= TOLERANCES[identity], f"{identity}: max error {err.max():.3e}"


def test_random_elements_are_members():
    """`random` samples group elements (checked on the product, whose factors sample independently)."""
    group = GROUPS["SO3xSE2xR2xE"]
    g = jax.jit(jax.vmap(lambda key: (group.random(key), membership_error(group, group.random(key)))))
    g, err = g(jax.random.split(jax.random.PRNGKey(5), 16))
    assert g.shape == (16, group.matrix_size, group.matrix_size)
    assert np.asarray(err).max() <= 1e-14
    for f, blocks in zip(group.factors, zip(*[group.blocks(x) for x in g])):
        if f.dim:  # each factor's samples really vary
            assert np.std(np.stack(blocks), axis=0).max() > 0.1


@pytest.mark.parametrize("name", [PRODUCT])
def test_basis_is_hat_of_unit_vectors(name):
    assert identity_errors(name)["basis"] == 0.0


# ---------------------------------------------------------------------------------------------
# Derivatives: safe at zero, equal to the limits, jacfwd = jacrev = finite differences
# ---------------------------------------------------------------------------------------------


N_TINY = 4  # the first samples of `derivative_checks`: |ξ| = 0, 1e-12, 1e-9, 1e-6 along one direction


# The derivative checks run on the product group only: its exp and log are the factors' closed forms
# block by block, so one compiled function exercises every factor's Taylor branches (SO(3), SE(2),
# R^n, trivial) and keeps the compile time of this file low.
DERIVATIVE_GROUP = "SO3xSE2xR2xE"


@functools.cache
def derivative_checks(name):
    """Derivatives of exp and log at ξ = 0, tiny ξ and moderate ξ (one compiled function)."""
    group = GROUPS[name]
    d = group.dim
    # samples drawn with numpy (eager JAX sampling costs more than the checks): every factor's block
    # at norm 0, 1e-12, 1e-9, 1e-6 (its own Taylor branches), then 8 random ξ with |ξ| from 0.125 to 2.5
    rng = np.random.default_rng(7)
    tiny, tiny_nrm = factorwise_samples(group, [0.0, 1e-12, 1e-9, 1e-6], 1, rng, roll=0)
    moderate = rng.standard_normal((8, d))
    moderate = 2.5 * moderate / np.linalg.norm(moderate, axis=1, keepdims=True)
    moderate = moderate * np.linspace(0.05, 1.0, 8)[:, None]
    xis = np.concatenate([tiny, moderate])
    E = group.basis()  # (d, k, k)
    sym = 0.5 * (E[:, None] @ E[None, :] + E[None, :] @ E[:, None])  # (d, d, k, k)
    def log_exp(x):
        return group.log(group.exp(x))

    def fd(f, x, h=1e-6):
        # vmapped over the directions (one compiled copy of f, not 2d)
        cols = jax.vmap(lambda ei: (f(x + h * ei) - f(x - h * ei)) / (2 * h))(jnp.eye(d))
        return jnp.moveaxis(cols, 0, -1)

    def at(xi):
        Jf = jax.jacfwd(group.exp)(xi)  # (k, k, d)
        Jr = jax.jacrev(group.exp)(xi)
        H = jnp.moveaxis(jax.jacfwd(jax.jacfwd(group.exp))(xi), (-2, -1), (0, 1))  # (d, d, k, k)
        Lr = jax.jacrev(log_exp)(xi)
        # forward mode: the derivative of log with respect to the matrix entries at g = exp(ξ),
        # applied to the tangent vectors ∂exp/∂ξ_b, is the identity (d(log∘exp) = I by the chain
        # rule; at ξ = 0 the tangents are the generators E_b); reverse mode: jacrev of log∘exp
        g = group.exp(xi)
        dlog_E = jnp.einsum("aij,ijb->ab", jax.jacfwd(group.log)(g), Jf)
        return {
            "exp_jac_vs_generators": _maxabs(jnp.moveaxis(Jf, -1, 0) - E),
            "exp_hessian_vs_sym": _maxabs(H - sym),
            "exp_jacfwd_vs_jacrev": _maxabs(Jf - Jr),
            "exp_jacfwd_vs_fd": _maxabs(Jf - fd(group.exp, xi)),
            "logexp_jacrev_vs_I": _maxabs(Lr - jnp.eye(d)),
            "dlog_on_tangents_vs_I": _maxabs(dlog_E - jnp.eye(d)),
            "finite": jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in (Jf, Jr, H, Lr, dlog_E)])),
        }

    out = run_once(jax.vmap(at), xis)
    # the scale of the O(|ξ|) bounds at tiny ξ: the factors' own norms (each factor as on its own)
    nrm = np.concatenate([tiny_nrm, np.linalg.norm(moderate, axis=1)])
    return {k: np.asarray(v) for k, v in out.items()}, nrm


@pytest.mark.parametrize("name", [DERIVATIVE_GROUP])
def test_derivatives_at_and_near_zero(name):
    """At ξ = 0 and tiny ξ: d exp/dξ = generators, d²exp/dξ_i dξ_j = (E_iE_j + E_jE_i)/2, d(log∘exp) = I.

    All values finite (no NaN from the Taylor branches) and jacfwd = jacrev.
    """
    res, nrm = derivative_checks(name)
    res = {k: v[:N_TINY] for k, v in res.items()}
    nrm = nrm[:N_TINY]
    assert np.all(res["finite"])
    # the deviations from the values at ξ = 0 are O(|ξ|)
    assert np.all(res["exp_jac_vs_generators"] <= 1e-15 + 2.0 * nrm), res["exp_jac_vs_generators"]
    assert np.all(res["exp_hessian_vs_sym"] <= 1e-14 + 2.0 * nrm), res["exp_hessian_vs_sym"]
    assert np.all(res["exp_jacfwd_vs_jacrev"] <= 1e-15)
    assert np.all(res["logexp_jacrev_vs_I"] <= 1e-14)
    assert np.all(res["dlog_on_tangents_vs_I"] <= 1e-14), res["dlog_on_tangents_vs_I"]


@pytest.mark.parametrize("name", [DERIVATIVE_GROUP])
def test_jacobians_random_points(name):
    """At moderate ξ (|ξ| ≤ 2.5): jacfwd = jacrev = central finite differences for exp;
    d(log∘exp)/dξ = I by jacfwd and jacrev, and through the matrix derivative of log."""
    res, _ = derivative_checks(name)
    res = {k: v[N_TINY:] for k, v in res.items()}
    assert np.all(res["finite"])
    assert res["exp_jacfwd_vs_jacrev"].max() <= 1e-14
    assert res["exp_jacfwd_vs_fd"].max() <= 1e-8  # central differences: O(h²) + O(ε/h)
    assert res["logexp_jacrev_vs_I"].max() <= 1e-12
    assert res["dlog_on_tangents_vs_I"].max() <= 1e-12


# ---------------------------------------------------------------------------------------------
# Group-specific facts
# ---------------------------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(-3.0, 3.0, allow_subnormal=False), st.floats(-1e-7, 1e-7, allow_subnormal=False), st.just(0.0)
        ),
        min_size=3,
        max_size=3,
    ),
    st.lists(st.floats(-5.0, 5.0), min_size=3, max_size=3),
)
@example(w=[0.0, 2.2250738585072014e-308, 0.0], m=[0.0, 0.0, 0.0])  # the smallest normal number
def test_so3_hypothesis(w, m):
    """SO(3): exp ∈ SO(3), the axis is fixed, log∘exp = id (|ω| < π), ad*_ω M = M × ω, Ad = R."""
    w = np.asarray(w)
    if np.linalg.norm(w) >= 3.1:
        w = w * (3.0 / np.linalg.norm(w))
    R, lw, adstar = _so3_fns(jnp.asarray(w), jnp.asarray(m))
    R = np.asarray(R)
    assert np.abs(R.T @ R - np.eye(3)).max() <= 1e-14
    assert abs(np.linalg.det(R) - 1.0) <= 1e-14
    assert np.abs(R @ w - w).max() <= 1e-14 * max(1.0, np.linalg.norm(w))
    # floor 1e-290: XLA on CPU flushes subnormal intermediates to zero, so for |ω| near the smallest
    # normal number (2.2e-308, found by hypothesis) log∘exp returns 0: an absolute error of 2.2e-308
    assert np.abs(np.asarray(lw) - w).max() <= 1e-14 * max(np.linalg.norm(w), 1e-290)
    assert np.abs(np.asarray(adstar) - np.cross(m, w)).max() <= 1e-14
    assert np.array_equal(np.asarray(SO3().Ad(R)), R)


@jax.jit
def _so3_fns(w, m):
    G = SO3()
    R = G.exp(w)
    return R, G.log(R), G.ad_star(w, m)


def test_so3_hat_is_cross_product():
    w, r = np.array([0.3, -1.2, 2.0]), np.array([-0.7, 0.1, 0.4])
    assert np.abs(np.asarray(SO3().hat(w)) @ r - np.cross(w, r)).max() <= 1e-15
    assert np.abs(np.asarray(SO3().ad(w)) @ r - np.cross(w, r)).max() <= 1e-15


def test_so3_log_near_and_at_pi():
    """Principal log near angle π (the hard case for the quaternion branch): exp(log R) = R."""
    G = SO3()
    axes = np.random.default_rng(11).standard_normal((16, 3))  # numpy: eager JAX sampling costs more
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.array([np.pi - 1e-3, np.pi - 1e-8, np.pi, np.pi - 1e-12])
    w = (angles[:, None, None] * axes[None]).reshape(-1, 3)

    def f(w):
        R = G.exp(w)
        lw = G.log(R)
        return _maxabs(G.exp(lw) - R), jnp.linalg.norm(lw), jnp.minimum(_maxabs(lw - w), _maxabs(lw + w))

    e_exp, nrm, e_w = map(np.asarray, jax.jit(jax.vmap(f))(w))
    assert e_exp.max() <= 1e-14
    assert np.all(nrm <= np.pi + 1e-14)
    # at angle π the logarithm is ±ω; just below π it is ω (up to the conditioning ε/(π − θ))
    assert e_w.max() <= 1e-6


def test_se2_structure():
    """SE(2): exp of a pure translation / rotation, the principal angle of log, Ad's translation column."""
    G = SE2()
    g = np.asarray(G.exp(jnp.array([1.5, -2.0, 0.0])))
    assert np.abs(g - np.array([[1, 0, 1.5], [0, 1, -2.0], [0, 0, 1]])).max() == 0.0
    th = 2.0
    g = np.asarray(G.exp(jnp.array([0.0, 0.0, th])))
    assert np.abs(g[:2, :2] - np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])).max() <= 1e-16
    # a rotation by 3π/2 has principal angle −π/2
    assert abs(float(G.log(G.exp(jnp.array([0.0, 0.0, 1.5 * np.pi])))[2]) + 0.5 * np.pi) <= 1e-15
    # Ad_g for a pure translation t maps the rotation generator to (t_y, −t_x, 1)
    Adg = np.asarray(G.Ad(G.exp(jnp.array([0.4, 0.9, 0.0]))))
    assert np.abs(Adg[:, 2] - np.array([0.9, -0.4, 1.0])).max() <= 1e-16


def test_product_is_blockwise():
    G = GROUPS["SO3xSE2xR2xE"]
    xi = jnp.array([0.1, -0.2, 0.3, 1.0, 2.0, -0.5, 3.0, 4.0])
    parts = G.split(xi)
    expected = block_diag(*[f.exp(x) for f, x in zip(G.factors, parts)])
    assert np.abs(np.asarray(G.exp(xi) - expected)).max() == 0.0
    expected_Ad = block_diag(*[f.Ad(f.exp(x)) for f, x in zip(G.factors, parts)])
    assert np.abs(np.asarray(G.Ad(G.exp(xi)) - expected_Ad)).max() == 0.0
    assert (G.dim, G.matrix_size) == (8, 10)


def test_trivial_group():
    G = TrivialGroup()
    e = G.exp(jnp.zeros(0))
    assert e.shape == (1, 1) and float(e[0, 0]) == 1.0
    assert G.log(e).shape == (0,) and G.Ad(e).shape == (0, 0) and G.ad(jnp.zeros(0)).shape == (0, 0)
    assert G.basis().shape == (0, 1, 1) and G.hat(jnp.zeros(0)).shape == (1, 1)


def test_rn_is_abelian():
    G = Rn(3)
    x, y = jnp.array([1.0, 2.0, 3.0]), jnp.array([-0.5, 0.25, 4.0])
    assert np.abs(np.asarray(G.exp(x) @ G.exp(y) - G.exp(x + y))).max() == 0.0
    assert np.abs(np.asarray(G.ad(x))).max() == 0.0 and np.abs(np.asarray(G.ad_star(x, y))).max() == 0.0


def test_validation():
    with pytest.raises(ValueError, match="factors"):
        ProductGroup()
    with pytest.raises(TypeError, match="factors"):
        ProductGroup(SO3(), "SE2")
    with pytest.raises(ValueError, match="n:"):
        Rn(0)
    with pytest.raises(ValueError, match="xi"):
        SO3().exp(jnp.zeros(4))
    with pytest.raises(ValueError, match="g"):
        SE2().log(jnp.eye(4))
    with pytest.raises(NotImplementedError):
        MatrixLieGroup.log(SO3(), jnp.eye(3))


def test_groups_are_hashable_static_pytrees():
    """Groups carry no array leaves: they can be closed over or passed through jit freely."""
    for G in GROUPS.values():
        assert jax.tree_util.tree_leaves(G) == []
        hash(G)
    assert ProductGroup(SO3(), Rn(2)) == ProductGroup(SO3(), Rn(2))
    f = jax.jit(lambda G, x: G.exp(x))
    assert f(GROUPS["SO3"], jnp.zeros(3)).shape == (3, 3)
