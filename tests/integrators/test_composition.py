"""Compositions of symmetric methods (gnipy.integrators.composition): fitted orders against exact
solutions, the impulse rescaling and the consistent start they need on the GNI, and their names.

Orders are least-squares slopes of the error at T = 1 against the model's exact solution, on the
points above round-off (:func:`gnipy.analysis.fitted_order`), and must equal `method.order`.

Every composition runs the same Composition.step (substeps at γ_i h, for a GNI base the impulse
rescaling of change_step), so the fitted orders run one case per kind of result, each compiling its
own program (3-6 s): order 4 on a GNI (yoshida4-gni-trapezoid, a negative substep, affine
constraints), order 6 on a base that is not a GNI (kahanli6-mp, and yoshida6-mp with its two
negative substeps of size ~2h), and the GNI's cap at order 4 (kahanli6-gni-trapezoid). The order
conditions of every scheme's coefficients (suzuki4's included) are checked exactly in
test_composition_coefficients_are_palindromic_and_consistent, and the base's l_d enters only through
its own step (yoshida4-gni-midpoint, suzuki4-gni-trapezoid left out). Measured on the 2-core machine
(noisy, shared): 38 s before, 36 s after (loaded; the cases kept took 30 s of the run before).
"""

import jax
import numpy as np
import pytest

import gnipy
from gnipy.analysis import ROUND_OFF, fitted_order
from gnipy.equations import lagrange_dalembert_acceleration
from gnipy.integrators.composition import COMPOSITIONS, GNI_COMPOSITION_ORDER, Composition
from gnipy.integrators.gni import GNI

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

T = 1.0
ORDER_TOL = 0.3


def _errors(model, method, steps):
    """Final-time errors (q and v, max norm) against the exact solution, one run per step count."""
    spec = gnipy.get_model(model)
    system = spec.system()
    q_ex, v_ex = spec.exact(spec.params, np.asarray(spec.q0), np.asarray(spec.v0), np.array([T]))
    out = []
    for n in steps:
        sol = gnipy.simulate(system, method, h=T / n, steps=n, saveat=gnipy.SaveAt(t1=True))
        out.append(max(float(np.max(np.abs(sol.q[-1] - q_ex[-1]))), float(np.max(np.abs(sol.v[-1] - v_ex[-1])))))
    return np.asarray(out)


CASES = [
    # (method, model with an exact solution, step counts giving errors above round-off)
    ("yoshida4-gni-trapezoid", "rotating-table-ball", [10, 20, 40, 80]),
    ("kahanli6-mp", "knife-edge", [2, 4, 8, 16]),
    ("yoshida6-mp", "knife-edge", [3, 6, 12]),
    ("kahanli6-gni-trapezoid", "vertical-disk", [10, 20, 40, 80]),  # order 6 scheme on a GNI: order 4
]


@pytest.mark.parametrize("method,model,steps", CASES)
def test_fitted_order_matches_the_declared_order(method, model, steps, capsys):
    m = gnipy.get_method(method)
    errors = _errors(model, method, steps)
    h = T / np.asarray(steps)
    assert np.sum(errors > ROUND_OFF) >= 3, errors
    order = fitted_order(h, errors)
    with capsys.disabled():
        print(f"\n  {method:24s} {model:20s} fitted order {order:.2f} (declared {m.order}); errors "
              + " ".join(f"{e:.1e}" for e in errors))
    assert abs(order - m.order) <= ORDER_TOL, (order, errors)


class _Naive(Composition):
    """The triple jump without impulse rescaling and with the paper's start (for comparison)."""

    def _base(self):
        return self.base

    def step(self, system, state, h):
        for g in self.coefficients:
            state, info = self.base.step(system, state, g * h)
        return state, info

    def init(self, system, q0, v0, h):
        return self.base.init(system, q0, v0, h)


def test_without_rescaling_the_composed_gni_stays_of_order_2():
    naive = _Naive(gnipy.GNI(gnipy.Trapezoid()), "yoshida4")
    steps = [5, 10, 20, 40]
    errors = _errors("rotating-table-ball", naive, steps)
    assert abs(fitted_order(T / np.asarray(steps), errors) - 2.0) <= ORDER_TOL, errors
    rescaled = _errors("rotating-table-ball", "yoshida4-gni-trapezoid", steps)
    assert np.all(rescaled[1:] < errors[1:] / 10)


def test_consistent_start_carries_the_impulse_the_steps_leave():
    """With `start="consistent"` the hidden impulse p⁺ − p̄ stays −(h/2)μᵀλ to O(h³) relative to the
    impulse itself; from rest it does not (the paper's start leaves a free oscillation)."""
    system = gnipy.make_system("contact-oscillator")
    h = 0.01

    def mismatch(start):
        m = gnipy.GNI(gnipy.Trapezoid(), start=start)
        sol = gnipy.simulate(system, m, h=h, steps=40, saveat=gnipy.SaveAt(every=10, states=True))
        worst = 0.0
        for k in range(len(sol.t)):
            state = jax.tree_util.tree_map(lambda a: a[k], sol.states)
            hidden = m.hidden_momentum(system, state, h)
            _, lam = lagrange_dalembert_acceleration(system, state.b, sol.v[k])
            expected = -0.5 * h * system.mu(state.b).T @ lam
            worst = max(worst, float(np.max(np.abs(hidden - expected)) / np.max(np.abs(expected))))
        return worst

    assert mismatch("consistent") < 10 * h**2
    assert mismatch("rest") > 0.1


def test_start_is_checked():
    with pytest.raises(gnipy.InputError, match="start"):
        gnipy.GNI(gnipy.Trapezoid(), start="sideways")


def test_composition_coefficients_are_palindromic_and_consistent():
    for name, (order, gammas, _) in COMPOSITIONS.items():
        assert sum(gammas) == pytest.approx(1.0, abs=1e-14), name
        assert gammas == gammas[::-1], name
        # the order-3 condition Σγ³ = 0 of symmetric compositions of order ≥ 4
        assert abs(sum(g**3 for g in gammas)) < 1e-13, name
        if order >= 6:
            assert abs(sum(g**5 for g in gammas)) < 1e-13, name


def test_names_and_properties():
    m = gnipy.get_method("suzuki4-gni-midpoint")
    assert isinstance(m, Composition) and m.name == "suzuki4-gni-midpoint" and m.symmetric
    assert m.order == 4 and gnipy.get_method("yoshida6-gni-midpoint").order == GNI_COMPOSITION_ORDER
    assert gnipy.get_method("kahanli6-mp").order == 6
    assert gnipy.methods.is_method_name("yoshida4-mp") and not gnipy.methods.is_method_name("yoshida4-dla")
    with pytest.raises(gnipy.MethodError, match="not symmetric"):
        Composition(gnipy.get_method("gni-euler-a"), "yoshida4")
    with pytest.raises(gnipy.MethodError, match="unknown composition"):
        Composition(gnipy.get_method("mp"), "yoshida8")
    with pytest.raises(gnipy.MethodError, match="unknown method"):
        gnipy.get_method("yoshida4-dla")


def test_shortened_last_step_keeps_the_order():
    """t_final off the grid (half a step past T): the composition's last step is shortened, its
    impulse rescaled to the shorter first substep (change_step), and the order stays 4."""
    spec = gnipy.get_model("rotating-table-ball")
    hs = (0.1, 0.05, 0.025, 0.0125)
    errs = []
    for h in hs:
        t_final = T + 0.5 * h
        q_ex, _ = spec.exact(spec.params, np.asarray(spec.q0), np.asarray(spec.v0), np.array([t_final]))
        sol = gnipy.simulate(spec.system(), "yoshida4-gni-trapezoid", h=h, t_final=t_final, saveat=gnipy.SaveAt(t1=True))
        assert float(sol.t[-1]) == pytest.approx(t_final, abs=1e-14)
        errs.append(float(np.max(np.abs(sol.q[-1] - q_ex[-1]))))
    assert abs(fitted_order(hs, errs) - 4.0) <= ORDER_TOL, errs


def test_gni_state_is_unchanged_by_consistent_rescaling_of_zero_impulse():
    """change_step with the same size is the identity (the rescaling only touches the impulse)."""
    system = gnipy.make_system("contact-oscillator")
    m = GNI(gnipy.Trapezoid(), start="consistent")
    state = m.init(system, np.array([1.0, 1.0, 1.0]), np.array([-1.0, 1.0, 1.0]), 0.1)
    same = m.change_step(system, state, 0.1, 0.1)
    np.testing.assert_array_equal(np.asarray(same.p_plus), np.asarray(state.p_plus))
    flipped = m.change_step(system, state, 0.1, -0.1)  # σ: the impulse changes sign, p̄ stays
    _, v_bar, p_bar = m.observe(system, state, 0.1)
    np.testing.assert_allclose(np.asarray(flipped.p_plus - p_bar), -np.asarray(state.p_plus - p_bar), atol=1e-15)
