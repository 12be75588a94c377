"""Derivatives of simulations (jax.grad, jax.jacrev, jax.jacfwd) against central differences.

The reference numbers are central differences of the same function, computed on concrete
values (no transformation): an independent formulation of the derivative. A gradient is checked
along a fixed random direction (:func:`direction`, every component of order one): its derivative
there against one central difference, two runs instead of two per component. The methods are one
per family (FLAT); the rolling ball's Jacobian and the parameter's gradient are taken under
jax.jit (one program each), the vertical disk's gradients outside it, as a user calls jax.grad.

Measured on the shared 2-core machine (`pytest -n 0 --durations=0` on this file alone, other jobs
running, so noisy to several seconds): 102.8 s → 64.6 s (a second run of the same version: 91 s).
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy

#: numerics, not verdicts: the untransformed runs (the central differences) check the saved nodes
#: only (tests/conftest.py); the transformed runs never carry the every-node check
CHECK_EVERY_NODE = False

H, STEPS = 0.05, 30


def central(f, x, eps=1e-6):
    x = np.asarray(x, dtype=float)
    g = np.zeros_like(x)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = eps
        g.flat[i] = (float(f(x + e)) - float(f(x - e))) / (2 * eps)
    return g


def direction(x, seed=0):
    """A fixed random direction with every component of order one (standard normal): a wrong
    component of a gradient changes its derivative along it, as it changes its own central
    difference."""
    return np.random.default_rng(seed).standard_normal(np.shape(x))


def central_along(f, x, d, eps=1e-6):
    """The central difference of `f` at `x` along `d`: two runs, where :func:`central` takes two
    per component."""
    x = np.asarray(x, dtype=float)
    return (float(f(x + eps * d)) - float(f(x - eps * d))) / (2 * eps)


def final_value(system, method, **kw):
    def f(v0):
        sol = gnipy.simulate(system, method, system.defaults[0], v0, h=H, steps=STEPS,
                             saveat=gnipy.SaveAt(t1=True), project_v0=True, **kw)
        return jnp.sum(jnp.sin(sol.q[-1])) + 0.5 * jnp.sum(sol.v[-1] ** 2)

    return f


# one of each family (the GNI with an explicit and an implicit l_d, the paper's schemes, the comparators);
# the others share their step code (euler-a, euler-b and euler-ab are rattle's kicks and drift,
# paper_schemes._kick_drift_kick, with other signs and step fractions). SHAKE, the paper's other
# scheme, is left out: its step is explicit, linear solves differentiated by JAX's own rules as in
# rattle's and gni-euler-a's, through the same loop (run_nodes_checkpointed) and start
# (project_v0), so it has no derivative rule of its own (measured: 3 s of CPU).
FLAT = ["gni-euler-a", "gni-midpoint", "rattle", "dla", "mp"]


@functools.cache
def _v0_gradient(method):
    """`(f, v0, jax.grad(f)(v0))` for :func:`final_value` on the vertical disk, computed once (with the
    default memory budget): the gradient of gni-midpoint is also test_checkpointed_blocks_give_the_same_gradient's."""
    system = gnipy.make_system("vertical-disk")
    f = final_value(system, method)
    v0 = np.asarray(system.defaults[1], dtype=float)
    return f, v0, np.asarray(jax.grad(f)(jnp.asarray(v0)))


@pytest.mark.slow
@pytest.mark.parametrize("method", FLAT)
def test_gradient_wrt_the_initial_velocity_matches_central_differences(method):
    f, v0, g = _v0_gradient(method)
    d = direction(v0)
    np.testing.assert_allclose(g @ d, central_along(f, v0, d), rtol=1e-6, atol=1e-7)
    if method == "dla":
        # forward mode too, once: every implicit solve's derivative is one custom JVP
        # (gnipy.integrators.base.implicit_solve), which reverse mode linearizes and transposes, so
        # the gradients above run the same rule (one compile, the cheapest of the implicit families)
        np.testing.assert_allclose(np.asarray(jax.jacfwd(f)(jnp.asarray(v0))), g, rtol=1e-10, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["gni-trapezoid", "rat"])
def test_gradient_on_a_group_matches_central_differences(method):
    """Rolling ball on R² × SO(3): Newton's steps (implicit solves) differentiated implicitly.

    jax.jacrev under jax.jit: one compiled program (eagerly, the rolling ball's new shapes cost
    some 400 small compilations; measured in this module 17.4 → 13.9 s for gni-trapezoid, 12.6 →
    9.5 s for rat); the prepared steps are those of the eager call (gni-trapezoid is implicit on
    the rolling ball either way, rat has one form), and the eager path of jax.grad is the vertical
    disk's above."""
    system = gnipy.make_system("rolling-ball")
    f = final_value(system, method)
    v0 = np.asarray(system.defaults[1], dtype=float)
    g = np.asarray(jax.jit(jax.jacrev(f))(jnp.asarray(v0)))
    d = direction(v0)
    np.testing.assert_allclose(g @ d, central_along(f, v0, d), rtol=1e-6, atol=1e-7)


@pytest.mark.slow
def test_gradient_wrt_a_parameter_and_h():
    """A model parameter (built inside the function: the System is a pytree of its parameters) and
    the step size; the number of steps is fixed. Under jax.jit: one compiled program (eagerly some
    60 small compilations; measured 13.7 → 10.0 s); jax.grad outside jit is the vertical disk's above."""

    def f(m, h):
        system = gnipy.make_system("vertical-disk", m=m, I_rot=2.0)
        sol = gnipy.simulate(system, "gni-midpoint", (0.0, 0.0, 0.0, 0.0), (1.0, 0.0, 1.0, 1.0), h=h,
                             steps=STEPS, saveat=gnipy.SaveAt(t1=True))
        return jnp.sum(jnp.sin(sol.q[-1])) + sol.energy[-1]

    dm, dh = jax.jit(jax.grad(f, argnums=(0, 1)))(1.3, H)
    np.testing.assert_allclose(float(dm), central(lambda m: f(float(m[0]), H), [1.3])[0], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(float(dh), central(lambda h: f(1.3, float(h[0])), [H])[0], rtol=1e-6, atol=1e-8)


@pytest.mark.slow
def test_jit_of_simulate_equals_the_untransformed_run():
    system = gnipy.make_system("rolling-ball")
    ref = gnipy.simulate(system, "gni-trapezoid", h=H, steps=STEPS, save_every=7)
    run = jax.jit(lambda v0: gnipy.simulate(system, "gni-trapezoid", system.defaults[0], v0, h=H, steps=STEPS,
                                            save_every=7).q)
    np.testing.assert_array_equal(np.asarray(ref.t), np.asarray(gnipy.simulate(
        system, "gni-trapezoid", h=H, steps=STEPS, save_every=7).t))
    np.testing.assert_allclose(np.asarray(run(jnp.asarray(system.defaults[1]))), np.asarray(ref.q), rtol=0, atol=1e-13)


def test_checkpoint_blocks_cover_every_step_and_save_where_asked():
    from gnipy.stepping import checkpoint_blocks

    for lengths, tail in [((10, 10, 10), 0), ((1000,), 3), ((1, 1, 1, 500), 17), ((), 40)]:
        L, blocks, saved = checkpoint_blocks(lengths, tail)
        assert sum(blocks) == sum(lengths) + tail and max(blocks) <= L
        assert [sum(blocks[: i + 1]) for i in saved] == list(np.cumsum(lengths))


def test_a_transformed_run_refuses_what_it_cannot_do():
    system = gnipy.make_system("vertical-disk")
    with pytest.raises(gnipy.InputError, match="steps: h is traced"):
        jax.jit(lambda h: gnipy.simulate(system, "gni-midpoint", h=h, t_final=1.0).q)(0.1)
    with pytest.raises(gnipy.MethodError, match="continuous reference"):
        jax.grad(lambda v: gnipy.simulate(system, "reference", (0.0,) * 4, v, h=0.1, steps=3).q[-1, 0])(
            jnp.asarray([1.0, 0.0, 1.0, 1.0]))
    # a model built from traced parameters: its default start holds no derivative, so it is not used
    with pytest.raises(gnipy.InputError, match="q0/v0: the system's parameters are traced"):
        jax.grad(lambda r: gnipy.simulate(gnipy.make_system("rolling-ball", r=r), "gni-trapezoid", h=0.1,
                                          steps=3).q[-1, 0])(1.0)


@pytest.mark.slow
def test_checkpointed_blocks_give_the_same_gradient(monkeypatch):
    """Reverse mode with the blocks rematerialized (forced by a zero memory budget) equals reverse
    mode keeping every step's residuals (the default for a short run), and both equal central
    differences; the residuals of one step are counted from their shapes."""
    from gnipy import stepping

    system = gnipy.make_system("vertical-disk")
    f, v0, kept = _v0_gradient("gni-midpoint")  # the default budget keeps every step's residuals
    v0 = jnp.asarray(v0)
    monkeypatch.setattr(stepping, "GRADIENT_MEMORY_BYTES", 0)
    remat = np.asarray(jax.grad(f)(v0))
    np.testing.assert_allclose(remat, kept, rtol=1e-12, atol=1e-14)
    d = direction(v0)
    np.testing.assert_allclose(kept @ d, central_along(f, np.asarray(v0), d), rtol=1e-6, atol=1e-7)
    method = gnipy.get_method("gni-midpoint")
    core = system.without_metadata()
    state = method.init(core, system.initial_point(system.defaults[0]), v0, H)
    assert stepping.residual_bytes(method, core, state, H) > 0
