"""The problem zoo: classic nonholonomic systems with exact solutions or invariants.

Not in the zoo's table (build them from their modules), both with a holonomic constraint:
:mod:`gnipy.models.whipple_bicycle`, the Carvallo–Whipple bicycle of the Meijaard 2007 benchmark;
:mod:`gnipy.models.rattleback`, Kane and Levinson's rattleback, whose spin reverses."""

from . import (  # noqa: F401  (registration)
    chaplygin_sleigh,
    chaplygin_sleigh_se2,
    chaplygin_sphere,
    chaplygin_top,
    contact_oscillator,
    contact_oscillator_gauge,
    contact_oscillator_mp,
    default_methods,
    differential_drive,
    knife_edge,
    nonholonomic_particle,
    nonholonomic_particle_gauge,
    rolling_ball,
    rolling_disk,
    rotating_table_ball,
    suslov,
    veselova,
    vertical_disk,
)
from ..registry import ModelSpec, get_model, make_system, model_from_function, model_names, register

__all__ = ["ModelSpec", "get_model", "make_system", "model_from_function", "model_names", "register"]
