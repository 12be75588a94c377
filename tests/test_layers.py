"""The structure of the package (docs: conventions, "Architecture"; DESIGN.md §3), read from the
source with `ast`: every `import` and `from ... import` of a gnipy module, at module level and inside
functions (relative imports resolved; `from package import submodule` imports the submodule).

- The import graph of the modules has no cycle.
- No module imports another module's private name (one with a leading underscore): a name shared
  between modules is public in the module that defines it.
- The layers: each top-level module or package of src/gnipy has a layer, stated here once (a new
  one must be added: the test fails on an unknown name). A module imports only modules of lower
  layers and of its own package; two modules or packages in one layer never import each other.
  Inside a package the modules are ordered by their imports, which the first check keeps acyclic.
"""

import ast
from pathlib import Path

import gnipy

ROOT = Path(gnipy.__file__).parent

#: The layers, lowest first: each holds top-level modules and packages of src/gnipy that do not
#: import each other; each imports only from the layers before it. Design layers (DESIGN.md §3) in
#: the comments.
LAYERS = [
    # foundations: errors, the files' schema, input checks, files, the native cache
    ["version", "errors", "text", "schema"],
    ["inputs", "files", "resources", "sharding", "solution_text", "extras", "private_folder"],
    ["private_cache", "file_attributes", "user_systems"],
    ["compilation"],
    ["linalg"],  # its solves are traced once per shape (compilation.traced_once)
    # 1. Lie groups and retractions
    ["lie_groups"],
    ["retractions"],
    # 2. mechanics: the System and what derives from it; the model table
    ["spaces", "forcing", "projectors", "equations"],
    ["holonomic"],  # holonomic constraints: the System's rows, the methods' position multiplier
    ["system_checks", "system_arguments", "symbolic_mechanics"],  # symbolic_mechanics: reading SymPy mechanics models
    ["system"],
    ["registry", "symbolic"],
    # 3. discretization
    ["discrete_lagrangians"],
    # 4. integrators, and the method names that stand for them
    ["integrators"],
    ["methods"],
    # 5. the simulation driver: saving, diagnostics and verdicts, the Solution, the one stepping
    # loop and its native backend, the run's arguments, the one assembly of a Solution, batches,
    # transformed runs, the Problem and the one integrate, streamed runs
    ["saveat", "diagnostics"],
    ["monitor", "run_arguments"],
    ["solution", "stepping"],
    ["io", "reference", "assembly"],
    ["native"],
    ["preparation"],
    ["ensembles", "transformed"],
    ["problem"],
    ["integration"],
    ["simulate"],
    ["streaming"],
    # 6. models
    ["models"],
    # 7. analysis, control and sweeps (8. plots)
    ["analysis", "control", "sweep"],
    ["plots"],
    # the public API (the package's __init__, a facade over all of the above), then its clients:
    # 8. experiments, 9. the command line
    ["__init__"],
    ["experiments"],
    ["cli"],
    ["__main__"],
]

LAYER = {unit: i for i, units in enumerate(LAYERS) for unit in units}


def _module_name(path: Path) -> str:
    parts = ["gnipy", *path.relative_to(ROOT).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


#: Every module of src/gnipy: dotted name -> file.
MODULES = {_module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def _unit(module: str) -> str:
    """The top-level module or package of src/gnipy that holds `module` (`__init__`: gnipy itself)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _owner(name: str) -> str:
    """The module `name` is, or the innermost module that holds it (`gnipy.a.b.f` -> `gnipy.a.b`)."""
    while name not in MODULES and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def _imports(module: str):
    """`(line, imported module, name or None)` for every import of a gnipy module in `module`:
    `import gnipy.a.b` and `from gnipy.a import b` (b a submodule) give `gnipy.a.b` and None, `from
    gnipy.a import f` gives `gnipy.a` and `f`."""
    path = MODULES[module]
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "gnipy":
                    yield node.lineno, _owner(alias.name), None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package[: len(package) - (node.level - 1)] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            if base.split(".")[0] != "gnipy":
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:
                    yield node.lineno, sub, None
                else:
                    yield node.lineno, _owner(base), alias.name


def _graph() -> dict[str, set[str]]:
    """module -> the modules it imports (itself excepted)."""
    return {m: {t for _, t, _ in _imports(m) if t != m} for m in MODULES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (a list of modules, the first repeated at the end) in each strongly connected
    component of `graph` with more than one module (Tarjan's algorithm, without recursion)."""
    index, low, on_stack, stack, components = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            w = next(children, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                component = set()
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.add(w)
                    if w == v:
                        break
                if len(component) > 1:
                    components.append(component)
    cycles = []
    for component in components:  # the shortest way back to the first module, inside the component
        start = min(component)
        paths, seen, found = [[start]], {start}, None
        while found is None:
            path = paths.pop(0)
            for w in sorted(graph[path[-1]] & component):
                if w == start:
                    found = path + [start]
                    break
                if w not in seen:
                    seen.add(w)
                    paths.append(path + [w])
        cycles.append(found)
    return sorted(cycles)


def test_the_cycle_finder_finds_cycles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"d"}, "f": {"g"}, "g": {"f"}}
    assert _cycles(graph) == [["a", "b", "c", "a"], ["f", "g", "f"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_the_imports_are_read_from_every_statement():
    imports = {(t, name) for _, t, name in _imports("gnipy.simulate")}
    assert ("gnipy.solution", "Solution") in imports  # from .solution import Solution
    assert ("gnipy.monitor", None) in imports  # from . import monitor: the submodule
    imports = {(t, name) for _, t, name in _imports("gnipy.integration")}
    assert ("gnipy.native.backend", "choose") in imports  # inside a function


def test_the_import_graph_has_no_cycle():
    cycles = _cycles(_graph())
    assert cycles == [], "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_no_module_imports_a_private_name_of_another():
    private = [f"{MODULES[m].relative_to(ROOT)}:{line}: {name} from {target}"
               for m in MODULES for line, target, name in _imports(m)
               if target != m and name and name.startswith("_") and not name.startswith("__")]
    assert private == [], "private names imported from another module:\n" + "\n".join(private)


def _module_aliases(module: str) -> dict[str, str]:
    """The names under which `module` binds other gnipy modules (`from ..integrators import
    paper_schemes as ps`: `ps`; `import gnipy.io as gio`: `gio`; `from . import monitor`: `monitor`)."""
    path = MODULES[module]
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    out = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in MODULES and alias.asname:
                    out[alias.asname] = alias.name
        elif isinstance(node, ast.ImportFrom):
            base = (".".join(package[: len(package) - (node.level - 1)] + ([node.module] if node.module else []))
                    if node.level else node.module or "")
            for alias in node.names:
                if f"{base}.{alias.name}" in MODULES:
                    out[alias.asname or alias.name] = f"{base}.{alias.name}"
    return out


def test_no_module_reads_a_private_name_of_another_through_the_module():
    """`ps._helper` where `ps` is another gnipy module: as private as `from ... import _helper`."""
    private = []
    for m in MODULES:
        aliases = {a: t for a, t in _module_aliases(m).items() if t != m}
        tree = ast.parse(MODULES[m].read_text(encoding="utf-8"), str(MODULES[m]))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                private.append(f"{MODULES[m].relative_to(ROOT)}:{node.lineno}: {node.value.id}.{node.attr} "
                               f"({aliases[node.value.id]})")
    assert private == [], "private names of another module read through it:\n" + "\n".join(private)


def test_the_module_aliases_are_found():
    assert _module_aliases("gnipy.experiments.particle_study")["ps"] == "gnipy.integrators.paper_schemes"
    assert _module_aliases("gnipy.simulate")["monitor"] == "gnipy.monitor"


def test_every_module_has_a_layer():
    units = {_unit(m) for m in MODULES}
    assert units - set(LAYER) == set(), "add the new modules to LAYERS"
    assert set(LAYER) - units == set(), "remove the modules that no longer exist from LAYERS"
    assert len(LAYER) == sum(len(units) for units in LAYERS), "a module in two layers"


def test_no_module_imports_its_layer_or_a_higher_one():
    wrong = []
    for m in MODULES:
        own = _unit(m)
        for line, target in sorted({(line, target) for line, target, _ in _imports(m)}):
            other = _unit(target)
            if other != own and LAYER[other] >= LAYER[own]:
                wrong.append(f"{MODULES[m].relative_to(ROOT)}:{line} ({own}, layer {LAYER[own]}) imports {target} "
                             f"({other}, layer {LAYER[other]})")
    assert wrong == [], "imports of the same or a higher layer:\n" + "\n".join(wrong)


def test_version_is_stated_alike_in_the_package_and_pyproject():
    import tomllib

    pyproject = Path(__file__).resolve().parent.parent / "pyproject.toml"
    assert tomllib.loads(pyproject.read_text(encoding="utf-8"))["project"]["version"] == gnipy.__version__
