"""gnipy: the Geometric Nonholonomic Integrator and its extensions, in JAX.

Importing gnipy enables float64 in JAX (`jax_enable_x64`). It imports the library's core (on JAX
and equinox; optimistix and diffrax are imported by the solves that use them); the names of the
interfaces (fits and optimal control, streamed runs to files, sweeps, netCDF files: :data:`_LAZY`)
are imported on first use (PEP 562), and the optional packages they need (xarray, dask, ...:
:mod:`gnipy.extras`) only by the calls that use them.
"""

import typing as _typing

import jax as _jax

_jax.config.update("jax_enable_x64", True)

from .version import __version__  # noqa: E402

from . import models  # noqa: E402
from .diagnostics import EnergyVerdict, HiddenMomentumVerdict  # noqa: E402
from .discrete_lagrangians import (  # noqa: E402
    CustomDiscreteLagrangian,
    DiscreteLagrangian,
    EulerA,
    EulerB,
    Midpoint,
    Trapezoid,
)
from .integrators import (  # noqa: E402
    GNI,
    Composition,
    DiscreteGradient,
    DiscreteLagrangeDAlembert,
    EulerABComposition,
    Integrator,
    McLachlanPerlmutter,
    NonholonomicEulerA,
    NonholonomicEulerB,
    Rattle,
    Shake,
    SisterMethod,
    StepInfo,
)
from .lie_groups import SE2, SO3, MatrixLieGroup, ProductGroup, Rn, TrivialGroup  # noqa: E402
from .methods import get_method, method_names  # noqa: E402
from .models import get_model, make_system, model_from_function, model_names  # noqa: E402
from .projectors import projectors, reflect_momentum, reported_momentum  # noqa: E402
from .reference import ContinuousReference  # noqa: E402
from .retractions import Cayley, Exp, Retraction, get_retraction  # noqa: E402
from .ensembles import model_systems, stack_systems  # noqa: E402
from .sharding import member_devices  # noqa: E402
from .simulate import simulate  # noqa: E402
from .problem import Problem  # noqa: E402
from .integration import integrate  # noqa: E402
from .solution import RESULTS, Solution  # noqa: E402
from .saveat import SaveAt  # noqa: E402
from .errors import (InputError, MethodError, OutputBusy, OutputError, QualitativeFailure,  # noqa: E402
                     QualitativeFailureWarning, SolverFailure)
from .extras import MissingExtra  # noqa: E402
from .private_folder import CacheWarning  # noqa: E402
from .spaces import EuclideanSpace, GroupSpace, Point  # noqa: E402
from .system import System  # noqa: E402

__all__ = [
    "EnergyVerdict",
    "HiddenMomentumVerdict",
    "__version__",
    "System",
    "DiscreteLagrangian",
    "EulerA",
    "EulerB",
    "Trapezoid",
    "Midpoint",
    "CustomDiscreteLagrangian",
    "Integrator",
    "StepInfo",
    "MethodError",
    "GNI",
    "NonholonomicEulerA",
    "NonholonomicEulerB",
    "EulerABComposition",
    "Rattle",
    "Shake",
    "SisterMethod",
    "DiscreteLagrangeDAlembert",
    "McLachlanPerlmutter",
    "DiscreteGradient",
    "Composition",
    "ContinuousReference",
    "simulate",
    "Problem",
    "integrate",
    "fit",
    "FitResult",
    "Observations",
    "solve_optimal_control",
    "ControlResult",
    "model_systems",
    "simulate_to_file",
    "run_sweep",
    "open_sweep",
    "OutputError",
    "OutputBusy",
    "QualitativeFailure",
    "QualitativeFailureWarning",
    "CacheWarning",
    "write_netcdf",
    "read_netcdf",
    "verify_netcdf",
    "stack_systems",
    "member_devices",
    "Solution",
    "SaveAt",
    "RESULTS",
    "InputError",
    "SolverFailure",
    "MissingExtra",
    "projectors",
    "reflect_momentum",
    "reported_momentum",
    "get_method",
    "method_names",
    "get_model",
    "model_from_function",
    "from_sympy",
    "linearize",
    "modified_equations",
    "sister_trajectory",
    "sister_method",
    "make_system",
    "model_names",
    "models",
    "MatrixLieGroup",
    "SO3",
    "SE2",
    "Rn",
    "ProductGroup",
    "TrivialGroup",
    "Retraction",
    "Cayley",
    "Exp",
    "get_retraction",
    "Point",
    "EuclideanSpace",
    "GroupSpace",
]

#: name -> the module that defines it, for the names imported on first use (:func:`__getattr__`):
#: the interfaces above the core (their modules are small, but they are not needed to simulate)
_LAZY = {
    **dict.fromkeys(["ControlResult", "FitResult", "Observations", "fit", "solve_optimal_control"], "control"),
    "simulate_to_file": "streaming",
    "from_sympy": "symbolic",
    **dict.fromkeys(["linearize", "modified_equations", "sister_trajectory", "sister_method"], "analysis"),
    **dict.fromkeys(["open_sweep", "run_sweep"], "sweep"),
    **dict.fromkeys(["read_netcdf", "verify_netcdf", "write_netcdf"], "io"),
}


def __getattr__(name: str):
    """The names of :data:`_LAZY`, imported from their module on first use, and gnipy's subpackages
    and modules (`gnipy.sweep`, `gnipy.plots`, ...), imported when first named (PEP 562)."""
    import importlib
    import importlib.util

    module = _LAZY.get(name)
    if module is not None:
        value = getattr(importlib.import_module(f".{module}", __name__), name)
        globals()[name] = value
        return value
    if not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}") is not None:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'gnipy' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names, those imported on first use included."""
    return sorted({*globals(), *__all__})


if _typing.TYPE_CHECKING:  # for type checkers and the API reference (griffe reads imports statically)
    from .control import ControlResult, FitResult, Observations, fit, solve_optimal_control  # noqa: F401
    from .io import read_netcdf, verify_netcdf, write_netcdf  # noqa: F401
    from .streaming import simulate_to_file  # noqa: F401
    from .sweep import open_sweep, run_sweep  # noqa: F401
