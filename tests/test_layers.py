"""The layers of the package (docs: conventions, "Architecture"): every module imports gnipy
modules only from its own layer and the layers below it, at module level and inside functions.

The layer of each top-level module or package is stated here once; a new module must be added
(the test fails on an unknown name)."""

import ast
from pathlib import Path

import gnipy

#: Layer of each top-level module or package of src/gnipy (lower numbers are imported by higher).
LAYERS = {
    # foundations used everywhere: errors, compilation options, input arrays, small solves, files
    "errors": 0, "compilation": 0, "inputs": 0, "linalg": 0, "sharding": 0, "schema": 0, "files": 0, "text": 0,
    "version": 0, "private_cache": 0, "resources": 0,
    # core: groups and retractions; the system, spaces, projectors, continuous equations, model table
    "lie_groups": 1, "retractions": 1,
    "system": 2, "system_checks": 2, "forcing": 2, "spaces": 2, "projectors": 2, "equations": 2, "registry": 2,
    "discrete_lagrangians": 3,
    "integrators": 4, "methods": 4,
    # driver: one loop, saving, the Solution, diagnostics, reference run, batches, streamed runs
    "saveat": 5, "stepping": 5, "preparation": 5, "simulate": 5, "transformed": 5, "ensembles": 5,
    "solution": 5, "solution_text": 5, "diagnostics": 5, "monitor": 5, "reference": 5, "streaming": 5, "io": 5, "native": 5,
    "models": 6,
    "analysis": 7, "control": 7,
    "plots": 8, "sweep": 8, "experiments": 9,
    # the public API (the package's __init__, a facade over all of the above), then its clients
    "__init__": 9, "cli": 10, "__main__": 10,
}

ROOT = Path(gnipy.__file__).parent


def _top(parts: list[str]) -> str:
    return parts[0].removesuffix(".py") if parts else "__init__"


def _imports(path: Path):
    """(line, imported top-level gnipy module) for every gnipy import in `path`."""
    rel = path.relative_to(ROOT).parts
    package = list(rel[:-1])
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                names = node.module.split(".") if node.module else None
                if names:
                    yield node.lineno, _top(base + names)
                else:
                    for alias in node.names:  # a submodule, or a name from the package's __init__
                        sub = _top(base + [alias.name])
                        yield node.lineno, sub if (base or sub in LAYERS) else "__init__"
            elif node.module and node.module.split(".")[0] == "gnipy":
                parts = node.module.split(".")[1:]
                if parts:
                    yield node.lineno, _top(parts)
                else:
                    for alias in node.names:
                        yield node.lineno, alias.name if alias.name in LAYERS else "__init__"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "gnipy":
                    yield node.lineno, _top(alias.name.split(".")[1:])


def test_every_module_has_a_layer():
    tops = {p.name.removesuffix(".py") for p in ROOT.iterdir()
            if (p.suffix == ".py" or (p.is_dir() and (p / "__init__.py").exists()))}
    assert tops - set(LAYERS) == set(), "add the new modules to LAYERS"


def test_no_module_imports_a_higher_layer():
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        own = _top(list(path.relative_to(ROOT).parts))
        for line, target in _imports(path):
            if target != own and LAYERS[target] > LAYERS[own]:
                upward.append(f"{path.relative_to(ROOT)}:{line} ({own}, layer {LAYERS[own]}) imports {target} "
                              f"(layer {LAYERS[target]})")
    assert upward == []


def test_version_is_stated_alike_in_the_package_and_pyproject():
    import tomllib

    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    assert tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]["version"] == gnipy.__version__
