"""gnipy: the Geometric Nonholonomic Integrator and its extensions, in JAX.

Importing gnipy enables float64 in JAX (`jax_enable_x64`).
"""

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
    StepInfo,
)
from .lie_groups import SE2, SO3, MatrixLieGroup, ProductGroup, Rn, TrivialGroup  # noqa: E402
from .methods import get_method, method_names  # noqa: E402
from .models import get_model, make_system, model_names  # noqa: E402
from .projectors import projectors, reflect_momentum, reported_momentum  # noqa: E402
from .reference import ContinuousReference  # noqa: E402
from .retractions import Cayley, Exp, Retraction, get_retraction  # noqa: E402
from .ensembles import model_systems, stack_systems  # noqa: E402
from .sharding import member_devices  # noqa: E402
from .simulate import simulate  # noqa: E402
from .control import (  # noqa: E402
    ControlResult,
    FitResult,
    Observations,
    fit,
    solve_optimal_control,
)
from .streaming import simulate_to_file  # noqa: E402
from .sweep import open_sweep, run_sweep  # noqa: E402
from .io import read_netcdf, verify_netcdf, write_netcdf  # noqa: E402
from .solution import RESULTS, Solution  # noqa: E402
from .saveat import SaveAt  # noqa: E402
from .errors import (InputError, MethodError, OutputBusy, OutputError, QualitativeFailure,  # noqa: E402
                     QualitativeFailureWarning, SolverFailure)
from .private_cache import CacheWarning  # noqa: E402
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
    "DiscreteLagrangeDAlembert",
    "McLachlanPerlmutter",
    "DiscreteGradient",
    "Composition",
    "ContinuousReference",
    "simulate",
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
    "projectors",
    "reflect_momentum",
    "reported_momentum",
    "get_method",
    "method_names",
    "get_model",
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
