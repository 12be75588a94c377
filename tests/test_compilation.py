"""Compiled programs: releasing them when the process holds many memory maps; the opt-in cache."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from gnipy.compilation import memory_map_count, release_compiled_programs_if_needed


def test_release_drops_compiled_programs_and_their_maps():
    for i in range(20):  # twenty distinct programs, each with its own mapped machine code
        jax.jit(lambda x, i=i: jnp.sin(x) * i + jnp.cumsum(jnp.cos(x) ** (i % 3 + 1)))(jnp.ones(50)).block_until_ready()
    before = memory_map_count()
    assert before is not None and before > 0
    assert not release_compiled_programs_if_needed(fraction=1e9)  # far below the limit: nothing done
    assert release_compiled_programs_if_needed(fraction=0.0)
    assert memory_map_count() <= before


def test_cache_is_opt_in_and_goes_where_asked(tmp_path):
    code = (
        "from gnipy.compilation import cache_requested, enable_compilation_cache;"
        "print(cache_requested()); print(enable_compilation_cache())"
    )
    env = {k: v for k, v in os.environ.items() if k != "GNIPY_COMPILATION_CACHE"}
    env["GNIPY_CACHE_DIR"] = str(tmp_path / "cache")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", str(tmp_path / "cache")]
    assert (tmp_path / "cache").is_dir()


def test_map_count_is_read_again_only_after_a_compile(monkeypatch):
    import gnipy.compilation as comp

    reads = []

    def counting():
        reads.append(1)
        return 10

    monkeypatch.setattr(comp, "memory_map_count", counting)
    monkeypatch.setattr(comp, "_last_count", None)
    assert not comp.release_compiled_programs_if_needed()
    assert not comp.release_compiled_programs_if_needed()
    assert not comp.release_compiled_programs_if_needed(fraction=0.1)
    assert len(reads) == 1  # no compilation in between: the last count stands
    jax.jit(lambda x: jnp.tanh(x) * 3.25 - 1.5)(jnp.ones(7)).block_until_ready()  # a new program
    assert not comp.release_compiled_programs_if_needed()
    assert len(reads) == 2
    assert comp.release_compiled_programs_if_needed(fraction=0.0)  # 10 maps ≥ 0: released
    assert len(reads) == 2


def test_compiler_options_are_accepted_and_the_decorator_compiles_the_same_function(monkeypatch):
    from gnipy.compilation import COMPILER_OPTIONS, compiler_options, jit

    # this JAX runs on the CPU; XLA knows the option from jax 0.5.3 on (a rejected option gives {},
    # and gnipy compiles with XLA's defaults: docs/dependencies.md)
    try:
        jax.jit(lambda x: x + 1, compiler_options=dict(COMPILER_OPTIONS)).lower(1.0).compile()
        known = True
    except Exception:
        known = False
    assert known == (tuple(int(p) for p in jax.__version__.split(".")[:3]) >= (0, 5, 3))
    assert compiler_options() == (COMPILER_OPTIONS if known else {})
    monkeypatch.setenv("GNIPY_XLA_DEFAULTS", "1")
    assert compiler_options.__wrapped__() == {}

    def f(x, n: int):
        return jnp.sum(jnp.sin(x) ** n)

    x = jnp.linspace(0.0, 1.0, 11)
    expected = np.sum(np.sin(np.linspace(0.0, 1.0, 11)) ** 3)
    np.testing.assert_allclose(float(jit(f)(x, 3)), expected, rtol=1e-14)
    assert jit(f).__name__ == "f"
    np.testing.assert_allclose(float(jit(donate="none")(f)(x, 2)), np.sum(np.sin(np.asarray(x)) ** 2), rtol=1e-14)


def test_the_decorator_works_inside_transformations():
    """Under jax.jit, jax.grad and jax.vmap (traced arguments) gnipy's jit is a nested program without
    compiler options, which JAX refuses on a nested jit: d/dx sin(x)^2 = sin(2x), exactly."""
    from gnipy.compilation import jit

    f = jit(lambda x: jnp.sin(x) ** 2)
    x = jnp.linspace(-1.0, 1.0, 5)
    np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(f))(x)), np.sin(2 * np.asarray(x)), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(float(jax.jit(f)(0.5)), np.sin(0.5) ** 2, rtol=1e-15)
    np.testing.assert_allclose(float(jax.jit(jax.grad(f))(0.5)), np.sin(1.0), rtol=1e-15)
    np.testing.assert_allclose(float(f(0.5)), np.sin(0.5) ** 2, rtol=1e-15)


def test_traced_once_traces_a_function_once_inside_a_program_and_runs_it_as_written_outside():
    from gnipy.compilation import traced_once

    traces = []

    @traced_once
    def f(x, scale):
        traces.append(1)  # a Python side effect: runs each time JAX traces (or eagerly runs) the body
        return jnp.sin(x) * scale

    def plain(x, scale):
        return jnp.sin(x) * scale

    def program(g):
        return lambda x: g(x, 2.0) + g(x + 1.0, 3.0) + jax.grad(lambda y: g(y, 2.0).sum())(x)

    x = jnp.linspace(0.0, 1.0, 5)
    got = jax.jit(program(f))(x)
    # three calls and a derivative: one trace per value of `scale` (a Python float is static, as in
    # equinox.filter_jit), the derivative reusing the trace of its call
    assert len(traces) == 2
    np.testing.assert_array_equal(got, jax.jit(program(plain))(x))  # XLA inlines the call: same numbers
    traces.clear()
    assert isinstance(f(x, 2.0), jax.Array) and f(x, 3.0) is not None
    assert len(traces) == 2  # concrete arguments: run as written, each call


def test_the_maps_of_systems_and_groups_share_one_trace_inside_a_program():
    """A system's metric and a group's exponential, called at several points inside a program,
    appear as calls of one shared jaxpr, and compute what the undecorated functions compute."""
    import gnipy
    from gnipy.lie_groups import SO3
    from gnipy.system import System

    system = gnipy.make_system("vertical-disk")
    q0 = jnp.asarray(system.defaults[0])
    group = SO3()

    def program(metric, exp):
        def run(q, w):
            return (metric(system, q) + metric(system, 2.0 * q), exp(group, w) @ exp(group, 0.5 * w))
        return run

    decorated = program(System.metric, SO3.exp)
    closed = jax.make_jaxpr(decorated)(q0, jnp.ones(3))
    calls = [e for e in closed.jaxpr.eqns if e.primitive.name in ("jit", "pjit")]
    by_name = {}
    for e in calls:
        by_name.setdefault(e.params["name"], set()).add(id(e.params["jaxpr"]))
    assert set(by_name) >= {"metric", "exp"}, by_name
    assert all(len(ids) == 1 for ids in by_name.values()), by_name  # one trace each, called twice
    plain = program(System.metric.__wrapped__, SO3.exp.__wrapped__)
    for a, b in zip(jax.jit(decorated)(q0, jnp.ones(3)), jax.jit(plain)(q0, jnp.ones(3))):
        np.testing.assert_array_equal(a, b)


def test_bind_computes_what_filter_jit_does_and_compiles_once_per_structure():
    """gnipy.compilation.bind: `fun(tree, *args)` as filter_jit computes it; trees of one structure
    with other numbers (new objects, other static function objects equal by value) share the program,
    a tree of another structure (a static field, a shape) compiles its own."""
    import equinox as eqx

    from gnipy.compilation import _bound_program, bind

    class Tree(eqx.Module):
        a: jax.Array
        b: tuple
        power: int = eqx.field(static=True)

    def fun(tree, x, y):
        return tree.power * jnp.sum(tree.a * x) + tree.b[0] @ y, tree.b[1] * x

    def make(a, power=2, n=3):
        return Tree(jnp.asarray(a, jnp.float64) * jnp.ones(n), (np.arange(n, dtype=np.float64), np.float64(0.5)), power)

    x, y = np.linspace(0.0, 1.0, 3), np.array([1.0, -2.0, 3.0])
    program = _bound_program()
    start = program._cache_size()
    for a in (1.0, 2.5, -3.0):
        tree = make(a)
        got = bind(fun, tree)(x, y)
        want = eqx.filter_jit(fun)(tree, x, y)
        assert all(np.array_equal(np.asarray(g), np.asarray(w)) for g, w in zip(got, want))
        assert np.asarray(got[0]) == 2 * a * np.sum(x) + np.arange(3.0) @ y
    assert program._cache_size() == start + 1  # three trees, one structure, one program
    bind(fun, make(1.0, power=3))(x, y)  # a static field
    bind(fun, make(1.0, n=4))(np.ones(4), np.ones(4))  # shapes
    assert program._cache_size() == start + 3

    class Unhashable(eqx.Module):  # a part that cannot key a program
        a: jax.Array
        options: set

    with pytest.raises(TypeError, match="tree: its parts that are not arrays must be hashable"):
        bind(lambda t, x: t.a @ x, Unhashable(jnp.ones(3), {1, 2}))
