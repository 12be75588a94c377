"""The step solver of every implicit method (gnipy.integrators.base.newton): a Jacobian kept from an
earlier solve (`reuse`), the constant columns of multipliers (`tail_columns`), and the stopping
test at round-off row by row.

The roots are checked against the equations themselves (the residual at the floor) and against
`np.linalg.solve` on linear problems; a solve with an unusable kept Jacobian is held bit for bit
equal to the plain solve (the same arithmetic). Sizes 5 and 13 meet both kinds of chord solver
(the inverse up to gnipy.linalg.UNROLL_MAX = 12, the LU factors above it).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.integrators.base import REUSE_MAX_EVALUATIONS, chord_apply, chord_solver, newton
from gnipy.linalg import UNROLL_MAX

EPS = np.finfo(np.float64).eps


def saddle_problem(n, m, seed, lam_size=1.0):
    """F(x, λ) = (G x + c·sin(x) + μᵀλ − p, μ x − d): a discrete-Lagrangian-like step (a metric
    over h, a mild nonlinearity, multipliers entering through constant columns)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    G = jnp.asarray(A @ A.T + n * np.eye(n)) * 100.0  # ~ G/h
    mu = jnp.asarray(rng.standard_normal((m, n)))
    p = jnp.asarray(rng.standard_normal(n)) * 100.0 * lam_size
    d = jnp.asarray(rng.standard_normal(m))

    def F(w, c=1.0):
        x, lam = w[:n], w[n:]
        return jnp.concatenate([G @ x + c * jnp.sin(x) + mu.T @ lam - p, mu @ x - d])

    def terms(w):  # the magnitude of the terms of each row, for the round-off floor
        x, lam = jnp.abs(w[:n]), jnp.abs(w[n:])
        return jnp.concatenate([jnp.abs(G) @ x + x + jnp.abs(mu.T) @ lam + jnp.abs(p), jnp.abs(mu) @ x + jnp.abs(d)])

    F.terms = terms
    tail = jnp.concatenate([mu.T, jnp.zeros((m, m))])
    scale = jnp.concatenate([jnp.full(n, jnp.max(jnp.abs(p))), jnp.ones(m)])
    return F, tail, scale


def at_round_off(F, z):
    return float(jnp.max(jnp.abs(F(z)) / F.terms(z))) <= 8 * EPS


@pytest.mark.parametrize("n, m", [(3, 2), (8, 5)], ids=["5-inverse", "13-lu"])
def test_an_unusable_kept_solver_gives_the_plain_solve_bit_for_bit(n, m):
    assert (n + m <= UNROLL_MAX) == (n == 3)
    F, _, scale = saddle_problem(n, m, seed=n)
    guess = jnp.zeros(n + m)
    z, info = jax.jit(lambda g: newton(F, g, floor_scale=scale))(guess)
    garbage = jax.tree_util.tree_map(lambda a: jnp.full_like(a, jnp.nan), chord_solver(jnp.eye(n + m)))
    z2, (info2, (solver, keep)) = jax.jit(
        lambda g: newton(F, g, floor_scale=scale, reuse=(garbage, False)))(guess)
    np.testing.assert_array_equal(z2, z)
    assert int(info2.iterations) == int(info.iterations) and bool(info2.ok) and bool(keep)
    # the solver returned is the fresh one, J(guess)'s
    fresh = chord_solver(jax.jacfwd(F)(guess))
    for a, b in zip(solver, fresh):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("n, m", [(3, 2), (8, 5)], ids=["5-inverse", "13-lu"])
def test_a_kept_jacobian_from_a_nearby_problem_reaches_the_same_root(n, m):
    F, tail, scale = saddle_problem(n, m, seed=10 + n)
    # a guess near the root, as a step's guess is (O(h²) off)
    root, _ = newton(F, jnp.zeros(n + m), floor_scale=scale)
    guess = root * (1.0 + 1e-3 * jnp.cos(jnp.arange(n + m)))
    z, info = newton(F, guess, floor_scale=scale)
    # the Jacobian of a neighbouring problem (the nonlinearity 1 % stronger, at another point)
    old = chord_solver(jax.jacfwd(lambda w: F(w, 1.01))(guess + 0.001))
    z2, (info2, (solver, keep)) = newton(F, guess, floor_scale=scale, reuse=(old, True))
    assert bool(info.ok) and bool(info2.ok) and bool(keep)
    np.testing.assert_allclose(z2, z, rtol=0, atol=20 * EPS * float(jnp.max(jnp.abs(z))))
    assert at_round_off(F, z2)
    for a, b in zip(solver, old):  # it converged with the kept one: kept, not formed again
        np.testing.assert_array_equal(a, b)


def test_a_kept_jacobian_that_does_not_contract_is_replaced():
    n, m = 3, 2
    F, _, scale = saddle_problem(n, m, seed=3)
    guess = jnp.zeros(n + m)
    J = jax.jacfwd(F)(guess)
    wrong = chord_solver(J * jnp.asarray([1.0, 0.3, 3.0, 1.0, 1.0])[None, :])  # columns far off
    z, (info, (solver, keep)) = newton(F, guess, floor_scale=scale, reuse=(wrong, True))
    assert bool(info.ok) and bool(keep)
    assert at_round_off(F, z)
    np.testing.assert_allclose(solver[0], chord_solver(J)[0], rtol=1e-12)  # J(guess)'s


def test_a_kept_jacobian_that_has_aged_is_marked_for_renewal():
    """Converging, but slower than REUSE_MAX_EVALUATIONS evaluations: the root is accepted and the
    caller is told to form the Jacobian again next time (`keep` False)."""
    n, m = 3, 2
    F, _, scale = saddle_problem(n, m, seed=4)
    guess = jnp.zeros(n + m)
    J = jax.jacfwd(F)(guess)
    aged = chord_solver(J * 1.2)  # contraction about 1/6 per iteration: converges, slowly
    z, (info, (solver, keep)) = newton(F, guess, floor_scale=scale, reuse=(aged, True))
    assert bool(info.ok) and int(info.iterations) > REUSE_MAX_EVALUATIONS and not bool(keep)
    np.testing.assert_array_equal(solver[0], aged[0])
    assert at_round_off(F, z)


@pytest.mark.parametrize("n, m", [(3, 2), (8, 5)], ids=["5-inverse", "13-lu"])
def test_constant_multiplier_columns_give_the_same_root(n, m):
    F, tail, scale = saddle_problem(n, m, seed=20 + n)
    guess = jnp.zeros(n + m)
    z, info = newton(F, guess, floor_scale=scale)
    z2, info2 = newton(F, guess, floor_scale=scale, tail_columns=tail)
    assert bool(info.ok) and bool(info2.ok)
    np.testing.assert_allclose(z2, z, rtol=0, atol=20 * EPS * float(jnp.max(jnp.abs(z))))


def test_a_linear_step_stops_once_its_residual_is_at_round_off_row_by_row():
    """A linear saddle point with large multipliers: the first correction is exact to round-off
    and the second evaluation finds every row at its floor, so the solve stops there (before the
    row test, the multipliers' corrections, at their floor far above 0.01ε|z|, kept it going until
    two corrections stopped shrinking)."""
    n, m = 4, 3
    rng = np.random.default_rng(7)
    A = rng.standard_normal((n, n))
    G = jnp.asarray(A @ A.T + n * np.eye(n)) * 100.0
    mu = jnp.asarray(rng.standard_normal((m, n)))
    p, d = jnp.asarray(rng.standard_normal(n)) * 1e3, jnp.asarray(rng.standard_normal(m))

    def F(w):
        return jnp.concatenate([G @ w[:n] + mu.T @ w[n:] - p, mu @ w[:n] - d])

    K = np.block([[np.asarray(G), np.asarray(mu).T], [np.asarray(mu), np.zeros((m, m))]])
    exact = np.linalg.solve(K, np.concatenate([p, d]))
    scale = jnp.concatenate([jnp.full(n, jnp.max(jnp.abs(p))), jnp.full(m, 10.0)])
    z, info = newton(F, jnp.zeros(n + m), floor_scale=scale)
    assert bool(info.ok) and int(info.iterations) == 2
    np.testing.assert_allclose(z, exact, rtol=0, atol=1e3 * EPS * np.max(np.abs(exact)))


def test_chord_apply_solves_with_either_kind_of_solver():
    rng = np.random.default_rng(2)
    for N in (5, 13):
        A = rng.standard_normal((N, N)) + N * np.eye(N)
        b = rng.standard_normal(N)
        np.testing.assert_allclose(chord_apply(chord_solver(jnp.asarray(A)), jnp.asarray(b)),
                                   np.linalg.solve(A, b), rtol=1e-12)


def test_a_degenerate_kept_solver_is_not_trusted():
    """A kept solver that corrects nothing (zeros) gives corrections of 0: nothing is accepted from
    them (no contraction measured), their ratio 0/0 stops phase 0, and J(guess) solves."""
    n, m = 3, 2
    F, _, scale = saddle_problem(n, m, seed=5)
    guess = jnp.zeros(n + m)
    zeros = jax.tree_util.tree_map(jnp.zeros_like, chord_solver(jax.jacfwd(F)(guess)))
    z, (info, (solver, keep)) = newton(F, guess, floor_scale=scale, reuse=(zeros, True))
    assert bool(info.ok) and at_round_off(F, z)
    np.testing.assert_allclose(solver[0], chord_solver(jax.jacfwd(F)(guess))[0], rtol=1e-12)


def test_a_kept_solver_that_amplifies_at_first_is_not_accepted_on_its_first_correction():
    """A kept solver whose iteration matrix E = I − J_old⁻¹J is nilpotent with a large entry (as the
    multipliers' rows make it: max-norm 50–95 at spectral radius 0.005–0.01 on the bicycle): from
    a guess 1e-14 off, its first correction is small but off by 50 times the error; the root is
    accepted only after the contraction has been measured, to round-off."""
    n, m = 3, 2
    F, _, scale = saddle_problem(n, m, seed=6)
    root, _ = newton(F, jnp.zeros(n + m), floor_scale=scale)
    J = jax.jacfwd(F)(root)
    E = jnp.zeros((n + m, n + m)).at[n, 0].set(50.0)  # E² = 0
    old = chord_solver(J @ (jnp.eye(n + m) + E))  # J_old⁻¹ = (I − E) J⁻¹
    guess = root + 1e-14 * jnp.max(jnp.abs(root)) * jnp.cos(jnp.arange(n + m))
    z, (info, _) = newton(F, guess, floor_scale=scale, reuse=(old, True))
    assert bool(info.ok) and int(info.iterations) >= 3
    np.testing.assert_allclose(z, root, rtol=0, atol=20 * EPS * float(jnp.max(jnp.abs(root))))
