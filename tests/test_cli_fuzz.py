"""Fuzzing the `gni` command line: arbitrary strings for every option, random config
files and random result files never give a Python traceback.

Every invocation (typer's CliRunner, in process) is checked for:

- no "Traceback" in the output, and `result.exception` None or a `SystemExit` (how typer
  exits);
- on failure: a non-zero exit code and exactly one line starting with "Error", which
  names the option the error is about; for a fuzzed value that is invalid, that is the
  fuzzed option.

**No fuzzed run may start a simulation** (a compilation costs seconds). Each command
line carries a *sentinel*: another option whose value is invalid and which `gni` checks
after the fuzzed one and before any computation, so that a fuzzed value that happens to
be valid ends in the sentinel's error. The order of the checks, read from
the `gnipy/cli/` modules:

- `gni run`: config file, MODEL, --method, --h, --steps/--t-final, --save-every, the step
  count (gnipy.simulate.resolve_steps: h below the normal floats, t_final / h beyond any run,
  t_final not a whole number of steps), --set, --q0, --v0, --R0, then --out (its directory
  writable; nothing there, or a regular file and --overwrite; never a link, FIFO or
  directory), --plot (the same), --checkpoint-every, the memory and file bounds (unless
  --yes), then the run. Sentinel `--out /<missing dir>/x.nc` for everything parsed before
  --out; `--checkpoint-every 0` when fuzzing --out and --plot; `--method reference` (not
  streamed) when fuzzing --checkpoint-every.
- `gni convergence`: --error, MODEL, --set, --q0, --v0, --methods, --h-max, --h-min,
  --count, --t-final, --R0, then --out, then the initial condition, then the study.
  Sentinel: --out an existing file; when fuzzing --out, a v0 off the constraints.
- `gni demo`: --out is its only input: fuzzed below a missing directory.
- `gni verify PATH`, `gni info FILE`: random file contents, random attributes (rich markup,
  control characters), and paths that are links, FIFOs, directories or unfinished runs:
  they compute nothing (exit 0, 1 or 2, one clean line).

Path options pointing at existing files, symbolic links, FIFOs and directories (with and
without --overwrite) are checked for every command that writes: what is there is left as it
was, and a refusal names the option.

A tripwire (a module fixture) replaces every entry point of a computation with a
function that raises, so that a sentinel that failed to stop a run shows up as a test
failure, not a slow test.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app

runner = CliRunner()

MODEL = "vertical-disk"  # 4 coordinates, 4 velocities, no group part
GROUP_MODEL = "suslov"  # on SO(3): --R0 takes 9 numbers
MISSING_DIR = "/nonexistent-gnipy-fuzz-dir"
MISSING_OUT = f"{MISSING_DIR}/x.nc"
OFF_CONSTRAINTS_V0 = "0,1,1,1"  # vertical disk at φ = 0: ẏ = 0 is violated

HAS_SWEEP = any(
    (c.name or c.callback.__name__) == "sweep" for c in app.registered_commands
)

RUN_OPTIONS = {
    "MODEL",
    "--method",
    "--h",
    "--steps",
    "--t-final",
    "--set",
    "--q0",
    "--v0",
    "--R0",
    "--project-v0",
    "--save-every",
    "--out",
    "--plot",
    "--config",
    "--checkpoint-every",
    "--resume",
    "--overwrite",
    "--yes",
}


def fuzz_settings(max_examples: int):
    return settings(
        max_examples=max_examples,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow],
    )


# --------------------------------------------------------------------------------------
# The tripwire: nothing may compute
# --------------------------------------------------------------------------------------
class ReachedComputation(AssertionError):
    pass


def _tripwire(*args, **kwargs):
    raise ReachedComputation(
        "a fuzzed command line reached a computation: its sentinel did not stop it"
    )


@pytest.fixture(scope="module", autouse=True)
def tripwire():
    import gnipy.cli
    import gnipy.experiments.reproduce
    import gnipy.streaming

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(gnipy, "simulate", _tripwire)
        mp.setattr(gnipy.streaming, "simulate_to_file", _tripwire)
        mp.setattr(gnipy.experiments.reproduce, "run_reproduction", _tripwire)
        if HAS_SWEEP:  # (being written: only its command-line checks are fuzzed here)
            import gnipy.sweep

            mp.setattr(gnipy.sweep, "run_sweep", _tripwire)
        yield


# --------------------------------------------------------------------------------------
# Strategies
# --------------------------------------------------------------------------------------
SPECIAL = [
    "",
    " ",
    "=",
    "==",
    ",",
    ",,",
    "=1",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "Infinity",
    "-1e999",
    "1e999",
    "1e-320",
    "0",
    "-0",
    "-1",
    "0.1",
    "1",
    "2.5",
    "1_0",
    "0x10",
    "1e5",
    " 3 ",
    "١٢",
    "²",
    "1,2,3,4",
    "1 2 3 4",
    "1,2,3",
    "1,2,3,4,5",
    "1,nan,3,4",
    "1,,2,3,4",
    "--h",
    "-",
    "--",
    "\x00",
    "\n",
    "\t",
    "ü",
    "🚀",
    "r=1",
    "m=-1",
    "r=nan",
    "I_rot=2,r",
    "x=1",
    "=1,r=",
    "/",
    "..",
    ".",
    "~",
    "$HOME",
    "a" * 300,
    "1e308,1e308,1e308,1e308",
    "gni-trapezoid",
    "reference",
    "vertical-disk",
    "1,0,0,0,1,0,0,0,1",
    "x.png",
    "x.nc",
    "a/b.nc",
]


def fuzz_text():
    """Arbitrary strings, biased towards the ones parsers trip on."""
    return st.one_of(
        st.sampled_from(SPECIAL),
        st.text(max_size=30),
        st.text(alphabet="0123456789.,=eE+-naifINF_ x", max_size=24),
        st.integers(300, 20000).map(lambda n: "9" * n),  # huge numbers, long names
        st.lists(st.sampled_from(SPECIAL), min_size=2, max_size=5).map(",".join),
    )


def number_text():
    """Numbers as people and programs write them (valid or not for a positive
    option)."""
    return st.one_of(
        st.floats().map(repr),  # nan, inf, -0.0, 5e-324, 1e+300, ...
        st.integers(-(10**30), 10**30).map(str),
        st.floats(0.0, 10.0).map(lambda x: f"{x:.3g}"),
    )


def vector_text(n: int):
    """n numbers (or one more or one less), separated by commas or spaces."""
    elements = st.one_of(
        st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.floats()
    )  # mostly finite
    count = st.one_of(st.just(n), st.integers(max(0, n - 1), n + 1))  # mostly n
    return st.tuples(
        count.flatmap(lambda k: st.lists(elements, min_size=k, max_size=k)),
        st.sampled_from([",", " ", ", ", ",,"]),
    ).map(lambda a: a[1].join(repr(x) for x in a[0]))


def name_text(names):
    """Valid names and near misses (case, whitespace, truncation)."""
    names = sorted(names)
    return st.one_of(
        st.sampled_from(names),
        st.sampled_from(names).map(str.upper),
        st.sampled_from(names).map(lambda x: f" {x}"),
        st.sampled_from(names).map(lambda x: x[:-1]),
    )


def set_text():
    """NAME=VALUE items for the vertical disk (known and unknown names, any values)."""
    names = st.one_of(
        st.sampled_from(sorted(gnipy.get_model(MODEL).params)), fuzz_text()
    )
    items = st.tuples(names, st.one_of(number_text(), fuzz_text())).map(
        lambda a: f"{a[0]}={a[1]}"
    )
    return st.lists(items, min_size=1, max_size=3).map(",".join)


# --------------------------------------------------------------------------------------
# Checking one invocation
# --------------------------------------------------------------------------------------
_NAMED = [
    re.compile(r"Error: Invalid value for '([^']+)'"),
    re.compile(r"Error: Option '([^']+)'"),
    re.compile(r"Error: No such option: (\S+)"),
    re.compile(r"Error: Missing (?:argument|option) '([^']+)'"),
    re.compile(r"Error: ((?:--[\w-]+|MODEL|FILE|PATH)(?:/--[\w-]+)*)(?: \(from [^)]*\))?:"),
]
# click's errors about words that belong to no option: they name the word instead
EXTRA_ARGUMENT, NO_SUCH_COMMAND = "<extra argument>", "<no such command>"
_WORDS = [
    (re.compile(r"Error: Got unexpected extra argument"), EXTRA_ARGUMENT),
    (re.compile(r"Error: No such command "), NO_SUCH_COMMAND),
]


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def assert_clean(res, computation_ok: bool = False) -> set[str] | None:
    """The properties every invocation has; returns the options the error names (None on
    success).

    `computation_ok`: arbitrary words may happen to form a valid command line, whose
    computation the tripwire stops; that counts as a success of the parsing."""
    if computation_ok and isinstance(res.exception, ReachedComputation):
        return None
    assert "Traceback" not in res.output, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(
        res.exception
    )
    if res.exit_code == 0:
        return None
    assert res.exit_code in (1, 2), res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1, res.output
    for pattern in _NAMED:
        m = pattern.match(errors[0])
        if m:
            return set(m.group(1).split("/"))
    for pattern, word in _WORDS:
        if pattern.match(errors[0]):
            return {word}
    raise AssertionError(f"the error names no option: {errors[0]!r}")


def assert_fails_naming(res, allowed: set[str], required: str | None = None) -> set[str]:
    named = assert_clean(res)
    assert named is not None, f"expected a failure, got exit code 0:\n{res.output}"
    assert named & allowed, (named, allowed, res.output)
    if required is not None:
        assert required in named, (named, required, res.output)
    return named


def _float_or_none(text: str):
    try:
        return float(text)
    except ValueError:
        return None


_PLAIN_NUMBER = re.compile(r"[0-9]+(\.[0-9]*)?([eE][+-]?[0-9]+)?")
_PLAIN_INTEGER = re.compile(r"[0-9]+")
_SIGNED_NUMBER = re.compile(r"[+-]?[0-9]+(\.[0-9]*)?([eE][+-]?[0-9]+)?")


def expectation_for_positive_number(value: str) -> str | None:
    """Return "fuzzed" when the value is certainly rejected, "sentinel" when certainly
    accepted, None when the option parser may read it either way."""
    x = _float_or_none(value)
    if x is None or not math.isfinite(x) or x <= 0:
        return "fuzzed"
    if _PLAIN_NUMBER.fullmatch(value.strip()):
        return "sentinel"
    # e.g. non-ASCII digits, which Python reads and the option parser may not
    return None


def expectation_for_positive_integer(value: str) -> str | None:
    if _PLAIN_INTEGER.fullmatch(value.strip()):
        try:
            return "sentinel" if int(value) > 0 else "fuzzed"
        except ValueError:  # more digits than Python converts (4300): rejected
            return "fuzzed"
    x = _float_or_none(value)
    if x is None or not math.isfinite(x) or x <= 0 or x != int(x):
        return "fuzzed"
    return None


def expectation_for_vector(value: str, n: int) -> str | None:
    """The documented format: n numbers separated by commas or spaces, all finite."""
    if not any(ch.isdigit() for ch in value):
        # no digits: not n finite numbers ("nan", "inf" are rejected too)
        return "fuzzed"
    parts = [p for p in value.replace(" ", ",").split(",") if p]
    numbers = [_float_or_none(p) for p in parts]
    if any(x is None for x in numbers):
        # a part Python cannot read: rejected, but leave the parser its own reading
        return None
    if len(numbers) != n or not all(math.isfinite(x) for x in numbers):
        return "fuzzed"
    return "sentinel" if all(_SIGNED_NUMBER.fullmatch(p) for p in parts) else None


def assert_expectation(
    named: set[str], expectation: str | None, fuzzed: str, sentinel: str
):
    if expectation == "fuzzed":
        assert fuzzed in named, (named, fuzzed)
    elif expectation == "sentinel":
        assert sentinel in named, (named, sentinel)


# --------------------------------------------------------------------------------------
# gni run: every option
# --------------------------------------------------------------------------------------
RUN_BASE = {"--h": "0.1", "--steps": "10", "--out": MISSING_OUT}


def run_args(model=MODEL, **options):
    """`gni run` with the base options, `options` replacing them (None drops one); MODEL
    after `--` so that a fuzzed model name starting with '-' stays a positional
    argument."""
    opts = dict(RUN_BASE)
    opts.update(
        {
            k.replace("_", "-") if k.startswith("--") else k: v
            for k, v in options.items()
        }
    )
    args = ["run"]
    for k, v in opts.items():
        if v is None:
            continue
        for item in v if isinstance(v, list) else [v]:
            args += [k, item]
    return [*args, "--", model]


def expectation_for_step_count(base, argument: str):
    """`base`'s expectation, and a value it accepts that gnipy.simulate.resolve_steps refuses
    with the other base options (h = 0.1, or 10 steps) is "fuzzed" too: the step count is
    checked before --out (h below the normal floats, a step count beyond any run, a final time
    that is not a whole number of steps)."""
    from gnipy.simulate import resolve_steps

    def expectation(value: str) -> str | None:
        verdict = base(value)
        if verdict != "sentinel":
            return verdict
        x = int(value) if argument == "steps" else float(value)
        kwargs = {"h": 0.1, "steps": 10, "t_final": None}
        kwargs[argument] = x
        if argument == "t_final":
            kwargs["steps"] = None
        try:
            resolve_steps(**kwargs)
        except gnipy.InputError:
            return "fuzzed"
        return "sentinel"

    return expectation


NUMBER_OPTIONS = {
    "--h": (expectation_for_step_count(expectation_for_positive_number, "h"), {}),
    "--t-final": (expectation_for_step_count(expectation_for_positive_number, "t_final"), {"--steps": None}),
    "--steps": (expectation_for_step_count(expectation_for_positive_integer, "steps"), {}),
    "--save-every": (expectation_for_positive_integer, {}),
}


@pytest.mark.parametrize("option", sorted(NUMBER_OPTIONS))
@fuzz_settings(40)
@given(value=st.one_of(fuzz_text(), number_text()))
def test_run_numeric_options(option, value):
    expectation, extra = NUMBER_OPTIONS[option]
    res = invoke(*run_args(**{**extra, option: value}))
    named = assert_fails_naming(res, {option, "--out"})
    assert_expectation(named, expectation(value), option, "--out")


@fuzz_settings(40)
@given(value=st.one_of(fuzz_text(), name_text(gnipy.model_names())))
def test_run_model_argument(value):
    res = invoke(*run_args(model=value))
    named = assert_fails_naming(res, {"MODEL", "--out"})
    assert_expectation(
        named,
        "sentinel" if value in gnipy.model_names() else "fuzzed",
        "MODEL",
        "--out",
    )


@fuzz_settings(40)
@given(value=st.one_of(fuzz_text(), name_text(gnipy.method_names())))
def test_run_method_option(value):
    res = invoke(*run_args(**{"--method": value}))
    named = assert_fails_naming(res, {"--method", "--out"})
    assert_expectation(
        named,
        "sentinel" if value in gnipy.method_names() else "fuzzed",
        "--method",
        "--out",
    )


@fuzz_settings(40)
@given(values=st.lists(st.one_of(fuzz_text(), set_text()), min_size=1, max_size=3))
def test_run_set_option(values):
    res = invoke(*run_args(**{"--set": values}))
    named = assert_fails_naming(res, {"--set", "--out"})
    parts = [p.strip() for v in values for p in v.split(",") if p.strip()]
    if any("=" not in p for p in parts):  # a part that is not NAME=VALUE
        assert "--set" in named, named


@pytest.mark.parametrize(
    "option, model, n",
    [("--q0", MODEL, 4), ("--v0", MODEL, 4), ("--R0", GROUP_MODEL, 9)],
)
@fuzz_settings(40)
@given(data=st.data())
def test_run_vector_options(option, model, n, data):
    value = data.draw(st.one_of(fuzz_text(), vector_text(n)), label="value")
    res = invoke(*run_args(model=model, **{option: value}))
    named = assert_fails_naming(res, {option, "--out"})
    assert_expectation(named, expectation_for_vector(value, n), option, "--out")


@contextlib.contextmanager
def scratch_dir():
    """A fresh empty working directory (relative fuzzed paths land there); it must stay
    empty."""
    with tempfile.TemporaryDirectory() as d:
        old = os.getcwd()
        os.chdir(d)
        try:
            yield Path(d)
        finally:
            os.chdir(old)
        assert os.listdir(d) == [], os.listdir(d)


@fuzz_settings(40)
@given(value=fuzz_text())
def test_run_out_option(value):
    with scratch_dir():
        res = invoke(*run_args(**{"--out": value, "--checkpoint-every": "0"}))
    assert_fails_naming(res, {"--out", "--checkpoint-every"})


@fuzz_settings(40)
@given(value=fuzz_text())
def test_run_plot_option(value):
    with scratch_dir() as d:
        res = invoke(
            *run_args(
                **{"--out": str(d / "x.nc"), "--plot": value, "--checkpoint-every": "0"}
            )
        )
    assert_fails_naming(res, {"--plot", "--checkpoint-every"})


@fuzz_settings(40)
@given(value=fuzz_text())
def test_run_checkpoint_every_option(value):
    with scratch_dir() as d:
        res = invoke(
            *run_args(
                **{
                    "--out": str(d / "x.nc"),
                    "--checkpoint-every": value,
                    "--method": "reference",
                }
            )
        )
    # an invalid K, or a valid one that the continuous reference refuses: both about
    # this option
    assert_fails_naming(res, {"--checkpoint-every"}, required="--checkpoint-every")


@fuzz_settings(30)
@given(args=st.lists(fuzz_text(), max_size=4))
def test_run_stray_arguments(args):
    """Arbitrary extra words and options after the options (the first plain word is
    MODEL)."""
    with scratch_dir():
        res = invoke(*run_args()[:-2], *args)
    # an error names an option of `run`, a stray word ("No such option: -0") or an extra
    # argument
    assert_clean(res, computation_ok=True)


# --------------------------------------------------------------------------------------
# gni run --config: random TOML
# --------------------------------------------------------------------------------------
def _toml_string(s: str) -> str:
    """A TOML basic string (escapes as TOML has them; JSON's \\uXXXX is valid TOML)."""
    out = ['"']
    for ch in s:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _toml_string(k)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return (
            "{"
            + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items())
            + "}"
        )
    raise TypeError(type(v))


CONFIG_KEYS = [
    "model",
    "method",
    "h",
    "steps",
    "t-final",
    "t_final",
    "set",
    "x0",
    "v0",
    "R0",
    "r0",
    "save-every",
    "save_every",
    "out",
    "plot",
    "project-v0",
    "project_v0",
    "checkpoint-every",
    "resume",
    "config",
    "overwrite",
    "yes",
]

scalars = st.one_of(
    st.booleans(),
    st.integers(-(2**63), 2**63 - 1),
    st.floats(allow_subnormal=False),
    fuzz_text(),
    st.sampled_from(
        gnipy.model_names() + gnipy.method_names() + ["x.nc", "x.png", "I_rot=2", "r=1"]
    ),
)
toml_values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(
            st.one_of(
                st.sampled_from(["r", "m", "I_rot", "I_flip"]), st.text(max_size=8)
            ),
            inner,
            max_size=4,
        ),
    ),
    max_leaves=8,
)


@st.composite
def toml_documents(draw):
    """A TOML document: random keys (mostly the known ones) with random values, some as
    [tables]."""
    keys = st.one_of(st.sampled_from(CONFIG_KEYS), st.text(min_size=1, max_size=12))
    data = draw(st.dictionaries(keys, toml_values, max_size=6))
    lines, tables = [], []
    for k, v in data.items():
        if isinstance(v, dict) and draw(st.booleans()):
            tables.append((k, v))
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for k, v in tables:
        lines.append(f"[{_toml_key(k)}]")
        lines += [f"{_toml_key(kk)} = {_toml_value(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


@st.composite
def typed_documents(draw):
    """Known keys with values of (mostly) the right type: exercises the checks of the
    values."""
    finite = st.floats(-1e3, 1e3)
    params = sorted(gnipy.get_model(MODEL).params)
    kinds = {
        "model": st.one_of(st.just(MODEL), name_text(gnipy.model_names())),
        "method": name_text(gnipy.method_names()),
        "h": st.one_of(st.floats(0.001, 1.0), st.floats(), st.integers(-5, 5)),
        "steps": st.one_of(st.integers(-5, 10**6), st.floats(0, 10)),
        "t-final": st.one_of(st.floats(0.01, 10.0), st.floats()),
        "set": st.one_of(
            st.dictionaries(
                st.one_of(st.sampled_from(params), st.text(max_size=5)),
                st.one_of(finite, st.floats()),
                max_size=3,
            ),
            st.lists(set_text(), max_size=2),
        ),
        "x0": st.one_of(
            st.lists(st.one_of(finite, st.floats()), max_size=5), vector_text(4)
        ),
        "v0": st.one_of(
            st.lists(st.one_of(finite, st.floats()), max_size=5), vector_text(4)
        ),
        "save-every": st.one_of(st.integers(-2, 20), st.booleans()),
        "project-v0": st.one_of(st.booleans(), st.integers(0, 1)),
        "plot": st.sampled_from(["x.png", "x.svg", "x.unknown", "", "sub/x.png"]),
        "checkpoint-every": st.integers(-2, 20),
    }
    others = sorted(set(kinds) - {"model", "h"})
    chosen = [
        "model",
        "h",
        *draw(st.lists(st.sampled_from(others), unique=True, max_size=len(others))),
    ]
    data = {k: draw(kinds[k]) for k in chosen}
    return (
        "\n".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in data.items()) + "\n"
    )


random_config_files = st.one_of(
    toml_documents().map(lambda s: s.encode("utf-8")),
    st.text(max_size=200).map(lambda s: s.encode("utf-8")),  # mostly invalid TOML
    st.binary(max_size=200),  # possibly not UTF-8
    st.lists(
        st.sampled_from(
            [
                'model = "vertical-disk"',
                "h = 0.1",
                "steps = 10",
                "h = [0.1",
                'x0 = [1, "a"]',
                "[set]",
                "r = 2",
                "r = 'big'",
                "[model]",
                'name = "x"',
                "steps = 10.5",
                "h = nan",
                'set = ["r"]',
                "project-v0 = 1",
                'out = "a\\u0000b.nc"',
                "x0 = []",
                'v0 = "1,2"',
            ]
        ),
        max_size=8,
    ).map(lambda lines: "\n".join(lines).encode()),
)


def _run_config(content: bytes):
    with scratch_dir() as d:
        path = d / "run.toml"
        path.write_bytes(content)
        res = invoke(
            "run", "--config", path, "--out", MISSING_OUT
        )  # --out beats the file's `out`
        path.unlink()
    return assert_fails_naming(res, RUN_OPTIONS), res.output


@fuzz_settings(40)
@given(content=random_config_files)
def test_run_random_config_file(content):
    """Random TOML (unknown keys, nested tables, any types), invalid TOML, non-UTF-8
    bytes."""
    named, output = _run_config(content)
    # the sentinel --out is missing: every random file fails, naming an option, without a traceback
    assert named and "Traceback" not in output, output


@fuzz_settings(40)
@given(content=typed_documents())
def test_run_typed_config_file(content):
    """The known keys with values of mostly the right type: the values' own checks,
    which name the option (and the file)."""
    import tomllib

    named, output = _run_config(content.encode("utf-8"))
    from_file = {"MODEL" if k == "model" else f"--{k}" for k in tomllib.loads(content)}
    if (
        named & from_file
    ):  # an error about a value read from the file says where it came from
        error = next(line for line in output.splitlines() if line.startswith("Error"))
        assert "run.toml" in error, error


# --------------------------------------------------------------------------------------
# gni convergence
# --------------------------------------------------------------------------------------
# the options each fuzzed option's value can make an error name (checks that couple
# options)
CONVERGENCE_OPTIONS = {
    "--methods": {"--methods"},
    "--h-max": {"--h-max", "--h-min", "--count"},
    "--h-min": {"--h-min", "--h-max", "--count"},
    "--count": {"--count", "--h-min", "--h-max"},
    "--t-final": {"--t-final", "--h-max", "--count"},
    "--set": {"--set"},
    "--q0": {"--q0"},
    "--v0": {"--v0"},
    "--R0": {"--R0"},
    "--error": {"--error"},
}


@pytest.fixture(scope="module")
def existing_file():
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "a-file"
        path.write_text("")
        yield path


@pytest.mark.parametrize("option", sorted(CONVERGENCE_OPTIONS))
@fuzz_settings(30)
@given(value=fuzz_text())
def test_convergence_options(option, existing_file, value):
    if option == "--count":
        # left out: a huge --count makes `gni convergence` allocate np.geomspace(...,
        # count) before any check (MemoryError/ValueError tracebacks, or a minute and
        # GBs for ~1e7-1e8)
        assume(not (_PLAIN_INTEGER.fullmatch(value.strip()) and len(value.strip()) > 5))
    res = invoke("convergence", option, value, "--out", existing_file, "--", MODEL)
    named = assert_fails_naming(res, CONVERGENCE_OPTIONS[option] | {"--out"})
    if option in ("--h-max", "--h-min", "--t-final"):
        x = _float_or_none(value)
        if x is None or not math.isfinite(x) or x <= 0:
            assert option in named, named
    if option == "--error" and value not in ("auto", "state", "q", "v"):
        assert option in named, named


@fuzz_settings(30)
@given(value=fuzz_text())
def test_convergence_model_argument(existing_file, value):
    res = invoke("convergence", "--out", existing_file, "--", value)
    named = assert_fails_naming(res, {"MODEL", "--out"})
    if value not in gnipy.model_names():
        assert "MODEL" in named


@fuzz_settings(30)
@given(value=fuzz_text())
def test_convergence_out_option(value):
    with scratch_dir():  # nothing is created before the study runs
        res = invoke(
            "convergence", "--v0", OFF_CONSTRAINTS_V0, "--out", value, "--", MODEL
        )
    assert_fails_naming(res, {"--out", "--v0"})


# --------------------------------------------------------------------------------------
# gni sweep (if present): the checks the command line makes before gnipy.sweep.run_sweep
# --------------------------------------------------------------------------------------
if HAS_SWEEP:

    @pytest.mark.parametrize("option", ["--h", "--steps", "--t-final", "--set"])
    @fuzz_settings(20)
    @given(value=st.one_of(fuzz_text(), number_text()))
    def test_sweep_options_checked_by_the_command_line(option, value):
        """A value these checks accept reaches run_sweep, which the tripwire stands for
        (gnipy.sweep's own checks are left to its tests while it is being written)."""
        opts = {"--grid": "r=0.5:2:3", "--h": "0.1", "--steps": "10"}
        if option == "--t-final":
            del opts["--steps"]
        opts[option] = value
        args = [a for kv in opts.items() for a in kv]
        with scratch_dir() as d:
            res = invoke("sweep", *args, "--out", d / "s.zarr", "--", MODEL)
        if isinstance(res.exception, ReachedComputation):
            return
        named = assert_fails_naming(res, {option, "--steps"})
        if option != "--set":
            expectation = (
                expectation_for_positive_integer
                if option == "--steps"
                else expectation_for_positive_number
            )(value)
            if expectation == "fuzzed":
                assert option in named, named


# --------------------------------------------------------------------------------------
# gni demo, gni info, the listings, unknown commands
# --------------------------------------------------------------------------------------
@fuzz_settings(30)
@given(value=fuzz_text())
def test_demo_out_option(value):
    # two levels below the missing directory: "/missing/" + "" is "/missing", whose
    # parent exists
    res = invoke("demo", "--out", f"{MISSING_DIR}/sub/{value}")
    assert_fails_naming(res, {"--out"}, required="--out")


MAGIC = [
    b"",
    b"CDF\x01",
    b"CDF\x02",
    b"CDF\x05",
    b"\x89HDF\r\n\x1a\n",
    b"\x89HDF\r\n\x1a\n\x00\x00\x00\x00",
]


@fuzz_settings(40)
@given(magic=st.sampled_from(MAGIC), tail=st.binary(max_size=300))
def test_info_on_random_file_contents(magic, tail):
    """Arbitrary bytes, also behind the netCDF-3 and HDF5 signatures: a clean error
    naming the file (or a summary, for the few byte strings that are valid, e.g. an
    empty netCDF-3 file)."""
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.nc"
        path.write_bytes(magic + tail)
        res = invoke("info", path)
    named = assert_clean(res)
    if named is not None:
        assert "FILE" in named, res.output


@pytest.mark.parametrize(
    "command", ["models", "methods", "info", "verify", "demo", "reproduce", "convergence"]
)
@fuzz_settings(15)
@given(args=st.lists(fuzz_text(), min_size=1, max_size=3))
def test_stray_arguments_of_other_commands(command, existing_file, args):
    """Arbitrary words after a command (each command is given a sentinel that stops it
    early)."""
    sentinel = {
        "info": [],  # FILE is the first word: a missing or unreadable file
        "verify": [],  # PATH likewise
        "demo": ["--out", MISSING_OUT],
        "reproduce": ["--out", MISSING_OUT],
        "convergence": ["--out", str(existing_file)],
    }.get(command, [])
    with scratch_dir():
        res = invoke(command, *sentinel, *args)
    assert_clean(res, computation_ok=True)


@fuzz_settings(30)
@given(args=st.lists(fuzz_text(), min_size=1, max_size=3))
def test_unknown_commands(args):
    commands = {
        "run",
        "convergence",
        "info",
        "demo",
        "models",
        "methods",
        "reproduce",
        "sweep",
        "verify",
    }
    if args[0] in commands:
        args = ["x" + args[0], *args[1:]]
    assert_clean(invoke(*args))


# ---------------------------------------------------------------------------------------------
# Regressions: inputs the fuzzing found that used to end in a traceback
# ---------------------------------------------------------------------------------------------
def assert_one_error_naming(res, option: str) -> None:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1 and option in errors[0], res.output


def test_reproduce_out_that_is_a_file(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("x")
    assert_one_error_naming(invoke("reproduce", "--out", str(afile)), "--out")
    assert_one_error_naming(invoke("reproduce", "--out", str(afile / "sub")), "--out")


@pytest.mark.parametrize(
    "attrs",
    [{"method": "m", "h": "fast"}, {"method": "m", "steps": "1.5"}, {"save_every": "x"},
     {"invariant_drift_H": "big"}, {"max_error_q_vs_exact": "no"}],
)
def test_info_on_foreign_attributes(tmp_path, attrs):
    import xarray as xr

    ds = xr.Dataset({"t": (("time",), [0.0, 1.0])})
    ds.attrs.update(attrs)
    path = tmp_path / "foreign.nc"
    ds.to_netcdf(path)
    assert_one_error_naming(invoke("info", str(path)), "FILE")


def test_info_params_not_an_object(tmp_path):
    import xarray as xr

    path = tmp_path / "p.nc"
    xr.Dataset(attrs={"params": "[1, 2]"}).to_netcdf(path)
    res = invoke("info", str(path))
    assert res.exit_code == 0 and "Traceback" not in res.output


def test_config_out_with_nul(tmp_path):
    cfg = tmp_path / "nul.toml"
    cfg.write_text('model = "vertical-disk"\nh = 0.1\nsteps = 2\nout = "x\\u0000.nc"\n')
    assert_one_error_naming(invoke("run", "--config", str(cfg)), "--out")


@pytest.mark.parametrize(
    ("args", "option"),
    [(["--count", "1000000000000"], "--count"), (["--t-final", "1e300"], "--t-final/--h-min")],
)
def test_convergence_huge_values(tmp_path, args, option):
    base = {"--t-final": "1", "--h-max": "0.1", "--h-min": "0.01", "--count": "2"}
    for k, v in zip(args[::2], args[1::2]):
        base[k] = v
    flat = [x for kv in base.items() for x in kv]
    assert_one_error_naming(invoke("convergence", "vertical-disk", *flat, "--out", str(tmp_path / "c")), option)


# ---------------------------------------------------------------------------------------------
# gni info and gni verify: random attributes (rich markup, control characters), random paths
# ---------------------------------------------------------------------------------------------
CONTROL = "".join(map(chr, [*range(1, 0x20), 0x7F, *range(0x80, 0xA0)]))
MARKUP = ["[/bold]", "[/]", "[bold]", "[link=http://x]y[/link]", "[red]x", "\\[", "[", "]", ":warning:",
          "\x1b[31mred", "\x1b]8;;http://x\x1b\\y\x1b]8;;\x1b\\", "\x07", "\x1b[2J", "\u202eevil", "\x9b31m"]
attribute_text = st.one_of(
    st.sampled_from(MARKUP),
    st.text(alphabet=st.sampled_from(list("[]/=:\\ ab") + list(CONTROL)), max_size=20),
    st.lists(st.sampled_from(MARKUP), min_size=1, max_size=4).map("".join),
)
attribute_values = st.one_of(attribute_text, st.floats(allow_nan=True), st.integers(-(2**31), 2**31 - 1))
attribute_names = st.one_of(
    st.sampled_from(["model", "method", "h", "steps", "start", "params", "save_every", "created", "command",
                     "q0", "coordinates", "invariant_drift_H", "max_error_q_vs_exact", "title"]),
    st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,10}", fullmatch=True),
)

RAW_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")  # what may never reach the terminal raw


def assert_no_raw_control(output: str) -> None:
    m = RAW_CONTROL.search(output)
    assert m is None, (m.group(), output)


@fuzz_settings(40)
@given(attrs=st.dictionaries(attribute_names, attribute_values, max_size=6),
       with_checksum=st.booleans())
def test_info_and_verify_with_random_attributes(attrs, with_checksum):
    """Attributes holding rich markup and control characters: shown literally and escaped
    (never a MarkupError, never an escape sequence on the terminal); `gni verify` agrees with
    the checksum the file carries."""
    import numpy as np
    import xarray as xr

    from gnipy.io import write_netcdf

    ds = xr.Dataset({"energy": (("time",), np.array([1.0, 2.0]))}, coords={"time": [0.0, 1.0]})
    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "[").mkdir()  # paths holding "[/]" and "[/bold]"
        path = Path(d) / "[" / ("]x\x1b.nc" if with_checksum else "bold]plain.nc")
        if with_checksum:
            write_netcdf(ds, path, attrs=attrs)
        else:
            ds.attrs.update(attrs)
            ds.to_netcdf(path)
        info = invoke("info", path)
        verify = invoke("verify", path)
    named = assert_clean(info)
    if named is not None:
        assert "FILE" in named, info.output
    assert_no_raw_control(info.output)
    if info.exit_code == 0:
        for key, value in attrs.items():  # each string listed shown literally (markup not interpreted)
            listed = key not in gnipy.cli.info.SHOWN_ATTRS and not key.startswith(
                ("param_", "invariant_drift_", "max_error_"))
            if listed and isinstance(value, str) and value.strip() and " " not in value and len(value) < 12:
                assert gnipy.cli.output.safe(value) in info.output.replace("\n", ""), (value, info.output)
    named = assert_clean(verify)
    assert_no_raw_control(verify.output)
    if with_checksum:
        assert verify.exit_code == 0 and "ok" in verify.output, verify.output
    else:
        assert verify.exit_code == 1 and named == {"PATH"} and "gnipy_checksum" in verify.output


@fuzz_settings(40)
@given(magic=st.sampled_from(MAGIC), tail=st.binary(max_size=300))
def test_verify_on_random_file_contents(magic, tail):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "f.nc"
        path.write_bytes(magic + tail)
        res = invoke("verify", path)
    named = assert_clean(res)
    if named is not None:
        assert "PATH" in named, res.output


# ---------------------------------------------------------------------------------------------
# Path options that point at what is already there
# ---------------------------------------------------------------------------------------------
KINDS = ["missing", "file", "link-to-file", "dangling-link", "fifo", "directory", "link-to-directory"]


def make_kind(path: Path, kind: str, target_dir: Path) -> None:
    """Put a `kind` at `path` (targets of links live in `target_dir`)."""
    if kind == "file":
        path.write_bytes(b"precious")
    elif kind == "link-to-file":
        (target_dir / f"{path.name}.target").write_bytes(b"precious")
        path.symlink_to(target_dir / f"{path.name}.target")
    elif kind == "dangling-link":
        path.symlink_to(target_dir / f"{path.name}.nowhere")
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    elif kind == "link-to-directory":
        (target_dir / f"{path.name}.dir").mkdir()
        path.symlink_to(target_dir / f"{path.name}.dir")


def snapshot(directory: Path) -> dict:
    """What is in `directory` (recursively): each entry's kind and a regular file's bytes."""
    out = {}
    for p in sorted(directory.rglob("*")):
        rel = str(p.relative_to(directory))
        if p.is_symlink():
            out[rel] = ("link", os.readlink(p))
        elif p.is_fifo():
            out[rel] = ("fifo",)
        elif p.is_dir():
            out[rel] = ("dir",)
        else:
            out[rel] = ("file", p.read_bytes())
    return out


@fuzz_settings(60)
@given(out_kind=st.sampled_from(KINDS), plot_kind=st.sampled_from(KINDS + ["none"]), overwrite=st.booleans())
def test_run_out_and_plot_at_existing_paths(out_kind, plot_kind, overwrite):
    """`gni run --out P [--plot Q] [--overwrite]` with links, FIFOs, directories and files at P, Q:
    a link, FIFO or directory is refused always, a file without --overwrite; the refusal names
    the option, and nothing there changes. (Sentinel: --checkpoint-every 0.)"""
    with tempfile.TemporaryDirectory() as d, tempfile.TemporaryDirectory() as targets:
        d, targets = Path(d), Path(targets)
        out, plot = d / "out.nc", d / "plot.png"
        make_kind(out, out_kind, targets)
        args = ["--out", out]
        if plot_kind != "none":
            make_kind(plot, plot_kind, targets)
            args += ["--plot", plot]
        before = snapshot(d), snapshot(targets)
        res = invoke(*run_args(**{"--out": None, "--checkpoint-every": "0"})[:-2], *args,
                     *(["--overwrite"] if overwrite else []), "--", MODEL)
        assert (snapshot(d), snapshot(targets)) == before

    def refused(kind):
        return kind not in ("missing", "none", "file") or (kind == "file" and not overwrite)

    named = assert_fails_naming(res, {"--out", "--plot", "--checkpoint-every"})
    expected = "--out" if refused(out_kind) else "--plot" if refused(plot_kind) else "--checkpoint-every"
    assert expected in named, (expected, res.output)


WRITERS = {
    # command: (args before the path, option, args after, sentinel options, what a directory there is)
    "demo": (["demo", "--out"], "--out", [], "file"),
    "convergence": (["convergence", "--v0", OFF_CONSTRAINTS_V0, "--out"], "--out", ["--", MODEL], "directory"),
    "reproduce": (["reproduce", "--quick", "--out"], "--out", [], "directory"),
}


@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("command", sorted(WRITERS))
def test_other_writers_at_existing_paths(command, kind, overwrite, tmp_path):
    """demo --out FILE, convergence --out DIR, reproduce --out DIR pointed at each kind of thing,
    with and without --overwrite: one clean line or (for a path they may use) the tripwire; what
    is there is unchanged."""
    before_args, option, after, what = WRITERS[command]
    targets = tmp_path / "targets"
    targets.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    path = work / ("x.nc" if what == "file" else "x")
    make_kind(path, kind, targets)
    before = snapshot(tmp_path)
    res = invoke(*before_args, path, *(["--overwrite"] if overwrite else []), *after)
    assert snapshot(tmp_path) == before
    usable = {"file": kind == "missing" or (kind == "file" and overwrite),
              "directory": kind in ("missing", "directory", "link-to-directory")}[what]
    if isinstance(res.exception, ReachedComputation):
        assert usable and command != "convergence", (command, kind)  # (convergence has its --v0 sentinel)
        return
    named = assert_fails_naming(res, {option, "--v0"})
    assert ("--v0" in named) == (usable and command == "convergence"), res.output


@pytest.mark.parametrize("kind", ["file", "link-to-file", "dangling-link", "fifo", "directory"])
@pytest.mark.parametrize("command", ["convergence", "reproduce"])
def test_output_directories_holding_files_of_their_names(command, kind, tmp_path):
    """In a directory gnipy did not create, a file of an output's name needs --overwrite; a link,
    FIFO or directory there is refused even with it, and nothing is changed."""
    targets = tmp_path / "targets"
    targets.mkdir()
    folder = tmp_path / "folder"
    folder.mkdir()
    make_kind(folder / ("convergence.png" if command == "convergence" else "report.html"), kind, targets)
    before = snapshot(tmp_path)
    for overwrite in (False, True):
        flag = ["--overwrite"] if overwrite else []
        if command == "convergence":
            res = invoke("convergence", "--v0", OFF_CONSTRAINTS_V0, "--out", folder, *flag, "--", MODEL)
        else:
            res = invoke("reproduce", "--quick", "--out", folder, *flag)
        assert snapshot(tmp_path) == before
        if kind == "file" and overwrite:  # allowed: the run starts (stopped by --v0, or the tripwire)
            if command == "reproduce":
                assert isinstance(res.exception, ReachedComputation), res.output
            else:
                assert_fails_naming(res, {"--v0"}, required="--v0")
            continue
        assert_fails_naming(res, {"--out"}, required="--out")


@pytest.mark.parametrize("kind", KINDS + ["parts"])
def test_verify_and_info_at_each_kind_of_path(kind, tmp_path):
    targets = tmp_path / "targets"
    targets.mkdir()
    path = tmp_path / "x.nc"
    if kind == "parts":
        (tmp_path / "x.nc.parts").mkdir()
        (tmp_path / "x.nc.parts" / "spec.json").write_text("{}")
    else:
        make_kind(path, kind, targets)
    before = snapshot(tmp_path)
    for command, option in (("verify", "PATH"), ("info", "FILE")):
        res = invoke(command, path)
        assert snapshot(tmp_path) == before
        assert_fails_naming(res, {option}, required=option)  # none of these is a result file
        if command == "verify":
            assert res.exit_code == (1 if kind == "parts" else 2), res.output
