"""The variables of gnipy's files, stated once: names, dimensions, units and long names.

Every file gnipy writes uses these: a result file (:meth:`gnipy.Solution.to_xarray`,
:func:`gnipy.io.write_netcdf`), a streamed run (:func:`gnipy.simulate_to_file`) and a sweep store
(:func:`gnipy.sweep.run_sweep`). Each variable is a :class:`Variable` in :data:`VARIABLES`: its
dimensions *per trajectory* (a batch puts `member` in front, a sweep store the grid axes), its
dtype where gnipy fixes one, and its CF attributes (`long_name`, `units`, `standard_name`,
`axis`). The helpers give a variable's attributes (:func:`variable_attrs`) and dimensions
(:func:`dims`), set the attributes of a whole dataset (:func:`apply`) and build the coordinates
along `time` (:func:`time_coordinates`).

**Conventions** (CF-1.8, :data:`CONVENTIONS`). The coordinate `time` holds the times of the saved
nodes in seconds (:data:`TIME_UNITS`), with `node(time)` (the saved-node index) and `step(time)`
(the step index k, t = t0 + k h) beside it. Ratios carry `units = "1"`. `q`, `v`, `p` and the
constraint residual mix lengths and angles (radians), so they carry no single `units`
attribute, and no model states an energy unit, so the energies carry none
(:data:`UNITS_CONVENTION`, stored in each file's attribute `units_convention`). `q`, `v` and `p`
name their components in the attribute `components` (from the coordinates `coordinate` and
`velocity`).

**Result codes.** `result` is 0 when every step converged and 1 when a step's solve failed
(:class:`gnipy.RESULTS`); then `failed_step` is the failed step (else -1), `failed_time` the
time at its start and `failed_residual` the residual of its solve (NaN when none), and `valid`
is False at the nodes after it (whose values are NaN in a batch or a sweep).

This module imports nothing of gnipy: every layer may use it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import MappingProxyType

__all__ = [
    "Variable",
    "VARIABLES",
    "CONVENTIONS",
    "TIME_UNITS",
    "UNITS_CONVENTION",
    "VARIABLE_ATTRS",
    "VARIABLE_UNITS",
    "variable_attrs",
    "dims",
    "apply",
    "time_coordinates",
    "grid_axis_attrs",
    "param_attrs",
]

#: The metadata conventions gnipy's files follow.
CONVENTIONS = "CF-1.8"

#: The units of time (the models state no other).
TIME_UNITS = "s"

#: What the global attribute `units_convention` of a file says.
UNITS_CONVENTION = (
    "time in s; the models' parameters are SI values or nondimensional unit scales unless the model "
    "states otherwise; angles in radians; q, v, p and the constraint residual mix lengths and angles and "
    "carry no single units attribute; no energy unit is stated"
)


@dataclasses.dataclass(frozen=True)
class Variable:
    """One variable (or coordinate) of gnipy's files.

    Attributes:
        name: the variable's name in the files.
        dims: its dimensions for one trajectory (`("time", "coordinate")` for `q`); a batch
            puts `member` in front, a sweep store the grid axes (:func:`dims`).
        long_name: the CF `long_name`.
        units: the CF `units`, where the quantity has one (else None).
        dtype: the dtype gnipy stores it in, where fixed (a NumPy dtype name; None: as computed).
        standard_name, axis: the CF `standard_name` and `axis` (of `time`), else None.
        components: the dimension whose names the attribute `components` lists (`"coordinate"`
            for `q`, `"velocity"` for `v` and `p`), else None.
        sweep_long_name: the `long_name` in a sweep store, where it says more there.
    """

    name: str
    dims: tuple[str, ...]
    long_name: str
    units: str | None = None
    dtype: str | None = None
    standard_name: str | None = None
    axis: str | None = None
    components: str | None = None
    sweep_long_name: str | None = None

    def attrs(self, *, sweep: bool = False) -> dict[str, str]:
        """The CF attributes, in the order files hold them (`components` is added by
        :func:`apply`, which knows the names)."""
        out = {}
        if self.standard_name:
            out["standard_name"] = self.standard_name
        out["long_name"] = (self.sweep_long_name if sweep and self.sweep_long_name else self.long_name)
        if self.units is not None:
            out["units"] = self.units
        if self.axis:
            out["axis"] = self.axis
        return out


def _variables(*vs: Variable) -> Mapping[str, Variable]:
    return MappingProxyType({v.name: v for v in vs})


_T = ("time",)

#: Every variable of gnipy's files, by name.
VARIABLES: Mapping[str, Variable] = _variables(
    # coordinates along time and the component axes
    Variable("time", _T, "time", TIME_UNITS, "float64", standard_name="time", axis="T"),
    Variable("node", _T, "saved node index", dtype="int64"),
    Variable("step", _T, "step index k: t = t0 + k h", dtype="int64"),
    Variable("coordinate", ("coordinate",), "name of the configuration coordinate"),
    Variable("velocity", ("velocity",), "name of the velocity component"),
    Variable("constraint", ("constraint",), "constraint index", dtype="int64"),
    Variable("member", ("member",), "member index of the batch", dtype="int64"),
    # the state at the saved nodes
    Variable("q", (*_T, "coordinate"), "configuration", dtype="float64", components="coordinate"),
    Variable("v", (*_T, "velocity"), "reported velocity", dtype="float64", components="velocity"),
    Variable("p", (*_T, "velocity"), "reported momentum", dtype="float64", components="velocity"),
    Variable("energy", _T, "energy ½vᵀGv + V", dtype="float64"),
    Variable("constraint_residual", (*_T, "constraint"), "constraint residual mu(q)(v - Y(q)), then phi(q) (holonomic)",
             dtype="float64"),
    Variable("R", (*_T, "i", "j"), "orientation R (group matrix)", dtype="float64"),
    # the GNI family's diagnostics
    Variable("energy_plus", _T, "energy of the post-momentum ½p⁺ᵀG⁻¹p⁺ + V (energy theorem)",
             dtype="float64"),
    Variable("hidden_momentum", _T, "hidden momentum |p⁺ - p̄|/|p̄| (norms in G⁻¹)", "1", "float64"),
    Variable("hidden_momentum_expected", _T, "its expected size (|h|/2)|μᵀλ|/|p̄|", "1", "float64"),
    # how each member's run ended (a batch, a sweep)
    Variable("valid", _T, "saved node computed (False after a failed step)", dtype="bool",
             sweep_long_name="saved node computed (False after a failed step, or chunk not done)"),
    Variable("result", (), "0: success, 1: a step failed", dtype="int32"),
    Variable("failed_step", (), "first failed step or -1", dtype="int32"),
    Variable("failed_time", (), "time at the start of the failed step, or NaN", TIME_UNITS, "float64"),
    Variable("failed_residual", (), "residual of the failed step's solve, or NaN", dtype="float64"),
    # the verdicts of each member's run, every node checked (gnipy.monitor; a sweep)
    Variable("healthy", (), "every step converged and every verdict stayed in band", dtype="bool"),
    Variable("native", (), "the run's loop was compiled by the native backend (else by XLA)", dtype="bool"),
    Variable("hidden_momentum_first_time", (), "time the hidden momentum left its O(h) band, or NaN",
             TIME_UNITS, "float64"),
    Variable("hidden_momentum_max_band_ratio", (), "largest hidden momentum over its band (> 1: out of band; "
             "NaN: no hidden momentum)", "1", "float64"),
    Variable("energy_drift_first_time", (), "time the conserved energy drifted out of its band, or NaN",
             TIME_UNITS, "float64"),
    Variable("energy_drift_max", (), "largest energy drift over the kinetic energy (> 1/2: out of band; NaN: "
             "the energy is not conserved)", "1", "float64"),
    # the inputs of a controlled run (gni control, gnipy.control), one per step, held over the step
    Variable("control_step", ("control_step",), "step index k of the inputs", dtype="int64"),
    Variable("control_time", ("control_step",), "time t_k at which the step's input starts", TIME_UNITS,
             "float64"),
    Variable("input", ("input",), "name of the input"),
    Variable("u", ("control_step", "input"), "input u_k, held over the step [t_k, t_k + h)", dtype="float64",
             components="input"),
    # the estimates of a fit (gni fit, gnipy.fit): parameters, then q0.<name>, v0.<name>
    Variable("quantity", ("quantity",), "name of the estimated quantity"),
    Variable("quantity_", ("quantity_",), "name of the estimated quantity (second axis of the covariance)"),
    Variable("estimate", ("quantity",), "estimate", dtype="float64"),
    Variable("standard_error", ("quantity",), "standard error of the estimate (inf: not identifiable)",
             dtype="float64"),
    Variable("covariance", ("quantity", "quantity_"), "covariance of the estimates", dtype="float64"),
    # the exact solution (gni demo)
    Variable("q_exact", (*_T, "coordinate"), "exact configuration", dtype="float64"),
    Variable("v_exact", (*_T, "velocity"), "exact velocity", dtype="float64"),
    # the bookkeeping of a sweep store, per chunk
    Variable("chunk", ("chunk",), "chunk index of the sweep", dtype="int64"),
    Variable("chunk_done", ("chunk",),
             "True once the chunk's data and checksum are written (written last)", dtype="bool"),
    Variable("chunk_checksum", ("chunk", "digest"),
             "SHA-256 digest of the chunk's data (gnipy.files.array_checksum of its member "
             "variables); zero until written", dtype="uint8"),
)

#: The attributes of each variable (`long_name`, `units` where meaningful, ...), by name.
VARIABLE_ATTRS: Mapping[str, Mapping[str, str]] = MappingProxyType(
    {name: MappingProxyType(v.attrs()) for name, v in VARIABLES.items()}
)

#: The units of the variables that have one.
VARIABLE_UNITS: Mapping[str, str] = MappingProxyType(
    {name: v.units for name, v in VARIABLES.items() if v.units is not None}
)


def grid_axis_attrs(name: str) -> dict[str, str]:
    """The attributes of the coordinate of a sweep's grid axis `name` (`m`, `q0.x`, ...)."""
    return {"long_name": f"grid axis {name}"}


def param_attrs(name: str) -> dict[str, str]:
    """The attributes of `param_NAME(member)`, a batch's per-member parameter `name`."""
    return {"long_name": f"parameter {name}"}


def variable_attrs(name: str, *, sweep: bool = False) -> dict[str, str]:
    """The CF attributes of the variable `name` (a copy; `{}` for a name gnipy does not state).
    `param_NAME` is a batch's per-member parameter; `sweep=True` gives the wording of a sweep
    store where it differs."""
    v = VARIABLES.get(name)
    if v is not None:
        return v.attrs(sweep=sweep)
    if name.startswith("param_") and len(name) > 6:
        return param_attrs(name[6:])
    return {}


def dims(name: str, leading: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The dimensions of the variable `name`, after the `leading` ones: `dims("q")` is
    `("time", "coordinate")`, `dims("q", ("member",))` that of a batch, and a sweep store's
    `dims("q", ("m", "q0_x"))` `("m", "q0_x", "time", "coordinate")`. A batch's per-member
    parameter `param_NAME` has none of its own.

    Raises:
        KeyError: a name gnipy does not state.
    """
    if name not in VARIABLES and name.startswith("param_") and len(name) > 6:
        return tuple(leading)
    return (*leading, *VARIABLES[name].dims)


def apply(ds, *, sweep: bool = False):
    """Give the variables of the dataset `ds` their attributes, in place (and return it): those of
    :func:`variable_attrs` where not set already, and on `q`, `v` and `p` the names of their
    components (attribute `components`, from the coordinates `coordinate` and `velocity`)."""
    for name, var in ds.variables.items():
        for key, value in variable_attrs(str(name), sweep=sweep).items():
            var.attrs.setdefault(key, value)
    for name, v in VARIABLES.items():
        if v.components and name in ds.variables and v.components in ds.coords:
            ds.variables[name].attrs["components"] = ", ".join(str(x) for x in ds[v.components].values)
    return ds


def time_coordinates(times, h: float | None = None, steps=None, nodes=None) -> dict[str, tuple]:
    """The coordinates along `time` of a result dataset, for `xarray.Dataset(coords=...)`:
    `time` (the times, float64, CF attributes), `node` (the saved-node index, or `nodes`) and
    `step` (the step index: `steps`, or round((t - t0)/h) when `h` is finite and non-zero;
    left out otherwise, e.g. without a step size)."""
    import numpy as np

    t = np.asarray(times, dtype=np.float64)
    node = np.arange(len(t), dtype=np.int64) if nodes is None else np.asarray(nodes, np.int64)
    coords = {
        "time": (("time",), t, variable_attrs("time")),
        "node": (("time",), node, variable_attrs("node")),
    }
    if steps is None and h is not None and np.isfinite(h) and h != 0 and len(t):
        steps = np.rint((t - t[0]) / h)
    if steps is not None:
        coords["step"] = (("time",), np.asarray(steps).astype(np.int64), variable_attrs("step"))
    return coords
