"""The user's own systems by reference (gnipy.user_systems, gnipy.registry.get_model and
model_from_function) and parameters as arguments (System(args=...)), with systems defined in files
of the tests' own (tests/user_system_files.py).

Reference values: the zoo's Chaplygin sleigh (gnipy.models.chaplygin_sleigh: the same mechanics
written separately), run with the same method, parameters and start (the same arithmetic: equal to
round-off); derivatives against central differences; the digests against hashlib.
"""

from __future__ import annotations

import hashlib
import os
import stat
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy.registry import model_from_function
from gnipy.user_systems import _trust_problem, load, split_reference
from user_system_files import SLEIGH_ARGS, SLEIGH_CLOSURE, write_source

CHECK_EVERY_NODE = False
H, STEPS = 0.02, 50


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("user_models")
    os.chmod(d, 0o755)
    write_source(d / "sleigh_args.py", SLEIGH_ARGS)
    write_source(d / "sleigh_closure.py", SLEIGH_CLOSURE)
    return d


def zoo_run(**params):
    a = params["a"]
    return gnipy.simulate(gnipy.make_system("chaplygin-sleigh", **params), "gni-midpoint", (0.0, 0.0, 0.0),
                          (1.0, a, 1.0), h=H, steps=STEPS)


# ------------------------------------------------------------------------------------------------
# loading
# ------------------------------------------------------------------------------------------------
def test_a_file_loads_with_its_digest_and_no_bytecode(folder):
    loaded = load(f"{folder / 'sleigh_args.py'}:make_sleigh")
    data = (folder / "sleigh_args.py").read_bytes()
    assert loaded.digest == "sha256:" + hashlib.sha256(data).hexdigest()
    assert loaded.reference == f"{folder / 'sleigh_args.py'}:make_sleigh"
    assert callable(loaded.obj) and loaded.obj.__name__ == "make_sleigh"
    assert not (folder / "__pycache__").exists()  # compiled by gnipy: no cached bytecode read or written
    assert str(folder) not in sys.path


def test_a_relative_reference_is_made_absolute(folder, monkeypatch):
    monkeypatch.chdir(folder)
    spec = gnipy.get_model("sleigh_args.py:make_sleigh")
    assert spec.name == f"{folder / 'sleigh_args.py'}:make_sleigh"
    assert spec.origin == (spec.name, "sha256:" + hashlib.sha256(SLEIGH_ARGS.encode()).hexdigest())


@pytest.mark.parametrize("text, message", [
    ("sleigh_args.py:", "NAME a Python name"),
    ("sleigh_args.py:make-sleigh", "NAME a Python name"),
    ("not a module:f", "SOURCE must be a file ending in .py or a dotted module name"),
])
def test_malformed_references(text, message):
    with pytest.raises(gnipy.InputError, match=message) as e:
        split_reference(text)
    assert str(e.value).startswith("model: ")


def test_missing_file_name_and_bad_python(folder):
    with pytest.raises(gnipy.InputError, match="no file"):
        gnipy.get_model(f"{folder / 'nothing.py'}:f")
    with pytest.raises(gnipy.InputError, match=r"has no 'make_sled' \(its functions: constraints, lagrangian, make_sleigh"):
        gnipy.get_model(f"{folder / 'sleigh_args.py'}:make_sled")
    bad = write_source(folder / "bad.py", "def f(:\n")
    with pytest.raises(gnipy.InputError, match="is not valid Python"):
        gnipy.get_model(f"{bad}:f")
    with pytest.raises(gnipy.InputError, match="no module 'no_such_gnipy_module_xyz'"):
        gnipy.get_model("no_such_gnipy_module_xyz:f")


def test_a_file_others_may_write_is_refused_before_it_runs(tmp_path, monkeypatch):
    monkeypatch.setattr("gnipy.user_systems.private_group", lambda gid: False)  # whoever runs the tests
    os.chmod(tmp_path, 0o755)
    marker = tmp_path / "ran"
    src = f"open({str(marker)!r}, 'w').close()\ndef f():\n    pass\n"
    path = write_source(tmp_path / "group.py", src, mode=0o664)
    with pytest.raises(gnipy.InputError, match=r"refusing to run .*the file is writable by its group \(mode 0664\)"):
        gnipy.get_model(f"{path}:f")
    os.chmod(path, 0o646)
    with pytest.raises(gnipy.InputError, match="writable by others"):
        gnipy.get_model(f"{path}:f")
    assert not marker.exists()
    # its folder, likewise (without the sticky bit)
    os.chmod(path, 0o644)
    os.chmod(tmp_path, 0o777)
    try:
        with pytest.raises(gnipy.InputError, match="its folder is writable by its group and others"):
            gnipy.get_model(f"{path}:f")
        assert not marker.exists()
        os.chmod(tmp_path, 0o1777)  # like /tmp: no one else can replace the user's own file
        with pytest.raises(gnipy.InputError, match="returned a NoneType, expected a gnipy.System"):
            gnipy.get_model(f"{path}:f")
        assert marker.exists()
    finally:
        os.chmod(tmp_path, 0o755)


def test_ownership_rules():
    """Another user's file or folder is refused; root's and the user's are not (stat results built
    here: the tests cannot own a file as someone else)."""
    def st(mode, uid):
        return os.stat_result((mode, 0, 0, 1, uid, 0, 10, 0, 0, 0))

    me, other = os.geteuid(), os.geteuid() + 4242
    assert _trust_problem(st(stat.S_IFREG | 0o644, me), "the file") is None
    assert _trust_problem(st(stat.S_IFREG | 0o644, 0), "the file") is None
    assert "belongs to" in _trust_problem(st(stat.S_IFREG | 0o644, other), "the file")
    assert "writable by others" in _trust_problem(st(stat.S_IFDIR | 0o757, me), "its folder", folder=True)
    assert _trust_problem(st(stat.S_IFDIR | 0o1777, 0), "its folder", folder=True) is None


def test_a_module_reference(tmp_path, monkeypatch):
    pkg = tmp_path / "my_gnipy_models"
    pkg.mkdir()
    os.chmod(tmp_path, 0o755)
    os.chmod(pkg, 0o755)
    write_source(pkg / "__init__.py", "")
    write_source(pkg / "sleighs.py", SLEIGH_ARGS)
    monkeypatch.syspath_prepend(str(tmp_path))
    spec = gnipy.get_model("my_gnipy_models.sleighs:make_sleigh")
    assert spec.name == "my_gnipy_models.sleighs:make_sleigh"
    assert spec.origin[1] == "sha256:" + hashlib.sha256(SLEIGH_ARGS.encode()).hexdigest()
    assert spec.params == {"m": 1.0, "I": 0.5, "a": 0.3}


# ------------------------------------------------------------------------------------------------
# a function as a model
# ------------------------------------------------------------------------------------------------
def test_the_model_of_a_function(folder):
    ref = f"{folder / 'sleigh_args.py'}:make_sleigh"
    spec = gnipy.get_model(ref)
    assert spec is gnipy.get_model(ref)  # one spec per source: its runs share compilations
    assert spec.params == {"m": 1.0, "I": 0.5, "a": 0.3}  # `label` (a string default) is not a parameter
    assert spec.coordinates == ("x", "y", "theta")
    assert (spec.q0, spec.v0) == ((0.0, 0.0, 0.0), (1.0, 0.3, 1.0))
    assert spec.initial_condition(spec.resolve_params({"a": 0.7})) == ((0.0, 0.0, 0.0), (1.0, 0.7, 1.0))
    assert spec.description == "A sleigh of mass m, inertia I and knife-edge offset a."
    system = spec.system(a=0.7)
    assert system.origin == spec.origin and system.model is None  # no zoo invariants or record apply
    assert system.parameters == {"m": 1.0, "I": 0.5, "a": 0.7}
    # its args follow by name, the default start with them (the function builds it again)
    assert system.with_args(a=0.2).defaults == ((0.0, 0.0, 0.0), (1.0, 0.2, 1.0))
    with pytest.raises(gnipy.InputError, match="unknown parameter 'b'"):
        spec.system(b=1.0)
    with pytest.raises(gnipy.InputError, match="returned a int, expected a gnipy.System"):
        gnipy.get_model(f"{folder / 'sleigh_args.py'}:not_a_system")
    with pytest.raises(gnipy.InputError, match="parameter 'm' has no default"):
        gnipy.get_model(f"{folder / 'sleigh_closure.py'}:needs_value")
    with pytest.raises(gnipy.InputError, match="is a float, not a function"):
        model_from_function(1.5)


def test_a_system_object_is_a_model_without_parameters(folder):
    spec = gnipy.get_model(f"{folder / 'sleigh_closure.py'}:SLEIGH")
    assert spec.params == {} and spec.v0 == (1.0, 0.3, 1.0)
    with pytest.raises(gnipy.InputError, match="unknown parameter 'a'.*known: none"):
        spec.system(a=0.2)


@pytest.mark.parametrize("source", ["sleigh_args.py", "sleigh_closure.py"])
def test_a_user_model_runs_as_the_zoo_sleigh(folder, source):
    spec = gnipy.get_model(f"{folder / source}:make_sleigh")
    params = spec.resolve_params({"a": 0.45, "I": 0.8})
    q0, v0 = spec.initial_condition(params)
    sol = gnipy.simulate(spec.build(params), "gni-midpoint", q0, v0, h=H, steps=STEPS)
    ref = zoo_run(m=1.0, I=0.8, a=0.45)
    np.testing.assert_allclose(sol.q, ref.q, rtol=0, atol=1e-13)
    np.testing.assert_allclose(sol.v, ref.v, rtol=0, atol=1e-13)
    assert sol.healthy


# ------------------------------------------------------------------------------------------------
# parameters as arguments
# ------------------------------------------------------------------------------------------------
def _sleigh(**args):
    def l(q, v, p):
        return 0.5 * p["m"] * (v[0] ** 2 + v[1] ** 2) + 0.5 * p["I"] * v[2] ** 2

    def mu(q, p):
        return jnp.stack([-jnp.sin(q[2]), jnp.cos(q[2]), -p["a"] * jnp.ones_like(q[2])])[None, :]

    return gnipy.System(l, mu, coordinates=("x", "y", "theta"), args=args)


def test_args_are_leaves_that_grad_reaches():
    base = _sleigh(m=1.0, I=0.5, a=0.3)
    assert base.params == (("m", 1.0), ("I", 0.5), ("a", 0.3))
    q0, v0 = jnp.zeros(3), jnp.array([1.0, 0.3, 1.0])

    def final_x(m):
        return gnipy.simulate(base.with_args(m=m), "gni-midpoint", q0, v0, h=H, steps=STEPS).q[-1, 0]

    g = jax.grad(final_x)(1.3)
    eps = 1e-5
    fd = (final_x(1.3 + eps) - final_x(1.3 - eps)) / (2 * eps)
    assert abs(g - fd) < 1e-8 * max(1.0, abs(fd)), (g, fd)
    # the zoo's sleigh at m = 1.3: the same trajectory
    np.testing.assert_allclose(final_x(1.3), zoo_run(m=1.3, I=0.5, a=0.3).q[-1, 0], rtol=0, atol=1e-13)


def test_args_batch_as_one_program():
    systems = [_sleigh(m=1.0, I=I, a=0.3) for I in (0.5, 0.8)]
    # one function pair, two values: the batch runs them stacked
    systems = [systems[0].with_args(I=I) for I in (0.5, 0.8)]
    sol = gnipy.simulate(systems, "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=STEPS)
    assert sol.q.shape == (2, STEPS + 1, 3)
    for i, I in enumerate((0.5, 0.8)):
        np.testing.assert_allclose(sol.q[i], zoo_run(m=1.0, I=I, a=0.3).q, rtol=0, atol=1e-13)


def test_args_are_checked():
    with pytest.raises(gnipy.InputError, match="args: expected a mapping"):
        gnipy.System(lambda q, v, p: v @ v, lambda q, p: q[None, :], n=2, args=[1.0])
    with pytest.raises(gnipy.InputError, match="args: parameter 'm' must be finite"):
        _sleigh(m=float("nan"), I=0.5, a=0.3)
    with pytest.raises(gnipy.InputError, match="args: parameter 'm' must be a number"):
        _sleigh(m="1", I=0.5, a=0.3)
    with pytest.raises(gnipy.InputError, match="args: unknown parameter 'b'"):
        _sleigh(m=1.0, I=0.5, a=0.3).with_args(b=2.0)
    closed = gnipy.System(lambda q, v: 0.5 * v @ v, lambda q: jnp.array([[0.0, 0.0, 1.0]]), n=3)
    with pytest.raises(gnipy.InputError, match="has no named parameters"):
        closed.with_args(m=2.0)


def test_a_zoo_model_takes_its_parameters_as_args():
    """The zoo's models hold their parameters as args: with_args(a=...) is the model built with
    a = ..., its default start included (v0 = (1, a, 1) for the sleigh), and the System hashes
    (a bound method of it under jax.jit)."""
    zoo = gnipy.make_system("chaplygin-sleigh")
    assert set(zoo.args) == set(gnipy.get_model("chaplygin-sleigh").params)
    moved = zoo.with_args(a=0.7)
    built = gnipy.make_system("chaplygin-sleigh", a=0.7)
    assert moved.defaults == built.defaults == ((0.0, 0.0, 0.0), (1.0, 0.7, 1.0))
    assert moved.parameters == built.parameters
    np.testing.assert_array_equal(gnipy.simulate(moved, "gni-midpoint", h=H, steps=10).q,
                                  gnipy.simulate(built, "gni-midpoint", h=H, steps=10).q)
    np.testing.assert_allclose(jax.jit(zoo.metric)(jnp.zeros(3)), np.diag([1.0, 1.0, 1.0]), rtol=0, atol=0)
    # a System written by hand has no rule for its defaults: with_args drops them, a run asks
    hand = _sleigh(m=1.0, I=0.5, a=0.3)
    hand = gnipy.System(hand.lagrangian, hand.constraints, coordinates=hand.coordinates, args=dict(hand.args),
                        defaults=((0.0, 0.0, 0.0), (1.0, 0.3, 1.0)))
    with pytest.raises(gnipy.InputError, match="has no default initial condition; give q0 and v0"):
        gnipy.simulate(hand.with_args(a=0.7), "gni-midpoint", h=H, steps=10)


def test_a_force_receives_args_too():
    """F(q, v, u, t, args): a torque scaled by a parameter, against the same torque written out."""
    base = _sleigh(m=1.0, I=0.5, a=0.3)
    args_sys = gnipy.System(base.lagrangian, base.constraints, coordinates=base.coordinates,
                            args=dict(m=1.0, I=0.5, a=0.3, k=2.0),
                            force=lambda q, v, u, t, p: jnp.array([0.0, 0.0, p["k"] * u[0]]), inputs=1)
    zoo = gnipy.make_system("chaplygin-sleigh", m=1.0, I=0.5, a=0.3).with_force(
        lambda q, v, u, t: jnp.array([0.0, 0.0, 2.0 * u[0]]), inputs=1)
    controls = np.full((STEPS, 1), 0.3)
    runs = [gnipy.simulate(s, "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=STEPS,
                           controls=controls) for s in (args_sys, zoo)]
    np.testing.assert_allclose(runs[0].q, runs[1].q, rtol=0, atol=1e-13)
    # a force F(q, v, u, t) added to a system with args keeps working (it does not take them)
    four = base.with_force(lambda q, v, u, t: jnp.array([0.0, 0.0, 2.0 * u[0]]), inputs=1)
    assert not four.force_args and args_sys.force_args
    sol = gnipy.simulate(four, "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=STEPS, controls=controls)
    np.testing.assert_allclose(sol.q, runs[1].q, rtol=0, atol=1e-13)
    # gnipy's own input force (gni control's [inputs]) on a system with args
    from gnipy.forcing import input_force

    F, m, _ = input_force(base, {"torque": {"dtheta": 2.0}})
    driven = base.with_force(F, inputs=m)
    sol = gnipy.simulate(driven, "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=STEPS,
                         controls=controls)
    np.testing.assert_allclose(sol.q, runs[1].q, rtol=0, atol=1e-13)


def test_fit_estimates_args_in_place():
    """gnipy.fit on a System with args: the estimated parameter is set by name (with_args), no
    build function; noise-free data of I = 0.8 give it back."""
    base = _sleigh(m=1.0, I=0.5, a=0.3)
    observed = gnipy.simulate(base.with_args(I=0.8, a=0.4), "gni-trapezoid", (0.0, 0.0, 0.0), (1.0, 0.4, 1.0),
                              h=0.05, steps=30)
    result = gnipy.fit(base, observed, params={"I": 0.6}, fixed={"a": 0.4}, q0=(0.0, 0.0, 0.0), v0=(1.0, 0.4, 1.0),
                       method="gni-trapezoid", h=0.05)
    assert result.success and abs(result.params["I"] - 0.8) < 1e-10, result
    with pytest.raises(gnipy.InputError, match="params: unknown parameter 'J' of the System"):
        gnipy.fit(base, observed, params={"J": 0.6}, method="gni-trapezoid", h=0.05)


# ------------------------------------------------------------------------------------------------
# the edges of loading (review of issue 31)
# ------------------------------------------------------------------------------------------------
def test_a_symbolic_link_is_checked_at_its_target(tmp_path, monkeypatch):
    """The link is followed; the target's folder is what is checked."""
    monkeypatch.setattr("gnipy.user_systems.private_group", lambda gid: False)
    mine, shared = tmp_path / "mine", tmp_path / "shared"
    mine.mkdir(mode=0o755)
    shared.mkdir()
    os.chmod(tmp_path, 0o755)
    os.chmod(shared, 0o777)  # anyone may replace what is in it
    target = write_source(shared / "sleigh.py", SLEIGH_ARGS)
    os.symlink(target, mine / "sleigh.py")
    try:
        with pytest.raises(gnipy.InputError, match="its folder is writable by its group and others"):
            gnipy.get_model(f"{mine / 'sleigh.py'}:make_sleigh")
        os.chmod(shared, 0o755)
        spec = gnipy.get_model(f"{mine / 'sleigh.py'}:make_sleigh")
        assert spec.params == {"m": 1.0, "I": 0.5, "a": 0.3}
    finally:
        os.chmod(shared, 0o755)


def test_the_users_errors_name_the_model_and_the_line(tmp_path):
    os.chmod(tmp_path, 0o755)
    top = write_source(tmp_path / "top.py", "import numpy\nDATA = numpy.loadtxt('no-such-file.csv')\n")
    with pytest.raises(gnipy.InputError, match=r"^model: '.*top.py': running it raised FileNotFoundError: .*top.py:2\)"):
        gnipy.get_model(f"{top}:f")
    inside = write_source(tmp_path / "inside.py", "def f(k=1.0):\n    return 1 / 0\n")
    with pytest.raises(gnipy.InputError, match=r"running it raised ZeroDivisionError: division by zero \(at .*inside.py:2\)"):
        gnipy.get_model(f"{inside}:f")
    with pytest.raises(gnipy.InputError, match="model: cannot open"):
        gnipy.get_model("bad\0name.py:f")
    with pytest.raises(gnipy.InputError, match=r"model: 'json.decoder': running it raised|no 'nothing_here'"):
        gnipy.get_model("json.decoder:nothing_here")


def test_two_files_of_the_same_text_are_two_modules(tmp_path):
    os.chmod(tmp_path, 0o755)
    (tmp_path / "a").mkdir(mode=0o755)
    (tmp_path / "b").mkdir(mode=0o755)
    one = load(f"{write_source(tmp_path / 'a' / 'm.py', SLEIGH_ARGS)}:make_sleigh").obj
    two = load(f"{write_source(tmp_path / 'b' / 'm.py', SLEIGH_ARGS)}:make_sleigh").obj
    assert one.__module__.startswith("gnipy_user_") and two.__module__.startswith("gnipy_user_")
    assert one.__module__ != two.__module__ and sys.modules[one.__module__].__file__.endswith("a/m.py")


def test_with_args_keeps_what_the_function_was_built_with(tmp_path):
    """A function whose keywords are not all its args: with_args rebuilds with the values the System
    was built with (L = 3 here), not the function's defaults."""
    os.chmod(tmp_path, 0o755)
    src = write_source(tmp_path / "bar.py", SLEIGH_ARGS.replace(
        "def make_sleigh(m=1.0, I=0.5, a=0.3, label=\"mine\"):", "def make_sleigh(m=1.0, I=0.5, a=0.3, L=2.0):").replace(
        "defaults=((0.0, 0.0, 0.0), (1.0, a, 1.0))", "defaults=((L, 0.0, 0.0), (1.0, a, 1.0))"))
    spec = gnipy.get_model(f"{src}:make_sleigh")
    assert spec.params == {"m": 1.0, "I": 0.5, "a": 0.3, "L": 2.0}
    moved = spec.system(L=3.0).with_args(a=0.2)
    assert moved.defaults == ((3.0, 0.0, 0.0), (1.0, 0.2, 1.0))
    with pytest.raises(gnipy.InputError, match=r"args: parameter 'm' has shape \(\), got a value of shape \(3,\)"):
        moved.with_args(m=jnp.ones(3))


def test_a_force_with_a_keyword_default_is_not_given_args():
    base = _sleigh(m=1.0, I=0.5, a=0.3)
    keyword = base.with_force(lambda q, v, u, t, gain=2.0: jnp.array([0.0, 0.0, gain * u[0]]), inputs=1)
    starred = base.with_force(lambda *a: jnp.array([0.0, 0.0, a[-1]["m"] * a[-3][0]]), inputs=1)
    assert not keyword.force_args and starred.force_args
    controls = np.full((10, 1), 0.3)
    runs = [gnipy.simulate(s, "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=10, controls=controls)
            for s in (keyword, starred)]
    zoo = gnipy.make_system("chaplygin-sleigh", m=1.0, I=0.5, a=0.3)
    for run, gain in zip(runs, (2.0, 1.0)):  # the keyword's default gain 2; m = 1 read from args
        ref = gnipy.simulate(zoo.with_force(lambda q, v, u, t, g=gain: jnp.array([0.0, 0.0, g * u[0]]), inputs=1),
                             "gni-midpoint", (0.0, 0.0, 0.0), (1.0, 0.3, 1.0), h=H, steps=10, controls=controls)
        np.testing.assert_allclose(run.q, ref.q, rtol=0, atol=1e-13)


def test_a_private_group_may_write(monkeypatch):
    """umask 002 with user-private groups: group write by the user's own group is no one else's."""
    import gnipy.user_systems as us

    def st(mode, gid):
        return os.stat_result((mode, 0, 0, 1, os.geteuid(), gid, 10, 0, 0, 0))

    monkeypatch.setattr(us, "private_group", lambda gid: gid == 4242)
    assert _trust_problem(st(stat.S_IFREG | 0o664, 4242), "the file") is None
    assert "writable by its group" in _trust_problem(st(stat.S_IFREG | 0o664, 4343), "the file")
    assert "writable by others" in _trust_problem(st(stat.S_IFREG | 0o666, 4242), "the file")


def test_a_data_file_names_only_a_file_beside_it(tmp_path):
    from gnipy.user_systems import data_file_reference

    assert data_file_reference("models/s.py:f", tmp_path, "system.model") == f"{tmp_path / 'models' / 's.py'}:f"
    assert data_file_reference("chaplygin-sleigh", tmp_path, "system.model") == "chaplygin-sleigh"
    for text in ("/etc/x.py:f", "../x.py:f", "~/x.py:f", "os:abort", "sub/../../x.py:f"):
        with pytest.raises(gnipy.InputError, match=r"^system.model: in a file of data, a model of your own must"):
            data_file_reference(text, tmp_path, "system.model")
