"""The rolling ball of paper §7.4 on R² × SO(3) (model `rolling-ball`).

Every number here comes from the paper's explicit equations, the exact circular motion of the
homogeneous ball, the conserved Jacobi integral, the continuous reference or the constraints. Compile
time dominates: runs share one compilation wherever the number of steps (the only static size) and
the system agree; h is traced, so e.g. (h = 0.1, 200 steps) and (h = 0.0125, 200 steps) share one.
The rolling ball's four references (examples 1 and 2, the equal-moment ball on a turning and a
fixed table) are saved at 201 nodes and run without the System's provenance fields
(:func:`reference`): one compiled program. Measured on the shared 2-core machine (`pytest -n 0
--durations=0` on this file alone, other jobs running, so noisy to a few seconds): 43.9 s → 36.4 s.
"""

from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import gnipy
from gnipy.analysis import ROUND_OFF
from gnipy.analysis import fitted_order as analysis_order
from gnipy.cli import app
from gnipy.lie_groups import SO3
from gnipy.models import rolling_ball as rb
from gnipy.retractions import Cayley
from gnipy.spaces import Point

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

T_CONV = 2.5
HS = [0.1, 0.05, 0.025, 0.0125]  # compared on t ≤ T_CONV: 25, 50, 100, 200 steps
N_CONV = round(T_CONV / HS[-1])  # every convergence run takes 200 steps: one compiled program
#: The paper's GNI of §7.4: Euler A l_d, started from rest (p⁺₀ = p̄₀), as its five equations assume.
PAPER_GNI = gnipy.GNI(gnipy.EulerA(), start="rest")
H_EQ, N_EQ = 0.1, 200  # the five equations: 200 steps of h = 0.1 (shares the 200-step compile)


def _np(x):
    return np.asarray(x, dtype=np.float64)


def reference(s, q0, v0, **kw):
    """The continuous reference of `s` from (q0, v0), run on `s.without_metadata()`: the reference's
    compiled program is keyed by the whole System, the parameter values of its provenance field
    `params` included, so each example and table below compiled its own (about 2 s of CPU each);
    without the provenance fields the rolling ball's references with 201 saved nodes share one."""
    return gnipy.simulate(s.without_metadata(), "reference", q0, v0, **kw)


def fitted_order(hs, errors):
    """Least-squares slope of log(error) against log(h)."""
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


def ex1():
    s = gnipy.make_system("rolling-ball")
    q0, v0 = gnipy.get_model("rolling-ball").initial_condition(s.parameters)
    return s, q0, v0


# --------------------------------------------------------------------------------------------
# Independent numpy formulas: the Cayley map (Appendix) and the five equations of §7.4
# --------------------------------------------------------------------------------------------
def hat(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def cay_inv(Q):
    """σ with cay(σ) = Q: σ̂ = 2(Q − I)(Q + I)⁻¹."""
    S = 2.0 * (Q - np.eye(3)) @ np.linalg.inv(Q + np.eye(3))
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2.0


def step_angular_velocities(R, h):
    """ω_k = σ_k/h with σ_k = cay⁻¹(R_{k+1}R_kᵀ) (the model's reconstruction R_{k+1} = cay(σ_k)R_k:
    ω is the space angular velocity)."""
    return np.array([cay_inv(R[k + 1] @ R[k].T) for k in range(len(R) - 1)]) / h


def five_equations(p, x, y, w, h, *, order2=True, order1=True):
    """The five explicit equations of §7.4 at the nodes k = 1 .. K-1 (rows), with their O(h) and
    O(h²) terms, as printed (eqs 4 and 5 carry +Ωy_k and −Ωx_k: the correct sign of Π)."""
    m, r, I1, I2, I3, W = (p[k] for k in ("m", "r", "I1", "I2", "I3", "Omega"))
    I = np.array([I1, I2, I3])
    a, b = w[1:], w[:-1]  # ω^k, ω^{k-1}
    na, nb = (I * a**2).sum(1), (I * b**2).sum(1)  # ||ω||²_I
    x1, x0, xm = x[2:], x[1:-1], x[:-2]
    y1, y0, ym = y[2:], y[1:-1], y[:-2]
    c1, c2 = float(order1), float(order2)
    e1 = (m * r * (x1 - 2 * x0 + xm) / h + I2 * (a[:, 1] - b[:, 1])
          + c1 * h / 2 * (I1 - I3) * (a[:, 0] * a[:, 2] + b[:, 0] * b[:, 2])
          + c2 * h**2 / 4 * (a[:, 1] * na - b[:, 1] * nb))
    e2 = (m * r * (y1 - 2 * y0 + ym) / h - I1 * (a[:, 0] - b[:, 0])
          - c1 * h / 2 * (I3 - I2) * (a[:, 1] * a[:, 2] + b[:, 1] * b[:, 2])
          - c2 * h**2 / 4 * (a[:, 0] * na - b[:, 0] * nb))
    e3 = (I3 * (a[:, 2] - b[:, 2]) + c1 * h / 2 * (I2 - I1) * (a[:, 0] * a[:, 1] + b[:, 0] * b[:, 1])
          + c2 * h**2 / 4 * (a[:, 2] * na - b[:, 2] * nb))
    e4 = ((x1 - xm) / (2 * h) + W * y0 - r * (a[:, 1] + b[:, 1]) / 2
          - c1 * r * h / 4 * (I1 - I3) / I2 * (a[:, 0] * a[:, 2] - b[:, 0] * b[:, 2])
          - c2 * h**2 / (8 * I2) * r * (a[:, 1] * na + b[:, 1] * nb))
    e5 = ((y1 - ym) / (2 * h) - W * x0 + r * (a[:, 0] + b[:, 0]) / 2
          + c1 * r * h / 4 * (I3 - I2) / I1 * (a[:, 1] * a[:, 2] - b[:, 1] * b[:, 2])
          + c2 * h**2 / (8 * I1) * r * (a[:, 0] * na + b[:, 0] * nb))
    return np.stack([e1, e2, e3, e4, e5], axis=1)


def relative_residuals(p, sol, h, **kw):
    """Max |residual| of each equation: eqs 1–3 relative to the momentum scale max|p̄|, eqs 4–5
    relative to the velocity scale max|v̄|."""
    x, R = _np(sol.q), _np(sol.R)
    w = step_angular_velocities(R, h)
    res = np.max(np.abs(five_equations(p, x[:, 0], x[:, 1], w, h, **kw)), axis=0)
    return res / np.array([np.max(np.abs(_np(sol.p)))] * 3 + [np.max(np.abs(_np(sol.v)))] * 2)


# --------------------------------------------------------------------------------------------
# Shared runs
# --------------------------------------------------------------------------------------------
def _convergence_runs(s, q0, v0):
    """gni-euler-a at every h of HS, on t ≤ T_CONV (host arrays). Every run takes N_CONV steps (h and
    the steps are traced, the saved-node count is static), so the four share one compiled program;
    the first round(T_CONV/h) steps of a longer run are the shorter run's, and the rest is dropped."""
    runs = {}
    for h in HS:
        sol = gnipy.simulate(s, "gni-euler-a", q0, v0, h=h, steps=N_CONV)
        n = round(T_CONV / h) + 1
        runs[h] = SimpleNamespace(**{k: _np(getattr(sol, k))[:n] for k in
                                     ("t", "q", "v", "R", "p", "energy", "constraint_residual")})
        assert runs[h].t[-1] == pytest.approx(T_CONV, abs=1e-12)
    return runs


@pytest.fixture(scope="module")
def ex1_runs():
    """GNI (Euler A, the paper's l_d) on example 1 for the h of HS up to T_CONV, plus the 200-step run."""
    s, q0, v0 = ex1()
    runs = _convergence_runs(s, q0, v0)
    runs["eq"] = gnipy.simulate(s, PAPER_GNI, q0, v0, h=H_EQ, steps=N_EQ)
    return runs


@pytest.fixture(scope="module")
def ex2_runs():
    s, q0, v0 = rb.example_2()
    runs = _convergence_runs(s, q0, v0)
    runs["eq"] = gnipy.simulate(s, PAPER_GNI, q0, v0, h=H_EQ, steps=N_EQ)
    runs["ref"] = reference(s, q0, v0, h=HS[-1], t_final=T_CONV)
    return runs


# --------------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------------
def test_registered_with_documented_defaults():
    assert "rolling-ball" in gnipy.model_names()
    spec = gnipy.get_model("rolling-ball")
    assert dict(spec.params) == pytest.approx({"m": 1, "r": 1, "I1": 2 / 3, "I2": 2 / 3, "I3": 2 / 3, "Omega": 1})
    assert spec.initial_condition(spec.params) == ((1.0, 1.0), (1.0, 1.0, 0.0, 2.0, 0.0))
    assert (spec.q0, spec.v0) == ((1.0, 1.0), (1.0, 1.0, 0.0, 2.0, 0.0))
    assert np.array_equal(np.reshape(spec.R0, (3, 3)), np.eye(3))
    assert spec.coordinates == ("x", "y") and set(spec.invariants) == {"jacobi", "spin"}
    s = spec.system()
    assert isinstance(s.group, SO3) and isinstance(s.space.retraction, Cayley) and s.n == 2 and s.dim == 5
    assert not s.depends_on_orientation and s.velocities == ("dx", "dy", "omega1", "omega2", "omega3")
    # the docstring says which ball this is
    notes = " ".join(spec.notes.split())
    assert "chaplygin-sphere" in notes and "not** the physical Chaplygin sphere" in notes
    assert "simplified" in notes and "Cayley" in notes


@pytest.mark.parametrize("example", [1, 2])
def test_metric_constraints_and_initial_conditions(example):
    if example == 1:
        s, q0, v0 = ex1()
    else:
        s, q0, v0 = rb.example_2()
        assert rb.EXAMPLE_2["params"] == {"m": 3.0, "r": 1.0, "I1": 1.0, "I2": 1.1, "I3": 1.2, "Omega": 0.2}
        assert tuple(q0) == (1.0, 0.0) and tuple(v0[2:]) == (-0.2, 0.0, 0.4)
        # (ẋ₀, ẏ₀) = (rω₂ − Ωy₀, Ωx₀ − rω₁) = (0, 0.2 + 0.2)
        assert v0[:2] == pytest.approx((0.0, 0.4), abs=1e-15)
    p = s.parameters
    m, r, W = p["m"], p["r"], p["Omega"]
    b0, _ = s.check(q0, v0)  # mechanical type, rank, constraints
    assert np.array_equal(_np(b0.R), np.eye(3))
    b = Point(jnp.asarray([0.3, -0.7]), jnp.asarray(SO3().exp(jnp.array([0.4, -0.2, 1.0]))))
    # one compiled program (eagerly, the metric's jax.hessian costs ~1.4 s of small compilations)
    G, mu, Pi = map(_np, jax.jit(lambda b: (s.metric(b), s.mu(b), s.Pi(b)))(b))
    np.testing.assert_allclose(G, np.diag([m, m, p["I1"], p["I2"], p["I3"]]), atol=1e-15)
    np.testing.assert_allclose(mu, [[1, 0, 0, -r, 0], [0, 1, r, 0, 0]], atol=0)
    np.testing.assert_allclose(Pi, [m * W * 0.7, m * W * 0.3, 0, 0, 0], atol=1e-15)  # (−mΩy, mΩx)
    assert s.has_constant_metric(b0)


def test_exact_solution_circle_and_invariants():
    spec = gnipy.get_model("rolling-ball")
    p = dict(spec.params)
    q0, v0 = spec.initial_condition(p)
    t = np.linspace(0.0, 7.0, 29)
    q, v = rb.exact(p, q0, v0, t)
    assert q.shape == (29, 2) and v.shape == (29, 5)
    assert q[0] == pytest.approx(q0, abs=1e-15) and v[0] == pytest.approx(v0, abs=1e-15)
    d = 1e-5
    qp, _ = rb.exact(p, q0, v0, t + d)
    qm, _ = rb.exact(p, q0, v0, t - d)
    assert (qp - qm) / (2 * d) == pytest.approx(v[:, :2], abs=1e-8)
    # the contact point runs round a circle at rate κ = IΩ/(I + mr²) (2/5 here)
    kappa = p["I1"] * p["Omega"] / (p["I1"] + p["m"] * p["r"] ** 2)
    assert kappa == pytest.approx(0.4)
    z, dz = q[:, 0] + 1j * q[:, 1], v[:, 0] + 1j * v[:, 1]
    centre = complex(*q0) + 1j * complex(*v0[:2]) / kappa
    assert np.abs(z - centre) == pytest.approx(abs(complex(*v0[:2])) / kappa, rel=1e-13)
    assert dz == pytest.approx(complex(*v0[:2]) * np.exp(1j * kappa * t), abs=1e-14)
    # ω₁, ω₂ from the constraints; ω₃ constant; J conserved
    s = spec.system()
    for qi, vi in zip(q, v):
        assert np.max(np.abs(_np(s.constraint_residual(Point(jnp.asarray(qi), jnp.eye(3)), jnp.asarray(vi))))) < 1e-13
    assert v[:, 4] == pytest.approx(v0[4], abs=0)
    J = rb.jacobi_integral(p, q, v)
    assert np.max(np.abs(J - J[0])) < 1e-13
    # the Jacobi-type integral is the physical one: E − mΩ(xẏ − yẋ), E = ½m|ż|² + ½Σ Iᵢωᵢ²
    E = 0.5 * p["m"] * np.abs(dz) ** 2 + 0.5 * np.sum(np.array([p["I1"], p["I2"], p["I3"]]) * v[:, 2:] ** 2, axis=1)
    assert J == pytest.approx(E - p["m"] * p["Omega"] * (q[:, 0] * v[:, 1] - q[:, 1] * v[:, 0]), rel=1e-15)
    # no closed form (None) and no spin invariant (NaN) for unequal moments
    p2 = rb.EXAMPLE_2["params"]
    assert rb.exact(p2, (1.0, 0.0), (0.0, 0.4, -0.2, 0.0, 0.4), t) is None
    assert np.isnan(spec.invariants["spin"](p2, q[0], v[0]))
    assert spec.invariants["spin"](dict(p2, I2=1.0), q[0], v[0]) == v[0, 4]


# --------------------------------------------------------------------------------------------
# The five explicit equations of §7.4
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("example", [1, 2])
def test_gni_satisfies_the_five_equations_of_section_7_4(example, ex1_runs, ex2_runs):
    """The GNI with the paper's l_d = h l(q_k, Δ, ω_k) (Euler A) and Cayley: the five equations of
    §7.4, with their O(h) and O(h²) terms, hold to round-off at every node."""
    sol = (ex1_runs if example == 1 else ex2_runs)["eq"]
    p = gnipy.get_model("rolling-ball").params if example == 1 else rb.EXAMPLE_2["params"]
    R = _np(sol.R)
    assert len(R) == N_EQ + 1 and np.max(np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3))) < 1e-13
    res = relative_residuals(p, sol, H_EQ)
    assert np.max(res) <= 1e-12, res
    # the check is sensitive: without the O(h²) terms the equations fail by far more
    res2 = relative_residuals(p, sol, H_EQ, order2=False)
    nonzero = [0, 1, 3, 4] if example == 1 else [0, 1, 2, 3, 4]  # ω₃ = 0 in example 1
    assert np.min(res2[nonzero]) > 1e-6, res2
    if example == 2:  # unequal moments: the O(h) gyroscopic terms matter too
        res1 = relative_residuals(p, sol, H_EQ, order1=False)
        assert np.min(res1[[0, 1, 3, 4]]) > 1e-5, res1


def _negated_affine(x, p):
    return -rb._affine(x, p)


def test_printed_sign_of_RBb_violates_the_constraint_equations():
    """(RBb) as printed, Q*(FL⁻ + FL⁺) + 2Q*Π = 0, is the GNI with Π → −Π (a System with Y negated):
    its trajectory still satisfies equations 1–3 (the P* part) but fails the constraint equations
    4 and 5 by O(1)."""
    s, q0, v0 = rb.example_2()
    p = rb.EXAMPLE_2["params"]
    flipped = gnipy.System(s.lagrangian, s.constraints, _negated_affine, args=p,
                           n=2, group=SO3(), retraction="cayley", reconstruction="right",
                           name="rolling-ball-printed-RBb")
    sol = gnipy.simulate(flipped, "gni-euler-a", q0, v0, h=H_EQ, steps=40, project_v0=True)
    res = relative_residuals(p, sol, H_EQ)
    assert np.max(res[:3]) <= 1e-12, res
    assert np.min(res[3:]) > 0.1, res  # e.g. eq 4 is off by 2Ωy_k


def test_the_four_discrete_lagrangian_families_coincide(ex2_runs):
    """With V = 0 and a constant metric, Euler A, Euler B, trapezoid and midpoint are one l_d:
    equal values and Legendre transforms at random steps, and equal GNI trajectories."""
    s, q0, v0 = rb.example_2()
    space = s.space
    families = [gnipy.EulerA(), gnipy.EulerB(), gnipy.Trapezoid(), gnipy.Midpoint()]
    rng = np.random.default_rng(3)
    h = 0.1

    @jax.jit  # one compiled program for the three points (eagerly: seconds of small compilations)
    def values_and_transforms(x, w, z):
        b0 = Point(x, SO3().exp(w))
        return ([ld(s, b0, z, h) for ld in families],
                [space.legendre_minus(lambda b, zz, ld=ld: ld(s, b, zz, h), b0, z) for ld in families],
                [space.legendre_plus(lambda b, zz, ld=ld: ld(s, b, zz, h), b0, z) for ld in families])

    for _ in range(3):
        x, w, z = rng.standard_normal(2), rng.standard_normal(3), rng.standard_normal(5)
        vals, fm, fp = values_and_transforms(x, w, z)
        vals, fm, fp = [float(v) for v in vals], [_np(f) for f in fm], [_np(f) for f in fp]
        # equal up to round-off: 1e-14 relative to the largest component (the transforms reach ~10²
        # here, where one ulp is already 3e-14)
        tol_m, tol_p = 1e-14 * max(1.0, np.max(np.abs(fm[0]))), 1e-14 * max(1.0, np.max(np.abs(fp[0])))
        for i in range(1, 4):
            assert vals[i] == pytest.approx(vals[0], rel=1e-14)
            np.testing.assert_allclose(fm[i], fm[0], rtol=0, atol=tol_m)
            np.testing.assert_allclose(fp[i], fp[0], rtol=0, atol=tol_p)
    # trajectories: the midpoint (the family evaluated furthest from b_k) against Euler A
    # (the trapezoid is held equal to the reduced RATTLE in tests/integrators/test_reduced_rattle.py)
    ref = ex2_runs["eq"]
    sol = gnipy.simulate(s, gnipy.GNI(gnipy.Midpoint(), start="rest"), q0, v0, h=H_EQ, steps=N_EQ)  # as ref
    assert np.max(np.abs(_np(sol.q) - _np(ref.q))) <= 1e-12
    assert np.max(np.abs(_np(sol.v) - _np(ref.v))) <= 1e-12
    assert np.max(np.abs(_np(sol.R) - _np(ref.R))) <= 1e-12


# --------------------------------------------------------------------------------------------
# Convergence
# --------------------------------------------------------------------------------------------
def test_example_1_converges_to_the_exact_circular_motion(ex1_runs):
    """Order 2 in position, angular velocity and energy: with V = 0 and a constant metric the
    paper's Euler A l_d is the trapezoid l_d (symmetric, and τ(σ)τ(−σ) = e), so this GNI is the
    reduced RATTLE, a symmetric method, and its order is even."""
    s, q0, v0 = ex1()
    p = s.parameters
    eq, ew, eE = [], [], []
    for h in HS:
        sol = ex1_runs[h]
        qe, ve = rb.exact(p, q0, v0, _np(sol.t))
        eq.append(np.max(np.abs(_np(sol.q) - qe)))
        ew.append(np.max(np.abs(_np(sol.v)[:, 2:] - ve[:, 2:])))
        E = 0.5 * p["m"] * (ve[:, 0] ** 2 + ve[:, 1] ** 2) + 0.5 * p["I1"] * np.sum(ve[:, 2:] ** 2, axis=1)
        eE.append(np.max(np.abs(_np(sol.energy) - E)))
        assert np.max(np.abs(_np(sol.constraint_residual))) < 1e-13
    assert eq[-1] < 1e-4
    for errors in (eq, ew, eE):
        assert fitted_order(HS, errors) == pytest.approx(2.0, abs=0.15), (eq, ew, eE)


def test_example_2_converges_to_the_reference_and_J(ex2_runs):
    s, q0, v0 = rb.example_2()
    p = s.parameters
    ref = ex2_runs["ref"]
    J_ref = rb.jacobi_integral(p, ref.q, ref.v)
    assert np.max(np.abs(J_ref - J_ref[0])) <= 1e-10  # the reference conserves J
    assert np.max(np.abs(_np(ref.constraint_residual))) <= 1e-12
    J0 = rb.jacobi_integral(p, q0, v0)
    assert J_ref[0] == pytest.approx(J0, rel=1e-15)
    eq, ev, eR, eJ = [], [], [], []
    for h in HS:
        sol = ex2_runs[h]
        every = round(h / HS[-1])  # the reference is saved on the finest grid
        eq.append(np.max(np.abs(_np(sol.q) - _np(ref.q)[::every])))
        ev.append(np.max(np.abs(_np(sol.v) - _np(ref.v)[::every])))
        eR.append(np.max(np.abs(_np(sol.R) - _np(ref.R)[::every])))
        eJ.append(np.max(np.abs(rb.jacobi_integral(p, sol.q, sol.v) - J0)))
    for errors in (eq, ev, eR, eJ):
        assert fitted_order(HS, errors) == pytest.approx(2.0, abs=0.15), (eq, ev, eR, eJ)
    assert all(np.diff(eJ) < 0)


# --------------------------------------------------------------------------------------------
# The attitude: R from the space angular velocity, as the paper's constraints use ω
# --------------------------------------------------------------------------------------------
T_SPHERE, H_SPHERE = 20.0, (0.02, 0.01)  # saved every 0.2: 101 nodes, one compilation per model
#: The references are saved every 0.1 (201 nodes, as ex2_runs' and dla_runs' references of the
#: rolling ball: one compiled program for the three; the solver lands a step on every saved time)
#: and compared with the GNI runs at every other node.
H_SPHERE_REF = 0.1


@pytest.fixture(scope="module")
def ball_and_sphere():
    """`rolling-ball` and `chaplygin-sphere` with I1 = I2 = I3 from the same x, y, ω (R0 = I, where
    the sphere's body angular velocity equals the space one), on a turning and a fixed table:
    the reference and the GNI (midpoint) at two step sizes of each."""
    out = {}
    for Omega in (1.0, 0.0):
        p = dict(m=1.0, r=1.0, I1=2.0 / 3.0, I2=2.0 / 3.0, I3=2.0 / 3.0, Omega=Omega)
        q0 = (1.0, 1.0)
        v0 = rb.velocity_from_constraints(p, q0, (0.3, 2.0, -0.5))
        runs = {}
        for name in ("rolling-ball", "chaplygin-sphere"):
            s = gnipy.make_system(name, **p)
            runs[name, "ref"] = reference(s, q0, v0, h=H_SPHERE_REF, t_final=T_SPHERE)
            for h in H_SPHERE:
                runs[name, h] = gnipy.simulate(s, "gni-midpoint", q0, v0, h=h, t_final=T_SPHERE,
                                               save_every=round(0.2 / h))
        out[Omega] = runs
    return out


@pytest.mark.parametrize("Omega", [1.0, 0.0])
def test_attitude_is_the_physical_ball_for_equal_moments(ball_and_sphere, Omega):
    """With ω the space angular velocity (Ṙ = ω̂R, R_{k+1} = cay(σ_k)R_k) the model's R is the
    physical ball's: the continuous solutions agree to 1e-10 at T = 20, and so do the GNI runs
    (to round-off: the two GNIs are one map here), which converge to it at order 2."""
    runs = ball_and_sphere[Omega]
    ball, sphere = runs["rolling-ball", "ref"], runs["chaplygin-sphere", "ref"]
    assert np.max(np.abs(_np(ball.q) - _np(sphere.q))) <= 1e-10
    assert np.max(np.abs(_np(ball.R) - _np(sphere.R))) <= 1e-10
    assert np.max(np.abs(_np(ball.R) - np.eye(3))) > 1.0  # the ball turns
    every = round(0.2 / H_SPHERE_REF)  # the GNI runs' nodes, t = 0, 0.2, ..., T_SPHERE
    np.testing.assert_allclose(_np(ball.t)[::every], _np(runs["rolling-ball", H_SPHERE[0]].t), rtol=0, atol=1e-12)
    errors = []
    for h in H_SPHERE:
        gb, gs = runs["rolling-ball", h], runs["chaplygin-sphere", h]
        assert np.max(np.abs(_np(gb.R) - _np(gs.R))) <= 1e-10
        errors.append(np.max(np.abs(_np(gb.R) - _np(ball.R)[::every])))
    assert fitted_order(H_SPHERE, errors) == pytest.approx(2.0, abs=0.1), errors


def test_left_reconstruction_is_not_the_attitude_and_changes_only_R(ball_and_sphere):
    """Read as the body angular velocity (Ṙ = Rω̂), ω gives another R (off by O(1) at T = 20 on the
    turning table); the motion of (x, y, ω) is the same to the last bit. (The run with the model's
    right reconstruction is that of `ball_and_sphere` at h = 0.02.)"""
    p = dict(m=1.0, r=1.0, I1=2.0 / 3.0, I2=2.0 / 3.0, I3=2.0 / 3.0, Omega=1.0)
    q0 = (1.0, 1.0)
    v0 = rb.velocity_from_constraints(p, q0, (0.3, 2.0, -0.5))
    kw = dict(h=0.02, t_final=T_SPHERE, save_every=10)
    right = ball_and_sphere[1.0]["rolling-ball", 0.02]
    assert dict(right.params) == p and (right.h, len(right.t)) == (0.02, 101)
    left = gnipy.simulate(rb.build_system(p, reconstruction="left"), "gni-midpoint", q0, v0, **kw)
    for name in ("q", "v", "p", "energy", "constraint_residual"):
        np.testing.assert_array_equal(_np(getattr(left, name)), _np(getattr(right, name)), err_msg=name)
    assert np.max(np.abs(_np(left.R) - _np(right.R))) > 1.0
    assert "body velocity" in left.orientation and "space velocity" in right.orientation


@pytest.mark.slow
def test_orientation_attribute_says_whether_R_is_physical():
    s, q0, v0 = rb.example_2()  # unequal moments: the paper's simplified model
    assert s.reconstruction == "right"
    # 101 saved nodes of a run to t_final: the compiled program of the gni-midpoint runs of
    # `ball_and_sphere` (a run given `steps` has another loop and compiles its own, 5 s of CPU)
    ds = gnipy.simulate(s, "gni-midpoint", q0, v0, h=0.1, t_final=10.0).to_xarray()
    assert "dR/dt = hat(xi) R" in ds.attrs["orientation"]
    assert "R is not a physical attitude" in ds.attrs["orientation"]
    # a batch over the moments: the attribute names both cases
    systems = [gnipy.make_system("rolling-ball", I1=I) for I in (2.0 / 3.0, 1.0)]
    sol = gnipy.simulate(systems, "gni-midpoint", np.stack([(1.0, 1.0)] * 2), np.stack([(1.0, 1.0, 0.0, 2.0, 0.0)] * 2),
                         h=0.1, steps=2)
    text = sol.to_xarray().attrs["orientation"]
    assert "depending on the member" in text and "physical ball" in text and "not a physical attitude" in text


def test_other_group_models_keep_the_body_reconstruction():
    for name in gnipy.model_names():
        s = gnipy.make_system(name)
        if s.group is not None:
            assert s.reconstruction == ("right" if name == "rolling-ball" else "left"), name


# --------------------------------------------------------------------------------------------
# Discrete Lagrange–d'Alembert on R² × SO(3)
# --------------------------------------------------------------------------------------------
#: DLA's step sizes, each run for N_DLA steps (one compilation per system), compared over t ≤ T_CONV
H_DLA = (0.1, 0.05, 0.025)
N_DLA = 100
H_REF = 0.1  # the nodes compared, a multiple of every h of H_DLA
#: the reference is saved every HS[-1] up to T_CONV (201 nodes, as ex2_runs' reference: one
#: compiled program) and compared at every H_REF
H_DLA_REF = HS[-1]


def dcay_inv_along(s):
    """dcay⁻¹_σ σ with the Appendix's matrix dcay⁻¹_σ = I − σ̂/2 + σσᵀ/4."""
    return (np.eye(3) - 0.5 * hat(s) + 0.25 * np.outer(s, s)) @ s


@pytest.fixture(scope="module")
def dla_runs():
    """DLA (midpoint l_d) on example 1 and on the same motion written on R⁵: `rotating-table-ball`,
    whose defaults are example 1's (m = r = Ω = 1, I = 2/3, the same (x, y, ẋ, ẏ, ω); its θ₀ = 0 are
    integrals of ω, not an attitude); and the reference of example 1 at t = 0, 0.1, ..., T_CONV (host arrays)."""
    s, q0, v0 = ex1()
    twin = gnipy.make_system("rotating-table-ball")
    tq0, tv0 = gnipy.get_model("rotating-table-ball").initial_condition(twin.parameters)
    p, tp = s.parameters, twin.parameters
    assert (p["m"], p["r"], p["Omega"]) == (tp["m"], tp["r"], tp["Omega"])
    assert p["I1"] == p["I2"] == p["I3"] == tp["I"]
    assert tuple(tq0) == (*q0, 0.0, 0.0, 0.0) and tuple(tv0) == tuple(v0)
    runs = {("group", h): gnipy.simulate(s, "dla", q0, v0, h=h, steps=N_DLA) for h in H_DLA}
    runs |= {("twin", h): gnipy.simulate(twin, "dla", tq0, tv0, h=h, steps=N_DLA) for h in H_DLA}
    ref = reference(s, q0, v0, h=H_DLA_REF, t_final=T_CONV)
    every = round(H_REF / H_DLA_REF)
    runs["ref"] = SimpleNamespace(t=_np(ref.t)[::every], q=_np(ref.q)[::every], R=_np(ref.R)[::every])
    return s, runs


def _dla_errors(runs, key, h):
    """Largest errors in (x, y) and, on the group, in R against the reference, at its saved times."""
    sol, ref = runs[key, h], runs["ref"]
    nodes = slice(0, round(T_CONV / h) + 1, round(H_REF / h))
    np.testing.assert_allclose(_np(sol.t)[nodes], _np(ref.t), rtol=0, atol=1e-12)
    ex = np.max(np.abs(_np(sol.q)[nodes, :2] - _np(ref.q)))
    eR = np.max(np.abs(_np(sol.R)[nodes] - _np(ref.R))) if key == "group" else None
    return ex, eR


def test_dla_on_the_group_is_its_euclidean_twin(dla_runs):
    """Issue 29: the same motion, on R² × SO(3) with the Cayley map and on R⁵, gives DLA the same
    error. Its discrete constraint acts on (Δ, dcay⁻¹_σ σ/h), the velocity its momenta
    (dcay⁻¹_{±σ})ᵀ Iσ/h hold, so with I1 = I2 = I3 the group scheme in (x, y, 𝔾⁻¹p) is the R⁵ one
    step for step, and the two runs agree to round-off. (With the constraint on σ/h, which is
    ω(1 + h²|ω|²/12) where the momentum holds Iω(1 + h²|ω|²/3), the group run's error was 550 times
    the twin's at h = 0.01.)"""
    _, runs = dla_runs
    for h in H_DLA:
        group, twin = runs["group", h], runs["twin", h]
        e_group, _ = _dla_errors(runs, "group", h)
        e_twin, _ = _dla_errors(runs, "twin", h)
        assert e_group <= 1.01 * e_twin, (h, e_group, e_twin)
        assert np.max(np.abs(_np(group.q) - _np(twin.q)[:, :2])) <= 1e-12, h
        assert np.max(np.abs(_np(group.v) - _np(twin.v))) <= 1e-12, h
        assert np.max(np.abs(_np(group.p) - _np(twin.p))) <= 1e-12, h


def test_dla_keeps_its_discrete_constraint_on_the_group(dla_runs):
    """DLA (midpoint l_d) holds its discrete constraint μ(b_{k+½})((Δ, dcay⁻¹_σ σ/h) − Y(b_{k+½})) = 0
    at every step to round-off, recomputed here from the saved (x, R): σ_k = cay⁻¹(R_{k+1}R_kᵀ) (the
    model's reconstruction R_{k+1} = cay(σ_k)R_k) and the Appendix's dcay⁻¹. The plain σ/h misses it by
    the O(h²) of the Cayley map."""
    s, runs = dla_runs
    p = s.parameters
    mu = np.array([[1.0, 0, 0, -p["r"], 0], [0, 1.0, p["r"], 0, 0]])
    for h in H_DLA:
        sol = runs["group", h]
        x, R = _np(sol.q), _np(sol.R)
        sigma = np.array([cay_inv(R[k + 1] @ R[k].T) for k in range(len(R) - 1)])
        xm = 0.5 * (x[1:] + x[:-1])
        Y = np.stack([-p["Omega"] * xm[:, 1], p["Omega"] * xm[:, 0]] + [np.zeros(len(xm))] * 3, axis=1)
        vel = np.concatenate([np.diff(x, axis=0) / h, np.array([dcay_inv_along(w) for w in sigma]) / h], axis=1)
        assert np.max(np.abs((vel - Y) @ mu.T)) <= 1e-12 * np.max(np.abs(vel)), h
        plain = np.concatenate([np.diff(x, axis=0) / h, sigma / h], axis=1)
        assert np.max(np.abs((plain - Y) @ mu.T)) > 0.1 * h**2, h


def test_dla_second_order_on_the_group(dla_runs):
    """Order 2 in (x, y) and in R against the continuous reference (slopes on the points above
    round-off, :func:`gnipy.analysis.fitted_order`)."""
    _, runs = dla_runs
    ex, eR = zip(*(_dla_errors(runs, "group", h) for h in H_DLA))
    assert min(ex) > ROUND_OFF and min(eR) > ROUND_OFF
    assert analysis_order(H_DLA, ex, ROUND_OFF) == pytest.approx(2.0, abs=0.1), ex
    assert analysis_order(H_DLA, eR, ROUND_OFF) == pytest.approx(2.0, abs=0.1), eR


# --------------------------------------------------------------------------------------------
# The command line
# --------------------------------------------------------------------------------------------
runner = CliRunner()


def _invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def test_cli_run_writes_orientations(tmp_path):
    out = tmp_path / "f.nc"
    # 200 steps: shares the compilation of the convergence runs (N_CONV steps)
    res = _invoke("run", "rolling-ball", "--method", "gni-euler-a", "--h", "0.0125", "--steps", str(N_CONV),
                  "--out", out)
    assert res.exit_code == 0, res.output
    assert "error vs exact" in res.output and "omega3" in res.output
    ds = xr.load_dataset(out)
    R = ds["R"]
    assert R.dims == ("time", "i", "j") and R.shape == (N_CONV + 1, 3, 3)
    R = R.values
    assert np.max(np.abs(np.einsum("kji,kjl->kil", R, R) - np.eye(3))) < 1e-13
    assert np.linalg.det(R) == pytest.approx(np.ones(N_CONV + 1), abs=1e-13)
    assert list(ds["coordinate"].values) == ["x", "y"] and ds.sizes["velocity"] == 5
    np.testing.assert_array_equal(ds.attrs["R0"], np.eye(3).ravel())
    assert ds.attrs["max_error_q_vs_exact"] < 1e-2 and ds.attrs["invariant_drift_spin"] < 1e-13
    # the file says how R was reconstructed, and that it is the ball's attitude (equal moments)
    assert "space velocity" in ds.attrs["orientation"] and "dR/dt = hat(xi) R" in ds.attrs["orientation"]
    assert "R is the attitude of the physical ball" in ds.attrs["orientation"]

    # --q0 (2 values), --v0 (5 values) and --R0 (9 values): on the constraints at x0
    out2 = tmp_path / "g.nc"
    Rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    res = _invoke("run", "rolling-ball", "--method", "gni-euler-a", "--h", "0.05", "--steps", str(N_CONV),
                  "--q0", "0.5,-1", "--v0", "0.5,1.5,-1,-0.5,0.3", "--R0", ",".join(map(str, Rz.ravel())),
                  "--out", out2)
    assert res.exit_code == 0, res.output
    ds = xr.load_dataset(out2)
    np.testing.assert_array_equal(ds["q"].values[0], [0.5, -1.0])
    np.testing.assert_array_equal(ds["v"].values[0], [0.5, 1.5, -1.0, -0.5, 0.3])
    np.testing.assert_array_equal(ds["R"].values[0], Rz)
    assert np.max(np.abs(ds["constraint_residual"].values)) < 1e-13


@pytest.mark.parametrize(
    "args, option",
    [
        (["--q0", "1,1,0"], "--q0"),
        (["--q0", "1"], "--q0"),
        (["--v0", "1,1"], "--v0"),
        (["--v0", "1,1,0,2"], "--v0"),
        (["--v0", "1,1,0,2,0,0"], "--v0"),
        (["--v0", "1,1,0,0,0"], "--v0"),  # off the constraints
        (["--R0", "1,0,0,0,1,0,0,0"], "--R0"),
        (["--R0", "1,0,0,0,1,0,0,0,2"], "--R0"),  # not a rotation
        (["--R0", "1,0,0,0,-1,0,0,0,-1,0"], "--R0"),
    ],
)
def test_cli_wrong_lengths_give_a_clean_error(args, option, tmp_path):
    res = _invoke("run", "rolling-ball", "--h", "0.1", "--steps", "5", *args, "--out", tmp_path / "x.nc")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and errors[0].startswith(f"Error: {option}:"), res.output
    assert not (tmp_path / "x.nc").exists()


def test_cli_R0_on_a_model_without_orientation(tmp_path):
    res = _invoke("run", "vertical-disk", "--h", "0.1", "--steps", "5", "--R0", "1,0,0,0,1,0,0,0,1",
                  "--out", tmp_path / "x.nc")
    assert res.exit_code == 2 and "Error: --R0:" in res.output and "Traceback" not in res.output
