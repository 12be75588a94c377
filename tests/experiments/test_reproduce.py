"""`gni reproduce --quick`, the README's main job in its quick form, run once for the module end
to end through the CLI: the report it writes, and the numbers of what it computed on the way (its
figures, its theorem table and errata), taken as the CLI computed them (:func:`reproduction` wraps
the stages' functions) rather than computed a second time (the three modules' 63 s of worker time in
the suite before, 50 s alone after).

The expected values are the paper's or theory's, never an earlier run's:

- The figures of paper §7.4 (gnipy.experiments.figures; the derivations are in
  tests/experiments/test_figures.py's docstring, with the checks that need no run).
- The theorem table: the orders of Theorem 5.1, Remark 5.1 and the remark after Theorem 5.2; zero
  for the identities (Theorem 5.2, exact constraints, the explicit schemes equal to the GNI,
  energy conservation), within round-off bounds derived from the size of the numbers.
- The errata: a printed form that fails clearly (> 1e-3) against a corrected form that holds to
  round-off (≤ 1e-10).
"""

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from gnipy.cli import app
from gnipy.experiments import figures as F
from gnipy.experiments import theorems as th
from gnipy.experiments.reproduce import FIGURE_NAMES, OUTPUT_FILES
from gnipy.files.owned import MARKER
from gnipy.models import rolling_ball as rb

EPS = np.finfo(np.float64).eps
ORDER_TOL = 0.15
# the paper's claims (Theorem 5.1; Remark 5.1, [SDD2]; remark after Theorem 5.2; the GNI variants)
PAPER_ORDERS = {"euler-a": 1, "euler-b": 1, "rattle": 2, "euler-ab": 2, "gni-midpoint": 2,
                "gni-euler-a": 1, "gni-euler-b": 1, "gni-trapezoid": 2}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


class _Recorder:
    def __init__(self):
        self.advances, self.descriptions = [], []

    def __call__(self, advance, description):
        self.advances.append(advance)
        self.descriptions.append(description)


@pytest.fixture(scope="module")
def reproduction(tmp_path_factory):
    """`gni reproduce --out DIR --quick` through the CLI, once: `out`, `result` (the CLI's), and what
    its stages returned with the progress each reported: `figures` (name → FigureResult, with
    `figure_calls`), `table` (rows, recorder) and `errata` (location → Erratum, recorder)."""
    out = tmp_path_factory.mktemp("reproduction") / "report"
    returned, recorders = {}, {}

    def capture(key, fn):
        def stage(*args):  # the reproduction calls each stage as fn(..., quick, advance)
            *rest, advance = args
            rec = recorders[key] = _Recorder()

            def both(adv, description):
                rec(adv, description)
                advance(adv, description)

            returned[key] = fn(*rest, both)
            return returned[key]

        return stage

    with pytest.MonkeyPatch.context() as mp:
        for name in FIGURE_NAMES:
            mp.setattr(F, name, capture(name, getattr(F, name)))
        mp.setattr(th, "theorem_table", capture("theorems", th.theorem_table))
        mp.setattr(th, "errata_rows", capture("errata", th.errata_rows))
        result = CliRunner().invoke(app, ["reproduce", "--out", str(out), "--quick"])
    assert result.exit_code == 0, result.output
    figures = {returned[name].name: returned[name] for name in FIGURE_NAMES}
    figure_calls = {returned[name].name: list(zip(recorders[name].advances, recorders[name].descriptions))
                    for name in FIGURE_NAMES}
    return SimpleNamespace(out=out, result=result, figures=figures, figure_calls=figure_calls,
                           table=(returned["theorems"], recorders["theorems"]),
                           errata=({e.location: e for e in returned["errata"]}, recorders["errata"]))


@pytest.fixture(scope="module")
def run(reproduction):
    """The figures as tests/experiments/test_figures.py's checks read them: (out, results, calls)."""
    return reproduction.out, reproduction.figures, reproduction.figure_calls


@pytest.fixture(scope="module")
def table(reproduction):
    return reproduction.table


@pytest.fixture(scope="module")
def errata(reproduction):
    return reproduction.errata


# ------------------------------------------------------------------------------------------------
# The report
# ------------------------------------------------------------------------------------------------
def test_gni_reproduce_quick(reproduction):
    out, result = reproduction.out, reproduction.result
    assert result.exit_code == 0, result.output
    assert "Traceback" not in result.output
    for name in ("figure1", "figure2", "figure3"):
        assert (out / f"{name}.png").stat().st_size > 1000
        assert (out / f"{name}.pdf").stat().st_size > 1000
    md = next(out.glob("*.md")).read_text()
    html = next(out.glob("*.html")).read_text()
    assert "data:image/png;base64," in html
    assert not re.search(r"""(src|href)=["']https?://""", html)
    # the theorem table and the errata are in the report, with no failing row
    assert "Theorem 5.2" in md and "Errat" in md
    m = re.search(r"Theorem table: (\d+) of (\d+) claims pass", md)
    assert m and m.group(1) == m.group(2) and int(m.group(2)) >= 10, m
    assert "| FAIL |" not in md
    # where the GNI struggles: the three measured failures, each reported by its diagnostic
    assert "## Where the GNI struggles" in md
    for name in ("struggles_sleigh", "struggles_suslov", "struggles_oscillator"):
        assert (out / f"{name}.png").stat().st_size > 1000
    assert re.search(r"The verdict fires at t = [0-9.]+", md)
    assert "energy verdict" in md and "out of band at t =" in md


# ------------------------------------------------------------------------------------------------
# The figures (paper §7.4)
# ------------------------------------------------------------------------------------------------
def test_files_written_into_out_dir(run):
    out, results, _ = run
    for name, res in results.items():
        assert res.name == name
        assert [f.name for f in res.files] == [f"{name}.png", f"{name}.pdf"]
        png, pdf = (f.read_bytes() for f in res.files)
        assert png.startswith(PNG_MAGIC) and len(png) > 10_000
        assert pdf.startswith(b"%PDF") and len(pdf) > 5_000
        assert all(f.parent == out for f in res.files)
        assert res.title and res.caption and res.notes and res.table
        assert all(isinstance(v, float) for v in res.metrics.values())
    # the reproduction's folder holds the figures, the struggles' figures, the report and gnipy's marker
    # of a folder it created (gnipy.files.owned), nothing else
    assert sorted(p.name for p in out.iterdir()) == sorted([*OUTPUT_FILES, MARKER])


def test_progress_adds_up_to_one_per_figure(run):
    _, _, calls = run
    for name, c in calls.items():
        assert c and all(adv >= 0 and isinstance(desc, str) for adv, desc in c)
        assert sum(adv for adv, _ in c) == pytest.approx(1.0, abs=1e-9), name


def test_figure_1_orders(run):
    res = run[1]["figure1"]
    m = res.metrics
    # GNI = reduced RATTLE here: order 2
    for q in ("position", "omega", "energy"):
        assert m[f"gni_order_{q}"] == pytest.approx(2.0, abs=0.2), (q, m)
    # DLA: positions order 2, reported velocity order 1
    assert m["dla_order_position"] == pytest.approx(2.0, abs=0.2), m
    assert m["dla_order_omega"] == pytest.approx(1.0, abs=0.2), m
    # ... with the leading constant (h/2)|ω̇|, |ω̇| = (Ω − κ)|ż₀| (exact circular motion)
    p = rb.DEFAULT_PARAMS
    kappa = p["I1"] * p["Omega"] / (p["I1"] + p["m"] * p["r"] ** 2)
    h_min = min(row["h"] for row in res.table)
    predicted = 0.5 * h_min * (p["Omega"] - kappa) * math.hypot(1.0, 1.0)
    assert m["dla_error_omega_smallest_h"] == pytest.approx(predicted, rel=0.1)
    # the table holds every run
    assert {row["method"] for row in res.table} == {"gni", "dla"}
    assert "exact solution" in res.caption and "t = 1, 2, ..., 10" in res.caption


def test_figure_2_path_stays_on_the_exact_circle(run):
    m = run[1]["figure2"].metrics
    p = rb.DEFAULT_PARAMS
    kappa = p["I1"] * p["Omega"] / (p["I1"] + p["m"] * p["r"] ** 2)
    assert m["radius"] == pytest.approx(math.hypot(1.0, 1.0) / kappa, rel=1e-14)
    assert m["h"] == 0.1 and m["steps"] == 1000
    # O(h²): within (hω₀)² of the radius (ω₀ = 2 sets the step's rotation), and a factor 4 for h/2
    assert m["relative_max_distance_from_exact_circle"] < (0.1 * 2.0) ** 2
    assert m["distance_ratio_h_over_half_h"] == pytest.approx(4.0, rel=0.1)
    # no drift off the circle
    assert m["max_distance_second_half"] <= 1.05 * m["max_distance_first_half"]
    assert m["kappa_discrete"] == pytest.approx(kappa, rel=(0.1 * 2.0) ** 2)


def test_figure_3_orders_of_both_starts(run):
    res = run[1]["figure3"]
    m = res.metrics
    for start in ("paper", "momentum"):
        for q in ("position", "omega", "energy"):
            for suffix in ("", "_fine"):
                assert math.isfinite(m[f"{start}_start_order_{q}{suffix}"]), (start, q, suffix)
    # momentum start: the order-2 GNI
    for q in ("position", "omega", "energy"):
        assert m[f"momentum_start_order_{q}"] == pytest.approx(2.0, abs=0.2), (q, m)
    # paper's start: the O(h) start error dominates position and ω at small h
    assert m["paper_start_order_position_fine"] == pytest.approx(1.0, abs=0.3), m
    assert m["paper_start_order_omega_fine"] == pytest.approx(1.0, abs=0.3), m
    assert m["paper_start_matches_caption"] == 1.0 and m["momentum_start_matches_caption"] == 0.0
    notes = " ".join(res.notes)
    assert "Comparison with the caption: the paper's start (a) matches the caption's slopes (1, 1, 2)" in notes
    assert {row["start"] for row in res.table} == {"paper", "momentum"}
    assert "quick run" in res.caption and "p⁺₁ = FL⁺" in res.caption


# ------------------------------------------------------------------------------------------------
# The theorem table
# ------------------------------------------------------------------------------------------------
def _rows_with(rows, key):
    return [r for r in rows if key in r.values]


def test_every_row_passes(table):
    rows, _ = table
    assert len(rows) >= 15
    failed = [(r.claim, r.measured, r.detail) for r in rows if not r.passed]
    assert not failed, failed
    for r in rows:
        assert r.claim and r.paper_ref and r.expected and r.measured and r.detail


def test_measured_orders_match_the_paper(table, capsys):
    rows, _ = table
    orders = {r.values["method"]: r.values["order"] for r in _rows_with(rows, "order")}
    assert set(PAPER_ORDERS) <= set(orders)
    with capsys.disabled():
        print("\n  " + "  ".join(f"{k} {v:.3f}" for k, v in orders.items()))
    for method, claim in PAPER_ORDERS.items():
        assert abs(orders[method] - claim) <= ORDER_TOL, (method, orders[method])
    # the order rows' errors decrease monotonically with h (convergence, not noise)
    for r in _rows_with(rows, "order"):
        assert np.all(np.diff(r.values["errors"]) < 0), r.values


def test_theorem_5_2_residual_and_control(table):
    rows, _ = table
    (row,) = [r for r in rows if r.paper_ref == "Theorem 5.2"]
    v = row.values
    assert v["residual"] <= 1e-12  # F_A^h ∘ F_B^{-h} = Id to round-off on M_A
    assert v["manifold_B"] <= 1e-12  # F_B^{-h} maps M_A into itself
    assert v["off_domain"] > 1e-3  # off M_A the identity fails: the domain of the theorem matters
    assert v["manifold_A"] > 1e-4  # F_A^{-h} leaves M_A: it is not the inverse there


def test_reported_momentum_on_the_constraints(table):
    rows, _ = table
    rs = [r for r in _rows_with(rows, "step_velocity_residual")]
    assert {r.values["method"] for r in rs} == {"gni-euler-a", "gni-euler-b", "gni-trapezoid", "gni-midpoint"}
    for r in rs:
        assert r.values["residual"] <= 1e-12
        assert r.values["step_velocity_residual"] > 1e-5  # the check is not vacuous


def test_explicit_schemes_equal_the_gni(table):
    rows, _ = table
    pairs = {r.values["methods"]: r.values["difference"] for r in _rows_with(rows, "difference")}
    assert set(pairs) >= {("euler-a", "gni-euler-a"), ("euler-b", "gni-euler-b"), ("rattle", "gni-trapezoid")}
    # round-off of 256 steps: a few eps per step, accumulated at most linearly (20·N·eps)
    assert max(pairs.values()) <= 20 * 256 * EPS


def test_energy_theorem_quick(table):
    rows, _ = table
    (row,) = [r for r in rows if "drift" in r.values]
    v = row.values
    assert v["steps"] == 10_000
    bound = 25.0 * math.sqrt(10_000) * EPS  # round-off random walk of a few eps per step
    assert v["drift"] <= bound and v["trend"] <= bound
    assert v["constraint_residual"] <= 1e-12
    assert v["reported_energy_variation"] >= 1e-2  # the reflection acts: p̄ is not conserved


def test_progress_advances_add_up_to_one(table, errata):
    for rec in (table[1], errata[1]):
        assert rec.advances and min(rec.advances) >= 0.0
        assert sum(rec.advances) == pytest.approx(1.0, abs=1e-9)
        assert all(isinstance(d, str) and d for d in rec.descriptions)


# ------------------------------------------------------------------------------------------------
# Errata
# ------------------------------------------------------------------------------------------------
def _erratum(errata, where):
    (e,) = [e for loc, e in errata[0].items() if where in loc]
    assert e.printed and e.corrected and e.measurement and math.isfinite(e.evidence_value)
    return e


@pytest.mark.parametrize("where", ["(RBb)", "Remark 5.1", "(Cona)", "(RATc)"])
def test_printed_form_fails_and_corrected_form_holds(errata, where):
    e = _erratum(errata, where)
    assert e.values["printed_residual"] > 1e-3, e.measurement
    assert e.values["corrected_residual"] <= 1e-10, e.measurement
    assert e.evidence_value == e.values["printed_residual"]


def test_sign_of_pi_erratum_details(errata):
    """The printed (RBb) keeps the P* part (equations 1–3) and breaks the rolling constraints."""
    v = _erratum(errata, "(RBb)").values
    assert v["equations_1_3_residual"] <= 1e-12
    assert v["printed_constraint_residual"] > 0.1 and v["corrected_constraint_residual"] <= 1e-12


def test_literal_composition_is_first_order(errata):
    e = _erratum(errata, "composition")
    assert abs(e.values["printed_order"] - 1.0) <= ORDER_TOL
    assert abs(e.values["corrected_order"] - 2.0) <= ORDER_TOL
    assert e.evidence_value == e.values["printed_order"]


def test_all_five_errata_present(errata):
    locs = list(errata[0])
    assert len(locs) == 5
    for key in ["(RBb)", "Remark 5.1", "(Cona)", "composition", "(RATc)"]:
        assert any(key in loc for loc in locs), (key, locs)
