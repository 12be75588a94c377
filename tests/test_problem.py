"""The Problem (`gnipy.problem`), the one integrate (`gnipy.integration`) and the one assembly
(`gnipy.assembly`): arguments checked once, into a frozen object, and every path (one trajectory,
a batch, a run under a JAX transformation) returning the same fields."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import InputError, MethodError, Problem, SaveAt, integrate, simulate
from gnipy.integrators.reversal import Reversed

#: what every path says about its run (gnipy.assembly.labels), and the diagnostics' sentences
LABELS = ("system", "method", "h", "coordinates", "velocities", "params", "start", "method_settings", "backend",
          "orientation", "conserved", "energy_invariant")


@pytest.fixture(scope="module")
def sleigh():
    return gnipy.make_system("chaplygin-sleigh")


def test_a_problem_is_frozen_and_resolved(sleigh):
    p = Problem.of(sleigh, "gni-midpoint", h=0.1, t_final=1.05)
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.h = 0.2
    # t_final - t0 = 10.5 steps of h: ten full steps and a last one of half a step
    assert (p.steps, p.partial, p.total_steps) == (10, pytest.approx(0.5), 11)
    assert p.times[0] == 0.0 and p.times[-1] == pytest.approx(1.05, abs=1e-15)
    # the system's documented initial condition fills what was not given
    np.testing.assert_array_equal(p.q0, sleigh.defaults[0])
    np.testing.assert_array_equal(p.v0, sleigh.defaults[1])
    assert not p.batched and not p.traced and p.throw and not p.strict
    assert Problem.of(sleigh, "gni-midpoint", h=0.1, steps=3, throw="strict").strict
    # h < 0: the method's exact inverse runs
    assert isinstance(Problem.of(sleigh, "gni-midpoint", h=-0.1, steps=3).method, Reversed)


def test_a_batch_problem_knows_its_size(sleigh):
    q0, v0 = sleigh.defaults[0], sleigh.defaults[1]
    p = Problem.of(sleigh, "gni-midpoint", np.stack([q0] * 3), np.stack([v0] * 3), h=0.1, steps=2)
    assert p.batched and p.batch_size == 3
    members = gnipy.model_systems("chaplygin-sleigh", m=[1.0, 2.0])
    assert Problem.of(members, "gni-midpoint", h=0.1, steps=2).batch_size == 2


@pytest.mark.parametrize("kwargs, named", [
    (dict(h=0.1), "steps/t_final"),
    (dict(h=0.1, steps=2, t_final=1.0), "steps/t_final"),
    (dict(h="0.1", steps=2), "h:"),
    (dict(h=0.0, steps=2), "h:"),
    (dict(h=0.1, steps=0), "steps:"),
    (dict(h=0.1, steps=2, throw="loud"), "throw:"),
    (dict(h=0.1, steps=2, saveat=SaveAt(every=1), save_every=2), "saveat/save_every"),
    (dict(h=0.1, steps=2, saveat="every"), "saveat:"),
    (dict(h=0.1, steps=2, save_every=0), "save_every:"),
    (dict(h=0.1, steps=2, progress="yes"), "progress:"),
    (dict(h=0.1, steps=2, backend="gpu"), "backend:"),
    (dict(h=0.1, steps=2, project_v0="no"), "project_v0:"),
    (dict(h=0.1, steps=2, check_every_node=1), "check_every_node:"),
    (dict(h=0.1, steps=2, controls=np.zeros((2, 1))), "controls:"),
    (dict(h=0.1, steps=2, t0=float("nan")), "t0:"),
    (dict(h=0.1, steps=2, state0=(1.0,), q0=np.zeros(3)), "state0:"),
])
def test_every_argument_is_checked_once_by_name(sleigh, kwargs, named):
    args = dict(kwargs)
    q0 = args.pop("q0", None)
    with pytest.raises(InputError, match="^" + named.replace("/", "/")):
        Problem.of(sleigh, "gni-midpoint", q0, **args)


def test_bad_systems_and_methods_are_named(sleigh):
    with pytest.raises(InputError, match="^system:"):
        Problem.of("chaplygin-sleigh", "gni-midpoint", h=0.1, steps=2)
    with pytest.raises(InputError, match=r"^system\[1\]:"):
        Problem.of([sleigh, 3], "gni-midpoint", h=0.1, steps=2)
    with pytest.raises(MethodError, match="^method:"):
        Problem.of(sleigh, 3.0, h=0.1, steps=2)
    with pytest.raises(MethodError, match="^method: the continuous reference runs one trajectory"):
        Problem.of(gnipy.model_systems("chaplygin-sleigh", m=[1.0, 2.0]), "reference", h=0.1, steps=2)
    with pytest.raises(TypeError, match="problem"):
        integrate("not a problem")


def test_integrate_is_simulate(sleigh):
    a = simulate(sleigh, "gni-midpoint", h=0.05, steps=20, backend="xla")
    b = integrate(Problem.of(sleigh, "gni-midpoint", h=0.05, steps=20, backend="xla"))
    for name in ("t", "q", "v", "p", "energy", "constraint_residual", "hidden_momentum"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert {k: getattr(a, k) for k in LABELS} == {k: getattr(b, k) for k in LABELS}


def test_every_path_returns_the_same_fields(sleigh):
    """One trajectory, a batch of one initial condition, and the run under `jax.grad`: the same
    labels and sentences; the batch member equals the single run to round-off."""
    q0, v0 = np.asarray(sleigh.defaults[0]), np.asarray(sleigh.defaults[1])
    single = simulate(sleigh, "gni-midpoint", q0, v0, h=0.05, steps=20, backend="xla")
    batch = simulate(sleigh, "gni-midpoint", q0[None], v0[None], h=0.05, steps=20, backend="xla")
    seen = {}

    def last_x(h):
        sol = simulate(sleigh, "gni-midpoint", q0, v0, h=h, steps=20)
        seen["sol"] = sol
        return sol.q[-1, 0]

    jax.grad(last_x)(jnp.float64(0.05))
    traced = seen["sol"]
    expected = {k: getattr(single, k) for k in LABELS}
    assert {k: getattr(batch, k) for k in LABELS} == expected
    assert {k: getattr(traced, k) for k in LABELS} == expected
    member = batch.member(0)
    for name in ("q", "v", "p", "energy", "hidden_momentum", "hidden_expected", "energy_plus"):
        np.testing.assert_allclose(getattr(member, name), getattr(single, name), rtol=1e-13, atol=1e-15,
                                   err_msg=name)
    # under a transformation the per-node diagnostics are not computed (gnipy.assembly says why)
    assert traced.hidden_momentum is None and single.hidden_momentum is not None
