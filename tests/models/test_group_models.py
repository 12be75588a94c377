"""The models on R^n × G: Chaplygin sphere and top, Suslov, Veselova, the sleigh on SE(2).

Every number here comes from an exact solution, an invariant, the constraints or an independent
formulation (the R^3 sleigh) — never from a previous run. Bounds on the GNI's invariant errors are
either O(h²) (checked by halving h at a fixed number of steps, which shares one compilation) or a
round-off / solver-tolerance model (steps × tolerance × scale).

Compile time dominates: each system is compiled once for the reference (101 saved nodes; run on
the System without its provenance fields, :func:`reference`, so that one model's parameter values
share it) and once per GNI family with one (steps, save_every) pair. Suslov's convergence is checked
for the GNI with the midpoint l_d (the trapezoid's order on SO(3): the comment above
test_suslov_gni_converges_at_order_two).
Measured on the shared 2-core machine (`pytest -n 0 --durations=0` on this file alone, other jobs
running, so noisy to a few seconds): 44.2 s → 37.6 s.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.lie_groups import SO3
from gnipy.models import chaplygin_sleigh, chaplygin_sphere, chaplygin_top, suslov

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

EPS = np.finfo(np.float64).eps
NEWTON_TOL = 1e-12  # the GNI root finder's tolerance (integrators.base.default_root_finder)
GROUP_MODELS = ["chaplygin-sphere", "chaplygin-top", "suslov", "veselova", "chaplygin-sleigh-se2"]
H_REF, T_REF = 0.1, 10.0  # reference runs: 101 saved nodes (one compilation per system)
LONG_STEPS, LONG_SAVE = 100_000, 100  # long GNI runs
CONV_STEPS, CONV_HS, CONV_T = 320, [0.1, 0.05, 0.025, 0.0125], 4.0  # convergence: compare on t <= 4


def _np(x):
    return np.asarray(x, dtype=np.float64)


def reference(sys_, q0, v0, R0=None, **kw):
    """The continuous reference of `sys_` from (q0, v0, R0), run on `sys_.without_metadata()`: the
    reference's compiled program is keyed by the whole System, the parameter values of its
    provenance field `params` included, so runs of one model at other parameter values (the
    turning tables below, Suslov's generic body) compiled anew (2-3 s of CPU each); without the
    provenance fields they share one program, as the GNI runs do."""
    return gnipy.simulate(sys_.without_metadata(), "reference", q0, v0, R0=R0, **kw)


def _setup(name, **over):
    spec = gnipy.get_model(name)
    p = spec.resolve_params(over)
    q0, v0 = spec.initial_condition(p)
    return spec, p, spec.build(p), q0, v0


def invariant_series(spec, p, sol, name):
    """The invariant `name` of `spec` at every saved node of `sol` (R-dependent models take R).
    Compiled (one small program; evaluated eagerly the vmapped invariant costs more)."""
    f = spec.invariants[name]
    if spec.build(p).depends_on_orientation:
        return _np(jax.jit(jax.vmap(lambda q, v, R: f(p, q, v, R)))(sol.q, sol.v, sol.R))
    return _np(jax.jit(jax.vmap(lambda q, v: f(p, q, v)))(sol.q, sol.v))


def drift_and_amplitude(t, x):
    """(|fitted linear change over the run|, peak-to-peak of the residual about the line, max |x − x₀|)."""
    t, d = _np(t), _np(x) - _np(x)[0]
    slope, icpt = np.polyfit(t, d, 1)
    resid = d - (slope * t + icpt)
    return abs(slope * (t[-1] - t[0])), float(np.ptp(resid)), float(np.max(np.abs(d)))


def fitted_order(hs, errors):
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


def max_step_rate(sol):
    """max |ξ| (the angular velocity, the last three components) over the saved nodes: the fastest
    rate of the motion, the scale of O(h²) bounds."""
    return float(np.max(np.linalg.norm(_np(sol.v)[:, -3:], axis=-1)))


# --------------------------------------------------------------------------------------------
# Registration and defaults
# --------------------------------------------------------------------------------------------
OVERRIDES = {
    "chaplygin-sphere": {"r": 0.5, "I1": 0.2, "Omega": 0.3},
    "chaplygin-top": {"a": 0.2, "r": 0.8, "Omega": 0.5},
    "suslov": {"a1": 0.3, "a2": -0.5, "a3": 0.8, "I12": -0.2},
    "veselova": {"I1": 2.0},
    "chaplygin-sleigh-se2": {"a": -0.3},
}


@pytest.mark.parametrize("name", GROUP_MODELS)
@pytest.mark.parametrize("override", [False, True])
def test_defaults_satisfy_the_constraints(name, override):
    spec, p, sys_, q0, v0 = _setup(name, **(OVERRIDES[name] if override else {}))
    assert name in gnipy.model_names() and sys_.name == name and sys_.group is not None
    assert spec.notes and spec.invariants and all(isinstance(x, float) for x in p.values())
    R0 = sys_.defaults[2] if len(sys_.defaults) > 2 else None
    assert R0 == spec.R0
    b0, _ = sys_.check(q0, v0, R0=R0)  # mechanical type, full rank, v0 on the constraints
    assert np.max(np.abs(_np(sys_.constraint_residual(b0, jnp.asarray(v0))))) <= 1e-14
    if not override:
        assert (tuple(q0), tuple(v0)) == (spec.q0, spec.v0)


def test_top_default_attitude_is_tilted_rotation():
    R = np.asarray(chaplygin_top.R0).reshape(3, 3)
    assert np.max(np.abs(R.T @ R - np.eye(3))) <= 1e-15 and np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R, np.asarray(SO3().exp(jnp.asarray(chaplygin_top.THETA0))), atol=1e-15)
    assert R[2, 2] < 0.9  # the body's e3 is tilted away from the vertical


def test_sphere_constraints_are_rolling_without_slipping():
    """μ(R)(v − Y) is the velocity of the body point in contact minus the table's velocity there."""
    _spec, p, sys_, _, _ = _setup("chaplygin-sphere", Omega=0.7, r=0.6)
    rng = np.random.default_rng(3)
    R = np.asarray(SO3().random(jax.random.PRNGKey(4)))
    x, v = rng.standard_normal(2), rng.standard_normal(5)
    b = sys_.initial_point(x, R)
    w = R @ v[2:]  # space angular velocity
    contact = np.array([v[0], v[1], 0.0]) + np.cross(w, [0.0, 0.0, -p["r"]])
    table = p["Omega"] * np.array([-x[1], x[0], 0.0])
    np.testing.assert_allclose(_np(sys_.constraint_residual(b, jnp.asarray(v))), (contact - table)[:2], atol=1e-14)


# --------------------------------------------------------------------------------------------
# Chaplygin sphere
# --------------------------------------------------------------------------------------------
SPHERE_ICS = {  # (params, R0 rotation vector, Omega0): a fixed and a turning table, tilted starts
    "fixed": ({}, (0.4, -0.3, 1.1), (1.0, 0.5, 2.0)),
    "turning": ({"Omega": 0.7}, (0.0, 0.9, 0.2), (-0.5, 1.5, 1.0)),
}


def _sphere_start(case):
    over, th, W = SPHERE_ICS[case]
    spec, p, sys_, _, _ = _setup("chaplygin-sphere", **over)
    R0 = np.asarray(SO3().exp(jnp.asarray(th)))
    x0 = np.array([0.3, -0.2])
    xd = _np(chaplygin_sphere.rolling_velocity(p["r"], p["Omega"], jnp.asarray(x0), jnp.asarray(R0), jnp.asarray(W)))
    return spec, p, sys_, x0, np.concatenate([xd, W]), R0


@pytest.fixture(scope="module")
def sphere_references():
    out = {}
    for case in SPHERE_ICS:
        spec, p, sys_, x0, v0, R0 = _sphere_start(case)
        out[case] = (spec, p, reference(sys_, x0, v0, R0, h=H_REF, t_final=T_REF))
    return out


def test_sphere_reference_conserves_energy_and_contact_momentum(sphere_references):
    spec, p, sol = sphere_references["fixed"]
    E = _np(sol.energy)
    assert np.max(np.abs(E - E[0])) <= 1e-10 * abs(E[0])
    for name in ("jacobi", "M_gamma", "M_squared"):
        x = invariant_series(spec, p, sol, name)
        assert np.max(np.abs(x - x[0])) <= 1e-10 * max(1.0, abs(x[0])), name
    # the classical form M = IΩ + m r² γ × (Ω × γ) on a fixed table equals R^T K_A on the constraint
    R, W = _np(sol.R), _np(sol.v)[:, 2:]
    gam = R[:, 2, :]
    M = np.array([p["I1"], p["I2"], p["I3"]]) * W + p["m"] * p["r"] ** 2 * np.cross(gam, np.cross(W, gam))
    Mb = _np(jax.jit(jax.vmap(lambda q, v, R_: chaplygin_sphere.contact_momentum_body(p, q, v, R_)))(sol.q, sol.v, sol.R))
    np.testing.assert_allclose(Mb, M, atol=1e-13)
    assert np.ptp(np.sum(M * gam, axis=1)) <= 1e-10 and np.ptp(np.sum(M * M, axis=1)) <= 1e-10
    assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-10


def test_sphere_reference_on_a_turning_table(sphere_references):
    """The Jacobi integral E − Ω_t L_z and the space vector K_A are conserved; the energy is not."""
    spec, p, sol = sphere_references["turning"]
    E = _np(sol.energy)
    assert np.ptp(E) > 1e-2 * abs(E[0])  # the table does work on the ball
    J = invariant_series(spec, p, sol, "jacobi")
    assert np.max(np.abs(J - J[0])) <= 1e-10 * max(1.0, abs(J[0]))
    K = _np(jax.jit(jax.vmap(lambda q, v, R: chaplygin_sphere.contact_momentum_space(p, q, v, R)))(sol.q, sol.v, sol.R))
    assert np.max(np.abs(K - K[0])) <= 1e-10 * max(1.0, np.max(np.abs(K[0])))


@pytest.fixture(scope="module")
def sphere_long_runs():
    """gni-midpoint on a fixed table, 10⁵ steps at h and h/2 (one compilation)."""
    spec, p, sys_, x0, v0, R0 = _sphere_start("fixed")
    runs = {h: gnipy.simulate(sys_, "gni-midpoint", x0, v0, R0=R0, h=h, steps=LONG_STEPS, save_every=LONG_SAVE)
            for h in (0.1, 0.05)}
    return spec, p, runs


def test_sphere_gni_energy_is_bounded_without_drift(sphere_long_runs):
    runs = sphere_long_runs[2]
    dev = {}
    for h, sol in runs.items():
        E = _np(sol.energy)
        drift, amp, dev[h] = drift_and_amplitude(sol.t, E)
        # a second-order method: |ΔE| ≲ E (h ν)² with ν the fastest rate of the motion
        assert dev[h] <= abs(E[0]) * (h * max_step_rate(sol)) ** 2, (h, dev[h])
        assert drift <= 0.05 * amp, (h, drift, amp)  # no secular drift over t = 10⁴ (h = 0.1)
        # the same oscillation in the first and the last tenth of the run (bounded, no growth)
        d = np.abs(E - E[0])
        n = len(d) // 10
        assert np.max(d[-n:]) <= 1.5 * np.max(d[: 2 * n]) and np.max(d[-n:]) >= 0.5 * np.max(d[: 2 * n])
    assert 3.0 <= dev[0.1] / dev[0.05] <= 5.3  # O(h²)


def test_sphere_gni_keeps_contact_momentum_and_rolling(sphere_long_runs):
    """⟨M, γ⟩ and |M|² are kept to the solver tolerance (no O(h²) oscillation), the rolling constraint
    by the reported velocity to round-off."""
    spec, p, runs = sphere_long_runs
    for h, sol in runs.items():
        for name in ("M_gamma", "M_squared"):
            x = invariant_series(spec, p, sol, name)
            assert np.max(np.abs(x - x[0])) <= LONG_STEPS * NEWTON_TOL * max(1.0, abs(x[0])), (h, name)
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-12
        R = _np(sol.R)
        assert np.max(np.abs(np.einsum("tji,tjk->tik", R, R) - np.eye(3))) <= 1e-10


# --------------------------------------------------------------------------------------------
# Chaplygin top
# --------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_top_reference_conserves_energy_and_jacobi():
    spec, p, sys_, _, _ = _setup("chaplygin-top")
    sol = reference(sys_, *sys_.defaults, h=H_REF, t_final=T_REF)  # the documented tilted start
    np.testing.assert_allclose(_np(sol.R[0]).ravel(), spec.R0, atol=1e-15)
    E = _np(sol.energy)
    assert np.max(np.abs(E - E[0])) <= 1e-10 * max(1.0, abs(E[0]))
    gam3 = _np(sol.R)[:, 2, 2]
    assert np.ptp(gam3) > 0.05  # it rocks: the tilt changes
    # turning table (same compilation): the energy changes, the Jacobi integral does not
    spec, p, sys_, _q0, _v0 = _setup("chaplygin-top", Omega=0.7)
    sol = reference(sys_, *sys_.defaults, h=H_REF, t_final=T_REF)
    J = invariant_series(spec, p, sol, "jacobi")
    assert np.ptp(_np(sol.energy)) > 1e-2 and np.max(np.abs(J - J[0])) <= 1e-10 * max(1.0, abs(J[0]))


@pytest.mark.slow
def test_top_gni_energy_is_bounded():
    spec, p, sys_, q0, v0 = _setup("chaplygin-top")
    dev = {}
    for h in (0.02, 0.01):
        sol = gnipy.simulate(sys_, "gni-trapezoid", h=h, steps=5000, save_every=10)
        E = _np(sol.energy)
        drift, amp, dev[h] = drift_and_amplitude(sol.t, E)
        T0 = 0.5 * _np(v0) @ _np(jax.jit(sys_.metric)(sys_.initial_point(q0, spec.R0))) @ _np(v0)
        scale = T0 + p["m"] * p["g"] * p["a"]  # the kinetic energy and the range of the potential
        nu = max(max_step_rate(sol), np.sqrt(p["g"] / p["r"]))  # fastest rate: spin or rocking
        assert dev[h] <= scale * (h * nu) ** 2, (h, dev[h])
        assert drift <= 0.1 * amp, (h, drift, amp)
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-12
    assert 3.0 <= dev[0.02] / dev[0.01] <= 5.3  # O(h²)


# --------------------------------------------------------------------------------------------
# Suslov
# --------------------------------------------------------------------------------------------
def _suslov_generic():
    """Non-default parameters: a generic body vector a and inertia; Ω0 projected onto a^⊥."""
    over = {"a1": 0.3, "a2": -0.5, "a3": 0.8, "I12": -0.2, "I13": 0.4, "I23": 0.7}
    spec, p, sys_, _q0, _ = _setup("suslov", **over)
    a = np.array([p["a1"], p["a2"], p["a3"]])
    w = np.array([-0.7, 1.1, 0.4])
    return spec, p, sys_, (), w - (a @ w) / (a @ a) * a


def test_suslov_exact_solution_matches_reference():
    for spec, p, sys_, q0, v0 in (_setup("suslov"), _suslov_generic()):
        sol = reference(sys_, q0, v0, h=H_REF, t_final=T_REF)
        _, W = spec.exact(p, q0, v0, _np(sol.t))
        np.testing.assert_allclose(_np(sol.v), W, rtol=0, atol=1e-9)
        E = _np(sol.energy)
        assert np.max(np.abs(E - E[0])) <= 1e-10 * E[0]
        # the motion is not trivial: Ω turns by a finite angle in the plane a^⊥
        assert np.max(np.abs(W - W[0])) > 0.1


def test_suslov_exact_solution_limits():
    """Equilibria (steady rotations about cos ψ = 0) stay put; Ω ∥ ±e_* at t → ±∞."""
    spec, p, _, _, v0 = _setup("suslov")
    Q, I1, I2, b1, b2 = suslov.adapted_frame(p)
    I = suslov.inertia_tensor(p)
    np.testing.assert_allclose(Q.T @ I @ Q, [[I1, 0, b1], [0, I2, b2], [b1, b2, I @ Q[:, 2] @ Q[:, 2]]], atol=1e-14)
    _, W = spec.exact(p, (), v0, np.array([0.0, 1e3]))
    # the limit is an equilibrium: IΩ × Ω has no component in a^⊥
    assert np.max(np.abs((np.cross(I @ W[1], W[1]))[:2])) <= 1e-12
    _, Weq = spec.exact(p, (), W[1], np.array([0.0, 5.0, 50.0]))
    np.testing.assert_allclose(Weq, np.tile(W[1], (3, 1)), atol=1e-12)
    assert 0.5 * W[1] @ I @ W[1] == pytest.approx(0.5 * np.asarray(v0) @ I @ np.asarray(v0), rel=1e-14)


# The GNI with the midpoint l_d; the trapezoid's order 2 on SO(3) is that of the forced Suslov problem
# (tests/test_forcing.py, test_order_two_with_forcing_on_so3[gni-trapezoid]) and of the rolling ball's
# GNI, whose Euler A l_d is the trapezoid there (tests/models/test_rolling_ball.py): its own run here
# took 1.7 s of CPU.
@pytest.mark.parametrize("method", ["gni-midpoint"])
def test_suslov_gni_converges_at_order_two(method):
    spec, p, sys_, q0, v0 = _setup("suslov")
    errs = []
    for h in CONV_HS:  # same number of steps: one compilation; errors on the common window t <= 4
        sol = gnipy.simulate(sys_, method, q0, v0, h=h, steps=CONV_STEPS)
        t = _np(sol.t)
        keep = t <= CONV_T + 1e-9
        _, W = spec.exact(p, q0, v0, t[keep])
        errs.append(np.max(np.abs(_np(sol.v)[keep] - W)))
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-14
    assert 1.9 <= fitted_order(CONV_HS, errs) <= 2.1, errs


def test_suslov_gni_long_run_energy():
    """The GNI keeps the energy to O(h²) while Ω relaxes to the steady rotation, but not after.

    Every Suslov motion relaxes (at rate A, see the model) to a steady rotation. Near it the GNI's
    reported energy does not stay at E₀: a period-2 ("zig-zag") mode of the reflection grows, the
    steps σ_k leave a^⊥ with alternating sign, and the reported Ω̄ = (p⁻ + p⁺)/2 collapses to ~0 and
    recovers, again and again (the same happens for the Chaplygin sleigh, in R^3 and on SE(2), and
    for the paper's explicit RATTLE; DLA keeps the energy). Asserted here: the O(h²) energy error
    before the relaxation (t ≤ 5, where the exact Ω is still turning), the upper bound E ≤ E₀ + O(h²)
    over 10⁵ steps, and the collapse itself, so that a change of this behaviour is noticed.
    """
    _spec, _p, sys_, q0, v0 = _setup("suslov")
    h = 0.05
    sol = gnipy.simulate(sys_, "gni-midpoint", q0, v0, h=h, steps=LONG_STEPS, save_every=LONG_SAVE)
    E = _np(sol.energy)
    nu = max_step_rate(sol)
    assert np.max(E) - E[0] <= E[0] * (h * nu) ** 2  # never above the level by more than O(h²)
    assert np.min(E) <= 1e-2 * E[0]  # the zig-zag collapse (see the docstring)
    # before the relaxation: the energy error is O(h²) (the convergence runs, shared compilation)
    dev = {}
    for hh in (0.05, 0.025):
        s = gnipy.simulate(sys_, "gni-midpoint", q0, v0, h=hh, steps=CONV_STEPS)
        keep = _np(s.t) <= 5.0 + 1e-9
        e = _np(s.energy)[keep]
        dev[hh] = np.max(np.abs(e - e[0]))
    assert dev[0.05] <= E[0] * (0.05 * nu) ** 2 and 3.0 <= dev[0.05] / dev[0.025] <= 5.3


# --------------------------------------------------------------------------------------------
# Veselova
# --------------------------------------------------------------------------------------------
VESELOVA_TILTED = ((0.7, -0.4, 0.3), (0.8, -1.3, 0.5))  # R0 rotation vector, Ω before projection


def _veselova_tilted():
    spec, p, sys_, _, _ = _setup("veselova")
    R0 = np.asarray(SO3().exp(jnp.asarray(VESELOVA_TILTED[0])))
    g = R0[2]
    w = np.asarray(VESELOVA_TILTED[1])
    return spec, p, sys_, w - (g @ w) * g, R0


def test_veselova_reference_conserves_energy_and_F():
    spec, p, sys_, _q0, v0 = _setup("veselova")
    _, _, _, v1, R1 = _veselova_tilted()
    for v, R0 in ((v0, None), (v1, R1)):
        sol = gnipy.simulate(sys_, "reference", (), v, R0=R0, h=H_REF, t_final=T_REF)
        for name in ("energy", "F"):
            x = invariant_series(spec, p, sol, name)
            assert np.max(np.abs(x - x[0])) <= 1e-10 * max(1.0, abs(x[0])), name
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-10
        # |M|² and ⟨M, γ⟩² change (by the same amount): F is not conserved trivially
        M = np.array([p["I1"], p["I2"], p["I3"]]) * _np(sol.v)
        assert np.ptp(np.sum(M * M, axis=1)) > 1e-2


def test_veselova_gni_keeps_energy_bounded_and_F():
    spec, p, sys_, v0, R0 = _veselova_tilted()
    dev = {}
    for h in (0.1, 0.05):
        sol = gnipy.simulate(sys_, "gni-midpoint", (), v0, R0=R0, h=h, steps=LONG_STEPS, save_every=LONG_SAVE)
        E = invariant_series(spec, p, sol, "energy")
        drift, amp, dev[h] = drift_and_amplitude(sol.t, E)
        assert dev[h] <= E[0] * (h * max_step_rate(sol)) ** 2, (h, dev[h])
        assert drift <= 0.05 * amp, (h, drift, amp)
        F = invariant_series(spec, p, sol, "F")
        # F is kept to round-off: a bound of steps × eps × scale
        assert np.max(np.abs(F - F[0])) <= LONG_STEPS * EPS * F[0], h
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-13
    assert 3.0 <= dev[0.1] / dev[0.05] <= 5.3  # O(h²)


# --------------------------------------------------------------------------------------------
# The sleigh on SE(2)
# --------------------------------------------------------------------------------------------
SLEIGH_H, SLEIGH_T = 0.0625, 4.0  # as tests/models/test_models.py: the R^3 reference compiles once


def _se2(theta, p_contact):
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, p_contact[0]], [s, c, p_contact[1]], [0.0, 0.0, 1.0]])


def test_sleigh_se2_exact_body_velocities_match_reference():
    spec, p, sys_, q0, v0 = _setup("chaplygin-sleigh-se2")
    sol = gnipy.simulate(sys_, "reference", h=SLEIGH_H, t_final=SLEIGH_T)
    _, v = spec.exact(p, q0, v0, _np(sol.t))
    np.testing.assert_allclose(_np(sol.v), v, rtol=0, atol=1e-9)
    R = _np(sol.R)
    theta = np.unwrap(np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    np.testing.assert_allclose(theta, chaplygin_sleigh.exact_heading(p, (0, 0, 0), (v0[0], p["a"] * v0[2], v0[2]),
                                                                     _np(sol.t)), atol=1e-9)
    assert np.max(np.abs(_np(sol.energy) - _np(sol.energy)[0])) <= 1e-12


@pytest.mark.parametrize("start", ["default", "turned"])
def test_sleigh_se2_and_r3_models_agree(start):
    """Two independent formulations of one sleigh: same body velocities, heading and centre of mass."""
    _se2_spec, p, se2, _, _ = _setup("chaplygin-sleigh-se2")
    r3 = gnipy.make_system("chaplygin-sleigh")
    a = p["a"]
    th0, com0, u0, w0 = (0.0, (0.0, 0.0), 1.0, 1.0) if start == "default" else (0.7, (0.3, -0.2), 0.8, -1.2)
    c, s = np.cos(th0), np.sin(th0)
    q0_r3 = (*com0, th0)
    v0_r3 = (u0 * c - a * w0 * s, u0 * s + a * w0 * c, w0)  # (ẋ, ẏ) = R(θ)(u, aω)
    g0 = _se2(th0, (com0[0] - a * c, com0[1] - a * s))  # contact point a behind the centre of mass
    s_r3 = gnipy.simulate(r3, "reference", q0_r3, v0_r3, h=SLEIGH_H, t_final=SLEIGH_T)
    s_se2 = gnipy.simulate(se2, "reference", (), (u0, 0.0, w0), R0=g0, h=SLEIGH_H, t_final=SLEIGH_T)
    u, w = chaplygin_sleigh.body_velocities(s_r3.q, s_r3.v)
    np.testing.assert_allclose(_np(s_se2.v), np.stack([u, 0 * u, w], axis=-1), rtol=0, atol=1e-9)
    g = _np(s_se2.R)
    theta = np.unwrap(np.arctan2(g[:, 1, 0], g[:, 0, 0]))
    com = g[:, :2, 2] + a * g[:, :2, 0]  # p + a R(θ) e₁
    np.testing.assert_allclose(theta, _np(s_r3.q)[:, 2], atol=1e-9)
    np.testing.assert_allclose(com, _np(s_r3.q)[:, :2], atol=1e-9)
    if start == "default":  # the R^3 model's documented start is this one
        assert (q0_r3, v0_r3) == (tuple(gnipy.get_model("chaplygin-sleigh").q0), gnipy.get_model("chaplygin-sleigh").v0)


def test_sleigh_se2_gni_converges_at_order_two():
    spec, p, sys_, q0, v0 = _setup("chaplygin-sleigh-se2")
    errs = []
    for h in CONV_HS:
        sol = gnipy.simulate(sys_, "gni-midpoint", h=h, steps=CONV_STEPS)
        t = _np(sol.t)
        keep = t <= CONV_T + 1e-9
        _, v = spec.exact(p, q0, v0, t[keep])
        errs.append(np.max(np.abs(_np(sol.v)[keep] - v)))
        assert np.max(np.abs(_np(sol.constraint_residual))) <= 1e-14
    assert 1.9 <= fitted_order(CONV_HS, errs) <= 2.1, errs
