"""The problem zoo: classic nonholonomic systems with exact solutions or invariants."""

from . import contact_oscillator, nonholonomic_particle  # noqa: F401  (registration)
from .registry import ModelSpec, get_model, make_system, model_names, register

__all__ = ["ModelSpec", "get_model", "make_system", "model_names", "register"]
