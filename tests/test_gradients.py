"""Derivatives of simulations (jax.grad, jax.jacrev, jax.jacfwd) against central differences.

The reference numbers are central differences of the same function, computed on concrete
values (no transformation): an independent formulation of the derivative.
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


def final_value(system, method, **kw):
    def f(v0):
        sol = gnipy.simulate(system, method, system.defaults[0], v0, h=H, steps=STEPS,
                             saveat=gnipy.SaveAt(t1=True), project_v0=True, **kw)
        return jnp.sum(jnp.sin(sol.q[-1])) + 0.5 * jnp.sum(sol.v[-1] ** 2)

    return f


# one of each family (the GNI with an explicit and an implicit l_d, the paper's schemes, the comparators);
# the others share their step code (euler-a, euler-b and euler-ab are rattle's kicks and drift,
# paper_schemes._kick_drift_kick, with other signs and step fractions)
FLAT = ["gni-euler-a", "gni-midpoint", "shake", "rattle", "dla", "mp"]


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
    expected = central(f, v0)
    np.testing.assert_allclose(g, expected, rtol=1e-6, atol=1e-7)
    if method == "dla":
        # forward mode too, once: every implicit solve's derivative is one custom JVP
        # (gnipy.integrators.base.implicit_solve), which reverse mode linearizes and transposes, so
        # the gradients above run the same rule (one compile, the cheapest of the implicit families)
        np.testing.assert_allclose(np.asarray(jax.jacfwd(f)(jnp.asarray(v0))), g, rtol=1e-10, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["gni-trapezoid", "rat"])
def test_gradient_on_a_group_matches_central_differences(method):
    """Rolling ball on R² × SO(3): Newton's steps (implicit solves) differentiated implicitly."""
    system = gnipy.make_system("rolling-ball")
    f = final_value(system, method)
    v0 = np.asarray(system.defaults[1], dtype=float)
    g = np.asarray(jax.jacrev(f)(jnp.asarray(v0)))
    np.testing.assert_allclose(g, central(f, v0), rtol=1e-6, atol=1e-7)


@pytest.mark.slow
def test_gradient_wrt_a_parameter_and_h():
    """A model parameter (built inside the function: the System is a pytree of its parameters) and
    the step size; the number of steps is fixed."""

    def f(m, h):
        system = gnipy.make_system("vertical-disk", m=m, I_rot=2.0)
        sol = gnipy.simulate(system, "gni-midpoint", (0.0, 0.0, 0.0, 0.0), (1.0, 0.0, 1.0, 1.0), h=h,
                             steps=STEPS, saveat=gnipy.SaveAt(t1=True))
        return jnp.sum(jnp.sin(sol.q[-1])) + sol.energy[-1]

    dm, dh = jax.grad(f, argnums=(0, 1))(1.3, H)
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
    np.testing.assert_allclose(kept, central(f, np.asarray(v0)), rtol=1e-6, atol=1e-7)
    method = gnipy.get_method("gni-midpoint")
    core = system.without_metadata()
    state = method.init(core, system.initial_point(system.defaults[0]), v0, H)
    assert stepping.residual_bytes(method, core, state, H) > 0
