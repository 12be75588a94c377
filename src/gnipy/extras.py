"""gnipy's optional parts and the packages they need (the extras of `pip install 'gnipy[...]'`).

`pip install gnipy` installs the library: systems, methods, the zoo, `simulate`, the continuous
reference, gradients, fits and optimal control, on JAX's XLA backend. The rest is optional:

| extra | what it adds | packages |
| --- | --- | --- |
| `files` | netCDF result files (`Solution.to_xarray`, `gnipy.io`, `simulate_to_file`, problem and observation files of `gnipy.control`) | xarray, netCDF4, zarr |
| `plots` | `gnipy.plots` | matplotlib (and `files`) |
| `cli` | the `gni` command | typer, rich (and `plots`, `files`) |
| `sweeps` | `gnipy.run_sweep`, `gnipy.open_sweep`, `gni sweep` | dask[distributed], rich (and `files`) |
| `native` | the native CPU backend (`backend="native"`; `"auto"` uses it when it is installed) | llvmlite |
| `sympy` | `gnipy.from_sympy`: systems from SymPy expressions and `sympy.physics.mechanics` | sympy, sympy2jax |
| `ipopt` | IPOPT as the optimizer of optimal control (`optimizer="ipopt"`) | cyipopt-wheels (cyipopt with IPOPT built in) |
| `all` | everything above | |

The library imports an optional package only where it is used, through :func:`require`: without
it, that call raises :class:`MissingExtra`, an ImportError that names the pip line, e.g.
``gnipy's file output needs xarray: pip install 'gnipy[files]'``. The native backend is the
exception: without llvmlite, `backend="auto"` runs on XLA (and `backend="native"` warns and does).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from types import ModuleType

__all__ = ["EXTRAS", "MissingExtra", "require", "check"]

#: extra -> what it is for, in the words of the error message ("gnipy's {what} needs ...").
EXTRAS: dict[str, str] = {
    "files": "file output",
    "plots": "plotting",
    "cli": "command line",
    "sweeps": "sweep runner",
    "native": "native backend",
    "sympy": "SymPy models (gnipy.from_sympy)",
    "ipopt": "IPOPT optimizer",
}


class MissingExtra(ImportError):
    """An optional package of gnipy is not installed; the message names the extra that installs it
    (``pip install 'gnipy[files]'``). `extra` and `name` (the missing package) are attributes."""

    def __init__(self, package: str, *, extra: str, what: str | None = None):
        if extra not in EXTRAS:
            raise ValueError(f"unknown extra {extra!r} (known: {', '.join(EXTRAS)})")
        super().__init__(f"gnipy's {what or EXTRAS[extra]} needs {package}: pip install 'gnipy[{extra}]'",
                         name=package)
        self.extra = extra


def require(module: str, *, extra: str, what: str | None = None) -> ModuleType:
    """Import `module` (e.g. `"xarray"`, `"matplotlib.figure"`) and return it; if its package is not
    installed, raise :class:`MissingExtra` naming `extra`, the extra of gnipy that installs it.

    `what` says what needs it (default: the extra's purpose, :data:`EXTRAS`): the message reads
    ``gnipy's {what} needs {package}: pip install 'gnipy[{extra}]'``."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r} (known: {', '.join(EXTRAS)})")
    try:
        return importlib.import_module(module)
    except ImportError as e:
        package = module.partition(".")[0]
        if isinstance(e, MissingExtra) or (e.name is not None and e.name.partition(".")[0] != package):
            raise  # the package is there, but something it imports failed: not a missing extra
        raise MissingExtra(package, extra=extra, what=what) from e


def check(*packages: str, extra: str, what: str | None = None) -> None:
    """Raise :class:`MissingExtra` (as :func:`require` does) for the first of `packages` (top-level
    names, e.g. `"xarray"`) that is not installed, without importing any: a cheap check before
    work starts (the `gni` command's, a sweep's, a streamed run's)."""
    for package in packages:
        try:
            found = importlib.util.find_spec(package) is not None
        except (ImportError, ValueError):  # ValueError: a module in sys.modules without a spec
            found = sys.modules.get(package) is not None
        if not found:
            raise MissingExtra(package, extra=extra, what=what)
