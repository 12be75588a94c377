"""Configuration files of `gni run --config RUN.toml`: the options as TOML keys.

The keys are the option names (dashes or underscores), read from the command's own declarations
(:func:`config_keys`); options given on the command line override the file; `--overwrite`,
`--yes` and `--accept-out-of-band` are command-line options only (a configuration file cannot
grant them). Relative paths in the file are relative to the file's directory.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

from .errors import UsageError

__all__ = ["config_keys", "config_value", "load_config"]

#: What a config value must hold, by the type of the option it stands for (the command function's
#: annotation); an option of text "a,b,..." is named in `config_keys`'s `vectors`, and a
#: repeatable option (a list: `--set`) holds NAME=VALUE items.
_KINDS = {str: "string", float: "number", int: "integer", bool: "boolean", Path: "path"}


def config_keys(command, *, command_line_only, vectors) -> dict[str, tuple[str, str]]:
    """`{key: (option, kind)}` for the options of a CLI command that a configuration file may hold,
    read from the command function itself (its typer declarations and type annotations), so that
    the keys are the command's options and nothing else: every argument and option except
    `command_line_only`, a key for each long name of an option (`--q0` and its older name `--x0`
    both, dashes read as underscores), `option` its first long name (`MODEL` for the argument),
    and `kind` what the value must be (:data:`_KINDS`; `"vector"` for the options in `vectors`,
    `"set"` for a repeatable one)."""
    import inspect
    import typing

    hints = typing.get_type_hints(command)
    keys: dict[str, tuple[str, str]] = {}
    for name, param in inspect.signature(command).parameters.items():
        if name in command_line_only:
            continue
        annotation = hints[name]
        kind_of = next((a for a in typing.get_args(annotation) if a is not type(None)), annotation)
        kind = "set" if typing.get_origin(kind_of) is list else "vector" if name in vectors else _KINDS[kind_of]
        longs = [d.split("/")[0] for d in getattr(param.default, "param_decls", None) or () if d.startswith("--")]
        if not longs:  # the argument
            keys[name] = (getattr(param.default, "metavar", None) or name.upper(), kind)
        for long in longs:
            keys[long[2:].replace("-", "_")] = (longs[0], kind)
    return keys


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


def config_value(where: str, key: str, kind: str, value, base: Path):
    """Check one config value's type and turn it into what the CLI option would hold."""

    def bad():
        return UsageError("--config", f"{where}: key {key!r} must be {_KIND_TEXT[kind]}, got {value!r}")

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
        return _config_path(where, key, value, base, bad)
    if kind == "vector":
        return _config_vector(value, bad)
    if kind == "set":
        return _config_set(where, key, value, bad)
    raise AssertionError(kind)  # pragma: no cover


def _config_path(where: str, key: str, value, base: Path, bad) -> Path:
    """A config value of kind "path": relative to the config file's directory `base`."""
    if not isinstance(value, str) or not value:
        raise bad()
    try:
        path = Path(value).expanduser()
    except RuntimeError as e:  # "~user" of no such user
        raise UsageError("--config", f"{where}: key {key!r}: cannot use {value!r}: {e}") from None
    return path if path.is_absolute() else base / path


def _config_vector(value, bad) -> str:
    """A config value of kind "vector" as the option's text "a,b,...": a string, or a list of numbers."""
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value):
        return ",".join(repr(float(x)) for x in value)
    raise bad()


def _config_set(where: str, key: str, value, bad) -> list[str]:
    """A config value of kind "set" as the NAME=VALUE items of --set: a string, a list of
    strings, or a table of numbers by parameter name."""
    if isinstance(value, str):
        return [value]
    if isinstance(value, list) and all(isinstance(x, str) for x in value):
        return list(value)
    if not isinstance(value, dict):
        raise bad()
    items = []
    for name, x in value.items():
        if not _PARAM_NAME.fullmatch(name):  # e.g. { "m=2,g" = 1 } must not set m and g
            raise UsageError(
                "--config", f"{where}: key {key!r}: {name!r} is not a parameter name (in the table form "
                "each key is one name, e.g. set = { m = 2 }; or write set = [\"m=2\", ...])"
            )
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise UsageError("--config", f"{where}: key 'set.{name}' must be a number, got {x!r}")
        items.append(f"{name}={float(x)!r}")
    return items


def load_config(path: Path, keys: dict[str, tuple[str, str]]) -> dict[str, Any]:
    """Read a run configuration (TOML) whose `keys` are those of :func:`config_keys`: `{key:
    value}` with keys normalized (dashes → underscores) and values in the form the CLI options
    take; raises `UsageError` naming the file and key."""
    import tomllib

    where = str(path)
    if not path.exists():
        raise UsageError("--config", f"cannot read {where!r}: no such file")
    if not path.is_file():
        raise UsageError("--config", f"cannot read {where!r}: not a file")
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise UsageError("--config", f"{where}: not valid TOML: {e}") from None
    except UnicodeDecodeError:
        raise UsageError("--config", f"{where}: not valid TOML: the file is not UTF-8 text") from None
    except OSError as e:
        raise UsageError("--config", f"cannot read {where!r}: {e.strerror or e}") from None
    base = path.resolve().parent
    out: dict[str, Any] = {}
    for raw_key, value in data.items():
        key = raw_key.replace("-", "_")
        if key == "r0":
            key = "R0"
        if key == "x0" and "q0" in data:
            raise UsageError("--config", f"{where}: keys 'x0' and 'q0' both given ('x0' is the older name of 'q0')")
        if key not in keys:
            known = ", ".join(k.replace("_", "-") for k in keys)
            raise UsageError("--config", f"{where}: unknown key {raw_key!r} (known: {known})")
        if key in out:
            raise UsageError("--config", f"{where}: key {raw_key!r} given twice (with dashes and underscores)")
        out[key] = config_value(where, raw_key, keys[key][1], value, base)
        if key == "model" and isinstance(out[key], str):
            # a model of the user's own: only a .py file beside the config file (gnipy.user_systems)
            from gnipy.errors import InputError
            from gnipy.user_systems import data_file_reference

            try:
                out[key] = data_file_reference(out[key], base, "model")
            except InputError as e:
                raise UsageError("--config", f"{where}: {e}") from None
    return out


