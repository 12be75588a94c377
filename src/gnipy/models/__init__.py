"""The problem zoo: classic nonholonomic systems with exact solutions or invariants."""

from . import (  # noqa: F401  (registration)
    chaplygin_sleigh,
    contact_oscillator,
    knife_edge,
    nonholonomic_particle,
    rotating_table_ball,
    vertical_disk,
)
from .registry import ModelSpec, get_model, make_system, model_names, register

__all__ = ["ModelSpec", "get_model", "make_system", "model_names", "register"]
