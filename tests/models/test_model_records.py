"""A zoo model's record (its registered invariants and measured default method) belongs to the
systems the zoo builds (`System.model`), not to a name: a System written by hand inherits nothing
from the zoo model it is named like (issue 30). The default methods are data of the library: the
module the atlas writes (gnipy.experiments.atlas_report.default_methods_source), read by no file."""

import ast
import inspect
import types

import jax.numpy as jnp

import gnipy
from gnipy import registry
from gnipy.experiments.atlas_report import default_methods_source
from gnipy.models import default_methods


def test_zoo_systems_carry_their_model_and_hand_written_ones_none():
    spec = gnipy.get_model("knife-edge")
    built = [gnipy.make_system("knife-edge"), spec.system(), spec.build(spec.resolve_params()),
             *gnipy.model_systems("knife-edge", m=[1.0, 2.0])]
    assert [s.model for s in built] == ["knife-edge"] * len(built)
    assert built[0].without_metadata().model == "knife-edge"
    assert built[0].with_force(lambda q, v, u, t: jnp.zeros(3)).model == "knife-edge"
    own = gnipy.System(built[0].lagrangian, built[0].constraints, coordinates=built[0].coordinates, name="knife-edge")
    assert own.model is None and own.name == "knife-edge"
    assert registry.registered_invariants(own.model) == ()
    assert registry.registered_invariants(built[0].model) == tuple(spec.invariants)


def test_a_system_named_like_a_zoo_model_inherits_neither_invariants_nor_default():
    """The turning table's ball, from the zoo and written again by hand under the same name: the
    zoo's system runs its measured default and is told of its Jacobi integral; the hand-written
    one runs the fallback and is told of no registered invariant."""
    spec = gnipy.get_model("rotating-table-ball")
    zoo = spec.system()
    own = gnipy.System(zoo.lagrangian, zoo.constraints, zoo.affine, coordinates=zoo.coordinates, name=zoo.name,
                       args=zoo.args)
    q0, v0 = spec.initial_condition(spec.resolve_params())
    kw = dict(q0=q0, v0=v0, h=0.01, steps=50)
    from_zoo, by_hand = gnipy.simulate(zoo, **kw), gnipy.simulate(own, **kw)
    assert from_zoo.method == spec.default_method != registry.FALLBACK_METHOD
    assert by_hand.method == registry.FALLBACK_METHOD
    assert "jacobi" in from_zoo.conserved.lower() and "jacobi" not in by_hand.conserved.lower()


def test_the_recorded_defaults_are_the_atlas_record_and_read_no_file():
    """src/gnipy/models/default_methods.py is, to the byte, the module the atlas writes with the
    recorded recommendations (an atlas that measured no model keeps every entry), and it is data:
    importing it calls nothing but the registry's setter."""
    source = inspect.getsource(default_methods)
    assert source == default_methods_source(types.SimpleNamespace(models=[]))
    calls = {ast.unparse(n.func) for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Call)}
    assert calls == {"set_default_methods"}
    for name, (method, _) in default_methods.DEFAULT_METHODS.items():
        assert gnipy.get_model(name).default_method == method
        assert registry.default_method_for(gnipy.make_system(name).model) == method
