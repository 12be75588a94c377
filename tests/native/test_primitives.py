"""Every JAX primitive in the step of every zoo model × method that the native backend runs has a
lowering rule (gnipy.native.lowering), so that a JAX upgrade that brings a new primitive (or
renames one) fails here, naming the primitive and where it appears, instead of quietly sending
those runs to XLA.

The pairs are those `backend="native"` runs (gnipy.native.backend.choose): every model of the
zoo without a force (a forced system's drive stays on XLA), with every listed method except the
continuous reference, that the method accepts (`method.check`). Each step is traced as the backend
traces it (gnipy.native.program.trace_step: the carry with the every-node monitor, as
`native_loop` builds it) at h = 0.01, from the state `method.init` makes at the model's default
start (its shapes only: `jax.eval_shape`). Nothing is compiled.

A composition's step is its base method's step and change of step size, once per stage, the
stages differing only in their coefficients: the longer schemes (Suzuki's 5 stages, Kahan–Li's 9)
are traced as Yoshida's 3-stage scheme of the same base, which has the same primitives
(`test_a_composition_has_the_primitives_of_its_three_stage_stand_in` checks it on one model).
That halves the time of the survey. The survey's 184 steps take about 19 s of tracing on the 2-core
machine (105 s before the maps of the systems and groups and the small solves were traced once per
shape: `gnipy.compilation.traced_once`).

The sub-jaxprs walked are those the lowering walks: every `Jaxpr` or `ClosedJaxpr` among an
equation's parameters (calls, `custom_jvp_call`, `custom_vjp_call`, `while`, `cond`, `scan`,
...), except the parts of `custom_linear_solve` that it does not lower (it lowers the solve; the
matvec and transposed solves are for differentiation).
"""

import collections
import time

import jax
import jax.numpy as jnp
import pytest

import gnipy
from gnipy.errors import InputError
from gnipy.integrators.composition import Composition
from gnipy.methods import get_method, method_names
from gnipy.monitor import initial
from gnipy.native.lowering import lowered_primitives
from gnipy.native.program import trace_step
from gnipy.preparation import prepare
from gnipy.reference import ContinuousReference
from gnipy.stepping import initial_carry, loop_step

H = 0.01


def _sub_jaxprs(eqn):
    """The jaxprs inside `eqn` that the lowering walks."""
    if eqn.primitive.name == "custom_linear_solve":
        return [eqn.params["jaxprs"].solve.jaxpr]
    found = []

    def visit(x):
        if hasattr(x, "eqns"):  # a Jaxpr
            found.append(x)
        elif hasattr(x, "jaxpr") and hasattr(getattr(x, "jaxpr"), "eqns"):  # a ClosedJaxpr
            found.append(x.jaxpr)
        elif isinstance(x, (tuple, list)):
            for y in x:
                visit(y)

    for value in eqn.params.values():
        visit(value)
    return found


def primitives(jaxpr, into=None) -> collections.Counter:
    """The primitives of `jaxpr` and of its sub-jaxprs, with their number of equations."""
    into = collections.Counter() if into is None else into
    for eqn in jaxpr.eqns:
        into[eqn.primitive.name] += 1
        for sub in _sub_jaxprs(eqn):
            primitives(sub, into)
    return into


def native_pairs():
    """`(model, method name, method, system)` of every pair the native backend runs."""
    for model in gnipy.model_names():
        system = gnipy.make_system(model)
        if getattr(system, "force", None) is not None:
            continue
        for name in method_names():
            method = get_method(name)
            if isinstance(method, ContinuousReference):
                continue
            yield model, name, method, system


def stand_in(method):
    """The method whose step is traced for `method`: itself, or for a composition the 3-stage
    scheme of its base (the same primitives: see the module docstring)."""
    if isinstance(method, Composition) and method.scheme != "yoshida4":
        return Composition(method.base, "yoshida4")
    return method


def _prepared(system, method):
    q0, v0 = system.defaults[0], system.defaults[1]
    R0 = system.defaults[2] if len(system.defaults) > 2 else None
    try:
        return prepare(system, method, q0, v0, R0, True, None)
    except InputError:  # MethodError included: the method cannot run this system
        return None


def step_jaxpr(system, method):
    """The jaxpr of the step that `native_loop` lowers, or None when the method refuses the system."""
    prep = _prepared(system, method)
    if prep is None:
        return None
    state0 = jax.eval_shape(lambda: prep.method.init(prep.core, prep.b0, jnp.asarray(prep.v0), H))
    carry0 = initial_carry(state0, initial(H, 1.0, 0.0))
    return trace_step(loop_step(prep.method, prep.core), carry0, H)[0]


@pytest.fixture(scope="module")
def survey():
    """{primitive: [model × method, ...]} over every pair, the pairs traced, and the seconds."""
    t0 = time.perf_counter()
    where, traced, found = collections.defaultdict(list), [], {}
    for model, name, method, system in native_pairs():
        if _prepared(system, method) is None:
            continue
        stand = stand_in(method)
        key = (model, stand.name)
        if key not in found:
            found[key] = primitives(step_jaxpr(system, stand))
        traced.append(f"{model} × {name}")
        for prim in found[key]:
            where[prim].append(f"{model} × {name}")
    return dict(where), traced, time.perf_counter() - t0


def test_every_primitive_of_every_native_step_is_lowered(survey):
    where, traced, seconds = survey
    assert len(traced) >= 150, traced  # every model, most methods
    missing = {prim: pairs for prim, pairs in where.items() if prim not in lowered_primitives()}
    lines = [f"primitive {prim!r} has no native lowering rule (gnipy.native); it appears in the step of "
             f"{len(pairs)} model × method pair(s): {', '.join(pairs[:5])}{' ...' if len(pairs) > 5 else ''}"
             for prim, pairs in sorted(missing.items())]
    assert not missing, "\n".join(lines)
    print(f"{len(traced)} steps traced in {seconds:.1f} s; {len(where)} primitives: {', '.join(sorted(where))}")


def test_the_survey_sees_the_steps_structure(survey):
    """The walk reaches inside the steps (the calls, the Newton loops, the solves): a survey that
    stopped at the top-level call would pass the test above vacuously."""
    where, _, _ = survey
    assert {"jit", "pjit", "closed_call"} & set(where), sorted(where)  # calls (`pjit` before jax 0.7)
    # the Newton loops; inside the linear solves (custom_linear_solve's solve: LU, triangular solves)
    for prim in ("while", "custom_linear_solve", "lu", "triangular_solve", "dot_general", "sqrt"):
        assert prim in where, (prim, sorted(where))


def test_a_composition_has_the_primitives_of_its_three_stage_stand_in():
    """The survey's stand-in for the longer compositions is exact (on the nonholonomic particle)."""
    system = gnipy.make_system("nonholonomic-particle")
    for name in ("suzuki4-gni-trapezoid", "kahanli6-mp"):
        method = get_method(name)
        assert stand_in(method).name.startswith("yoshida4-")
        assert set(primitives(step_jaxpr(system, method))) == set(primitives(step_jaxpr(system, stand_in(method))))


def test_the_survey_is_what_the_lowering_rejects():
    """A step with a primitive the lowering does not know is reported by the survey as it is by the
    lowering (`cumsum` has no rule)."""
    def step(carry, h):
        x, *rest = carry
        return (jax.lax.cumsum(x) * h, *rest)

    jaxpr = trace_step(step, (jnp.ones(3), jnp.asarray(0, jnp.int32)), H)[0]
    found = primitives(jaxpr)
    assert "cumsum" in found and "cumsum" not in lowered_primitives()
    from gnipy.native import Unsupported
    from gnipy.native.program import build_loop

    with pytest.raises(Unsupported, match="cumsum"):  # raised while lowering: nothing is compiled
        build_loop(step, (jnp.ones(3), jnp.asarray(0, jnp.int32)), H)
