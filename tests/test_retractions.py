"""Tests of gnipy.retractions: Cayley and exp retractions and their right-trivialized tangents.

Expected values come from the definitions, differentiated automatically:
$\\mathrm{d}\\tau_\\xi\\eta = (\\partial_\\epsilon\\tau(\\xi+\\epsilon\\eta)\\,\\tau(\\xi)^{-1})^\\vee$ (eq:dtaudef) with
$\\tau$ written independently of the closed forms (the matrix Cayley formula, a matrix-exponential
series), and $\\mathrm{d}\\tau^{-1}_\\xi\\eta = \\partial_\\epsilon\\tau^{-1}(e^{\\epsilon\\hat\\eta}\\tau(\\xi))$
(eq:dtauinversedef); from the Appendix identities (eq:dtauAd), (eq:dtauinverseAd); and from the
paper's series. Each retraction is checked by one jitted, vmapped function whose results the tests
share, on one group: the product SO(3) × SE(2) × R² × E, whose τ, dτ, dτ⁻¹, τ⁻¹, the jump and
dτ⁻¹_ξ ξ are its factors' own closed forms, block by block (`gnipy.lie_groups.product`). Its samples
give every factor's block each magnitude of MAGNITUDES as its own norm
(`group_checks.factorwise_samples`), and relative errors and O(|ξ|) bounds are taken per factor,
so that each factor (SO(3), SE(2), R^n, trivial) is checked exactly as on its own.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from group_checks import maxabs as _maxabs
from group_checks import factorwise_relative, factorwise_samples, membership_error, run_once, series_expm
from hypothesis import given, settings
from hypothesis import strategies as st

import gnipy  # noqa: F401  (float64)
from gnipy.lie_groups import SE2, SO3, MatrixLieGroup, ProductGroup, Rn, TrivialGroup
from gnipy.retractions import (
    Cayley,
    Exp,
    Retraction,
    dexp_inv_series,
    dexp_series,
    get_retraction,
    retraction_names,
)


class PlainSO3(MatrixLieGroup):
    """SO(3) through hat/vee only: exercises the generic (base-class and series) code paths."""

    @property
    def dim(self):
        return 3

    @property
    def matrix_size(self):
        return 3

    def hat(self, xi):
        return SO3().hat(xi)

    def vee(self, X):
        return SO3().vee(X)


class PlainSE2(MatrixLieGroup):
    """SE(2) through hat/vee only."""

    @property
    def dim(self):
        return 3

    @property
    def matrix_size(self):
        return 3

    def hat(self, xi):
        return SE2().hat(xi)

    def vee(self, X):
        return SE2().vee(X)


GROUPS = {
    # SO(3), SE(2), R² and the trivial group, each as a factor (see the module docstring)
    "SO3xSE2xR2xE": ProductGroup(SO3(), SE2(), Rn(2), TrivialGroup()),
}
RETRACTIONS = {"cayley": Cayley(), "exp": Exp()}

# Magnitudes: zero, tiny (Taylor branches), both sides of the branch switches (0.5 and 1), up to 3 < π.
MAGNITUDES = np.array([0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.07, 0.49, 0.51, 0.99, 1.01, 2.0, 3.0])
N_DIRECTIONS = 4
N_TINY = 4  # magnitudes 0, 1e-12, 1e-9, 1e-6


def expm(X):
    """Reference matrix exponential (Taylor series of $e^{X/2^s}$, squared s times)."""
    return series_expm(X, squarings=6, terms=12)


def tau_definition(retraction, group, xi):
    """τ written from its definition as a matrix function of $\\hat\\xi$ (no closed forms, no branches)."""
    X = group.hat(xi)
    eye = jnp.eye(group.matrix_size)
    if retraction.name == "cayley":
        return jnp.linalg.solve(eye - 0.5 * X, eye + 0.5 * X)  # (I − X/2)⁻¹(I + X/2)
    return expm(X)


def right_trivialized(group, tau_fn, xi, jac=jax.jacfwd):
    """(eq:dtaudef): column j is $(\\partial_j\\tau(\\xi)\\,\\tau(\\xi)^{-1})^\\vee$, by automatic differentiation."""
    J = jac(tau_fn)(xi)  # (k, k, d)
    t_inv = jnp.linalg.inv(tau_fn(xi))
    return jax.vmap(lambda Jj: group.vee(Jj @ t_inv), in_axes=2, out_axes=1)(J)


def samples(group, seed):
    """(ξ, η, scale): tiny magnitudes first (every factor at the same magnitude, one direction), then
    every magnitude for every factor along N_DIRECTIONS random directions; the scale of each sample's
    O(|ξ|) bounds is its largest factor norm."""
    rng = np.random.default_rng(seed)
    tiny, tiny_nrm = factorwise_samples(group, MAGNITUDES[:N_TINY], 1, rng, roll=0)
    rest, rest_nrm = factorwise_samples(group, MAGNITUDES, N_DIRECTIONS, rng)
    xi = np.concatenate([tiny, rest])
    return xi, rng.standard_normal(xi.shape), np.concatenate([tiny_nrm, rest_nrm])


@functools.cache
def report(rname, gname):
    """Errors of every checked property, per sample, for one retraction on one group."""
    retraction, group = RETRACTIONS[rname], GROUPS[gname]
    d = group.dim
    e = group.identity()
    E = group.basis()
    ad_basis = jax.vmap(group.ad)(jnp.eye(d))  # ad(e_j), (d, d, d)
    tau = functools.partial(retraction.tau, group)
    dtau = functools.partial(retraction.dtau, group)
    dtau_inv = functools.partial(retraction.dtau_inv, group)
    tau_def = functools.partial(tau_definition, retraction, group)

    def dtau_inv_definition(xi):
        # (eq:dtauinversedef): column j is d/dε τ⁻¹(exp(ε ê_j) τ(ξ)) at ε = 0
        t = tau(xi)
        return jax.jacfwd(lambda eta: retraction.tau_inv(group, expm(group.hat(eta)) @ t))(jnp.zeros(d))

    def fd(f, x, h=1e-6):
        # vmapped over the directions (one compiled copy of f, not 2d)
        cols = jax.vmap(lambda ei: (f(x + h * ei) - f(x - h * ei)) / (2 * h))(jnp.eye(d))
        return jnp.moveaxis(cols, 0, -1)

    def per_sample(xi, eta):
        # ±ξ through one vmapped copy of each function (halves the compiled program)
        (T, Tm), (D, Dm), (Di, Dim) = (jax.vmap(f)(jnp.stack([xi, -xi])) for f in (tau, dtau, dtau_inv))
        D_def = right_trivialized(group, tau_def, xi)
        out = {
            "tau_vs_definition": _maxabs(T - tau_def(xi)),
            "tau_in_group": membership_error(group, T),
            "tau_times_tau_minus": _maxabs(T @ Tm - e),
            # closed form vs AD of the definition (eq:dtaudef)
            "dtau_vs_AD_definition": _maxabs(D - D_def),
            "dtau_inv_vs_inverse_of_definition": _maxabs(Di - jnp.linalg.inv(D_def)),
            "dtau_dtau_inv_is_I": jnp.maximum(_maxabs(D @ Di - jnp.eye(d)), _maxabs(Di @ D - jnp.eye(d))),
            # Appendix, Lemma (lemaPr_again)
            "eq_dtauAd": _maxabs(D @ eta - group.Ad(T) @ (Dm @ eta)),
            "eq_dtauinverseAd": _maxabs(Di @ eta - Dim @ (group.Ad(Tm) @ eta)),
            "dtau_at_0_is_I": _maxabs(D - jnp.eye(d)),
            # the closed-form jump dτ⁻¹_{−ξ} − dτ⁻¹_ξ (= ad_ξ) against the difference of the two
            "dtau_inv_jump_vs_difference": _maxabs(retraction.dtau_inv_jump(group, xi) - (Dim - Di)),
            # dτ⁻¹_ξ ξ in closed form (DLA's constraint velocity) against the matrix, and from −ξ (its
            # odd part −ad_ξ/2 vanishes on ξ)
            "dtau_inv_along_vs_matrix": _maxabs(retraction.dtau_inv_along(group, xi) - Di @ xi),
            "dtau_inv_along_from_minus_xi": _maxabs(retraction.dtau_inv_along(group, xi) - Dim @ xi),
        }
        finite = [T, D, Di]
        if gname in FULL:
            dD = jax.jacfwd(dtau)(xi)  # (d, d, d): derivative of the entries along e_j
            dDi = jax.jacfwd(dtau_inv)(xi)
            dT = jax.jacfwd(tau)(xi)
            out |= {
                "tau_inv_of_tau_rel": factorwise_relative(group, retraction.tau_inv(group, T) - xi, xi),
                # AD of the retraction's own τ (its Taylor branches' derivatives) and of (eq:dtauinversedef)
                "dtau_vs_AD_of_tau": _maxabs(D - right_trivialized(group, tau, xi)),
                "dtau_inv_vs_AD_definition": _maxabs(Di - dtau_inv_definition(xi)),
                # derivatives of dτ, dτ⁻¹: jacfwd = jacrev = finite differences
                "d_dtau_fwd_vs_rev": jnp.maximum(
                    _maxabs(dD - jax.jacrev(dtau)(xi)), _maxabs(dDi - jax.jacrev(dtau_inv)(xi))
                ),
                "d_dtau_fwd_vs_fd": jnp.maximum(_maxabs(dD - fd(dtau, xi)), _maxabs(dDi - fd(dtau_inv, xi))),
                # limits at ξ = 0: dτ/dξ_j = E_j, ∂dτ/∂ξ_j = ad(e_j)/2, ∂dτ⁻¹/∂ξ_j = −ad(e_j)/2
                # (both retractions: dτ_ξ = I + ad_ξ/2 + O(ξ²))
                "d_tau_vs_generators": _maxabs(jnp.moveaxis(dT, -1, 0) - E),
                "d_dtau_vs_half_ad": _maxabs(jnp.moveaxis(dD, -1, 0) - 0.5 * ad_basis),
                "d_dtau_inv_vs_minus_half_ad": _maxabs(jnp.moveaxis(dDi, -1, 0) + 0.5 * ad_basis),
            }
            finite += [dD, dDi, dT]
        out["finite"] = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in finite]))
        return out

    def checks(xi, eta):
        out = jax.vmap(per_sample)(xi, eta)
        # the values at ξ = 0 exactly, in the same compiled program (eagerly they cost more than it)
        zero = jnp.zeros(d)
        out |= {"tau_at_zero": tau(zero), "dtau_at_zero": dtau(zero), "dtau_inv_at_zero": dtau_inv(zero)}
        return out

    xi, eta, nrm = samples(group, sorted(GROUPS).index(gname))
    res = run_once(checks, xi, eta)
    return {k: np.asarray(v) for k, v in res.items()}, nrm


# Checks at every sample and their tolerances (matrix entries are O(1) for |ξ_f| ≤ 3). The checks
# involving derivatives of τ⁻¹, dτ and dτ⁻¹ run on the product group (FULL): its τ, dτ, dτ⁻¹ and
# τ⁻¹ are the factors' own (SO(3), SE(2), R², trivial), block by block, so one compiled function
# covers every closed form and keeps the compile time of this file low.
FULL = ("SO3xSE2xR2xE",)
BASIC = {
    "tau_vs_definition": 1e-13,
    "tau_in_group": 1e-14,
    "tau_times_tau_minus": 1e-14,
    "dtau_vs_AD_definition": 1e-12,
    "dtau_inv_vs_inverse_of_definition": 1e-12,
    "dtau_dtau_inv_is_I": 1e-14,
    "eq_dtauAd": 1e-13,
    "eq_dtauinverseAd": 1e-13,
    "dtau_inv_jump_vs_difference": 1e-13,
    "dtau_inv_along_vs_matrix": 1e-13,
    "dtau_inv_along_from_minus_xi": 1e-13,
}
DERIVATIVES = {
    "tau_inv_of_tau_rel": 1e-13,
    "dtau_vs_AD_of_tau": 1e-12,
    "dtau_inv_vs_AD_definition": 1e-12,
    "d_dtau_fwd_vs_rev": 1e-14,
    "d_dtau_fwd_vs_fd": 1e-8,  # central differences, h = 1e-6
}
CASES = [
    (r, g, c)
    for r in sorted(RETRACTIONS)
    for g in sorted(GROUPS)
    for c in sorted(BASIC) + (sorted(DERIVATIVES) if g in FULL else [])
]


@pytest.mark.parametrize("rname,gname,check", CASES)
def test_property(rname, gname, check):
    """τ(ξ) ∈ G, τ(ξ)τ(−ξ) = e, dτ and dτ⁻¹ equal AD of their definitions, (eq:dtauAd), (eq:dtauinverseAd),
    jacfwd = jacrev = finite differences — at ξ = 0, tiny ξ, both sides of every Taylor switch, and |ξ| ≤ 3."""
    res, _ = report(rname, gname)
    err = res[check]
    assert np.all(res["finite"]), "non-finite values or derivatives"
    tol = {**BASIC, **DERIVATIVES}[check]
    assert np.all(np.isfinite(err)) and err.max() <= tol, f"{check}: max error {err.max():.3e}"


@pytest.mark.parametrize("gname", sorted(GROUPS))
@pytest.mark.parametrize("rname", sorted(RETRACTIONS))
def test_values_at_zero(rname, gname):
    """τ(0) = e and dτ_0 = dτ⁻¹_0 = I exactly; dτ_ξ = I + O(|ξ|) at tiny ξ."""
    group = GROUPS[gname]
    res, nrm = report(rname, gname)
    assert np.array_equal(res["tau_at_zero"], np.eye(group.matrix_size))
    assert np.array_equal(res["dtau_at_zero"], np.eye(group.dim))
    assert np.array_equal(res["dtau_inv_at_zero"], np.eye(group.dim))
    tiny = slice(0, N_TINY)
    assert np.all(res["finite"][tiny])
    assert np.all(res["dtau_at_0_is_I"][tiny] <= 1e-15 + 2.0 * nrm[tiny]), res["dtau_at_0_is_I"][tiny]


@pytest.mark.parametrize("gname", FULL)
@pytest.mark.parametrize("rname", sorted(RETRACTIONS))
def test_derivative_limits_at_zero(rname, gname):
    """No NaN derivatives at ξ = 0 or tiny ξ, and they equal their limits: dτ/dξ_j = E_j,
    ∂(dτ)/∂ξ_j = ad(e_j)/2, ∂(dτ⁻¹)/∂ξ_j = −ad(e_j)/2 (exactly at 0, up to O(|ξ|) at tiny ξ)."""
    res, nrm = report(rname, gname)
    tiny = slice(0, N_TINY)
    assert np.all(res["finite"][tiny])
    assert np.all(res["d_tau_vs_generators"][tiny] <= 1e-15 + 2.0 * nrm[tiny]), res["d_tau_vs_generators"][tiny]
    # the second-order terms of dτ differ between the retractions: O(|ξ|) with a constant ≤ 1
    for key in ("d_dtau_vs_half_ad", "d_dtau_inv_vs_minus_half_ad"):
        assert np.all(res[key][tiny] <= 1e-15 + nrm[tiny]), (key, res[key][tiny])
        assert res[key][0] == 0.0, (key, res[key][0])


# ---------------------------------------------------------------------------------------------
# Closed forms against the generic code paths and the paper's series
# ---------------------------------------------------------------------------------------------


@functools.cache
def generic_report():
    """Closed forms against the generic code paths and the paper's series, for |ξ| ≤ 1."""
    rng = np.random.default_rng(17)
    u = rng.standard_normal((8, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    mags = np.array([0.0, 1e-9, 1e-6, 1e-3, 0.1, 0.49, 0.51, 0.99, 1.0])
    xi = (mags[:, None, None] * u[None]).reshape(-1, 3)
    cay, ex = Cayley(), Exp()
    so3, se2 = SO3(), SE2()

    def per_sample(xi):
        out = {}
        # SO(3) Cayley: the Appendix's closed forms against the generic matrix formulas
        for f in ("tau", "dtau", "dtau_inv"):
            out[f"cayley_SO3_{f}"] = _maxabs(getattr(cay, f)(so3, xi) - getattr(cay, f)(PlainSO3(), xi))
        g = cay.tau(so3, xi)
        out["cayley_SO3_tau_inv"] = _maxabs(cay.tau_inv(so3, g) - cay.tau_inv(PlainSO3(), g))
        # dcay⁻¹_ξ ξ: the SO(3) and SE(2) closed forms against the generic x − x³/4
        out["cayley_SO3_dtau_inv_along"] = _maxabs(cay.dtau_inv_along(so3, xi) - cay.dtau_inv_along(PlainSO3(), xi))
        out["cayley_SE2_dtau_inv_along"] = _maxabs(cay.dtau_inv_along(se2, xi) - cay.dtau_inv_along(PlainSE2(), xi))
        # exp: the closed forms (SO(3), SE(2)) against the paper's series (Appendix a)
        for gname, group in (("SO3", so3), ("SE2", se2)):
            out[f"series_{gname}_dexp"] = _maxabs(ex.dtau(group, xi) - dexp_series(group, xi))
            out[f"series_{gname}_dexp_inv"] = _maxabs(ex.dtau_inv(group, xi) - dexp_inv_series(group, xi))
        # the generic fallback of Exp (series, base-class expm) on a group without closed forms
        for f in ("tau", "dtau", "dtau_inv"):
            out[f"exp_SE2_{f}"] = _maxabs(getattr(ex, f)(se2, xi) - getattr(ex, f)(PlainSE2(), xi))
        return out

    res = run_once(jax.vmap(per_sample), xi)
    return {k: np.asarray(v) for k, v in res.items()}


def test_closed_forms_match_generic_paths_and_series():
    """SO(3) Cayley (Appendix closed forms) = generic matrix Cayley (and dcay⁻¹_ξ ξ on SO(3) and SE(2));
    SO(3)/SE(2) exp closed forms =
    the paper's series Σ ad^j/(j+1)! and Σ B_j/j! ad^j (|ξ| ≤ 1) = the generic fallback of Exp."""
    res = generic_report()
    bad = {k: float(v.max()) for k, v in res.items() if not v.max() <= 1e-14}
    assert not bad, bad
    assert len(res) == 4 + 2 + 4 + 3


def test_series_converge_beyond_unit_ball_with_more_terms():
    """At |ξ| = 3 the default truncation is not enough, but more terms converge to the closed form
    (documented range of the series)."""
    G, ex = SO3(), Exp()
    xi = jnp.array([1.2, -2.0, 1.8])
    xi = 3.0 * xi / jnp.linalg.norm(xi)
    assert float(_maxabs(ex.dtau(G, xi) - dexp_series(G, xi, terms=40))) <= 1e-14
    assert float(_maxabs(ex.dtau_inv(G, xi) - dexp_inv_series(G, xi, terms=40))) <= 1e-12


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.one_of(
            st.floats(-4.0, 4.0, allow_subnormal=False), st.floats(-1e-6, 1e-6, allow_subnormal=False), st.just(0.0)
        ),
        min_size=3,
        max_size=3,
    )
)
def test_so3_cayley_appendix_formulas(w):
    """SO(3) Cayley, against the Appendix's matrix formulas evaluated in numpy:
    cay(ω̂) = (I − ω̂/2)⁻¹(I + ω̂/2), dcay_ω y = ((I − ω̂/2)⁻¹ ŷ (I + ω̂/2)⁻¹)^∨,
    dcay⁻¹_ω y = ((I − ω̂/2) ŷ (I + ω̂/2))^∨, and cay⁻¹(cay(ω)) = ω."""
    w = np.asarray(w, dtype=np.float64)
    T, D, Di, w_back = _so3_cayley(jnp.asarray(w))

    def hat(a):
        return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])

    def vee(X):
        return np.array([X[2, 1], X[0, 2], X[1, 0]])

    A, B = np.eye(3) - hat(w) / 2, np.eye(3) + hat(w) / 2
    Ai, Bi = np.linalg.inv(A), np.linalg.inv(B)
    scale = 1.0 + w @ w
    assert np.abs(np.asarray(T) - Ai @ B).max() <= 1e-14 * scale
    D_ref = np.stack([vee(Ai @ hat(y) @ Bi) for y in np.eye(3)], axis=1)
    Di_ref = np.stack([vee(A @ hat(y) @ B) for y in np.eye(3)], axis=1)
    assert np.abs(np.asarray(D) - D_ref).max() <= 1e-14 * scale
    assert np.abs(np.asarray(Di) - Di_ref).max() <= 1e-14 * scale
    assert np.abs(np.asarray(w_back) - w).max() <= 1e-14 * max(np.linalg.norm(w), 1e-300) * scale


@jax.jit
def _so3_cayley(w):
    G, c = SO3(), Cayley()
    T = c.tau(G, w)
    return T, c.dtau(G, w), c.dtau_inv(G, w), c.tau_inv(G, T)


# ---------------------------------------------------------------------------------------------
# Construction and the API
# ---------------------------------------------------------------------------------------------


def test_get_retraction():
    assert retraction_names() == ("cayley", "exp")
    assert isinstance(get_retraction("cayley"), Cayley) and get_retraction("cayley").name == "cayley"
    assert isinstance(get_retraction("exp"), Exp) and get_retraction("exp").name == "exp"
    assert isinstance(get_retraction("Cayley"), Cayley)
    for bad in ("cay", "", "expm", None, 3):
        with pytest.raises(ValueError, match="retraction"):
            get_retraction(bad)


def test_retractions_are_static_pytrees():
    for r in (Cayley(), Exp()):
        assert isinstance(r, Retraction)
        assert jax.tree_util.tree_leaves(r) == []
        hash(r)
    assert Cayley() == Cayley() and Cayley() != Exp()


def test_trivial_group_and_validation():
    G, c = TrivialGroup(), Cayley()
    for r in (Cayley(), Exp()):
        assert np.array_equal(np.asarray(r.tau(G, jnp.zeros(0))), np.ones((1, 1)))
        assert r.dtau(G, jnp.zeros(0)).shape == (0, 0) and r.dtau_inv(G, jnp.zeros(0)).shape == (0, 0)
        assert r.tau_inv(G, jnp.ones((1, 1))).shape == (0,)
    with pytest.raises(ValueError, match="xi"):
        c.tau(SO3(), jnp.zeros(2))
    with pytest.raises(TypeError, match="group"):
        c.dtau("SO3", jnp.zeros(3))


def test_cayley_lands_in_se2_though_not_quadratic():
    """SE(2) is not a quadratic group, yet the matrix Cayley of se(2) is block upper-triangular with a
    rotation block: cay(v, ω) = (R(2 atan(ω/2)), ...)."""
    w = 1.3
    T = np.asarray(Cayley().tau(SE2(), jnp.array([0.4, -0.2, w])))
    phi = 2 * np.arctan(w / 2)
    assert np.abs(T[:2, :2] - np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])).max() <= 1e-15
    assert np.array_equal(T[2], np.array([0.0, 0.0, 1.0]))
