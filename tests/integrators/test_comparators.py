"""The comparators: discrete Lagrange–d'Alembert (DLA) and McLachlan–Perlmutter (4.18).

Numbers come from hand-derived closed forms of the schemes on the nonholonomic particle, exact
solutions, the schemes' own defining equations recomputed from the saved output, reversibility,
invariants, and error bounds derived in the comments.

Runs that differ only in numbers share a compiled program (h, parameter values, initial conditions,
node counts in one bucket, gnipy.preparation.node_bucket): the DLA runs on the particle take 60 steps,
every node saved, as the closed form with k = 0 does, and the reversibility runs of mp save every
node, as its closed form on the particle does. Measured on the 2-core machine (noisy, shared):
29 s before, 15 s after (the machine less loaded than before: noisy).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import EulerA, Midpoint, System, Trapezoid
from gnipy.integrators.base import MethodError
from gnipy.integrators.comparators import DiscreteLagrangeDAlembert, McLachlanPerlmutter

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False


# ---------------------------------------------------------------------------------------------
# Systems
# ---------------------------------------------------------------------------------------------
def _particle_mu(q):
    return jnp.stack([-q[1], jnp.zeros_like(q[1]), jnp.ones_like(q[1])])[None, :]


def varmetric_affine_system(c=0.5):
    """l = ½((1 + ½z²)ẋ² + ẏ² + (1 + 0.3x²)ż²) − ½(x² + y²), constraint ż = yẋ + c."""

    def lagrangian(q, v):
        x, y, z = q
        return 0.5 * ((1 + 0.5 * z**2) * v[0] ** 2 + v[1] ** 2 + (1 + 0.3 * x**2) * v[2] ** 2) - 0.5 * (x**2 + y**2)

    return System(lagrangian, _particle_mu, lambda q: jnp.array([0.0, 0.0, c]) + 0.0 * q, n=3, name="varmetric")


VM_Q0 = np.array([0.4, 0.8, -0.2])
VM_V0 = np.array([0.7, -0.5, 0.8 * 0.7 + 0.5])


@pytest.fixture(scope="module")
def particle():
    return gnipy.make_system("nonholonomic-particle")


@pytest.fixture(scope="module")
def varmetric():
    return varmetric_affine_system()


def discrete_constraint(system, q, h):
    """μ(q_{k+½})((q_{k+1} − q_k)/h − Y(q_{k+½})) for consecutive saved nodes (save_every = 1)."""
    q = jnp.asarray(q)
    mid = 0.5 * (q[1:] + q[:-1])
    vel = (q[1:] - q[:-1]) / h
    return np.asarray(jax.vmap(lambda m, w: system.mu(m) @ (w - system.Y(m)))(mid, vel))


# ---------------------------------------------------------------------------------------------
# Registry and applicability
# ---------------------------------------------------------------------------------------------
def test_method_names_give_the_comparators():
    dla, mp = gnipy.get_method("dla"), gnipy.get_method("mp")
    assert isinstance(dla, DiscreteLagrangeDAlembert) and isinstance(dla.discrete_lagrangian, Midpoint)
    assert isinstance(mp, McLachlanPerlmutter)
    assert (dla.name, dla.order, mp.name, mp.order) == ("dla", 2, "mp", 2)
    assert DiscreteLagrangeDAlembert(EulerA()).order == 1


def test_mp_refuses_a_position_dependent_metric(varmetric):
    with pytest.raises(MethodError, match="constant metric"):
        gnipy.simulate(varmetric, "mp", VM_Q0, VM_V0, h=0.1, steps=2)
    McLachlanPerlmutter().check(gnipy.make_system("nonholonomic-particle"), np.ones(3))  # no raise


# ---------------------------------------------------------------------------------------------
# DLA
# ---------------------------------------------------------------------------------------------
H_DLA = 0.05
N_DLA = 60  # the step count of test_dla_free_particle_closed_form: one compiled program


@pytest.fixture(scope="module")
def dla_particle(particle):
    return gnipy.simulate(particle, "dla", h=H_DLA, steps=N_DLA)


def test_dla_discrete_constraint_particle(particle, dla_particle):
    r = discrete_constraint(particle, dla_particle.q, H_DLA)
    assert r.shape == (N_DLA, 1)
    assert np.max(np.abs(r)) <= 1e-12


@pytest.mark.parametrize("ld", [Midpoint(), Trapezoid()], ids=["midpoint", "trapezoid"])
def test_dla_discrete_constraint_varmetric_affine(varmetric, ld):
    sol = gnipy.simulate(varmetric, DiscreteLagrangeDAlembert(ld), VM_Q0, VM_V0, h=H_DLA, steps=N_DLA)
    r = discrete_constraint(varmetric, sol.q, H_DLA)
    assert np.max(np.abs(r)) <= 1e-12
    # the continuous constraint is not what DLA enforces: its residual is visibly nonzero
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) > 1e-4


def test_dla_equations_recomputed_by_hand(particle, dla_particle):
    """Midpoint l_d = h(½|Δ|² − V(q_mid)) with V = ½(x² + y²) (k = 1):
    FL⁻ = Δ + (h/2)V_q(q_mid), FL⁺ = Δ − (h/2)V_q(q_mid). Check p⁺_{k+1} = FL⁺ and that
    p⁺_k − FL⁻ (= μ(q_k)ᵀλ_k) is parallel to μ(q_k)ᵀ = (−y_k, 0, 1)."""
    q, p, h = np.asarray(dla_particle.q), np.asarray(dla_particle.p), H_DLA
    delta = (q[1:] - q[:-1]) / h
    mid = 0.5 * (q[1:] + q[:-1])
    Vq = mid * np.array([1.0, 1.0, 0.0])
    np.testing.assert_allclose(p[1:], delta - 0.5 * h * Vq, rtol=0, atol=1e-12)
    force = p[:-1] - (delta + 0.5 * h * Vq)
    mu = np.stack([-q[:-1, 1], np.zeros(N_DLA), np.ones(N_DLA)], axis=1)
    lam = np.sum(force * mu, axis=1) / np.sum(mu * mu, axis=1)
    np.testing.assert_allclose(force, lam[:, None] * mu, rtol=0, atol=1e-12)
    assert np.max(np.abs(lam)) > 1e-3  # the constraint force is active
    np.testing.assert_allclose(np.asarray(dla_particle.v), p, rtol=0, atol=0)  # M = I: v = p⁺


def test_dla_free_particle_closed_form():
    """V = 0 (k = 0), M = I, midpoint l_d. Then FL∓ = Δ_k and the DLA step is, with a_k = Δx_k,
        a_k = a_{k-1} + y_k λ,   y_{k+½} a_k = Δz_{k-1} − λ,   Δy_k = Δy_{k-1},
    so y is exactly linear, y_k = y_0 + k h ẏ_0 (the exact solution), and eliminating λ:
        a_k (1 + y_k y_{k+½}) = a_{k-1} (1 + y_k y_{k-½}),   Δz_k = y_{k+½} a_k,
    with a_{-1} = ẋ_0 and y_{-½} := y_0 at k = 0 (p⁺_0 = v_0 satisfies ż_0 = y_0 ẋ_0)."""
    system = gnipy.make_system("nonholonomic-particle", k=0.0)
    q0, v0 = np.array([0.3, -0.7, 0.2]), np.array([1.1, 0.9, -0.7 * 1.1])
    h, n = 0.1, 60
    sol = gnipy.simulate(system, "dla", q0, v0, h=h, steps=n)
    k = np.arange(n + 1)
    y = q0[1] + k * h * v0[1]
    q = np.zeros((n + 1, 3))
    q[0] = q0
    a_prev, y_prev_half = v0[0], q0[1]
    for i in range(n):
        y_half = y[i] + 0.5 * h * v0[1]
        a = a_prev * (1 + y[i] * y_prev_half) / (1 + y[i] * y_half)
        q[i + 1] = q[i] + h * np.array([a, v0[1], y_half * a])
        a_prev, y_prev_half = a, y_half
    np.testing.assert_allclose(np.asarray(sol.q[:, 1]), y, rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(sol.q), q, rtol=0, atol=1e-12)


def test_dla_reported_velocity_is_first_order_off_the_constraint(particle):
    """v = G⁻¹p⁺_k = Δ_{k-1} − (h/2)V_q: μ(q_k)v = μ(q_k)Δ_{k-1} + O(h) with μ(q_{k-½})Δ_{k-1} = 0,
    so the continuous-constraint residual is O(h) (not O(h²), not round-off): halving h halves it."""
    r1 = gnipy.simulate(particle, "dla", h=0.1, steps=40, save_every=4).constraint_residual
    r2 = gnipy.simulate(particle, "dla", h=0.05, steps=80, save_every=8).constraint_residual
    m1, m2 = np.max(np.abs(np.asarray(r1))), np.max(np.abs(np.asarray(r2)))
    assert m1 > 1e-3
    assert 1.8 <= m1 / m2 <= 2.2


def test_dla_second_order_with_position_dependent_metric(varmetric):
    """Errors of x and z (the coordinates that feel the metric and the affine constraint) against
    the reference at t = 0.25, 0.5, 0.75, 1: fitted order 2 ± 0.15."""
    T = 1.0
    ref = gnipy.ContinuousReference().solve(varmetric, VM_Q0, VM_V0, np.linspace(0.0, T, 5))
    hs, errs = [], []
    for n in (16, 32, 64):
        sol = gnipy.simulate(varmetric, "dla", VM_Q0, VM_V0, h=T / n, steps=n, save_every=n // 4)
        hs.append(T / n)
        errs.append(np.max(np.abs(np.asarray(sol.q)[:, [0, 2]] - np.asarray(ref.q)[:, [0, 2]])))
    order = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert abs(order - 2.0) <= 0.15, (order, errs)


def test_dla_keeping_its_jacobian_is_the_same_map(varmetric):
    """DLA keeping its Jacobian from step to step (`reuse_jacobian`; by default above 12 unknowns,
    here asked for on 4) solves the same equations to the same round-off test as with a fresh
    Jacobian and the velocity's guess at each step, so the runs agree to round-off over 400 steps
    (a position-dependent metric, an affine constraint, h = 0.05); the kept solver, the last
    solution and their step sizes travel in the state, and the discrete map's eigenvalues
    (gnipy.analysis.discrete_linearization, which differentiates the step with respect to the
    state) are those of the map without them."""
    from gnipy.linalg import UNROLL_MAX

    kept = gnipy.simulate(varmetric, DiscreteLagrangeDAlembert(reuse_jacobian=True), VM_Q0, VM_V0, h=0.05, steps=400,
                          save_every=100)
    fresh = gnipy.simulate(varmetric, DiscreteLagrangeDAlembert(reuse_jacobian=False), VM_Q0, VM_V0, h=0.05,
                           steps=400, save_every=100)
    assert kept.healthy and fresh.healthy
    np.testing.assert_allclose(np.asarray(kept.q), np.asarray(fresh.q), rtol=0, atol=1e-13)
    np.testing.assert_allclose(np.asarray(kept.p), np.asarray(fresh.p), rtol=0, atol=1e-13)
    # fewer evaluations in all (the Jacobian, counted as one, formed at some steps only)
    assert int(kept.iterations[0]) != int(fresh.iterations[0])
    (inverse,), h_solver, w, h_w = kept.final_state.jacobian
    assert inverse.shape == (4, 4) and 3 + 1 <= UNROLL_MAX and float(h_solver) in (0.0, 0.05) and float(h_w) == 0.05
    assert DiscreteLagrangeDAlembert(reuse_jacobian=False).init(varmetric, VM_Q0, VM_V0, 0.05).jacobian is None
    assert DiscreteLagrangeDAlembert().init(varmetric, VM_Q0, VM_V0, 0.05).jacobian is None  # 4 unknowns
    assert DiscreteLagrangeDAlembert().memoryless().reuse_jacobian is False
    # a batch runs without the kept Jacobian (Integrator.memoryless); a member's final state, which
    # has none, continues a run of the method that keeps it (continue_from), as one run does
    method = DiscreteLagrangeDAlembert(reuse_jacobian=True)
    q2 = np.stack([VM_Q0, VM_Q0])
    v2 = np.stack([VM_V0, VM_V0])
    batch = gnipy.simulate(varmetric, method, q2, v2, h=0.05, steps=200, save_every=200)
    member = jax.tree_util.tree_map(lambda a: a[0], batch.final_state)
    assert member.jacobian is None
    rest = gnipy.simulate(varmetric, method, h=0.05, steps=200, save_every=200, state0=member, t0=10.0)
    np.testing.assert_allclose(np.asarray(rest.q[-1]), np.asarray(kept.q[-1]), rtol=0, atol=1e-13)
    # the map of the state alone, without the kept solver: on the Chaplygin sleigh sliding straight
    # (a steady motion), dla's multipliers with and without it are the same, at most 9 of them
    # (q, p and the compensated-summation error x_err, 3 each; the solver adds 17 entries)
    sleigh = gnipy.make_system("chaplygin-sleigh").with_args(m=1.0, I=1.0, a=0.5)
    q, v = np.zeros(3), np.array([1.0, 0.0, 0.0])
    lin = gnipy.analysis.discrete_linearization(sleigh, "dla", q, v, 0.1)
    plain = gnipy.analysis.discrete_linearization(sleigh, DiscreteLagrangeDAlembert(reuse_jacobian=False), q, v, 0.1)
    np.testing.assert_allclose(np.sort_complex(lin.multipliers), np.sort_complex(plain.multipliers), rtol=1e-12)
    assert len(lin.multipliers) <= 9


# ---------------------------------------------------------------------------------------------
# McLachlan–Perlmutter (4.18)
# ---------------------------------------------------------------------------------------------
def test_mp_closed_form_on_the_particle(particle):
    """On the nonholonomic particle (M = I, V = ½k(x² + y²), μ = (−y, 0, 1)) the MP step solves in
    closed form: v_1y = v_y − hk y½ does not involve λ, so y_1 = y½ + (h/2)v_1y is known, and
    −y_1 v_1x + v_1z = 0 with v_1x = v_x − hk x½ − hλ y½, v_1z = v_z + hλ gives
        hλ (1 + y_1 y½) = y_1 (v_x − hk x½) − v_z."""
    k, h, n = 1.0, 0.08, 50
    q0, v0 = np.asarray(particle.defaults[0]), np.asarray(particle.defaults[1])
    sol = gnipy.simulate(particle, "mp", h=h, steps=n)
    qs, vs = [q0], [v0]
    q, v = q0.copy(), v0.copy()
    for _ in range(n):
        qh = q + 0.5 * h * v
        vy1 = v[1] - h * k * qh[1]
        y1 = qh[1] + 0.5 * h * vy1
        hlam = (y1 * (v[0] - h * k * qh[0]) - v[2]) / (1 + y1 * qh[1])
        v = np.array([v[0] - h * k * qh[0] - hlam * qh[1], vy1, v[2] + hlam])
        q = qh + 0.5 * h * v
        qs.append(q)
        vs.append(v)
    np.testing.assert_allclose(np.asarray(sol.q), np.array(qs), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.v), np.array(vs), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.p), np.array(vs), rtol=0, atol=1e-12)  # p = Mv, M = I


@pytest.mark.parametrize("model", ["nonholonomic-particle", "contact-oscillator"])
def test_mp_reversible(model):
    """For linear constraints (4.18) maps (q_1, −v_1) back to (q_0, −v_0) with the same λ, so N
    steps forward, a velocity flip and N steps forward return to the start (up to round-off)."""
    system = gnipy.make_system(model)
    h, n = 0.1, 50
    # every node saved, as test_mp_closed_form_on_the_particle's 50 steps: one compiled program
    fwd = gnipy.simulate(system, "mp", h=h, steps=n)
    back = gnipy.simulate(system, "mp", fwd.q[-1], -fwd.v[-1], h=h, steps=n)
    assert np.max(np.abs(np.asarray(fwd.q[-1] - fwd.q[0]))) > 0.1  # it did move
    np.testing.assert_allclose(np.asarray(back.q[-1]), np.asarray(fwd.q[0]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(back.v[-1]), -np.asarray(fwd.v[0]), rtol=0, atol=1e-12)


def test_mp_constraints_exact_linear_and_affine():
    """(4.18) imposes μ(q_1)(v_1 − Y(q_1)) = 0 at every node."""
    co = gnipy.make_system("contact-oscillator")
    sol = gnipy.simulate(co, "mp", h=0.1, steps=100)
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-12
    affine = System(
        lambda q, v: 0.5 * v @ v - 0.5 * (q[0] ** 2 + q[1] ** 2),
        _particle_mu,
        lambda q: jnp.array([0.0, 0.0, 0.5]) + 0.0 * q,
        n=3,
    )
    sol = gnipy.simulate(affine, "mp", np.array([1.0, 1.0, 0.0]), np.array([1.0, 0.0, 1.5]), h=0.1, steps=100)
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-12
    assert abs(float(sol.energy[-1] - sol.energy[0])) > 1e-3  # the affine constraint does work


# ---------------------------------------------------------------------------------------------
# The contact oscillator over 10⁵ steps (McLachlan–Perlmutter's test problem)
# ---------------------------------------------------------------------------------------------
CO_H = 2.0 * np.sin(np.pi / 40)  # Störmer–Verlet on ÿ = −y turns by exactly π/20 per step
CO_STEPS = 100_000
CO_SAVE = 10


@pytest.fixture(scope="module")
def contact():
    spec = gnipy.get_model("contact-oscillator")
    params = spec.resolve_params()
    assert params["epsilon"] == 0.3
    return spec, params, spec.system()


@pytest.mark.parametrize("method", ["gni-trapezoid", "mp", "gni-midpoint", "dla"])
def test_contact_oscillator_long_time(contact, method, capsys):
    """No drift and an O(h²) bound over 10⁵ steps for second-order symmetric methods.

    Bounds from theory:
    - H and H − H_y: a symmetric second-order method on this reversible, integrable system keeps
      |H − H_0| = O(h²) uniformly in time (McLachlan–Perlmutter observe this for reversible methods).
      The constant is that of the harmonic parts (frequency 1) up to a factor: Störmer–Verlet has
      relative energy error h²ω²/4 on a harmonic oscillator; we allow max|H − H_0| ≤ h² H_0 (four
      times that, for the constraint coupling and the ε x²z² term). A secular drift would show in the
      least-squares slope: its change over the run must stay below 5% of the oscillation range, and
      the deviation in the second half must not exceed that in the first by more than 10%.
    - H_y: y is a free harmonic oscillator (the constraint force (1, 0, y)λ has no y-component, and
      the GNI's Q* and DLA's μᵀλ have none either). The GNI trapezoid is velocity Verlet in y, MP is
      position Verlet; each conserves a quadratic form within (h²/4)/(1 − h²/4) of H_y, so
      |H_y − H_y(0)| ≤ (h²/4) H_y(0)/(1 − h²/4). The GNI midpoint and DLA are the implicit midpoint
      rule in (y, p_y), which conserves ½(y² + p_y²) exactly: round-off only.
    """
    spec, params, system = contact
    sol = gnipy.simulate(system, method, h=CO_H, steps=CO_STEPS, save_every=CO_SAVE)
    t = np.asarray(sol.t)
    assert t.shape == (CO_STEPS // CO_SAVE + 1,) and sol.result == 0
    H = np.asarray(jax.vmap(lambda q, v: spec.invariants["H"](params, q, v))(sol.q, sol.v))
    Hy = np.asarray(jax.vmap(lambda q, v: spec.invariants["H_y"](params, q, v))(sol.q, sol.v))
    h2 = CO_H**2
    report = []
    for name, f in (("H", H), ("H-H_y", H - Hy)):
        d = f - f[0]
        drift = np.polyfit(t, d, 1)[0] * (t[-1] - t[0])
        half = len(d) // 2
        report.append(f"{name}: max|dev| {np.max(np.abs(d)):.3e} range {np.ptp(d):.3e} drift {drift:.2e}")
        assert np.max(np.abs(d)) <= h2 * H[0], (name, np.max(np.abs(d)))
        assert abs(drift) <= 0.05 * np.ptp(d), (name, drift, np.ptp(d))
        assert np.max(np.abs(d[half:])) <= 1.1 * np.max(np.abs(d[:half])), name
    dy = np.max(np.abs(Hy - Hy[0]))
    report.append(f"H_y: max|dev| {dy:.3e}")
    if method in ("gni-trapezoid", "mp"):
        assert dy <= 0.25 * h2 * Hy[0] / (1 - 0.25 * h2)
    else:
        assert dy <= 1e-10
    with capsys.disabled():
        print(f"\n  contact oscillator, {method}: " + "; ".join(report))
