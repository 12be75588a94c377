"""`gni open-questions`: the paper's open questions 1 and 3, measured
(:mod:`gnipy.experiments.open_questions_report`)."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import app
from .errors import relabel
from .held import hold, holding
from .output import EXIT_FAILURE, EXIT_USAGE, console, fail, safe
from .progress import Progress

__all__ = ["open_questions"]


@app.command(name="open-questions")
def open_questions(
    out: Path = typer.Option(Path("gnipy-open-questions"), "--out", "-o",
                             help="Output folder: open-questions.md, open-questions.json and the figures (PNG, PDF)."),
    quick: bool = typer.Option(False, "--quick", help="The nonholonomic particle's rows of question 1 with 10^5 "
                               "steps and three sister cases: about 3 minutes on 2 cores (full: 4 models x 6 "
                               "methods with 10^6 steps each, about an hour)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace the files in a folder gnipy did not create "
                                   "(in one it created, marked by its .gnipy-owned file, a rerun replaces them)."),
) -> None:
    """Measure the paper's open questions 1 (backward error analysis: the modified equations of the
    GNI, sgni, dla, mp and the discrete gradient tested for the same constraints, a modified energy
    and phase volume, with the energy error they predict against runs of 10^6 steps) and 3 (sister
    systems: holonomic phases switched every tau with a plastic impact, their convergence as tau
    -> 0, the sister method and its relation to the GNI and dla). Writes OUT/open-questions.md,
    OUT/open-questions.json and the figures. Exits with 1 if a file cannot be written, 2 if --out
    may not be written."""
    from gnipy.experiments.open_questions_report import OPEN_QUESTIONS_FILES, run_open_questions
    from gnipy.experiments.report import overwriting
    from gnipy.experiments.reproduce import check_output_dir
    from gnipy.files import OutputBusy, OutputError

    try:
        check_output_dir(Path(out), overwrite, files=OPEN_QUESTIONS_FILES)
    except OutputError as e:
        fail(relabel("--out", e), EXIT_USAGE)
    with holding():
        try:
            hold("--out", out)  # one writer per folder
        except OutputBusy as e:
            fail(str(e), EXIT_USAGE)
        try:
            with overwriting(overwrite), Progress("open-questions", unit="studies", heartbeat=True) as progress:
                result = run_open_questions(Path(out), quick=quick, progress=progress)
        except OutputError as e:
            fail(relabel("--out", e), EXIT_FAILURE)
    con = console()
    con.print(f"measured in {result.runtime_s:.0f} s; written: {safe(result.markdown)}, {safe(result.data)} and "
              f"{len(result.figures)} figure files", markup=False)
