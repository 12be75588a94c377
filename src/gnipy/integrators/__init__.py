"""One-step methods: the GNI core, the paper's explicit schemes, and comparators."""

from .base import Integrator, MethodError, StepInfo
from .gni import GNI, GNIState

__all__ = ["Integrator", "MethodError", "StepInfo", "GNI", "GNIState"]
