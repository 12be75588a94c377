"""The model zoo against its exact solutions and invariants.

Every number here comes from a closed-form solution, an invariant or the constraints — never from
a previous run. Compile time dominates: the reference runs share one (h, t_final) per model, and
the non-default initial conditions reuse those compilations; the four convergence runs of a model
take one number of steps (h is traced) and so share one compiled program.
"""

import math
from types import SimpleNamespace

import jax
import numpy as np
import pytest

import gnipy
from gnipy.models import chaplygin_sleigh, knife_edge
from gnipy.models.elementary import (cosh_ratio, gudermannian, log_cosh_ratio, sine_defect_ratio, sinc,
                                     versine_ratio)

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

EXACT_MODELS = ["vertical-disk", "knife-edge", "rotating-table-ball"]
NEW_MODELS = [*EXACT_MODELS, "chaplygin-sleigh"]

H_REF, T_REF = 0.0625, 4.0  # reference runs: 65 saved nodes
HS, T_CONV = [0.05, 0.025, 0.0125, 0.00625], 2.0  # convergence runs


def _np(x):
    return np.asarray(x, dtype=np.float64)


def _ic(name):
    spec = gnipy.get_model(name)
    p = dict(spec.params)
    q0, v0 = spec.initial_condition(p)
    return spec, p, q0, v0


def fitted_order(hs, errors, floor=1e-12):
    """Least-squares slope of log(error) against log(h), on points above the round-off floor."""
    hs, errors = np.asarray(hs), np.asarray(errors)
    keep = errors > floor
    if keep.sum() < 3:
        raise AssertionError(f"fewer than 3 errors above {floor:g}: {errors}")
    return float(np.polyfit(np.log(hs[keep]), np.log(errors[keep]), 1)[0])


def _sleigh_observables(p, q0, v0, sol):
    """(numerical, exact) arrays of (θ, u, ω) at the saved times."""
    t = _np(sol.t) - float(sol.t[0])
    u, w = chaplygin_sleigh.body_velocities(_np(sol.q), _np(sol.v))
    num = np.stack([_np(sol.q)[:, 2], u, w], axis=-1)
    ue, we = chaplygin_sleigh.exact_body_velocities(p, q0, v0, t)
    ex = np.stack([chaplygin_sleigh.exact_heading(p, q0, v0, t), ue, we], axis=-1)
    return num, ex


@pytest.fixture(scope="module")
def references():
    """The continuous reference of every new model from its default initial condition."""
    out = {}
    for name in NEW_MODELS:
        sys_ = gnipy.make_system(name)
        out[name] = gnipy.simulate(sys_, "reference", h=H_REF, t_final=T_REF)
    return out


# --------------------------------------------------------------------------------------------
# Registration, defaults, parameters
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, coords",
    [
        ("vertical-disk", ("x", "y", "phi", "theta")),
        ("knife-edge", ("x", "y", "phi")),
        ("chaplygin-sleigh", ("x", "y", "theta")),
        ("rotating-table-ball", ("x", "y", "theta1", "theta2", "theta3")),
        ("contact-oscillator-mp", ("x", "y", "z")),
        ("contact-oscillator-gauge", ("x", "y", "z", "w")),
        ("nonholonomic-particle-gauge", ("x", "y", "z", "w")),
    ],
)
def test_registered_with_coordinates(name, coords):
    assert name in gnipy.model_names()
    spec = gnipy.get_model(name)
    sys_ = spec.system()
    assert spec.coordinates == coords and sys_.coordinates == coords and sys_.name == name
    assert sys_.parameters == dict(spec.params)
    assert spec.notes and spec.invariants and spec.description
    q0, v0 = spec.initial_condition(spec.params)
    assert sys_.defaults == (tuple(q0), tuple(v0)) == (spec.q0, spec.v0)


OVERRIDES = {
    "vertical-disk": {"r": 2.0, "m": 3.0},
    "knife-edge": {"alpha": 0.2, "J": 2.0},
    "chaplygin-sleigh": {"a": 0.3, "I": 2.5},
    "rotating-table-ball": {"r": 0.5, "Omega": 0.3, "I": 0.4},
}


@pytest.mark.parametrize("name", NEW_MODELS)
@pytest.mark.parametrize("override", [False, True])
def test_default_initial_condition_satisfies_constraints(name, override):
    spec = gnipy.get_model(name)
    params = spec.resolve_params(OVERRIDES[name] if override else None)
    sys_ = spec.build(params)
    q0, v0 = spec.initial_condition(params)
    assert sys_.defaults == (tuple(q0), tuple(v0))
    res = _np(sys_.constraint_residual(_np(q0), _np(v0)))
    assert np.max(np.abs(res)) <= 1e-14
    sys_.check(q0, v0)  # full validation: mechanical type, rank, constraints
    if not override:
        assert (tuple(q0), tuple(v0)) == (spec.q0, spec.v0)  # the documented numbers


def test_documented_defaults():
    assert gnipy.get_model("vertical-disk").initial_condition(gnipy.get_model("vertical-disk").params) == (
        (0.0, 0.0, 0.0, 0.0), (1.0, 0.0, 1.0, 1.0))
    ball = gnipy.get_model("rotating-table-ball")
    assert dict(ball.params) == pytest.approx({"m": 1.0, "r": 1.0, "I": 2 / 3, "Omega": 1.0})
    assert ball.initial_condition(ball.params) == ((1.0, 1.0, 0.0, 0.0, 0.0), (1.0, 1.0, 0.0, 2.0, 0.0))
    assert gnipy.get_model("knife-edge").initial_condition({}) == ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))


@pytest.mark.parametrize("name", NEW_MODELS)
def test_parameter_overrides_reach_the_system(name):
    over = OVERRIDES[name]
    sys_ = gnipy.make_system(name, **over)
    assert {k: sys_.parameters[k] for k in over} == over
    q = _np(gnipy.get_model(name).initial_condition(sys_.parameters)[0]) + 0.1
    # one compiled program (eagerly, the metric's jax.hessian costs ~1.4 s of op-by-op dispatch)
    G, mu, Y, V = map(_np, jax.jit(lambda q: (sys_.metric(q), sys_.mu(q), sys_.Y(q), sys_.potential(q)))(q))
    p = sys_.parameters
    if name == "vertical-disk":
        assert G[0, 0] == pytest.approx(p["m"]) and mu[0, 3] == pytest.approx(-p["r"] * math.cos(q[2]))
    elif name == "knife-edge":
        assert G[2, 2] == pytest.approx(p["J"])
        # V = -m g sin(α) x
        assert float(V) == pytest.approx(-p["m"] * p["g"] * math.sin(p["alpha"]) * q[0])
    elif name == "chaplygin-sleigh":
        assert G[2, 2] == pytest.approx(p["I"]) and mu[0, 2] == pytest.approx(-p["a"])
    else:
        assert G[2, 2] == pytest.approx(p["I"]) and mu[1, 2] == pytest.approx(p["r"])
        assert Y[:2] == pytest.approx([-p["Omega"] * q[1], p["Omega"] * q[0]])


@pytest.mark.parametrize("name", gnipy.model_names())
def test_unknown_or_bad_parameters_raise(name):
    with pytest.raises(gnipy.InputError, match="unknown parameter 'nonsense'"):
        gnipy.make_system(name, nonsense=1.0)
    first = next(iter(gnipy.get_model(name).params))
    with pytest.raises(gnipy.InputError, match="finite"):
        gnipy.make_system(name, **{first: float("nan")})


# --------------------------------------------------------------------------------------------
# The closed forms themselves (host-side, independent of the integrators)
# --------------------------------------------------------------------------------------------
def test_elementary_ratios():
    x = np.array([-3.0, -0.5, -0.1000001, -0.0999999, -1e-3, 0.0, 1e-6, 0.05, 0.0999999, 0.1, 0.7, 2.0])
    nz = x != 0
    direct_sinc = np.where(nz, np.sin(x) / np.where(nz, x, 1), 1.0)
    direct_vers = np.where(nz, 2 * np.sin(x / 2) ** 2 / np.where(nz, x, 1) ** 2, 0.5)
    assert sinc(x) == pytest.approx(direct_sinc, rel=1e-15)
    assert versine_ratio(x) == pytest.approx(direct_vers, rel=1e-15)
    # x − sin x = Σ (−1)^k x^(2k+3)/(2k+3)!, summed to convergence (an independent evaluation)
    series = np.zeros_like(x)
    term = np.full_like(x, 1 / 6)
    for k in range(30):
        series += term
        term = -term * x**2 / ((2 * k + 4) * (2 * k + 5))
    assert sine_defect_ratio(x) == pytest.approx(series, rel=1e-12)


def test_hyperbolic_ratios():
    """cosh c0/cosh s and log(cosh s/cosh c0) against the direct forms where those do not overflow
    (and finite where they would), gd(s) against the integral of sech (SciPy's quad)."""
    from scipy.integrate import quad

    c0, s = np.array([-3.0, 0.0, 0.4, 5.0]), np.array([2.0, -1.5, 0.0, 20.0])
    assert cosh_ratio(c0, s) == pytest.approx(np.cosh(c0) / np.cosh(s), rel=1e-14)
    assert log_cosh_ratio(s, c0) == pytest.approx(np.log(np.cosh(s) / np.cosh(c0)), rel=1e-13, abs=1e-15)
    assert np.isfinite(cosh_ratio(800.0, 900.0)) and cosh_ratio(800.0, 900.0) == pytest.approx(np.exp(-100.0))
    assert log_cosh_ratio(900.0, 800.0) == pytest.approx(100.0, rel=1e-15)
    for x in (-4.0, -0.3, 0.0, 1.0, 7.0):
        assert gudermannian(x) == pytest.approx(quad(lambda u: 1 / np.cosh(u), 0.0, x, epsabs=1e-14)[0], abs=1e-13)


@pytest.mark.parametrize("name", EXACT_MODELS)
def test_exact_solution_is_consistent(name):
    """The exact v is dq/dt (central differences), and (q, v) satisfy the constraints."""
    spec, p, q0, v0 = _ic(name)
    sys_ = spec.system()
    t = np.linspace(0.1, 3.0, 7)
    d = 1e-5
    q, v = spec.exact(p, q0, v0, t)
    qp, _ = spec.exact(p, q0, v0, t + d)
    qm, _ = spec.exact(p, q0, v0, t - d)
    assert (qp - qm) / (2 * d) == pytest.approx(v, abs=1e-8)
    q_0, v_0 = spec.exact(p, q0, v0, [0.0])
    assert q_0[0] == pytest.approx(q0, abs=1e-15) and v_0[0] == pytest.approx(v0, abs=1e-15)
    for qi, vi in zip(q, v):
        assert np.max(np.abs(_np(sys_.constraint_residual(qi, vi)))) <= 1e-13


def test_knife_edge_textbook_form_and_zero_turning_rate():
    """The small-argument-safe closed form equals the textbook form (ω ≠ 0) and the uniformly
    accelerated straight slide (ω = 0), and is continuous in ω."""
    p = dict(gnipy.get_model("knife-edge").params)
    a = p["g"] * math.sin(p["alpha"])
    t = np.linspace(0, 3, 13)
    q0, s0, w = (0.3, -0.2, 0.7), 0.8, 1.3
    v0 = (s0 * math.cos(q0[2]), s0 * math.sin(q0[2]), w)
    q, _ = knife_edge.exact(p, q0, v0, t)
    phi0, phi = q0[2], q0[2] + w * t
    k = a / w
    c = s0 - k * math.sin(phi0)
    x = q0[0] + c / w * (np.sin(phi) - math.sin(phi0)) + k / (2 * w) * (np.sin(phi) ** 2 - math.sin(phi0) ** 2)
    y = (q0[1] - c / w * (np.cos(phi) - math.cos(phi0))
         + k * ((phi - phi0) / (2 * w) - (np.sin(2 * phi) - math.sin(2 * phi0)) / (4 * w)))
    assert q[:, 0] == pytest.approx(x, abs=1e-12) and q[:, 1] == pytest.approx(y, abs=1e-12)

    v0 = (s0 * math.cos(phi0), s0 * math.sin(phi0), 0.0)
    q, v = knife_edge.exact(p, q0, v0, t)
    dist = s0 * t + 0.5 * a * math.cos(phi0) * t**2
    assert q[:, 0] == pytest.approx(q0[0] + math.cos(phi0) * dist, abs=1e-14)
    assert q[:, 1] == pytest.approx(q0[1] + math.sin(phi0) * dist, abs=1e-14)
    # continuity in ω: the textbook form would lose everything to cancellation at ω = 1e-12
    q_eps, _ = knife_edge.exact(p, q0, (*v0[:2], 1e-12), t)
    assert q_eps == pytest.approx(q, abs=1e-9)


def test_chaplygin_sleigh_closed_forms_satisfy_the_reduced_equations():
    """u̇ = aω², (I + ma²)ω̇ = −m a u ω, θ̇ = ω, and energy conservation, by central differences."""
    spec, p, q0, v0 = _ic("chaplygin-sleigh")
    m, I, a = p["m"], p["I"], p["a"]
    t = np.linspace(0.2, 6.0, 9)
    d = 1e-5
    u, w = chaplygin_sleigh.exact_body_velocities(p, q0, v0, t)
    up, wp = chaplygin_sleigh.exact_body_velocities(p, q0, v0, t + d)
    um, wm = chaplygin_sleigh.exact_body_velocities(p, q0, v0, t - d)
    th_p = chaplygin_sleigh.exact_heading(p, q0, v0, t + d)
    th_m = chaplygin_sleigh.exact_heading(p, q0, v0, t - d)
    assert (up - um) / (2 * d) == pytest.approx(a * w**2, abs=1e-8)
    assert (I + m * a**2) * (wp - wm) / (2 * d) == pytest.approx(-m * a * u * w, abs=1e-8)
    assert (th_p - th_m) / (2 * d) == pytest.approx(w, abs=1e-8)
    E0 = 0.5 * m * 1.0**2 + 0.5 * (I + m * a**2) * 1.0**2  # u0 = ω0 = 1 in the default
    assert 0.5 * m * u**2 + 0.5 * (I + m * a**2) * w**2 == pytest.approx(E0, abs=1e-13)
    # ω0 = 0: straight sliding at constant speed
    u, w = chaplygin_sleigh.exact_body_velocities(p, q0, (0.7, 0.0, 0.0), t)
    assert u == pytest.approx(0.7) and w == pytest.approx(0.0)


# --------------------------------------------------------------------------------------------
# The continuous reference against the closed forms and invariants
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", EXACT_MODELS)
def test_reference_matches_exact_solution(name, references):
    spec, p, q0, v0 = _ic(name)
    ref = references[name]
    q, v = spec.exact(p, q0, v0, _np(ref.t))
    assert np.max(np.abs(_np(ref.q) - q)) <= 1e-8
    assert np.max(np.abs(_np(ref.v) - v)) <= 1e-8


def test_reference_matches_sleigh_body_velocities(references):
    _, p, q0, v0 = _ic("chaplygin-sleigh")
    num, ex = _sleigh_observables(p, q0, v0, references["chaplygin-sleigh"])
    assert np.max(np.abs(num - ex)) <= 1e-8


@pytest.mark.parametrize("name", NEW_MODELS)
def test_reference_conserves_invariants(name, references):
    spec, p, _, _ = _ic(name)
    ref = references[name]
    for inv_name, f in spec.invariants.items():
        vals = np.array([float(f(p, q, v)) for q, v in zip(_np(ref.q), _np(ref.v))])
        assert np.max(np.abs(vals - vals[0])) <= 1e-10, inv_name
    assert np.max(np.abs(_np(ref.constraint_residual))) <= 1e-10


def test_rotating_table_energy_is_not_conserved(references):
    """The table does work: the energy changes by mΩ Δ(xẏ − yẋ) (the Jacobi integral's other term)."""
    _, p, _, _ = _ic("rotating-table-ball")
    ref = references["rotating-table-ball"]
    q, v, e = _np(ref.q), _np(ref.v), _np(ref.energy)
    L = q[:, 0] * v[:, 1] - q[:, 1] * v[:, 0]
    assert np.ptp(e) > 0.1
    assert e - e[0] == pytest.approx(p["m"] * p["Omega"] * (L - L[0]), abs=1e-10)


NON_DEFAULT_IC = {
    # heading rate 0: straight line
    "vertical-disk": ((0.5, -1.0, 0.4, 0.2), (2 * math.cos(0.4), 2 * math.sin(0.4), 0.0, 2.0)),
    # turning rate 0: uniformly accelerated straight slide
    "knife-edge": ((0.1, 0.2, 0.3), (0.5 * math.cos(0.3), 0.5 * math.sin(0.3), 0.0)),
    # arbitrary point, spin about the vertical
    "rotating-table-ball": ((-0.4, 0.8, 0.0, 0.0, 0.0), (0.3, -0.7, -0.4 + 0.7, 0.3 + 0.8, 1.5)),
}


@pytest.mark.parametrize("name", EXACT_MODELS)
def test_reference_matches_exact_from_other_initial_conditions(name):
    spec, p, _, _ = _ic(name)
    q0, v0 = NON_DEFAULT_IC[name]
    if name == "rotating-table-ball":  # ω1 = (Ωx − ẏ)/r, ω2 = (ẋ + Ωy)/r with Ω = r = 1
        assert v0[2] == pytest.approx(p["Omega"] * q0[0] - v0[1]) and v0[3] == pytest.approx(v0[0] + q0[1])
    ref = gnipy.simulate(spec.system(), "reference", q0, v0, h=H_REF, t_final=T_REF)
    q, v = spec.exact(p, q0, v0, _np(ref.t))
    assert np.max(np.abs(_np(ref.q) - q)) <= 1e-8
    assert np.max(np.abs(_np(ref.v) - v)) <= 1e-8


def test_reference_matches_exact_with_overridden_parameters():
    spec = gnipy.get_model("rotating-table-ball")
    p = spec.resolve_params(OVERRIDES["rotating-table-ball"])
    q0, v0 = spec.initial_condition(p)
    ref = gnipy.simulate(gnipy.make_system(spec.name, **OVERRIDES[spec.name]), "reference", h=H_REF, t_final=T_REF)
    q, v = spec.exact(p, q0, v0, _np(ref.t))
    assert np.max(np.abs(_np(ref.q) - q)) <= 1e-8
    assert np.max(np.abs(_np(ref.v) - v)) <= 1e-8


# --------------------------------------------------------------------------------------------
# gni-trapezoid converges at order 2 to the exact solutions
# --------------------------------------------------------------------------------------------
def _gni_errors(name):
    """Errors of gni-trapezoid on t ≤ T_CONV at every h of HS. Every run takes the same number of
    steps (that of the finest h; the saved-node count is the only static size, h and the steps are
    traced), so the four runs share one compiled program; the nodes after T_CONV are not used, and
    the first round(T_CONV/h) steps of a longer run are the shorter run's."""
    spec, p, q0, v0 = _ic(name)
    sys_ = spec.system()
    steps = round(T_CONV / HS[-1])
    errs_q, errs_v, worst_res = [], [], 0.0
    for h in HS:
        # every node: the GNI's positions carry a period-2 oscillation of size O(h²) (the
        # centred constraint of (Afin) admits a parasitic (−1)^k mode, started by q_1 = q_0 + h v_0),
        # so errors sampled only at odd or only at even nodes have different constants
        full = gnipy.simulate(sys_, "gni-trapezoid", h=h, steps=steps)
        assert len(full.t) == steps + 1
        n = round(T_CONV / h) + 1  # the nodes on t ≤ T_CONV
        sol = SimpleNamespace(**{k: _np(getattr(full, k))[:n] for k in ("t", "q", "v", "constraint_residual")})
        assert float(sol.t[-1]) == pytest.approx(T_CONV, abs=1e-12) and len(sol.t) == n
        worst_res = max(worst_res, float(np.max(np.abs(_np(sol.constraint_residual)))))
        if spec.exact is not None:
            q, v = spec.exact(p, q0, v0, _np(sol.t))
            errs_q.append(np.max(np.abs(_np(sol.q) - q)))
            errs_v.append(np.max(np.abs(_np(sol.v) - v)))
        else:  # the sleigh: heading and body velocities
            num, ex = _sleigh_observables(p, q0, v0, sol)
            errs_q.append(np.max(np.abs(num[:, 0] - ex[:, 0])))
            errs_v.append(np.max(np.abs(num[:, 1:] - ex[:, 1:])))
    return np.array(errs_q), np.array(errs_v), worst_res


@pytest.mark.parametrize("name", NEW_MODELS)
def test_gni_trapezoid_converges_at_order_two(name):
    errs_q, errs_v, worst_res = _gni_errors(name)
    assert np.all(np.diff(errs_q) < 0) and np.all(np.diff(errs_v) < 0), (errs_q, errs_v)
    assert fitted_order(HS, errs_q) == pytest.approx(2.0, abs=0.15), errs_q
    # at least 2: from the consistent start (the default) the vertical disk's velocities converge at
    # order 4 (measured 4.00; its heading and rolling rates are constant and the start excites no
    # impulse oscillation)
    assert fitted_order(HS, errs_v) >= 2.0 - 0.15, errs_v
    # the GNI's reported velocity satisfies the constraints to round-off (DESIGN §2)
    assert worst_res <= 1e-12
