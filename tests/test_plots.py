"""gnipy.plots: what each figure draws, from a Solution or from a file read back (no compilation:
hand-made solutions)."""

import dataclasses

import numpy as np
import pytest
import xarray as xr

import gnipy
from gnipy import plots
from gnipy.io import write_netcdf

PNG = b"\x89PNG\r\n\x1a\n"


def _solution(n=4, coords=("x", "y", "phi", "theta"), R=None, T=21, residual=None):
    t = np.linspace(0.0, 2.0, T)
    q = np.stack([np.cos(t) * (i + 1) for i in range(n)], axis=1) if n else np.zeros((T, 0))
    N = max(n, 3)
    v = np.ones((T, N))
    energy = 1.0 + 1e-3 * np.sin(t)
    res = np.zeros((T, 2)) if residual is None else residual
    return gnipy.Solution(t, q, v, v, energy, res, np.array([0, 0], dtype=np.int32), R=R,
                          system="test-model", method="gni-trapezoid", h=0.1, coordinates=tuple(coords[:n]))


def _line(ax, i=0):
    x, y = ax.lines[i].get_data()
    return np.asarray(x), np.asarray(y)


def test_path_on_Rn_plots_the_first_two_coordinates():
    sol = _solution()
    ax = plots.plot_path(sol)
    x, y = _line(ax)
    np.testing.assert_array_equal(x, np.asarray(sol.q[:, 0]))
    np.testing.assert_array_equal(y, np.asarray(sol.q[:, 1]))
    assert ax.get_xlabel() == "x" and ax.get_ylabel() == "y" and ax.get_aspect() == 1.0
    assert "test-model" in ax.get_title()


def test_path_with_one_coordinate_is_against_time():
    sol = _solution(n=1, coords=("s",))
    x, y = _line(plots.plot_path(sol))
    np.testing.assert_array_equal(x, np.asarray(sol.t))
    np.testing.assert_array_equal(y, np.asarray(sol.q[:, 0]))


def test_path_on_se2_is_the_position():
    T = 21
    th = np.linspace(0, 1, T)
    R = np.zeros((T, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = np.cos(th), -np.sin(th), np.sin(th), np.cos(th)
    R[:, 0, 2], R[:, 1, 2], R[:, 2, 2] = 2 * th, th**2, 1.0
    x, y = _line(plots.plot_path(_solution(n=0, R=R)))
    np.testing.assert_array_equal(x, 2 * th)
    np.testing.assert_array_equal(y, th**2)


def test_path_on_so3_is_the_body_axis():
    T = 21
    a = np.linspace(0, 1, T)
    R = np.zeros((T, 3, 3))  # rotations about the x axis: R e3 = (0, -sin a, cos a)
    R[:, 0, 0], R[:, 1, 1], R[:, 1, 2], R[:, 2, 1], R[:, 2, 2] = 1, np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
    x, y = _line(plots.plot_path(_solution(n=0, R=R)))
    np.testing.assert_array_equal(x, np.zeros(T))
    np.testing.assert_array_equal(y, -np.sin(a))


def test_energy_error_and_constraint_residual():
    T = 21
    res = np.zeros((T, 2))
    res[5:, 0], res[5:, 1] = 1e-14, -3e-14
    sol = _solution(residual=res)
    t, de = _line(plots.plot_energy_error(sol))
    np.testing.assert_array_equal(t, np.asarray(sol.t))
    np.testing.assert_allclose(de, np.asarray(sol.energy) - float(sol.energy[0]), rtol=0, atol=0)
    ax = plots.plot_constraint_residual(sol)
    _, r = _line(ax)
    assert ax.get_yscale() == "log"
    np.testing.assert_array_equal(r[:5], 1e-18)  # exact zeros drawn at the floor
    np.testing.assert_array_equal(r[5:], 3e-14)  # the largest |component|


def test_plot_solution_from_a_file_read_back(tmp_path):
    sol = _solution()
    write_netcdf(sol, tmp_path / "run.nc")
    with xr.open_dataset(tmp_path / "run.nc") as ds:
        fig = plots.plot_solution(ds, tmp_path / "run.png")
    assert len(fig.axes) == 3 and (tmp_path / "run.png").read_bytes()[:8] == PNG
    assert "test-model" in fig._suptitle.get_text() and "h = 0.1" in fig._suptitle.get_text()
    # the same figure data as from the Solution itself
    fig2 = plots.plot_solution(sol)
    for a, b in zip(fig.axes, fig2.axes):
        np.testing.assert_array_equal(_line(a)[1], _line(b)[1])
    fig.savefig(tmp_path / "run.svg")  # other formats by suffix
    assert (tmp_path / "run.svg").stat().st_size > 1000


def _gni_solution(out_at=None):
    """A hand-made GNI-family run (T = 21 nodes, h = 0.1): hidden momentum 1e-3 of |p̄| with an
    expected size 1e-3, except from `out_at` on, where it is 100 times its band."""
    sol = _solution()
    t = np.asarray(sol.t)
    e = np.full_like(t, 1e-3)
    r = np.where(t >= out_at, 0.5, 1e-3) if out_at is not None else e.copy()
    return dataclasses.replace(sol, hidden_momentum=r, hidden_expected=e, energy_plus=np.asarray(sol.energy))


def _texts_inside(fig) -> None:
    """Every axis label and title of `fig` lies within the figure once drawn (none cut at an edge)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    W, H = fig.bbox.width, fig.bbox.height
    for ax in fig.axes:
        for text in (ax.xaxis.label, ax.yaxis.label, ax.title):
            if text.get_text():
                bb = text.get_window_extent(canvas.get_renderer())
                assert bb.x0 >= 0 and bb.y0 >= 0 and bb.x1 <= W and bb.y1 <= H, (text.get_text(), bb)


def test_plot_solution_shows_the_hidden_momentum_and_when_the_warning_fired(tmp_path):
    """For the GNI family a fourth panel: r with its O(h) band (log scale, labelled); the time the
    verdict went out of band (t = 1.0 by construction) marked on every panel against time and named
    in the title. A healthy run has neither mark nor title note."""
    import warnings

    sol = _gni_solution(out_at=1.0)
    assert sol.hidden_verdict.first_time == pytest.approx(1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fig = plots.plot_solution(sol, tmp_path / "gni.png")
    assert len(fig.axes) == 4 and (tmp_path / "gni.png").read_bytes()[:8] == PNG
    hidden = fig.axes[3]
    assert hidden.get_yscale() == "log" and hidden.get_ylabel() == "|p⁺ − p̄| / |p̄|"
    assert [t.get_text() for t in hidden.get_legend().get_texts()] == ["|p⁺ − p̄| / |p̄|", "its O(h) band"]
    np.testing.assert_array_equal(_line(hidden)[1], np.asarray(sol.hidden_momentum))
    for ax in fig.axes[1:]:  # the energy, the residual, the hidden momentum: against time
        marks = [line for line in ax.lines if np.all(np.asarray(line.get_xdata()) == 1.0)]
        assert len(marks) == 1, ax.get_title()
    assert "QUALITATIVELY WRONG from t = 1 " in fig._suptitle.get_text()
    assert any("hidden momentum out of band, t = 1" in t.get_text() for t in fig.axes[1].texts)
    _texts_inside(fig)
    healthy = plots.plot_solution(_gni_solution())
    assert len(healthy.axes) == 4 and "WRONG" not in healthy._suptitle.get_text()
    assert not any(np.all(np.asarray(line.get_xdata()) == 1.0) for ax in healthy.axes[1:] for line in ax.lines)
    assert len(plots.plot_solution(_solution()).axes) == 3  # no hidden momentum: three panels
    with pytest.raises(ValueError, match="only the GNI family"):
        plots.plot_hidden_momentum(_solution())


def test_hidden_momentum_panel_of_a_run_from_rest_and_of_a_nan():
    """r = e = inf at a node at rest under a force is not judged: a gap, not a point at 1e300 that
    would flatten the axis; a NaN ratio (out of band) is marked at the top."""
    sol = _gni_solution()
    r, e = np.asarray(sol.hidden_momentum).copy(), np.asarray(sol.hidden_expected).copy()
    r[0] = e[0] = np.inf
    ax = plots.plot_hidden_momentum(dataclasses.replace(sol, hidden_momentum=r, hidden_expected=e))
    y = _line(ax)[1]
    assert np.isnan(y[0]) and np.all(y[1:] == 1e-3) and ax.get_ylim()[1] < 1.0
    r[0], e[0] = np.nan, 1e-3
    ax = plots.plot_hidden_momentum(dataclasses.replace(sol, hidden_momentum=r, hidden_expected=e))
    marks = [line for line in ax.lines if line.get_label() == "infinite or NaN (out of band)"]
    assert len(marks) == 1 and list(marks[0].get_xdata()) == [0.0] and ax.get_ylim()[1] < 1.0


def test_plot_control_labels_stay_inside_the_figure():
    """The path's y label was cut at the left edge (equal scales applied after the layout) and the
    velocities had no y label; the angle turned is drawn on R^n x G only (the help says so)."""
    sol = _solution(n=3, coords=("x", "y", "theta"))
    t = np.asarray(sol.t)  # the sleigh's path of the control guide: x 0 .. 1, y 0 .. 0.65
    sol = dataclasses.replace(sol, q=np.stack([t / 2, 0.65 * np.sin(t * 1.2), t], axis=1))
    ds = sol.to_xarray()
    ds["u"] = xr.DataArray(np.ones((20, 1)), dims=("control_step", "input"))
    ds = ds.assign_coords(input=["torque"])
    fig = plots.plot_control(ds)
    assert [ax.get_ylabel() for ax in fig.axes] == ["y", "input", "velocity"]
    _texts_inside(fig)


def test_convergence_guides_are_told_apart():
    h = 1.0 / 2.0 ** np.arange(3, 7)
    fig = plots.plot_convergence(h, {"a": h, "b": h**2}, guides=(1, 2))
    ax = fig.axes[0]
    guides = [line for line in ax.lines if line.get_label().startswith("$O(h")]
    assert len(guides) == 2 and guides[0].get_linestyle() != guides[1].get_linestyle()
    assert guides[0].get_color() != guides[1].get_color()
    assert sorted(t.get_text() for t in ax.texts) == ["$h^{1}$", "$h^{2}$"]  # each named at its end


def test_rejects_other_objects():
    with pytest.raises(TypeError):
        plots.plot_path({"q": 1})
    with pytest.raises(ValueError, match="'time'"):
        plots.plot_energy_error(xr.Dataset({"a": ("i", [1.0])}))


def test_fitted_order():
    h = 1.0 / 2.0 ** np.arange(3, 8)
    assert plots.fitted_order(h, 3 * h**2) == pytest.approx(2.0, abs=1e-12)
    # round-off plateau and failures are left out
    err = np.maximum(5 * h**3, 1e-13)
    err[0] = np.nan
    assert plots.fitted_order(h, err) == pytest.approx(3.0, abs=1e-12)
    assert np.isnan(plots.fitted_order(h, np.full_like(h, 1e-14)))
    assert np.isnan(plots.fitted_order(h[:1], h[:1]))


def test_fitted_order_options():
    h = 1.0 / 2.0 ** np.arange(3, 9)
    # truncation error 2h² until h = 2⁻⁶, then round-off growing as h shrinks (1e-9/h): the slope
    # over all points is spoiled, the one that stops at the smallest error is the order
    err = 2 * h**2
    err[-2:] = 2 * h[-3] ** 2 * np.array([2.0, 4.0])
    assert plots.fitted_order(h, err) < 1.5
    assert plots.fitted_order(h, err, stop_at_minimum=True) == pytest.approx(2.0, abs=1e-12)
    # the fewest points: two clean points give the order unless three are asked for
    assert plots.fitted_order(h[:2], 2 * h[:2] ** 2) == pytest.approx(2.0, abs=1e-12)
    assert np.isnan(plots.fitted_order(h[:2], 2 * h[:2] ** 2, min_points=3))


def test_plot_convergence_legend_has_the_fitted_slopes(tmp_path):
    h = 1.0 / 2.0 ** np.arange(3, 8)
    errors = {"first": 0.5 * h, "second": 2 * h**2, "exact": np.zeros_like(h)}
    fig = plots.plot_convergence(h, errors, tmp_path / "conv.png", guides=(1, 2))
    assert (tmp_path / "conv.png").read_bytes()[:8] == PNG
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "first (slope 1.00)" in labels and "second (slope 2.00)" in labels and "exact (no fit)" in labels
    assert sum("O(h" in label for label in labels) == 2
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    # one h per method
    fig = plots.plot_convergence({"a": h, "b": h[:3]}, {"a": h, "b": h[:3] ** 2}, guides=())
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["a (slope 1.00)", "b (slope 2.00)"]
    with pytest.raises(ValueError, match="'a'"):
        plots.plot_convergence(h, {"a": h[:2]})
