"""The native lowering (gnipy.native.lowering): each primitive's scalar code against XLA's result
for the same jaxpr (the independent formulation), with IEEE special values; loops, branches,
linear algebra and indexing with runtime indices; unsupported primitives named."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gnipy.native import Unsupported
from gnipy.native.function import build_function

# (no subnormals: XLA's CPU code flushes them to zero, see test_subnormals_are_kept)
SPECIAL = np.array([0.0, -0.0, 1.0, -1.5, 2.5, 1e-300, -1e300, np.inf, -np.inf, np.nan, 3.0, 0.5])


def _assert_same(native, xla, ulps=0):
    a, b = np.asarray(native, dtype=np.float64), np.asarray(xla, dtype=np.float64)
    assert a.shape == b.shape
    both_nan = np.isnan(a) & np.isnan(b)
    if ulps == 0:
        ok = both_nan | (a == b)
        # the sign of zero too
        ok &= both_nan | (np.signbit(a) == np.signbit(b)) | (a != 0)
    else:
        ok = both_nan | (a == b) | (np.abs(a - b) <= ulps * np.spacing(np.maximum(np.abs(a), np.abs(b))))
    assert ok.all(), (a[~ok], b[~ok])


def _assert_native_equals_xla(f, *args, ulps=0, rtol=0.0):
    native = build_function(f, *args)(*args)
    xla = jax.tree_util.tree_leaves(jax.jit(f)(*args))
    for n, x in zip(native, xla):
        if rtol:
            np.testing.assert_allclose(n, x, rtol=rtol, atol=0)
        else:
            _assert_same(n, x, ulps)


@pytest.mark.parametrize("op", [jnp.add, jnp.subtract, jnp.multiply, jnp.divide, jnp.maximum, jnp.minimum,
                                jnp.less, jnp.less_equal, jnp.equal, jnp.not_equal, jnp.greater, jnp.arctan2,
                                jnp.power, lambda a, b: jnp.where(a > b, a, b)])
def test_binary_ops_bit_for_bit_with_special_values(op):
    a = np.repeat(SPECIAL, SPECIAL.size)
    b = np.tile(SPECIAL, SPECIAL.size)
    ulps = 2 if op in (jnp.arctan2, jnp.power) else 0
    _assert_native_equals_xla(op, a, b, ulps=ulps)


@pytest.mark.parametrize("op", [jnp.sqrt, jnp.abs, jnp.negative, jnp.sign, jnp.floor, jnp.ceil, jnp.isfinite,
                                jnp.square, lambda x: x ** 3, lambda x: x ** -2])
def test_exact_unary_ops(op):
    _assert_native_equals_xla(op, SPECIAL)


@pytest.mark.parametrize("name", ["sin", "cos", "exp", "log", "tan", "arcsin", "arctan", "tanh", "log1p", "expm1",
                                  "sinh", "cosh"])
def test_transcendental_ops_within_two_ulps_of_numpy(name):
    """The native code calls the C library's functions: within 2 units in the last place of
    NumPy's (XLA's own approximations are further off, e.g. log1p by up to 50 units)."""
    x = np.concatenate([SPECIAL, np.linspace(-3, 3, 61)])
    got = build_function(getattr(jnp, name), x)(x)[0]
    with np.errstate(all="ignore"):
        want = getattr(np, name)(x)
    _assert_same(got, want, ulps=2)


def test_rsqrt_is_one_over_sqrt():
    x = SPECIAL
    with np.errstate(all="ignore"):
        _assert_same(build_function(jax.lax.rsqrt, x)(x)[0], 1.0 / np.sqrt(x))


def test_integer_arithmetic_and_division_by_zero():
    a = np.array([7, -7, 0, 5, -9, 2**31 - 1], dtype=np.int32)
    b = np.array([2, 2, 3, 0, -4, 1], dtype=np.int32)
    _assert_native_equals_xla(lambda x, y: (x + y, x * y, x - y, jax.lax.div(x, y), jax.lax.rem(x, y), jnp.maximum(x, y),
                         x < y, (x > 0) & (y > 0), ~(x > 0), jnp.abs(x), jnp.sign(x)), a, b)


def test_conversions():
    x = np.array([0.0, -0.0, 1.7, -2.5, 3.99, 1e9])
    _assert_native_equals_xla(lambda v: (v.astype(jnp.int32), (v > 1).astype(jnp.float64), v.astype(jnp.int32).astype(jnp.float64),
                      v.astype(bool)), x)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.lists(st.one_of(st.floats(min_value=-1e100, max_value=1e100).filter(lambda v: v == 0 or abs(v) > 1e-100),
                          st.sampled_from([np.inf, -np.inf, np.nan, -0.0])), min_size=6, max_size=6))
def test_elementwise_expressions_property(values):
    """Bit for bit with XLA on expressions where no product feeds a sum (XLA may contract a·b + c
    into a fused multiply-add, e.g. jax 0.4.38 for 1 + x·x at x = 1.2519617379298333, one unit
    off the two IEEE roundings of the native code, which cancellation can then amplify); values
    kept away from subnormal results, which XLA flushes to zero. Derandomized: the same examples
    in every run."""
    x = np.array(values)
    _assert_native_equals_xla(_expr, x)


def _expr(x):
    y = x[:3] - x[::-1][:3] / (1.0 + jnp.abs(x[3:]))
    z = x[:3] * x[3:]
    return jnp.where(jnp.isfinite(y), y, 0.0) * 2.0, jnp.max(x), jnp.sum(x[:3] + x[3:]), jnp.min(y), z



def test_reductions_argmax_sort_with_nan():
    x = np.array([1.0, np.nan, 3.0, -0.0, 0.0, -np.inf, 3.0])
    _assert_native_equals_xla(lambda v: (jnp.max(v), jnp.min(v), jnp.sum(v), jnp.prod(v), jnp.argmax(v), jnp.argmin(v), jnp.sort(v),
                      jnp.argsort(v), jnp.all(v > 0), jnp.any(v > 2)), x)
    y = np.array([2.0, -1.0, 5.0, 0.5])
    _assert_native_equals_xla(lambda v: (jnp.max(v), jnp.argmax(v), jnp.sort(v), jnp.argsort(v)), y)


def test_predicates_of_constants_fold_to_booleans():
    """is_finite of an entry known at lowering time (a structural zero of a factor) folds to a
    boolean that the logical reductions accept (it once folded to a double, and `all` of it failed)."""
    x = np.array([1.0, np.inf, 2.0])
    _assert_native_equals_xla(lambda v: (jnp.all(jnp.isfinite(jnp.concatenate([v[::2], jnp.zeros(2)]))),
                                         jnp.all(jnp.isfinite(jnp.concatenate([v, jnp.zeros(2)]))),
                                         jnp.isfinite(jnp.zeros(2)) & (v[:2] > 0)), x)


def test_structure_ops():
    A = np.arange(24.0).reshape(2, 3, 4)
    _assert_native_equals_xla(lambda a: (a.T, a.reshape(6, 4), a[:, 1:, ::2], jnp.concatenate([a, a], axis=1), jnp.flip(a, 2),
                      jnp.pad(a, ((1, 0), (0, 2), (1, 1))), jnp.broadcast_to(a[:, :1], (2, 3, 4)),
                      jnp.stack([a[0], a[1]]), jnp.split(a, 2, axis=2)[1], jnp.expand_dims(a, 1),
                      jax.lax.pad(a, 0.0, ((0, 0, 0), (1, -1, 1), (-1, 0, 0)))), A)


def test_dot_general_with_batch_and_contraction():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((2, 3, 4)), rng.standard_normal((2, 4, 5))
    m, v = rng.standard_normal((3, 3)), rng.standard_normal(3)
    native = build_function(lambda x, y, M, w: (jnp.einsum("bij,bjk->bik", x, y), M @ w, w @ M @ w,
                                                 jnp.outer(w, w)), a, b, m, v)(a, b, m, v)
    for got, want in zip(native, (np.einsum("bij,bjk->bik", a, b), m @ v, v @ m @ v, np.outer(v, v))):
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 7])
def test_solve_lu_and_triangular_with_pivoting(n):
    rng = np.random.default_rng(n)
    A = rng.standard_normal((n, n))
    A[0, 0] = 1e-12  # forces a row exchange
    b = rng.standard_normal(n)
    lu, piv, perm = build_function(lambda M: jax.lax.linalg.lu(M), A)(A)
    lu_x, piv_x, perm_x = jax.lax.linalg.lu(A)
    np.testing.assert_array_equal(piv, piv_x)
    np.testing.assert_array_equal(perm, perm_x)
    np.testing.assert_allclose(lu, lu_x, rtol=1e-13, atol=1e-13)
    x = build_function(lambda M, r: jnp.linalg.solve(M, r), A, b)(A, b)[0]
    np.testing.assert_allclose(A @ x, b, rtol=0, atol=1e-12 * np.linalg.cond(A))
    for lower in (True, False):
        for trans in (0, 1):
            for left in (True, False):
                T = np.tril(A) + 3 * np.eye(n) if lower else np.triu(A) + 3 * np.eye(n)
                B = rng.standard_normal((n, 2)) if left else rng.standard_normal((2, n))
                f = lambda M, r: jax.lax.linalg.triangular_solve(M, r, left_side=left, lower=lower,  # noqa: E731
                                                                  transpose_a=bool(trans))
                np.testing.assert_allclose(build_function(f, T, B)(T, B)[0], jax.jit(f)(T, B), rtol=1e-13,
                                           atol=1e-13)


def test_runtime_indices_gather_dynamic_slice():
    x = np.arange(20.0).reshape(4, 5)
    for i in (0, 2, 3, 7, -1):  # out of range: clamped, as XLA clamps
        _assert_native_equals_xla(lambda a, k: (a[k % 4], jax.lax.dynamic_slice(a, (k, jnp.int32(1)), (2, 3)), jnp.take(a.ravel(), k + 3),
                             a[:, k % 5]), x, np.int32(i))


def test_scatter_at_known_positions_with_drop_mode():
    """`x.at[i].set(y)` and `.add` (XLA's FILL_OR_DROP scatter) at positions known when the code is
    made, a window out of range included: XLA drops such a window whole, and so does the native code."""
    x = np.arange(12.0).reshape(3, 4)

    def f(a, y):
        return (a.at[1].set(y[:4]), a.at[0, 2].add(y[0]), a.at[:, 1].set(y[:3]), a.at[5].set(y[:4]),
                jnp.zeros(6).at[jnp.array([0, 2, 9])].set(y[:3]))

    _assert_native_equals_xla(f, x, np.array([-1.5, 2.0, 0.25, 7.0]))


def test_while_cond_scan_loops():
    def f(x, n):
        def body(c):
            i, acc = c
            acc = jax.lax.cond(i % 2 == 0, lambda a: a * 1.5 + x, lambda a: a - 0.25 * x, acc)
            return i + 1, acc
        _, acc = jax.lax.while_loop(lambda c: c[0] < n, body, (0, x))
        s, ys = jax.lax.scan(lambda c, xi: (c + xi, c * xi), 0.0, x)
        t = jax.lax.fori_loop(0, 100, lambda i, c: c * 0.99 + 1.0, 0.0)
        w = jax.lax.switch(n % 3, [lambda: x[0], lambda: x[1], lambda: x[2]])
        return acc, s, ys, t, w

    x = np.array([0.5, -1.0, 2.0])
    for n in (0, 1, 5, 12):
        # XLA contracts c*0.99 + 1 into a fused multiply-add; the native code rounds each operation
        _assert_native_equals_xla(f, x, np.int32(n), rtol=1e-14)


def test_subnormals_are_kept():
    """IEEE gradual underflow: the native code keeps subnormal numbers (XLA's CPU code flushes
    them to zero, so here the exact IEEE answers are the reference)."""
    x = np.array([1e-310, 2.5e-320])
    got = build_function(lambda v: (v + 0.0, v * 0.5, v[0] - 0.5e-310), x)(x)
    np.testing.assert_array_equal(got[0], x)
    np.testing.assert_array_equal(got[1], x * 0.5)
    assert got[2] == 1e-310 - 0.5e-310 and got[2] != 0.0


def test_unsupported_primitive_is_named():
    with pytest.raises(Unsupported, match="cumsum"):
        build_function(lambda x: jnp.cumsum(x), np.arange(3.0))
