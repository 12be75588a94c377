"""Forces and inputs in every method (issue 15): the discrete forced Lagrange–d'Alembert form.

Measured against the continuous reference (Dopri8, rtol 1e-12): the symmetric methods keep order 2
with a time-dependent input u(t) and a velocity-dependent (damping) force, on the Chaplygin sleigh
(on R^3) and on Suslov's problem (SO(3), a body torque); a composition keeps order 4. Also: an exact
answer (uniform acceleration along a knife edge), exact constraints, F = 0 changes nothing, held
inputs, the discrete-gradient method's energy balance, the refusals, and a gradient with respect
to the controls.

Kept cheap (the whole suite is over its time budget): the references are module fixtures and each
fit uses three step counts.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import InputError, MethodError, SaveAt, make_system, simulate
from gnipy.compilation import jit as gnipy_jit

#: numerics, not verdicts: simulate checks the saved nodes only (tests/conftest.py)
CHECK_EVERY_NODE = False

T = 1.0
NS = (10, 20, 40)


def signal(t):
    """A smooth input u(t)."""
    return jnp.array([jnp.sin(2.0 * t)])


def sleigh_force(q, v, u, t):
    """A torque on the heading: the input, minus a damping of the turning rate."""
    return jnp.array([0.0, 0.0, u[0] - 0.1 * v[2]])


def suslov_force(x, v, u, t):
    """A body torque: the input about axis 1, an explicit time dependence about axis 2, a constant
    part about axis 3 (normal to the allowed plane: absorbed by the constraint), and damping."""
    return jnp.array([u[0], 0.3 * jnp.cos(t) - 0.2 * v[1], 0.1]) - 0.1 * v


def configuration(sol, k=-1):
    parts = [np.asarray(sol.q[k]).ravel()]
    if sol.R is not None:
        parts.append(np.asarray(sol.R[k]).ravel())
    return np.concatenate(parts)


def node(sol, k=-1):
    return np.concatenate([configuration(sol, k), np.asarray(sol.v[k]).ravel()])


def slope(hs, errs):
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0])


@pytest.fixture(scope="module")
def sleigh():
    return make_system("chaplygin-sleigh").with_force(sleigh_force, inputs=1)


@pytest.fixture(scope="module")
def suslov():
    return make_system("suslov").with_force(suslov_force, inputs=1)


@pytest.fixture(scope="module")
def sleigh_ref(sleigh):
    return simulate(sleigh, "reference", h=0.01, t_final=T, controls=signal, saveat=SaveAt(t1=True))


@pytest.fixture(scope="module")
def suslov_ref(suslov):
    return simulate(suslov, "reference", h=0.01, t_final=T, controls=signal, saveat=SaveAt(t1=True))


def fitted_order(system, ref, method, ns=NS, observe=node):
    hs, errs = [], []
    for n in ns:
        sol = simulate(system, method, h=T / n, steps=n, controls=signal, saveat=SaveAt(t1=True))
        assert sol.success, sol.message
        hs.append(T / n)
        errs.append(np.max(np.abs(observe(sol) - observe(ref))))
    assert min(errs) > 1e-11, f"{method}: errors {errs} too close to round-off to fit an order"
    return slope(hs, errs), errs


# DLA reports a velocity of order 1 only (its class docstring): its configurations are of order 2
SLEIGH_SYMMETRIC = ["gni-trapezoid", "gni-midpoint", "rattle", "sgni-trapezoid", "mp", "discrete-gradient", "dla",
                    "euler-ab"]
# On SO(3) the parts of a forced step that depend on the space (the quadrature points of the force
# on the group, the forced group Legendre transforms) are those of the GNI with each force rule
# (trapezoid, midpoint); sgni-trapezoid combines the same space primitives in its own, space-agnostic
# way (gni_variants.SymmetricImpulseGNI.step), checked on the sleigh above, so it is not run again here.
SUSLOV_SYMMETRIC = ["gni-trapezoid", "gni-midpoint", "discrete-gradient", "dla"]


@pytest.mark.parametrize("method", SLEIGH_SYMMETRIC)
def test_order_two_with_forcing_on_rn(sleigh, sleigh_ref, method):
    order, errs = fitted_order(sleigh, sleigh_ref, method, observe=configuration if method == "dla" else node)
    assert abs(order - 2.0) <= 0.15, (method, order, errs)


@pytest.mark.parametrize("method", SUSLOV_SYMMETRIC)
def test_order_two_with_forcing_on_so3(suslov, suslov_ref, method):
    order, errs = fitted_order(suslov, suslov_ref, method, observe=configuration if method == "dla" else node)
    assert abs(order - 2.0) <= 0.15, (method, order, errs)


def test_composition_order_four_with_forcing(sleigh, sleigh_ref):
    """Each substep at its own time (system.shifted): Suzuki's composition of the forced GNI is of
    order 4 (measured 4.01, 4.00)."""
    order, errs = fitted_order(sleigh, sleigh_ref, "suzuki4-gni-trapezoid")
    assert abs(order - 4.0) <= 0.15, (order, errs)


@pytest.mark.parametrize("explicit, gni", [("rattle", gnipy.Trapezoid), ("euler-a", gnipy.EulerA),
                                           ("euler-b", gnipy.EulerB)])
def test_forced_paper_schemes_are_the_forced_gni(sleigh, explicit, gni):
    """The paper's maps with their discrete Lagrangian's force rule are the forced GNI, node by node."""
    kw = dict(h=0.05, steps=20, controls=signal)
    a = simulate(sleigh, explicit, **kw)
    b = simulate(sleigh, gnipy.GNI(gni(), start="rest"), **kw)
    assert np.max(np.abs(np.asarray(a.q) - np.asarray(b.q))) < 1e-13
    assert np.max(np.abs(np.asarray(a.v) - np.asarray(b.v))) < 1e-13


def test_exact_uniform_acceleration_along_a_knife_edge():
    """A knife edge on a level plane (α = 0), heading φ₀ fixed (φ̇₀ = 0), pushed along its blade by
    a constant force c(cos φ, sin φ, 0). The force lies in the allowed direction, so the constraint
    force vanishes (λ = 0) and φ stays φ₀; along the blade $m\\ddot s = c$, hence exactly

        x = x₀ + cos φ₀ (s₀t + c t²/2m),  y = y₀ + sin φ₀ (s₀t + c t²/2m),  φ = φ₀,
        v = (s₀ + c t/m)(cos φ₀, sin φ₀, 0).

    The GNI with the trapezoid and its forced trapezoid rule is velocity Verlet here (constant metric,
    constant force): it integrates the uniform acceleration exactly, to round-off, at any step."""
    m, c, phi0, s0 = 1.0, 0.7, 0.4, 0.3
    sysf = make_system("knife-edge", alpha=0.0, m=m).with_force(
        lambda q, v, u, t: c * jnp.array([jnp.cos(q[2]), jnp.sin(q[2]), 0.0]))
    q0 = np.array([0.1, -0.2, phi0])
    v0 = s0 * np.array([np.cos(phi0), np.sin(phi0), 0.0])
    sol = simulate(sysf, "gni-trapezoid", q0, v0, h=0.25, steps=8)
    t = np.asarray(sol.t)
    s = s0 * t + 0.5 * c / m * t**2
    q = np.stack([q0[0] + np.cos(phi0) * s, q0[1] + np.sin(phi0) * s, np.full_like(t, phi0)], axis=1)
    v = (s0 + c / m * t)[:, None] * np.array([np.cos(phi0), np.sin(phi0), 0.0])
    assert np.max(np.abs(np.asarray(sol.q) - q)) < 1e-14
    assert np.max(np.abs(np.asarray(sol.v) - v)) < 1e-14


def test_gravity_as_a_force_is_gravity_as_a_potential():
    """The knife edge on an incline, the exact solution of the model (:func:`gnipy.models.knife_edge.exact`):
    gravity as the force F = (m g sin α, 0, 0) on a level system gives the same GNI-trapezoid steps as
    gravity as the potential (the trapezoid of a constant force is that of a linear potential), and
    the exact solution to O(h²)."""
    from gnipy.models import knife_edge

    params = dict(m=1.0, J=1.0, g=9.81, alpha=0.5)
    a = params["m"] * params["g"] * np.sin(params["alpha"])
    level = make_system("knife-edge", **(params | {"alpha": 0.0})).with_force(
        lambda q, v, u, t: jnp.array([a, 0.0, 0.0]))
    incline = make_system("knife-edge", **params)
    q0, v0 = np.zeros(3), np.array([0.0, 0.0, 1.0])
    n, h = 20, 0.05
    forced = simulate(level, "gni-trapezoid", q0, v0, h=h, steps=n)
    potential = simulate(incline, "gni-trapezoid", q0, v0, h=h, steps=n)
    assert np.max(np.abs(np.asarray(forced.q) - np.asarray(potential.q))) < 1e-13
    assert np.max(np.abs(np.asarray(forced.v) - np.asarray(potential.v))) < 1e-13
    q_exact, _ = knife_edge.exact(params, q0, v0, np.asarray(forced.t))
    assert np.max(np.abs(np.asarray(forced.q) - q_exact)) < 2.0 * h**2  # O(h²): measured 1.1 h²


@pytest.mark.parametrize("name, fixture", [("chaplygin-sleigh", "sleigh"), ("suslov", "suslov")])
def test_constraints_exact_with_forcing(request, name, fixture):
    sysf = request.getfixturevalue(fixture)
    sol = simulate(sysf, "gni-trapezoid", h=0.05, steps=40, controls=signal)
    assert np.max(np.abs(np.asarray(sol.constraint_residual))) <= 1e-13


@pytest.mark.parametrize("method, tol", [("gni-trapezoid", 1e-14), ("rattle", 1e-14), ("mp", 1e-13)])
def test_zero_force_changes_nothing(method, tol):
    """F = 0 through the forced code paths (Newton instead of the explicit step, the forced
    transforms) gives the unforced trajectory to round-off. (That the unforced paths are the old
    ones, bit for bit, is what the existing integrator tests check.)"""
    base = make_system("chaplygin-sleigh")
    zero = base.with_force(lambda q, v, u, t: jnp.zeros(3))
    a = simulate(base, method, h=0.05, steps=10)
    b = simulate(zero, method, h=0.05, steps=10)
    assert np.max(np.abs(np.asarray(a.q) - np.asarray(b.q))) <= tol
    assert np.max(np.abs(np.asarray(a.v) - np.asarray(b.v))) <= tol


def test_held_controls_order_two(sleigh):
    """Inputs held over steps of H = 0.1 (zero-order hold); the runs take h = H/r with each value
    repeated r times, so that all see the same piecewise-constant u(t), whose jumps fall on nodes;
    the reference lands a step on every jump. Order 2."""
    H, K, rs = 0.1, 10, (2, 4, 8)
    U = np.cos(np.arange(K) * 0.7)[:, None]
    ref = simulate(sleigh, "reference", h=H, steps=K, controls=U, saveat=SaveAt(t1=True))
    hs, errs = [], []
    for r in rs:
        # padded to one length (values past the run's steps are unused): one compiled program
        held = np.pad(np.repeat(U, r, axis=0), ((0, K * (max(rs) - r)), (0, 0)), mode="edge")
        sol = simulate(sleigh, "gni-trapezoid", h=H / r, steps=K * r, controls=held, saveat=SaveAt(t1=True))
        hs.append(H / r)
        errs.append(np.max(np.abs(node(sol) - node(ref))))
    assert abs(slope(hs, errs) - 2.0) <= 0.15, errs


def test_discrete_gradient_energy_balance():
    """On the sleigh (linear constraints, constant metric, V = 0) the discrete-gradient method changes
    the energy by exactly the discrete work of the force, $E_{k+1} - E_k = hF(q_{k+1/2}, Δq/h, u,
    t_k + h/2)\\cdot Δq/h$ (midpoint rule), to round-off, with a force that does work (an input
    torque and a push along x, with damping)."""
    def force(q, v, u, t):
        return jnp.array([0.5 * jnp.cos(t) - 0.2 * v[0], 0.0, u[0] - 0.3 * v[2]])

    sysf = make_system("chaplygin-sleigh").with_force(force, inputs=1)
    h, n = 0.05, 60
    sol = simulate(sysf, "discrete-gradient", h=h, steps=n, controls=signal)
    q, t, E = np.asarray(sol.q), np.asarray(sol.t), np.asarray(sol.energy)
    dq = np.diff(q, axis=0)
    mid = 0.5 * (q[1:] + q[:-1])
    work = np.array([np.asarray(force(mid[k], dq[k] / h, signal(t[k] + 0.5 * h), t[k] + 0.5 * h)) @ dq[k]
                     for k in range(n)])
    assert np.max(np.abs(work)) > 1e-3  # the force does work
    assert np.max(np.abs(np.diff(E) - work)) < 1e-14 * max(1.0, np.max(np.abs(E)))


# ---------------------------------------------------------------------------------------------
# Refusals
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("method, fixture", [("shake", "sleigh"), ("rat", "suslov")])
def test_methods_that_refuse_forces(request, method, fixture):
    sysf = request.getfixturevalue(fixture)
    with pytest.raises(MethodError, match=rf"method '{method}'.*does not support forces"):
        simulate(sysf, method, h=0.05, steps=4, controls=signal)


def test_input_errors():
    base = make_system("chaplygin-sleigh")
    sysf = base.with_force(sleigh_force, inputs=1)
    kw = dict(h=0.05, steps=4)
    with pytest.raises(InputError, match="controls"):  # no force to drive
        simulate(base, "gni-trapezoid", controls=np.zeros((4, 1)), **kw)
    with pytest.raises(InputError, match="controls"):  # inputs but no controls
        simulate(sysf, "gni-trapezoid", **kw)
    with pytest.raises(InputError, match="controls"):  # wrong number of inputs
        simulate(sysf, "gni-trapezoid", controls=np.zeros((4, 2)), **kw)
    with pytest.raises(InputError, match="controls"):  # too few steps
        simulate(sysf, "gni-trapezoid", controls=np.zeros((3, 1)), **kw)
    with pytest.raises(InputError, match="controls"):  # not finite
        simulate(sysf, "gni-trapezoid", controls=np.array([[0.0], [np.nan], [0.0], [0.0]]), **kw)
    with pytest.raises(InputError, match="controls"):  # inputs to a force without any
        simulate(base.with_force(lambda q, v, u, t: -v), "gni-trapezoid", controls=signal, **kw)
    with pytest.raises(InputError, match=r"^h:"):  # backward
        simulate(sysf, "gni-trapezoid", h=-0.05, steps=4, controls=signal)


def test_backward_refused_with_traced_controls(sleigh):
    """Under jax.grad (traced controls) the backward run of a forced system is refused too, as
    without a transformation (the step size is known)."""
    q0, v0 = (np.asarray(x) for x in sleigh.defaults)
    with pytest.raises(InputError, match=r"^h: a forced system runs forward in time"):
        jax.grad(lambda U: simulate(sleigh, "gni-trapezoid", q0, v0, h=-0.05, steps=4, controls=U).q[-1, 0])(
            jnp.ones((4, 1)))


# ---------------------------------------------------------------------------------------------
# Derivatives with respect to the controls
# ---------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_gradient_with_respect_to_the_controls(sleigh):
    """jax.grad of a final-state cost through simulate(..., controls=U) (implicit steps: the
    implicit function theorem) against central differences of the cost (plain simulate runs).

    The gradient is compiled as one program (gnipy's jit, as simulate's own programs): taken
    eagerly, jax.grad costs 12 s of small compilations and 3 s of tracing per call; under a
    transformation simulate takes the same path (gnipy.transformed) either way, and the refusals
    of jax.grad outside jit are tested below."""
    n, h = 24, 0.05
    U0 = 0.5 * np.sin(np.arange(n) * 0.3)[:, None]
    target = np.array([0.8, 0.4, 0.9])

    # q0, v0 given: the traced controls make the system traced, whose defaults simulate then refuses
    q0, v0 = (np.asarray(x) for x in sleigh.defaults)

    def cost(U):
        sol = simulate(sleigh, "gni-trapezoid", q0, v0, h=h, steps=n, controls=U, saveat=SaveAt(t1=True))
        return jnp.sum((sol.q[-1] - target) ** 2) + jnp.sum(sol.v[-1] ** 2)

    g = np.asarray(gnipy_jit(jax.grad(cost))(jnp.asarray(U0)))
    assert np.max(np.abs(g)) > 1e-3
    eps = 1e-5
    for k in (0, n // 2, n - 2):
        dU = np.zeros_like(U0)
        dU[k, 0] = eps
        fd = (float(cost(U0 + dU)) - float(cost(U0 - dU))) / (2 * eps)
        assert abs(g[k, 0] - fd) <= 1e-6 * np.max(np.abs(g)) + 1e-9, (k, g[k, 0], fd)


@pytest.mark.slow
def test_held_pushes_from_a_later_start_with_a_shortened_last_step_are_exact():
    """The knife edge pushed along its blade by held forces c_k (step k, from t0 = 1.7), to a final
    time 8.3 steps later: the last step is shortened and keeps c_8. Along the blade the speed is
    piecewise linear and the position piecewise quadratic, exactly; the forced trapezoid (velocity
    Verlet here) follows them at every node. Continuing the run from its state at step 4 with the
    remaining inputs gives the same nodes."""
    m, phi0, s0, h, t0 = 1.0, 0.4, 0.3, 0.25, 1.7
    c = np.array([0.7, -0.3, 1.1, 0.0, 0.5, -0.8, 0.2, 0.9, -0.4])
    sysf = make_system("knife-edge", alpha=0.0, m=m).with_force(
        lambda q, v, u, t: u[0] * jnp.array([jnp.cos(q[2]), jnp.sin(q[2]), 0.0]), inputs=1)
    q0 = np.array([0.1, -0.2, phi0])
    v0 = s0 * np.array([np.cos(phi0), np.sin(phi0), 0.0])
    t_final = t0 + 8.3 * h
    # every node and its integrator state (to continue from step 4 below without another compiled run)
    sol = simulate(sysf, "gni-trapezoid", q0, v0, h=h, t_final=t_final, t0=t0, controls=c,
                   saveat=SaveAt(steps=True, states=True))
    lengths = np.array([h] * 8 + [0.3 * h])  # the steps' durations
    speed = s0 + np.concatenate([[0.0], np.cumsum(c * lengths / m)])
    dist = np.concatenate([[0.0], np.cumsum(speed[:-1] * lengths + 0.5 * c / m * lengths**2)])
    q = np.stack([q0[0] + np.cos(phi0) * dist, q0[1] + np.sin(phi0) * dist, np.full(10, phi0)], axis=1)
    assert np.allclose(np.asarray(sol.t), t0 + np.concatenate([[0.0], np.cumsum(lengths)]), atol=1e-15)
    assert np.max(np.abs(np.asarray(sol.q) - q)) < 1e-14
    assert np.max(np.abs(np.asarray(sol.v)[:, 0] - np.cos(phi0) * speed)) < 1e-14
    state4 = jax.tree_util.tree_map(lambda x: x[4], sol.states)
    rest = simulate(sysf, "gni-trapezoid", h=h, t_final=t_final, t0=float(sol.t[4]), controls=c[4:],
                    state0=state4)
    assert np.max(np.abs(np.asarray(rest.q) - np.asarray(sol.q)[4:])) < 1e-15


def test_a_batch_member_has_its_single_runs_diagnostics(sleigh):
    """A batch of initial conditions of one forced system: each member's hidden-momentum diagnostics
    (λ at each node's time and input) are those of its single run."""
    q0, v0 = (np.asarray(x) for x in sleigh.defaults)
    single = simulate(sleigh, "gni-trapezoid", q0, v0, h=0.05, steps=40, controls=signal)
    batch = simulate(sleigh, "gni-trapezoid", np.stack([q0, q0]), np.stack([v0, 0.5 * v0]), h=0.05, steps=40,
                     controls=signal, project_v0=True)
    member = batch.member(0)
    assert np.max(np.abs(np.asarray(member.q) - np.asarray(single.q))) <= 1e-15
    assert np.max(np.abs(np.asarray(member.hidden_expected) - np.asarray(single.hidden_expected))) <= 1e-14
    assert np.ptp(np.asarray(single.hidden_expected)) > 1e-3  # it changes with the input along the run


def test_controls_are_checked_under_a_transformation_and_before_anything_else(sleigh):
    q0, v0 = (np.asarray(x) for x in sleigh.defaults)

    def cost(U):
        return simulate(sleigh, "gni-trapezoid", q0, v0, h=0.05, t_final=0.4, controls=U).q[-1, 0]

    with pytest.raises(InputError, match=r"^controls: 3 per-step values for 8 steps"):
        jax.grad(cost)(jnp.ones((3, 1)))
    for kw, name in [(dict(h=None, steps=4), "h"), (dict(h="x", steps=4), "h"), (dict(h=0.05, steps="a"), "steps")]:
        with pytest.raises(InputError, match=rf"^{name}:"):
            simulate(sleigh, "gni-trapezoid", q0, v0, controls=np.ones((4, 1)), **kw)
