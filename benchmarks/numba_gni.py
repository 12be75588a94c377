"""The GNI step hand-written in Numba: the speed limit for issue 16's "native backend" benchmark.

This module is the *upper bound* of the per-step benchmark, not a baseline to beat by a large
factor: the same three GNI steps as :mod:`benchmarks.numpy_gni` (and thus as gnipy's GNI), ported
by hand to scalar, allocation-free Numba code the way a performance-minded researcher would write
them for one model, and two more cases that numpy_gni does not have (issue 35, point 2: "on the
three cases and on two more, a group model with unequal moments, a composition"): gnipy's
composition `"yoshida4-gni-trapezoid"` on the rolling ball ex. 2 and gnipy's `"sgni-trapezoid"` on
Suslov's problem (below, "The two added cases"). Issue 16's target for gnipy's native backend is to come within 2× of these
timings (µs/step of one trajectory, trajectory-steps/s of a batch). gnipy itself never imports or
uses this module; it exists only for the benchmark and its tests
(`tests/test_benchmark_numba.py`, which checks it against numpy_gni and gnipy).

There are two generations of kernels (issue 35, point 1: "the baseline is the limit"):

- the current kernels (`run_rolling_ball_ex2`, ..., `CASES`): the fastest scalar code we could write
  for each case (below);
- the first version, kept unchanged as the "old baseline" so that the benchmark can show the
  history: `run_rolling_ball_ex2_v1`, `run_chaplygin_sphere_v1`, `run_contact_oscillator_v1` (and
  their `_batch_v1`, `run_ball_v1`, `run_oscillator_v1`), gathered as :class:`Case` objects in
  `LEGACY_CASES` (`get_case(name, legacy=True)`). It solves for the increments with Gaussian
  elimination (partial pivoting) and stops Newton at $\\|\\delta\\| \\le 10^{-14}\\max(1, \\|z\\|)$
  (`NEWTON_TOL_V1`): ~3 iterations per step, the last one only confirming convergence.

`benchmarks/c_gni.c` (loaded by :mod:`benchmarks.c_gni`) is the rolling ball's current kernel
ported line by line to C: it computes the same numbers bit for bit.

Measured on the 2-core test machine (µs per step of one trajectory at h = 0.01 from the case's
initial state, 2,000 steps for the rolling ball and 100,000 for the others; minimum of 30 runs
interleaved in one process, noisy to ~5%; in parentheses the mean iterations per step):

    case                 first version   newton        chord         predicted-newton
    rolling-ball-ex2     0.135 (2.97)    0.056 (2.00)  0.055 (2.26)  0.051 (1.00)   case: predicted-newton
    contact-oscillator   0.087 (2.76)    0.040 (2.00)  0.037 (2.00)  0.038 (1.00)   case: chord
    chaplygin-sphere     0.137 (3.00)    0.069 (2.02)  0.075 (3.00)  0.079 (1.93)   case: newton

and the two added cases (the same machine, a later session: minimum of 30 runs interleaved in one
process, over three processes, while a CI job used both cores: noisy, ~5-10%; in the same processes
the rolling ball and the Chaplygin sphere above took 0.049-0.052 and 0.065-0.070, close to the
table; the composition over 2,000 steps as its base case, its iterations summed over its three
substeps; Suslov over 100,000):

    case                       first version   newton        chord         predicted-newton
    rolling-ball-ex2-yoshida4  —               0.183 (6.00)  0.181 (7.73)  0.162 (3.00)   case: predicted-newton
    suslov                     —               0.069 (2.00)  0.062 (2.00)  0.069 (1.00)   case: chord

(the composition: three ball steps and two impulse rescalings, ~3.2 times the rolling ball's step.)

The C port of the rolling ball takes 0.046 µs/step (timed inside C; `cc -O3 -march=native
-fno-fast-math -ffp-contract=off`, GCC 12). Where the gain comes from (rolling ball; the others
alike): the first version with the stopping test loosened to 1e-10 (2.0 iterations) takes 0.105;
Cramer's rule instead of the pivoted elimination saves ~25% of the current step (0.077 -> 0.058
with the same iterations); the predictor sweeps save one Jacobian and solve (0.056 -> 0.051);
Numba-level inlining ~3%.

How it was derived. Every formula is numpy_gni's (read its docstring: reflection (Comb), the
discrete Legendre transforms FL⁻/FL⁺ of the trapezoid and midpoint discrete Lagrangians, the Cayley
retraction and dcay⁻¹, the node report p̄, v̄), written out component by component. Each choice
below was timed and checked against a long-double run of the same scheme (the first version's
formulas in 80-bit arithmetic, Newton to 1e-30).

- **The unknown is the step's mean velocity**: $\\xi = \\sigma/h$ for the balls (σ the Cayley
  coordinate of the rotation), $v = (q_{k+1} - q_k)/h$ for the oscillator; the residual is
  $F = FL^- - p^-$ itself, $\\mathbb{G}\\xi + O(h) - p^-$: its two big terms are subtracted first
  (`(M0 - pm2)`, exact when within a factor 2) and the O(h) terms added after, and the new
  position is $x_k + h\\xi$, so the round-off is that of the increment, not of $x_k$ (as in the
  first version, which solved for the increment itself).
- **FL⁺ from the identity FL⁺ = FL⁻ − (FL⁻ − FL⁺)**: at the solution FL⁻ = p⁻, so
  $p^+_{k+1} = p^- - h\\,\\xi\\times I\\xi$ (balls) and $p^- - h\\nabla V(\\bar q)$ (oscillator), and
  the balls' x-part is simply $p^+_x = p^-_x$ (their l_d is quadratic in Δx). The same map in
  exact arithmetic, but a Newton error e of ξ enters p⁺ as O(|ξ|e) instead of O(e/h) (FL⁺
  evaluated directly amplifies the residual by 1/h): the reason why Newton may stop earlier. No
  division by h is left in the step.
- **The gyroscopic term in Euler's form**: with I diagonal, $\\xi\\times I\\xi = ((I_3 - I_2)\\xi_1\\xi_2,
  (I_1 - I_3)\\xi_0\\xi_2, (I_2 - I_1)\\xi_0\\xi_1)$, and the Jacobian's skew part
  $\\tfrac h2(\\hat\\xi I - \\widehat{I\\xi})$ has the six entries $\\tfrac h2(I_3 - I_2)\\xi_2$, ...:
  two products per entry instead of four, and no cancellation.
- **Residual and Jacobian fused** (`_ball_fj`, `_osc_fj`): they share Iξ, ξ·Iξ, (h²/4)ξ, the
  mid-point and its squares; $J = I + \\tfrac h2(\\hat\\xi I - \\widehat{I\\xi}) + \\tfrac{h^2}{4}((\\xi\\cdot
  I\\xi)E + 2\\xi(I\\xi)^T)$ (balls), $E + \\tfrac{h^2}{4}\\nabla^2V(\\bar q)$ (oscillator).
- **Closed-form solves**: Cramer's rule for the balls' 3×3 (the adjugate times one reciprocal of
  det J: J = I + O(h) is far from singular, no pivoting needed, and the cofactors do not wait for
  one another as elimination's pivots do); the oscillator's y-equation is linear (V is ½y² in y)
  and solved in closed form, its (x, z) part is a 2×2 inverted by its adjugate.
- **Projectors in closed form**: the rolling ball's μ is constant, so $C = \\mu\\mathbb{G}^{-1}\\mu^T$
  is diagonal and λ is one quotient per component, $\\lambda_0 = (I_2(p_0 - \\Pi_0) - mr\\,p_3)/(I_2 +
  mr^2)$ (one division instead of four); the Chaplygin sphere's 2×2 C(R) is inverted by its
  adjugate; the oscillator's C = 1 + y² is a scalar.
- **The Cayley map applied without forming cay(σ)**: $R\\,\\mathrm{cay}(\\sigma) = R + \\alpha(A +
  \\tfrac12 A\\hat\\sigma)$ with the rows $A_i = R_i\\times\\sigma$ (Chaplygin sphere, body frame),
  $\\mathrm{cay}(\\sigma)R = R + \\alpha(B + \\tfrac12\\hat\\sigma B)$ with the columns $B_j = \\sigma\\times
  R_{:j}$ (rolling ball, space frame), $\\alpha = 4/(4 + |\\sigma|^2)$: the division overlaps the
  cross products, which shortens the Chaplygin sphere's dependency chain (its R enters the next
  projector); measured faster than cay(σ) and a 3×3 product for both balls.
- **Divisions**: every division that rounds a *result* stays a division (by m, by I in the
  Chaplygin projector, by the projectors' determinants, by $1 + h^2/4$ and $4 + |\\sigma|^2$): a
  product with a precomputed reciprocal rounds the same way at every step, a bias that adds up (the
  first version measured ~1e-13 instead of ~1e-14 drift over 1000 steps from 1/h; reciprocals of I
  in the Chaplygin projector would gain ~4%, within the noise, for no measured loss of accuracy).
  Reciprocals are used only where the rounding is corrected later: the first guess
  ($\\bar\\xi = \\bar p_\\omega/I$), the predictor sweeps (Newton follows) and Newton's update (one
  reciprocal of det: the increment is ~1e-9 at the last iteration).
- **Inlined by Numba** (`inline="always"` on the step's pieces): LLVM's inliner leaves a function
  as large as the step or its Newton solve as a call (arguments through the stack, the loop
  invariants h/2, (h/2)(I3 − I2), 1/I recomputed each step); inlined, the step loop is one
  function (measured ~3-4% faster).
- **No allocation**: the state is a tuple of scalars inside the step loop, 3×3 matrices are nine
  scalars, cross products are written out.
- **IEEE arithmetic**: `fastmath=False` (no reassociation, no FMA contraction); every sum is
  evaluated in the order written.

The iteration (issue 35). Three solvers were written and timed for each case (`SOLVERS`; all are
available through the general kernels' `solver` argument and :func:`count_iterations`):

- `"newton"`: full Newton from gnipy's first guess ($\\xi_0 = \\bar\\xi_k$, $v_0 = \\bar v_k$), the
  Jacobian refreshed at every iterate;
- `"chord"`: the Jacobian frozen at the first guess (gnipy's phase 1), its inverse formed once;
- `"predicted-newton"`: `PREDICTOR_SWEEPS` fixed-point sweeps $\\xi \\leftarrow I^{-1}(p^- - \\tfrac h2
  \\xi\\times I\\xi - \\tfrac{h^2}{4}\\xi(\\xi\\cdot I\\xi))$ (oscillator: $v \\leftarrow p^- - \\tfrac h2
  \\nabla V(q_k + \\tfrac h2 v)$) from the same guess, each as cheap as a residual and contracting by
  ~h|ξ|, then Newton.

Stopping rules. Newton (both variants) stops at an increment $\\|\\delta\\|_\\infty \\le
10^{-8}\\max(1, \\|z\\|_\\infty)$ (`NEWTON_TOL`, z = ξ or v): Newton converges quadratically, so the
error left after that update is $\\approx K\\|\\delta\\|^2$, $K = \\tfrac12\\|J^{-1}\\|\\,\\|F''\\|$ at most
~1e-2 here ($F'' = O(h)$ for the balls, $O(h^2)$ for the oscillator): $\\le 10^{-18}$, below the
round-off of z (ε|z| ≈ 1e-16). The chord iteration converges linearly; with the contraction θ
estimated from two consecutive increments it stops when Hairer–Wanner's estimate of the error
left, $\\theta\\|\\delta\\|/(1 - \\theta)$, is $\\le 10^{-17}\\max(1, \\|z\\|)$ (`CHORD_TOL`; at least two
iterations, or a zero increment). At most `NEWTON_MAXITER` = 20 iterations; a step that has not met
its test (or produced a non-finite value) returns NaN for the whole state, which then stays NaN: a
failure is never silent. All three solvers and the first version agree to ≤ 7e-15 (relative) over
1000 steps, and the case's solver (`CASE_SOLVER`: the fastest, see the table; `EX2_SOLVER`,
`OSC_SOLVER`, `CHAPLYGIN_SOLVER`) is within ~2e-15 of the long-double run after 1000 steps (the first
version: ~4e-15); over 20,000 steps all of them, the first version included, drift from it alike
(the rolling ball's trajectory amplifies round-off to ~1e-11, the others stay below ~3e-14).

The two added cases (issue 35, point 2). Neither has a first version (`LEGACY_CASES` lacks them,
`get_case(name, legacy=True)` is None) nor a numpy_gni version; both are transcribed from gnipy's
own implementation and checked against gnipy's `simulate` (tests/test_benchmark_numba.py).

- **"rolling-ball-ex2-yoshida4"**, gnipy's `"yoshida4-gni-trapezoid"` on the rolling ball ex. 2
  (`gnipy.integrators.composition.Composition`): the substeps γ₁h, γ₂h, γ₁h of Yoshida's triple
  jump (`YOSHIDA4`, γ₁ = 1/(2 − 2^{1/3}), γ₂ = −2^{1/3}γ₁: the middle substep goes back in time) are
  the rolling ball's `_ball_step` itself (any solver), and between two substeps the hidden impulse
  is rescaled to the new step as gnipy's `GNI.change_step` does, $p^+ \\leftarrow \\bar p +
  (\\gamma_i h/\\gamma_{i-1}h)(p^+ - \\bar p)$, the ratio signed and computed from the rounded
  substeps as gnipy computes it, $p^+ - \\bar p = \\mu^T\\lambda$ in the closed form of the ball's
  projector (`_ex2_rescale`). The start is gnipy's consistent one for the first substep (a
  composition of a GNI always starts so), $p^+_0 = \\mathbb{G}v_0 - \\tfrac{\\gamma_1 h}{2}\\mu^T
  \\lambda_0$, with the continuous multiplier λ₀ in closed form
  (:func:`rolling_ball_ex2_consistent_start`; `Case.initial_state(h)`: it depends on h). The three
  substeps run in a loop over one inlined copy of the step (three copies compile 3× longer, ~9 s,
  and run no faster). Its solver: predicted-newton, one Newton iteration per substep.
- **"suslov"**, gnipy's `"sgni-trapezoid"` (`gnipy.integrators.gni_variants.SymmetricImpulseGNI`)
  on gnipy's `"suslov"` (SO(3), body angular velocity, a full symmetric inertia tensor with unequal
  moments, one constraint ⟨a, Ω⟩ = 0, a = e₃; `SUSLOV_PARAMS`). The GNI itself (`gni-trapezoid`)
  is qualitatively wrong on Suslov (its hidden momentum leaves its band at t ≈ 27: gnipy's
  `sol.healthy` is False over 10⁵ steps; the methods guide says the same of every `gni-*`), and
  gnipy's default method there is
  the discrete gradient, not a GNI step; sgni-trapezoid is healthy over 10⁵ steps on gnipy's
  native backend. Its state is (R, p̄), p̄ on the constraint; gnipy solves one Newton system in (σ, α), α
  the impulse acting at both ends of the step. The constraint row is linear in α, so α is
  eliminated in closed form and the step is 3 equations in the mean velocity ξ = σ/h with an
  oblique projector P (derivation above `_suslov_consts`); the Jacobian $I + \\tfrac h2
  P(\\hat\\xi I - \\widehat{I\\xi}) + \\tfrac{h^2}{4}((\\xi\\cdot I\\xi)E + 2\\xi(I\\xi)^T)$ is solved by
  Cramer's rule, R advances by the Chaplygin sphere's closed-form body-frame Cayley update, and
  $\\bar p_{k+1} = (\\bar p - c_0e) - hP(\\xi\\times I\\xi)$ has no division by h ($c_0 = a^TI^{-1}\\bar
  p$, zero up to round-off, kept as gnipy keeps it: the constraint is restored at every node). I is
  not diagonal, so the gyroscopic term is not in Euler's two-product form; I⁻¹ (for the first
  guess ξ₀ = v̄ = I⁻¹p̄ and the predictor), k = I⁻¹a and e = a/(aᵀk) are loop invariants. Its
  solver: the chord (2.0 iterations, each a residual and a 3×3 product, cheaper than Newton's two
  Jacobians).

Over 1000 steps at h = 0.01 the added cases agree with gnipy's `simulate` (XLA) to 6.5e-15
(composition) and 4.3e-15 (Suslov) relative (every solver ≤ 7.4e-15; gnipy's native backend ≤
9.4e-15); their solvers agree among themselves to ≤ 9e-16 (≤ 1.4e-14 over 20,000 steps of Suslov).
They were not checked against a long-double run as the first three were.

States (flat float64 vectors, the integrator state, not the reported node):

- balls ("rolling-ball-ex2", "chaplygin-sphere", "rolling-ball-ex2-yoshida4"): 16 numbers
  `(x, y, R (3×3, row-major), p⁺ (5))`;
- "contact-oscillator" (gni-midpoint): 6 numbers `(q (3), p⁺ (3))`;
- "suslov" (sgni-trapezoid): 12 numbers `(R (3×3, row-major), p̄ (3))`.

API:

- `run_rolling_ball_ex2(state0, h, steps)`, `run_contact_oscillator(state0, h, steps)`,
  `run_chaplygin_sphere(state0, h, steps)` -> the final state (one trajectory; the whole loop is
  compiled); the first version: the same names with `_v1`;
- `run_rolling_ball_ex2_batch(states0, h, steps)` etc. -> the final states (B, m): `numba.prange`
  over the trajectories (`parallel=True`, all cores);
- the general kernels `run_ball(state0, h, steps, params, chaplygin, solver=-1)` /
  `run_ball_batch(...)` (params `(m, r, I1, I2, I3, Omega)`; solver: a value of `SOLVERS`, by
  default the case's), `run_oscillator(state0, h, steps, eps, solver=OSC_SOLVER)` /
  `run_oscillator_batch(...)`, `run_ball_yoshida4(state0, h, steps, params, solver=-1)` /
  `run_ball_yoshida4_batch(...)` (the rolling ball's composition: constant μ) and
  `run_suslov_general(state0, h, steps, params, solver=-1)` / `run_suslov_general_batch(...)`
  (params as `SUSLOV_PARAMS`); the added cases' own `run_rolling_ball_ex2_yoshida4` and
  `run_suslov` (and their `_batch`);
- `CASES[name]` (names as gnipy's models: "rolling-ball-ex2", "contact-oscillator",
  "chaplygin-sphere", "suslov"; and "rolling-ball-ex2-yoshida4") -> a :class:`Case` with
  `initial_state(h=0.01)`, `run(state0, h, steps)`, `run_batch(states0, h, steps)`,
  `observe(state)` (`dict(q, v, p, R)` as numpy_gni's observe: the reported node $\\bar v$,
  $\\bar p$; Suslov's q is empty), and `numpy_case`/`method` (numpy_gni's name, None for the added
  cases, and gnipy's method); `LEGACY_CASES[name]`: the same with the first version's kernels (the
  first three cases only);
- `count_iterations(name, h, steps, solver=None, legacy=False)` -> (the mean number of Newton or
  chord iterations per step, the final state).

Parameters and initial conditions are copied from numpy_gni (so from gnipy's models; Suslov's from
gnipy's model file). All functions are compiled with `@numba.njit(cache=True, fastmath=False,
error_model="numpy")`. Over 1000 steps at h = 0.01 the final nodes agree with gnipy's to ≤ 2e-14
and with numpy_gni's to ≤ 9e-13 (numpy_gni's own round-off: SciPy's `root` stops at a relative
tolerance of 1e-12).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "CASES",
    "CASE_SOLVER",
    "CHAPLYGIN_PARAMS",
    "CHAPLYGIN_SOLVER",
    "CHORD_TOL",
    "EX2_PARAMS",
    "EX2_SOLVER",
    "EX2_YOSHIDA4_SOLVER",
    "LEGACY_CASES",
    "NEWTON_MAXITER",
    "NEWTON_TOL",
    "NEWTON_TOL_V1",
    "OSCILLATOR_EPS",
    "OSC_SOLVER",
    "PREDICTOR_SWEEPS",
    "SOLVERS",
    "START_H",
    "SUSLOV_PARAMS",
    "SUSLOV_SOLVER",
    "YOSHIDA4",
    "Case",
    "count_iterations",
    "get_case",
    "rolling_ball_ex2_consistent_start",
    "run_ball",
    "run_ball_batch",
    "run_ball_batch_v1",
    "run_ball_v1",
    "run_ball_yoshida4",
    "run_ball_yoshida4_batch",
    "run_chaplygin_sphere",
    "run_chaplygin_sphere_batch",
    "run_chaplygin_sphere_batch_v1",
    "run_chaplygin_sphere_v1",
    "run_contact_oscillator",
    "run_contact_oscillator_batch",
    "run_contact_oscillator_batch_v1",
    "run_contact_oscillator_v1",
    "run_oscillator",
    "run_oscillator_batch",
    "run_oscillator_batch_v1",
    "run_oscillator_v1",
    "run_rolling_ball_ex2",
    "run_rolling_ball_ex2_batch",
    "run_rolling_ball_ex2_batch_v1",
    "run_rolling_ball_ex2_v1",
    "run_rolling_ball_ex2_yoshida4",
    "run_rolling_ball_ex2_yoshida4_batch",
    "run_suslov",
    "run_suslov_batch",
    "run_suslov_general",
    "run_suslov_general_batch",
    "suslov_observe",
]

#: Newton (both variants) stops when max|δ| <= NEWTON_TOL * max(1, max|z|) (z = ξ or v)
NEWTON_TOL = 1e-8
#: the chord iteration stops when θ max|δ| / (1 − θ) <= CHORD_TOL * max(1, max|z|)
CHORD_TOL = 1e-17
NEWTON_MAXITER = 20
#: the first version's test: max|δ| <= NEWTON_TOL_V1 * max(1, max|z|) (z = σ, or q_{k+1})
NEWTON_TOL_V1 = 1e-14

#: the solvers (the `solver` argument of the general kernels)
NEWTON, CHORD, PREDICTED = 0, 1, 2
SOLVERS = {"newton": NEWTON, "chord": CHORD, "predicted-newton": PREDICTED}
#: fixed-point sweeps before Newton in the "predicted-newton" solver, (balls, oscillator)
PREDICTOR_SWEEPS = (2, 2)
#: each case's solver: the fastest at h = 0.01 (timed, see the module docstring)
EX2_SOLVER = PREDICTED
CHAPLYGIN_SOLVER = NEWTON
OSC_SOLVER = CHORD
EX2_YOSHIDA4_SOLVER = PREDICTED
SUSLOV_SOLVER = CHORD

#: (m, r, I1, I2, I3, Omega): numpy_gni.RollingBallEx2.PARAMS (gnipy's rolling_ball.example_2())
EX2_PARAMS = (3.0, 1.0, 1.0, 1.1, 1.2, 0.2)
#: (m, r, I1, I2, I3, Omega): numpy_gni.ChaplyginSphere.PARAMS (gnipy's "chaplygin-sphere")
CHAPLYGIN_PARAMS = (1.0, 1.0, 0.3, 0.4, 0.5, 0.0)
#: the step for which `Case.initial_state()` gives the composition's consistent start by default
START_H = 0.01
#: epsilon of numpy_gni.ContactOscillator (gnipy's "contact-oscillator")
OSCILLATOR_EPS = 0.3
#: (I11, I22, I33, I12, I13, I23, a1, a2, a3): gnipy's "suslov" defaults (src/gnipy/models/suslov.py)
SUSLOV_PARAMS = (2.0, 3.0, 4.0, 0.3, 0.6, -0.5, 0.0, 0.0, 1.0)
#: the rolling ball ex. 2's (q0, v0) (numpy_gni.RollingBallEx2.Q0, V0; gnipy's rolling_ball.example_2())
_EX2_Q0, _EX2_V0 = (1.0, 0.0), (0.0, 0.4, -0.2, 0.0, 0.4)
#: Suslov's Ω0 (gnipy's default: w − ⟨a, w⟩a/|a|², w = (1, 0.5, 0.3), a = e3)
_SUSLOV_V0 = (1.0, 0.5, 0.0)

_JIT = {"cache": True, "fastmath": False, "error_model": "numpy"}
#: the step's pieces are inlined by Numba itself: LLVM's inliner leaves a function as big as a step
#: (or its Newton solve) as a call, which costs the call and the hoisting of the loop invariants
#: (h/2, the reciprocals of I, ...) out of the step loop (measured: ~3-4% per step)
_JIT_INLINE = {**_JIT, "inline": "always"}
_NAN16 = (math.nan,) * 16
_NAN6 = (math.nan,) * 6
_NAN12 = (math.nan,) * 12
_BALL_SWEEPS, _OSC_SWEEPS = PREDICTOR_SWEEPS


# ---------------------------------------------------------------------------------------------
# A ball on a table, R^2 x SO(3), trapezoid l_d (rolling ball ex. 2 and the Chaplygin sphere)
# ---------------------------------------------------------------------------------------------
#
# With σ = hξ, the σ-part of FL⁻ = p⁻ (numpy_gni's dcay⁻¹_σᵀ(Iσ/h) = p⁻_ω) reads
#
#     F(ξ) = Iξ + (h/2) ξ×Iξ + (h²/4) ξ (ξ·Iξ) − p⁻_ω = 0,
#
# and FL⁺ = Iξ − (h/2) ξ×Iξ + (h²/4) ξ (ξ·Iξ) = p⁻_ω − h ξ×Iξ at the solution.


@numba.njit(**_JIT_INLINE)
def _ball_f(k0, k1, k2, pm2, pm3, pm4, c2, I1, I2, I3, a, b, c):
    """The residual F(ξ) alone (chord iterations, predictor sweeps): (F0, F1, F2).

    a, b, c = (h/2)(I3 − I2), (h/2)(I1 − I3), (h/2)(I2 − I1): (h/2)ξ×Iξ = (a ξ1ξ2, b ξ0ξ2, c ξ0ξ1).
    (M − p⁻) first: the two big terms cancel exactly when within a factor 2; then the O(h) terms.
    """
    M0, M1, M2 = I1 * k0, I2 * k1, I3 * k2
    sM = k0 * M0 + k1 * M1 + k2 * M2
    return (
        (M0 - pm2) + a * (k1 * k2) + (c2 * k0) * sM,
        (M1 - pm3) + b * (k0 * k2) + (c2 * k1) * sM,
        (M2 - pm4) + c * (k0 * k1) + (c2 * k2) * sM,
    )


@numba.njit(**_JIT_INLINE)
def _ball_fj(k0, k1, k2, pm2, pm3, pm4, c2, I1, I2, I3, a, b, c):
    """F(ξ) and its Jacobian, fused (they share Iξ, ξ·Iξ, (h²/4)ξ): (F0, F1, F2, J00, ..., J22).

    J = I + (h/2)(ξ̂I − (Iξ)^) + (h²/4)((ξ·Iξ)E + 2ξ(Iξ)ᵀ); the skew part is, in Euler's form,
    [[0, a ξ2, a ξ1], [b ξ2, 0, b ξ0], [c ξ1, c ξ0, 0]].
    """
    M0, M1, M2 = I1 * k0, I2 * k1, I3 * k2
    sM = k0 * M0 + k1 * M1 + k2 * M2
    u0, u1, u2 = c2 * k0, c2 * k1, c2 * k2
    q = c2 * sM
    t0, t1, t2 = 2.0 * u0, 2.0 * u1, 2.0 * u2
    return (
        (M0 - pm2) + a * (k1 * k2) + u0 * sM,
        (M1 - pm3) + b * (k0 * k2) + u1 * sM,
        (M2 - pm4) + c * (k0 * k1) + u2 * sM,
        (I1 + t0 * M0) + q, a * k2 + t0 * M1, a * k1 + t0 * M2,
        b * k2 + t1 * M0, (I2 + t1 * M1) + q, b * k0 + t1 * M2,
        c * k1 + t2 * M0, c * k0 + t2 * M1, (I3 + t2 * M2) + q,
    )  # fmt: skip


@numba.njit(**_JIT_INLINE)
def _newton_update3(F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22):
    """δ = −J⁻¹F by Cramer's rule: the adjugate (cofactors) times one reciprocal of det J."""
    C00 = J11 * J22 - J12 * J21
    C01 = J12 * J20 - J10 * J22
    C02 = J10 * J21 - J11 * J20
    C10 = J02 * J21 - J01 * J22
    C11 = J00 * J22 - J02 * J20
    C12 = J01 * J20 - J00 * J21
    C20 = J01 * J12 - J02 * J11
    C21 = J02 * J10 - J00 * J12
    C22 = J00 * J11 - J01 * J10
    nid = -1.0 / (J00 * C00 + J01 * C01 + J02 * C02)
    return (
        (C00 * F0 + C10 * F1 + C20 * F2) * nid,
        (C01 * F0 + C11 * F1 + C21 * F2) * nid,
        (C02 * F0 + C12 * F1 + C22 * F2) * nid,
    )


@numba.njit(**_JIT_INLINE)
def _ball_solve(pm2, pm3, pm4, pb2, pb3, pb4, h, I1, I2, I3, solver):
    """Solve F(ξ) = 0 from ξ̄ = p̄_ω/I: (ξ0, ξ1, ξ2, iterations, ok)."""
    c2 = 0.25 * h * h
    c1 = 0.5 * h
    a, b, c = c1 * (I3 - I2), c1 * (I1 - I3), c1 * (I2 - I1)
    r1, r2, r3 = 1.0 / I1, 1.0 / I2, 1.0 / I3  # guesses only: Newton corrects their rounding
    k0, k1, k2 = pb2 * r1, pb3 * r2, pb4 * r3
    if solver == PREDICTED:
        for _ in range(_BALL_SWEEPS):
            M0, M1, M2 = I1 * k0, I2 * k1, I3 * k2
            sM = k0 * M0 + k1 * M1 + k2 * M2
            n0 = (pm2 - a * (k1 * k2) - (c2 * k0) * sM) * r1
            n1 = (pm3 - b * (k0 * k2) - (c2 * k1) * sM) * r2
            n2 = (pm4 - c * (k0 * k1) - (c2 * k2) * sM) * r3
            k0, k1, k2 = n0, n1, n2
    if solver == CHORD:
        F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22 = _ball_fj(
            k0, k1, k2, pm2, pm3, pm4, c2, I1, I2, I3, a, b, c
        )
        # J(ξ₀)⁻¹ = adj(J)/det once; then each iteration is a residual and a 3×3 product
        C00 = J11 * J22 - J12 * J21
        C01 = J12 * J20 - J10 * J22
        C02 = J10 * J21 - J11 * J20
        nid = -1.0 / (J00 * C00 + J01 * C01 + J02 * C02)
        A00, A01, A02 = C00 * nid, (J02 * J21 - J01 * J22) * nid, (J01 * J12 - J02 * J11) * nid
        A10, A11, A12 = C01 * nid, (J00 * J22 - J02 * J20) * nid, (J02 * J10 - J00 * J12) * nid
        A20, A21, A22 = C02 * nid, (J01 * J20 - J00 * J21) * nid, (J00 * J11 - J01 * J10) * nid
        prev = math.inf
        for it in range(1, NEWTON_MAXITER + 1):
            if it > 1:
                F0, F1, F2 = _ball_f(k0, k1, k2, pm2, pm3, pm4, c2, I1, I2, I3, a, b, c)
            d0 = A00 * F0 + A01 * F1 + A02 * F2
            d1 = A10 * F0 + A11 * F1 + A12 * F2
            d2 = A20 * F0 + A21 * F1 + A22 * F2
            k0 += d0
            k1 += d1
            k2 += d2
            size = max(abs(d0), abs(d1), abs(d2))
            th = size / prev
            if size == 0.0 or (
                it > 1 and th < 0.5 and th * size <= CHORD_TOL * (1.0 - th) * max(1.0, abs(k0), abs(k1), abs(k2))
            ):
                return k0, k1, k2, it, True
            prev = size
        return k0, k1, k2, NEWTON_MAXITER, False
    for it in range(1, NEWTON_MAXITER + 1):
        F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22 = _ball_fj(
            k0, k1, k2, pm2, pm3, pm4, c2, I1, I2, I3, a, b, c
        )
        d0, d1, d2 = _newton_update3(F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22)
        k0 += d0
        k1 += d1
        k2 += d2
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL * max(1.0, abs(k0), abs(k1), abs(k2)):
            return k0, k1, k2, it, True
    return k0, k1, k2, NEWTON_MAXITER, False


@numba.njit(**_JIT_INLINE)
def _ball_step(s, h, params, chaplygin, solver):
    """One GNI (trapezoid, Cayley) step of a ball: (16-tuple, iterations); NaNs if Newton fails.

    The reflection (Comb) p⁻ = p⁺ − 2μᵀλ, p̄ = p⁺ − μᵀλ, λ = C⁻¹μG⁻¹(p⁺ − Π), μ = [[1, 0, a],
    [0, 1, c]], G = diag(m, m, I), Π = (−mΩy, mΩx, 0, 0, 0): the rolling ball has a = (0, −r, 0),
    c = (r, 0, 0), so C is diagonal and λ_i is one quotient; the Chaplygin sphere has
    a = −r R[1, :], c = r R[0, :] and a 2×2 C(R).
    """
    m, r, I1, I2, I3, W = params
    x, y = s[0], s[1]
    p0, p1, p2, p3, p4 = s[11], s[12], s[13], s[14], s[15]
    mW = m * W
    if chaplygin:
        # C = μG⁻¹μᵀ = 1/m + r²[[R1·R1/I, −R1·R0/I], [., R0·R0/I]]; μG⁻¹(p⁺ − Π) likewise
        e0, e1, e2 = s[2] / I1, s[3] / I2, s[4] / I3  # R[0, :]/I
        f0, f1, f2 = s[5] / I1, s[6] / I2, s[7] / I3  # R[1, :]/I
        rr = r * r
        C00 = 1.0 / m + rr * (s[5] * f0 + s[6] * f1 + s[7] * f2)
        C11 = 1.0 / m + rr * (s[2] * e0 + s[3] * e1 + s[4] * e2)
        C01 = -rr * (s[5] * e0 + s[6] * e1 + s[7] * e2)
        g0 = (p0 + mW * y) / m - r * (f0 * p2 + f1 * p3 + f2 * p4)
        g1 = (p1 - mW * x) / m + r * (e0 * p2 + e1 * p3 + e2 * p4)
        det = C00 * C11 - C01 * C01
        l0 = (C11 * g0 - C01 * g1) / det
        l1 = (C00 * g1 - C01 * g0) / det
        # μᵀλ, ω-part: a l0 + c l1 = r(R[0, :] l1 − R[1, :] l0)
        q2 = r * (s[2] * l1 - s[5] * l0)
        q3 = r * (s[3] * l1 - s[6] * l0)
        q4 = r * (s[4] * l1 - s[7] * l0)
    else:
        # C = diag(1/m + r²/I2, 1/m + r²/I1): λ_i = (μG⁻¹(p⁺ − Π))_i / C_ii, times m I_i above and below
        mr = m * r
        l0 = (I2 * (p0 + mW * y) - mr * p3) / (I2 + mr * r)
        l1 = (I1 * (p1 - mW * x) + mr * p2) / (I1 + mr * r)
        q2, q3, q4 = r * l1, -r * l0, 0.0
    pm0, pm1 = p0 - 2.0 * l0, p1 - 2.0 * l1
    pm2, pm3, pm4 = p2 - 2.0 * q2, p3 - 2.0 * q3, p4 - 2.0 * q4
    k0, k1, k2, its, ok = _ball_solve(pm2, pm3, pm4, p2 - q2, p3 - q3, p4 - q4, h, I1, I2, I3, solver)
    if not ok:  # also when an update is NaN (comparisons with NaN are false)
        return _NAN16, its
    # σ = hξ; cay(σ) = E + α(σ̂ + ½σ̂²), α = 4/(4 + |σ|²), applied to R without forming it: the
    # division overlaps the cross products (measured faster than forming cay(σ) and a 3×3 product,
    # though a few more operations: shorter dependency chain)
    s0, s1, s2 = h * k0, h * k1, h * k2
    al = 4.0 / (4.0 + (s0 * s0 + s1 * s1 + s2 * s2))
    z0, z1, z2 = 0.5 * s0, 0.5 * s1, 0.5 * s2
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10]
    if chaplygin:  # R_{k+1} = R cay(σ): row i += α(A + A×σ/2), A = R_i×σ (R_i σ̂ = R_i×σ)
        A0, A1, A2 = R01 * s2 - R02 * s1, R02 * s0 - R00 * s2, R00 * s1 - R01 * s0
        B0, B1, B2 = R11 * s2 - R12 * s1, R12 * s0 - R10 * s2, R10 * s1 - R11 * s0
        C0, C1, C2 = R21 * s2 - R22 * s1, R22 * s0 - R20 * s2, R20 * s1 - R21 * s0
        N00 = R00 + al * (A0 + (A1 * z2 - A2 * z1))
        N01 = R01 + al * (A1 + (A2 * z0 - A0 * z2))
        N02 = R02 + al * (A2 + (A0 * z1 - A1 * z0))
        N10 = R10 + al * (B0 + (B1 * z2 - B2 * z1))
        N11 = R11 + al * (B1 + (B2 * z0 - B0 * z2))
        N12 = R12 + al * (B2 + (B0 * z1 - B1 * z0))
        N20 = R20 + al * (C0 + (C1 * z2 - C2 * z1))
        N21 = R21 + al * (C1 + (C2 * z0 - C0 * z2))
        N22 = R22 + al * (C2 + (C0 * z1 - C1 * z0))
    else:  # R_{k+1} = cay(σ) R: column j += α(B + σ×B/2), B = σ×R_{:j}
        A0, A1, A2 = s1 * R20 - s2 * R10, s2 * R00 - s0 * R20, s0 * R10 - s1 * R00
        B0, B1, B2 = s1 * R21 - s2 * R11, s2 * R01 - s0 * R21, s0 * R11 - s1 * R01
        C0, C1, C2 = s1 * R22 - s2 * R12, s2 * R02 - s0 * R22, s0 * R12 - s1 * R02
        N00 = R00 + al * (A0 + (z1 * A2 - z2 * A1))
        N10 = R10 + al * (A1 + (z2 * A0 - z0 * A2))
        N20 = R20 + al * (A2 + (z0 * A1 - z1 * A0))
        N01 = R01 + al * (B0 + (z1 * B2 - z2 * B1))
        N11 = R11 + al * (B1 + (z2 * B0 - z0 * B2))
        N21 = R21 + al * (B2 + (z0 * B1 - z1 * B0))
        N02 = R02 + al * (C0 + (z1 * C2 - z2 * C1))
        N12 = R12 + al * (C1 + (z2 * C0 - z0 * C2))
        N22 = R22 + al * (C2 + (z0 * C1 - z1 * C0))
    # FL⁺: the x-part is m Δx/h = p⁻_x; the ω-part p⁻_ω − h ξ×Iξ (Euler's form, as in F)
    hd = h * (I3 - I2), h * (I1 - I3), h * (I2 - I1)
    return (
        x + h * pm0 / m, y + h * pm1 / m,
        N00, N01, N02, N10, N11, N12, N20, N21, N22,
        pm0, pm1,
        pm2 - hd[0] * (k1 * k2), pm3 - hd[1] * (k0 * k2), pm4 - hd[2] * (k0 * k1),
    ), its  # fmt: skip


@numba.njit(**_JIT)
def _ball_loop(state0, h, steps, params, chaplygin, solver, out):
    """`steps` steps from state0 (16,) into out (16,); returns the total number of iterations.

    The state lives in a tuple of scalars: the loop allocates nothing."""
    s = (
        state0[0], state0[1], state0[2], state0[3], state0[4], state0[5], state0[6], state0[7],
        state0[8], state0[9], state0[10], state0[11], state0[12], state0[13], state0[14], state0[15],
    )  # fmt: skip
    n = 0
    for _ in range(steps):
        s, its = _ball_step(s, h, params, chaplygin, solver)
        n += its
    for i in range(16):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_ball(state0, h, steps, params, chaplygin, solver=-1):
    """`steps` GNI steps of a ball from the flat state0 (16,); returns the final state (16,).

    params = (m, r, I1, I2, I3, Omega); chaplygin: False for the rolling ball (constant μ,
    R_{k+1} = cay(σ)R_k), True for the Chaplygin sphere (μ(R), R_{k+1} = R_k cay(σ)); solver: one
    of `SOLVERS`' values (default: `CHAPLYGIN_SOLVER` or `EX2_SOLVER`, as the cases).
    """
    if solver < 0:
        solver = CHAPLYGIN_SOLVER if chaplygin else EX2_SOLVER
    out = np.empty(16)
    _ball_loop(state0, h, steps, params, chaplygin, solver, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_ball_batch(states0, h, steps, params, chaplygin, solver=-1):
    """:func:`run_ball` for each row of states0 (B, 16), in parallel over the rows (all cores)."""
    if solver < 0:
        solver = CHAPLYGIN_SOLVER if chaplygin else EX2_SOLVER
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, params, chaplygin, solver, out[b])
    return out


@numba.njit(**_JIT)
def _ball_count(state0, h, steps, params, chaplygin, solver):
    out = np.empty(16)
    return _ball_loop(state0, h, steps, params, chaplygin, solver, out), out


@numba.njit(**_JIT)
def run_rolling_ball_ex2(state0, h, steps):
    """The rolling ball, example 2 (gni-trapezoid): final state (16,) after `steps` steps."""
    out = np.empty(16)
    _ball_loop(state0, h, steps, EX2_PARAMS, False, EX2_SOLVER, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_rolling_ball_ex2_batch(states0, h, steps):
    """The rolling ball, example 2: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, EX2_PARAMS, False, EX2_SOLVER, out[b])
    return out


@numba.njit(**_JIT)
def run_chaplygin_sphere(state0, h, steps):
    """The Chaplygin sphere (gni-trapezoid): final state (16,) after `steps` steps."""
    out = np.empty(16)
    _ball_loop(state0, h, steps, CHAPLYGIN_PARAMS, True, CHAPLYGIN_SOLVER, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_chaplygin_sphere_batch(states0, h, steps):
    """The Chaplygin sphere: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop(states0[b], h, steps, CHAPLYGIN_PARAMS, True, CHAPLYGIN_SOLVER, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# The contact oscillator on R^3, midpoint l_d (gni-midpoint)
# ---------------------------------------------------------------------------------------------
#
# V = ½(|q|² + εx²z²). With v = (q_{k+1} − q_k)/h and the mid-point q̄ = q_k + (h/2)v, FL⁻ = p⁻ is
#
#     F(v) = v + (h/2)∇V(q̄) − p⁻ = 0,   J = E + (h²/4)∇²V(q̄),
#
# and FL⁺ = v − (h/2)∇V(q̄) = p⁻ − h∇V(q̄) at the solution. ∇V = (x + εxz², y, z + εx²z): the
# y-equation v_y(1 + h²/4) = p⁻_y − (h/2)y is linear and solved in closed form; (x, z) is a 2×2.


@numba.njit(**_JIT_INLINE)
def _osc_f(x, z, v0, v2, pm0, pm2, hh, eps):
    """The (x, z) residual alone: (F0, F2)."""
    mx, mz = x + hh * v0, z + hh * v2
    return (v0 - pm0) + hh * (mx + eps * mx * (mz * mz)), (v2 - pm2) + hh * (mz + eps * (mx * mx) * mz)


@numba.njit(**_JIT_INLINE)
def _osc_fj(x, z, v0, v2, pm0, pm2, hh, c4, eps):
    """The (x, z) residual and its 2×2 Jacobian, fused (they share q̄ and its squares):
    (F0, F2, J00, J02, J22)."""
    mx, mz = x + hh * v0, z + hh * v2
    xx, zz = mx * mx, mz * mz
    return (
        (v0 - pm0) + hh * (mx + eps * mx * zz),
        (v2 - pm2) + hh * (mz + eps * xx * mz),
        1.0 + c4 * (1.0 + eps * zz),
        c4 * (2.0 * eps * mx * mz),
        1.0 + c4 * (1.0 + eps * xx),
    )


@numba.njit(**_JIT_INLINE)
def _osc_solve(x, z, pm0, pm2, pb0, pb2, h, eps, solver):
    """Solve the (x, z) equations from v̄ (G = E, so v̄ = p̄): (v0, v2, iterations, ok)."""
    hh = 0.5 * h
    c4 = 0.25 * h * h
    v0, v2 = pb0, pb2
    if solver == PREDICTED:
        for _ in range(_OSC_SWEEPS):
            mx, mz = x + hh * v0, z + hh * v2
            v0, v2 = pm0 - hh * (mx + eps * mx * (mz * mz)), pm2 - hh * (mz + eps * (mx * mx) * mz)
    if solver == CHORD:
        F0, F2, J00, J02, J22 = _osc_fj(x, z, v0, v2, pm0, pm2, hh, c4, eps)
        nid = -1.0 / (J00 * J22 - J02 * J02)  # −J(v₀)⁻¹ = −adj(J)/det, formed once
        A00, A02, A22 = J22 * nid, -J02 * nid, J00 * nid
        prev = math.inf
        for it in range(1, NEWTON_MAXITER + 1):
            if it > 1:
                F0, F2 = _osc_f(x, z, v0, v2, pm0, pm2, hh, eps)
            d0 = A00 * F0 + A02 * F2
            d2 = A02 * F0 + A22 * F2
            v0 += d0
            v2 += d2
            size = max(abs(d0), abs(d2))
            th = size / prev
            if size == 0.0 or (
                it > 1 and th < 0.5 and th * size <= CHORD_TOL * (1.0 - th) * max(1.0, abs(v0), abs(v2))
            ):
                return v0, v2, it, True
            prev = size
        return v0, v2, NEWTON_MAXITER, False
    for it in range(1, NEWTON_MAXITER + 1):
        F0, F2, J00, J02, J22 = _osc_fj(x, z, v0, v2, pm0, pm2, hh, c4, eps)
        nid = -1.0 / (J00 * J22 - J02 * J02)
        d0 = (J22 * F0 - J02 * F2) * nid
        d2 = (J00 * F2 - J02 * F0) * nid
        v0 += d0
        v2 += d2
        if max(abs(d0), abs(d2)) <= NEWTON_TOL * max(1.0, abs(v0), abs(v2)):
            return v0, v2, it, True
    return v0, v2, NEWTON_MAXITER, False


@numba.njit(**_JIT_INLINE)
def _osc_step(s, h, eps, solver):
    """One GNI (midpoint) step of the contact oscillator: (6-tuple, iterations); NaNs if Newton fails.

    The reflection: μ = (1, 0, y), G = E, Π = 0, C = 1 + y², λ = μp⁺/C, μᵀλ = (λ, 0, yλ).
    """
    x, y, z, p0, p1, p2 = s
    lam = (p0 + y * p2) / (1.0 + y * y)
    yl = y * lam
    pm0, pm2 = p0 - 2.0 * lam, p2 - 2.0 * yl
    hh = 0.5 * h
    v1 = (p1 - hh * y) / (1.0 + 0.25 * h * h)  # the y-equation, linear (p⁻_y = p⁺_y)
    v0, v2, its, ok = _osc_solve(x, z, pm0, pm2, p0 - lam, p2 - yl, h, eps, solver)
    if not ok or not math.isfinite(v1):
        return _NAN6, its
    mx, my, mz = x + hh * v0, y + hh * v1, z + hh * v2
    return (
        x + h * v0, y + h * v1, z + h * v2,
        pm0 - h * (mx + eps * mx * (mz * mz)),
        p1 - h * my,
        pm2 - h * (mz + eps * (mx * mx) * mz),
    ), its  # fmt: skip


@numba.njit(**_JIT)
def _osc_loop(state0, h, steps, eps, solver, out):
    """`steps` steps from state0 (6,) into out (6,); returns the total number of iterations."""
    s = (state0[0], state0[1], state0[2], state0[3], state0[4], state0[5])
    n = 0
    for _ in range(steps):
        s, its = _osc_step(s, h, eps, solver)
        n += its
    for i in range(6):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_oscillator(state0, h, steps, eps, solver=OSC_SOLVER):
    """`steps` GNI-midpoint steps of the contact oscillator from state0 = (q, p⁺) (6,)."""
    out = np.empty(6)
    _osc_loop(state0, h, steps, eps, solver, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_oscillator_batch(states0, h, steps, eps, solver=OSC_SOLVER):
    """:func:`run_oscillator` for each row of states0 (B, 6), in parallel over the rows."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop(states0[b], h, steps, eps, solver, out[b])
    return out


@numba.njit(**_JIT)
def _osc_count(state0, h, steps, eps, solver):
    out = np.empty(6)
    return _osc_loop(state0, h, steps, eps, solver, out), out


@numba.njit(**_JIT)
def run_contact_oscillator(state0, h, steps):
    """The contact oscillator (gni-midpoint, ε = 0.3): final state (6,) after `steps` steps."""
    out = np.empty(6)
    _osc_loop(state0, h, steps, OSCILLATOR_EPS, OSC_SOLVER, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_contact_oscillator_batch(states0, h, steps):
    """The contact oscillator: final states (B, 6), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop(states0[b], h, steps, OSCILLATOR_EPS, OSC_SOLVER, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# A composition: Yoshida's triple jump of the rolling ball's step (yoshida4-gni-trapezoid)
# ---------------------------------------------------------------------------------------------
#
# gnipy's Composition (src/gnipy/integrators/composition.py) of a GNI is not just three steps of
# γ_i h: the state (b, p⁺) carries the hidden impulse p⁺ − p̄ = μᵀλ ≈ −(h/2)μᵀλ_cont of the step
# that produced it, so before substep i (i > 1) it is rescaled to the new step,
#
#     p⁺ ← p̄ + (γ_i h / γ_{i−1} h)(p⁺ − p̄)      (GNI.change_step, the ratio signed),
#
# and the run starts consistently for the first substep, p⁺₀ = p̄₀ − (γ₁h/2)μᵀλ₀ (λ₀ the continuous
# multiplier; :func:`rolling_ball_ex2_consistent_start`). The substeps are `_ball_step` itself.


def _triple_jump_coefficients():
    """(γ₁, γ₂, γ₁) of Yoshida's triple jump, computed as gnipy's composition._triple_jump(2)."""
    r = 2.0 ** (1.0 / 3.0)
    g1, g2 = 1.0 / (2.0 - r), -r / (2.0 - r)
    return (g1, g2, g1)


#: the substep fractions of "yoshida4" (gnipy.integrators.composition.COMPOSITIONS["yoshida4"])
YOSHIDA4 = _triple_jump_coefficients()
_Y1, _Y2 = YOSHIDA4[0], YOSHIDA4[1]


@numba.njit(**_JIT_INLINE)
def _ex2_rescale(s, rho, params):
    """The rolling ball's p⁺ ← p̄ + ρ(p⁺ − p̄), p⁺ − p̄ = μᵀλ in the closed form of `_ball_step`
    (μ constant: λ_i is one quotient); μᵀλ = (λ0, λ1, rλ1, −rλ0, 0), so p⁺_4 is unchanged."""
    m, r, I1, I2, _, W = params
    x, y = s[0], s[1]
    p0, p1, p2, p3 = s[11], s[12], s[13], s[14]
    mW = m * W
    mr = m * r
    l0 = (I2 * (p0 + mW * y) - mr * p3) / (I2 + mr * r)
    l1 = (I1 * (p1 - mW * x) + mr * p2) / (I1 + mr * r)
    q2, q3 = r * l1, -r * l0
    return (
        s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10],
        (p0 - l0) + rho * l0, (p1 - l1) + rho * l1, (p2 - q2) + rho * q2, (p3 - q3) + rho * q3, s[15],
    )  # fmt: skip


@numba.njit(**_JIT)
def _yoshida4_loop(state0, h, steps, params, solver, out):
    """`steps` triple-jump steps of the rolling ball from state0 (16,) into out (16,); returns the
    total number of iterations (the three substeps' summed, as gnipy's Composition counts them)."""
    s = (
        state0[0], state0[1], state0[2], state0[3], state0[4], state0[5], state0[6], state0[7],
        state0[8], state0[9], state0[10], state0[11], state0[12], state0[13], state0[14], state0[15],
    )  # fmt: skip
    h1, h2 = _Y1 * h, _Y2 * h
    hs = (h1, h2, h1)
    rhos = (1.0, h2 / h1, h1 / h2)  # gnipy's h_new / h_old, from the rounded substeps
    n = 0
    for _ in range(steps):
        for i in range(3):  # one copy of the step's code (three inlined copies: 3x the compile time)
            if i > 0:
                s = _ex2_rescale(s, rhos[i], params)
            s, its = _ball_step(s, hs[i], params, False, solver)
            n += its
    for i in range(16):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_ball_yoshida4(state0, h, steps, params, solver=-1):
    """`steps` yoshida4-gni-trapezoid steps of the rolling ball (params as `run_ball`, constant μ)
    from the flat state0 (16,); solver: one of `SOLVERS`' values (default `EX2_YOSHIDA4_SOLVER`)."""
    if solver < 0:
        solver = EX2_YOSHIDA4_SOLVER
    out = np.empty(16)
    _yoshida4_loop(state0, h, steps, params, solver, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_ball_yoshida4_batch(states0, h, steps, params, solver=-1):
    """:func:`run_ball_yoshida4` for each row of states0 (B, 16), in parallel over the rows."""
    if solver < 0:
        solver = EX2_YOSHIDA4_SOLVER
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _yoshida4_loop(states0[b], h, steps, params, solver, out[b])
    return out


@numba.njit(**_JIT)
def _yoshida4_count(state0, h, steps, params, solver):
    out = np.empty(16)
    return _yoshida4_loop(state0, h, steps, params, solver, out), out


@numba.njit(**_JIT)
def run_rolling_ball_ex2_yoshida4(state0, h, steps):
    """The rolling ball, example 2, yoshida4-gni-trapezoid: final state (16,) after `steps` steps
    (from a consistent start for h, :func:`rolling_ball_ex2_consistent_start`)."""
    out = np.empty(16)
    _yoshida4_loop(state0, h, steps, EX2_PARAMS, EX2_YOSHIDA4_SOLVER, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_rolling_ball_ex2_yoshida4_batch(states0, h, steps):
    """The rolling ball, example 2, yoshida4-gni-trapezoid: final states (B, 16), in parallel."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _yoshida4_loop(states0[b], h, steps, EX2_PARAMS, EX2_YOSHIDA4_SOLVER, out[b])
    return out


def rolling_ball_ex2_consistent_start(h, q0=None, v0=None, params=EX2_PARAMS, gamma=_Y1):
    """The composition's start (gnipy's `start="consistent"` for the first substep γ₁h): the flat
    state (16,) `(x, y, R₀ = E, p⁺₀)` with p⁺₀ = G v₀ − (γ₁h/2)μᵀλ₀.

    λ₀ is the continuous multiplier at (q₀, v₀) (gnipy.equations.lagrange_dalembert_acceleration),
    in closed form: m ẍ = λ0, m ÿ = λ1, I ω̇ = Iω×ω + aλ0 + cλ1 (a = (0, −r, 0), c = (r, 0, 0)) and
    the derivative of the constraints, ẍ − r ω̇₂ + Ω ẏ = 0, ÿ + r ω̇₁ − Ω ẋ = 0 (1-based ω indices),
    give λ0 (I2 + mr²) = mr(I3 − I1)ω1ω3 − mI2Ω ẏ and λ1 (I1 + mr²) = mI1Ω ẋ − mr(I2 − I3)ω2ω3;
    μᵀλ = (λ0, λ1, rλ1, −rλ0, 0). Agrees with gnipy's `Composition.init` to ≤ 3e-19 (absolute;
    tests/test_benchmark_numba.py). Default (q₀, v₀): the example's, as `CASES["rolling-ball-ex2"]`.
    """
    m, r, I1, I2, I3, W = params
    x, y = _EX2_Q0 if q0 is None else q0
    xd, yd, w0, w1, w2 = _EX2_V0 if v0 is None else v0
    l0 = (m * r * (I3 - I1) * w0 * w2 - m * I2 * W * yd) / (I2 + m * r * r)
    l1 = (m * I1 * W * xd - m * r * (I2 - I3) * w1 * w2) / (I1 + m * r * r)
    c = 0.5 * gamma * h
    p = np.array([m * xd, m * yd, I1 * w0, I2 * w1, I3 * w2]) - c * np.array([l0, l1, r * l1, -r * l0, 0.0])
    return np.concatenate([np.array([x, y], dtype=float), np.eye(3).ravel(), p])


# ---------------------------------------------------------------------------------------------
# Suslov's problem on SO(3), trapezoid l_d, one impulse at both ends of the step (sgni-trapezoid)
# ---------------------------------------------------------------------------------------------
#
# gnipy's SymmetricImpulseGNI (src/gnipy/integrators/gni_variants.py) on gnipy's "suslov": l = ½ΩᵀIΩ
# with a full symmetric I, one constraint ⟨a, Ω⟩ = 0 (μ = aᵀ constant, Y = 0), Ω the body angular
# velocity (R_{k+1} = R_k cay(σ)). The state is (R, p̄), p̄ on the constraint. With σ = hξ and
# M = Iσ/h = Iξ, the trapezoid l_d = σᵀIσ/(2h) gives FL⁻ = dcay⁻¹_σᵀM = Iξ + (h/2)ξ×Iξ + (h²/4)ξ(ξ·Iξ)
# and the jump FL⁺ − FL⁻ = ad_σᵀM = −hξ×Iξ (gnipy.spaces.GroupSpace, ∇ᴸ_R l_d = 0). gnipy solves
# for (σ, α):
#
#     FL⁻(σ) = p̄ + (h/2)aα,   p̄_{k+1} = p̄ + h aα − h ξ×Iξ,   aᵀI⁻¹p̄_{k+1} = 0.
#
# The constraint is linear in α: with k = I⁻¹a, s = aᵀk, e = a/s and c0 = kᵀp̄ (zero up to
# round-off: gnipy keeps it, and so does this step), α = (k·w)/s − c0/(hs), w = ξ×Iξ. Eliminated,
# with the oblique projector Pw = w − e(k·w) (kᵀP = 0), the step is 3 equations in ξ:
#
#     F(ξ) = (Iξ − p̄) + (h/2)Pw + (h²/4)ξ(ξ·Iξ) + (c0/2)e = 0,
#     J = I + (h/2)P(ξ̂I − (Iξ)^) + (h²/4)((ξ·Iξ)E + 2ξ(Iξ)ᵀ),
#     p̄_{k+1} = (p̄ − c0 e) − h Pw        (kᵀp̄_{k+1} = 0: the constraint restored every step).
#
# The same solution as gnipy's 4×4 Newton on (σ, α) (in exact arithmetic); a Newton error e of ξ
# enters p̄_{k+1} as O(h|ξ|e), no division by h.


@numba.njit(**_JIT)
def _suslov_consts(params):
    """Loop invariants from params (I11, I22, I33, I12, I13, I23, a1, a2, a3): the 6 entries of I,
    the 6 of I⁻¹ (first guess and predictor only), k = I⁻¹a and e = a/(aᵀk) (18 numbers)."""
    A00, A11, A22, A01, A02, A12, a0, a1, a2 = params
    C00 = A11 * A22 - A12 * A12
    C01 = A02 * A12 - A01 * A22
    C02 = A01 * A12 - A02 * A11
    C11 = A00 * A22 - A02 * A02
    C12 = A01 * A02 - A00 * A12
    C22 = A00 * A11 - A01 * A01
    det = A00 * C00 + A01 * C01 + A02 * C02
    B00, B01, B02, B11, B12, B22 = C00 / det, C01 / det, C02 / det, C11 / det, C12 / det, C22 / det
    k0 = B00 * a0 + B01 * a1 + B02 * a2
    k1 = B01 * a0 + B11 * a1 + B12 * a2
    k2 = B02 * a0 + B12 * a1 + B22 * a2
    s = a0 * k0 + a1 * k1 + a2 * k2
    return (
        A00, A01, A02, A11, A12, A22,
        B00, B01, B02, B11, B12, B22,
        k0, k1, k2, a0 / s, a1 / s, a2 / s,
    )  # fmt: skip


@numba.njit(**_JIT_INLINE)
def _suslov_f(x0, x1, x2, t0, t1, t2, hh, c2, C):
    """F(ξ) alone (chord iterations): t = p̄ − (c0/2)e."""
    A00, A01, A02, A11, A12, A22 = C[0], C[1], C[2], C[3], C[4], C[5]
    k0, k1, k2, e0, e1, e2 = C[12], C[13], C[14], C[15], C[16], C[17]
    u0 = A00 * x0 + A01 * x1 + A02 * x2
    u1 = A01 * x0 + A11 * x1 + A12 * x2
    u2 = A02 * x0 + A12 * x1 + A22 * x2
    w0, w1, w2 = x1 * u2 - x2 * u1, x2 * u0 - x0 * u2, x0 * u1 - x1 * u0
    kw = k0 * w0 + k1 * w1 + k2 * w2
    q = c2 * (x0 * u0 + x1 * u1 + x2 * u2)
    return (
        (u0 - t0) + hh * (w0 - e0 * kw) + x0 * q,
        (u1 - t1) + hh * (w1 - e1 * kw) + x1 * q,
        (u2 - t2) + hh * (w2 - e2 * kw) + x2 * q,
    )


@numba.njit(**_JIT_INLINE)
def _suslov_fj(x0, x1, x2, t0, t1, t2, hh, c2, C):
    """F(ξ) and J(ξ), fused (they share Iξ, ξ×Iξ, ξ·Iξ): (F0, F1, F2, J00, ..., J22)."""
    A00, A01, A02, A11, A12, A22 = C[0], C[1], C[2], C[3], C[4], C[5]
    k0, k1, k2, e0, e1, e2 = C[12], C[13], C[14], C[15], C[16], C[17]
    u0 = A00 * x0 + A01 * x1 + A02 * x2
    u1 = A01 * x0 + A11 * x1 + A12 * x2
    u2 = A02 * x0 + A12 * x1 + A22 * x2
    w0, w1, w2 = x1 * u2 - x2 * u1, x2 * u0 - x0 * u2, x0 * u1 - x1 * u0
    kw = k0 * w0 + k1 * w1 + k2 * w2
    sq = c2 * (x0 * u0 + x1 * u1 + x2 * u2)
    # W = ξ̂I − (Iξ)^, row by row
    W00 = x1 * A02 - x2 * A01
    W01 = (x1 * A12 - x2 * A11) + u2
    W02 = (x1 * A22 - x2 * A12) - u1
    W10 = (x2 * A00 - x0 * A02) - u2
    W11 = x2 * A01 - x0 * A12
    W12 = (x2 * A02 - x0 * A22) + u0
    W20 = (x0 * A01 - x1 * A00) + u1
    W21 = (x0 * A11 - x1 * A01) - u0
    W22 = x0 * A12 - x1 * A02
    # kᵀW, then (h/2)PW = (h/2)(W − e kᵀW)
    r0 = k0 * W00 + k1 * W10 + k2 * W20
    r1 = k0 * W01 + k1 * W11 + k2 * W21
    r2 = k0 * W02 + k1 * W12 + k2 * W22
    v0, v1, v2 = 2.0 * c2 * x0, 2.0 * c2 * x1, 2.0 * c2 * x2
    return (
        (u0 - t0) + hh * (w0 - e0 * kw) + x0 * sq,
        (u1 - t1) + hh * (w1 - e1 * kw) + x1 * sq,
        (u2 - t2) + hh * (w2 - e2 * kw) + x2 * sq,
        (A00 + sq) + hh * (W00 - e0 * r0) + v0 * u0,
        A01 + hh * (W01 - e0 * r1) + v0 * u1,
        A02 + hh * (W02 - e0 * r2) + v0 * u2,
        A01 + hh * (W10 - e1 * r0) + v1 * u0,
        (A11 + sq) + hh * (W11 - e1 * r1) + v1 * u1,
        A12 + hh * (W12 - e1 * r2) + v1 * u2,
        A02 + hh * (W20 - e2 * r0) + v2 * u0,
        A12 + hh * (W21 - e2 * r1) + v2 * u1,
        (A22 + sq) + hh * (W22 - e2 * r2) + v2 * u2,
    )


@numba.njit(**_JIT_INLINE)
def _suslov_solve(t0, t1, t2, x0, x1, x2, h, C, solver):
    """Solve F(ξ) = 0 from the guess ξ (gnipy's: v̄ = I⁻¹p̄): (ξ0, ξ1, ξ2, iterations, ok)."""
    hh = 0.5 * h
    c2 = 0.25 * h * h
    if solver == PREDICTED:
        A00, A01, A02, A11, A12, A22 = C[0], C[1], C[2], C[3], C[4], C[5]
        B00, B01, B02, B11, B12, B22 = C[6], C[7], C[8], C[9], C[10], C[11]
        k0, k1, k2, e0, e1, e2 = C[12], C[13], C[14], C[15], C[16], C[17]
        for _ in range(_BALL_SWEEPS):  # ξ ← I⁻¹(t − (h/2)Pw − (h²/4)ξ(ξ·Iξ))
            u0 = A00 * x0 + A01 * x1 + A02 * x2
            u1 = A01 * x0 + A11 * x1 + A12 * x2
            u2 = A02 * x0 + A12 * x1 + A22 * x2
            w0, w1, w2 = x1 * u2 - x2 * u1, x2 * u0 - x0 * u2, x0 * u1 - x1 * u0
            kw = k0 * w0 + k1 * w1 + k2 * w2
            q = c2 * (x0 * u0 + x1 * u1 + x2 * u2)
            g0 = t0 - hh * (w0 - e0 * kw) - x0 * q
            g1 = t1 - hh * (w1 - e1 * kw) - x1 * q
            g2 = t2 - hh * (w2 - e2 * kw) - x2 * q
            x0 = B00 * g0 + B01 * g1 + B02 * g2
            x1 = B01 * g0 + B11 * g1 + B12 * g2
            x2 = B02 * g0 + B12 * g1 + B22 * g2
    if solver == CHORD:
        F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22 = _suslov_fj(x0, x1, x2, t0, t1, t2, hh, c2, C)
        C00 = J11 * J22 - J12 * J21
        C01 = J12 * J20 - J10 * J22
        C02 = J10 * J21 - J11 * J20
        nid = -1.0 / (J00 * C00 + J01 * C01 + J02 * C02)
        N00, N01, N02 = C00 * nid, (J02 * J21 - J01 * J22) * nid, (J01 * J12 - J02 * J11) * nid
        N10, N11, N12 = C01 * nid, (J00 * J22 - J02 * J20) * nid, (J02 * J10 - J00 * J12) * nid
        N20, N21, N22 = C02 * nid, (J01 * J20 - J00 * J21) * nid, (J00 * J11 - J01 * J10) * nid
        prev = math.inf
        for it in range(1, NEWTON_MAXITER + 1):
            if it > 1:
                F0, F1, F2 = _suslov_f(x0, x1, x2, t0, t1, t2, hh, c2, C)
            d0 = N00 * F0 + N01 * F1 + N02 * F2
            d1 = N10 * F0 + N11 * F1 + N12 * F2
            d2 = N20 * F0 + N21 * F1 + N22 * F2
            x0 += d0
            x1 += d1
            x2 += d2
            size = max(abs(d0), abs(d1), abs(d2))
            th = size / prev
            if size == 0.0 or (
                it > 1 and th < 0.5 and th * size <= CHORD_TOL * (1.0 - th) * max(1.0, abs(x0), abs(x1), abs(x2))
            ):
                return x0, x1, x2, it, True
            prev = size
        return x0, x1, x2, NEWTON_MAXITER, False
    for it in range(1, NEWTON_MAXITER + 1):
        F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22 = _suslov_fj(x0, x1, x2, t0, t1, t2, hh, c2, C)
        d0, d1, d2 = _newton_update3(F0, F1, F2, J00, J01, J02, J10, J11, J12, J20, J21, J22)
        x0 += d0
        x1 += d1
        x2 += d2
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL * max(1.0, abs(x0), abs(x1), abs(x2)):
            return x0, x1, x2, it, True
    return x0, x1, x2, NEWTON_MAXITER, False


@numba.njit(**_JIT_INLINE)
def _suslov_step(s, h, C, solver):
    """One sgni-trapezoid step of Suslov's problem: (12-tuple (R (9), p̄ (3)), iterations); NaNs if
    Newton fails. C: :func:`_suslov_consts`."""
    A00, A01, A02, A11, A12, A22 = C[0], C[1], C[2], C[3], C[4], C[5]
    B00, B01, B02, B11, B12, B22 = C[6], C[7], C[8], C[9], C[10], C[11]
    k0, k1, k2, e0, e1, e2 = C[12], C[13], C[14], C[15], C[16], C[17]
    p0, p1, p2 = s[9], s[10], s[11]
    c0 = k0 * p0 + k1 * p1 + k2 * p2  # aᵀI⁻¹p̄: zero up to round-off
    ch = 0.5 * c0
    t0, t1, t2 = p0 - ch * e0, p1 - ch * e1, p2 - ch * e2
    # gnipy's first guess ξ = v̄ = I⁻¹p̄ (the reciprocal entries of I⁻¹: Newton corrects their rounding)
    g0 = B00 * p0 + B01 * p1 + B02 * p2
    g1 = B01 * p0 + B11 * p1 + B12 * p2
    g2 = B02 * p0 + B12 * p1 + B22 * p2
    x0, x1, x2, its, ok = _suslov_solve(t0, t1, t2, g0, g1, g2, h, C, solver)
    if not ok:
        return _NAN12, its
    # p̄_{k+1} = (p̄ − c0 e) − h P(ξ×Iξ)
    u0 = A00 * x0 + A01 * x1 + A02 * x2
    u1 = A01 * x0 + A11 * x1 + A12 * x2
    u2 = A02 * x0 + A12 * x1 + A22 * x2
    w0, w1, w2 = x1 * u2 - x2 * u1, x2 * u0 - x0 * u2, x0 * u1 - x1 * u0
    kw = k0 * w0 + k1 * w1 + k2 * w2
    # R_{k+1} = R cay(σ), σ = hξ: row i += α(A + A×σ/2), A = R_i×σ (as the Chaplygin sphere's)
    s0, s1, s2 = h * x0, h * x1, h * x2
    al = 4.0 / (4.0 + (s0 * s0 + s1 * s1 + s2 * s2))
    z0, z1, z2 = 0.5 * s0, 0.5 * s1, 0.5 * s2
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7], s[8]
    A0, A1, A2 = R01 * s2 - R02 * s1, R02 * s0 - R00 * s2, R00 * s1 - R01 * s0
    D0, D1, D2 = R11 * s2 - R12 * s1, R12 * s0 - R10 * s2, R10 * s1 - R11 * s0
    E0, E1, E2 = R21 * s2 - R22 * s1, R22 * s0 - R20 * s2, R20 * s1 - R21 * s0
    return (
        R00 + al * (A0 + (A1 * z2 - A2 * z1)),
        R01 + al * (A1 + (A2 * z0 - A0 * z2)),
        R02 + al * (A2 + (A0 * z1 - A1 * z0)),
        R10 + al * (D0 + (D1 * z2 - D2 * z1)),
        R11 + al * (D1 + (D2 * z0 - D0 * z2)),
        R12 + al * (D2 + (D0 * z1 - D1 * z0)),
        R20 + al * (E0 + (E1 * z2 - E2 * z1)),
        R21 + al * (E1 + (E2 * z0 - E0 * z2)),
        R22 + al * (E2 + (E0 * z1 - E1 * z0)),
        (p0 - c0 * e0) - h * (w0 - e0 * kw),
        (p1 - c0 * e1) - h * (w1 - e1 * kw),
        (p2 - c0 * e2) - h * (w2 - e2 * kw),
    ), its


@numba.njit(**_JIT)
def _suslov_loop(state0, h, steps, params, solver, out):
    """`steps` steps from state0 (12,) into out (12,); returns the total number of iterations."""
    C = _suslov_consts(params)
    s = (
        state0[0], state0[1], state0[2], state0[3], state0[4], state0[5],
        state0[6], state0[7], state0[8], state0[9], state0[10], state0[11],
    )  # fmt: skip
    n = 0
    for _ in range(steps):
        s, its = _suslov_step(s, h, C, solver)
        n += its
    for i in range(12):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_suslov_general(state0, h, steps, params, solver=-1):
    """`steps` sgni-trapezoid steps of Suslov's problem from state0 = (R (9), p̄ (3)) (12,).

    params = (I11, I22, I33, I12, I13, I23, a1, a2, a3) (gnipy's "suslov" parameters); solver: one
    of `SOLVERS`' values (default `SUSLOV_SOLVER`)."""
    if solver < 0:
        solver = SUSLOV_SOLVER
    out = np.empty(12)
    _suslov_loop(state0, h, steps, params, solver, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_suslov_general_batch(states0, h, steps, params, solver=-1):
    """:func:`run_suslov_general` for each row of states0 (B, 12), in parallel over the rows."""
    if solver < 0:
        solver = SUSLOV_SOLVER
    B = states0.shape[0]
    out = np.empty((B, 12))
    for b in numba.prange(B):
        _suslov_loop(states0[b], h, steps, params, solver, out[b])
    return out


@numba.njit(**_JIT)
def _suslov_count(state0, h, steps, params, solver):
    out = np.empty(12)
    return _suslov_loop(state0, h, steps, params, solver, out), out


@numba.njit(**_JIT)
def run_suslov(state0, h, steps):
    """Suslov's problem (sgni-trapezoid, gnipy's default parameters): final state (12,)."""
    out = np.empty(12)
    _suslov_loop(state0, h, steps, SUSLOV_PARAMS, SUSLOV_SOLVER, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_suslov_batch(states0, h, steps):
    """Suslov's problem: final states (B, 12), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 12))
    for b in numba.prange(B):
        _suslov_loop(states0[b], h, steps, SUSLOV_PARAMS, SUSLOV_SOLVER, out[b])
    return out


def _suslov_inertia(params):
    """The inertia tensor (3, 3) of Suslov's params (I11, I22, I33, I12, I13, I23, ...)."""
    A00, A11, A22, A01, A02, A12 = params[:6]
    return np.array([[A00, A01, A02], [A01, A11, A12], [A02, A12, A22]])


def suslov_observe(state, params=SUSLOV_PARAMS):
    """The reported node of a Suslov state: (q (0,), v̄ = I⁻¹p̄ (3), p̄ (3), R (3, 3))."""
    state = np.asarray(state, dtype=np.float64)
    p = state[9:12].copy()
    return np.zeros(0), np.linalg.solve(_suslov_inertia(params), p), p, state[:9].copy().reshape(3, 3)


# =============================================================================================
# The first version (v1), kept unchanged as the benchmark's "old baseline" (issue 35)
# =============================================================================================
#
# Its design: the unknowns are the increments σ (balls) and d = q_{k+1} − q_k (oscillator); FL⁺
# is evaluated from the increment (M = Iσ/h, d/h); Newton with the analytic Jacobian, solved by
# the 3×3 Gaussian elimination with partial pivoting below (also for the oscillator's
# block-diagonal Jacobian), stopping at max|δ| <= 1e-14 max(1, max|z|) (`NEWTON_TOL_V1`), which
# takes one more iteration than needed (the last one only confirms convergence); the projectors
# with one division per entry. Its only change: each step also returns its iteration count (for
# `count_iterations`; an integer sum per step, no measurable cost). The node report
# (`_ball_reflect`/`ball_observe`, `_osc_reflect`/`oscillator_observe`) is shared by both versions.


# ---------------------------------------------------------------------------------------------
# 3×3 Gaussian elimination with partial pivoting, on scalars
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def _solve3_v1(a00, a01, a02, a10, a11, a12, a20, a21, a22, b0, b1, b2):
    """Solve A u = b for a 3×3 A (row-major scalars) by Gaussian elimination with partial pivoting.

    The pivots' reciprocals are taken once (3 divisions): this only rounds the Newton update, which
    the next iteration corrects, so it changes no result (measured: bit-identical final states)."""
    # column 0: bring the largest |a_i0| to row 0
    if abs(a10) > abs(a00) and abs(a10) >= abs(a20):
        a00, a01, a02, b0, a10, a11, a12, b1 = a10, a11, a12, b1, a00, a01, a02, b0
    elif abs(a20) > abs(a00):
        a00, a01, a02, b0, a20, a21, a22, b2 = a20, a21, a22, b2, a00, a01, a02, b0
    i0 = 1.0 / a00
    f1 = a10 * i0
    f2 = a20 * i0
    a11 -= f1 * a01
    a12 -= f1 * a02
    b1 -= f1 * b0
    a21 -= f2 * a01
    a22 -= f2 * a02
    b2 -= f2 * b0
    # column 1: pivot between rows 1 and 2
    if abs(a21) > abs(a11):
        a11, a12, b1, a21, a22, b2 = a21, a22, b2, a11, a12, b1
    i1 = 1.0 / a11
    f2 = a21 * i1
    a22 -= f2 * a12
    b2 -= f2 * b1
    # back substitution
    u2 = b2 / a22
    u1 = (b1 - a12 * u2) * i1
    u0 = (b0 - a01 * u1 - a02 * u2) * i0
    return u0, u1, u2


# ---------------------------------------------------------------------------------------------
# A ball on a table, R^2 x SO(3), trapezoid l_d (rolling ball ex. 2 and the Chaplygin sphere)
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def _ball_reflect(s, params, chaplygin):
    """(p⁻, p̄) of the ball at state `s` (16-tuple): numpy_gni.reflect_and_report written out.

    μ = [[1, 0, a], [0, 1, c]] with a = (0, −r, 0), c = (r, 0, 0) (rolling ball: constant) or
    a = −r R[1, :], c = r R[0, :] (Chaplygin sphere); G = diag(m, m, I); Π = G Y,
    Y = (−Ω y, Ω x, 0, 0, 0). Returns the 10-tuple (p⁻ (5), p̄ (5)).
    """
    m, r, I1, I2, I3, W = params
    x, y = s[0], s[1]
    if chaplygin:
        a0, a1, a2 = -r * s[5], -r * s[6], -r * s[7]
        c0, c1, c2 = r * s[2], r * s[3], r * s[4]
    else:
        a0, a1, a2 = 0.0, -r, 0.0
        c0, c1, c2 = r, 0.0, 0.0
    # w = G⁻¹(p⁺ − Π)
    w0 = (s[11] - m * (-W * y)) / m
    w1 = (s[12] - m * (W * x)) / m
    w2, w3, w4 = s[13] / I1, s[14] / I2, s[15] / I3
    # C = μG⁻¹μᵀ (2×2, symmetric), μw, λ = C⁻¹μw
    im = 1.0 / m
    C00 = im + a0 * a0 / I1 + a1 * a1 / I2 + a2 * a2 / I3
    C01 = a0 * c0 / I1 + a1 * c1 / I2 + a2 * c2 / I3
    C11 = im + c0 * c0 / I1 + c1 * c1 / I2 + c2 * c2 / I3
    g0 = w0 + a0 * w2 + a1 * w3 + a2 * w4
    g1 = w1 + c0 * w2 + c1 * w3 + c2 * w4
    det = C00 * C11 - C01 * C01
    l0 = (C11 * g0 - C01 * g1) / det
    l1 = (C00 * g1 - C01 * g0) / det
    # Q*(p⁺ − Π) = μᵀλ
    q0, q1 = l0, l1
    q2, q3, q4 = a0 * l0 + c0 * l1, a1 * l0 + c1 * l1, a2 * l0 + c2 * l1
    return (
        s[11] - 2.0 * q0, s[12] - 2.0 * q1, s[13] - 2.0 * q2, s[14] - 2.0 * q3, s[15] - 2.0 * q4,
        s[11] - q0, s[12] - q1, s[13] - q2, s[14] - q3, s[15] - q4,
    )  # fmt: skip


@numba.njit(**_JIT)
def _ball_step_v1(s, h, params, chaplygin):
    """One GNI (trapezoid, Cayley) step of a ball: 16-tuple -> 16-tuple (NaNs if Newton fails)."""
    m, r, I1, I2, I3, W = params
    x, y = s[0], s[1]
    rf = _ball_reflect(s, params, chaplygin)
    pm0, pm1, pm2, pm3, pm4 = rf[0], rf[1], rf[2], rf[3], rf[4]
    # x-part of FL⁻ = p⁻: m (x_{k+1} − x_k)/h = p⁻_x, linear: the increment is (h/m) p⁻_x
    dx = h * pm0 / m
    dy = h * pm1 / m
    # σ-part: h dcay⁻¹_σᵀ(Iσ/h) − h p⁻_ω = Iσ + ½ σ×Iσ + ¼ σ(σ·Iσ) − h p⁻_ω = 0; guess σ = h ξ̄ = h p̄_ω/I
    t0, t1, t2 = h * pm2, h * pm3, h * pm4
    s0, s1, s2 = h * rf[7] / I1, h * rf[8] / I2, h * rf[9] / I3
    ok = False
    for it in range(1, NEWTON_MAXITER + 1):
        M0, M1, M2 = I1 * s0, I2 * s1, I3 * s2
        sM = s0 * M0 + s1 * M1 + s2 * M2
        F0 = M0 + 0.5 * (s1 * M2 - s2 * M1) + 0.25 * s0 * sM - t0
        F1 = M1 + 0.5 * (s2 * M0 - s0 * M2) + 0.25 * s1 * sM - t1
        F2 = M2 + 0.5 * (s0 * M1 - s1 * M0) + 0.25 * s2 * sM - t2
        # J = I + ½(σ̂ I − (Iσ)^) + ¼((σᵀIσ)E + 2σ(Iσ)ᵀ)
        q = 0.25 * sM
        J00 = I1 + q + 0.5 * s0 * M0
        J01 = 0.5 * (-s2 * I2 + M2) + 0.5 * s0 * M1
        J02 = 0.5 * (s1 * I3 - M1) + 0.5 * s0 * M2
        J10 = 0.5 * (s2 * I1 - M2) + 0.5 * s1 * M0
        J11 = I2 + q + 0.5 * s1 * M1
        J12 = 0.5 * (-s0 * I3 + M0) + 0.5 * s1 * M2
        J20 = 0.5 * (-s1 * I1 + M1) + 0.5 * s2 * M0
        J21 = 0.5 * (s0 * I2 - M0) + 0.5 * s2 * M1
        J22 = I3 + q + 0.5 * s2 * M2
        d0, d1, d2 = _solve3_v1(J00, J01, J02, J10, J11, J12, J20, J21, J22, -F0, -F1, -F2)
        s0 += d0
        s1 += d1
        s2 += d2
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL_V1 * max(1.0, abs(s0), abs(s1), abs(s2)):
            ok = True
            break
    if not ok:  # also when an update is NaN (comparisons with NaN are false)
        return _NAN16, NEWTON_MAXITER
    # cay(σ) = E + α(σ̂ + ½σ̂²), σ̂² = σσᵀ − |σ|²E, α = 4/(4 + |σ|²)
    n2 = s0 * s0 + s1 * s1 + s2 * s2
    al = 4.0 / (4.0 + n2)
    ah = 0.5 * al
    g00 = 1.0 + ah * (s0 * s0 - n2)
    g11 = 1.0 + ah * (s1 * s1 - n2)
    g22 = 1.0 + ah * (s2 * s2 - n2)
    g01 = -al * s2 + ah * s0 * s1
    g10 = al * s2 + ah * s0 * s1
    g02 = al * s1 + ah * s0 * s2
    g20 = -al * s1 + ah * s0 * s2
    g12 = -al * s0 + ah * s1 * s2
    g21 = al * s0 + ah * s1 * s2
    R00, R01, R02, R10, R11, R12, R20, R21, R22 = s[2], s[3], s[4], s[5], s[6], s[7], s[8], s[9], s[10]
    if chaplygin:  # R_{k+1} = R_k cay(σ) (body angular velocity)
        A00, A01, A02, A10, A11, A12, A20, A21, A22 = R00, R01, R02, R10, R11, R12, R20, R21, R22
        B00, B01, B02, B10, B11, B12, B20, B21, B22 = g00, g01, g02, g10, g11, g12, g20, g21, g22
    else:  # R_{k+1} = cay(σ) R_k (space angular velocity)
        A00, A01, A02, A10, A11, A12, A20, A21, A22 = g00, g01, g02, g10, g11, g12, g20, g21, g22
        B00, B01, B02, B10, B11, B12, B20, B21, B22 = R00, R01, R02, R10, R11, R12, R20, R21, R22
    # FL⁺ = (m Δx/h, dcay⁻¹_{−σ}ᵀ M), M = Iσ/h: M − ½σ×M + ¼σ(σ·M)
    M0, M1, M2 = I1 * s0 / h, I2 * s1 / h, I3 * s2 / h
    sM = s0 * M0 + s1 * M1 + s2 * M2
    return (
        x + dx, y + dy,
        A00 * B00 + A01 * B10 + A02 * B20, A00 * B01 + A01 * B11 + A02 * B21, A00 * B02 + A01 * B12 + A02 * B22,
        A10 * B00 + A11 * B10 + A12 * B20, A10 * B01 + A11 * B11 + A12 * B21, A10 * B02 + A11 * B12 + A12 * B22,
        A20 * B00 + A21 * B10 + A22 * B20, A20 * B01 + A21 * B11 + A22 * B21, A20 * B02 + A21 * B12 + A22 * B22,
        m * dx / h, m * dy / h,
        M0 - 0.5 * (s1 * M2 - s2 * M1) + 0.25 * s0 * sM,
        M1 - 0.5 * (s2 * M0 - s0 * M2) + 0.25 * s1 * sM,
        M2 - 0.5 * (s0 * M1 - s1 * M0) + 0.25 * s2 * sM,
    ), it  # fmt: skip


@numba.njit(**_JIT)
def _ball_loop_v1(state0, h, steps, params, chaplygin, out):
    """`steps` steps from state0 (16,) into out (16,): the state lives in a tuple of scalars."""
    s = (
        state0[0], state0[1], state0[2], state0[3], state0[4], state0[5], state0[6], state0[7],
        state0[8], state0[9], state0[10], state0[11], state0[12], state0[13], state0[14], state0[15],
    )  # fmt: skip
    n = 0
    for _ in range(steps):
        s, its = _ball_step_v1(s, h, params, chaplygin)
        n += its
    for i in range(16):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_ball_v1(state0, h, steps, params, chaplygin):
    """`steps` GNI steps of a ball from the flat state0 (16,); returns the final state (16,).

    params = (m, r, I1, I2, I3, Omega); chaplygin: False for the rolling ball (constant μ,
    R_{k+1} = cay(σ)R_k), True for the Chaplygin sphere (μ(R), R_{k+1} = R_k cay(σ)).
    """
    out = np.empty(16)
    _ball_loop_v1(state0, h, steps, params, chaplygin, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_ball_batch_v1(states0, h, steps, params, chaplygin):
    """:func:`run_ball_v1` for each row of states0 (B, 16), in parallel over the rows (all cores)."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop_v1(states0[b], h, steps, params, chaplygin, out[b])
    return out


@numba.njit(**_JIT)
def _ball_count_v1(state0, h, steps, params, chaplygin):
    out = np.empty(16)
    return _ball_loop_v1(state0, h, steps, params, chaplygin, out), out


@numba.njit(**_JIT)
def ball_observe(state, params, chaplygin):
    """The reported node of a ball state: (x (2), v̄ (5), p̄ (5), R (3, 3))."""
    m, r, I1, I2, I3, W = params
    s = (
        state[0], state[1], state[2], state[3], state[4], state[5], state[6], state[7],
        state[8], state[9], state[10], state[11], state[12], state[13], state[14], state[15],
    )  # fmt: skip
    rf = _ball_reflect(s, params, chaplygin)
    p = np.array([rf[5], rf[6], rf[7], rf[8], rf[9]])
    v = np.array([rf[5] / m, rf[6] / m, rf[7] / I1, rf[8] / I2, rf[9] / I3])
    return state[:2].copy(), v, p, state[2:11].copy().reshape(3, 3)


@numba.njit(**_JIT)
def run_rolling_ball_ex2_v1(state0, h, steps):
    """The rolling ball, example 2 (gni-trapezoid): final state (16,) after `steps` steps."""
    return run_ball_v1(state0, h, steps, EX2_PARAMS, False)


@numba.njit(parallel=True, **_JIT)
def run_rolling_ball_ex2_batch_v1(states0, h, steps):
    """The rolling ball, example 2: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop_v1(states0[b], h, steps, EX2_PARAMS, False, out[b])
    return out


@numba.njit(**_JIT)
def run_chaplygin_sphere_v1(state0, h, steps):
    """The Chaplygin sphere (gni-trapezoid): final state (16,) after `steps` steps."""
    return run_ball_v1(state0, h, steps, CHAPLYGIN_PARAMS, True)


@numba.njit(parallel=True, **_JIT)
def run_chaplygin_sphere_batch_v1(states0, h, steps):
    """The Chaplygin sphere: final states (B, 16), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 16))
    for b in numba.prange(B):
        _ball_loop_v1(states0[b], h, steps, CHAPLYGIN_PARAMS, True, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# The contact oscillator on R^3, midpoint l_d (gni-midpoint)
# ---------------------------------------------------------------------------------------------


@numba.njit(**_JIT)
def _osc_reflect(s):
    """(p⁻, p̄) at s = (q, p⁺): μ = (1, 0, y), G = E, Π = 0, C = 1 + y², λ = μp⁺/C, Q*p⁺ = μᵀλ."""
    y = s[1]
    lam = (s[3] + y * s[5]) / (1.0 + y * y)
    ly = y * lam
    return s[3] - 2.0 * lam, s[4], s[5] - 2.0 * ly, s[3] - lam, s[4], s[5] - ly


@numba.njit(**_JIT)
def _osc_step_v1(s, h, eps):
    """One GNI (midpoint) step of the contact oscillator: 6-tuple -> 6-tuple (NaNs if Newton fails).

    With V = ½(|q|² + εx²z²) and the unknown increment d = q_{k+1} − q_k:
    h FL⁻ − h p⁻ = d + (h²/2)∇V(q_k + d/2) − h p⁻ = 0, Jacobian E + (h²/4)∇²V(q_k + d/2);
    FL⁺ = d/h − (h/2)∇V(q_k + d/2). (Solving for d rather than q_{k+1} keeps every term of the
    residual O(h): its round-off is that of d, not of q_k, and FL⁺ uses d itself rather than the
    rounded difference q_{k+1} − q_k.)
    """
    x, y, z = s[0], s[1], s[2]
    rf = _osc_reflect(s)
    t0, t1, t2 = h * rf[0], h * rf[1], h * rf[2]  # h p⁻
    u0, u1, u2 = h * rf[3], h * rf[4], h * rf[5]  # guess d = h v̄ (G = E), i.e. q_{k+1} = q_k + h v̄
    c = 0.5 * h * h
    c4 = 0.25 * h * h
    ok = False
    for it in range(1, NEWTON_MAXITER + 1):
        mx, my, mz = x + 0.5 * u0, y + 0.5 * u1, z + 0.5 * u2
        F0 = u0 + c * (mx + eps * mx * mz * mz) - t0
        F1 = u1 + c * my - t1
        F2 = u2 + c * (mz + eps * mx * mx * mz) - t2
        J00 = 1.0 + c4 * (1.0 + eps * mz * mz)
        J02 = c4 * (2.0 * eps * mx * mz)
        J11 = 1.0 + c4
        J22 = 1.0 + c4 * (1.0 + eps * mx * mx)
        d0, d1, d2 = _solve3_v1(J00, 0.0, J02, 0.0, J11, 0.0, J02, 0.0, J22, -F0, -F1, -F2)
        u0 += d0
        u1 += d1
        u2 += d2
        # z = q_{k+1} = q_k + d
        if max(abs(d0), abs(d1), abs(d2)) <= NEWTON_TOL_V1 * max(1.0, abs(x + u0), abs(y + u1), abs(z + u2)):
            ok = True
            break
    if not ok:
        return _NAN6, NEWTON_MAXITER
    mx, my, mz = x + 0.5 * u0, y + 0.5 * u1, z + 0.5 * u2
    hh = 0.5 * h
    return (
        x + u0, y + u1, z + u2,
        u0 / h - hh * (mx + eps * mx * mz * mz),
        u1 / h - hh * my,
        u2 / h - hh * (mz + eps * mx * mx * mz),
    ), it  # fmt: skip


@numba.njit(**_JIT)
def _osc_loop_v1(state0, h, steps, eps, out):
    s = (state0[0], state0[1], state0[2], state0[3], state0[4], state0[5])
    n = 0
    for _ in range(steps):
        s, its = _osc_step_v1(s, h, eps)
        n += its
    for i in range(6):
        out[i] = s[i]
    return n


@numba.njit(**_JIT)
def run_oscillator_v1(state0, h, steps, eps):
    """`steps` GNI-midpoint steps of the contact oscillator from state0 = (q, p⁺) (6,)."""
    out = np.empty(6)
    _osc_loop_v1(state0, h, steps, eps, out)
    return out


@numba.njit(parallel=True, **_JIT)
def run_oscillator_batch_v1(states0, h, steps, eps):
    """:func:`run_oscillator_v1` for each row of states0 (B, 6), in parallel over the rows."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop_v1(states0[b], h, steps, eps, out[b])
    return out


@numba.njit(**_JIT)
def _osc_count_v1(state0, h, steps, eps):
    out = np.empty(6)
    return _osc_loop_v1(state0, h, steps, eps, out), out


@numba.njit(**_JIT)
def oscillator_observe(state):
    """The reported node of an oscillator state: (q (3), v̄ (3), p̄ (3)) (G = E, so v̄ = p̄)."""
    rf = _osc_reflect((state[0], state[1], state[2], state[3], state[4], state[5]))
    p = np.array([rf[3], rf[4], rf[5]])
    return state[:3].copy(), p.copy(), p


@numba.njit(**_JIT)
def run_contact_oscillator_v1(state0, h, steps):
    """The contact oscillator (gni-midpoint, ε = 0.3): final state (6,) after `steps` steps."""
    return run_oscillator_v1(state0, h, steps, OSCILLATOR_EPS)


@numba.njit(parallel=True, **_JIT)
def run_contact_oscillator_batch_v1(states0, h, steps):
    """The contact oscillator: final states (B, 6), in parallel over the trajectories."""
    B = states0.shape[0]
    out = np.empty((B, 6))
    for b in numba.prange(B):
        _osc_loop_v1(states0[b], h, steps, OSCILLATOR_EPS, out[b])
    return out


# ---------------------------------------------------------------------------------------------
# The Python API
# ---------------------------------------------------------------------------------------------


class Case:
    """One benchmark case: its compiled runs, initial state and node report.

    Attributes:
        name: the case's name (gnipy's model name, or "rolling-ball-ex2-yoshida4" for the
            composition on the rolling ball); numpy_case, method: numpy_gni's case name (None: no
            numpy_gni version) and the gnipy method.
        size: the length of the flat state.
        version: "v2" (the current kernels) or "v1" (the first version, `LEGACY_CASES`).
    """

    def __init__(self, name, numpy_case, method, size, state0, run, run_batch, observe, version="v2"):
        self.name, self.numpy_case, self.method, self.size = name, numpy_case, method, size
        self._state0, self._run, self._run_batch, self._observe = state0, run, run_batch, observe
        self.version = version

    def __repr__(self):
        return f"numba_gni.Case({self.name!r}, {self.method!r}, {self.version!r})"

    def initial_state(self, h=START_H):
        """The flat float64 start state: numpy_gni's initial_state(), flattened (p⁺₀ = G v₀, the
        paper's start), Suslov's (R₀ = E, p̄₀ = I Ω₀, gnipy's sgni start), or for the composition
        gnipy's consistent start, which depends on the step `h` (the other cases ignore it)."""
        return self._state0(float(h)) if callable(self._state0) else self._state0.copy()

    def run(self, state0, h, steps):
        """The final state after `steps` steps of size h from `state0` (one trajectory)."""
        return self._run(np.ascontiguousarray(state0, dtype=np.float64), float(h), int(steps))

    def run_batch(self, states0, h, steps):
        """The final states (B, size) from `states0` (B, size), in parallel over the trajectories."""
        states0 = np.ascontiguousarray(states0, dtype=np.float64)
        if states0.ndim != 2 or states0.shape[1] != self.size:
            raise ValueError(f"states0: expected shape (B, {self.size}), got {states0.shape}")
        return self._run_batch(states0, float(h), int(steps))

    def observe(self, state):
        """The reported node `dict(q, v, p, R)` as numpy_gni's observe (v̄, p̄; R None for the oscillator)."""
        return self._observe(np.ascontiguousarray(state, dtype=np.float64))


def _ball_state0(params, q0, v0):
    m, _, I1, I2, I3, _ = params
    p0 = np.array([m, m, I1, I2, I3]) * np.asarray(v0)
    return np.concatenate([np.asarray(q0, dtype=float), np.eye(3).ravel(), p0])


def _ball_observer(params, chaplygin):
    def observe(state):
        q, v, p, R = ball_observe(state, params, chaplygin)
        return {"q": q, "v": v, "p": p, "R": R}

    return observe


def _osc_observe(state):
    q, v, p = oscillator_observe(state)
    return {"q": q, "v": v, "p": p, "R": None}


def _suslov_observe(state):
    q, v, p, R = suslov_observe(state)
    return {"q": q, "v": v, "p": p, "R": R}


def _suslov_state0(params, v0):
    """(R₀ = E, p̄₀ = I Ω₀): gnipy's sgni start projects I Ω₀ on the constraint, a no-op for
    ⟨a, Ω₀⟩ = 0 (exactly 0 here: Ω₀ = (1, 0.5, 0), a = e3)."""
    return np.concatenate([np.eye(3).ravel(), _suslov_inertia(params) @ np.asarray(v0, dtype=float)])


_EX2_STATE0 = _ball_state0(EX2_PARAMS, _EX2_Q0, _EX2_V0)
_OSC_STATE0 = np.array([1.0, 1.0, 1.0, -1.0, 1.0, 1.0])  # (q0, p⁺0 = v0)
_CHAPLYGIN_STATE0 = _ball_state0(CHAPLYGIN_PARAMS, (0.0, 0.0), (0.5, -1.0, 1.0, 0.5, 2.0))
_SUSLOV_STATE0 = _suslov_state0(SUSLOV_PARAMS, _SUSLOV_V0)

CASES = {
    "rolling-ball-ex2": Case(
        "rolling-ball-ex2", "rolling_ball_ex2", "gni-trapezoid", 16, _EX2_STATE0,
        run_rolling_ball_ex2, run_rolling_ball_ex2_batch, _ball_observer(EX2_PARAMS, False),
    ),
    "contact-oscillator": Case(
        "contact-oscillator", "contact_oscillator", "gni-midpoint", 6, _OSC_STATE0,
        run_contact_oscillator, run_contact_oscillator_batch, _osc_observe,
    ),
    "chaplygin-sphere": Case(
        "chaplygin-sphere", "chaplygin_sphere", "gni-trapezoid", 16, _CHAPLYGIN_STATE0,
        run_chaplygin_sphere, run_chaplygin_sphere_batch, _ball_observer(CHAPLYGIN_PARAMS, True),
    ),
    "rolling-ball-ex2-yoshida4": Case(
        "rolling-ball-ex2-yoshida4", None, "yoshida4-gni-trapezoid", 16, rolling_ball_ex2_consistent_start,
        run_rolling_ball_ex2_yoshida4, run_rolling_ball_ex2_yoshida4_batch, _ball_observer(EX2_PARAMS, False),
    ),
    "suslov": Case(
        "suslov", None, "sgni-trapezoid", 12, _SUSLOV_STATE0, run_suslov, run_suslov_batch, _suslov_observe,
    ),
}  # fmt: skip

#: The first version's kernels as cases (the "old baseline" of the benchmark's history). The cases
#: added after it (the composition, Suslov) have none: `get_case(name, legacy=True)` is None for them.
LEGACY_CASES = {
    "rolling-ball-ex2": Case(
        "rolling-ball-ex2", "rolling_ball_ex2", "gni-trapezoid", 16, _EX2_STATE0,
        run_rolling_ball_ex2_v1, run_rolling_ball_ex2_batch_v1, _ball_observer(EX2_PARAMS, False), "v1",
    ),
    "contact-oscillator": Case(
        "contact-oscillator", "contact_oscillator", "gni-midpoint", 6, _OSC_STATE0,
        run_contact_oscillator_v1, run_contact_oscillator_batch_v1, _osc_observe, "v1",
    ),
    "chaplygin-sphere": Case(
        "chaplygin-sphere", "chaplygin_sphere", "gni-trapezoid", 16, _CHAPLYGIN_STATE0,
        run_chaplygin_sphere_v1, run_chaplygin_sphere_batch_v1, _ball_observer(CHAPLYGIN_PARAMS, True), "v1",
    ),
}  # fmt: skip

#: The solver each case's `run`/`run_batch` uses, by name.
CASE_SOLVER = {
    name: next(k for k, v in SOLVERS.items() if v == code)
    for name, code in (
        ("rolling-ball-ex2", EX2_SOLVER),
        ("contact-oscillator", OSC_SOLVER),
        ("chaplygin-sphere", CHAPLYGIN_SOLVER),
        ("rolling-ball-ex2-yoshida4", EX2_YOSHIDA4_SOLVER),
        ("suslov", SUSLOV_SOLVER),
    )
}

#: The model arguments of each case's general kernel (`_COUNTS`: run_ball, run_oscillator, ...).
_MODEL_ARGS = {
    "rolling-ball-ex2": (EX2_PARAMS, False),
    "chaplygin-sphere": (CHAPLYGIN_PARAMS, True),
    "contact-oscillator": (OSCILLATOR_EPS,),
    "rolling-ball-ex2-yoshida4": (EX2_PARAMS,),
    "suslov": (SUSLOV_PARAMS,),
}

#: (the current kernel's iteration count, the first version's or None) of each case
_COUNTS = {
    "rolling-ball-ex2": (_ball_count, _ball_count_v1),
    "chaplygin-sphere": (_ball_count, _ball_count_v1),
    "contact-oscillator": (_osc_count, _osc_count_v1),
    "rolling-ball-ex2-yoshida4": (_yoshida4_count, None),
    "suslov": (_suslov_count, None),
}


def get_case(name, legacy=False):
    """The :class:`Case` called `name` (also accepts numpy_gni's names, e.g. "rolling_ball_ex2");
    `legacy=True`: the first version's (`LEGACY_CASES`), None for a case that has none (the
    composition and Suslov were added after it)."""
    key = name.replace("_", "-")
    if key not in CASES:
        raise ValueError(f"case: expected one of {tuple(CASES)}, got {name!r}")
    return LEGACY_CASES.get(key) if legacy else CASES[key]


def count_iterations(name, h=0.01, steps=1000, solver=None, legacy=False, state0=None):
    """The mean number of Newton (or chord) iterations per step of a case.

    Runs `steps` steps of size h from the case's initial state (for h; or `state0`) with the solver
    `solver` (a name of `SOLVERS`; default: the case's own, `CASE_SOLVER`), or with the first
    version (`legacy=True`; ValueError for a case without one). Counted: Jacobian solves (Newton)
    or increments (chord), including the last one that meets the stopping test, summed over the
    composition's three substeps; not the predictor's fixed-point sweeps (`PREDICTOR_SWEEPS`, a
    fixed number per step). Returns `(mean_iterations, final_state)`.
    """
    case = get_case(name)
    s0 = case.initial_state(h) if state0 is None else np.ascontiguousarray(state0, dtype=np.float64)
    args = _MODEL_ARGS[case.name]
    count, count_v1 = _COUNTS[case.name]
    if legacy:
        if count_v1 is None:
            raise ValueError(f"legacy: case {case.name!r} has no first version")
        if solver is not None:
            raise ValueError("solver: the first version has only its Newton iteration")
        n, out = count_v1(s0, float(h), int(steps), *args)
    else:
        solver = CASE_SOLVER[case.name] if solver is None else solver
        if solver not in SOLVERS:
            raise ValueError(f"solver: expected one of {tuple(SOLVERS)}, got {solver!r}")
        n, out = count(s0, float(h), int(steps), *args, SOLVERS[solver])
    return n / max(int(steps), 1), out
