"""Property-based tests (hypothesis) over random metrics, constraints, systems and group
elements.

What is drawn: dimensions, SPD metrics $\\mathbb{G} = A^TA + \\varepsilon I$ (scaled),
constraint one-forms $\\mu = U\\,\\mathrm{diag}(s)\\,W^T$ of full row rank (orthonormal
U, W from QR factors, so that the singular values s, hence the conditioning, are
controlled), covectors, regular matrices (some needing row exchanges), whole systems on
$\\mathbb{R}^n$ integrated by the GNI, and Lie-algebra vectors at random and
near-identity magnitudes (exact 0 and 1e-9..1e-4 included).

Tolerances are stated relative to the conditioning of the drawn data (condition numbers
computed with NumPy for each example) and the size of the quantities that cancel. The
constant factors were checked on a few hundred random (not derandomized) examples per
test: every test still passes with its tolerances divided by 10, and the algebraic ones
fail when divided by 100 (they are not slack); the GNI residuals stay below 1e-15
relative against a bound of 1e-13.

Cost: compilation dominates, so the number of distinct shapes is kept small (fixed lists
of shapes; one compiled check per group, with both retractions; one system structure per
GNI test), and every test is derandomized so that CI sees the same examples on every
run.
"""

from __future__ import annotations

import functools
import importlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from group_checks import series_expm
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import gnipy
from gnipy.linalg import LU_UNROLL_MAX, lu_factor, lu_solve, solve, solve_spd

# `gnipy.projectors` is the function (re-exported by the package): reach the module
# itself
reflect_and_report = importlib.import_module("gnipy.projectors").reflect_and_report

EPS = float(np.finfo(np.float64).eps)
FINITE = dict(allow_nan=False, allow_infinity=False, allow_subnormal=False)


def property_settings(max_examples: int):
    return settings(
        max_examples=max_examples, deadline=None, derandomize=True, database=None
    )


def maxabs(x) -> float:
    x = np.asarray(x)
    return float(np.max(np.abs(x))) if x.size else 0.0


def norm2(x) -> float:
    """Spectral norm of a matrix, Euclidean norm of a vector."""
    x = np.asarray(x)
    return float(np.linalg.norm(x, 2)) if x.size else 0.0


# --------------------------------------------------------------------------------------
# Strategies
# --------------------------------------------------------------------------------------
def _flush_tiny(x: np.ndarray) -> np.ndarray:
    """Entries below 1e-100 in magnitude become exact zeros (which are kept: they are
    the interesting degenerate cases), so that no product of drawn values reaches the
    subnormal range, where no relative precision is promised."""
    return np.where(np.abs(x) < 1e-100, 0.0, x)


def matrices(rows: int, cols: int, bound: float = 1.0):
    return hnp.arrays(
        np.float64, (rows, cols), elements=st.floats(-bound, bound, **FINITE)
    ).map(_flush_tiny)


def vectors(n: int, bound: float = 1.0):
    return hnp.arrays(
        np.float64, (n,), elements=st.floats(-bound, bound, **FINITE)
    ).map(_flush_tiny)


def orthonormal_columns(raw: np.ndarray, k: int) -> np.ndarray:
    """The first k columns of the Q factor of a square matrix: orthonormal whatever
    `raw` is (Householder QR; a zero or rank-deficient `raw` still gives an orthogonal
    Q)."""
    q, _ = np.linalg.qr(raw)
    return q[:, :k]


@st.composite
def spd_metrics(
    draw, n: int, entry: float = 1.0, eps_min: float = 0.5, scaled: bool = True
):
    """$c(A^TA + \\varepsilon I)$ with $|A_{ij}| \\le$ `entry`, $\\varepsilon \\ge$
    `eps_min`: cond ≤ $(n^2 \\cdot entry^2 + \\varepsilon)/\\varepsilon$ (≤ 99 for n = 7
    and the defaults). The scale c = 10^k (|k| ≤ 3) checks that nothing depends on the
    absolute size of G."""
    A = draw(matrices(n, n, entry))
    eps = draw(st.floats(eps_min, 1.0))
    c = 10.0 ** draw(st.integers(-3, 3)) if scaled else 1.0
    G = c * (A.T @ A + eps * np.eye(n))
    return 0.5 * (G + G.T)


@st.composite
def constraint_forms(draw, m: int, n: int, scaled: bool = True):
    """$\\mu = c\\,U\\mathrm{diag}(s)W^T$, (m, n), singular values $c\\,s_i$ with $s_i
    \\in [0.5, 2]$: full row rank with cond(μ) ≤ 4 whatever the raw draws."""
    W = orthonormal_columns(draw(matrices(n, n)), m)
    U = orthonormal_columns(draw(matrices(m, m)), m)
    s = draw(hnp.arrays(np.float64, (m,), elements=st.floats(0.5, 2.0, **FINITE)))
    c = 10.0 ** draw(st.integers(-2, 2)) if scaled else 1.0
    return c * (U * s) @ W.T


# (N, m) pairs: both ends of 2 ≤ N ≤ 7 and 1 ≤ m ≤ N − 1, and a few in between. The
# eliminations are unrolled per shape, so every shape costs its own traces; a fixed list
# bounds the cost.
SHAPES = [(2, 1), (3, 2), (5, 3), (7, 1), (7, 6)]


def _numpy_projectors(G, mu):
    """Independent reference: $Q = G^{-1}\\mu^T(\\mu G^{-1}\\mu^T)^{-1}\\mu$ with LAPACK
    solves."""
    Ginv_muT = np.linalg.solve(G, mu.T)
    C = mu @ Ginv_muT
    Q = Ginv_muT @ np.linalg.solve(C, mu)
    return np.eye(G.shape[0]) - Q, Q, C


# --------------------------------------------------------------------------------------
# Projectors and the reflection
# --------------------------------------------------------------------------------------
# The inputs are NumPy arrays: the unrolled eliminations of gnipy.linalg then run
# largely on NumPy scalars, so a new shape costs few op-by-op compilations and no jit
# compilation (the same code runs compiled inside every GNI step, which the GNI tests
# below check).


@st.composite
def node_data(draw):
    n, m = draw(st.sampled_from(SHAPES))
    G = draw(spd_metrics(n))
    mu = draw(constraint_forms(m, n))
    scale_p = draw(st.floats(1e-3, 1e3))
    p = scale_p * draw(vectors(n))
    Pi = draw(st.sampled_from([0.0, 1.0])) * scale_p * draw(vectors(n))
    return G, mu, Pi, p


def _conditioning(G, mu):
    """$\\kappa = \\mathrm{cond}(G)\\,\\mathrm{cond}(C)$, $C = \\mu G^{-1}\\mu^T$: the
    two eliminations (without pivoting, backward stable on SPD matrices) lose at most a
    factor of each condition number; their product bounds the relative error of Q and of
    everything built from it."""
    _, _, C = _numpy_projectors(G, mu)
    return float(np.linalg.cond(G) * np.linalg.cond(C))


@property_settings(20)
@given(node_data())
def test_projector_identities(data):
    G, mu, _, _ = data
    n = G.shape[0]
    P, Q = (np.asarray(x) for x in gnipy.projectors(G, mu))
    assert P.shape == Q.shape == (n, n)
    P_ref, Q_ref, _ = _numpy_projectors(G, mu)
    kappa = _conditioning(G, mu)
    # |Q| ≤ sqrt(cond G) for a G-orthogonal projector: products of two projectors carry
    # |Q|²
    size = 1.0 + norm2(Q_ref)
    tol = 20 * n * EPS * kappa * size**2
    assert maxabs(P + Q - np.eye(n)) <= 4 * EPS * size  # P is formed as I − Q
    assert maxabs(Q - Q_ref) <= tol
    assert maxabs(P @ P - P) <= tol
    assert maxabs(Q @ Q - Q) <= tol
    assert maxabs(P @ Q) <= tol and maxabs(Q @ P) <= tol
    # μP = 0: P maps onto D = ker μ (relative to the size of μ)
    assert maxabs(mu @ P) <= tol * norm2(mu)
    # Q is the identity on D^⊥ = G⁻¹ range μᵀ
    Z = np.linalg.solve(G, mu.T)
    assert maxabs(Q @ Z - Z) <= tol * maxabs(Z)
    # G-orthogonality: ⟨Pu, Qw⟩_G = uᵀ PᵀGQ w = 0, i.e. GQ is symmetric
    GQ = G @ Q
    assert maxabs(P.T @ G @ Q) <= tol * norm2(G) * size
    assert maxabs(GQ - GQ.T) <= tol * norm2(G) * size


@property_settings(20)
@given(node_data())
def test_reflection_properties(data):
    G, mu, Pi, p = data
    n = G.shape[0]
    P_ref, Q_ref, _ = _numpy_projectors(G, mu)
    kappa = _conditioning(G, mu)
    size = 1.0 + norm2(Q_ref)
    # max norms (np.linalg.norm squares the entries: it underflows for |p| ~ 1e-196,
    # which is drawn)
    scale = maxabs(p) + maxabs(Pi) + np.finfo(float).tiny
    tol = 20 * n * EPS * kappa * size**2 * scale

    p_minus = np.asarray(gnipy.reflect_momentum(G, mu, Pi, p))
    assert p_minus.shape == (n,)
    # (Comb): p⁻ = (P* − Q*)p⁺ + 2Q*Π, with the independent projectors
    assert maxabs(p_minus - ((P_ref.T - Q_ref.T) @ p + 2 * Q_ref.T @ Pi)) <= tol
    # (GNIintAffa), (GNIintAffb): P*(p⁻ − p⁺) = 0 and Q*((p⁻ + p⁺)/2 − Π) = 0
    assert maxabs(P_ref.T @ (p_minus - p)) <= tol
    assert maxabs(Q_ref.T @ (0.5 * (p_minus + p) - Pi)) <= tol
    # an involution, also with Π ≠ 0: reflecting twice gives p⁺ back
    twice = np.asarray(gnipy.reflect_momentum(G, mu, Pi, p_minus))
    assert maxabs(twice - p) <= 2 * tol
    # p − Π ↦ p⁻ − Π = (P* − Q*)(p − Π) is an isometry of the G⁻¹ norm (P*, Q* are
    # G⁻¹-orthogonal); with Π = 0 (drawn half of the time): |p⁻|_{G⁻¹} = |p⁺|_{G⁻¹}
    Ginv = np.linalg.inv(G)
    u, w = (
        (p - Pi) / scale,
        (p_minus - Pi) / scale,
    )  # normalized: no underflow in the squares
    a, b = u @ Ginv @ u, w @ Ginv @ w
    assert abs(a - b) <= tol / scale * (a + b)
    # the reported momentum p̄ = (p⁻ + p⁺)/2 satisfies the constraints μG⁻¹(p̄ − Π) = 0
    p_bar = np.asarray(gnipy.reported_momentum(G, mu, Pi, p))
    assert maxabs(p_bar - 0.5 * (p_minus + p)) <= tol
    residual = mu @ np.linalg.solve(G, p_bar - Pi)
    assert maxabs(residual) <= tol * norm2(mu) * norm2(Ginv)
    # the one-pass version agrees, and v̄ = G⁻¹p̄
    rr_minus, rr_bar, rr_v = (np.asarray(x) for x in reflect_and_report(G, mu, Pi, p))
    assert rr_minus.shape == rr_bar.shape == rr_v.shape == (n,)
    assert maxabs(rr_minus - p_minus) <= tol
    assert maxabs(rr_bar - p_bar) <= tol
    v_ref = np.linalg.solve(G, p_bar)
    assert maxabs(rr_v - v_ref) <= tol * norm2(Ginv)


# --------------------------------------------------------------------------------------
# Small solves (gnipy.linalg) against numpy.linalg.solve
# --------------------------------------------------------------------------------------
@st.composite
def regular_matrices(draw, n: int):
    """A well-conditioned matrix; half of them need row exchanges.

    - `U diag(s) Vᵀ` with orthogonal U, V and $s_i \\in [0.2, 5]$: cond ≤ 25;
    - a row permutation without fixed points (a cyclic shift) of a strictly diagonally
      dominant matrix $\\mathrm{diag}(d) + 0.1R$ ($|d_i| \\in [1, 2]$, $|R_{ij}| \\le
      1$, so the off-diagonal row sums are ≤ 0.6): cond ≤ (2 + 0.6)/(1 − 0.6) = 6.5, but
      every diagonal entry is one of the small $0.1R_{ij}$, often exactly 0: elimination
      without pivoting breaks down.
    """
    c = 10.0 ** draw(st.integers(-3, 3))
    if draw(st.booleans()):
        U = orthonormal_columns(draw(matrices(n, n)), n)
        V = orthonormal_columns(draw(matrices(n, n)), n)
        s = draw(hnp.arrays(np.float64, (n,), elements=st.floats(0.2, 5.0, **FINITE)))
        return c * (U * s) @ V.T, False
    d = draw(hnp.arrays(np.float64, (n,), elements=st.floats(1.0, 2.0, **FINITE)))
    signs = np.where(draw(hnp.arrays(np.bool_, (n,))), -1.0, 1.0)
    R = draw(matrices(n, n))
    np.fill_diagonal(R, 0.0)
    shift = draw(st.integers(1, n - 1))
    return c * np.roll(np.diag(signs * d) + 0.1 * R, shift, axis=0), True


# Sizes and a fixed width of the matrix right-hand side: every shape costs its own
# traces.
SOLVE_SIZES = [2, 5, 7]


def assert_solves(x, A, b):
    x_ref = np.linalg.solve(A, b)
    assert np.shape(x) == np.shape(b)
    assert np.all(np.isfinite(x))
    # both eliminations are backward stable: forward error ≲ n·ε·cond(A) (relative, max
    # norm)
    tol = 10 * A.shape[0] * EPS * np.linalg.cond(A)
    assert maxabs(np.asarray(x) - x_ref) <= tol * maxabs(x_ref)


@property_settings(20)
@given(st.data())
def test_solve_agrees_with_numpy(data):
    n = data.draw(st.sampled_from(SOLVE_SIZES), label="n")
    A, needs_pivoting = data.draw(regular_matrices(n), label="A")
    b = data.draw(vectors(n, 10.0), label="b")
    B = data.draw(matrices(n, 2, 10.0), label="B")
    if needs_pivoting:
        assert np.all(np.abs(np.diag(A)) <= 0.1 * np.max(np.abs(A)))
    for rhs in (b, B):  # (the elimination turns NumPy input into one JAX array at once)
        assert_solves(np.asarray(solve(A, rhs)), A, rhs)


@property_settings(20)
@given(st.data())
def test_solve_spd_agrees_with_numpy(data):
    n = data.draw(st.sampled_from(SOLVE_SIZES), label="n")
    if data.draw(st.booleans(), label="spd"):
        A = data.draw(spd_metrics(n), label="A")
    else:  # strictly diagonally dominant (documented: no pivoting needed either)
        d = data.draw(
            hnp.arrays(np.float64, (n,), elements=st.floats(1.0, 2.0, **FINITE)),
            label="d",
        )
        R = data.draw(matrices(n, n), label="R")
        np.fill_diagonal(R, 0.0)
        A = np.diag(d) + (0.5 / n) * R
    b = data.draw(vectors(n, 10.0), label="b")
    B = data.draw(matrices(n, 2, 10.0), label="B")
    for rhs in (b, B):
        assert_solves(np.asarray(solve_spd(A, rhs)), A, rhs)
        assert_solves(
            np.asarray(solve_spd(jnp.asarray(A), jnp.asarray(rhs))), A, rhs
        )  # op by op in JAX


_lu_solve_jit = jax.jit(lambda A, b: lu_solve(lu_factor(A), b))


@property_settings(8)
@given(st.data())
def test_lu_factor_and_solve_agree_with_numpy_on_metrics_and_saddle_points(data):
    """The chord iteration's factors (gnipy.linalg.lu_factor, no pivoting up to LU_UNROLL_MAX,
    LAPACK's above): an SPD metric, and the saddle-point matrix [[G, μᵀ], [μ, 0]] of a step with
    multipliers (13 unknowns: the Whipple bicycle's DLA step), whose zero block needs no pivoting
    when the multipliers come last; one size above LAPACK's threshold."""
    n = data.draw(st.sampled_from([3, 8, LU_UNROLL_MAX + 2]), label="n")
    G = data.draw(spd_metrics(n), label="G")
    if data.draw(st.booleans(), label="saddle"):
        m = {3: 1, 8: 5}.get(n, 3)  # 8 + 5: the bicycle's size; one m per n (each shape compiles once)
        mu = orthonormal_columns(data.draw(matrices(n, n)), m).T  # full rank: the block is regular
        A = np.block([[G, mu.T], [mu, np.zeros((m, m))]])
    else:
        A = G
    b = data.draw(vectors(A.shape[0], 10.0), label="b")
    for x in (lu_solve(lu_factor(A), b), _lu_solve_jit(A, b)):
        assert_solves(np.asarray(x), A, b)


# --------------------------------------------------------------------------------------
# The GNI keeps random linear and affine constraints exactly
# --------------------------------------------------------------------------------------
# The system's data are array leaves of `jax.tree_util.Partial` closures: systems of one
# shape share one compilation of the integrator (h is traced too), so hypothesis varies
# only values.


def _lagrangian(M, K, c4, q, v):
    return 0.5 * v @ M @ v - 0.5 * q @ K @ q - c4 * jnp.sum(q**4)


def _constant_forms(MU, q):
    return MU


def _affine_field(c, B, q):
    return c + B @ q


@st.composite
def random_systems(draw, n: int, m: int, affine: bool):
    """A system on Rⁿ: l = ½vᵀMv − ½qᵀKq − c₄Σq⁴, constant μ, and Y = c + Bq if
    `affine`.

    cond(M) ≤ (n²/4 + 1)/0.5 ≤ 10 (n ≤ 4) and cond(μ) ≤ 4, so cond(μM⁻¹μᵀ) ≤ 160: the
    reported momentum meets the constraints to about 160 ε ≈ 4e-14 relative. The
    potential is mild (|K| ≤ 1, c₄ ≤ 0.1) so that 20 steps of h ≤ 0.1 stay in a bounded
    region.
    """
    M = draw(spd_metrics(n, entry=0.5, scaled=False))
    Kraw = draw(matrices(n, n, 1.0 / n))
    K = Kraw.T @ Kraw
    c4 = draw(st.floats(0.0, 0.1))
    MU = draw(constraint_forms(m, n, scaled=False))
    P = jax.tree_util.Partial
    Y = None
    c = np.zeros(n)
    B = np.zeros((n, n))
    if affine:
        c = draw(vectors(n, 2.0))
        B = draw(matrices(n, n, 0.2))
        Y = P(_affine_field, jnp.asarray(c), jnp.asarray(B))
    system = gnipy.System(
        P(_lagrangian, jnp.asarray(M), jnp.asarray(K), jnp.asarray(c4)),
        P(_constant_forms, jnp.asarray(MU)),
        Y,
        n=n,
    )
    q0 = draw(vectors(n, 1.0))
    v_raw = draw(vectors(n, 2.0))
    # the G-orthogonal projection of v_raw onto {v : μ(v − Y(q0)) = 0}, computed here:
    # it meets the constraints to round-off, so `project_v0=True` (kept, as a user would
    # pass it) leaves it as it is; the library's own projection runs op by op and would
    # add seconds of small compilations per shape (it is tested in tests/test_system.py
    # and through the CLI)
    _, Q, _ = _numpy_projectors(M, MU)
    v0 = v_raw - Q @ (v_raw - (c + B @ q0))
    return system, (M, MU, c, B), q0, v0


def assert_gni_run_keeps_the_constraints(system, data, q0, v0, method, h):
    M, MU, c, B = data
    sol = gnipy.simulate(system, method, q0, v0, h=h, steps=20, project_v0=True)
    q, v, p = np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.p)
    assert (
        q.shape == (21, q0.size) and np.all(np.isfinite(q)) and np.all(np.isfinite(v))
    )
    Y = c + q @ B.T
    # μ(v̄ − Y) is a sum of terms of size |μ||v̄|, exact up to a relative round-off ≲
    # 160 ε ≈ 3.5e-14 (see random_systems): 1e-13 (observed: below 1e-15)
    scale = norm2(MU) * max(1.0, maxabs(v), maxabs(Y))
    assert maxabs(sol.constraint_residual) <= 1e-13 * scale
    # the same residual recomputed here from the saved nodes, independently of the
    # library
    assert maxabs((v - Y) @ MU.T) <= 1e-13 * scale
    # the reported velocity is v̄ = G⁻¹p̄ (cond G ≤ 10)
    assert maxabs(p - v @ M) <= 1e-13 * norm2(M) * max(1.0, maxabs(v))


@property_settings(5)
@given(random_systems(4, 2, affine=False), st.floats(0.01, 0.1))
def test_gni_trapezoid_keeps_linear_constraints(drawn, h):
    system, data, q0, v0 = drawn
    assert_gni_run_keeps_the_constraints(system, data, q0, v0, "gni-trapezoid", h)


@property_settings(5)
@given(random_systems(3, 1, affine=True), st.floats(0.01, 0.1))
def test_gni_midpoint_keeps_affine_constraints(drawn, h):
    system, data, q0, v0 = drawn
    assert_gni_run_keeps_the_constraints(system, data, q0, v0, "gni-midpoint", h)


# --------------------------------------------------------------------------------------
# Lie groups and retractions, at random and near-identity points
# --------------------------------------------------------------------------------------
# One compiled check per group evaluates the group identities and both retractions'
# identities at (ξ, η, ζ); compiling them together costs a fraction of compiling them
# apart. (The product group is left to tests/test_lie_groups.py and
# tests/test_retractions.py: it acts blockwise with these factors' code, and its
# compilation would double this section's cost.)
GROUPS = {"SO3": gnipy.SO3(), "SE2": gnipy.SE2(), "R3": gnipy.Rn(3)}
RETRACTIONS = {"cayley": gnipy.Cayley(), "exp": gnipy.Exp()}


def _compile(f, *args):
    """Compile once with XLA's backend optimizations off (about twice as fast to
    compile; the arithmetic keeps IEEE semantics, far below the tolerances)."""
    return (
        jax.jit(f)
        .lower(*args)
        .compile(compiler_options={"xla_backend_optimization_level": 0})
    )


def _mx(x):
    return jnp.max(jnp.abs(x)) if x.size else jnp.zeros(())


def _rel(err, ref):
    """err / |ref|, and err itself (which must then be 0) when ref = 0."""
    return jnp.where(ref > 0, err / jnp.where(ref > 0, ref, 1.0), err)


def _series_expm(X):
    """exp(X) by its Taylor series with scaling and squaring, independent of the groups'
    closed forms (round-off accurate for |X| ≲ 6, here |ad_ξ| ≤ 3)."""
    return series_expm(X, squarings=4, terms=16)


def _group_identities(group, xi, eta, zeta, m):
    e = group.identity()
    # few distinct exponentials: each one inlines the closed form and its Taylor branch
    E, Einv = group.exp(xi), group.exp(-xi)
    g, h = group.exp(zeta), group.exp(eta)
    return {
        "vee_hat": _mx(group.vee(group.hat(xi)) - xi),
        # relative: exercises the Taylor branches at tiny |ξ| (exactly 0 at ξ = 0)
        "log_exp": _rel(_mx(group.log(E) - xi), jnp.linalg.norm(xi)),
        "exp_log": _mx(group.exp(group.log(g)) - g),
        "exp_minus": jnp.maximum(
            _mx(group.compose(E, Einv) - e), _mx(Einv - group.inverse(E))
        ),
        "inverse": jnp.maximum(
            _mx(group.compose(g, group.inverse(g)) - e),
            _mx(group.compose(group.inverse(g), g) - e),
        ),
        "identity": jnp.maximum(
            _mx(group.compose(e, g) - g), _mx(group.compose(g, e) - g)
        ),
        "associativity": _mx(
            group.compose(group.compose(g, h), E)
            - group.compose(g, group.compose(h, E))
        ),
        "Ad_definition": _mx(
            group.Ad(g) @ eta - group.vee(g @ group.hat(eta) @ group.inverse(g))
        ),
        "Ad_exp": _mx(g @ h @ group.inverse(g) - group.exp(group.Ad(g) @ eta)),
        "Ad_homomorphism": _mx(
            group.Ad(group.compose(g, h)) - group.Ad(g) @ group.Ad(h)
        ),
        # Ad and ad agree: Ad_{exp ξ} = e^{ad_ξ}
        "Ad_of_exp": _mx(group.Ad(E) - _series_expm(group.ad(xi))),
        "ad_bracket": _mx(
            group.ad(xi) @ eta
            - group.vee(group.hat(xi) @ group.hat(eta) - group.hat(eta) @ group.hat(xi))
        ),
        "ad_star": _mx(group.ad_star(xi, m) - group.ad(xi).T @ m),
    }


def _retraction_identities(r, group, xi, eta):
    d = group.dim
    e = group.identity()
    T = r.tau(group, xi)
    Tinv = group.inverse(T)
    dtau, dtau_inv = r.dtau(group, xi), r.dtau_inv(group, xi)
    # (eq:dtaudef): dτ_ξ η = (∂_ε τ(ξ + εη) τ(ξ)⁻¹)^∨, column by column from the
    # Jacobian of τ
    J = jax.jacfwd(lambda x: r.tau(group, x))(xi)  # (k, k, d)
    dtau_from_derivative = jax.vmap(
        lambda Jj: group.vee(Jj @ Tinv), in_axes=2, out_axes=1
    )(J)
    # the GNI's Newton solves differentiate dτ⁻¹ (inside FL±): that derivative must be
    # finite
    ddtau_inv = jax.jacfwd(lambda x: r.dtau_inv(group, x) @ eta)(xi)
    return {
        "tau_zero": _mx(r.tau(group, jnp.zeros(d)) - e),
        "tau_minus": jnp.maximum(
            _mx(T @ r.tau(group, -xi) - e), _mx(r.tau(group, -xi) @ T - e)
        ),
        "tau_inv": _rel(_mx(r.tau_inv(group, T) - xi), jnp.linalg.norm(xi)),
        "dtau_dtau_inv": jnp.maximum(
            _mx(dtau @ dtau_inv - jnp.eye(d)), _mx(dtau_inv @ dtau - jnp.eye(d))
        ),
        "dtau_vs_derivative": _mx(dtau - dtau_from_derivative),
        "dtau_Ad": _mx(dtau - group.Ad(T) @ r.dtau(group, -xi)),  # (eq:dtauAd)
        "finite_derivative_of_dtau_inv": jnp.where(
            jnp.all(jnp.isfinite(ddtau_inv)), 0.0, jnp.inf
        ),
    }


@functools.cache
def _group_check(name):
    group = GROUPS[name]

    def f(xi, eta, zeta, m):
        out = {
            f"group.{k}": v
            for k, v in _group_identities(group, xi, eta, zeta, m).items()
        }
        for rname, r in RETRACTIONS.items():
            out.update(
                {
                    f"{rname}.{k}": v
                    for k, v in _retraction_identities(r, group, xi, eta).items()
                }
            )
        return out

    z = jnp.zeros(group.dim)
    return _compile(f, z, z, z, z)


# Absolute tolerances for O(1) quantities (|ξ|, |η|, |ζ| ≤ 3, matrix entries ≤ ~10):
# 50-500 ε; "log_exp" and "tau_inv" are relative to |ξ|; zero means exact.
TOLERANCES = {
    "group.vee_hat": 0.0,
    "group.log_exp": 1e-13,
    "group.exp_log": 1e-13,
    "group.exp_minus": 1e-14,
    "group.inverse": 1e-14,
    "group.identity": 0.0,
    "group.associativity": 1e-13,
    "group.Ad_definition": 1e-13,
    "group.Ad_exp": 1e-13,
    "group.Ad_homomorphism": 1e-13,
    "group.Ad_of_exp": 1e-13,
    "group.ad_bracket": 1e-13,
    "group.ad_star": 1e-13,
}
for _r in RETRACTIONS:
    TOLERANCES.update(
        {
            f"{_r}.tau_zero": 0.0,
            f"{_r}.tau_minus": 1e-14,
            f"{_r}.tau_inv": 1e-13,
            f"{_r}.dtau_dtau_inv": 1e-13,
            f"{_r}.dtau_vs_derivative": 1e-13,
            f"{_r}.dtau_Ad": 1e-13,
            f"{_r}.finite_derivative_of_dtau_inv": 0.0,
        }
    )


def algebra_vectors(d: int, max_norm: float = 3.0):
    """ξ = r u/|u|: exact 0, tiny (1e-9..1e-4, the Taylor branches) or up to `max_norm`
    < π."""
    magnitude = st.one_of(
        st.just(0.0),
        st.floats(-9.0, -4.0).map(lambda k: 10.0**k),
        st.floats(1e-4, max_norm),
    )

    def build(args):
        u, r = args
        nu = np.linalg.norm(u)
        return np.zeros(d) if nu == 0.0 or r == 0.0 else (r / nu) * u

    return st.tuples(vectors(d), magnitude).map(build)


def _assert_identities(name, xi, eta, zeta, m):
    out = {k: float(v) for k, v in _group_check(name)(xi, eta, zeta, m).items()}
    assert set(out) == set(TOLERANCES)
    bad = {k: v for k, v in out.items() if not v <= TOLERANCES[k]}  # NaN fails too
    assert not bad, (name, xi, bad)


@pytest.mark.parametrize("name", sorted(GROUPS))
@property_settings(20)
@given(data=st.data())
def test_group_and_retraction_identities(name, data):
    d = GROUPS[name].dim
    xi = data.draw(algebra_vectors(d), label="xi")
    eta = data.draw(algebra_vectors(d), label="eta")
    zeta = data.draw(algebra_vectors(d), label="zeta")
    m = data.draw(vectors(d, 5.0), label="m")
    _assert_identities(name, xi, eta, zeta, m)


@pytest.mark.parametrize("name", sorted(GROUPS))
def test_group_and_retraction_identities_at_zero(name):
    """ξ = 0 exactly, whatever hypothesis draws: exact identities, finite
    derivatives."""
    d = GROUPS[name].dim
    _assert_identities(name, np.zeros(d), np.ones(d), np.zeros(d), np.ones(d))
