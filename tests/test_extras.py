"""A light core and extras (issue 30): `import gnipy` loads no optional package, and a call that
needs one that is missing says which extra installs it (gnipy.extras). A missing package is
simulated with `sys.modules[name] = None`, which makes `import name` raise ImportError."""

import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import gnipy
from gnipy.extras import EXTRAS, MissingExtra, check, require

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "gnipy"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]

#: the packages of the extras: `import gnipy` loads none of them
OPTIONAL = ("xarray", "netCDF4", "zarr", "matplotlib", "typer", "rich", "dask", "distributed", "llvmlite", "cyipopt")

#: import names whose distribution is named otherwise (cyipopt's wheels with IPOPT built in)
DISTRIBUTIONS = {"cyipopt": "cyipopt-wheels"}


def _requirement_name(req: str) -> str:
    return re.match(r"[A-Za-z0-9_.-]+", req).group(0)


def _extra_packages(extra: str) -> set[str]:
    """The packages an extra installs, its self-references (`gnipy[files]`) expanded; a package's
    own extras are packages too (`dask[distributed]` installs distributed)."""
    out = set()
    for req in PYPROJECT["optional-dependencies"][extra]:
        name = _requirement_name(req)
        extras = re.findall(r"\[([^\]]*)\]", req)
        names = [x.strip() for x in extras[0].split(",")] if extras else []
        if name == "gnipy":
            for x in names:
                out |= _extra_packages(x)
        else:
            out |= {name, *names}
    return out


def test_import_gnipy_loads_no_optional_package_nor_the_cli_or_experiments():
    code = ("import sys, json, gnipy; print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
            f"{OPTIONAL + ('diffrax', 'optimistix')!r} or m.startswith(('gnipy.cli', 'gnipy.experiments')))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


def test_every_public_name_is_listed_importable_and_documented():
    listed = set(dir(gnipy))
    for name in gnipy.__all__:
        assert name in listed, name
        value = getattr(gnipy, name)
        exec(f"from gnipy import {name}", {})
        if name != "__version__":
            assert (getattr(value, "__doc__", None) or "").strip(), f"gnipy.{name} has no docstring"
    assert gnipy.MissingExtra is MissingExtra and issubclass(MissingExtra, ImportError)
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        gnipy.no_such_name  # noqa: B018


def test_require_names_the_extra_and_its_pip_line(monkeypatch):
    assert require("json", extra="files") is sys.modules["json"]
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(MissingExtra) as info:
        require("xarray", extra="files")
    assert str(info.value) == "gnipy's file output needs xarray: pip install 'gnipy[files]'"
    assert (info.value.extra, info.value.name) == ("files", "xarray")
    # rich and rich.progress absent (an earlier test of the session may have imported them)
    monkeypatch.setitem(sys.modules, "rich", None)
    monkeypatch.setitem(sys.modules, "rich.progress", None)
    with pytest.raises(ImportError, match=r"^gnipy's progress bar needs rich: pip install 'gnipy\[cli\]'$"):
        require("rich.progress", extra="cli", what="progress bar")
    with pytest.raises(ValueError, match="unknown extra"):
        require("json", extra="nonesuch")


def test_a_package_whose_own_import_fails_is_not_called_a_missing_extra(tmp_path, monkeypatch):
    (tmp_path / "brokenpkg").mkdir()
    (tmp_path / "brokenpkg" / "__init__.py").write_text("import gnipy_test_no_such_dependency\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ModuleNotFoundError) as info:
        require("brokenpkg", extra="files")
    assert not isinstance(info.value, MissingExtra)
    assert info.value.name == "gnipy_test_no_such_dependency"


def test_every_require_in_the_source_names_an_extra_that_installs_the_package():
    """The extras of pyproject.toml and the calls of gnipy.extras.require agree."""
    assert set(EXTRAS) <= set(PYPROJECT["optional-dependencies"])
    assert _extra_packages("all") >= {p for extra in EXTRAS for p in _extra_packages(extra)}
    assert "gnipy[all]" in PYPROJECT["optional-dependencies"]["test"]
    core = {_requirement_name(r) for r in PYPROJECT["dependencies"]}
    assert core == {"jax", "equinox", "optimistix", "diffrax", "numpy", "scipy"}
    calls = 0
    for path in SRC.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        named = re.findall(r'require\("([\w.]+)", extra="(\w+)"', text)
        for packages, extra in re.findall(r'check\(((?:"[\w.]+", )+)extra="(\w+)"', text):
            named += [(package, extra) for package in re.findall(r'"([\w.]+)"', packages)]
        for package, extra in named:
            calls += 1
            top = package.split(".")[0]
            assert DISTRIBUTIONS.get(top, top) in _extra_packages(extra), f"{path.name}: {package} not in [{extra}]"
    assert calls >= 20


@pytest.fixture(scope="module")
def solution():
    return gnipy.simulate(gnipy.make_system("nonholonomic-particle"), "gni-midpoint", h=0.1, steps=2)


def test_file_output_without_xarray_or_netcdf4_names_the_files_extra(solution, monkeypatch, tmp_path):
    message = r"^gnipy's file output needs {}: pip install 'gnipy\[files\]'$"
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(MissingExtra, match=message.format("xarray")):
        solution.to_xarray()
    with pytest.raises(MissingExtra, match=message.format("xarray")):
        gnipy.write_netcdf(solution, tmp_path / "run.nc")
    monkeypatch.delitem(sys.modules, "xarray")
    monkeypatch.setitem(sys.modules, "netCDF4", None)
    with pytest.raises(MissingExtra, match=message.format("netCDF4")):
        gnipy.simulate_to_file(gnipy.make_system("nonholonomic-particle"), "gni-midpoint", h=0.1, steps=2,
                               path=tmp_path / "streamed.nc")
    assert list(tmp_path.iterdir()) == []  # refused before anything is written


def test_plots_without_matplotlib_name_the_plots_extra(solution, monkeypatch):
    from gnipy import plots

    monkeypatch.setitem(sys.modules, "matplotlib", None)
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    with pytest.raises(MissingExtra, match=r"^gnipy's plotting needs matplotlib: pip install 'gnipy\[plots\]'$"):
        plots.plot_path(solution)


def test_sweeps_without_dask_name_the_sweeps_extra_before_writing(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "dask", None)
    with pytest.raises(MissingExtra, match=r"^gnipy's sweep runner needs dask: pip install 'gnipy\[sweeps\]'$"):
        gnipy.run_sweep("nonholonomic-particle", {"q0.x": [0.0, 1.0]}, out=tmp_path / "s.zarr", h=0.1, steps=2)
    assert list(tmp_path.iterdir()) == []


def test_gni_without_the_cli_extra_prints_the_pip_line(monkeypatch):
    from gnipy.__main__ import main

    monkeypatch.setitem(sys.modules, "typer", None)
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == "gni: gnipy's command line needs typer: pip install 'gnipy[cli]'"


def test_check_finds_packages_without_importing_them(tmp_path, monkeypatch):
    (tmp_path / "gnipy_test_loud").mkdir()
    (tmp_path / "gnipy_test_loud" / "__init__.py").write_text("raise RuntimeError('imported')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    check("gnipy_test_loud", "json", extra="files")
    assert "gnipy_test_loud" not in sys.modules
    monkeypatch.setitem(sys.modules, "zarr", None)
    with pytest.raises(MissingExtra, match=r"^gnipy's sweep runner needs zarr: pip install 'gnipy\[sweeps\]'$"):
        check("json", "zarr", extra="sweeps")


def test_gni_help_loads_only_what_the_command_line_needs():
    code = ("import sys, json\nsys.argv = ['gni', '--help']\nfrom gnipy.__main__ import main\ntry:\n    main()\n"
            "except SystemExit:\n    pass\nprint(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('xarray', 'netCDF4', 'zarr', 'matplotlib', 'dask', 'distributed', 'llvmlite', 'diffrax') or "
            "m.startswith('gnipy.experiments'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert "Usage: gni" in out.stdout
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
