"""The test problems that decide between methods: Modin–Verdier's gauge-perturbed (non-reversible)
contact oscillator and nonholonomic particle, and McLachlan–Perlmutter's contact-oscillator set-up.

Every number here comes from the set-ups' definitions, an invariant, the unperturbed models or the
constraints — never from a previous run:

- the perturbation is a pure gauge: the continuous reference of a perturbed model is that of the
  unperturbed model (an independent check of the construction), and w follows its closed form;
- the discrete methods tell the difference: on the perturbed problem the energy error of the GNI
  grows secularly and ends far above the unperturbed problem's, while on the control c = 0 (the same
  four coordinates, reversible) it stays bounded.

The references run without the Systems' provenance fields (one compiled program per model at every
parameter value); the long runs take the trapezoid GNI on each perturbed model. Measured on the
shared 2-core machine (`pytest -n 0 --durations=0` on this file alone, other jobs running, so noisy
to a few seconds): 25.6 s → 18.3 s.
"""

import math

import numpy as np
import pytest

import gnipy
from gnipy.models import contact_oscillator_gauge, contact_oscillator_mp, nonholonomic_particle_gauge
from gnipy.models.gauge import gauge_coordinate

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

GAUGE = {  # perturbed model -> (unperturbed model, its parameters from the perturbed one's, S, the energy)
    "contact-oscillator-gauge": ("contact-oscillator", lambda p: {"epsilon": p["epsilon"]}, contact_oscillator_gauge.S, "H"),
    "nonholonomic-particle-gauge": ("nonholonomic-particle", lambda p: {"k": p["k"]}, nonholonomic_particle_gauge.S,
                                    "energy"),
}
NEW = ["contact-oscillator-mp", *GAUGE]
H_REF, T_REF = 0.0625, 8.0


def _np(x):
    return np.asarray(x, dtype=np.float64)


def _values(spec, params, sol, name):
    f = spec.invariants[name]
    return np.array([float(f(params, q, v)) for q, v in zip(_np(sol.q), _np(sol.v))])


# --------------------------------------------------------------------------------------------
# Parameters (registration: tests/models/test_models.py)
# --------------------------------------------------------------------------------------------
OVERRIDES = {
    "contact-oscillator-mp": {"epsilon": 0.1},
    "contact-oscillator-gauge": {"epsilon": 0.3, "c": -0.5},
    "nonholonomic-particle-gauge": {"k": 2.0, "c": 0.25},
}


@pytest.mark.parametrize("name", NEW)
@pytest.mark.parametrize("override", [False, True])
def test_initial_condition_satisfies_constraints_and_levels(name, override):
    spec = gnipy.get_model(name)
    p = spec.resolve_params(OVERRIDES[name] if override else None)
    sys_ = gnipy.make_system(name, **(OVERRIDES[name] if override else {}))
    assert sys_.parameters == p
    q0, v0 = spec.initial_condition(p)
    assert sys_.defaults == (tuple(q0), tuple(v0))
    assert np.max(np.abs(_np(sys_.constraint_residual(_np(q0), _np(v0))))) <= 1e-14
    sys_.check(q0, v0)  # mechanical type, metric, rank, constraints
    inv = {k: float(f(p, _np(q0), _np(v0))) for k, f in spec.invariants.items()}
    if name != "nonholonomic-particle-gauge":  # McLachlan–Perlmutter's levels on the section y = 0, ẏ > 0
        assert inv["H"] == pytest.approx(contact_oscillator_mp.ENERGY, abs=1e-14)
        assert inv["H_y"] == pytest.approx(contact_oscillator_mp.ENERGY_Y, abs=1e-14)
        assert q0[1] == 0.0 and v0[1] > 0 and q0[2] == contact_oscillator_mp.Z0_DEFAULT
    if name in GAUGE:
        assert inv["p_w"] == pytest.approx(p["c"], abs=1e-15) and q0[3] == 0.0
        base, base_params, _, energy = GAUGE[name]
        bspec = gnipy.get_model(base)
        assert inv[energy] == pytest.approx(float(bspec.invariants[energy](base_params(p), _np(q0[:3]), _np(v0[:3]))),
                                            abs=1e-15)
        # the energy of the lifted Lagrangian is the unperturbed energy plus ½c²
        assert float(sys_.energy(_np(q0), _np(v0))) == pytest.approx(inv[energy] + 0.5 * p["c"] ** 2, abs=1e-13)


def test_gauge_shifts_the_momenta():
    """The momenta conjugate to q are the unperturbed ones minus c∇S (Modin–Verdier's shift)."""
    for name, grad_S in [("contact-oscillator-gauge", contact_oscillator_gauge.grad_S),
                         ("nonholonomic-particle-gauge", nonholonomic_particle_gauge.grad_S)]:
        spec = gnipy.get_model(name)
        for c in (1.0, -0.5, 0.0):
            sys_ = gnipy.make_system(name, c=c)
            q0, v0 = spec.initial_condition(spec.resolve_params({"c": c}))
            q = _np(q0) + np.array([0.3, -0.2, 0.7, 1.1])
            p = _np(sys_.momentum(q, _np(v0)))
            pw = v0[3] - float(_np(grad_S(q[:3])) @ _np(v0[:3]))
            assert p[3] == pytest.approx(pw, abs=1e-15)
            assert p[:3] == pytest.approx(_np(v0[:3]) - pw * _np(grad_S(q[:3])), abs=1e-15)


# --------------------------------------------------------------------------------------------
# McLachlan–Perlmutter's set-up
# --------------------------------------------------------------------------------------------
def test_mp_setup_family_and_grid():
    assert contact_oscillator_mp.Z0_GRID == pytest.approx(math.sqrt(2) * np.arange(-0.9, 0.91, 0.2), abs=1e-15)
    assert contact_oscillator_mp.Z0_DEFAULT == pytest.approx(0.1 * math.sqrt(2), abs=1e-15)
    spec = gnipy.get_model("contact-oscillator-mp")
    p = dict(spec.params)
    sys_ = spec.system()
    for z0 in contact_oscillator_mp.Z0_GRID:
        for zdot0 in (0.0, 0.3):
            q0, v0 = contact_oscillator_mp.setup_initial_condition(p["epsilon"], z0, zdot0=zdot0)
            assert spec.invariants["H"](p, _np(q0), _np(v0)) == pytest.approx(1.5, abs=1e-14)
            assert spec.invariants["H_y"](p, _np(q0), _np(v0)) == pytest.approx(0.5, abs=1e-14)
            assert abs(float(sys_.constraint_residual(_np(q0), _np(v0))[0])) <= 1e-15 and q0[0] > 0
    with pytest.raises(ValueError, match="below the energy"):
        contact_oscillator_mp.setup_initial_condition(p["epsilon"], 2.0)


@pytest.mark.parametrize("N", [15, 40])
def test_poincare_step_makes_the_y_oscillator_periodic(N):
    """With h = 2 sin(π/N), gni-trapezoid (Störmer–Verlet on the free y oscillator: the constraint
    force has no y-component) returns to the section y = 0 with ẏ = √(2H_y) after exactly N steps."""
    h = contact_oscillator_mp.poincare_step(N)
    assert h == pytest.approx(2 * math.sin(math.pi / N), abs=0) and math.cos(2 * math.pi / N) == pytest.approx(1 - h * h / 2)
    sol = gnipy.simulate(gnipy.make_system("contact-oscillator-mp"), "gni-trapezoid", h=h, steps=2 * N)
    y, ydot = _np(sol.q)[:, 1], _np(sol.v)[:, 1]
    for k in (N, 2 * N):
        assert abs(y[k]) <= 1e-13 and ydot[k] == pytest.approx(1.0, abs=1e-13)
    on_section = (np.abs(y) <= 1e-12) & (ydot > 0)
    assert np.flatnonzero(on_section).tolist() == [0, N, 2 * N]  # and not in between


# --------------------------------------------------------------------------------------------
# The perturbation is a pure gauge: the continuous motion is the unperturbed one
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", GAUGE)
@pytest.mark.parametrize("override", [False, True])
def test_reference_is_the_unperturbed_motion(name, override):
    spec = gnipy.get_model(name)
    p = spec.resolve_params(OVERRIDES[name] if override else None)
    q0, v0 = spec.initial_condition(p)
    base, base_params, S, energy = GAUGE[name]
    # on the Systems without their provenance fields (System.without_metadata): the reference's
    # compiled program is keyed by the whole System, its `params` included, so the overridden
    # parameters compiled both references anew (6 s of CPU); the motion does not depend on them
    ref = gnipy.simulate(gnipy.make_system(name, **(OVERRIDES[name] if override else {})).without_metadata(),
                         "reference", q0, v0, h=H_REF, t_final=T_REF)
    ref0 = gnipy.simulate(gnipy.make_system(base, **base_params(p)).without_metadata(), "reference", q0[:3], v0[:3],
                          h=H_REF, t_final=T_REF)
    q, v, t = _np(ref.q), _np(ref.v), _np(ref.t)
    assert np.max(np.abs(q[:, :3] - _np(ref0.q))) <= 1e-10
    assert np.max(np.abs(v[:, :3] - _np(ref0.v))) <= 1e-10
    assert np.max(np.abs(q[:, 3] - gauge_coordinate(S, p["c"], q0, t, q))) <= 1e-10
    assert np.ptp(q[:, 0]) > 0.5  # a genuine motion, not a rest point
    for inv_name in spec.invariants:
        vals = _values(spec, p, ref, inv_name)
        assert np.max(np.abs(vals - vals[0])) <= 1e-10, inv_name
    assert np.max(np.abs(_np(ref.constraint_residual))) <= 1e-10


def test_mp_reference_conserves_invariants():
    spec = gnipy.get_model("contact-oscillator-mp")
    p = dict(spec.params)
    ref = gnipy.simulate(spec.system(), "reference", h=H_REF, t_final=T_REF)
    for inv_name in spec.invariants:
        vals = _values(spec, p, ref, inv_name)
        assert np.max(np.abs(vals - vals[0])) <= 1e-10, inv_name
    y, t = _np(ref.q)[:, 1], _np(ref.t)
    assert y == pytest.approx(np.sin(t), abs=1e-10)  # y = √(2H_y) sin t from the section


# --------------------------------------------------------------------------------------------
# The discrete methods tell the difference
# --------------------------------------------------------------------------------------------
H_LONG, STEPS_LONG = 0.1, 20_000  # T = 2000


def _energy_error(name, method, **params):
    """|I_k − I_0| of the model's energy-type invariant along a long run from its initial condition,
    and the ratio of its largest values over the last and the first quarter (secular growth)."""
    spec = gnipy.get_model(name)
    p = spec.resolve_params(params)
    sol = gnipy.simulate(gnipy.make_system(name, **params), method, h=H_LONG, steps=STEPS_LONG, save_every=100)
    assert sol.result == 0
    key = "energy" if "energy" in spec.invariants else "H"
    err = np.abs(_values(spec, p, sol, key) - _values(spec, p, sol, key)[0])
    quarter = len(err) // 4
    return err, float(np.max(err[-quarter:]) / np.max(err[1:quarter]))


# One GNI on each perturbed model: the trapezoid (the midpoint on the contact oscillator, the same
# symmetric family and the same reversibility argument, was left out: 2.5 s of CPU)
@pytest.mark.parametrize("name, method", [("contact-oscillator-gauge", "gni-trapezoid"),
                                          ("nonholonomic-particle-gauge", "gni-trapezoid")])
def test_discrete_methods_tell_the_difference(name, method):
    base, base_params, _, _ = GAUGE[name]
    spec = gnipy.get_model(name)
    p = dict(spec.params)
    q0, v0 = spec.initial_condition(p)
    # the unperturbed model from the same state
    bsys = gnipy.make_system(base, **base_params(p))
    bspec = gnipy.get_model(base)
    key = "energy" if "energy" in bspec.invariants else "H"
    sol = gnipy.simulate(bsys, method, q0[:3], v0[:3], h=H_LONG, steps=STEPS_LONG, save_every=100)
    vals = np.array([float(bspec.invariants[key](base_params(p), q, v)) for q, v in zip(_np(sol.q), _np(sol.v))])
    err_plain = np.abs(vals - vals[0])
    quarter = len(err_plain) // 4
    growth_plain = float(np.max(err_plain[-quarter:]) / np.max(err_plain[1:quarter]))

    err_control, growth_control = _energy_error(name, method, c=0.0)  # same coordinates, reversible
    err_gauge, growth_gauge = _energy_error(name, method)  # c = 1: momenta shifted by ∇S

    # reversible problems: the energy error stays bounded, and the four-coordinate form alone changes little
    assert growth_plain <= 1.5 and growth_control <= 1.5, (growth_plain, growth_control)
    assert 0.5 <= np.max(err_control) / np.max(err_plain) <= 2.0
    # the non-reversible one: the error grows secularly and ends far above the unperturbed problem's
    assert growth_gauge >= 2.0, growth_gauge
    assert np.max(err_gauge) >= 10.0 * np.max(err_plain), (np.max(err_gauge), np.max(err_plain))
