"""gnipy.analysis.modified_equations: the modified vector field of a method's one-step map against
closed forms (linear oscillator) and, on a nonholonomic system, against the discrete trajectory
itself: the modified field's flow follows it one order closer than the vector field's."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnipy
from gnipy.analysis import fitted_order, modified_equations
from gnipy.errors import InputError, MethodError

#: the harmonic oscillator in the plane (x, y) with a third coordinate held still by ż = 0: unconstrained
#: motion in (x, y), so the methods are the variational integrators of ½|v|² − ½|q|²
OSCILLATOR = gnipy.System(lagrangian=lambda q, v: 0.5 * v @ v - 0.5 * q[:2] @ q[:2],
                          constraints=lambda q: jnp.array([[0.0, 0.0, 1.0]]), coordinates=("x", "y", "z"))
Q0, V0 = [0.3, -0.2, 0.0], [0.5, 0.1, 0.0]
#: the oscillator's vector field on (q, p): q' = p, p' = −q (z and its momentum still)
A = np.zeros((6, 6))
A[0, 3] = A[1, 4] = A[2, 5] = 1.0
A[3, 0] = A[4, 1] = -1.0
A[5, 5] = 0.0


def test_the_midpoint_gni_on_the_oscillator_has_the_implicit_midpoint_modified_equation():
    # For a quadratic Lagrangian the midpoint discrete Lagrangian gives the implicit midpoint rule on
    # (q, p): Φ_h = (I − hA/2)⁻¹(I + hA/2) = exp(2 artanh(hA/2)), so f̃ = A + h²A³/12 + h⁴A⁵/80 + …:
    # f_1 = Ay, f_2 = 0, f_3 = A³y/12 (Hairer–Lubich–Wanner IX.1)
    me = modified_equations(OSCILLATOR, "gni-midpoint", order=2, q=Q0, v=V0)
    assert me.fields == ("b", "p_plus")
    y = me.state(Q0, V0, 0.01)
    f1, f2, f3 = (np.asarray(f) for f in jax.jit(me.coefficients)(y))
    y = np.asarray(y)
    np.testing.assert_allclose(f1, A @ y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f2, 0.0, rtol=0, atol=1e-11)
    np.testing.assert_allclose(f3, np.linalg.matrix_power(A, 3) @ y / 12, rtol=0, atol=1e-9)


def test_the_euler_gni_on_the_oscillator_has_symplectic_eulers_modified_equation():
    # gni-euler-a on ½|v|² − ½|q|² is p₁ = p₀ − hq₀, q₁ = q₀ + hp₁ (l_d = h l(q₀, (q₁ − q₀)/h)), so
    # Φ_h = I + hB₁ + h²B₂ with B₁ = A, B₂ = [[−I, 0], [0, 0]] on (q, p), and log Φ_h/h gives
    # f_2 = B₂ − B₁²/2 = [[−I/2, 0], [0, I/2]]: f̃ = (p − hq/2, −q + hp/2) + O(h²)
    me = modified_equations(OSCILLATOR, "gni-euler-a", order=1, q=Q0, v=V0)
    y = me.state(Q0, V0, 0.1)
    q, p = np.asarray(y[:3]), np.asarray(y[3:])
    np.testing.assert_allclose(np.asarray(me.step_map(y, 0.1)), np.concatenate([q + 0.1 * (p - 0.1 * q), p - 0.1 * q]),
                               rtol=0, atol=1e-15)
    f1, f2 = (np.asarray(f) for f in jax.jit(me.coefficients)(y))
    np.testing.assert_allclose(f1, A @ np.asarray(y), rtol=0, atol=1e-12)
    np.testing.assert_allclose(f2, np.concatenate([-q / 2, p / 2]) * [1, 1, 0, 1, 1, 0], rtol=0, atol=1e-10)


PARTICLE = gnipy.System(lagrangian=lambda q, v: 0.5 * v @ v - 0.5 * (q[0] ** 2 + q[1] ** 2),
                        constraints=lambda q: jnp.array([[-q[1], 0.0, 1.0]]), coordinates=("x", "y", "z"))
P_Q0, P_V0 = [1.0, 1.0, 0.0], [1.0, 0.0, 1.0]


def test_the_modified_field_follows_the_discrete_trajectory_two_orders_closer():
    # the nonholonomic particle (ż = y ẋ in a harmonic well) with mp, a symmetric method of order 2
    # whose state (q, v) stays on the constraints: over T = 1 the flow of the vector field f_1 leaves
    # the discrete trajectory at O(h²), the flow of the modified field f_1 + h f_2 + h² f_3 at O(h⁴)
    # (f_4 = 0 for a symmetric method), integrated by DOP853 at 1e-13, an independent solver
    me = modified_equations(PARTICLE, "mp", order=2, q=P_Q0, v=P_V0)
    assert me.fields == ("q", "v")
    step = jax.jit(me.step_map)
    fs = [jax.jit(me.coefficient(j)) for j in (1, 2, 3)]
    hs = [0.2, 0.1, 0.05]
    plain, modified = [], []
    for h in hs:
        y = me.state(P_Q0, P_V0, h)
        y0 = np.asarray(y)
        for _ in range(round(1.0 / h)):
            y = step(y, h)
        for fields, errors in ((fs[:1], plain), (fs, modified)):
            def rhs(_, x, fields=fields, h=h):
                x = jnp.asarray(x)
                return np.asarray(sum(h ** j * f(x) for j, f in enumerate(fields)))

            sol = solve_ivp(rhs, (0.0, 1.0), y0, method="DOP853", rtol=1e-13, atol=1e-13)
            errors.append(np.max(np.abs(sol.y[:, -1] - np.asarray(y))))
    assert fitted_order(hs, plain) == pytest.approx(2.0, abs=0.15)
    assert fitted_order(hs, modified) == pytest.approx(4.0, abs=0.3)
    assert modified[-1] < plain[-1] / 100


def test_the_gni_is_its_reflection_after_the_flow_of_its_modified_field():
    # from (q, v) the GNI's p⁺ carries its starting impulse, and as h → 0 its step tends to the
    # reflection σ (Comb), p⁺ ↦ p⁻, not to the identity: the field expanded is that of σ∘Φ_h. With
    # gni-euler-a (order 1) on the particle, one step against σ after the flow for time h (DOP853 at
    # 1e-13): with f_1 alone the local error is O(h²) and after t = 1 O(h); with f_1 + h f_2 O(h³), O(h²)
    me = modified_equations(PARTICLE, "gni-euler-a", order=1, q=P_Q0, v=P_V0)
    assert me.reflected and me.fields == ("b", "p_plus")
    step, reflect = jax.jit(me.step_map), jax.jit(me.reflect)
    fs = [jax.jit(me.coefficient(1)), jax.jit(me.coefficient(2))]
    hs = [0.1, 0.05, 0.025]
    local, after = {1: [], 2: []}, {1: [], 2: []}
    for h in hs:
        y0 = me.state(P_Q0, P_V0, h)
        for k in (1, 2):
            def flow(x, k=k, h=h):
                rhs = lambda _, x: np.asarray(sum(h ** j * f(jnp.asarray(x)) for j, f in enumerate(fs[:k])))  # noqa: E731
                return solve_ivp(rhs, (0.0, h), np.asarray(x), method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]

            local[k].append(np.max(np.abs(flow(y0) - np.asarray(step(y0, h)))))
            x, y = np.asarray(y0), y0
            for _ in range(round(1.0 / h)):  # the method: σ∘(σ∘Φ_h) = Φ_h; the model: σ after the flow
                x, y = np.asarray(reflect(flow(x))), reflect(step(y, h))
            after[k].append(np.max(np.abs(x - np.asarray(y))))
    assert fitted_order(hs, local[1]) == pytest.approx(2.0, abs=0.15)
    assert fitted_order(hs, local[2]) == pytest.approx(3.0, abs=0.2)
    assert fitted_order(hs, after[1]) == pytest.approx(1.0, abs=0.15)
    assert fitted_order(hs, after[2]) == pytest.approx(2.0, abs=0.15)


@pytest.mark.parametrize("method", ["shake", "euler-a"])
def test_a_state_that_a_step_changes_at_any_h_is_refused_with_the_reason(method):
    # shake carries the increments q_(k+1) − q_k and q_k − q_(k−1), the paper's euler-a the multiplier
    # λ/h: as h → 0 a step still changes them by O(1), with or without a reflection
    with pytest.raises(MethodError, match="does not tend to the identity"):
        modified_equations(PARTICLE, method, order=0, q=P_Q0, v=P_V0)


def test_dla_starts_near_the_identity_and_leaves_it_at_order_one():
    # dla starts from p⁺ = G v₀ on the constraints (defect 0), but after one step its velocity G⁻¹p⁺
    # misses them by O(h), where the map at h → 0 projects again: the defect is O(h), first order
    me = modified_equations(PARTICLE, "dla", order=0, q=P_Q0, v=P_V0)
    defect = jax.jit(me.defect)
    hs, after = [0.1, 0.05, 0.025], []
    for h in hs:
        y = me.state(P_Q0, P_V0, h)
        assert float(defect(y)) <= 1e-13
        after.append(float(defect(me.step_map(y, h))))
    assert fitted_order(hs, after) == pytest.approx(1.0, abs=0.15)


@pytest.mark.parametrize("kwargs, message", [
    ({"order": -1}, "order"), ({"order": 1.5}, "order"), ({"nodes": 0}, "nodes"), ({"delta": 0.0}, "delta"),
    ({"steps": 0}, "steps"),
])
def test_bad_arguments_are_refused_by_name(kwargs, message):
    with pytest.raises(InputError, match=message):
        modified_equations(OSCILLATOR, "gni-midpoint", q=Q0, v=V0, **kwargs)


def test_on_a_group_the_orientation_moves_along_the_group_at_every_order():
    # the paper's ball on the turning table (R^2 x SO(3), Cayley): R enters y as its 9 entries. The step
    # keeps R on SO(3), so each f_j's R-part is R times a skew matrix; at first order it is the
    # reconstruction Ṙ = R ξ̂ with ξ the start's angular velocity (dla starts from p⁺ = G v₀ on the
    # constraints), and ẋ = the start's velocity (extrapolation error about 1e-8 here)
    ball = gnipy.model_systems("rolling-ball")[0]
    q0, v0 = ball.defaults[:2]
    me = modified_equations(ball, "dla", order=1)
    assert me.fields == ("b", "p_plus") and me.sizes == (11, 5) and not me.reflected
    y = me.state(q0, v0, 0.05)
    R = np.asarray(y[2:11]).reshape(3, 3)
    f1, f2 = (np.asarray(f) for f in jax.jit(me.coefficients)(y))
    xi = np.asarray(v0[2:])
    hat = np.array([[0.0, -xi[2], xi[1]], [xi[2], 0.0, -xi[0]], [-xi[1], xi[0], 0.0]])
    np.testing.assert_allclose(f1[:2], v0[:2], rtol=0, atol=1e-7)
    np.testing.assert_allclose(R.T @ f1[2:11].reshape(3, 3), hat, rtol=0, atol=1e-7)
    A = R.T @ f2[2:11].reshape(3, 3)
    np.testing.assert_allclose(A + A.T, 0.0, rtol=0, atol=1e-7)
    assert modified_equations(ball, "gni-midpoint", order=0).reflected


def test_two_midpoint_gni_steps_are_the_flow_of_the_half_step_modified_field():
    # two GNI steps of h/2 (steps=2): σ² = id, so the map tends to the identity without a reflection;
    # on the oscillator from the consistent start (no hidden momentum: z is still) they are two
    # implicit midpoint steps of h/2, whose field is A + (h/2)²A³/12: f_2 = 0, f_3 = A³y/48
    me = modified_equations(OSCILLATOR, "gni-midpoint", order=2, q=Q0, v=V0, steps=2)
    assert not me.reflected and me.steps == 2
    y = me.state(Q0, V0, 0.01)
    f1, f2, f3 = (np.asarray(f) for f in jax.jit(me.coefficients)(y))
    np.testing.assert_allclose(f1, A @ np.asarray(y), rtol=0, atol=1e-12)
    np.testing.assert_allclose(f2, 0.0, rtol=0, atol=1e-11)
    np.testing.assert_allclose(f3, np.linalg.matrix_power(A, 3) @ np.asarray(y) / 48, rtol=0, atol=1e-9)
    # the implicit midpoint rule conserves quadratic invariants: every f_j is tangent to E = const
    # (yᵀA³y = 0 for the oscillator's A)
    grad_E = np.asarray(jax.grad(me.energy)(y))
    assert max(abs(grad_E @ f) for f in (f1, f2, f3)) < 1e-11
    assert abs(float(me.energy_rate(y, 1)) - grad_E @ f1) < 1e-12
    # the constraint ż = 0 holds at every order: μ f_j,q is z's velocity, zero in every f_j
    assert max(abs(f[2]) for f in (f1, f2, f3)) < 1e-11
    np.testing.assert_allclose(np.asarray(me.normal_velocity(y, 1)), [f1[2]], rtol=0, atol=1e-15)


def test_on_se2_the_divergence_is_the_continuous_fields_and_the_gnis_vanishes():
    # the Chaplygin sleigh on SE(2): the state is (g, p) with p the left-trivialized momentum, whose
    # phase volume (Haar x Lebesgue) is the Liouville volume. f_1 of a method whose state is (g, p) is
    # the continuous field, ġ = gξ̂ and ṗ = 𝕀a(ξ) with a constant body metric 𝕀: its divergence is
    # tr ∂a/∂ξ, from the Lagrange–d'Alembert equations (gnipy.equations, an independent formulation:
    # no step, no extrapolation), -2/5 at the documented start. The GNI's two steps of h/2 have a map
    # of determinant (-1)² = 1: its field is divergence-free. The normal velocity μ(g)ξ of f_1 vanishes
    # (the motion keeps the constraint), read off f_1's matrix part through ξ̂ = g⁻¹ġ.
    from gnipy.equations import lagrange_dalembert_acceleration

    sleigh = gnipy.make_system("chaplygin-sleigh-se2")
    q0, v0 = sleigh.defaults[:2]
    b0 = sleigh.initial_point(q0)
    v0 = jnp.asarray(v0, dtype=jnp.float64)
    exact = float(jnp.trace(jax.jacfwd(lambda v: lagrange_dalembert_acceleration(sleigh.without_metadata(), b0, v)[0])(v0)))
    # on the constraint it is the reduced equations' u̇ = aω², ω̇ = -m a u ω/(I + m a²) (Bloch §1.7; u the
    # contact point's forward velocity): ∂ω̇/∂ω = -m a u/(I + m a²) = -0.5/1.25 at u = 1
    assert abs(exact + 0.4) < 1e-12
    for method, steps, divergence in (("sgni-trapezoid", 1, exact), ("gni-midpoint", 2, 0.0)):
        me = modified_equations(sleigh, method, order=0, steps=steps, nodes=3)
        y = me.state(q0, v0, 0.01)
        div, normal = jax.jit(lambda y: (me.divergence(y), me.normal_velocity(y, 1)))(y)
        assert abs(float(div) - divergence) < 1e-6, (method, float(div))
        assert float(jnp.max(jnp.abs(normal))) < 1e-7, (method, normal)
        # the configuration velocity is ξ itself at the start
        np.testing.assert_allclose(np.asarray(me.configuration_velocity(y, me.coefficient(1)(y))), v0, rtol=0,
                                   atol=1e-6)
