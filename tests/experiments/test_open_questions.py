"""`gni open-questions`: the report's verdict rules on constructed rows, the files it writes, the
command's refusal of a folder it may not write, and one row of question 1 measured end to end (a
short run against the prediction of its modified equations). The measurements' parts are tested
where they are made (tests/analysis/test_modified_equations.py, tests/analysis/test_sister.py); the
full study takes about an hour and its quick form about 3 minutes (`gni open-questions --quick`)."""

import dataclasses
import json

import numpy as np
from typer.testing import CliRunner

from gnipy.cli import app
from gnipy.experiments.open_questions_report import OPEN_QUESTIONS_FILES, write_open_questions


def _row(method, normal, rates, *, defect=0.0, measured=(1e-5, 1e-12), predicted=(1.1e-5, 1e-12), failure=None):
    t = [0.0, 1.0, 2.0]
    return {"model": "nonholonomic-particle", "method": method, "steps_per_map": 1, "leading": 3,
            "coefficient_sizes": [1.0, 0.0, 0.1], "normal_velocity": normal, "energy_rate": rates,
            "defect": defect, "divergence": 0.0, "g_max": [0.0, 0.1], "g_slope": [0.0, 0.0],
            "predicted_max": predicted[0], "predicted_slope": predicted[1], "measured_max": measured[0],
            "measured_slope": measured[1], "run_max": measured[0], "h": 0.01, "steps": 1000, "runtime_s": 1.0, "failure": failure,
            "verdicts": [], "series": {"t": t, "measured": [0.0, 1e-5, 0.0], "predicted": [0.0, 1.1e-5, 0.0]}}


def _measurements():
    sister = {"model": "knife-edge", "constraint": "rail", "kind": "system", "taus": [0.1, 0.05],
              "errors": [0.2, 0.1], "dissipation": [0.6, 0.3], "order": 1.0, "constant": 2.0,
              "dissipation_order": 1.0, "dissipation_constant": 6.0, "constraint_kept": 1e-16, "t_final": 2.0}
    rows = [
        _row("discrete-gradient", [0.0, 0.0, 0.08], [0.0, 0.0, 0.0]),  # E conserved; constraints modified at h²
        _row("mp", [0.0, 0.0, 0.0], [0.0, 0.0, 0.05]),  # same constraints, bounded energy error
        _row("sgni-trapezoid", [0.0, 0.0, 0.3], [0.0, 0.0, 0.2], measured=(1e-3, 1e-3),
             predicted=(1e-3, 1e-3)),  # a drift (slope·span > max/2), as predicted
        _row("gni-trapezoid", [0.0, 1e-3, 0.07], [0.0, 7e-4, 0.0], measured=(1.1, 0.0), predicted=(2.6e-5, 0.0)),
        _row("dla", [0.0, 0.0, 0.1], [0.0, 0.0, 0.1], defect=1e-3),  # the premise fails at its states
        {"model": "veselova", "method": "discrete-gradient", "not_applicable": "method 'discrete-gradient' refuses"},
    ]
    paths = {"reference": np.zeros((3, 3)), "sister": {0.5: np.ones((3, 3))}}
    relations = {"knife-edge": {"sister-system": {"h": [0.1, 0.05], "difference": [1e-16, 2e-16], "order": float("nan")},
                                "dla": {"h": [0.1, 0.05], "difference": [4e-3, 1e-3], "order": 2.0}}}
    longs = [{"model": "chaplygin-sleigh", "method": "gni-trapezoid", "h": 0.01, "t_final": 50.0, "error": float("nan"),
              "energy_error": float("nan"), "failure": "solve failed at step 2130", "verdicts": []}]
    meta = {"gnipy_version": "test", "date": "today", "machine": "here", "mode": "quick", "runtime_s": 1.0}
    return {"meta": meta, "backward_error": rows, "sister_convergence": [sister], "sister_relations": relations,
            "long_runs": longs, "sister_paths": paths}


def test_the_report_states_the_verdicts_its_rules_give_and_writes_every_file(tmp_path):
    out = tmp_path / "oq"
    result = write_open_questions(out, _measurements())
    for name in OPEN_QUESTIONS_FILES:
        assert (out / name).is_file(), name
    text = result.markdown.read_text()
    lines = {line.split("|")[2].strip(): line for line in text.splitlines() if line.startswith("| nonholonomic")}
    assert "conserved to h^2" in lines["discrete-gradient"] and "modified constraints from h^2" in lines["discrete-gradient"]
    assert "same constraints to h^2" in lines["mp"] and "predicted bounded, measured bounded" in lines["mp"]
    assert "predicted drift, measured drift" in lines["sgni-trapezoid"]
    assert "modified constraints from h^1" in lines["gni-trapezoid"] and "breaks down" in lines["gni-trapezoid"]
    assert "no modified field at the visited states" in lines["dla"]
    assert "round-off: the same map" in text and "failed: solve failed at step 2130" in text
    assert "| veselova | discrete-gradient |" in text and "does not apply | method 'discrete-gradient' refuses" in text
    data = json.loads(result.data.read_text())
    assert [r["method"] for r in data["backward_error"]] == ["discrete-gradient", "mp", "sgni-trapezoid",
                                                             "gni-trapezoid", "dla", "discrete-gradient"]
    assert "sister_paths" not in data  # the figure's arrays, not measurements


def test_the_command_refuses_a_folder_it_did_not_create_before_computing(tmp_path):
    (tmp_path / "open-questions.md").write_text("mine")
    result = CliRunner().invoke(app, ["open-questions", "--out", str(tmp_path), "--quick"])
    assert result.exit_code == 2
    assert "--out" in result.output and "open-questions.md" in result.output
    assert (tmp_path / "open-questions.md").read_text() == "mine"


def test_one_row_end_to_end_predicts_the_measured_energy_error():
    # mp on the nonholonomic particle (order 2 in (q, v)): f_2 vanishes, f_3 leaves the distribution
    # (modified constraints at h²) and predicts, with no free constant, the energy error of an actual run
    # of 1000 steps (E_k - E_0 ≈ h² G_3, G_3 = ∫∇E·f_3 along the continuous reference): two independent
    # computations (the run's energies, the expansion along the reference) agree to a few per cent
    from gnipy.experiments.open_questions import backward_error_row
    from gnipy.experiments.open_questions_report import _constraint_verdict, _energy_verdict

    row = dataclasses.asdict(backward_error_row("nonholonomic-particle", "mp", steps=1000, span=10.0, samples=2))
    assert row["leading"] == 3 and row["failure"] is None and row["defect"] < 1e-12
    assert max(row["normal_velocity"][:2]) < 1e-12 < 1e-3 < row["normal_velocity"][2]
    assert row["divergence"] < 1e-12  # the particle's motion preserves volume
    assert 1e-6 < row["measured_max"] and abs(row["predicted_max"] / row["measured_max"] - 1) < 0.1
    assert _constraint_verdict(row) == "modified constraints from h^2"
    assert _energy_verdict(row).startswith("predicted bounded")
