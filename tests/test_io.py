"""netCDF output: contents, provenance, and atomic writes (no partial file, ever)."""

import errno
import json
import os

import numpy as np
import pytest
import xarray as xr

import gnipy
from gnipy.io import OutputError, read_netcdf, write_netcdf


def _solution(scale=1.0, system="vertical-disk"):
    """A small hand-made Solution (no integration, no compilation)."""
    T, n, m = 5, 4, 2
    t = np.linspace(0.0, 0.4, T)
    q = scale * np.arange(T * n, dtype=float).reshape(T, n)
    v = q + 0.5
    return gnipy.Solution(
        t, q, v, 2 * v, scale * np.ones(T), np.zeros((T, m)), np.array([3, 1], dtype=np.int32),
        system=system, method="gni-trapezoid", h=0.1, coordinates=("x", "y", "phi", "theta"),
        params=(("m", 1.0), ("r", 2.0)),
    )


def _leftovers(directory, keep):
    return sorted(set(os.listdir(directory)) - set(keep))


def test_round_trip_variables_and_provenance(tmp_path):
    sol = _solution()
    path = tmp_path / "out.nc"
    assert write_netcdf(sol, path, attrs={"q0": (0, 0, 0, 1), "note": "hello", "flag": True}) == path
    ds = read_netcdf(path)
    assert isinstance(ds, xr.Dataset)
    for name, dims in [("time", ("time",)), ("q", ("time", "coordinate")), ("v", ("time", "velocity")),
                       ("energy", ("time",)), ("constraint_residual", ("time", "constraint"))]:
        assert ds[name].dims == dims
    np.testing.assert_array_equal(ds["q"].values, np.asarray(sol.q))
    np.testing.assert_array_equal(ds["time"].values, np.asarray(sol.t))
    assert "t" not in ds.variables  # the times are the coordinate, not a second copy
    assert list(ds["coordinate"].values) == ["x", "y", "phi", "theta"]
    a = ds.attrs
    assert a["gnipy_version"] == gnipy.__version__
    assert a["model"] == "vertical-disk" and a["method"] == "gni-trapezoid"
    assert a["h"] == 0.1 and a["steps"] == 4 and a["start"] and a["created"]
    assert json.loads(a["params"]) == {"m": 1.0, "r": 2.0}
    assert a["param_r"] == 2.0
    np.testing.assert_array_equal(a["q0"], [0.0, 0.0, 0.0, 1.0])
    assert a["note"] == "hello" and a["flag"] == 1
    assert _leftovers(tmp_path, ["out.nc"]) == []


def test_time_is_the_physical_time_with_cf_attributes(tmp_path):
    """`time` holds t (float64, seconds), so selecting by time selects by time; `node` and `step`
    hold the indices; CF global and variable attributes."""
    sys_ = gnipy.make_system("vertical-disk")
    sol = gnipy.simulate(sys_, "gni-trapezoid", h=0.5, steps=20, save_every=2)
    write_netcdf(sol, tmp_path / "run.nc")
    ds = read_netcdf(tmp_path / "run.nc")
    assert ds["time"].dtype == np.float64
    np.testing.assert_array_equal(ds["time"].values, np.asarray(sol.t))
    node = ds.sel(time=5.0)
    assert float(node["time"]) == 5.0 and int(node["node"]) == 5 and int(node["step"]) == 10
    np.testing.assert_array_equal(node["q"].values, np.asarray(sol.q)[5])  # not the node of t = 1.0
    np.testing.assert_array_equal(ds["node"].values, np.arange(11))
    np.testing.assert_array_equal(ds["step"].values, 2 * np.arange(11))
    assert ds["node"].dtype.kind == "i" and ds["step"].dtype.kind == "i"
    assert ds["time"].attrs == {"standard_name": "time", "long_name": "time", "units": "s", "axis": "T"}
    assert ds["node"].attrs["long_name"] == "saved node index"
    a = ds.attrs
    assert a["Conventions"] == "CF-1.8" and a["source"] == f"gnipy {gnipy.__version__}"
    assert "vertical-disk" in a["title"] and "gni-trapezoid" in a["title"]
    assert a["history"].startswith(a["created"])
    for name in ds.data_vars:
        assert ds[name].attrs["long_name"], name
    assert ds["q"].attrs["components"] == "x, y, phi, theta"
    assert ds["v"].attrs["components"] == ds["p"].attrs["components"] == ", ".join(sys_.velocities)
    assert ds["hidden_momentum"].attrs["units"] == "1" and ds["hidden_momentum_expected"].attrs["units"] == "1"
    assert "units" not in ds["energy"].attrs and "units" not in ds["energy_plus"].attrs
    assert "orientation" not in a  # no group part


def test_batch_dataset_has_the_same_time_coordinate():
    sys_ = gnipy.make_system("vertical-disk")
    spec = gnipy.get_model("vertical-disk")
    q0, v0 = spec.initial_condition(spec.params)
    sol = gnipy.simulate(sys_, "gni-trapezoid", np.stack([q0, q0]), np.stack([v0, v0]), h=0.5, steps=4)
    ds = sol.to_xarray()
    np.testing.assert_array_equal(ds["time"].values, [0.0, 0.5, 1.0, 1.5, 2.0])
    np.testing.assert_array_equal(ds["node"].values, np.arange(5))
    assert ds["q"].sel(time=1.0).dims == ("member", "coordinate")
    assert ds["valid"].attrs["long_name"] and ds.attrs["Conventions"] == "CF-1.8"


def test_the_schema_states_what_the_files_hold(tmp_path):
    """Every variable of a result file and of a batch's dataset is one gnipy.schema states, with
    its dimensions (`member` in front in a batch) and its attributes."""
    from gnipy import schema

    sol = gnipy.simulate(gnipy.make_system("rolling-ball"), "gni-midpoint", h=0.1, steps=4)  # R, diagnostics
    write_netcdf(sol, tmp_path / "run.nc")
    ds = read_netcdf(tmp_path / "run.nc")
    assert {"q", "v", "p", "energy", "constraint_residual", "R", "energy_plus", "hidden_momentum",
            "hidden_momentum_expected", "time", "node", "step", "coordinate", "velocity"} <= set(ds.variables)
    for name in ds.variables:
        assert ds[name].dims == schema.dims(name), name
        assert schema.variable_attrs(name).items() <= ds[name].attrs.items(), name
    assert ds["q"].attrs["long_name"] == "configuration" and ds["R"].attrs["long_name"] == "orientation R (group matrix)"
    assert ds["energy"].attrs["long_name"] == "energy ½vᵀGv + V" and "units" not in ds["energy"].attrs

    spec = gnipy.get_model("vertical-disk")
    q0, v0 = spec.initial_condition(spec.params)
    systems = gnipy.model_systems("vertical-disk", m=np.array([1.0, 2.0]))
    batch = gnipy.simulate(systems, "gni-trapezoid", np.stack([q0, q0]), np.stack([v0, v0]), h=0.5,
                           steps=4).to_xarray()
    assert {"result", "failed_step", "failed_residual", "valid", "param_m", "member"} <= set(batch.variables)
    for name in batch.variables:
        lead = ("member",) if name != "member" and "member" in batch[name].dims else ()
        assert batch[name].dims == schema.dims(name, lead), name
        assert schema.variable_attrs(name).items() <= batch[name].attrs.items(), name
    assert batch["param_m"].attrs["long_name"] == "parameter m"
    assert batch["valid"].attrs["long_name"] == "saved node computed (False after a failed step)"


def test_schema_apply_and_the_names_gnipy_io_shares():
    from gnipy import schema

    ds = xr.Dataset({"q": (("time", "coordinate"), np.zeros((2, 2))), "mine": (("time",), [1.0, 2.0])},
                    coords={"coordinate": ["x", "y"], **schema.time_coordinates([0.0, 0.5], 0.5)})
    ds["q"].attrs["long_name"] = "kept"
    assert schema.apply(ds) is ds
    assert ds["q"].attrs == {"long_name": "kept", "components": "x, y"}  # set attributes are kept
    assert ds["mine"].attrs == {}  # not gnipy's: nothing invented
    assert ds["time"].attrs == {"standard_name": "time", "long_name": "time", "units": "s", "axis": "T"}
    np.testing.assert_array_equal(ds["step"].values, [0, 1])
    assert schema.variable_attrs("valid", sweep=True)["long_name"].endswith("or chunk not done)")
    with pytest.raises(KeyError):
        schema.dims("nope")
    for name in ("VARIABLE_ATTRS", "VARIABLE_UNITS", "TIME_UNITS", "CONVENTIONS", "UNITS_CONVENTION",
                 "time_coordinates"):
        assert getattr(gnipy.io, name) is getattr(schema, name), name


def test_files_of_the_earlier_layout_still_read(tmp_path):
    """A file written when `time` was the node index and the times were a variable `t`: read_netcdf
    and the plots give it the present layout."""
    from gnipy import plots

    old = _solution().to_xarray().drop_vars(["node", "step"])
    t = old["time"].values
    old = old.drop_vars("time").assign(t=(("time",), t, {"long_name": "time", "units": "time units"}))
    old = old.assign_coords(time=np.arange(len(t)))
    old.to_netcdf(tmp_path / "old.nc")
    ds = read_netcdf(tmp_path / "old.nc")
    assert "t" not in ds.variables
    np.testing.assert_array_equal(ds["time"].values, t)
    np.testing.assert_array_equal(ds["node"].values, np.arange(len(t)))
    np.testing.assert_array_equal(ds["step"].values, np.arange(len(t)))  # h = 0.1 in the attributes
    assert ds["time"].attrs["units"] == "time units"  # what the file says
    np.testing.assert_array_equal(ds.sel(time=0.2)["q"].values, old["q"].values[2])
    with xr.open_dataset(tmp_path / "old.nc") as lazy:
        np.testing.assert_array_equal(gnipy.io.result_times(lazy), t)
        plots.plot_energy_error(lazy)


def test_dataset_is_written_with_provenance_added(tmp_path):
    ds = xr.Dataset({"a": (("i",), np.arange(3.0))}, attrs={"model": "mine"})
    write_netcdf(ds, tmp_path / "d.nc", attrs={"extra": {"k": 1}})
    back = read_netcdf(tmp_path / "d.nc")
    assert back.attrs["model"] == "mine" and back.attrs["gnipy_version"] == gnipy.__version__
    assert json.loads(back.attrs["extra"]) == {"k": 1.0}
    assert "gnipy_version" not in ds.attrs  # the caller's dataset is not modified


def test_missing_directory_is_a_clear_oserror(tmp_path):
    path = tmp_path / "no" / "such" / "dir" / "out.nc"
    with pytest.raises(OSError, match="does not exist") as info:
        write_netcdf(_solution(), path)
    assert isinstance(info.value, OutputError) and str(path) in str(info.value)
    assert os.listdir(tmp_path) == []


def test_parent_is_a_file(tmp_path):
    (tmp_path / "file").write_text("x")
    # (the message is the directory check's, or the system's ENOTDIR from looking the path up)
    with pytest.raises(OutputError, match="does not exist|Not a directory") as info:
        write_netcdf(_solution(), tmp_path / "file" / "out.nc")
    assert str(tmp_path / "file" / "out.nc") in str(info.value)


def test_path_is_a_directory(tmp_path):
    (tmp_path / "d.nc").mkdir()
    with pytest.raises(OutputError, match="is a directory"):
        write_netcdf(_solution(), tmp_path / "d.nc")


def test_unwritable_directory(tmp_path, monkeypatch):
    # (tests may run as root, for whom chmod does not deny writes: simulate the check instead)
    monkeypatch.setattr(os, "access", lambda *a, **k: False)
    with pytest.raises(OutputError, match="not writable") as info:
        write_netcdf(_solution(), tmp_path / "out.nc")
    assert str(tmp_path / "out.nc") in str(info.value)
    assert os.listdir(tmp_path) == []


def _failing_after_temp_written(monkeypatch, exc, seen):
    """Make Dataset.to_netcdf write the temporary file completely, then raise `exc`."""
    original = xr.Dataset.to_netcdf

    def to_netcdf(self, path=None, *args, **kwargs):
        original(self, path, *args, **kwargs)
        seen["temp"] = str(path)
        seen["temp_existed"] = os.path.exists(path)
        raise exc

    monkeypatch.setattr(xr.Dataset, "to_netcdf", to_netcdf)


def test_failed_overwrite_keeps_the_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    path = tmp_path / "out.nc"
    write_netcdf(_solution(1.0), path)
    old = read_netcdf(path)
    seen = {}
    _failing_after_temp_written(monkeypatch, RuntimeError("interrupted"), seen)
    with pytest.raises(RuntimeError, match="interrupted"):
        write_netcdf(_solution(7.0), path, overwrite=True)
    # the data went to a temporary file in the same directory, never to the destination
    assert seen["temp_existed"] and os.path.dirname(seen["temp"]) == str(tmp_path)
    assert seen["temp"] != str(path)
    assert _leftovers(tmp_path, ["out.nc"]) == []
    monkeypatch.undo()
    xr.testing.assert_identical(read_netcdf(path), old)


def test_oserror_during_write_is_named_and_cleaned_up(tmp_path, monkeypatch):
    seen = {}
    _failing_after_temp_written(monkeypatch, OSError(errno.ENOSPC, "No space left on device"), seen)
    path = tmp_path / "new.nc"
    with pytest.raises(OutputError, match="No space left") as info:
        write_netcdf(_solution(), path)
    assert str(path) in str(info.value)
    assert os.listdir(tmp_path) == []  # neither the destination nor the temporary file


def test_successful_overwrite_replaces_content_with_usual_permissions(tmp_path):
    path = tmp_path / "out.nc"
    write_netcdf(_solution(1.0), path)
    write_netcdf(_solution(3.0), path, overwrite=True)
    np.testing.assert_array_equal(read_netcdf(path)["q"].values, np.asarray(_solution(3.0).q))
    assert _leftovers(tmp_path, ["out.nc"]) == []
    (tmp_path / "plain").write_text("")  # what the umask gives an ordinary new file
    assert os.stat(path).st_mode & 0o777 == os.stat(tmp_path / "plain").st_mode & 0o777


def test_read_errors_name_the_path(tmp_path):
    with pytest.raises(OutputError, match="no such file") as info:
        read_netcdf(tmp_path / "missing.nc")
    assert "missing.nc" in str(info.value)
    (tmp_path / "junk.nc").write_text("not netcdf")
    with pytest.raises(OutputError, match="not a netCDF file"):
        read_netcdf(tmp_path / "junk.nc")


def test_rejects_other_objects(tmp_path):
    with pytest.raises(TypeError):
        write_netcdf({"q": 1}, tmp_path / "x.nc")
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------------------------------------------
# What may be replaced (gnipy.files.check_destination) and the data checksum (verify_netcdf)
# ------------------------------------------------------------------------------------------------
def test_existing_file_is_refused_without_overwrite(tmp_path):
    path = tmp_path / "out.nc"
    path.write_bytes(b"someone's data")
    with pytest.raises(OutputError, match="exists") as info:
        write_netcdf(_solution(), path)
    assert str(path) in str(info.value) and "overwrite" in str(info.value)
    assert path.read_bytes() == b"someone's data"  # untouched
    assert _leftovers(tmp_path, ["out.nc"]) == []
    write_netcdf(_solution(), path, overwrite=True)  # replacing is asked for: done
    assert read_netcdf(path)["q"].shape == (5, 4)


@pytest.mark.parametrize("kind", ["symlink", "dangling-symlink", "fifo"])
def test_links_and_special_files_are_refused_even_with_overwrite(tmp_path, kind):
    target = tmp_path / "target.txt"
    target.write_bytes(b"precious")
    path = tmp_path / "out.nc"
    if kind == "symlink":
        path.symlink_to(target)
    elif kind == "dangling-symlink":
        path.symlink_to(tmp_path / "nowhere.nc")
    else:
        os.mkfifo(path)  # opening it would block: it must not even be opened
    for overwrite in (False, True):
        with pytest.raises(OutputError, match="symbolic link|FIFO") as info:
            write_netcdf(_solution(), path, overwrite=overwrite)
        assert str(path) in str(info.value)
    assert target.read_bytes() == b"precious"
    assert os.path.islink(path) == (kind != "fifo")
    assert not (tmp_path / "nowhere.nc").exists()
    assert _leftovers(tmp_path, ["out.nc", "target.txt"]) == []


def test_verify_netcdf_detects_an_edited_value(tmp_path):
    import netCDF4

    from gnipy.io import CHECKSUM_ATTR, verify_netcdf

    path = tmp_path / "out.nc"
    write_netcdf(_solution(), path)
    ok, message = verify_netcdf(path)
    assert ok and "ok" in message and str(path) in message
    assert read_netcdf(path).attrs[CHECKSUM_ATTR].startswith("sha256:")
    with netCDF4.Dataset(path, "a") as nc:  # one value changed in place, attributes untouched
        nc.variables["q"][2, 1] = nc.variables["q"][2, 1] + 1e-12
    ok, message = verify_netcdf(path)
    assert not ok and "DAMAGED" in message and str(path) in message


def test_verify_netcdf_without_a_checksum_and_on_unreadable_files(tmp_path):
    from gnipy.io import verify_netcdf

    _solution().to_xarray().to_netcdf(tmp_path / "plain.nc")  # not written by write_netcdf
    ok, message = verify_netcdf(tmp_path / "plain.nc")
    assert not ok and "gnipy_checksum" in message
    (tmp_path / "junk.nc").write_text("not netcdf")
    with pytest.raises(OutputError, match="junk.nc"):
        verify_netcdf(tmp_path / "junk.nc")
    with pytest.raises(OutputError, match="no such file"):
        verify_netcdf(tmp_path / "missing.nc")
