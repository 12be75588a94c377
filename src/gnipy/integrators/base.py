"""The integrator interface: a small object with an initial state and a one-step map.

Modelled on diffrax's solvers: `init(system, q0, v0, h) -> state`,
`step(system, state, h) -> (state, StepInfo)`, and `observe(system, state, h) -> (b, v, p)`, the
base point (q on R^n, `Point(x, R)` on R^n x G), velocity and momentum that a solution reports at
the node held by `state`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..linalg import solve as small_solve
from ..linalg import UNROLL_MAX, lu_factor, lu_solve, solve_spd
from ..errors import MethodError

__all__ = ["Integrator", "StepInfo", "MethodError", "solve_step", "implicit_solve", "newton", "default_root_finder",
           "chord_solver", "chord_apply", "REUSE_THETA_MAX",
           "momentum_constraint_scale", "all_finite", "explicit_step_info"]


class StepInfo(NamedTuple):
    """What one step reports: whether it succeeded, Newton iterations, the final residual."""

    ok: jax.Array
    iterations: jax.Array
    residual: jax.Array


def all_finite(*arrays) -> jax.Array:
    """Whether every entry of the given arrays (None skipped) is finite."""
    return jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in arrays if a is not None]))


def explicit_step_info(*arrays) -> StepInfo:
    """The :class:`StepInfo` of an explicit step whose new state is `arrays` (None skipped): it
    succeeded if they are finite; no iterations, residual 0."""
    dtype = jnp.result_type(*[a for a in arrays if a is not None])
    return StepInfo(all_finite(*arrays), jnp.asarray(0, dtype=jnp.int32), jnp.asarray(0.0, dtype=dtype))


def default_root_finder():
    """Newton's method with tolerances near round-off, as an optimistix solver (pass it as
    `root_finder=` to use optimistix instead of the built-in :func:`newton`)."""
    import optimistix as optx  # imported where used (~0.1 s): the built-in Newton is the default

    return optx.Newton(rtol=1e-12, atol=1e-12)


#: A residual within FLOOR_FACTOR·ε·(the magnitude of the terms of F) is at the attainable floor:
#: the equations hold as well as float64 can state them, and the iterate is accepted even when the
#: correction test cannot be met (e.g. the multiplier λ of a step, whose correction is ~ε|v|/h).
FLOOR_FACTOR = 64.0

#: The chord iterations with a solver kept from an earlier solve (phase 0 of :func:`newton`,
#: `reuse`) are given up, and J(guess) formed, once an iteration contracts the correction by less
#: than this factor...
REUSE_THETA_MAX = 0.25
#: ... except on their first REUSE_TRANSIENT iterations: the multipliers' rows of the iteration
#: matrix are large where its spectral radius is small (the SymBRiM bicycle's DLA step with the
#: previous step's Jacobian: max-norm 50-95, spectral radius 0.005-0.01), so the first ratios of
#: corrections say little about the contraction.
REUSE_TRANSIENT = 2
#: Where phase 0 took more evaluations of F than this, the kept solver has aged: it still serves
#: this solve, and the caller is told to form a new one at the next (`keep` False). Chosen on the
#: bicycle's native DLA step at h = 0.01 (µs a step, the loop with every node checked): 4.45 (4),
#: 4.31 (5), 4.56 (6), 4.6-4.8 (7), 5.6 (8), 6.2 (never: the Jacobian kept ~30 steps, 11
#: evaluations a step).
REUSE_MAX_EVALUATIONS = 5


def chord_solver(J):
    """What the chord iterations of :func:`newton` solve with, a tuple of arrays: for N ≤
    :data:`gnipy.linalg.UNROLL_MAX` the inverse $J^{-1}$ (an iteration's product with it is
    independent multiply-adds, where substitution with LU factors is a chain of dependent ones:
    slower per iteration up to N = 12), above it the LU factors (:func:`gnipy.linalg.lu_factor`)."""
    n = J.shape[0]
    if n <= UNROLL_MAX:
        return (solve_spd(J, jnp.eye(n, dtype=J.dtype)),)
    return lu_factor(J)


def chord_apply(solver, f):
    """$J^{-1}f$ with the :func:`chord_solver` of J."""
    return solver[0] @ f if f.shape[0] <= UNROLL_MAX else lu_solve(solver, f)


def newton(F: Callable, guess, *, rtol: float = 1e-12, atol: float = 1e-12, max_steps: int = 50, floor_scale=None,
           tail_columns=None, reuse=None):
    r"""Solve a small system `F(z) = 0`: chord iterations with the Jacobian at the guess, then, if
    they do not converge quickly, Newton's method with fresh Jacobians from the guess.

    Written here rather than taken from optimistix because the GNI's steps are tiny (N ≤ 10) and
    per-step cost is what matters: `optx.Newton` with its lineax LU costs several µs per step of
    the rolling ball, this loop with the unrolled solves of :mod:`gnipy.linalg` about 1 µs
    (measured, see BENCHMARKS.md). `optx.Newton` stays available through the `root_finder=`
    argument of the integrators.

    Phase 1 (chord): the GNI's first guess is accurate to $O(h^2)$ and its Jacobian, $\approx
    \mathbb{G}/h$, changes by $O(h)$ over a step, so $z \leftarrow z - J(z_0)^{-1}F(z)$ contracts
    by a small factor per iteration at the cost of one evaluation of F ($F(z_0)$ itself comes with
    the forward-mode Jacobian, so the first iteration evaluates nothing more). Elimination without
    pivoting (stable for the symmetric-dominated Jacobians of discrete Lagrangians, and for their
    saddle-point systems with the multipliers last) forms $J(z_0)^{-1}$ once for N ≤
    :data:`gnipy.linalg.UNROLL_MAX` (each iteration's product with it is independent
    multiply-adds, fused by XLA into a few kernels); above, it factors $J(z_0) = LU$ once
    (:func:`gnipy.linalg.lu_factor`, a third of the inverse's arithmetic) and each iteration
    substitutes (on the native backend, the Whipple bicycle's DLA step of 13 unknowns: 12.0 → 6.8
    µs, where LAPACK's pivoted factorization and 13 right-hand sides took half the step).
    Phase 0 (with `reuse`, Hairer–Wanner IV.8's simplified Newton across steps): the chord
    iterations first run with the solver of an earlier solve, where the caller says it is usable;
    J(guess) is formed (phase 1) only where they do not converge or contract by less than
    :data:`REUSE_THETA_MAX`, and where they took more than :data:`REUSE_MAX_EVALUATIONS`
    evaluations the caller is told to form a new one next time.
    Phase 2 (fallback): when the chord iteration's contraction estimate
    $\theta_k = |\Delta_k|/|\Delta_{k-1}|$ exceeds 1/2, a value is not finite (e.g. a zero pivot
    in the saddle-point systems of methods with multipliers) or phase 1 runs out of iterations,
    Newton's method with partial pivoting restarts from the guess.

    Stopping test (both phases, max norm): $|\Delta_k| \le \mathrm{atol} + \mathrm{rtol}\,|z_{k+1}|$,
    and the iteration has reached round-off: the error estimate of Hairer–Wanner (*Solving ODEs
    II*, IV.8) $\theta_k|\Delta_k|/(1-\theta_k) \le 0.01\,\varepsilon|z_{k+1}|$, or $\theta_k \ge 1/2$
    (no more contraction: the round-off floor), or F at the iterate the correction came from was at
    round-off row by row, $|F_i| \le \varepsilon\,s_i$ with $s_i$ the magnitude of its terms
    (`floor_scale`): then the corrected iterate is as accurate as float64 allows (the SymBRiM
    bicycle's DLA step, whose multipliers' corrections stay at ~1e-13 against a test at 0.01ε|z|
    ≈ 7e-18, took 6.3 evaluations a step before this test, 5.5 after). Stopping at the tolerance
    alone, or a few ε above the floor, leaves an error of the same sign step after step (the chord
    iteration approaches from one side), which adds up to a drift far above round-off over $10^5$
    steps (the energy-theorem tests measure it).

    Round-off floor: the correction test compares $|\Delta|$ with $|z|$, but the attainable
    accuracy of $z$ can be far coarser: for the multiplier $\lambda$ of a step, $F$ is a velocity
    ($\sim|v|$, rounded to $\varepsilon|v|$) and $\partial F/\partial\lambda \sim h$, so $\lambda$
    is only determined to $\varepsilon|v|/h$, above 1e-12 for h < 1e-4. An iterate whose residual is
    within `FLOOR_FACTOR`·ε of the magnitude of the terms of F (`floor_scale`) solves the equations
    as well as float64 can state them; where the correction test fails (no more contraction, or the
    iteration cap), such an iterate is accepted, so a solve never reports failure at round-off.

    Arguments:
        F: the residual function.
        guess: the first guess.
        rtol, atol: the correction tolerances.
        max_steps: the iteration cap of each phase.
        floor_scale: the magnitude of the terms of which F is the difference (a scalar, or one per
            component), e.g. $|p^-|$ for $FL^-(z) - p^-$. Default: $|J(z_0)||z_0| + |F(z_0)|$.
        tail_columns: where the last k unknowns enter F affinely with coefficients that depend on
            nothing the iteration changes (the multipliers of DLA, $\mu(q_k)^T\lambda$, and the
            position multipliers $d\varphi(q_k)^T\Lambda$), their columns of the Jacobian, an
            (N, k) array: the forward-mode Jacobian then pushes N − k tangents through F instead
            of N (the SymBRiM bicycle's DLA step: 8 instead of 13; measured on the native
            backend, its Jacobian 3.2 → 3.1 µs and the loop 7.2 → 7.0 µs a step: the
            multipliers' tangents were already cheap).
        reuse: `(solver, usable)`, the solver (the inverse or the factors of a Jacobian) that an
            earlier solve returned, and whether it may be tried (e.g. it was formed with the same
            step size). Where usable, the chord iterations first run with it (phase 0) and J(guess)
            is formed only where they do not converge, or contract by less than
            :data:`REUSE_THETA_MAX` per iteration (on the Whipple bicycle's DLA step, the
            Jacobian is most of the step's cost). Needs `floor_scale`.

    Returns:
        `(z, StepInfo)`, or with `reuse`, `(z, (StepInfo, (solver, keep)))`: the solver to keep and
        whether it may serve the next solve (False: it has aged or is not finite). `ok`
        is False when phase 2 does not converge in `max_steps` iterations (and its residual is
        above the floor) or a value is not finite; `iterations` counts evaluations of F in all
        phases; `residual` is $\max|F|$ at the last iterate from which a correction was computed.
    """
    dtype = guess.dtype
    eps = jnp.finfo(dtype).eps
    inf = jnp.asarray(jnp.inf, dtype)
    k0 = jnp.asarray(0, jnp.int32)

    def test(dz, z1, prev, f):
        size = jnp.max(jnp.abs(dz))
        scale = jnp.max(jnp.abs(z1))
        theta = size / prev
        # accepted: below the tolerance, and either the estimated error left, θ|Δ|/(1−θ), is far
        # below eps|z| or the iteration no longer contracts (θ ≥ 1/2: the round-off floor). A
        # remaining error of a few eps would have the same sign step after step (a linearly
        # converging iteration approaches from one side) and add up to a drift.
        floor = (theta >= 0.5) | (theta / (1.0 - theta) * size <= 0.01 * eps * scale)
        # or F(z) itself was at round-off, row by row (each |F_i| within ε of the magnitude of its
        # terms), so z1 = z − Δ is as accurate as float64 allows: the multipliers, whose
        # corrections stay at their floor ~ε|v|/h far above 0.01ε|z|, no longer wait for θ ≥ 1/2
        quiet = jnp.all(jnp.abs(f) <= eps * row_scale)
        done = (size <= atol + rtol * scale) & (floor | quiet)
        return size, theta, done & jnp.isfinite(size)

    # phase 1: chord iterations with J(guess) (no pivoting) inverted or factored. The forward-mode
    # Jacobian computes F(guess) on the way: the first iteration uses it instead of evaluating F again
    def value_twice(z):
        f = F(z)
        return f, f

    def jacobian_and_value(z):
        if tail_columns is None:
            return jax.jacfwd(value_twice, has_aux=True)(z)
        k = tail_columns.shape[1]
        tail = z[z.shape[0] - k:]
        J, f = jax.jacfwd(lambda lead: value_twice(jnp.concatenate([lead, tail])), has_aux=True)(z[:z.shape[0] - k])
        return jnp.concatenate([J, tail_columns.astype(J.dtype)], axis=1), f

    n_unknowns = guess.shape[0]
    make_solver, apply = chord_solver, chord_apply

    def chord(solver, z, j, done, prev, residual, stop, theta_max, j_min, cap, kept=False):
        # chord iterations from z (F(z) not yet evaluated) with a fixed solver, up to `cap`
        # evaluations in all. With a kept solver (phase 0) nothing is accepted before a contraction
        # has been measured over j_min iterations (a first correction that is small says nothing
        # about a stale solver: it may be degenerate, or amplify), and a ratio of corrections that
        # is not a number (0/0) stops it
        def cond(c):
            _, j, done, _, _, stop = c
            return (~done) & (~stop) & (j < cap)

        def body(c):
            z, j, _, prev, _, _ = c
            f = F(z)
            dz = apply(solver, f)
            z1 = z - dz
            size, theta, done = test(dz, z1, prev, f)
            stop = ~jnp.isfinite(size) | ((j >= j_min) & (theta > theta_max))
            if kept:
                done = done & (j >= j_min)
                stop = stop | ~jnp.isfinite(theta)
            return z1, j + 1, done, size, jnp.max(jnp.abs(f)), ~done & stop

        return jax.lax.while_loop(cond, body, (z, j, done, prev, residual, stop))

    def fresh_chord(J0, f0, k):
        # phase 1 from J(guess) and F(guess) (the forward-mode Jacobian computes F(guess) on the
        # way: the first iteration uses it instead of evaluating F again)
        solver = make_solver(J0)
        dz0 = apply(solver, f0)
        z1 = guess - dz0
        size0, _, done0 = test(dz0, z1, inf, f0)
        z, k, done, size, residual, _ = chord(solver, z1, k + 1, done0, size0, jnp.max(jnp.abs(f0)),
                                              ~done0 & ~jnp.isfinite(size0), 0.5, 1, k + max_steps)
        return z, k, done, size, residual, solver

    if reuse is None:
        J0, f0 = jacobian_and_value(guess)
        if floor_scale is None:
            floor_scale = jnp.abs(J0) @ jnp.abs(guess) + jnp.abs(f0)
    elif floor_scale is None:
        raise ValueError("newton: reuse= needs floor_scale= (the default is computed from J(guess))")
    row_scale = jnp.broadcast_to(jnp.abs(jnp.asarray(floor_scale, dtype)), (n_unknowns,))
    floor = FLOOR_FACTOR * eps * jnp.max(row_scale)

    def at_floor(residual):
        return residual <= floor

    if reuse is None:
        z, k1, done, size, residual, solver = fresh_chord(J0, f0, k0)
    else:
        # phase 0: chord iterations with the solver of an earlier solve, where the caller says it
        # is usable (Hairer–Wanner IV.8: simplified Newton keeps its Jacobian over steps while it
        # contracts fast); given up once it contracts by less than REUSE_THETA_MAX
        old, usable = reuse
        usable = jnp.asarray(usable, dtype=bool)
        z, k1, done, size, residual, _ = chord(old, guess, k0, jnp.asarray(False), inf, inf, ~usable,
                                               REUSE_THETA_MAX, REUSE_TRANSIENT, max_steps, kept=True)
        # (no acceptance at the round-off floor here: where phase 0 stopped without converging,
        # phase 1 solves from the guess)
        # the Jacobian has aged: where phase 0 took more evaluations than that, the caller forms
        # a new one at the next solve (one evaluation of the Jacobian costs about as much as ten of F)
        aging = usable & done & (k1 > REUSE_MAX_EVALUATIONS)

        def refresh(c):
            k = c[1]
            J0, f0 = jacobian_and_value(guess)
            z, k, done, size, residual, solver = fresh_chord(J0, f0, k)
            # a solver with a zero pivot (the pivoted phase 2 then solves) is not kept: zeros instead,
            # so that the state stays finite (checked here, at the solves that form one, not every step)
            finite = all_finite(*solver)
            solver = jax.tree_util.tree_map(lambda a: jnp.where(finite, a, jnp.zeros_like(a)), solver)
            return z, k, done, size, residual, solver, finite, jnp.asarray(False)

        # phase 1 at most once, and only where phase 0 failed (a loop rather than a cond: under
        # vmap a cond computes both branches, a loop only while some member needs it)
        z, k1, done, size, residual, solver, finite, _ = jax.lax.while_loop(
            lambda c: c[-1], refresh, (z, k1, done, size, residual, old, jnp.asarray(True), ~done))
        aging = aging | ~finite
    # stopped without meeting the correction test, but at the round-off floor: accepted
    done = done | (at_floor(residual) & jnp.isfinite(size) & jnp.all(jnp.isfinite(z)))

    # phase 2 (only where phase 1 failed): Newton with pivoting, fresh Jacobians, from the guess
    def newton_cond(c):
        _, j, done, _, _ = c
        return (~done) & (j < max_steps)

    def newton_body(c):
        z, j, _, prev, _ = c
        J, f = jacobian_and_value(z)
        dz = jnp.linalg.solve(J, f)  # LAPACK: a rare fallback, cheaper to compile
        z1 = z - dz
        size, _, done = test(dz, z1, prev, f)
        return z1, j + 1, done | ~jnp.isfinite(size), size, jnp.max(jnp.abs(f))

    done1 = done
    z = jnp.where(done1, z, guess)
    z, k2, done, size, residual = jax.lax.while_loop(
        newton_cond, newton_body, (z, k0, done1, jnp.where(done1, size, inf), residual)
    )
    k = k1 + k2
    done = done | at_floor(residual)
    ok = done & jnp.isfinite(size) & jnp.all(jnp.isfinite(z))
    if reuse is None:
        return z, StepInfo(ok, k, residual)
    return z, (StepInfo(ok, k, residual), (solver, ~aging))


def momentum_constraint_scale(n: int, p, mu, v, Y):
    """The `floor_scale` of :func:`newton` for a residual of n momentum rows, terms of the size of
    the momentum `p`, followed by the constraint rows μ(v − Y), terms of size |μ|(|v| + |Y|)."""
    m = mu.shape[0]
    return jnp.concatenate([
        jnp.full(n, jnp.max(jnp.abs(p))),
        jnp.max(jnp.abs(mu)) * (jnp.max(jnp.abs(v)) + jnp.max(jnp.abs(Y))) * jnp.ones(m, dtype=p.dtype),
    ])


def implicit_solve(F: Callable, guess, solve: Callable, *args):
    r"""`solve(F, guess, *args) -> (z, info)` with the derivative of the root from the implicit function
    theorem: $dz = -(\partial F/\partial z)^{-1}\,\partial F/\partial\theta\;d\theta$ for whatever
    `F` closes over (the state, the parameters of the system, h).

    The iterations themselves are never differentiated, so forward and reverse mode (`jax.jvp`,
    `jax.grad`) cost one small linear solve per step instead of the iterations' derivatives, and
    reverse mode works through the `while_loop` of :func:`newton`. (Written here rather than with
    `jax.lax.custom_root`, which cannot carry the integer and boolean fields of :class:`StepInfo`
    as auxiliary output.) `solve` must not close over traced values: pass them in `args` (they
    are not differentiated: tolerances, scales).
    """
    F_closed, consts = jax.closure_convert(F, guess)
    return _root(F_closed, solve, len(args), guess, *args, *consts)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _root(F_closed, solve, n_args, guess, *rest):
    args, consts = rest[:n_args], rest[n_args:]
    args = jax.lax.stop_gradient(args)
    return solve(lambda z: F_closed(z, *consts), jax.lax.stop_gradient(guess), *args)


@_root.defjvp
def _root_jvp(F_closed, solve, n_args, primals, tangents):
    guess, *rest = primals
    consts, dconsts = rest[n_args:], tangents[1 + n_args:]
    z, info = _root(F_closed, solve, n_args, guess, *rest)
    # ∂F/∂θ·dθ at the root, then dz = −J⁻¹ (∂F/∂θ·dθ): linear in the tangents, so reverse mode
    # transposes it (jnp.linalg.solve is a custom_linear_solve)
    _, rhs = jax.jvp(lambda *c: F_closed(z, *c), tuple(consts), tuple(dconsts))
    J = jax.jacfwd(lambda zz: F_closed(zz, *consts))(z)
    dz = -jnp.linalg.solve(J, rhs)

    def zero(x):
        x = jnp.asarray(x)
        if jnp.issubdtype(x.dtype, jnp.inexact):
            return jnp.zeros_like(x)
        return np.zeros(x.shape, dtype=jax.dtypes.float0)

    return (z, info), (dz, jax.tree_util.tree_map(zero, info))


def solve_step(F: Callable, guess, *, explicit: bool, solver=None, max_steps: int = 50, floor_scale=None,
               tail_columns=None, reuse=None):
    """Solve `F(z) = 0` for the step unknowns.

    Arguments:
        F: residual function of the unknowns.
        guess: the first guess.
        explicit: `F` is affine in `z`: one Newton step from `guess` is the exact solution, so no
            iteration and no convergence test are needed (the fast path of explicit schemes).
        solver: an optimistix root finder for the implicit case (default: the built-in
            :func:`newton`, tolerance 1e-12).
        max_steps: iteration cap of the implicit case.
        floor_scale: the magnitude of the terms of F, for the round-off floor of :func:`newton`.
        tail_columns: the constant Jacobian columns of the last unknowns where F is affine in them
            (:func:`newton`; ignored by an optimistix `solver`).
        reuse: `(solver, usable)` from an earlier solve (:func:`newton`); with an optimistix
            `solver` it is returned unchanged.

    Returns:
        `(z, StepInfo)`, or with `reuse`, `(z, StepInfo, (solver, keep))` (:func:`newton`).
    """
    if explicit:
        J = jax.jacfwd(F)(guess)
        z = guess - small_solve(J, F(guess))
        ok = jnp.all(jnp.isfinite(z))
        return z, StepInfo(ok, jnp.asarray(1, dtype=jnp.int32), jnp.asarray(0.0, dtype=z.dtype))
    if solver is None:
        # traced values reach newton as arguments of implicit_solve, never by closure
        args = {k: v for k, v in (("floor_scale", floor_scale), ("tail_columns", tail_columns), ("reuse", reuse))
                if v is not None}
        names = tuple(args)
        z, aux = implicit_solve(
            F, guess, lambda f, z0, *a: newton(f, z0, max_steps=max_steps, **dict(zip(names, a))), *args.values()
        )
        return (z, aux) if reuse is None else (z, *aux)
    # The Cauchy test of optx.Newton asks |F| < atol absolutely, but F has a round-off floor of
    # about eps·|dF/dz|·|z| (e.g. G(z - q)/h), which passes atol once |z|/h is large, and the solve
    # then never terminates. Dividing F by that scale leaves the Newton iterates unchanged and
    # makes the f-space test relative; the y-space test still sets the accuracy.
    import optimistix as optx

    scale = jax.lax.stop_gradient(
        jnp.maximum(1.0, jnp.max(jnp.abs(jax.jacfwd(F)(guess))) * jnp.max(jnp.abs(guess)))
    )
    sol = optx.root_find(lambda y, _: F(y) / scale, solver, guess, throw=False, max_steps=max_steps)
    z = sol.value
    residual = jnp.max(jnp.abs(F(z)))
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(z)) & jnp.isfinite(residual)
    info = StepInfo(ok, jnp.asarray(sol.stats["num_steps"], dtype=jnp.int32), residual)
    return (z, info) if reuse is None else (z, info, reuse)


class Integrator(eqx.Module):
    """Base class of all one-step methods.

    Class attributes: `name` (the CLI name) and `order` (the expected global order, or None).
    """

    name: ClassVar[str] = "integrator"
    #: The expected global order of the method (None: not known), stated once, on the method: a
    #: class attribute, or a property where it depends on the method's parameters (the GNI and DLA
    #: read their discrete Lagrangian's). Everything else (`gni methods`, `gni convergence`, the
    #: experiments, the tests) reads it.
    order: ClassVar[int | None] = None

    #: Whether the method keeps holonomic constraints $\varphi(q_k) = 0$ with a position multiplier
    #: (:mod:`gnipy.holonomic`); the others refuse a system that has them (:meth:`validate`).
    holonomic: ClassVar[bool] = False

    def validate(self, system, q0) -> None:
        """Raise :class:`MethodError` if the method cannot integrate `system` (host side): holonomic
        constraints it does not keep (:func:`gnipy.holonomic.require_support`), then :meth:`check`."""
        from ..holonomic import require_support

        require_support(self, system)
        self.check(system, q0)

    def check(self, system, q0) -> None:
        """Raise :class:`MethodError` if the method cannot integrate `system` (host side), beyond
        holonomic constraints (:meth:`validate` checks those first)."""

    def prepare(self, system, q0) -> "Integrator":
        """Return a copy configured for `system` (host side; e.g. choosing the explicit fast path)."""
        return self

    def init(self, system, q0, v0, h):
        """The state at the first node from a configuration and a velocity on the constraints."""
        raise NotImplementedError

    @property
    def start_label(self) -> str:
        """How :meth:`init` sets up the first node, in words (the `start` attribute of a Solution
        and of its files)."""
        return "(q0, v0) as given"

    def settings(self) -> dict:
        """The method's parameters, name -> value (numbers and words; nested methods and discrete
        Lagrangians as `name.field`), for the `method_settings` attribute of a Solution and its
        files: what ran, beyond the method's name."""
        import dataclasses as _dc

        out = {}

        def walk(obj, prefix):
            for f in _dc.fields(obj):
                v = getattr(obj, f.name)
                key = prefix + f.name
                if isinstance(v, Integrator):
                    out[key] = v.name
                    walk(v, key + ".")
                elif _dc.is_dataclass(v):
                    out[key] = type(v).__name__
                    walk(v, key + ".")
                elif v is None:
                    out[key] = "default"
                elif isinstance(v, (bool, int, float, str)):
                    out[key] = v

        walk(self, "")
        return out

    def step(self, system, state, h):
        """Advance one step: returns `(state, StepInfo)`."""
        raise NotImplementedError

    def observe(self, system, state, h):
        """The `(b, v, p)` reported at the node that `state` holds (b: the base point)."""
        raise NotImplementedError

    #: Whether the method is symmetric (self-adjoint, hence time-reversible): its step with $-h$,
    #: conjugated by the involution :meth:`reverse`, is the exact inverse of its step with $h$,
    #: $\Phi_h^{-1} = \sigma\circ\Phi_{-h}\circ\sigma$, on every system (:meth:`symmetric_on` decides
    #: per system). `simulate` with h < 0 runs that inverse (a run of N steps forward and N back
    #: returns to the start to round-off; tested for every symmetric method) and refuses the
    #: methods not symmetric on the system (:func:`gnipy.integrators.reversal.backward`).
    symmetric: ClassVar[bool] = False

    def symmetric_on(self, system) -> bool:
        """Whether the method is symmetric on `system`: what `simulate` reads to run h < 0.

        :attr:`symmetric`, unless the method says otherwise for some systems: the GNI's midpoint $l_d$
        is not where the Lagrangian depends on the orientation and the retraction is Cayley's, Euler
        A and B are where the Lagrangian does not depend on the base point
        (:meth:`gnipy.discrete_lagrangians.DiscreteLagrangian.symmetric_on`). Host side, cheap (a
        probe compiled once per system structure)."""
        return bool(self.symmetric)

    def reverse(self, system, state):
        """The involution $\\sigma$ on states with $\\Phi_h^{-1} = \\sigma\\circ\\Phi_{-h}\\circ\\sigma$ for a
        :attr:`symmetric` method (default: the identity, for states that do not depend on the
        direction of the step, e.g. $(q, v)$ or $(q, p)$)."""
        return state

    #: Whether the method conserves the energy exactly (to round-off) where the motion does
    #: (linear constraints): the discrete-gradient method.
    conserves_energy: ClassVar[bool] = False

    #: Whether the method dissipates the energy where the motion conserves it, by design (the sister
    #: method's inelastic impacts): the run's summary says so (:func:`gnipy.diagnostics.scheme_energy`).
    dissipates_energy: ClassVar[bool] = False

    #: Whether :meth:`change_step` can continue a run with another step size (then `simulate`
    #: shortens the last step to end exactly at `t_final`).
    can_change_step: ClassVar[bool] = False

    def change_step(self, system, state, h_old, h_new):
        """The state from which steps of size `h_new` continue a run made with steps of `h_old`
        (:attr:`can_change_step`; by default the state unchanged, for states that do not depend on h)."""
        if not self.can_change_step:
            raise NotImplementedError(f"{self.name}: the step size cannot change during a run")
        return state

    def memoryless(self):
        """The same step map with nothing in its state that serves only to make steps cheaper
        (DLA's kept Jacobian, :class:`~gnipy.integrators.comparators.DiscreteLagrangeDAlembert`):
        what differentiates the step map with respect to its state (the discrete map's
        eigenvalues, :func:`gnipy.linearize`) uses. By default the method itself."""
        return self

    def continue_from(self, system, state):
        """The state a run continued from `state` (`simulate(state0=...)`) starts with: `state`
        itself, or for a method that keeps something to make steps cheaper (:meth:`memoryless`),
        a state of the memoryless method (a batch member's) with that part empty. By default
        `state` unchanged."""
        return state

    def hidden_momentum(self, system, state, h):
        """The GNI family's hidden momentum $p^+_k - \\bar p_k = Q^*(p^+_k - \\Pi)$ at the node that
        `state` holds (a covector), or None for methods that carry no such state.

        It should stay $\\approx -\\tfrac h2\\mu^T\\lambda$ (docs/conventions.md; see
        :mod:`gnipy.diagnostics`); on some problems it grows to O(1) and the motion goes wrong.
        """
        return None


def require_constant_metric(method: str, system, q0) -> None:
    """Raise :class:`MethodError` unless the system lives on R^n and its metric is constant."""
    if system.group is not None:
        raise MethodError(
            f"method {method!r} is written for systems on R^n (paper §5); {system.name!r} has a group "
            "part: use a gni-* method"
        )
    if not system.has_constant_metric(q0):
        raise MethodError(
            f"method {method!r} is written for a constant metric M (paper §5); "
            f"the metric of {system.name!r} depends on q: use a gni-* method"
        )
