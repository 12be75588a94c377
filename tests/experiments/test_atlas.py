"""The method atlas (`gni atlas`, gnipy.experiments.atlas and atlas_report): one tiny atlas, two
models × three methods with short horizons, shared by the tests; properties, not numbers: the
report holds every measured pair, the recommendation follows the rule on the measured numbers,
reversibility is round-off for a symmetric method and not measured for a non-symmetric one, the discrete
gradient keeps the energy to round-off where the constraints have no affine part.

Sharing compiled programs: the particle is measured by the quick atlas's own plan
(`plan("nonholonomic-particle", quick=True)`), so `gni atlas --quick` on the particle with two of the
module's methods (test_gni_atlas_quick_cli) runs the CLI end to end on the programs the module's
atlas compiled, instead of compiling a third model (it ran vertical-disk with gni-midpoint and mp:
11.4 s). What the CLI test proves is unchanged: the command writes atlas.md, atlas.html and the
ownership marker, lists the methods asked for and says the mode is quick. The sleigh keeps its own
plan (T = 30, where the GNI's hidden momentum leaves its band). File time, summed test time on the
shared 2-core machine (noisy): 37.9 s (full-suite run) -> 27.0 s."""

import ast
import math
import re

import pytest
from typer.testing import CliRunner

import gnipy
from gnipy.cli import app
from gnipy.experiments.atlas import Plan, plan, run_atlas
from gnipy.experiments.atlas_report import (FIGURES, PAIR_HEADER, default_methods_source, from_json, pair_row, to_json,
                                           write_atlas)
from gnipy.experiments.method_choice import INVARIANT_TOL, REFERENCE_FLOOR, MethodMeasurement, choose
from gnipy.models.default_methods import DEFAULT_METHODS

MODELS = ["nonholonomic-particle", "chaplygin-sleigh"]  # linear constraints; the GNI's hidden momentum fails
METHODS = ["gni-trapezoid", "gni-euler-a", "discrete-gradient"]  # symmetric, not symmetric, energy-conserving
# the particle runs by the quick atlas's plan (2000 steps, h = 0.01, the reference to T = 20), so
# that `gni atlas --quick` on it (test_gni_atlas_quick_cli) reuses the programs compiled here
PLAN = plan("nonholonomic-particle", quick=True)
# the sleigh runs to T = 30: from the default consistent start the GNI's hidden momentum leaves its
# band at t ≈ 22 (from rest at t ≈ 3; the methods guide)
PLANS = {"nonholonomic-particle": PLAN, "chaplygin-sleigh": Plan(steps=3000, t_ref=3.0, long_nodes=30)}


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    result = run_atlas(models=MODELS, methods=METHODS, plans=PLANS)
    report = write_atlas(tmp_path_factory.mktemp("atlas"), result)
    return result, report


def test_report_files_hold_every_measured_pair(tiny):
    result, report = tiny
    md, page = report.markdown.read_text(), report.html.read_text()
    for stem in FIGURES:
        assert (report.markdown.parent / f"{stem}.png").stat().st_size > 1000
        assert f"({stem}.png)" in md
    assert page.count("data:image/png;base64,") == len(FIGURES)  # self-contained: figures embedded
    assert not re.search(r"""(src|href)=["']https?://""", page)
    for model in result.models:
        assert model.pairs, model.model
        section = md.split(f"### {model.model}\n", 1)[1].split("\n### ", 1)[0]
        for p in model.pairs:
            assert f"| {p.method} |" in section, (model.model, p.method)
            assert p.method in page
        assert f"Recommended: **{model.recommended[0]}**" in section
        assert f'id="{model.model}"' in page
    # every number, machine-readable: read back, it redraws the same report
    text = (report.markdown.parent / "atlas.json").read_text()
    again = from_json(text)
    assert to_json(again) == text
    assert [m.recommended for m in again.models] == [m.recommended for m in result.models]


def test_recommendation_follows_the_rule(tiny):
    result, _ = tiny
    for model in result.models:
        pairs = model.pairs
        assert model.recommended == choose([p.measurement for p in pairs], h=PLANS[model.model].h, t_final=PLANS[model.model].t_final,
                                           t_ref=PLANS[model.model].t_ref)
        ok = [p for p in pairs if p.qualifies]
        for p in ok:  # qualifying: completed, no warning, invariants kept
            assert p.completed and not p.warnings and p.invariant_drift <= INVARIANT_TOL
        if not ok:
            assert model.recommended[0] == "reference"
            continue
        best = model.pair(model.recommended[0])
        assert best in ok and not best.warnings  # a method with a warning is never recommended
        assert best.error <= max(1.5 * min(p.error for p in ok), REFERENCE_FLOOR)
        assert model.agrees == (model.recommended[0] == gnipy.get_model(model.model).default_method)
    # the sleigh: the GNI's hidden momentum leaves its band, the warning disqualifies it
    sleigh = next(m for m in result.models if m.model == "chaplygin-sleigh")
    trapezoid = sleigh.pair("gni-trapezoid")
    assert trapezoid.warnings and trapezoid.hidden_in_band is False and trapezoid.verdict == "warning"
    assert sleigh.recommended[0] != "gni-trapezoid"


def test_reversibility_round_off_only_for_symmetric(tiny):
    result, _ = tiny
    particle = result.models[0]
    sym, non = particle.pair("gni-trapezoid"), particle.pair("gni-euler-a")
    assert sym.symmetric and not non.symmetric
    assert sym.reversibility < 1e-11  # 2000 steps forward, 2000 back: round-off
    # its formula at -h is not its inverse: simulate refuses h < 0, the atlas does not ask
    assert non.reversibility is None and not non.note
    assert pair_row(non)[PAIR_HEADER.index("reversibility")] == "not symmetric"


def test_discrete_gradient_keeps_energy_to_round_off(tiny):
    result, _ = tiny
    particle = result.models[0]
    spec = gnipy.get_model("nonholonomic-particle")
    assert not spec.system().is_affine
    dg, trap = particle.pair("discrete-gradient"), particle.pair("gni-trapezoid")
    assert dg.energy_error is not None and dg.energy_error < 1e-12
    assert trap.energy_error > 1e3 * dg.energy_error  # the others keep it to O(h^2) only
    assert dg.constraint_residual < 1e-12 and trap.constraint_residual < 1e-12


def test_measurements_are_consistent(tiny):
    result, _ = tiny
    for model in result.models:
        for p in model.pairs:
            assert p.completed and p.cost_us > 0 and math.isfinite(p.cost_us)
            assert p.order == gnipy.get_method(p.method).order
            assert (p.hidden_max is not None) == p.method.startswith("gni-")  # the GNI family is diagnosed
    particle = result.models[0]
    # first order against second order, the same h: the Euler GNI is further from the reference
    assert particle.pair("gni-euler-a").error > 5 * particle.pair("gni-trapezoid").error


def test_default_methods_source_is_the_record_with_the_recommendations(tiny):
    result, report = tiny
    text = report.defaults.read_text()
    assert text == default_methods_source(result)
    tree = ast.parse(text)
    table = next(n for n in tree.body if isinstance(n, ast.AnnAssign) and n.target.id == "DEFAULT_METHODS")
    entries = ast.literal_eval(table.value)
    assert set(entries) == set(DEFAULT_METHODS)
    for model in result.models:
        assert entries[model.model] == model.recommended
    for name in set(DEFAULT_METHODS) - set(MODELS):  # models the atlas did not measure keep their record
        assert entries[name] == DEFAULT_METHODS[name]


def test_gni_atlas_quick_cli(tmp_path):
    out = tmp_path / "atlas"
    # the particle and two methods of the module's atlas, by the same plan: the CLI end to end on
    # the programs compiled for the module's atlas (module docstring)
    res = CliRunner().invoke(app, ["atlas", "--quick", "--models", "nonholonomic-particle", "--methods",
                                   "gni-trapezoid,discrete-gradient", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    assert (out / "atlas.md").is_file() and (out / "atlas.html").is_file() and (out / ".gnipy-owned").is_file()
    md = (out / "atlas.md").read_text()
    assert "| gni-trapezoid |" in md and "| discrete-gradient |" in md and "mode | quick" in md
    assert "nonholonomic-particle" in res.output


def test_gni_atlas_bad_input(tmp_path):
    res = CliRunner().invoke(app, ["atlas", "--models", "no-such-model", "--out", str(tmp_path / "a")])
    assert res.exit_code == 2 and "--models" in res.output and "Traceback" not in res.output
    res = CliRunner().invoke(app, ["atlas", "--methods", "reference", "--out", str(tmp_path / "a")])
    assert res.exit_code == 2 and "--methods" in res.output
    assert not (tmp_path / "a").exists()  # refused before anything is computed or written


def test_errors_below_the_reference_accuracy_are_tied():
    """Below REFERENCE_FLOOR the ranking is not resolved by the reference: the tie rule decides (here
    exact constraints first), and above it the smaller error wins, whatever the tie rule prefers."""
    def m(name, err, exact, order):
        return MethodMeasurement(name, err, 1e-6, (), False, 1.0, 0.0 if exact else 1e-3, order)

    tied = [m("a", 1e-12, False, 6), m("b", 0.5 * REFERENCE_FLOOR, True, 2)]
    assert choose(tied)[0] == "b"
    apart = [m("a", 1e-12, False, 6), m("b", 2 * REFERENCE_FLOOR, True, 2)]
    assert choose(apart)[0] == "a"
    assert "or below" in choose(apart)[1]
