"""The `gni` command line: run a model with any method and write netCDF; convergence studies;
summaries of result files; the demo; listings.

    gni run MODEL --method METHOD --h H (--steps N | --t-final T) [--set NAME=VALUE ...]
            [--x0 a,b,...] [--v0 a,b,...] [--R0 r11,...,r33] [--project-v0] [--save-every K]
            [--plot FILE.png] [--config RUN.toml] --out FILE.nc
    gni convergence MODEL --methods M1,M2 --h-max A --h-min B --count N [--t-final T]
            [--set NAME=VALUE ...] [--x0 ...] [--v0 ...] [--R0 ...] [--error state|q|v] --out DIR
    gni info FILE.nc
    gni verify PATH
    gni demo [--out FILE.nc]
    gni models
    gni methods

Bad input gives a one-line message naming the option and exit code 2; a solver failure or a file
that cannot be written gives exit code 1. Neither prints a Python traceback.

**Files** (:mod:`gnipy.files`). An existing output file is replaced only with `--overwrite`; a
symbolic link, a directory, a FIFO or a device is never written to. Every file is written
atomically (a temporary file beside it, renamed when complete): a full disk or an interrupt leaves
an existing file as it was and no temporary behind. An output directory that gnipy creates
(`gni convergence --out DIR`, `gni reproduce --out DIR`) gets the marker `.gnipy-owned`; in such a
directory gnipy replaces its own files on a rerun, in any other directory only with `--overwrite`.
`--overwrite` and `--yes` are command-line options only: a configuration file cannot grant them.

**Terminal output.** Text from files and from the command line (paths, attributes, names) is
printed literally (no rich markup), with control characters shown as escapes (`\\x1b`).
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import time
from pathlib import Path
from typing import Any

import typer

from gnipy.files import format_bytes

__all__ = ["app", "main"]

EXIT_USAGE = 2
EXIT_FAILURE = 1

app = typer.Typer(
    name="gni",
    help="Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

# Prefixes of gnipy's error messages (`name: ...`) and the CLI option each one is about.
_OPTION_OF = {
    "h": "--h",
    "steps": "--steps",
    "t_final": "--t-final",
    "steps/t_final": "--steps/--t-final",
    "save_every": "--save-every",
    "q0": "--x0",
    "v0": "--v0",
    "q0/v0": "--x0/--v0",
    "R0": "--R0",
    "t0": "--t0",
    "--set/params": "--set",
    "model": "MODEL",
    "method": "--method",
    "lagrangian": "--set/--x0",
    "constraints": "--set/--x0",
    "affine": "--set/--x0",
    "chunk_steps": "--checkpoint-every",
    "chunk_steps/--checkpoint-every": "--checkpoint-every",
}


class _UsageError(Exception):
    """Bad command-line input: `option` is named in the message."""

    def __init__(self, option: str, message: str):
        super().__init__(f"{option}: {message}")
        self.option = option


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("gnipy")
    except Exception:  # not installed as a distribution: ask the package
        from . import __version__

        return __version__


def _version_callback(value: bool):
    if value:
        typer.echo(f"gni (gnipy) {_version()}")
        raise typer.Exit()


class _WriteFailure(Exception):
    """A file could not be written after the run (the message names the option and the path)."""


# control characters (C0, DEL, C1), lone surrogates (undecodable bytes of a path), and the
# invisible characters that reorder or break lines on a terminal
_UNSAFE = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028\u2029\u202a-\u202e\u2066-\u2069\ud800-\udfff]")
_NAMED_ESCAPES = {"\n": "\\n", "\t": "\\t", "\r": "\\r"}


def _escape_char(m) -> str:
    ch = m.group()
    if ch in _NAMED_ESCAPES:
        return _NAMED_ESCAPES[ch]
    o = ord(ch)
    return f"\\x{o:02x}" if o < 0x100 else f"\\u{o:04x}"


def _safe(text) -> str:
    """`text` for a terminal: control characters as visible escapes (`\\x1b`, `\\n`, `\\x07`, ...).
    Print the result without markup (rich `Text`, or `markup=False`)."""
    return _UNSAFE.sub(_escape_char, str(text))


def _table(title=None, **kwargs):
    """A rich `Table` whose title, headers and text cells are shown literally (:func:`_cell`)."""
    from rich.table import Table

    class SafeTable(Table):
        def add_row(self, *cells, **kw):
            return super().add_row(*(_cell(c) if isinstance(c, str) else c for c in cells), **kw)

        def add_column(self, header="", *args, **kw):
            return super().add_column(_cell(header) if isinstance(header, str) else header, *args, **kw)

    return SafeTable(title=None if title is None else _cell(title), **kwargs)


def _cell(text):
    """A table cell that shows `text` literally (no rich markup, control characters escaped)."""
    from rich.text import Text

    return Text(_safe(text))


def _fail(message: str, code: int) -> None:
    """Print a one-line error on stderr and exit with `code` (no traceback). Runs of whitespace
    become one space; other control characters are shown as escapes."""
    typer.echo("Error: " + _safe(" ".join(str(message).split())), err=True)
    raise typer.Exit(code)


def _rename(message: str) -> str:
    """Rewrite the `name:` prefix of a gnipy error message to the CLI option it is about."""
    head, sep, rest = str(message).partition(":")
    if sep and head.strip() in _OPTION_OF:
        rest = rest.replace("project_v0=True", "--project-v0")
        return f"{_OPTION_OF[head.strip()]}:{rest}"
    return str(message)


def _console(stderr: bool = False):
    """A rich console that interprets no markup or emoji codes in what it prints (text from files
    and from the command line is shown as it is; pass it through :func:`_safe`)."""
    from rich.console import Console

    return Console(highlight=False, soft_wrap=True, stderr=stderr, markup=False, emoji=False)


def _progress(*columns):
    """A rich progress display on stderr that disappears when done (and shows nothing at all when
    stderr is not a terminal, e.g. in scripts and tests)."""
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    cols = columns or (SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn())
    console = Console(stderr=True)
    return Progress(*cols, console=console, transient=True, disable=not console.is_terminal)


class _busy:
    """`with _busy("what"):` a spinner with elapsed time while a long call runs."""

    def __init__(self, text: str):
        self.text = text

    def __enter__(self):
        self.progress = _progress()
        self.progress.__enter__()
        self.progress.add_task(self.text, total=None)
        return self.progress

    def __exit__(self, *exc):
        return self.progress.__exit__(*exc)


# --------------------------------------------------------------------------------------------
# Parsing helpers
# --------------------------------------------------------------------------------------------
def _parse_vector(option: str, text: str | None, n: int, names) -> tuple[float, ...] | None:
    if text is None:
        return None
    parts = [s for s in text.replace(" ", ",").split(",") if s != ""]
    try:
        values = tuple(float(s) for s in parts)
    except ValueError:
        raise _UsageError(option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {text!r}") from None
    if len(values) != n:
        raise _UsageError(
            option, f"expected {n} comma-separated numbers ({', '.join(names)}), got {len(values)} in {text!r}"
        )
    if not all(math.isfinite(x) for x in values):
        raise _UsageError(option, f"contains NaN or infinite values: {text!r}")
    return values


def _parse_set(items: list[str] | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items or []:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            name, eq, value = part.partition("=")
            name, value = name.strip(), value.strip()
            if not eq or not name or not value:
                raise _UsageError("--set", f"expected NAME=VALUE, got {part!r}")
            try:
                x = float(value)
            except ValueError:
                raise _UsageError("--set", f"parameter {name!r} must be a number, got {value!r}") from None
            if not math.isfinite(x):
                raise _UsageError("--set", f"parameter {name!r} must be finite, got {value!r}")
            out[name] = x
    return out


def _check_positive(option: str, value, kind: str = "number"):
    if value is None:
        return
    if isinstance(value, float) and not math.isfinite(value):
        raise _UsageError(option, f"must be a positive finite {kind}, got {value!r}")
    if value <= 0:
        raise _UsageError(option, f"must be a positive {kind}, got {value!r}")


def _relabel(option: str, message) -> str:
    """An error message of gnipy.files / gnipy.io as one about the CLI `option`: its own argument
    prefix (`path:`, `out:`, ...) replaced by the option, `overwrite=True` written as the flag."""
    text = str(message).replace("overwrite=True (--overwrite)", "--overwrite").replace("overwrite=True", "--overwrite")
    head, sep, rest = text.partition(": ")
    if sep and head in ("path", "out", "plot", option):
        text = rest
    elif sep and re.fullmatch(r"--[\w-]+(/--[\w-]+)*", head):  # already about an option (e.g. --resume)
        return text
    return f"{option}: {text}"


def _check_output(path: Path, option: str = "--out", overwrite: bool = False) -> Path:
    """`path` may be written as a regular file (:func:`gnipy.files.check_destination`): its directory
    exists and is writable, and nothing is there, or a regular file and `overwrite`; a symbolic
    link, directory, FIFO or device never. Else `_UsageError` naming `option` and the path."""
    from gnipy.files import OutputError, check_destination

    try:
        return check_destination(path, overwrite=overwrite, argument=option)
    except OutputError as e:
        raise _UsageError(option, _relabel(option, e).partition(": ")[2]) from None
    except RuntimeError as e:  # Path.expanduser: "~user" of no such user
        raise _UsageError(option, f"cannot use {str(path)!r}: {e}") from None


def _check_plot(path: Path, overwrite: bool = False) -> None:
    """`--plot`: a writable path whose suffix is an image format matplotlib writes."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in formats:
        raise _UsageError(
            "--plot", f"cannot tell the image format of {str(path)!r}: use one of the suffixes "
            + ", ".join(f".{k}" for k in sorted(formats))
        )
    _check_output(path, "--plot", overwrite)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.abspath(a) == os.path.abspath(b) or (a.exists() and b.exists() and os.path.samefile(a, b))
    except (OSError, ValueError):
        return False


def _check_output_dir(path: Path, names=(), overwrite: bool = False) -> bool:
    """`--out DIR` (`gni convergence`): an existing directory, or one that can be created, in which
    the files `names` may be written. Returns whether gnipy may replace existing files of those names:
    in a directory gnipy created (it holds the marker :data:`gnipy.files.MARKER`), or with
    `--overwrite`; a symbolic link, directory or special file at one of the names is always refused."""
    import stat

    from gnipy.files import MARKER, OutputError, check_destination, is_owned_dir

    text = str(path)
    if "\x00" in text:
        raise _UsageError("--out", f"{text!r}: a path cannot contain a NUL character")
    try:
        st = os.stat(path)  # a link to a directory is that directory (not one gnipy owns)
    except FileNotFoundError:
        st = None
    except OSError as e:
        raise _UsageError("--out", f"cannot use {text!r}: {e.strerror or e}") from None
    if st is None:
        if os.path.islink(path):
            raise _UsageError("--out", f"{text!r} is a dangling symbolic link")
        parent = path.parent if str(path.parent) else Path(".")
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise _UsageError("--out", f"cannot create directory {text!r}: {str(parent)!r} is not a directory")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise _UsageError("--out", f"cannot create directory {text!r}: {str(parent)!r} is not writable")
        return True
    if not stat.S_ISDIR(st.st_mode):
        raise _UsageError("--out", f"{text!r} exists and is not a directory")
    if not os.access(path, os.W_OK | os.X_OK):
        raise _UsageError("--out", f"directory {text!r} is not writable")
    replace = overwrite or is_owned_dir(path)
    taken = []
    for name in names:
        try:
            check_destination(path / name, overwrite=True, argument="--out")
        except OutputError as e:  # a link, directory or special file: never
            raise _UsageError("--out", _relabel("--out", e).partition(": ")[2]) from None
        if (path / name).exists():
            taken.append(name)
    if taken and not replace:
        raise _UsageError(
            "--out", f"{text!r} is a directory gnipy did not create (no {MARKER} marker) and already holds "
            f"{', '.join(taken)}; pass --overwrite to replace them, or choose another directory"
        )
    return replace


def _create_output_dir(path: Path, purpose: str) -> bool:
    """Create the directory `path` (and missing parents) with gnipy's marker, unless it exists;
    returns whether it was created here."""
    from gnipy.files import make_owned_dir

    if os.path.isdir(path):
        return False
    parent = path.parent if str(path.parent) else Path(".")
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _WriteFailure(f"--out: cannot create {parent}: {e.strerror or e}") from None
    make_owned_dir(path, purpose)
    return True


@contextlib.contextmanager
def _writing(option: str, path):
    """Turn a failure to write `path` (an `OSError`, the netCDF library's `HDF error`) into a
    one-line error about `option` (exit code 1); other errors pass."""
    from gnipy.files import as_output_error

    try:
        yield
    except (OSError, RuntimeError) as e:
        err = as_output_error(e, path)
        if err is None:
            raise
        raise _WriteFailure(_relabel(option, err)) from None


# --------------------------------------------------------------------------------------------
# Configuration files (gni run --config RUN.toml)
# --------------------------------------------------------------------------------------------
# key (dashes read as underscores) -> (the CLI option it stands for, what it must hold)
_CONFIG_KEYS: dict[str, tuple[str, str]] = {
    "model": ("MODEL", "string"),
    "method": ("--method", "string"),
    "h": ("--h", "number"),
    "steps": ("--steps", "integer"),
    "t_final": ("--t-final", "number"),
    "set": ("--set", "set"),
    "x0": ("--x0", "vector"),
    "v0": ("--v0", "vector"),
    "R0": ("--R0", "vector"),
    "save_every": ("--save-every", "integer"),
    "out": ("--out", "path"),
    "plot": ("--plot", "path"),
    "project_v0": ("--project-v0", "boolean"),
    "checkpoint_every": ("--checkpoint-every", "integer"),
}

_KIND_TEXT = {
    "string": "a string",
    "number": "a number",
    "integer": "an integer",
    "set": "a table NAME = VALUE, or a list of \"NAME=VALUE\" strings",
    "vector": "a list of numbers, or a string \"a,b,...\"",
    "path": "a string (a path, relative to the config file)",
    "boolean": "true or false",
}


#: A parameter name (what a key of the table form `set = { NAME = VALUE }` must be).
_PARAM_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _config_value(where: str, key: str, kind: str, value, base: Path):
    """Check one config value's type and turn it into what the CLI option would hold."""

    def bad():
        return _UsageError("--config", f"{where}: key {key!r} must be {_KIND_TEXT[kind]}, got {value!r}")

    if kind == "string":
        if not isinstance(value, str):
            raise bad()
        return value
    if kind == "number":
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise bad()
        return float(value)
    if kind == "integer":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad()
        return int(value)
    if kind == "boolean":
        if not isinstance(value, bool):
            raise bad()
        return value
    if kind == "path":
        if not isinstance(value, str) or not value:
            raise bad()
        try:
            path = Path(value).expanduser()
        except RuntimeError as e:  # "~user" of no such user
            raise _UsageError("--config", f"{where}: key {key!r}: cannot use {value!r}: {e}") from None
        return path if path.is_absolute() else base / path
    if kind == "vector":
        if isinstance(value, str):
            return value
        if isinstance(value, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
            return ",".join(repr(float(x)) for x in value)
        raise bad()
    if kind == "set":
        if isinstance(value, str):
            return [value]
        if isinstance(value, list) and all(isinstance(x, str) for x in value):
            return list(value)
        if isinstance(value, dict):
            items = []
            for name, x in value.items():
                if not _PARAM_NAME.fullmatch(name):  # e.g. { "m=2,g" = 1 } must not set m and g
                    raise _UsageError(
                        "--config", f"{where}: key {key!r}: {name!r} is not a parameter name (in the table form "
                        "each key is one name, e.g. set = { m = 2 }; or write set = [\"m=2\", ...])"
                    )
                if isinstance(x, bool) or not isinstance(x, (int, float)):
                    raise _UsageError("--config", f"{where}: key 'set.{name}' must be a number, got {x!r}")
                items.append(f"{name}={float(x)!r}")
            return items
        raise bad()
    raise AssertionError(kind)  # pragma: no cover


def _load_config(path: Path) -> dict[str, Any]:
    """Read a run configuration (TOML): `{key: value}` with keys normalized (dashes → underscores)
    and values in the form the CLI options take; raises `_UsageError` naming the file and key."""
    import tomllib

    where = str(path)
    if not path.exists():
        raise _UsageError("--config", f"cannot read {where!r}: no such file")
    if not path.is_file():
        raise _UsageError("--config", f"cannot read {where!r}: not a file")
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise _UsageError("--config", f"{where}: not valid TOML: {e}") from None
    except UnicodeDecodeError:
        raise _UsageError("--config", f"{where}: not valid TOML: the file is not UTF-8 text") from None
    except OSError as e:
        raise _UsageError("--config", f"cannot read {where!r}: {e.strerror or e}") from None
    base = path.resolve().parent
    out: dict[str, Any] = {}
    for raw_key, value in data.items():
        key = raw_key.replace("-", "_")
        if key == "r0":
            key = "R0"
        if key not in _CONFIG_KEYS:
            known = ", ".join(k.replace("_", "-") for k in _CONFIG_KEYS)
            raise _UsageError("--config", f"{where}: unknown key {raw_key!r} (known: {known})")
        if key in out:
            raise _UsageError("--config", f"{where}: key {raw_key!r} given twice (with dashes and underscores)")
        out[key] = _config_value(where, raw_key, _CONFIG_KEYS[key][1], value, base)
    return out


# --------------------------------------------------------------------------------------------
# Running and reporting
# --------------------------------------------------------------------------------------------
def _invariant_drifts(spec, params, q, v, R=None) -> dict[str, float]:
    import inspect

    import numpy as np

    out = {}
    # host arrays: iterating a device array costs a dispatch per row
    q, v = np.asarray(q), np.asarray(v)
    R = None if R is None else np.asarray(R)
    for name, f in spec.invariants.items():
        # on R^n × G an invariant may also take the orientation: f(params, q, v, R)
        with_R = R is not None and len(inspect.signature(f).parameters) >= 4
        args = zip(q, v, R) if with_R else zip(q, v)
        vals = np.array([float(f(params, *a)) for a in args])
        out[name] = float(np.max(np.abs(vals - vals[0])))
    return out


def _exact_errors(spec, params, sol, q0, v0):
    """`(q_exact, v_exact, max|q − q_exact|, max|v − v_exact|)` or None."""
    import numpy as np

    if spec.exact is None:
        return None
    t = np.asarray(sol.t) - float(sol.t[0])
    result = spec.exact(params, q0, v0, t)
    if result is None:  # no closed form for these parameters (e.g. rolling-ball, unequal moments)
        return None
    qe, ve = result
    q, v = np.asarray(sol.q), np.asarray(sol.v)
    # initial=0: on R^0 × G there are no coordinates q
    return qe, ve, float(np.max(np.abs(q - qe), initial=0.0)), float(np.max(np.abs(v - ve), initial=0.0))


def _prepare_model(model: str, set_items, x0_text, v0_text):
    """The model, its parameters and the initial condition (`--set`, `--x0`, `--v0` or the
    model's defaults), raising `_UsageError` naming the option; returns `(spec, params, q0, v0)`."""
    import gnipy

    try:
        spec = gnipy.get_model(model)
    except gnipy.InputError as e:
        raise _UsageError("MODEL", str(e).partition(":")[2].strip()) from None
    try:
        params = spec.resolve_params(_parse_set(set_items))
    except gnipy.InputError as e:
        raise _UsageError("--set", str(e).partition(":")[2].strip()) from None
    names = spec.coordinates
    x0 = _parse_vector("--x0", x0_text, len(names), names)
    vnames = spec.build(params).velocities  # (ẋ, ξ) on R^n × G: longer than x
    v0 = _parse_vector("--v0", v0_text, len(vnames), vnames)
    dq, dv = spec.initial_condition(params)
    return spec, params, tuple(dq if x0 is None else x0), tuple(dv if v0 is None else v0)


def _prepare(model: str, method: str, h, steps, t_final, set_items, x0_text, v0_text, save_every):
    """Validate the input (raising `_UsageError` naming the option); returns `(spec, params, q0, v0)`."""
    import gnipy

    try:
        gnipy.get_model(model)
    except gnipy.InputError as e:
        raise _UsageError("MODEL", str(e).partition(":")[2].strip()) from None
    if method not in gnipy.method_names():
        raise _UsageError("--method", f"unknown method {method!r} (known: {', '.join(gnipy.method_names())})")
    _check_positive("--h", h)
    if (steps is None) == (t_final is None):
        raise _UsageError("--steps/--t-final", "give exactly one of --steps and --t-final")
    _check_positive("--steps", steps, "integer")
    _check_positive("--t-final", t_final)
    _check_positive("--save-every", save_every, "integer")
    # the step count now, not at the run: h below the normal range, t_final / h that overflows or is
    # more steps than any run can take, t_final not a whole number of steps (messages name the option)
    from gnipy.simulate import resolve_steps

    resolve_steps(h, steps, t_final)
    return _prepare_model(model, set_items, x0_text, v0_text)


def _parse_R0(spec, params, text: str | None):
    """The initial orientation (flattened row-major) for a model on R^n × G: `--R0`, else the
    model's documented one (None: the identity); None for models without a group part."""
    group = spec.build(params).group
    if group is None:
        if text is not None:
            raise _UsageError("--R0", f"model {spec.name!r} has no orientation (no group part)")
        return None
    k = group.matrix_size
    if text is None:
        return tuple(spec.R0) if spec.R0 is not None else tuple(float(x) for x in group.identity().reshape(-1))
    return _parse_vector("--R0", text, k * k, [f"r{i + 1}{j + 1}" for i in range(k) for j in range(k)])


def _simulate(spec, params, method, q0, v0, h, steps, t_final, project_v0, save_every, R0=None):
    """Run; returns `(sol, v0_used, seconds)` (v0_used is the projected v0 with --project-v0)."""
    import gnipy

    system = spec.build(params)
    # the initial velocity actually used: G-orthogonally projected onto the constraints if asked
    _, v0_used = system.check(q0, v0, R0=R0, project_v0=project_v0)
    v0_used = tuple(float(x) for x in v0_used)
    t0 = time.perf_counter()
    with _busy(f"{spec.name}: compiling and integrating with {method}"):
        sol = gnipy.simulate(
            system, method, q0, v0_used, R0=R0, h=h, steps=steps, t_final=t_final, save_every=save_every
        )
        sol.q.block_until_ready()
    seconds = time.perf_counter() - t0
    return sol, v0_used, seconds


def _report(
    title: str, spec, params, sol, exact, drifts, seconds: float, out: Path | str | None, note: str | None = None
) -> None:
    import numpy as np

    e = np.asarray(sol.energy)
    r = np.asarray(sol.constraint_residual)
    table = _table(title=title, show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    table.add_row("model", f"{spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())})")
    span = f"t = {float(sol.t[0]):g} .. {float(sol.t[-1]):g}"
    table.add_row("method", f"{sol.method}, h = {sol.h:g}, {sol.steps} steps, {span}")
    table.add_row("final q", ", ".join(f"{c} = {x:.10g}" for c, x in zip(spec.coordinates, np.asarray(sol.q[-1]))))
    vnames = sol.velocities or tuple(f"d{c}" for c in spec.coordinates)
    table.add_row("final v", ", ".join(f"{c} = {x:.10g}" for c, x in zip(vnames, np.asarray(sol.v[-1]))))
    table.add_row("energy", f"initial {e[0]:.12g}, max |E - E0| = {np.max(np.abs(e - e[0])):.3e}")
    table.add_row("constraint residual", f"max |mu(q)(v - Y)| = {np.max(np.abs(r)) if r.size else 0.0:.3e}")
    for name, d in drifts.items():
        table.add_row(f"invariant {name}", f"max drift {d:.3e}")
    if exact is not None:
        table.add_row("error vs exact", f"max |q - q_exact| = {exact[2]:.3e}, max |v - v_exact| = {exact[3]:.3e}")
    if sol.energy_plus is not None:
        ep = np.asarray(sol.energy_plus)
        table.add_row("energy of p+", f"initial {ep[0]:.12g}, max |E+ - E+0| = {np.max(np.abs(ep - ep[0])):.3e}")
    verdict = sol.hidden_verdict
    if verdict is not None and verdict.in_band:
        table.add_row("hidden momentum", f"max |p+ - p̄|/|p̄| = {verdict.max_ratio:.3e}, in its O(h) band")
    if sol.conserved:
        table.add_row("conserved", sol.conserved)
    table.add_row("time", f"{seconds:.2f} s (including compilation)")
    if note:
        table.add_row("note", note)
    con = _console()
    con.print(table)
    for warning in sol.warnings():  # the run-time diagnostics (gnipy.diagnostics): never silent
        _console(stderr=True).print(_safe(warning), style="bold yellow", markup=False)
    if out is not None:
        con.print(f"written: {_safe(out)}", markup=False)


def _attrs_for(spec, params, sol, q0, v0, exact, drifts, extra: dict[str, Any]) -> dict[str, Any]:
    attrs: dict[str, Any] = {
        "q0": list(q0),
        "v0": list(v0),
        "coordinates": ",".join(spec.coordinates),
        "t_final": float(sol.t[-1]),
        **extra,
    }
    for name, d in drifts.items():
        attrs[f"invariant_drift_{name}"] = d
    if exact is not None:
        attrs["max_error_q_vs_exact"] = exact[2]
        attrs["max_error_v_vs_exact"] = exact[3]
    return attrs


def _guarded(fn, origins: dict[str, str] | None = None, method_option: str = "--method"):
    """Run `fn()` turning gnipy's errors into one-line messages and exit codes.

    `origins` maps an option to where its value came from (e.g. `"--h"` → `"key 'h' in run.toml"`):
    a message about that option says so."""
    import gnipy
    from gnipy.io import OutputError

    def usage(message: str):
        head, sep, rest = message.partition(":")
        if sep and origins:
            for option in head.split("/"):
                if option in origins:
                    message = f"{head} (from {origins[option]}):{rest}"
                    break
        _fail(message, EXIT_USAGE)

    try:
        return fn()
    except _UsageError as e:
        usage(str(e))
    except gnipy.MethodError as e:  # before InputError, of which it is a subclass
        msg = _rename(str(e))
        usage(msg if msg.startswith(method_option) else f"{method_option}: {msg}")
    except gnipy.InputError as e:
        usage(_rename(str(e)))
    except gnipy.SolverFailure as e:
        _fail(f"solver failure: {e}", EXIT_FAILURE)
    except _WriteFailure as e:
        _fail(str(e), EXIT_FAILURE)
    except OutputError as e:
        _fail(_relabel("--out", e), EXIT_FAILURE)
    except OSError as e:
        where = f": {e.filename}" if getattr(e, "filename", None) else ""
        _fail(f"--out: {e.strerror or e}{where}", EXIT_FAILURE)
    except RuntimeError as e:  # the netCDF library's failed write ("NetCDF: HDF error"), else a bug
        from gnipy.files import as_output_error

        err = as_output_error(e, "the output")
        if err is None:
            raise
        _fail(_relabel("--out", err), EXIT_FAILURE)
    except MemoryError:
        _fail("out of memory: save fewer nodes (--save-every) or stream the run (--checkpoint-every K)",
              EXIT_FAILURE)


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------
@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the gnipy version and exit."
    ),
):
    """Simulate nonholonomic mechanical systems with the Geometric Nonholonomic Integrator (GNI).

    With GNIPY_COMPILATION_CACHE=1 in the environment, compiled programs are kept in
    ~/.cache/gnipy/jax between runs ($GNIPY_CACHE_DIR to move it).
    """
    from gnipy.compilation import cache_requested, enable_compilation_cache

    if cache_requested():
        enable_compilation_cache()


@app.command()
def run(
    model: str | None = typer.Argument(
        None, help="Model name (see `gni models`); or `model` in --config.", show_default=False, metavar="MODEL"
    ),
    method: str | None = typer.Option(
        None, "--method", "-m", help="Method name (see `gni methods`). [default: the model's, see `gni models`]", show_default=False
    ),
    h: float | None = typer.Option(None, "--h", help="Step size (> 0).", show_default=False),
    steps: int | None = typer.Option(
        None, "--steps", help="Number of steps (give this or --t-final).", show_default=False
    ),
    t_final: float | None = typer.Option(
        None, "--t-final", help="Final time, a whole number of steps (give this or --steps).", show_default=False
    ),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Parameter override NAME=VALUE (repeatable, or comma-separated).", show_default=False
    ),
    x0: str | None = typer.Option(
        None, "--x0", help="Initial configuration a,b,... (default: the model's).", show_default=False
    ),
    v0: str | None = typer.Option(
        None, "--v0", help="Initial velocity a,b,... (default: the model's).", show_default=False
    ),
    R0: str | None = typer.Option(
        None, "--R0", help="Initial orientation on R^n x G, row-major r11,...,r33 (default: the model's, or identity).",
        show_default=False,
    ),
    project_v0: bool | None = typer.Option(
        None, "--project-v0/--no-project-v0",
        help="Project v0 onto the constraints instead of rejecting it. [default: no]", show_default=False,
    ),
    save_every: int | None = typer.Option(
        None, "--save-every", help="Save every K-th node (and always the last). [default: 1]", show_default=False
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Output netCDF file.", show_default=False),
    plot: Path | None = typer.Option(
        None, "--plot", help="Also write a figure (configuration path, energy error, constraint residual), "
        "e.g. run.png.", show_default=False,
    ),
    config: Path | None = typer.Option(
        None, "--config", "-c", help="A TOML file with any of these options (keys as the option names, "
        "dashes or underscores); options given on the command line override it.", show_default=False,
    ),
    checkpoint_every: int | None = typer.Option(
        None, "--checkpoint-every", help="Stream the run in chunks of K steps (a multiple of --save-every), "
        "each committed to OUT.parts/ with the integrator state, so that an interrupted run can be resumed "
        "(--resume). Runs saving more than 10^6 nodes are streamed in any case.", show_default=False,
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue an interrupted streamed run of the same options from its last "
        "checkpoint (the result equals an uninterrupted run exactly).",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace existing --out and --plot files (without it they are refused; a "
        "symbolic link, directory or special file is refused always). Not read from --config.",
    ),
    yes: bool = typer.Option(
        False, "--yes", help="Run even when the memory or the file the run needs is estimated beyond gnipy's "
        "bounds (memory: the smaller of 8 GiB and half the RAM; file: 64 GiB, and the free disk space), which "
        "are otherwise refused before anything is compiled. Not read from --config.",
    ),
):
    """Integrate MODEL with METHOD and write the trajectory to a netCDF file.

    The file holds t(time), q(time, coordinate), v(time, velocity), p(time, velocity),
    energy(time) and constraint_residual(time, constraint), and R(time, i, j) on R^n x G, with
    provenance attributes. With --plot, also a figure of the run.

    A config file holds the same options, e.g.

    \b
        model = "vertical-disk"
        method = "gni-midpoint"
        h = 0.05
        t-final = 10
        x0 = [0, 0, 0, 0]
        set = { I_rot = 2 }
        out = "disk.nc"

    (`set` may also be a list of "NAME=VALUE" strings, `x0`/`v0`/`R0` strings "a,b,...").
    Relative paths in the file are relative to the file's directory.

    Long runs are streamed: with --checkpoint-every K (or when more than 10^6 nodes are saved)
    the nodes go to the file in chunks, memory holds one chunk, and the file appears (atomically)
    when the run is complete; --resume continues an interrupted run.
    """
    origins: dict[str, str] = {}

    def go():
        from gnipy.io import write_netcdf

        cfg: dict[str, Any] = {}
        if config is not None:
            cfg = _load_config(config)
            for key in cfg:
                origins[_CONFIG_KEYS[key][0]] = f"key {key.replace('_', '-')!r} in {str(config)}"

        def pick(key: str, given, default=None):
            if given is not None:
                origins.pop(_CONFIG_KEYS[key][0], None)
                return given
            return cfg.get(key, default)

        model_ = pick("model", model)
        if model_ is None:
            raise _UsageError("MODEL", "missing: give MODEL (or `model` in --config)")
        method_ = pick("method", method)
        if method_ is None:  # the model's measured default (gni models shows it and why)
            from .models.registry import default_method_for

            method_ = default_method_for(str(model_))
        h_ = pick("h", h)
        if h_ is None:
            raise _UsageError("--h", "missing: give --h (or `h` in --config)")
        if steps is not None or t_final is not None:  # the command line decides the length
            steps_, t_final_ = steps, t_final
            origins.pop("--steps", None)
            origins.pop("--t-final", None)
        else:
            steps_, t_final_ = cfg.get("steps"), cfg.get("t_final")
        set_items = list(cfg.get("set", [])) + list(set_ or [])  # the command line wins per name
        if set_:
            origins.pop("--set", None)
        x0_, v0_text, R0_text = pick("x0", x0), pick("v0", v0), pick("R0", R0)
        project = bool(pick("project_v0", project_v0, False))
        save_every_ = pick("save_every", save_every, 1)
        out_ = pick("out", out)
        plot_ = pick("plot", plot)
        if out_ is None:
            raise _UsageError("--out", "missing: give --out FILE.nc (or `out` in --config)")

        spec, params, q0, v0_ = _prepare(model_, method_, h_, steps_, t_final_, set_items, x0_, v0_text, save_every_)
        R0_ = _parse_R0(spec, params, R0_text)
        # --resume may find the run finished: its file is then read back, not replaced
        _check_output(out_, "--out", overwrite or resume)
        if plot_ is not None:
            _check_plot(plot_, overwrite)
            if _same_file(out_, plot_):
                raise _UsageError("--plot", f"{str(plot_)!r} is also --out: choose another path for the figure")
        chunk = pick("checkpoint_every", checkpoint_every)
        if chunk is not None and (isinstance(chunk, bool) or chunk < 1):
            raise _UsageError("--checkpoint-every", f"must be a positive integer, got {chunk!r}")
        if resume and chunk is None:
            raise _UsageError("--resume", "only streamed runs resume: give --checkpoint-every K as in the interrupted run")
        from gnipy.simulate import MAX_STEPS, resolve_steps

        n_steps = resolve_steps(h_, steps_, t_final_)[1]
        stride = min(int(save_every_), n_steps)  # the stride the run has (the last node is always saved)
        streamed = chunk is not None or n_steps // stride > STREAM_NODES or n_steps > MAX_STEPS
        if streamed:
            if method_ == "reference":
                raise _UsageError("--checkpoint-every", "the continuous reference is not streamed")
            if plot_ is not None:
                raise _UsageError("--plot", "not available for streamed runs: plot from the file (gnipy.plots)")
            if stride > MAX_STEPS:
                raise _UsageError("--save-every", f"at most {MAX_STEPS} steps between saved nodes in a streamed run "
                                  f"(a chunk holds at most {MAX_STEPS} steps), got {stride}")
            if chunk is None:  # chunks of the default number of nodes, within the steps one chunk may hold
                from gnipy.streaming import DEFAULT_CHUNK_NODES

                chunk = stride * max(1, min(DEFAULT_CHUNK_NODES, MAX_STEPS // stride))
        length = "--steps" if steps_ is not None else "--t-final"
        if not yes:  # estimated before anything is compiled or allocated
            _check_resources(spec.build(params), n_steps, stride, streamed, chunk, out_, length,
                             chunk_given=pick("checkpoint_every", checkpoint_every) is not None)
        if streamed:
            extra = {"save_every": stride, "project_v0": int(project), "command": "gni run",
                     "q0": list(q0), "coordinates": ",".join(spec.coordinates)}
            if config is not None:
                extra["config_file"] = str(config)
            if R0_ is not None:
                extra["R0"] = list(R0_)
            _run_streamed(spec, params, method_, q0, v0_, R0_, h_, steps_, t_final_, project, stride, chunk,
                          resume, out_, extra, overwrite=overwrite, yes=yes)
            return
        sol, v0_used, seconds = _simulate(
            spec, params, method_, q0, v0_, h_, steps_, t_final_, project, stride, R0=R0_
        )
        exact = _exact_errors(spec, params, sol, q0, v0_used)
        drifts = _invariant_drifts(spec, params, sol.q, sol.v, sol.R)
        extra = {"save_every": stride, "project_v0": int(project), "command": "gni run"}
        if config is not None:
            extra["config_file"] = str(config)
        if R0_ is not None:
            extra["R0"] = list(R0_)
        attrs = _attrs_for(spec, params, sol, q0, v0_used, exact, drifts, extra)
        with _writing("--out", out_):
            write_netcdf(sol, out_, attrs=attrs, overwrite=overwrite)
        written = str(out_)
        if plot_ is not None:
            _write_plot(sol, plot_, overwrite)
            written += f", {plot_}"
        _report("gni run", spec, params, sol, exact, drifts, seconds, written)

    _guarded(go, origins)


#: `gni run` streams runs that save more nodes than this (memory stays bounded by one chunk).
STREAM_NODES = 1_000_000

#: `gni run` refuses (before compiling anything, unless --yes) a run whose saved nodes would need
#: more memory than the smaller of this and half the machine's RAM (:func:`_memory_bound`) ...
MAX_MEMORY_BYTES = 8 * 2**30
#: ... or a result file larger than this, or than the free space of its file system.
MAX_OUTPUT_BYTES = 64 * 2**30
#: The memory of an in-memory run, as a multiple of its saved nodes' bytes (the device arrays,
#: their host copies, the dataset written).
MEMORY_COPIES = 3


def _memory_bound() -> int:
    """The memory bound of `gni run`: min(:data:`MAX_MEMORY_BYTES`, half the physical memory)."""
    bound = MAX_MEMORY_BYTES
    try:
        phys = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        if phys > 0:
            bound = min(bound, phys // 2)
    except (ValueError, OSError, AttributeError):  # not available on this system
        pass
    return bound


def _node_bytes(system) -> int:
    """Bytes of one saved node of a result (a generous estimate): t, q, v, p, the hidden momentum,
    energy, energy of p+, the constraint residual (at most one entry per velocity), R, the node and
    step indices."""
    k = system.group.matrix_size if system.group is not None else 0
    values = 1 + system.n + 4 * len(system.velocities) + k * k + 4
    return 8 * values + 16





def _check_resources(system, n_steps: int, stride: int, streamed: bool, chunk, out: Path, length: str,
                     chunk_given: bool = True) -> None:
    """Refuse (`_UsageError`) a run whose memory or file is estimated beyond the bounds
    (:data:`MAX_MEMORY_BYTES`, :data:`MAX_OUTPUT_BYTES`, the free disk space); `--yes` skips this."""
    import shutil

    per_node = _node_bytes(system)
    nodes = 1 + -(-n_steps // stride)  # the initial node, every stride-th, and the last
    file_bytes = nodes * per_node
    if streamed:
        from gnipy.streaming import DEFAULT_CHUNK_NODES

        chunk_nodes = (chunk // stride if chunk is not None else DEFAULT_CHUNK_NODES) + 1
        memory = min(chunk_nodes, nodes) * per_node * MEMORY_COPIES
        disk = 2 * file_bytes  # the checkpoint parts and the file they are joined into, at the end
        where = "in one chunk"
        option = "--checkpoint-every" if chunk_given else f"{length}/--save-every"
    else:
        memory = nodes * per_node * MEMORY_COPIES
        disk = file_bytes
        where = "in memory"
        option = f"{length}/--save-every"
    bound = _memory_bound()
    if memory > bound:
        raise _UsageError(
            option, f"the run would hold {min(nodes, chunk_nodes) if streamed else nodes:,} saved nodes {where}, "
            f"about {format_bytes(memory)}: more than gnipy's bound of {format_bytes(bound)} (the smaller of "
            f"{format_bytes(MAX_MEMORY_BYTES)} and half the RAM); "
            + ("choose a smaller --checkpoint-every" if streamed else
               "stream the run with --checkpoint-every K (memory then holds one chunk) or save fewer nodes "
               "(--save-every K)") + ", or pass --yes to run anyway"
        )
    parts = " (twice that on disk while the run goes on: the checkpoint parts and the file)" if streamed else ""
    what = f"the file would hold {nodes:,} saved nodes, about {format_bytes(file_bytes)}{parts}"
    if file_bytes > MAX_OUTPUT_BYTES:
        raise _UsageError(
            f"{length}/--save-every", f"{what}: more than gnipy's bound of {format_bytes(MAX_OUTPUT_BYTES)}; save fewer "
            "nodes (--save-every K), or pass --yes to run anyway"
        )
    directory = out.parent if str(out.parent) else Path(".")
    try:
        free = shutil.disk_usage(directory).free
    except OSError:
        return
    if disk > free:
        raise _UsageError(
            f"{length}/--save-every", f"{what}, but {str(directory)!r} has {format_bytes(free)} free; save fewer nodes "
            "(--save-every K) or free some space, or pass --yes to run anyway"
        )


def _run_streamed(spec, params, method, q0, v0, R0, h, steps, t_final, project, save_every, chunk, resume, out,
                  extra, *, overwrite: bool = False, yes: bool = False) -> None:
    """`gni run` in chunks through :func:`gnipy.streaming.simulate_to_file`, with a progress bar."""
    import numpy as np
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from gnipy.streaming import simulate_to_file

    system = spec.build(params)
    _, v0_used = system.check(q0, v0, R0=R0, project_v0=project)
    extra = dict(extra, v0=[float(x) for x in v0_used])
    t0 = time.perf_counter()
    columns = (TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"),
               TimeElapsedColumn(), TimeRemainingColumn())
    console = _console()
    with Progress(*columns, console=console, transient=True, disable=not console.is_terminal) as bar:
        total = steps if steps is not None else round(float(t_final) / float(h))
        task = bar.add_task(f"{spec.name} with {method}", total=total)

        def progress(done, total):
            bar.update(task, completed=done, total=total)

        # replacing an existing file: only with --overwrite (checked above, and again by the writer);
        # --yes lifts the writer's own bound on the size of the run (max_bytes=None)
        more = {"max_bytes": None} if yes else {}
        with _writing("--out", out):
            result = simulate_to_file(
                system, method, q0, v0_used, R0=R0, path=out, h=h, steps=steps, t_final=t_final,
                save_every=save_every, chunk_steps=chunk, resume=resume, overwrite=overwrite, attrs=extra,
                progress=progress, **more,
            )
    seconds = time.perf_counter() - t0
    table = _table(title="gni run (streamed)", show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    table.add_row("model", f"{spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())})")
    table.add_row("method", f"{method}, h = {float(h):g}, {result.steps} steps, {result.nodes} saved nodes, "
                  f"{result.chunks} chunks ({result.chunks_resumed} from an earlier run)")
    table.add_row("final q", ", ".join(f"{c} = {x:.10g}" for c, x in zip(spec.coordinates, np.asarray(result.final_q))))
    table.add_row("energy", f"max |E - E0| = {result.energy_error:.3e}")
    table.add_row("constraint residual", f"max |mu(q)(v - Y)| = {result.constraint_residual:.3e}")
    table.add_row("time", f"{seconds:.2f} s (including compilation)")
    con = _console()
    con.print(table)
    for warning in result.warnings:  # the run-time diagnostics, as for in-memory runs
        _console(stderr=True).print(_safe(warning), style="bold yellow", markup=False)
    con.print(f"written: {_safe(out)}", markup=False)


def _write_plot(sol, path: Path, overwrite: bool = False) -> None:
    """The three-panel figure of a run (configuration path, energy error, constraint residual),
    written atomically."""
    from gnipy.plots import plot_solution

    try:
        with _writing("--plot", path):
            plot_solution(sol, path, overwrite=overwrite)
    except _WriteFailure as e:
        raise _WriteFailure(f"{e} (the result file was written; the figure was not)") from None


# --------------------------------------------------------------------------------------------
# gni convergence
# --------------------------------------------------------------------------------------------
def _parse_methods(text: str) -> list[str]:
    import gnipy

    names = []
    for part in text.split(","):
        name = part.strip()
        if not name:
            continue
        if name not in gnipy.method_names():
            raise _UsageError("--methods", f"unknown method {name!r} (known: {', '.join(gnipy.method_names())})")
        if name == "reference":
            raise _UsageError("--methods", "'reference' is the yardstick of the study, not a method to study")
        if name not in names:
            names.append(name)
    if not names:
        raise _UsageError("--methods", f"give at least one method name, got {text!r}")
    return names


#: Bounds of `gni convergence`: step sizes per study, and steps per run (int32 step counters).
MAX_CONVERGENCE_COUNT = 1000
MAX_STEPS = 2**31 - 1


def _step_counts(h_max: float, h_min: float, count: int, t_final: float) -> list[int]:
    """Whole numbers of steps for `count` log-spaced h from h_max down to h_min (distinct)."""
    import numpy as np

    for option, value in (("--h-max", h_max), ("--h-min", h_min), ("--t-final", t_final)):
        _check_positive(option, value)
    if isinstance(count, bool) or count < 2:
        raise _UsageError("--count", f"need at least 2 step sizes to fit an order, got {count!r}")
    if count > MAX_CONVERGENCE_COUNT:
        raise _UsageError("--count", f"at most {MAX_CONVERGENCE_COUNT} step sizes, got {count!r}")
    if t_final / h_min > MAX_STEPS:
        raise _UsageError(
            "--t-final/--h-min", f"{t_final!r} / {h_min!r} is more than {MAX_STEPS:.0e} steps per run"
        )
    if h_min >= h_max:
        raise _UsageError("--h-min/--h-max", f"need h-min < h-max, got {h_min!r} and {h_max!r}")
    if h_max > t_final:
        raise _UsageError("--h-max", f"larger than the final time {t_final!r}")
    counts = sorted({max(1, round(t_final / h)) for h in np.geomspace(h_max, h_min, count)})
    if len(counts) < 2:
        raise _UsageError(
            "--count", f"the step sizes give only {len(counts)} distinct step count(s) on [0, {t_final:g}]; "
            "widen --h-max/--h-min"
        )
    return counts


def _expected_order(method) -> int | None:
    order = getattr(method, "expected_order", None)
    if order is None:
        order = getattr(method, "order", None)
    return order if isinstance(order, int) else None


@app.command()
def convergence(
    model: str = typer.Argument(..., help="Model name (see `gni models`).", show_default=False, metavar="MODEL"),
    methods_: str = typer.Option(
        "gni-trapezoid", "--methods", "-m", help="Comma-separated method names (see `gni methods`)."
    ),
    h_max: float = typer.Option(0.1, "--h-max", help="Largest step size."),
    h_min: float = typer.Option(0.01, "--h-min", help="Smallest step size."),
    count: int = typer.Option(5, "--count", help="Number of step sizes (log-spaced, at least 2)."),
    t_final: float = typer.Option(1.0, "--t-final", help="Final time: each h is adjusted to T / round(T / h)."),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Parameter override NAME=VALUE (repeatable, or comma-separated).", show_default=False
    ),
    x0: str | None = typer.Option(None, "--x0", help="Initial configuration (default: the model's).", show_default=False),
    v0: str | None = typer.Option(None, "--v0", help="Initial velocity (default: the model's).", show_default=False),
    R0: str | None = typer.Option(
        None, "--R0", help="Initial orientation on R^n x G, row-major (default: the model's).", show_default=False
    ),
    project_v0: bool = typer.Option(False, "--project-v0", help="Project v0 onto the constraints."),
    error: str = typer.Option(
        "auto", "--error", help="What to measure at the final time: q (the configuration), v (the reported "
        "velocity), state (the larger of the two), or auto (q; v on models without coordinates q)."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output directory (created if missing).", show_default=False),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace convergence.csv and convergence.png in a directory gnipy did not "
        "create (in one it created, marked by its .gnipy-owned file, they are replaced on a rerun).",
    ),
):
    """Measure the order of convergence of methods on MODEL.

    For each method and each of COUNT log-spaced step sizes from H-MAX to H-MIN (each adjusted so
    that T is a whole number of steps), the error at the final time T (max-norm; of the
    configuration q by default, see --error) is measured against the model's exact solution when
    it has one, else against the continuous reference (Dopri8 at tolerance 1e-12). The order is
    the least-squares slope of log(error) against log(h) over the points above round-off
    (2·√N·ε against an exact solution, N the largest step count: the steps' round-off grows like a
    random walk, gnipy.spaces; 1e-10 against the reference; times max(1, |state|)). Writes
    OUT/convergence.csv and OUT/convergence.png and prints the table and the fitted orders.
    """

    def go():
        import csv
        import io

        import numpy as np

        import gnipy
        from gnipy.files import atomic_write_text, remove_owned_dir
        from gnipy.plots import fitted_order, plot_convergence

        if error not in ("auto", "state", "q", "v"):
            raise _UsageError("--error", f"expected auto, state, q or v, got {error!r}")
        spec, params, q0, v0_ = _prepare_model(model, set_, x0, v0)
        measure = ("q" if spec.coordinates else "v") if error == "auto" else error
        names = _parse_methods(methods_)
        counts = _step_counts(h_max, h_min, count, t_final)
        R0_ = _parse_R0(spec, params, R0)
        if measure == "q" and not spec.coordinates:
            raise _UsageError("--error", f"model {spec.name!r} has no coordinates q (it lives on a group): use v or state")
        replace = _check_output_dir(out, ("convergence.csv", "convergence.png"), overwrite)

        system = spec.build(params)
        b0, v0_used = system.check(q0, v0_, R0=R0_, project_v0=project_v0)
        v0_used = tuple(float(x) for x in v0_used)
        T = float(t_final)

        # the yardstick at the final time
        truth = spec.exact(params, q0, v0_used, np.array([0.0, T])) if spec.exact is not None else None
        if truth is not None:
            q_true, v_true = np.asarray(truth[0])[-1], np.asarray(truth[1])[-1]
            # round-off of N steps: a random walk of roundings (gnipy.spaces), at most √N·ε·scale (tested)
            yardstick = f"exact solution of {spec.name}"
            floor_rel = 2.0 * math.sqrt(max(counts)) * float(np.finfo(np.float64).eps)
        else:
            with _busy(f"{spec.name}: continuous reference (Dopri8, tolerance 1e-12)"):
                ref = gnipy.simulate(system, "reference", q0, v0_used, R0=R0_, h=T, steps=1)
            q_true, v_true = np.asarray(ref.q)[-1], np.asarray(ref.v)[-1]
            yardstick, floor_rel = "continuous reference (Dopri8, tolerance 1e-12)", 1e-10
        scale = max(1.0, float(np.max(np.abs(np.concatenate([q_true, v_true])), initial=0.0)))
        floor = floor_rel * scale

        # check every method before running any of them
        methods: dict[str, Any] = {}
        for name in names:
            m = gnipy.get_method(name)
            m.check(system, b0)
            methods[name] = m.prepare(system, b0)

        rows, errors, hs, failures = [], {}, {}, []
        t_start = time.perf_counter()
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            SpinnerColumn,
            TextColumn,
            TimeElapsedColumn,
        )

        with _progress(
            SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()
        ) as progress:
            task = progress.add_task("convergence", total=len(names) * len(counts))
            for name, m in methods.items():
                errs = []
                for i, n in enumerate(counts):
                    h = T / n
                    note = " (compiling)" if i == 0 else ""
                    progress.update(task, description=f"{name}, h = {h:.4g}{note}")
                    # only the first and last nodes are saved, and the step count and h are traced:
                    # one compilation per method serves every step size of the study
                    sol = gnipy.simulate(system, m, q0, v0_used, R0=R0_, h=h, steps=n, save_every=n, throw=False)
                    ok = sol.result == 0
                    q, v = np.asarray(sol.q)[-1], np.asarray(sol.v)[-1]
                    e_q = float(np.max(np.abs(q - q_true), initial=0.0))
                    e_v = float(np.max(np.abs(v - v_true), initial=0.0))
                    if not ok or not (np.isfinite(e_q) and np.isfinite(e_v)):
                        failures.append(f"{name} at h = {h:.6g}")
                        e_q = e_v = float("nan")
                    e = {"state": max(e_q, e_v), "q": e_q, "v": e_v}[measure]
                    errs.append(e)
                    rows.append({"method": name, "steps": n, "h": h, "t_final": T, "error": e, "error_q": e_q,
                                 "error_v": e_v, "used_in_fit": int(bool(np.isfinite(e) and e > floor))})
                    progress.advance(task)
                errors[name] = np.array(errs)
                hs[name] = T / np.array(counts, dtype=float)
        seconds = time.perf_counter() - t_start

        orders = {name: fitted_order(hs[name], errors[name], floor) for name in names}
        expected = {name: _expected_order(m) for name, m in methods.items()}
        for row in rows:
            row["fitted_order"] = orders[row["method"]]
            row["expected_order"] = "" if expected[row["method"]] is None else expected[row["method"]]
            row["yardstick"] = "exact" if truth is not None else "reference"
            row["measure"] = measure

        csv_path, png_path = out / "convergence.csv", out / "convergence.png"
        fields = ["method", "steps", "h", "t_final", "error", "error_q", "error_v", "used_in_fit",
                  "fitted_order", "expected_order", "yardstick", "measure"]
        table = io.StringIO(newline="")
        writer = csv.DictWriter(table, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in row.items()})
        guides = sorted({p for p in expected.values() if p is not None}) or [1, 2]
        what = {"state": "max(|q − q*|, |v − v*|)", "q": "|q − q*|", "v": "|v − v*|"}[measure]
        with _writing("--out", out):
            created = _create_output_dir(out, "gni convergence: convergence.csv, convergence.png")
        try:
            # each file whole or not at all (a full disk leaves an earlier file as it was)
            with _writing("--out", csv_path):
                atomic_write_text(csv_path, table.getvalue(), overwrite=replace, argument="--out")
            with _writing("--out", png_path):
                plot_convergence(
                    hs, errors, png_path, guides=guides, floor=floor,
                    title=f"{spec.name}: error at t = {T:g} against the {yardstick.split(' (')[0]}",
                    ylabel=f"{what} at t = {T:g}", overwrite=replace,
                )
        except BaseException:
            if created:  # nothing of this study is left behind (the csv, if written, goes too)
                remove_owned_dir(out, ("convergence.csv", "convergence.png"))
            raise
        _convergence_report(spec, params, names, counts, T, errors, orders, expected, yardstick, measure, floor,
                            failures, seconds, csv_path, png_path)

    _guarded(go, method_option="--methods")


def _convergence_report(spec, params, names, counts, T, errors, orders, expected, yardstick, error, floor,
                        failures, seconds, csv_path, png_path) -> None:
    import math


    con = _console()
    con.print(f"gni convergence: {spec.name} ({', '.join(f'{k}={v:g}' for k, v in params.items())}), "
              f"t = 0 .. {T:g}", markup=False)
    con.print(f"errors at t = {T:g} ({error}, max-norm) against the {yardstick}", markup=False)
    table = _table(title_justify="left")
    for head in ("method", "steps", "h", f"error ({error})"):
        table.add_column(head, justify="left" if head == "method" else "right", no_wrap=True)
    for name in names:
        for i, n in enumerate(counts):
            e = errors[name][i]
            cell = "failed" if not math.isfinite(e) else f"{e:.3e}" + ("" if e > floor else " *")
            table.add_row(name if i == 0 else "", str(n), f"{T / n:.4g}", cell, end_section=i == len(counts) - 1)
    con.print(table)
    if any(not (e > floor) for name in names for e in errors[name] if math.isfinite(e)):
        con.print(f"* at or below round-off ({floor:.1e}): not used in the fit", markup=False)
    orders_table = _table(title="fitted orders (least squares, log error against log h)", title_justify="left")
    orders_table.add_column("method")
    orders_table.add_column("fitted order", justify="right")
    orders_table.add_column("expected", justify="right")
    for name in names:
        o = orders[name]
        orders_table.add_row(name, f"{o:.2f}" if math.isfinite(o) else "n/a (fewer than 2 points above round-off)",
                             "?" if expected[name] is None else str(expected[name]))
    con.print(orders_table)
    for name in names:  # one plain line per method, easy to grep
        o = orders[name]
        con.print(f"order {name}: {o:.3f}" if math.isfinite(o) else f"order {name}: n/a", markup=False)
    for f in failures:
        con.print(f"warning: solver failure for {f} (left out)", markup=False)
    con.print(f"time: {seconds:.2f} s (including compilation)", markup=False)
    con.print(f"written: {_safe(csv_path)}, {_safe(png_path)}", markup=False)


# --------------------------------------------------------------------------------------------
# gni sweep
# --------------------------------------------------------------------------------------------
# argument names in gnipy.sweep's error messages (`grid: ...`) and the CLI option each is about
_SWEEP_OPTION_OF = {
    "grid": "--grid",
    "out": "--out",
    "chunk_size": "--chunk-size",
    "workers": "--workers",
    "scheduler": "--scheduler",
    "set_params": "--set",
    "save_every": "--save-every",
    "method": "--method",
    "max_chunks": "--max-chunks",
}


def _sweep_message(message: str) -> str:
    """A gnipy.sweep error message with its argument names written as the CLI options."""
    head, sep, rest = str(message).partition(":")
    extra = {"connect_timeout": "--connect-timeout", "max_bytes": "--yes"}
    if sep and head.strip() in _SWEEP_OPTION_OF:
        message = f"{_SWEEP_OPTION_OF[head.strip()]}:{rest}"
    elif sep and head.strip() in extra:
        message = f"{extra[head.strip()]}:{rest}"
    else:
        message = _rename(message)
    for name, option in (("overwrite=True", "--overwrite"), ("project_v0=True", "--project-v0"),
                         ("set_params", "--set"), ("pass max_bytes=None", "pass --yes"),
                         ("the bound max_bytes = ", "the bound of "), ("a smaller chunk_size", "a smaller --chunk-size"),
                         ("a larger save_every", "a larger --save-every"),
                         ("raise connect_timeout", "raise --connect-timeout"),
                         ("write the store elsewhere", "choose another --out")):
        message = message.replace(name, option)
    return message


def _sweep_report(report, spec: dict[str, Any]) -> None:
    from gnipy.sweep import GridAxis

    con = _console()
    axes = [GridAxis(**g) for g in spec["grid"]]
    fixed = ", ".join(f"{k}={v:g}" for k, v in spec["params"].items())
    con.print(f"gni sweep: {spec['model']}" + (f" ({fixed})" if fixed else "") + f" with {spec['method']}, "
              f"h = {spec['h']:g}, {spec['steps']} steps, saved every {spec['save_every']}", markup=False)
    grid = " x ".join(f"{a.name} = {a.start:g} .. {a.stop:g} ({a.count})" for a in axes)
    con.print(f"  grid: {grid}: {report.members} members in {report.chunks} chunk(s) of {report.chunk_size}",
              markup=False)
    con.print(f"  chunks: {report.chunks_computed} computed, {report.chunks_skipped} skipped (done before), "
              f"{report.chunks_remaining} remaining", markup=False)
    repaired = getattr(report, "chunks_repaired", 0)
    if repaired:
        con.print(f"  damaged chunks found and computed again: {repaired}", markup=False)
    con.print(f"  failed members: {report.failed_members}", markup=False)
    rate = ""
    if report.members_computed:
        rate = (f"; {report.members_computed / report.wall_time:.3g} members/s, "
                f"{report.member_steps_per_second:.3g} member-steps/s")
    con.print(f"  time: {report.wall_time:.2f} s (including cluster start and compilation){rate}", markup=False)
    if report.complete:
        con.print(f"written: {_safe(report.path)}", markup=False)
    else:
        con.print(f"written (incomplete, run the same command again to resume): {_safe(report.path)}", markup=False)


@app.command()
def sweep(
    model: str = typer.Argument(..., help="Model name (see `gni models`).", show_default=False, metavar="MODEL"),
    grid: list[str] | None = typer.Option(
        None, "--grid", "-g", help="A grid axis NAME=START:STOP:COUNT, values numpy.linspace(START, STOP, COUNT); "
        "NAME is a parameter, q0.<coordinate> or v0.<velocity> (e.g. m=0.5:2:10, q0.x=-1:1:5, v0.omega3=0:1:3). "
        "Repeatable: the sweep is the Cartesian product.", show_default=False,
    ),
    method: str | None = typer.Option(
        None, "--method", "-m", help="Method name (see `gni methods`). [default: the model's, see `gni models`]",
        show_default=False,
    ),
    h: float | None = typer.Option(None, "--h", help="Step size (> 0).", show_default=False),
    steps: int | None = typer.Option(
        None, "--steps", help="Number of steps (give this or --t-final).", show_default=False
    ),
    t_final: float | None = typer.Option(
        None, "--t-final", help="Final time, a whole number of steps (give this or --steps).", show_default=False
    ),
    save_every: int | None = typer.Option(
        None, "--save-every", help="Save every K-th node (and always the last). [default: the number of steps: "
        "only the initial and the last node]", show_default=False,
    ),
    set_: list[str] | None = typer.Option(
        None, "--set", help="Fix a parameter that is not swept, NAME=VALUE (repeatable, or comma-separated).",
        show_default=False,
    ),
    project_v0: bool = typer.Option(
        True, "--project-v0/--no-project-v0", help="Project each member's initial velocity onto its constraints "
        "(on by default for sweeps: a v0 grid, or parameters that change the constraints, move v0 off them).",
    ),
    chunk_size: int = typer.Option(
        1000, "--chunk-size", help="Members per task (one vmapped batch) and per zarr chunk along `member`."
    ),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="An existing dask scheduler: its address, e.g. tcp://host:8786, or a scheduler "
        "file (JSON); its workers need gnipy. [default: start a local cluster]", show_default=False,
    ),
    connect_timeout: float = typer.Option(
        10.0, "--connect-timeout", help="Seconds to wait for the connection to --scheduler.",
    ),
    workers: int | None = typer.Option(
        None, "--workers", help="Number of worker processes of the local cluster. [default: the number of cores]",
        show_default=False,
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace an existing sweep store at --out (only one gnipy created) and start "
        "afresh (without it, the same sweep is resumed).",
    ),
    max_chunks: int | None = typer.Option(
        None, "--max-chunks", help="Compute at most this many chunks, then stop (run again to go on), e.g. under "
        "a batch-job time limit.", show_default=False,
    ),
    yes: bool = typer.Option(
        False, "--yes", help="Create a store larger than 100 GiB (estimated, uncompressed): lift the size bound. "
        "(The free disk space is checked anyway.)",
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output zarr store, a directory (e.g. sweep.zarr); its parent must exist.",
        show_default=False,
    ),
):
    """Run MODEL over a grid of parameters and initial conditions on a dask cluster; write zarr.

    The members (the grid's Cartesian product) run in chunks of --chunk-size, each one vmapped
    batch, on a local dask.distributed cluster (or an existing one: --scheduler), and each chunk
    is written to the zarr store OUT as it completes, with a progress display on a terminal.
    Running the same command again resumes an interrupted sweep: the chunks already written are
    read back and checked, and skipped (a damaged one is computed again). Read the result with
    gnipy.sweep.open_sweep(OUT), which gives the grid axes as dimensions.

    Exit codes: 0 when every member ran; 1 when members failed (the store is written, and the
    first failed members are listed), a chunk failed on the cluster or the store cannot be
    written; 2 for bad input (also a store that holds another sweep or is damaged, a sweep over
    the size bound, or a scheduler that cannot be reached).
    """

    def go():
        import warnings

        import gnipy.sweep as sweep_module
        from gnipy.sweep import SweepError, SweepFailure, SweepWarning, run_sweep

        if not grid:
            raise _UsageError("--grid", "missing: give at least one --grid NAME=START:STOP:COUNT")
        _check_positive("--h", h)
        if h is None:
            raise _UsageError("--h", "missing: give --h")
        if (steps is None) == (t_final is None):
            raise _UsageError("--steps/--t-final", "give exactly one of --steps and --t-final")
        _check_positive("--steps", steps, "integer")
        _check_positive("--t-final", t_final)
        set_params = _parse_set(set_)

        def _sweep_failures(report) -> str:
            """The error line of a sweep with failed members: how many, and the first few."""
            def one(f) -> str:
                grid = ", ".join(f"{k}={v:.6g}" for k, v in f["grid"].items())
                residual = "n/a" if math.isnan(f["residual"]) else f"{f['residual']:.3e}"
                return f"member {f['member']} ({grid}): step {f['step']}, t = {f['time']:.6g}, residual {residual}"

            listed = "; ".join(one(f) for f in report.failures)
            more = ", ..." if report.failed_members > len(report.failures) else ""
            return (f"{report.failed_members} of {report.members} members failed (a step's solve did not converge): "
                    f"{listed}{more}. Their data are NaN after their failed step (result = 1; failed_step, failed_time, "
                    "failed_residual in the store); the others are written")

        original = warnings.showwarning

        def show(message, category, *args, **kwargs):  # a damaged chunk computed again: one line
            if not issubclass(category, SweepWarning):
                return original(message, category, *args, **kwargs)
            typer.echo("warning: " + _safe(" ".join(_sweep_message(str(message)).split())), err=True)

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("always", SweepWarning)
                warnings.showwarning = show
                report = run_sweep(
                    model, list(grid), out=out, h=h, steps=steps, t_final=t_final, method=method,
                    save_every=save_every, set_params=set_params, project_v0=project_v0, chunk_size=chunk_size,
                    scheduler=scheduler, workers=workers, overwrite=overwrite, max_chunks=max_chunks, progress=True,
                    max_bytes=None if yes else sweep_module.DEFAULT_MAX_BYTES, connect_timeout=connect_timeout,
                )
        except SweepError as e:
            _fail(_sweep_message(str(e)), EXIT_USAGE)
        except SweepFailure as e:
            _fail(f"{e}; the chunks done are kept: run the same command again to resume", EXIT_FAILURE)
        except KeyboardInterrupt:
            _fail("interrupted; the chunks done are kept: run the same command again to resume", 130)
        _sweep_report(report, report.spec)
        if report.failed_members:
            _fail(_sweep_failures(report), EXIT_FAILURE)

    _guarded(go)


# --------------------------------------------------------------------------------------------
# gni info
# --------------------------------------------------------------------------------------------
_SHOWN_ATTRS = {"model", "params", "method", "h", "steps", "start", "save_every", "t_final", "gnipy_version",
                "jax_version", "created", "command", "config_file", "result", "newton_iterations_total",
                "newton_iterations_max", "units_convention", "q0", "v0", "R0", "project_v0", "coordinates",
                "gnipy_checksum"}


def _fmt_attr(v) -> str:
    import numpy as np

    if isinstance(v, np.ndarray):
        return "[" + ", ".join(f"{x:.10g}" for x in v.reshape(-1)) + "]"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.10g}"
    return str(v)


@app.command()
def info(
    file: Path = typer.Argument(..., help="A result file written by `gni run` (or gnipy.io.write_netcdf).",
                                show_default=False, metavar="FILE.nc"),
):
    """Summarize a result file: model, parameters, method, times, variables, energy drift,
    constraint residual and provenance."""

    def go():
        from gnipy.io import OutputError, read_netcdf

        _check_readable(file, "FILE")
        try:
            ds = read_netcdf(file)
        except OutputError as e:
            raise _UsageError("FILE", str(e)) from None
        except RuntimeError as e:  # the netCDF library on a damaged file ("NetCDF: HDF error")
            raise _UsageError("FILE", f"cannot read {str(file)!r}: {e}") from None
        try:
            _info_table(file, ds, _checksum_text(file))
        except (ValueError, TypeError, AttributeError, OverflowError, KeyError, IndexError) as e:
            raise _UsageError(
                "FILE", f"{str(file)!r} is not a result file gnipy can summarize ({type(e).__name__}: {e})"
            ) from None

    _guarded(go)


def _check_readable(path: Path, option: str) -> None:
    """`path` is a regular file (or a link to one) to read; else `_UsageError` (a FIFO or device
    is never opened: reading one could block)."""
    import stat

    text = str(path)
    if "\x00" in text:
        raise _UsageError(option, f"{text!r}: a path cannot contain a NUL character")
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise _UsageError(option, f"cannot read {text!r}: no such file") from None
    except OSError as e:
        raise _UsageError(option, f"cannot read {text!r}: {e.strerror or e}") from None
    if stat.S_ISDIR(st.st_mode):
        raise _UsageError(option, f"cannot read {text!r}: it is a directory")
    if not stat.S_ISREG(st.st_mode):
        raise _UsageError(option, f"cannot read {text!r}: not a regular file (a FIFO, socket or device)")


def _checksum_text(path: Path) -> str:
    """What `gni info` says of a file's checksum (:func:`gnipy.io.verify_netcdf`)."""
    from gnipy.io import OutputError, verify_netcdf

    try:
        ok, message = verify_netcdf(path)
    except OutputError as e:
        return f"cannot be verified: {e}"
    prefix = f"{Path(path)}: "
    message = message[len(prefix):] if message.startswith(prefix) else message
    return f"verified: {message}" if ok else f"NOT verified: {message}"


def _info_table(file, ds, checksum: str | None = None) -> None:
    """Print the summary table of `gni info` (raises on attributes of unexpected types)."""
    import json

    import numpy as np

    a = dict(ds.attrs)
    table = _table(title=f"gni info: {file}", show_header=False, title_justify="left", box=None)
    table.add_column(style="bold")
    table.add_column(overflow="fold")
    params = {}
    if "params" in a:
        try:
            params = json.loads(str(a["params"]))
        except ValueError:
            params = {}
        if not isinstance(params, dict):
            params = {}
    if not params:
        params = {k[len("param_"):]: a[k] for k in a if k.startswith("param_")}
    model_ = a.get("model", "(unknown)")
    ptxt = ", ".join(f"{k}={float(v):g}" if isinstance(v, (int, float, np.number)) else f"{k}={v}"
                     for k, v in params.items())
    table.add_row("model", f"{model_} ({ptxt})" if ptxt else str(model_))
    if "method" in a:
        parts = [str(a["method"])]
        if "h" in a:
            parts.append(f"h = {float(a['h']):g}")
        if "steps" in a:
            parts.append(f"{int(a['steps'])} steps")
        if "start" in a:
            parts.append(f"start: {a['start']}")
        table.add_row("method", ", ".join(parts))
    if "time" in ds.coords and ds["time"].dtype.kind == "f" and ds["time"].size:  # read_netcdf: times in `time`
        t = np.asarray(ds["time"].values, dtype=float)
        units = ds["time"].attrs.get("units", "")
        more = f", saved every {int(a['save_every'])} steps" if "save_every" in a else ""
        table.add_row("times", f"t = {t[0]:g} .. {t[-1]:g} {units}".rstrip() + f", {t.size} saved nodes{more}")
    for name, var in ds.data_vars.items():
        dims = ", ".join(f"{d}={ds.sizes[d]}" for d in var.dims)
        long = var.attrs.get("long_name", "")
        table.add_row(f"variable {name}", f"({dims}) {var.dtype}" + (f"  {long}" if long else ""))
    for dim in ("coordinate", "velocity"):
        if dim in ds.coords and ds.sizes.get(dim):
            table.add_row(f"{dim} names", ", ".join(str(x) for x in ds[dim].values))
    if "energy" in ds.variables and ds["energy"].size:
        e = np.asarray(ds["energy"].values, dtype=float)
        table.add_row("energy", f"initial {e[0]:.12g}, final {e[-1]:.12g}, max |E - E0| = "
                      f"{np.max(np.abs(e - e[0])):.3e}")
    if "constraint_residual" in ds.variables:
        r = np.asarray(ds["constraint_residual"].values, dtype=float)
        table.add_row("constraint residual", f"max |mu(q)(v - Y)| = {np.max(np.abs(r), initial=0.0):.3e}")
    for k in sorted(a):
        if k.startswith("invariant_drift_"):
            table.add_row(f"invariant {k[len('invariant_drift_'):]}", f"max drift {float(a[k]):.3e}")
    if "max_error_q_vs_exact" in a:
        table.add_row("error vs exact", f"max |q - q_exact| = {float(a['max_error_q_vs_exact']):.3e}, "
                      f"max |v - v_exact| = {float(a.get('max_error_v_vs_exact', float('nan'))):.3e}")
    for k in ("q0", "v0", "R0", "project_v0", "save_every", "result", "newton_iterations_total",
              "newton_iterations_max", "gnipy_version", "jax_version", "created", "command", "config_file",
              "units_convention"):
        if k in a:
            table.add_row(k, _fmt_attr(a[k]))
    for k in sorted(a):
        if k in _SHOWN_ATTRS or k.startswith(("param_", "invariant_drift_", "max_error_")):
            continue
        table.add_row(k, _fmt_attr(a[k]))
    if checksum is not None:
        table.add_row("checksum", checksum)
    _console().print(table)


# --------------------------------------------------------------------------------------------
# gni verify
# --------------------------------------------------------------------------------------------
def _is_parts_dir(path: Path) -> bool:
    """Whether `path` is the checkpoint directory `OUT.parts` of a streamed run."""
    return path.name.endswith(".parts") and path.is_dir() and (
        (path / "spec.json").exists() or any(path.glob("part_*.nc"))
    )


def _unfinished(parts: Path) -> None:
    result = parts.with_name(parts.name[: -len(".parts")])
    _fail(f"PATH: {parts} holds the checkpoints of an unfinished streamed run of {result} (not a result yet): "
          "run the same `gni run ... --checkpoint-every K` again with --resume, which verifies the parts and "
          "completes the file", EXIT_FAILURE)


def _verify_store(path: Path) -> None:
    """`gni verify` of a directory: a sweep store, through gnipy.sweep.verify_sweep."""
    try:
        from gnipy import sweep as sweep_module
    except ImportError as e:  # pragma: no cover - the sweep's dependencies are installed with gnipy
        raise _UsageError("PATH", f"{str(path)!r} is a directory, and sweep stores cannot be read here ({e})") from None
    verify_sweep = getattr(sweep_module, "verify_sweep", None)
    if verify_sweep is None:
        raise _UsageError("PATH", f"{str(path)!r} is a directory: this version of gnipy cannot verify sweep stores "
                          "(gnipy.sweep.verify_sweep is missing)")
    from gnipy.files import OutputError

    sweep_error = getattr(sweep_module, "SweepError", OutputError)
    try:
        ok, message, bad = verify_sweep(path)
    except sweep_error as e:  # not a sweep store, or one that cannot be read
        raise _UsageError("PATH", re.sub(r"^(--out|path|out): ", "", _sweep_message(str(e)))) from None
    except (OutputError, OSError, ValueError, KeyError, TypeError) as e:
        raise _UsageError("PATH", f"cannot verify {str(path)!r}: {e}") from None
    if ok:
        _console().print(_safe(message), markup=False)
        return
    if bad:
        shown = ", ".join(str(c) for c in list(bad)[:10]) + (", ..." if len(bad) > 10 else "")
        message = f"{message} (damaged chunks: {shown})" if shown not in str(message) else message
    _fail(f"PATH: {message}", EXIT_FAILURE)


@app.command()
def verify(
    path: Path = typer.Argument(..., help="A result file (FILE.nc), a sweep store (DIR.zarr) or the checkpoint "
                                "directory of a streamed run (FILE.nc.parts).", show_default=False, metavar="PATH"),
):
    """Check that a file gnipy wrote is whole: recompute the checksums it carries.

    A result file (`gni run`, gnipy.io.write_netcdf) carries the checksum of its data in its
    attribute gnipy_checksum; a sweep store one per chunk. Exit code 0: the data match ("ok");
    1: they do not (the file is damaged: the message says what), the file carries no checksum, or
    PATH is an unfinished streamed run (resume it with `gni run ... --resume`); 2: PATH does not
    exist or cannot be read.
    """

    def go():
        import stat

        from gnipy.io import OutputError, verify_netcdf

        text = str(path)
        if "\x00" in text:
            raise _UsageError("PATH", f"{text!r}: a path cannot contain a NUL character")
        try:
            st = os.stat(path)
        except FileNotFoundError:
            parts = path.with_name(path.name + ".parts") if path.name else None
            if parts is not None and _is_parts_dir(parts):
                _unfinished(parts)
            raise _UsageError("PATH", f"cannot read {text!r}: no such file or directory") from None
        except OSError as e:
            raise _UsageError("PATH", f"cannot read {text!r}: {e.strerror or e}") from None
        if stat.S_ISDIR(st.st_mode):
            if _is_parts_dir(path):
                _unfinished(path)
            _verify_store(path)
            return
        if not stat.S_ISREG(st.st_mode):
            raise _UsageError("PATH", f"cannot read {text!r}: not a regular file (a FIFO, socket or device)")
        try:
            ok, message = verify_netcdf(path)
        except OutputError as e:
            raise _UsageError("PATH", str(e)) from None
        if not ok:
            _fail(f"PATH: {message}", EXIT_FAILURE)
        _console().print(_safe(message), markup=False)

    _guarded(go)


DEMO_MODEL, DEMO_METHOD, DEMO_H, DEMO_T = "rotating-table-ball", "gni-trapezoid", 0.01, 10.0


@app.command()
def demo(
    out: Path = typer.Option(Path("gnipy-demo.nc"), "--out", "-o", help="Output netCDF file."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing --out file."),
):
    """Roll a ball on a rotating table (paper §7.4) with the GNI and compare with the exact solution.

    Runs the rotating-table-ball model (m = r = Ω = 1, I = 2/3, the paper's first example) with
    gni-trapezoid, h = 0.01, up to t = 10; prints the final state, energy and constraint residuals,
    the drift of the conserved quantities and the error against the exact solution (the contact
    point runs round a circle); writes the trajectory and the exact solution to OUT.
    """

    def go():
        import numpy as np

        from gnipy.io import write_netcdf

        spec, params, q0, v0 = _prepare(DEMO_MODEL, DEMO_METHOD, DEMO_H, None, DEMO_T, None, None, None, 1)
        _check_output(out, "--out", overwrite)
        sol, v0, seconds = _simulate(spec, params, DEMO_METHOD, q0, v0, DEMO_H, None, DEMO_T, False, 1)
        exact = _exact_errors(spec, params, sol, q0, v0)
        drifts = _invariant_drifts(spec, params, sol.q, sol.v)
        ds = sol.to_xarray()
        ds["q_exact"] = (("time", "coordinate"), np.asarray(exact[0]), {"long_name": "exact configuration"})
        ds["v_exact"] = (("time", "velocity"), np.asarray(exact[1]), {"long_name": "exact velocity"})
        attrs = _attrs_for(spec, params, sol, q0, v0, exact, drifts, {"command": "gni demo"})
        with _writing("--out", out):
            write_netcdf(ds, out, attrs=attrs, overwrite=overwrite)
        _report(
            "gni demo: ball on a rotating table, GNI (trapezoid) against the exact solution",
            spec, params, sol, exact, drifts, seconds, out,
            note="the turning table does work on the ball: the energy changes, the Jacobi integral "
            "E − mΩ(xẏ − yẋ), the speed |ż| and the spin ω₃ are conserved",
        )

    _guarded(go)


@app.command()
def models():
    """List the models with their parameters (defaults), coordinates and initial condition."""
    from rich.text import Text

    import gnipy

    con = _console()
    for name in gnipy.model_names():
        spec = gnipy.get_model(name)
        params = ", ".join(f"{k}={v:g}" for k, v in spec.params.items()) or "none"
        q0, v0 = spec.initial_condition(spec.params)
        extras = ["exact solution" if spec.exact is not None else None,
                  f"invariants: {', '.join(spec.invariants)}" if spec.invariants else None]
        con.print(Text.assemble((_safe(name), "bold"), ": ", _safe(spec.description)))
        con.print(f"    params: {params}", markup=False)
        con.print(f"    q = ({', '.join(spec.coordinates)}); default q0 = {q0}, v0 = {v0}", markup=False)
        more = "; ".join(x for x in extras if x)
        if more:
            con.print(f"    {more}", markup=False)
        con.print(f"    default method: {spec.default_method} ({spec.default_reason})", markup=False)


@app.command()
def methods():
    """List the method names with one-line descriptions."""
    from rich.text import Text

    from gnipy.methods import METHOD_DESCRIPTIONS

    con = _console()
    width = max(len(k) for k in METHOD_DESCRIPTIONS)
    for name, desc in METHOD_DESCRIPTIONS.items():
        con.print(Text.assemble((f"{_safe(name):<{width}}", "bold"), "  ", _safe(desc)))


# --------------------------------------------------------------------------------------------
# gni reproduce: the paper reproduction (src/gnipy/experiments/reproduce.py imports only the
# standard library and typer at the top, so `gni --help` stays fast).
# --------------------------------------------------------------------------------------------
from .experiments.reproduce import reproduce_command  # noqa: E402

app.command(name="reproduce")(reproduce_command)


if __name__ == "__main__":  # pragma: no cover
    app()
