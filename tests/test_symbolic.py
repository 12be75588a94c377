"""gnipy.from_sympy: systems written with SymPy, against the zoo's hand-written models (an
independent formulation of the same physics) and against central differences; and what it refuses.

- The plain form with `dynamicsymbols`: the Chaplygin sleigh equals the zoo's bit for bit (the same
  arithmetic: measured 0.0).
- The plain form with plain symbols and affine constraints: the rotating-table ball (its Y is the
  shortest vector with μY = −c₀, not the zoo's (−Ωy, Ωx, 0, 0, 0); only μY enters the equations)
  equals the zoo's with four families of solves to round-off (measured ≤ 5e-14 over 200 steps,
  coordinates up to about 10).
- A `sympy.physics.mechanics.System`: the knife edge on an inclined plane with body-frame speeds
  (u₁ along the blade, u₂ sideways, u₃ = φ̇: kinematic equations that are not u = q̇), its
  constraint u₂ = 0 and gravity applied by `apply_uniform_gravity`, equals the zoo's knife edge
  (Bloch §1.6) to round-off, and both follow the exact solution.
- The tilted rolling disk as a mechanics System: gnipy's GNI converges at order 2 to SymPy's own
  equations of motion of that System (Kane's method) integrated by SciPy.
- A model this project did not write: SymBRiM's Whipple bicycle (T. J. Stienstra et al., the
  `symbrim` package: Moore's coordinates, knife-edge wheels, non-holonomic tires, one holonomic
  constraint), with the benchmark's parameters, gives the nine accelerations of Basu-Mandal,
  Chatterjee and Papadopoulos (Proc. R. Soc. A 463 (2007) 1983–2003) Table 1 to the table's digits,
  as the hand-written gnipy.models.whipple_bicycle does.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import sympy as sp  # the `sympy` extra, installed with [test] (through [all])
import sympy.physics.mechanics as me

import gnipy
from sympy_models import rolling_disk_system

#: numerics, and the verdicts at the saved nodes: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

T = me.dynamicsymbols._t


def _sleigh(params):
    x, y, th = me.dynamicsymbols("x y theta")
    m, I, a = sp.symbols("m I a")
    L = m / 2 * (x.diff(T) ** 2 + y.diff(T) ** 2) + I / 2 * th.diff(T) ** 2
    c = -sp.sin(th) * x.diff(T) + sp.cos(th) * y.diff(T) - a * th.diff(T)
    return gnipy.from_sympy(L, [x, y, th], constraints=[c], params={m: params["m"], I: params["I"], "a": params["a"]},
                            name="sympy-sleigh")


def _args(system):
    return {k: float(v) for k, v in system.args.items()}


def test_plain_form_with_dynamicsymbols_is_the_zoos_sleigh():
    zoo = gnipy.make_system("chaplygin-sleigh")
    sleigh = _sleigh(_args(zoo))
    assert sleigh.coordinates == ("x", "y", "theta") and not sleigh.is_affine
    assert set(sleigh.args) == {"m", "I", "a"} and sleigh.parameters == _args(zoo)
    q0, v0 = zoo.defaults[:2]
    a = gnipy.simulate(sleigh, "gni-midpoint", q0, v0, h=0.05, steps=100)
    b = gnipy.simulate(zoo, "gni-midpoint", q0, v0, h=0.05, steps=100)
    np.testing.assert_allclose(np.asarray(a.q), np.asarray(b.q), rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.asarray(a.v), np.asarray(b.v), rtol=0, atol=1e-14)
    assert a.healthy


def test_parameters_are_args_that_grad_reaches():
    """d q_x(T)/d a through the converted functions, against central differences of the same run."""
    zoo = gnipy.make_system("chaplygin-sleigh")
    sleigh = _sleigh(_args(zoo))
    q0, v0 = zoo.defaults[:2]

    def final_x(a):
        return gnipy.simulate(sleigh.with_args(a=a), "gni-midpoint", q0, v0, h=0.05, steps=40, project_v0=True).q[-1, 0]

    a, d = 0.5, 1e-6
    grad = float(jax.grad(final_x)(a))
    central = (float(final_x(a + d)) - float(final_x(a - d))) / (2 * d)
    assert abs(grad) > 1e-3
    np.testing.assert_allclose(grad, central, rtol=1e-6)


def test_one_model_converted_twice_shares_its_functions_and_runs_as_one_batch():
    zoo = gnipy.make_system("chaplygin-sleigh")
    first, second = _sleigh(_args(zoo)), _sleigh({**_args(zoo), "a": 0.2})
    assert first.lagrangian is second.lagrangian and first.constraints is second.constraints
    q0, v0 = zoo.defaults[:2]
    batch = gnipy.simulate([first, second], "gni-midpoint", q0, v0, h=0.05, steps=40, project_v0=True)
    assert batch.batch_size == 2
    for i, member in enumerate((first, second)):
        single = gnipy.simulate(member, "gni-midpoint", q0, v0, h=0.05, steps=40, project_v0=True)
        np.testing.assert_allclose(np.asarray(batch.q[i]), np.asarray(single.q), rtol=0, atol=1e-13)


def test_a_model_without_parameters():
    x, y, th = me.dynamicsymbols("x y theta")
    L = (x.diff(T) ** 2 + y.diff(T) ** 2) / 2 + th.diff(T) ** 2 / 4 - sp.Rational(1, 3) * sp.cos(th)
    sleigh = gnipy.from_sympy(L, [x, y, th], constraints=[-sp.sin(th) * x.diff(T) + sp.cos(th) * y.diff(T)])
    assert dict(sleigh.args) == {} and sleigh.parameters == {}
    q, v = np.array([0.1, 0.2, 0.7]), np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(float(sleigh.L(q, v)), 0.5 * (1 + 4) + 0.25 * 0.25 - np.cos(0.7) / 3, rtol=1e-15)
    np.testing.assert_allclose(np.asarray(sleigh.mu(q)), [[-np.sin(0.7), np.cos(0.7), 0.0]], rtol=1e-15)


@pytest.mark.parametrize("method", ["gni-midpoint", "mp", "dla", "discrete-gradient"])
def test_affine_constraints_the_rotating_table_ball(method):
    X = sp.symbols("x y theta1 theta2 theta3")
    V = sp.symbols("dx dy w1 w2 w3")
    m, I, r, W = sp.symbols("m I r Omega")
    L = m / 2 * (V[0] ** 2 + V[1] ** 2) + I / 2 * (V[2] ** 2 + V[3] ** 2 + V[4] ** 2)
    cons = [V[0] - r * V[3] + W * X[1], V[1] + r * V[2] - W * X[0]]  # (Cona), (Conb)
    zoo = gnipy.make_system("rotating-table-ball")
    ball = gnipy.from_sympy(L, X, speeds=V, constraints=cons, params=_args(zoo))
    assert ball.is_affine and ball.coordinates == ("x", "y", "theta1", "theta2", "theta3")
    q0, v0 = zoo.defaults[:2]
    a = gnipy.simulate(ball, method, q0, v0, h=0.05, steps=200)
    b = gnipy.simulate(zoo, method, q0, v0, h=0.05, steps=200)
    np.testing.assert_allclose(np.asarray(a.q), np.asarray(b.q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.v), np.asarray(b.v), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.constraint_residual), np.asarray(b.constraint_residual), rtol=0, atol=1e-12)
    assert a.healthy == b.healthy


def _knife_edge_system():
    """The knife edge on a plane inclined at α (N.x down the slope, N.z the plane's normal), with
    body-frame speeds and its sideways speed u₂ as the dependent one."""
    x, y, phi = me.dynamicsymbols("x y phi")
    u1, u2, u3 = me.dynamicsymbols("u1 u2 u3")
    m, J, g, alpha = sp.symbols("m J g alpha")
    N = me.ReferenceFrame("N")
    B = N.orientnew("B", "Axis", (phi, N.z))
    O = me.Point("O")
    O.set_vel(N, 0)
    P = O.locatenew("P", x * N.x + y * N.y)
    P.set_vel(N, x.diff(T) * N.x + y.diff(T) * N.y)
    system = me.System(N, O)
    system.add_bodies(me.RigidBody("blade", P, B, m, (me.inertia(B, 0, 0, J), P)))
    system.q_ind = [x, y, phi]
    system.u_ind = [u1, u3]
    system.u_dep = [u2]
    system.kdes = [u1 - (x.diff(T) * sp.cos(phi) + y.diff(T) * sp.sin(phi)),
                   u2 - (-x.diff(T) * sp.sin(phi) + y.diff(T) * sp.cos(phi)),
                   u3 - phi.diff(T)]
    system.add_nonholonomic_constraints(u2)
    system.apply_uniform_gravity(g * sp.sin(alpha) * N.x - g * sp.cos(alpha) * N.z)
    return system


def test_a_mechanics_system_the_knife_edge_on_an_incline():
    spec = gnipy.get_model("knife-edge")
    zoo = spec.system()
    knife = gnipy.from_sympy(_knife_edge_system(), params=spec.params, name="sympy-knife-edge")
    assert knife.coordinates == ("x", "y", "phi") and set(knife.args) == set(spec.params) and not knife.is_affine
    a = gnipy.simulate(knife, "gni-trapezoid", spec.q0, spec.v0, h=0.01, steps=300)
    b = gnipy.simulate(zoo, "gni-trapezoid", spec.q0, spec.v0, h=0.01, steps=300)
    np.testing.assert_allclose(np.asarray(a.q), np.asarray(b.q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.v), np.asarray(b.v), rtol=0, atol=1e-12)
    q_exact, _ = spec.exact(spec.params, spec.q0, spec.v0, np.asarray(a.t))
    error = np.max(np.abs(np.asarray(a.q) - q_exact))
    assert 1e-8 < error < 1e-2  # a second-order method's error at h = 0.01 over t = 3 (not round-off)


# ------------------------------------------------------------------------------------------------
# What it refuses, by argument
# ------------------------------------------------------------------------------------------------
def _refused(match, *args, **kwargs) -> str:
    """The message of the InputError that from_sympy raises on these arguments (it must match)."""
    with pytest.raises(gnipy.InputError, match=match) as raised:
        gnipy.from_sympy(*args, **kwargs)
    return str(raised.value)


def test_plain_form_refusals():
    x, y = sp.symbols("x y")
    dx, dy = sp.symbols("dx dy")
    k = sp.symbols("k")
    L = (dx ** 2 + dy ** 2) / 2
    c = [dx - y * dy]
    messages = []
    messages.append(_refused("coordinates is needed", L))
    messages.append(_refused("speeds is needed", L, [x, y], constraints=c))
    messages.append(_refused("speeds has 1 entries", L, [x, y], speeds=[dx], constraints=c))
    messages.append(_refused("params: no value for k", L + k * x, [x, y], speeds=[dx, dy], constraints=c))
    messages.append(_refused(r"params\['k'\]", L + k * x, [x, y], speeds=[dx, dy], constraints=c, params={k: "heavy"}))
    messages.append(_refused("degree \\[1\\]", L + x * dx, [x, y], speeds=[dx, dy], constraints=c))
    messages.append(_refused("not a polynomial", L + sp.cos(dx), [x, y], speeds=[dx, dy], constraints=c))
    messages.append(_refused("constraints\\[0\\] is not affine", L, [x, y], speeds=[dx, dy], constraints=[dx ** 2 - dy]))
    messages.append(_refused("no constraint given", L, [x, y], speeds=[dx, dy]))
    messages.append(_refused(r"holonomic\[0\] = -dy \+ x involves the velocities", L, [x, y], speeds=[dx, dy],
                             holonomic=[x - dy]))
    messages.append(_refused("repeats", L, [x, x], speeds=[dx, dy], constraints=c))
    messages.append(_refused("depends on t", L, [x, y], speeds=[dx, dy], constraints=[dx - sp.Symbol("t") * dy]))
    messages.append(_refused("model must be", "0.5*dx**2", [x, y], speeds=[dx, dy], constraints=c))
    # the arguments' types
    messages.append(_refused("constraints must be a sequence", L, [x, y], speeds=[dx, dy], constraints=c[0]))
    messages.append(_refused("coordinates must be a sequence", L, x, speeds=[dx, dy], constraints=c))
    messages.append(_refused("params must be a mapping", L, [x, y], speeds=[dx, dy], constraints=c, params=[1.0]))
    # speeds: distinct symbols that are not coordinates
    messages.append(_refused("speeds repeats", L, [x, y], speeds=[dy, dy], constraints=c))
    messages.append(_refused(r"speeds\[0\] = x must be a symbol that is not a coordinate", L, [x, y], speeds=[x, dy], constraints=c))
    # assumptions under which SymPy simplifies for some values only, and look-alike symbols
    xp = sp.Symbol("x", positive=True)
    messages.append(_refused(r"coordinates\[0\] = x carries an assumption", L - sp.Abs(xp), [xp, y], speeds=[dx, dy], constraints=c))
    messages.append(_refused("is not the coordinate or speed x", L - sp.Symbol("x", real=True), [x, y], speeds=[dx, dy], constraints=c))
    # the conversion's own names cannot be taken by a parameter
    clash = sp.Symbol("gnipy_q0")
    messages.append(_refused("gnipy_", L - clash * x, [x, y], speeds=[dx, dy], constraints=c, params={clash: 3.0}))
    # params: twice, unknown, not a Python name; the imaginary unit
    messages.append(_refused("gives 'k' twice", L + k * x, [x, y], speeds=[dx, dy], constraints=c, params={k: 1.0, "k": 2.0}))
    messages.append(_refused("mass is not a symbol of the model", L + k * x, [x, y], speeds=[dx, dy], constraints=c,
             params={k: 1.0, "mass": 2.0}))
    k1 = sp.Symbol("k_{1}")
    messages.append(_refused("not a Python name", L + k1 * x, [x, y], speeds=[dx, dy], constraints=c, params={k1: 1.0}))
    messages.append(_refused("imaginary unit", L + sp.I * x, [x, y], speeds=[dx, dy], constraints=c))
    # a constraint without velocities is holonomic; messages name the user's q and q̇
    messages.append(_refused(r"constraints\[0\] = x - 1 does not involve the velocities", L, [x, y], speeds=[dx, dy],
             constraints=[x - 1]))
    messages.append(_refused(r"not affine in the velocities: dx\*dy", L, [x, y], speeds=[dx, dy], constraints=[dx * dy]))
    messages.append(_refused(r"constraints\[0\]: a function gnipy cannot convert", L, [x, y], speeds=[dx, dy],
             constraints=[dx - sp.besselj(0, x) * dy]))
    f = sp.Function("f")
    messages.append(_refused(r"f\(x\) is not a coordinate, a velocity or a function", L - f(x), [x, y], speeds=[dx, dy], constraints=c))
    messages.append(_refused("a function gnipy cannot convert to JAX", L - sp.besselj(0, x), [x, y], speeds=[dx, dy], constraints=c))
    # every refusal names the function and the argument it is about, and none was swallowed
    assert len(messages) == 30 and all(m.startswith("from_sympy: ") for m in messages), messages


def test_mechanics_system_refusals():
    system = _knife_edge_system()
    with pytest.raises(gnipy.InputError, match="read from the mechanics System"):
        gnipy.from_sympy(system, [sp.Symbol("x")])
    spec = gnipy.get_model("knife-edge")
    # a function of time in a load that is not named as an input (a torque someone else sets)
    torqued = _knife_edge_system()
    torqued.add_loads(me.Torque(torqued.bodies[0].frame, me.dynamicsymbols("tau") * torqued.frame.z))
    with pytest.raises(gnipy.InputError, match=r"forces\[2\]: tau\(t\) is not a coordinate.*inputs=\[\.\.\.\]"):
        gnipy.from_sympy(torqued, params=spec.params)
    with pytest.raises(gnipy.InputError, match="coordinates, speeds, constraints, holonomic and forces are read"):
        gnipy.from_sympy(torqued, forces=[0, 0, 1], params=spec.params)
    sprung = _knife_edge_system()
    # kinematic equations: u in terms of q̇, linear in u with coefficients in q only
    x = sprung.q[0]
    u1 = sprung.u[0]
    for kde, match in ((u1 * x.diff(T) - x.diff(T), "coefficients that depend on q only"),
                       (u1 ** 2 - x.diff(T), "not linear in u")):
        bad = _knife_edge_system()
        bad.kdes = [kde, *bad.kdes[1:]]
        with pytest.raises(gnipy.InputError, match=match):
            gnipy.from_sympy(bad, params=spec.params)
    # a body, and a point a force acts on, with no position from the fixed point (the kinetic energy
    # is formed from the positions' derivatives, not from velocities set on the points)
    lost = _knife_edge_system()
    nowhere = me.Point("Q")
    nowhere.set_vel(lost.frame, 0)
    lost.add_bodies(me.Particle("bead", nowhere, sp.Symbol("m")))
    with pytest.raises(gnipy.InputError, match="kinetic energy of bead needs the position of its mass centre Q"):
        gnipy.from_sympy(lost, params=spec.params)
    pushed = _knife_edge_system()
    pushed.add_loads(me.Force(me.Point("P"), sp.Symbol("g") * pushed.frame.z))
    with pytest.raises(gnipy.InputError, match="needs its position from the System's fixed point"):
        gnipy.from_sympy(pushed, params=spec.params)


# ------------------------------------------------------------------------------------------------
# Loads: forces, torques, actuators and inputs, against forces written by hand
# ------------------------------------------------------------------------------------------------
def _loaded_knife_edge():
    """The knife edge on the incline with a torque τ(t) on the blade (an input), a damper −c u₁
    along the blade on its centre, and a linear spring (stiffness k, natural length l0) from the
    fixed point O to the centre (sympy.physics.mechanics' LinearSpring actuator)."""
    system = _knife_edge_system()
    blade = system.bodies[0]
    tau = me.dynamicsymbols("tau")
    c, k, l0 = sp.symbols("c k l0")
    system.add_loads(me.Torque(blade.frame, tau * system.frame.z),
                     me.Force(blade.masscenter, -c * system.u[0] * blade.frame.x))
    system.add_actuators(me.LinearSpring(k, me.LinearPathway(system.fixed_point, blade.masscenter), l0))
    return system, tau


def _hand_written_knife_edge_force(c, k, l0):
    """The same loads' generalized force on (x, y, φ), derived by hand: the damper's −c u₁ (cos φ,
    sin φ) with u₁ = ẋ cos φ + ẏ sin φ, the spring's −k(ℓ − l0)(x, y)/ℓ with ℓ = |(x, y)|, the torque
    on φ."""
    def force(q, v, u, t):
        x, y, phi = q[0], q[1], q[2]
        u1 = v[0] * jnp.cos(phi) + v[1] * jnp.sin(phi)
        ell = jnp.sqrt(x * x + y * y)
        pull = -k * (ell - l0) / ell
        return jnp.stack([-c * u1 * jnp.cos(phi) + pull * x, -c * u1 * jnp.sin(phi) + pull * y, u[0]])
    return force


def test_a_mechanics_systems_loads_are_the_hand_written_generalized_force():
    spec = gnipy.get_model("knife-edge")
    system, tau = _loaded_knife_edge()
    values = {"c": 0.3, "k": 2.0, "l0": 0.5}
    loaded = gnipy.from_sympy(system, inputs=[tau], params={**spec.params, **values}, name="loaded-knife-edge")
    assert loaded.inputs == 1 and loaded.is_forced and set(loaded.args) == {*spec.params, *values}
    by_hand = spec.system().with_force(_hand_written_knife_edge_force(**values), inputs=1)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q, v, u, t = rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 3), rng.uniform(-2, 2, 1), rng.uniform(0, 5)
        np.testing.assert_allclose(np.asarray(loaded._call_force(*loaded._args(q), v, u, t)),
                                   np.asarray(by_hand.force(q, v, u, t)), rtol=1e-13, atol=1e-13)
    # a driven run: the same motion step by step (the forced discrete Lagrange–d'Alembert principle)
    q0 = np.array([0.4, 0.2, 0.3])
    v0 = np.array([np.cos(0.3), np.sin(0.3), 1.0])
    controls = np.sin(0.05 * np.arange(200))[:, None]
    a = gnipy.simulate(loaded, "gni-trapezoid", q0, v0, h=0.01, steps=200, controls=controls)
    b = gnipy.simulate(by_hand, "gni-trapezoid", q0, v0, h=0.01, steps=200, controls=controls)
    assert a.healthy and float(np.max(np.abs(np.asarray(a.q[-1] - q0)))) > 0.5
    np.testing.assert_allclose(np.asarray(a.q), np.asarray(b.q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(a.v), np.asarray(b.v), rtol=0, atol=1e-12)


def _forced_sleighs(params, c):
    """The Chaplygin sleigh with a torque τ(t) (an input) and a viscous drag −c v on its contact
    point, three ways: a LagrangesMethod with a forcelist, the plain form with `forces`, and the
    zoo's sleigh with the force written by hand."""
    x, y, th = me.dynamicsymbols("x y theta")
    tau = me.dynamicsymbols("tau")
    m, I, a, drag = sp.symbols("m I a c")
    N = me.ReferenceFrame("N")
    B = N.orientnew("B", "Axis", (th, N.z))
    P = me.Point("P")
    P.set_vel(N, x.diff(T) * N.x + y.diff(T) * N.y)
    L = m / 2 * (x.diff(T) ** 2 + y.diff(T) ** 2) + I / 2 * th.diff(T) ** 2
    knife = -sp.sin(th) * x.diff(T) + sp.cos(th) * y.diff(T) - a * th.diff(T)
    values = {"m": params["m"], "I": params["I"], "a": params["a"], "c": c}
    method = me.LagrangesMethod(L, [x, y, th], forcelist=[(B, tau * N.z), (P, -drag * P.vel(N))], frame=N,
                                nonhol_coneqs=[knife])
    from_method = gnipy.from_sympy(method, inputs=[tau], params=values, name="lagranges-sleigh")
    plain = gnipy.from_sympy(L, [x, y, th], constraints=[knife], inputs=[tau], params=values,
                             forces=[-drag * x.diff(T), -drag * y.diff(T), tau], name="plain-sleigh")
    zoo = gnipy.make_system("chaplygin-sleigh").with_force(
        lambda q, v, u, t: jnp.stack([-c * v[0], -c * v[1], u[0]]), inputs=1)
    return from_method, plain, zoo


def test_a_lagranges_method_and_the_plain_forms_forces_are_the_forced_zoo_sleigh():
    zoo = gnipy.make_system("chaplygin-sleigh")
    systems = _forced_sleighs(_args(zoo), c=0.2)
    q0, v0 = zoo.defaults[:2]
    controls = 0.5 * np.cos(0.1 * np.arange(100))[:, None]
    runs = [gnipy.simulate(s, "gni-midpoint", q0, v0, h=0.05, steps=100, controls=controls) for s in systems]
    assert all(r.healthy for r in runs)
    for r in runs[:2]:
        np.testing.assert_allclose(np.asarray(r.q), np.asarray(runs[2].q), rtol=0, atol=1e-13)
        np.testing.assert_allclose(np.asarray(r.v), np.asarray(runs[2].v), rtol=0, atol=1e-13)
    # the drag takes energy out: the energy falls (the torque's work is small against it here)
    energy = np.asarray(runs[0].energy)
    assert energy[-1] < 0.9 * energy[0]


def test_a_force_that_depends_on_time():
    """forces in the time t (`dynamicsymbols._t`) without inputs: a periodic push on the sleigh's
    heading, against the same force written by hand."""
    x, y, th = me.dynamicsymbols("x y theta")
    A, w = sp.symbols("A omega")
    L = (x.diff(T) ** 2 + y.diff(T) ** 2) / 2 + th.diff(T) ** 2 / 4
    knife = -sp.sin(th) * x.diff(T) + sp.cos(th) * y.diff(T) - th.diff(T) / 5
    pushed = gnipy.from_sympy(L, [x, y, th], constraints=[knife], forces=[0, 0, A * sp.sin(w * T)],
                              params={A: 0.7, w: 3.0})
    assert pushed.inputs == 0 and pushed.is_forced
    for t in (0.0, 0.3, 1.7):
        np.testing.assert_allclose(np.asarray(pushed._call_force(*pushed._args(np.zeros(3)), np.ones(3), jnp.zeros(0), t)),
                                   [0.0, 0.0, 0.7 * np.sin(3.0 * t)], rtol=1e-15, atol=1e-16)


def test_load_refusals():
    x, y, th = me.dynamicsymbols("x y theta")
    tau, other = me.dynamicsymbols("tau other")
    L = (x.diff(T) ** 2 + y.diff(T) ** 2) / 2 + th.diff(T) ** 2 / 4
    knife = [-sp.sin(th) * x.diff(T) + sp.cos(th) * y.diff(T)]
    for kwargs, match in (
        (dict(forces=[0, 0]), "forces has 2 entries for 3 coordinates"),
        (dict(forces=[0, 0, 1], inputs=[tau]), r"inputs\[0\] = tau\(t\) does not appear in the forces"),
        (dict(inputs=[tau]), "inputs are given but the model has no forces"),
        (dict(forces=[0, 0, tau], inputs=[tau, tau]), "inputs repeats a symbol"),
        (dict(forces=[0, 0, tau], inputs=[x]), r"inputs\[0\] = x\(t\) is a coordinate"),
        (dict(forces=[0, 0, tau + other], inputs=[tau]), r"forces\[2\]: other\(t\) is not a coordinate"),
        (dict(forces=[0, 0, tau], inputs=[tau + 1]), "neither a symbol nor a dynamicsymbol"),
    ):
        with pytest.raises(gnipy.InputError, match=match):
            gnipy.from_sympy(L, [x, y, th], constraints=knife, **kwargs)
    with pytest.raises(gnipy.InputError, match="params must be a mapping"):
        gnipy.from_sympy(L, [x, y, th], constraints=knife, forces=[0, 0, tau], inputs=[tau], params=5)
    with pytest.raises(gnipy.InputError, match=r"model involves inputs\[0\] = tau\(t\)"):
        gnipy.from_sympy(L + tau * th, [x, y, th], constraints=knife, forces=[0, 0, tau], inputs=[tau])
    N = me.ReferenceFrame("N")
    unframed = me.LagrangesMethod(L, [x, y, th], forcelist=[(N, tau * N.z)], nonhol_coneqs=knife)
    with pytest.raises(gnipy.InputError, match="has loads but no frame"):
        gnipy.from_sympy(unframed, inputs=[tau])
    speeds = me.dynamicsymbols("u1:4")
    kane = me.KanesMethod(N, q_ind=[x, y, th], u_ind=speeds,
                          kd_eqs=[c.diff(T) - u for c, u in zip((x, y, th), speeds)])
    with pytest.raises(gnipy.InputError, match="KanesMethod.*as a sympy.physics.mechanics.System"):
        gnipy.from_sympy(kane)


def test_the_rolling_disk_converges_to_sympys_own_equations_of_motion():
    """The tilted rolling disk, built once as a sympy.physics.mechanics System: gnipy's GNI on the
    System that from_sympy makes (l = T − V and the constraints, differentiated by JAX) converges at
    order 2 to the motion of SymPy's own equations (Kane's method, `System.form_eoms` and `rhs`,
    integrated by SciPy's DOP853 at rtol = atol = 1e-13): two formulations that share only the
    model's description. Measured: errors 0.111, 0.0280, 0.00701 at h = 0.01, 0.005, 0.0025
    (t = 1, a lean of 0.3 rad, spin 3 rad/s, heading rate 1 rad/s): slope 1.99."""
    from scipy.integrate import solve_ivp

    system = rolling_disk_system()
    params = {"m": 1.0, "R": 0.5, "g": 9.81}
    disk = gnipy.from_sympy(system, params=params, name="rolling-disk")
    assert disk.coordinates == ("x", "y", "psi", "theta", "phi") and not disk.is_affine

    system.form_eoms()
    rhs = sp.lambdify([[*system.q, *system.u], sp.symbols("m R g")], system.rhs(), "numpy")
    # the state: q, then u in the System's order (independent, then dependent): ψ̇, θ̇, φ̇, ẋ, ẏ
    spin, lean, heading_rate = 3.0, 0.3, 1.0
    u0 = [heading_rate, 0.0, spin, params["R"] * spin, 0.0]  # ẋ = Rφ̇ cos ψ, ẏ = Rφ̇ sin ψ at ψ = 0
    q0 = [0.0, 0.0, 0.0, lean, 0.0]
    t_final = 1.0
    ref = solve_ivp(lambda t, s: np.ravel(rhs(s, list(params.values()))).astype(float), (0.0, t_final),
                    [*q0, *u0], method="DOP853", rtol=1e-13, atol=1e-13)
    assert ref.success

    v0 = [u0[3], u0[4], u0[0], u0[1], u0[2]]  # q̇ in the order of q
    hs = np.array([0.01, 0.005, 0.0025])
    errors = []
    for h in hs:
        sol = gnipy.simulate(disk, "gni-trapezoid", q0, v0, h=float(h), steps=int(round(t_final / h)),
                             saveat=gnipy.SaveAt(t1=True))
        assert sol.healthy
        errors.append(np.max(np.abs(np.asarray(sol.q[-1]) - ref.y[:5, -1])))
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.9 < slope < 2.1, (errors, slope)
    assert errors[-1] < 1e-2


def _pendulum_mechanics_system():
    """The spherical pendulum as a particle at (x, y, z) held at distance l from the origin: a
    sympy.physics.mechanics System with a holonomic constraint and gravity."""
    x, y, z = me.dynamicsymbols("x y z")
    m, g, l = sp.symbols("m g l")
    N = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(N, 0)
    P = O.locatenew("P", x * N.x + y * N.y + z * N.z)
    P.set_vel(N, x.diff(T) * N.x + y.diff(T) * N.y + z.diff(T) * N.z)
    system = me.System(N, O)
    system.q_ind = [x, y, z]
    system.u_ind = [x.diff(T), y.diff(T), z.diff(T)]
    system.add_bodies(me.Particle("bob", P, m))
    system.apply_uniform_gravity(-g * N.z)
    system.add_holonomic_constraints(x**2 + y**2 + z**2 - l**2)
    return system


def test_mechanics_system_with_a_holonomic_constraint():
    """A sympy.physics.mechanics System with a holonomic constraint runs as the hand-written
    pendulum of tests/test_holonomic.py (φ = (|q|² − l²)/2 there: the same surface, a multiple
    of the multiplier) to round-off, and keeps its constraint at round-off."""
    import jax.numpy as jnp

    pendulum = gnipy.from_sympy(_pendulum_mechanics_system(), params={"m": 1.0, "g": 9.81, "l": 1.0}, name="pendulum")
    assert pendulum.constraints is None and pendulum.holonomic is not None

    def lagrangian(q, v):
        return 0.5 * v @ v - 9.81 * q[2]

    hand = gnipy.System(lagrangian, None, holonomic=lambda q: jnp.array([0.5 * (q @ q - 1.0)]), n=3)
    q0, v0 = np.array([np.sin(1.0), 0.0, -np.cos(1.0)]), np.array([0.0, 1.2, 0.0])
    a = gnipy.simulate(pendulum, "gni-trapezoid", q0, v0, h=0.01, steps=300)
    b = gnipy.simulate(hand, "gni-trapezoid", q0, v0, h=0.01, steps=300)
    assert np.max(np.abs(np.asarray(a.q) - np.asarray(b.q))) < 1e-13
    assert np.max(np.abs(np.sum(np.asarray(a.q) ** 2, axis=1) - 1.0)) < 1e-15


def _symbrim_whipple():
    """SymBRiM's Whipple bicycle as a sympy.physics.mechanics System, gravity along −ground.normal,
    with the benchmark's parameters in Moore's set (J. K. Moore, *Human control of a bicycle*, UC
    Davis 2012: the relations of `dtk.bicycle.benchmark_to_moore`), as the bicycle benchmark builds
    it (benchmarks/bicycle.py), converted by from_sympy."""
    import pathlib
    import sys

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # benchmarks/ is not installed
    from benchmarks.bicycle import symbrim_bicycle

    system, values = symbrim_bicycle()
    return gnipy.from_sympy(system, params=values, name="symbrim-whipple")


def test_symbrims_whipple_bicycle_gives_basu_mandal_table_1():
    import jax.numpy as jnp

    from gnipy.compilation import jit
    from gnipy.equations import lagrange_dalembert_acceleration
    from gnipy.models import whipple_bicycle as wb

    bicycle = _symbrim_whipple()
    # its coordinates are Moore's q1..q8 (contact point, yaw, roll, pitch, rear wheel, steer, front
    # wheel) in SymBRiM's order; from the hand-written model's: pitch + λ, the rear wheel's angle from
    # the rear frame (the hand-written one's is from the yaw-roll frame, so minus the pitch)
    table = wb.BASU_MANDAL_TABLE1
    ours, ours_dot = wb.from_basu_mandal(table["q"], table["qdot"])
    lam = wb.BENCHMARK["lam"]

    def moore(x, pitch_offset):
        m = dict(zip((f"bicycle_q{i}" for i in range(1, 9)), x))
        m["bicycle_q5"] = x[4] + pitch_offset
        m["bicycle_q6"] = x[5] - x[4]
        return np.array([m[name] for name in bicycle.coordinates])

    order = [int(name.removeprefix("bicycle_q")) - 1 for name in bicycle.coordinates]
    q, qdot = moore(ours, lam), moore(ours_dot, 0.0)
    # the state is on SymBRiM's constraints: the coordinates are the same
    assert abs(float(bicycle.phi(jnp.asarray(q))[0])) < 1e-12
    assert np.max(np.abs(np.asarray(bicycle.mu(jnp.asarray(q)) @ qdot))) < 1e-12
    acceleration = jit(lambda s, x, xd: lagrange_dalembert_acceleration(s, x, xd)[0])
    a = np.asarray(acceleration(bicycle, jnp.asarray(q), jnp.asarray(qdot)))
    a_moore = np.empty(8)
    a_moore[order] = a
    a_ours = a_moore.copy()
    a_ours[5] = a_moore[5] + a_moore[4]  # back to the hand-written model's rear wheel angle
    theirs = wb.basu_mandal_accelerations(ours, ours_dot, a_ours)
    # the table gives 13 decimals (measured: ≤ 1.1e-12 absolute, on the steer acceleration, as the
    # hand-written model: tests/models/test_whipple_bicycle.py)
    np.testing.assert_allclose(theirs, np.array(table["qddot"]), rtol=0, atol=2e-12)


def _sympys_nonminimal_pendulum():
    """SymPy's own example "Nonminimal Coordinates Pendulum" (the sympy.physics.mechanics tutorial,
    Lagrange's method), as the tutorial writes it: the mass at (q1, q2) with N.x down, the
    Lagrangian of the particle (kinetic energy only), gravity m g N.x as a load, and the holonomic
    constraint q1² + q2² − L² = 0."""
    q1, q2 = me.dynamicsymbols("q1:3")
    L, m, g = sp.symbols("L, m, g")
    N = me.ReferenceFrame("N")
    pN = me.Point("N*")
    pN.set_vel(N, 0)
    P = pN.locatenew("P1", q1 * N.x + q2 * N.y)
    P.set_vel(N, P.pos_from(pN).dt(N))
    pP = me.Particle("pP", P, m)
    f_c = sp.Matrix([q1 ** 2 + q2 ** 2 - L ** 2])
    return me.LagrangesMethod(me.Lagrangian(N, pP), [q1, q2], hol_coneqs=f_c, forcelist=[(P, m * g * N.x)], frame=N)


def test_sympys_nonminimal_pendulum_example():
    """The tutorial's linearization about hanging at rest, A = [[0, 1], [−g/L, 0]] (eigenvalues
    ±i√(g/L)), from gnipy's `linearize`; and a large swing against the pendulum's own equation
    θ̈ = −(g/L) sin θ (DOP853 at 1e-12), with the holonomic constraint at round-off and the energy
    ½m|q̇|² − m g q1 kept (a conserved quantity, computed here from the run)."""
    from scipy.integrate import solve_ivp

    values = {"L": 1.3, "m": 0.7, "g": 9.81}
    pendulum = gnipy.from_sympy(_sympys_nonminimal_pendulum(), params=values, name="sympy-nonminimal-pendulum")
    assert pendulum.is_forced and pendulum.inputs == 0 and pendulum.holonomic is not None
    lin = gnipy.linearize(pendulum, [values["L"], 0.0], [0.0, 0.0])
    np.testing.assert_allclose(np.sort(lin.eigenvalues.imag), [-np.sqrt(9.81 / 1.3), np.sqrt(9.81 / 1.3)], rtol=1e-12)
    np.testing.assert_allclose(lin.eigenvalues.real, 0.0, atol=1e-12)
    theta0 = 2.0  # from rest at 2 rad from the vertical (beyond the horizontal)
    q0 = values["L"] * np.array([np.cos(theta0), np.sin(theta0)])
    h, steps = 0.001, 3000
    run = gnipy.simulate(pendulum, "gni-trapezoid", q0, [0.0, 0.0], h=h, steps=steps)
    assert run.healthy
    exact = solve_ivp(lambda t, y: [y[1], -9.81 / 1.3 * np.sin(y[0])], (0.0, h * steps), [theta0, 0.0],
                      method="DOP853", rtol=1e-12, atol=1e-12, t_eval=np.asarray(run.t))
    q_exact = values["L"] * np.stack([np.cos(exact.y[0]), np.sin(exact.y[0])], axis=1)
    error = np.max(np.abs(np.asarray(run.q) - q_exact))
    assert 1e-8 < error < 1e-4  # second order at h = 0.001 over about 1.2 periods, not round-off
    q, v = np.asarray(run.q), np.asarray(run.v)
    assert np.max(np.abs(np.sum(q * q, axis=1) - 1.3 ** 2)) < 1e-13
    energy = 0.5 * 0.7 * np.sum(v * v, axis=1) - 0.7 * 9.81 * q[:, 0]
    assert np.max(np.abs(energy - energy[0])) < 1e-4 * abs(energy[0])
