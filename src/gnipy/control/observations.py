"""Observations for identification (:func:`gnipy.fit`): observed values of some of a system's
variables at some times, from arrays, a :class:`~gnipy.Solution` or a result file, with their
measurement errors."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence

import numpy as np

from ..extras import require
from ..errors import InputError
from ..inputs import real_array
from ..solution import Solution

__all__ = ["Observations", "SIGMA_RANGE"]

#: The standard deviations `sigma` accepted: the weights 1/sigma and the squared weighted residuals
#: must stay finite in float64 (1/sigma² below about 1e300).
SIGMA_RANGE = (1e-150, 1e150)


@dataclasses.dataclass(frozen=True, eq=False)
class Observations:
    """Observed values of some of a system's variables at some times.

    Arguments:
        times: the observation times, shape (T,); each must be a node $t_0 + kh$ of the
            simulation's step grid (checked by :func:`fit`, which knows `t0` and `h`), in the
            order of the run.
        values: the observed values, shape (T, k) (or (T,) for one variable); NaN marks a missing
            value (that entry is left out of the fit).
        variables: the names of the k observed variables: the system's coordinate names (e.g.
            `"x"`, `"y"`, compared with the solution's `q`) or velocity names (e.g. `"dx"`,
            compared with its `v`). A partial observation names only some of them.
        sigma: optional standard deviations of the measurement errors: a number, one per
            variable (k,), or one per value (T, k). Given here or as :func:`fit`'s `sigma`.

    Raises:
        InputError: (message starting `observations:`) on shapes that do not match, non-finite
            times, values that are not numbers (strings and booleans are not), repeated variable
            names, or a `sigma` that is not positive and finite.
    """

    times: np.ndarray
    values: np.ndarray
    variables: tuple[str, ...]
    sigma: np.ndarray | None = None

    def __post_init__(self):
        times = real_array("observations", self.times, "a sequence of times (numbers)")
        if times.ndim != 1 or times.size == 0:
            raise InputError(f"observations: times must be a non-empty 1-D sequence, got shape {times.shape}")
        if not np.all(np.isfinite(times)):
            raise InputError("observations: times contain NaN or infinite values")
        if isinstance(self.variables, str):
            variables = (self.variables,)
        else:
            try:
                variables = tuple(self.variables)
            except TypeError:
                raise InputError(
                    f"observations: variables must be a sequence of names, got {self.variables!r}") from None
        if not variables or not all(isinstance(v, str) for v in variables):
            raise InputError(f"observations: variables must be a non-empty sequence of names, got {self.variables!r}")
        if len(set(variables)) != len(variables):
            raise InputError(f"observations: repeated variable names in {list(variables)}")
        values = real_array("observations", self.values, "an array of observed values (numbers)")
        if values.ndim == 1 and len(variables) == 1:
            values = values[:, None]
        if values.shape != (times.size, len(variables)):
            raise InputError(
                f"observations: values have shape {values.shape}, expected ({times.size}, {len(variables)}): "
                f"one row per time ({times.size}) and one column per variable ({', '.join(variables)})"
            )
        if np.any(np.isinf(values)):
            raise InputError("observations: values contain infinite entries (mark a missing value with NaN)")
        if not np.any(np.isfinite(values)):
            raise InputError("observations: every value is missing (NaN)")
        object.__setattr__(self, "times", times)
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "variables", variables)
        if self.sigma is not None:
            object.__setattr__(self, "sigma", sigma_array(self.sigma, values.shape, "observations"))

    @property
    def count(self) -> int:
        """The number of observed (finite) values."""
        return int(np.sum(np.isfinite(self.values)))

    @classmethod
    def from_solution(cls, solution: Solution, variables: Sequence[str] | None = None, *,
                      sigma=None) -> "Observations":
        """Observations read off a :class:`~gnipy.Solution` at its saved nodes.

        Arguments:
            solution: a single trajectory (not a batch).
            variables: the coordinate and/or velocity names to take (default: every coordinate).
            sigma: as in :class:`Observations`.
        """
        if not isinstance(solution, Solution):
            raise InputError(f"observations: expected a gnipy.Solution, got {type(solution).__name__}")
        if solution.batch_size is not None:
            raise InputError("observations: a batch of trajectories; pass one member (sol.member(i))")
        q, v = np.asarray(solution.q), np.asarray(solution.v)
        coords = tuple(solution.coordinates) or tuple(f"q{i}" for i in range(q.shape[-1]))
        vels = tuple(solution.velocities) or tuple(f"v{i}" for i in range(v.shape[-1]))
        return cls._select(np.asarray(solution.t), q, v, coords, vels, variables, sigma)

    @classmethod
    def from_dataset(cls, dataset, variables: Sequence[str] | None = None, *, sigma=None) -> "Observations":
        """Observations read from a result dataset (`Solution.to_xarray`, a file written by
        :func:`gnipy.write_netcdf`), or from the path of such a netCDF file
        (:func:`gnipy.io.read_netcdf`).

        Arguments:
            dataset: an `xarray.Dataset` with `q(time, coordinate)` and/or `v(time, velocity)`,
                or a path to a netCDF file.
            variables: the coordinate and/or velocity names to take (default: every coordinate).
            sigma: as in :class:`Observations`.
        """
        from ..io import result_times

        dataset = _as_dataset(dataset)
        _check_dataset(dataset)
        empty = np.zeros((dataset.sizes.get("time", 0), 0))
        q, coords = _dataset_part(dataset, "q", "coordinate", empty)
        v, vels = _dataset_part(dataset, "v", "velocity", empty)
        if variables is None and not coords:
            raise InputError("observations: the dataset has no q(time, coordinate); name the variables to take")
        return cls._select(result_times(dataset), q, v, coords, vels, variables, sigma)

    @classmethod
    def _select(cls, t, q, v, coords, vels, variables, sigma):
        if variables is None:
            variables = coords
        if isinstance(variables, str):
            variables = (variables,)
        cols = []
        for name in variables:
            if not isinstance(name, str):
                raise InputError(f"observations: variable names must be strings, got {name!r}")
            if name in coords:
                cols.append(q[:, coords.index(name)])
            elif name in vels:
                cols.append(v[:, vels.index(name)])
            else:
                raise InputError(f"observations: unknown variable {name!r} (coordinates: "
                                 f"{', '.join(coords) or 'none'}; velocities: {', '.join(vels) or 'none'})")
        values = np.stack(cols, axis=1) if cols else np.zeros((len(t), 0))
        return cls(np.asarray(t, dtype=np.float64), values, tuple(variables), sigma)


def _as_dataset(dataset):
    """`dataset` as an `xarray.Dataset`: read from a path (:func:`gnipy.io.read_netcdf`), or as it is."""
    xr = require("xarray", extra="files")

    from ..io import read_netcdf

    if isinstance(dataset, (str, os.PathLike)):
        try:
            dataset = read_netcdf(dataset)
        except MemoryError:
            raise
        except Exception as e:  # OSError, or what a damaged file raises (HDF errors, ...)
            why = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise InputError(f"observations: {why}") from None
    if not isinstance(dataset, xr.Dataset):
        raise InputError(f"observations: expected an xarray.Dataset or a path, got {type(dataset).__name__}")
    return dataset


def _check_dataset(dataset) -> None:
    """One trajectory with `q(time, coordinate)` and/or `v(time, velocity)` of numbers, and numeric times."""
    if "member" in dataset.dims:
        raise InputError("observations: the dataset holds a batch (dimension 'member'); select one member")
    if "q" not in dataset.variables and "v" not in dataset.variables:
        raise InputError("observations: the dataset has neither q(time, coordinate) nor v(time, velocity)")
    for var, dim in (("q", "coordinate"), ("v", "velocity")):
        if var in dataset.variables:
            dims = tuple(dataset[var].dims)
            if sorted(dims) != sorted(("time", dim)):
                raise InputError(f"observations: {var} has dimensions {dims}, expected (time, {dim})")
            if dataset[var].dtype.kind not in "iuf":  # strings, booleans, dates are not observations
                raise InputError(f"observations: {var} holds {dataset[var].dtype} values, not numbers")
    time_var = dataset["t"] if "t" in dataset.variables and dataset["t"].dims == ("time",) else (
        dataset["time"] if "time" in dataset.variables else None)
    if time_var is not None and time_var.dtype.kind not in "iuf":
        raise InputError(f"observations: the times hold {time_var.dtype} values, not numbers")


def _dataset_part(dataset, var, dim, empty):
    """`(values (time, dim), names)` of the dataset's `var` (`empty` and no names without it)."""
    if var not in dataset.variables:
        return empty, ()
    names = tuple(str(c) for c in dataset[dim].values) if dim in dataset.coords else ()
    a = dataset[var].transpose("time", dim).values
    return np.asarray(a, dtype=np.float64), names or tuple(f"{var}{i}" for i in range(a.shape[1]))


def sigma_array(sigma, shape, name: str) -> np.ndarray:
    """`sigma` broadcast to `shape` (T, k): a number, (k,) or (T, k); positive and finite."""
    s = real_array(name, sigma, "positive standard deviations (numbers)")
    if s.ndim == 1 and s.shape[0] == shape[1]:
        s = np.broadcast_to(s[None, :], shape)
    elif s.ndim == 0 or s.shape == shape:
        s = np.broadcast_to(s, shape)
    else:
        raise InputError(f"{name}: sigma has shape {s.shape}; expected a number, one per variable ({shape[1]},) "
                         f"or one per value {shape}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise InputError(f"{name}: sigma must be positive and finite")
    low, high = SIGMA_RANGE
    if np.any(s < low) or np.any(s > high):
        raise InputError(f"{name}: sigma must lie in {low:g} .. {high:g}, got values from {float(np.min(s)):g} to "
                         f"{float(np.max(s)):g}: the weights 1/sigma or the squared weighted residuals would not be "
                         "finite in float64")
    return np.array(s, dtype=np.float64)


def as_observations(observations) -> Observations:
    """What :func:`fit` accepts as `observations`, as an :class:`Observations`."""
    xr = require("xarray", extra="files")

    if isinstance(observations, Observations):
        return observations
    if isinstance(observations, Solution):
        return Observations.from_solution(observations)
    if isinstance(observations, (xr.Dataset, str, os.PathLike)):
        return Observations.from_dataset(observations)
    if isinstance(observations, tuple) and len(observations) in (2, 3):
        if len(observations) == 3:
            return Observations(*observations)
        return UnnamedObservations(*observations)
    raise InputError(
        "observations: expected a gnipy.control.Observations, a (times, values[, variables]) tuple, a "
        f"gnipy.Solution, an xarray.Dataset or the path of a netCDF file, got {type(observations).__name__}"
    )


class UnnamedObservations:
    """`(times, values)` without names: every coordinate, named once the system is known."""

    def __init__(self, times, values):
        self.times, self.values = times, values

    def named(self, coordinates) -> Observations:
        """The observations with the system's `coordinates` as their variables."""
        values = real_array("observations", self.values, "an array of observed values (numbers)")
        if values.ndim == 1 and len(coordinates) == 1:
            values = values[:, None]
        if values.ndim != 2 or values.shape[1] != len(coordinates):
            raise InputError(
                f"observations: values of shape {values.shape} without variable names must hold every coordinate "
                f"({len(coordinates)} columns: {', '.join(coordinates)}); give (times, values, variables) for others"
            )
        return Observations(self.times, values, tuple(coordinates))
