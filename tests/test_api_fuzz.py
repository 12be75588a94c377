"""Fuzzing the Python API: whatever the arguments, `gnipy.simulate`, `gnipy.model_systems` and
`gnipy.io.write_netcdf` either work or raise gnipy's own errors, which name the argument — never an
IndexError, OverflowError, MemoryError or a silently dropped imaginary part (issue 12).

Valid calls save two nodes (`save_every = steps`), so every run of a model shares one compiled
program; the examples are bounded, and no example allocates more than a few nodes.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import gnipy
from gnipy.io import OutputError, write_netcdf

#: The errors the API may raise for bad input: gnipy's own, each naming its argument.
ALLOWED = (gnipy.InputError, gnipy.MethodError, gnipy.SolverFailure)
#: Argument names an error message must start with (`name: ...`, `name[i]: ...`).
NAMED = re.compile(r"^(?:(?:--[a-z0-9-]+/)?[a-z_0-9]+(?:\[\d+\])?(?:/[a-z_0-9]+)*|member \d+|batch|lagrangian|constraints|affine)"
                   r"(?:\[\d+\])?:")

FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=True)

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=1e-330, max_value=1e-300),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.complex_numbers(max_magnitude=10.0),
    st.sampled_from([None, "0.1", "x", True, [0.1], 10**400, 2**53 + 1, 1e-320]),
)


def _vectors(n):
    return st.one_of(
        st.lists(st.floats(min_value=-2.0, max_value=2.0), min_size=n, max_size=n),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=n + 1),
        st.lists(st.complex_numbers(max_magnitude=2.0), min_size=n, max_size=n),
        st.just(np.zeros((0, n))),
        st.just(np.zeros((2, n, 1))),
        st.just("abc"),
        st.none(),
    )


@pytest.fixture(scope="module")
def knife():
    return gnipy.make_system("knife-edge")


def _check(call):
    try:
        call()
    except ALLOWED as e:
        message = str(e)
        assert NAMED.match(message) or isinstance(e, gnipy.SolverFailure), f"unnamed error: {message!r}"


@FUZZ
@given(h=numbers, steps=numbers, t_final=numbers)
@example(h=0.1, steps=4, t_final=None)
@example(h=0.1, steps=True, t_final=0.4)
@example(h=1e-320, steps=True, t_final=10.0)
def test_step_size_and_length(knife, h, steps, t_final):
    """h, steps, t_final of any type and size: a run (two saved nodes) or a named error."""
    use_t = isinstance(steps, bool)  # half the examples give t_final instead of steps

    def call():
        if use_t:
            n = gnipy.simulate(knife, "gni-trapezoid", h=h, t_final=t_final, save_every=2**62)
        else:
            n = gnipy.simulate(knife, "gni-trapezoid", h=h, steps=steps, save_every=2**62)
        assert len(n.t) == 2 and np.all(np.isfinite(np.asarray(n.q)))

    _check(call)


@FUZZ
@given(q0=_vectors(3), v0=_vectors(3), t0=numbers)
@example(q0=[0.0, 0.0, 0.0], v0=[1.0, 1.0, 1.0], t0=0.5)
@example(q0=np.zeros((2, 3)), v0=[1.0, 1.0, 1.0], t0=0.0)
def test_initial_conditions(knife, q0, v0, t0):
    """q0, v0 (wrong lengths, NaN, complex, empty batches) and t0: a run or a named error."""
    def call():
        sol = gnipy.simulate(knife, "gni-trapezoid", q0, v0, h=0.1, steps=4, save_every=4, t0=t0, project_v0=True)
        assert len(sol.t) == 2 and np.all(np.isfinite(np.asarray(sol.q)))
        # what was accepted is on the constraints (projected), to round-off
        assert np.max(np.abs(np.asarray(sol.constraint_residual))) < 1e-12

    _check(call)


@FUZZ
@given(params=st.dictionaries(st.sampled_from(["m", "J", "g", "alpha", "mass", ""]),
                              st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                        st.lists(st.floats(min_value=0.1, max_value=3.0), min_size=0, max_size=3),
                                        st.complex_numbers(max_magnitude=2.0), st.text(max_size=3)),
                              max_size=3))
@example(params={"m": [1.0, 2.0], "alpha": 0.2})
def test_parameter_batches(params):
    """Parameter values of any type for a batch: systems and a run, or a named error."""
    def call():
        systems = gnipy.model_systems("knife-edge", **params)
        sol = gnipy.simulate(systems, "gni-trapezoid", h=0.1, steps=4, save_every=4, throw=False)
        assert sol.batch_size == len(systems)

    _check(call)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(name=st.text(min_size=1, max_size=12).filter(lambda s: "\x00" not in s and "/" not in s))
def test_write_netcdf_names(tmp_path_factory, name):
    """Any file name: written (then refused a second time without overwrite), or an OutputError."""
    sol = _small_solution()
    path = tmp_path_factory.mktemp("names") / name
    try:
        write_netcdf(sol, path)
    except OutputError as e:
        assert str(path) in str(e) or "path:" in str(e)
        return
    with pytest.raises(OutputError, match="exists; pass overwrite=True"):
        write_netcdf(sol, path)
    write_netcdf(sol, path, overwrite=True)


_SMALL = {}


def _small_solution():
    if "sol" not in _SMALL:
        _SMALL["sol"] = gnipy.simulate(gnipy.make_system("knife-edge"), "gni-trapezoid", h=0.1, steps=4,
                                       save_every=4)
    return _SMALL["sol"]


# ------------------------------------------------------------------------------------------------
# Strict types (issue 28, D9): a string or a boolean is not a number, a flag is True or False
# ------------------------------------------------------------------------------------------------
texts_and_bools = st.one_of(st.text(max_size=6), st.booleans(), st.sampled_from([b"0.1", np.bool_(True), "0.01",
                                                                                   "1e-2", "nan"]))


@FUZZ
@given(value=texts_and_bools, argument=st.sampled_from(["h", "t_final", "t0"]))
def test_texts_and_booleans_are_not_numbers(knife, value, argument):
    """`simulate(h=True)` ran with h = 1 and `h="0.01"` was accepted: now each is refused, naming it."""
    kwargs = {"h": 0.1, "t_final": 0.4, argument: value}
    with pytest.raises(gnipy.InputError, match=rf"^{argument}: expected a (positive )?number"):
        gnipy.simulate(knife, "gni-trapezoid", **kwargs)


@FUZZ
@given(value=st.one_of(st.text(max_size=4), st.integers(), st.none(), st.just([True])),
       argument=st.sampled_from(["throw", "project_v0"]))
def test_flags_are_true_or_false(knife, value, argument):
    """`throw="no"` and `project_v0="no"` were truthy (`throw` also takes "strict")."""
    with pytest.raises(gnipy.InputError, match=rf"^{argument}: expected True(,| or) False"):
        gnipy.simulate(knife, "gni-trapezoid", h=0.1, steps=2, **{argument: value})


@pytest.mark.parametrize("q0", [["0", "0", "0"], [True, 0.0, 0.0], np.array(["1", "2", "3"])])
def test_initial_conditions_of_strings_or_booleans_are_refused(knife, q0):
    with pytest.raises(gnipy.InputError, match="^q0: expected 3 real numbers, got (strings|str|bool)"):
        gnipy.simulate(knife, "gni-trapezoid", q0, [1.0, 0.0, 0.0], h=0.1, steps=2)


@pytest.mark.parametrize("value", ["1", ["0", "1"], True, [True, False], np.array([True, False])])
def test_model_parameters_of_strings_or_booleans_are_refused(value):
    with pytest.raises(gnipy.InputError, match="^params: parameter 'Omega'"):
        gnipy.model_systems("rolling-ball", Omega=value)
    with pytest.raises(gnipy.InputError, match="^params: parameter 'Omega'"):
        gnipy.get_model("rolling-ball").system(Omega=value)


def test_save_times_in_the_wrong_order_are_refused(knife):
    """`SaveAt(ts=[0.05, 0.01])` was silently sorted, so row i no longer matched ts[i]."""
    with pytest.raises(gnipy.InputError, match=r"^saveat.ts: the times are decreasing, but h = 0.01 runs forward"):
        gnipy.simulate(knife, "gni-trapezoid", h=0.01, steps=10, saveat=gnipy.SaveAt(ts=[0.05, 0.01]))
    sol = gnipy.simulate(knife, "gni-trapezoid", h=0.01, steps=10, saveat=gnipy.SaveAt(ts=[0.01, 0.05]))
    np.testing.assert_allclose(np.asarray(sol.t), [0.01, 0.05], rtol=0, atol=1e-15)
    with pytest.raises(gnipy.InputError, match="^saveat.ts: expected a sequence of times, got str '0.1'"):
        gnipy.SaveAt(ts=["0.1"])


def test_a_sequence_of_different_systems_is_refused_by_name(knife):
    """`simulate([knife-edge, vertical-disk])` raised a bare ValueError from np.stack."""
    disk = gnipy.make_system("vertical-disk")
    with pytest.raises(gnipy.InputError, match=r"^system\[1\]: is 'vertical-disk' .* system\[0\] is 'knife-edge'"):
        gnipy.simulate([knife, disk], "gni-trapezoid", h=0.1, steps=2)
