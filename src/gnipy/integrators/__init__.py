"""One-step methods: the GNI core, the paper's explicit schemes, and comparators."""

from .base import Integrator, MethodError, StepInfo
from .comparators import DiscreteLagrangeDAlembert, McLachlanPerlmutter
from .composition import COMPOSITIONS, Composition
from .discrete_gradient import DiscreteGradient, DiscreteGradientState
from .gni import GNI, GNIState
from .paper_schemes import EulerABComposition, NonholonomicEulerA, NonholonomicEulerB, Rattle
from .reversal import ForwardOnly, Reversed
from .shake import Shake
from .sister import SisterMethod, SisterState

__all__ = [
    "Integrator",
    "MethodError",
    "StepInfo",
    "GNI",
    "GNIState",
    "NonholonomicEulerA",
    "NonholonomicEulerB",
    "EulerABComposition",
    "Rattle",
    "Shake",
    "SisterMethod",
    "SisterState",
    "DiscreteLagrangeDAlembert",
    "McLachlanPerlmutter",
    "DiscreteGradient",
    "DiscreteGradientState",
    "Composition",
    "COMPOSITIONS",
    "Reversed",
    "ForwardOnly",
]
