"""The verdicts from every node (gnipy.monitor), adversarially: runs built to fail a verdict
between two saved nodes, at several strides and on both backends; the Chaplygin sleigh's recurrent
failure that saved nodes miss; batches judged member by member; loud failures (warning, health
flag, strict mode); continued runs.

Every expectation comes from an independent formulation: the node-by-node verdicts of
:mod:`gnipy.diagnostics` applied to a run that saves every node, or a blip placed at a known step.
"""

from __future__ import annotations

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gnipy
from gnipy import monitor
from gnipy.diagnostics import energy_verdict, hidden_momentum_verdict
from gnipy.integrators.base import Integrator
from gnipy.methods import get_method


class Blip(Integrator):
    """A healthy method whose *reported* node `k0` (and only it) is out of band: its hidden
    momentum multiplied into `hidden` (size relative to |p̄|) and its reported velocity and
    momentum scaled by `scale` (an energy excursion). The motion itself is untouched, so a verdict
    that reads saved nodes misses it unless node k0 is saved."""

    base: Integrator
    k0: int
    hidden: jnp.ndarray  # arrays: every blip shares one compiled program
    scale: jnp.ndarray
    name = "blip"

    def __init__(self, base, k0, hidden=0.0, scale=1.0):
        self.base, self.k0 = base, k0
        self.hidden, self.scale = jnp.asarray(hidden, jnp.float64), jnp.asarray(scale, jnp.float64)

    def check(self, system, q0):
        self.base.check(system, q0)

    def prepare(self, system, q0):
        return Blip(self.base.prepare(system, q0), self.k0, self.hidden, self.scale)

    def init(self, system, q0, v0, h):
        return (self.base.init(system, q0, v0, h), jnp.asarray(0.0))

    def step(self, system, state, h):
        new, info = self.base.step(system, state[0], h)
        return (new, state[1] + 1.0), info

    def _at_k0(self, state):
        return state[1] == float(self.k0)

    def observe(self, system, state, h):
        b, v, p = self.base.observe(system, state[0], h)
        f = jnp.where(self._at_k0(state), self.scale, 1.0)
        return b, f * v, f * p

    def hidden_momentum(self, system, state, h):
        x = self.base.hidden_momentum(system, state[0], h)
        if x is None:
            return None
        _, _, p = self.base.observe(system, state[0], h)
        return x + jnp.where(self._at_k0(state), self.hidden, 0.0) * p


H, STEPS, K0 = 0.05, 300, 101


@pytest.fixture(scope="module")
def disk():
    return gnipy.make_system("vertical-disk")


def _node_verdicts(system, method, stride_one_backend="xla"):
    """The verdicts the node-by-node rules of gnipy.diagnostics give on a run saving every node."""
    sol = gnipy.simulate(system, method, h=H, steps=STEPS, backend=stride_one_backend)
    kinetic = 0.5 * np.sum(np.asarray(sol.v) * np.asarray(sol.p), axis=-1)
    hidden = (hidden_momentum_verdict(sol.t, sol.hidden_momentum, sol.hidden_expected, H)
              if sol.hidden_momentum is not None else None)
    return hidden, energy_verdict(sol.t, sol.energy, kinetic), sol


@pytest.mark.parametrize("backend", ["xla", "native"])
@pytest.mark.parametrize("kind", ["hidden", "energy"])
def test_a_blip_between_saved_nodes_is_caught_at_its_step(disk, backend, kind):
    """A one-node excursion at step 101: every save that skips it warns at t = 101 h, as the
    every-node run does, on both backends; the saved nodes alone would call the run healthy."""
    method = Blip(get_method("gni-trapezoid"), K0, hidden=5.0 if kind == "hidden" else 0.0,
                  scale=3.0 if kind == "energy" else 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)
        every_hidden, every_energy, every = _node_verdicts(disk, method)
    expected = every_hidden if kind == "hidden" else every_energy
    assert not expected.in_band and expected.first_time == pytest.approx(K0 * H, abs=1e-12)
    assert not every.healthy
    # three saved nodes each (one compiled program): the first, one a stride of 7, 10, 13 or 50
    # steps from the blip's step on either side, and the last
    for k in (7 * 14, 10 * 10, 13 * 8, 3 * 50):
        saveat = gnipy.SaveAt(ts=(0.0, k * H, STEPS * H))
        with pytest.warns(gnipy.QualitativeFailureWarning, match=rf"t = {K0 * H:g}"):
            sol = gnipy.simulate(disk, method, h=H, steps=STEPS, saveat=saveat, backend=backend)
        assert sol.backend == backend
        k = np.rint(np.asarray(sol.t) / H).astype(int)
        assert K0 not in k  # the blip is never saved
        got = sol.hidden_verdict if kind == "hidden" else sol.energy_verdict
        assert not got.in_band and got.first_time == pytest.approx(expected.first_time, abs=1e-12)
        assert not sol.healthy and sol.success
        # what the saved nodes alone say: in band (the defect the monitor fixes)
        kinetic = 0.5 * np.sum(np.asarray(sol.v) * np.asarray(sol.p), axis=-1)
        saved_only = (hidden_momentum_verdict(sol.t, sol.hidden_momentum, sol.hidden_expected, H) if kind == "hidden"
                      else energy_verdict(sol.t, sol.energy, kinetic))
        assert saved_only.in_band


@pytest.mark.parametrize("backend", ["xla", "native"])
def test_no_blip_no_verdict(disk, backend):
    """The same wrapper without a blip: in band on both verdicts at every stride, no warning, and
    the largest ratios equal those of the every-node run."""
    method = Blip(get_method("gni-trapezoid"), K0)
    every_hidden, every_energy, _ = _node_verdicts(disk, method)
    assert every_hidden.in_band and every_energy.in_band
    for saveat in (gnipy.SaveAt(ts=(0.0, 100 * H, STEPS * H)), gnipy.SaveAt(ts=(0.0, 150 * H, STEPS * H))):
        with warnings.catch_warnings():
            warnings.simplefilter("error", gnipy.QualitativeFailureWarning)
            sol = gnipy.simulate(disk, method, h=H, steps=STEPS, saveat=saveat, backend=backend)
        assert sol.healthy and sol.hidden_verdict.in_band and sol.energy_verdict.in_band
        assert sol.hidden_verdict.max_ratio == pytest.approx(every_hidden.max_ratio, rel=1e-9)
        assert sol.energy_verdict.max_drift == pytest.approx(every_energy.max_drift, rel=1e-6, abs=1e-15)
        assert monitor.nodes_seen(sol.monitor) == STEPS + 1


# -- the Chaplygin sleigh: a recurrent failure that strided saves used to miss -----------------------
SLEIGH_STRIDES = (4100, 5500, 6000, 7200, 8200, 8300)


def _strided(stride: int, steps: int, h: float):
    """Four saved nodes a stride apart (the run's end where 3 strides overshoot it): one compiled
    program for every stride."""
    ts = [k * stride * h for k in range(4)]
    if 3 * stride > steps:
        ts = [0.0, stride * h, 2 * stride * h, steps * h]
    return gnipy.SaveAt(ts=tuple(ts))


@pytest.mark.parametrize("start,strides", [("consistent", SLEIGH_STRIDES), ("rest", (2500, 4900, 7300, 9800))])
def test_sleigh_warns_at_every_stride_when_every_node_does(start, strides):
    """gni-trapezoid on the sleigh, h = 0.01, T = 200, at the strides an outside test found
    silent: each warns, at the time the every-node run gives."""
    from gnipy.discrete_lagrangians import Trapezoid
    from gnipy.integrators.gni import GNI

    system = gnipy.make_system("chaplygin-sleigh")
    method = GNI(Trapezoid(), start=start)
    h, steps = 0.01, 20000
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)
        every_hidden, every_energy, _ = _node_verdicts_at(system, method, h, steps)
    assert not every_hidden.in_band
    for stride in strides:
        with pytest.warns(gnipy.QualitativeFailureWarning, match="hidden momentum"):
            sol = gnipy.simulate(system, method, h=h, steps=steps, saveat=_strided(stride, steps, h), backend="xla")
        assert sol.hidden_verdict.first_time == pytest.approx(every_hidden.first_time, abs=1e-9)
        assert sol.energy_verdict.in_band == every_energy.in_band
        assert sol.to_xarray().attrs["health"] == "qualitatively wrong"


def _node_verdicts_at(system, method, h, steps):
    sol = gnipy.simulate(system, method, h=h, steps=steps, backend="xla")
    kinetic = 0.5 * np.sum(np.asarray(sol.v) * np.asarray(sol.p), axis=-1)
    return (hidden_momentum_verdict(sol.t, sol.hidden_momentum, sol.hidden_expected, h),
            energy_verdict(sol.t, sol.energy, kinetic), sol)


def test_sleigh_long_run_and_native_backend_agree():
    """T = 1000 at the strides 6100-6300, on the native backend: out of band at the time the XLA
    loop's every-node monitor gives for the same run."""
    system = gnipy.make_system("chaplygin-sleigh")
    h, steps = 0.01, 100_000
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)
        first = gnipy.simulate(system, "gni-trapezoid", h=h, steps=steps, save_every=steps, backend="xla")
        for stride in (6100, 6200, 6300):
            sol = gnipy.simulate(system, "gni-trapezoid", h=h, steps=steps, saveat=_strided(stride, steps, h),
                                 backend="native")
            assert sol.backend == "native" and not sol.healthy
            assert sol.hidden_verdict.first_time == pytest.approx(first.hidden_verdict.first_time, abs=1e-9)


# -- loud -------------------------------------------------------------------------------------------
def test_strict_raises_and_the_summary_leads_with_health(disk):
    method = Blip(get_method("gni-trapezoid"), K0, hidden=5.0)
    with pytest.raises(gnipy.QualitativeFailure) as e:
        gnipy.simulate(disk, method, h=H, steps=STEPS, save_every=STEPS, throw="strict")
    assert e.value.time == pytest.approx(K0 * H) and e.value.solution is not None
    assert not e.value.solution.healthy and e.value.solution.success
    with pytest.warns(gnipy.QualitativeFailureWarning):
        sol = gnipy.simulate(disk, method, h=H, steps=STEPS, save_every=STEPS)
    lines = sol.summary().splitlines()
    assert lines[1].startswith("  health: QUALITATIVELY WRONG") and f"t = {K0 * H:g}" in lines[1]
    html = sol._repr_html_()
    assert html.index("health") < html.index("result") and "QUALITATIVELY WRONG" in html
    with pytest.raises(gnipy.InputError, match="throw"):
        gnipy.simulate(disk, method, h=H, steps=3, throw="yes")


def test_continued_runs_carry_the_verdicts(disk):
    """Two calls continued with monitor0 give the verdicts of one call; without it the second
    call alone does not know of the blip in the first."""
    method = Blip(get_method("gni-trapezoid"), K0, hidden=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)
        whole = gnipy.simulate(disk, method, h=H, steps=STEPS, save_every=STEPS)
        a = gnipy.simulate(disk, method, h=H, steps=150, save_every=150)
        b = gnipy.simulate(disk, method, h=H, steps=150, save_every=150, state0=a.final_state, t0=float(a.t[-1]),
                           monitor0=a.monitor)
        c = gnipy.simulate(disk, method, h=H, steps=150, save_every=150, state0=a.final_state, t0=float(a.t[-1]))
    assert b.hidden_verdict.first_time == pytest.approx(whole.hidden_verdict.first_time)
    assert b.hidden_verdict.max_ratio == pytest.approx(whole.hidden_verdict.max_ratio, rel=1e-12)
    assert c.hidden_verdict.in_band
    with pytest.raises(gnipy.InputError, match="monitor0"):
        gnipy.simulate(disk, method, h=H, steps=3, monitor0=a.monitor)


# -- per member ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, -1])
def test_readme_ensemble_members_have_their_own_labels(order):
    """The README's ensemble, in both orders: the Ω = 0 member conserves its energy (linear
    constraints), the Ω = 1 member does not (affine), and no member is called wrong."""
    omegas = np.linspace(0, 1, 50)[::order]
    systems = gnipy.model_systems("rolling-ball", Omega=omegas)
    with warnings.catch_warnings():
        warnings.simplefilter("error", gnipy.QualitativeFailureWarning)
        ens = gnipy.simulate(systems, "gni-trapezoid", h=0.01, steps=1000, save_every=100)
    assert ens.healthy and not ens.warnings()
    for i in range(50):
        m = ens.member(i)
        assert m.healthy and not m.warnings()
        if omegas[i] == 0.0:
            assert m.energy_invariant and m.energy_verdict is not None and "energy" in m.conserved
        else:
            assert not m.energy_invariant and m.energy_verdict is None and m.conserved.startswith("affine")
    assert "WARNING" not in ens.member(int(np.argmax(omegas))).summary()


def test_batch_flags_only_the_failing_members(disk):
    """A batch of initial conditions where the blip hits every member: each member's own
    verdict; and a batch of parameter values mixing a failing and a healthy sleigh."""
    method = Blip(get_method("gni-trapezoid"), K0, hidden=5.0)
    q0 = np.tile(np.asarray(disk.defaults[0], float), (3, 1))
    v0 = np.tile(np.asarray(disk.defaults[1], float), (3, 1))
    with pytest.warns(gnipy.QualitativeFailureWarning, match="3 of 3 members"):
        sol = gnipy.simulate(disk, method, q0, v0, h=H, steps=STEPS, save_every=STEPS)
    assert [sol.member(i).hidden_verdict.first_time for i in range(3)] == pytest.approx([K0 * H] * 3)
    healthy = Blip(get_method("gni-trapezoid"), K0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", gnipy.QualitativeFailureWarning)
        ok = gnipy.simulate(disk, healthy, q0, v0, h=H, steps=STEPS, save_every=STEPS)
    assert ok.healthy and all(ok.member(i).healthy for i in range(3))


# -- files, streams, sweeps: the verdicts and the labels read back ----------------------------------
def test_labels_say_what_ran(disk, tmp_path):
    """start, backend and the method's parameters: in the Solution and in its file."""
    import json

    from gnipy.discrete_lagrangians import Midpoint
    from gnipy.integrators.gni import GNI

    for method, start in ((GNI(Midpoint()), "consistent: p+ = G v0 - (h/2) mu^T lambda0"),
                          (GNI(Midpoint(), start="rest"), "rest: p+ = G v0 (no hidden impulse)"),
                          ("sgni-midpoint", "p = G v0 projected onto the constraints (no hidden impulse)"),
                          ("mp", "(q0, v0) as given")):
        sol = gnipy.simulate(disk, method, h=H, steps=20, save_every=20, backend="xla")
        assert sol.start == start and sol.backend == "xla"
        settings = dict(sol.method_settings)
        path = tmp_path / f"{sol.method}-{len(start)}.nc"
        gnipy.write_netcdf(sol, path)
        ds = gnipy.read_netcdf(path)
        assert ds.attrs["start"] == start and ds.attrs["backend"] == "xla" and ds.attrs["health"] == "healthy"
        assert json.loads(ds.attrs["method_settings"]) == settings
        if sol.method.startswith("gni"):
            assert settings["discrete_lagrangian"] == "Midpoint" and settings["start"] in start
            assert settings["explicit"] in (True, False)  # the prepared method's choice, not "default"


def test_streamed_run_carries_the_verdicts_and_labels(tmp_path):
    """A streamed sleigh run (chunks of 8200 steps, a node every 4100): the file's verdicts are
    those of one in-memory run, its health attribute says so, one warning, and a resumed run
    continues the monitor from the last part."""
    system = gnipy.make_system("chaplygin-sleigh")
    h, steps = 0.01, 20000
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gnipy.QualitativeFailureWarning)
        whole = gnipy.simulate(system, "gni-trapezoid", h=h, steps=steps, save_every=steps)
    with pytest.warns(gnipy.QualitativeFailureWarning, match="QUALITATIVELY WRONG"):
        res = gnipy.simulate_to_file(system, path=tmp_path / "a.nc", method="gni-trapezoid", h=h, steps=steps,
                                     save_every=4100, chunk_steps=8200)
    assert not res.healthy and res.result == 0
    ds = gnipy.read_netcdf(tmp_path / "a.nc")
    assert ds.attrs["health"] == "qualitatively wrong"
    assert ds.attrs["hidden_momentum_first_time"] == pytest.approx(whole.hidden_verdict.first_time, abs=1e-9)
    assert ds.attrs["start"].startswith("consistent") and ds.attrs["backend"] in ("xla", "native")
    # interrupted after one chunk, resumed: the same verdicts
    gnipy.simulate_to_file(system, path=tmp_path / "b.nc", method="gni-trapezoid", h=h, steps=steps,
                           save_every=4100, chunk_steps=8200, stop_after_chunks=1)
    with pytest.warns(gnipy.QualitativeFailureWarning):
        gnipy.simulate_to_file(system, path=tmp_path / "b.nc", method="gni-trapezoid", h=h, steps=steps,
                               save_every=4100, chunk_steps=8200, resume=True)
    db = gnipy.read_netcdf(tmp_path / "b.nc")
    assert db.attrs["hidden_momentum_first_time"] == ds.attrs["hidden_momentum_first_time"]
    assert db.attrs["energy_drift_first_time"] == ds.attrs["energy_drift_first_time"]


def test_checking_only_the_saved_nodes_is_asked_for_and_said(disk):
    """check_every_node=False (XLA): the blip between saved nodes is missed, as documented, and
    the health says that only the saved nodes were checked; a saved blip is still caught."""
    method = Blip(get_method("gni-trapezoid"), K0, hidden=5.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", gnipy.QualitativeFailureWarning)
        sol = gnipy.simulate(disk, method, h=H, steps=STEPS, saveat=gnipy.SaveAt(ts=(0.0, 100 * H, STEPS * H)),
                             backend="xla", check_every_node=False)
    assert sol.monitor is None and sol.healthy and "saved nodes checked" in sol.health
    with pytest.warns(gnipy.QualitativeFailureWarning):
        seen = gnipy.simulate(disk, method, h=H, steps=STEPS, saveat=gnipy.SaveAt(ts=(0.0, K0 * H, STEPS * H)),
                              backend="xla", check_every_node=False)
    assert seen.hidden_verdict.first_time == pytest.approx(K0 * H)
