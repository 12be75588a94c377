"""The README is the contract. Its examples run as written, with every other code block of the
docs, in tests/test_doc_examples.py (README.md is one of its pages, with the README's own checks:
the particle file written, orthonormal orientations, the parameter batch on its constraints);
here, what the README must keep."""

import pathlib
import re

from test_doc_examples import PYTHON, RUNNABLE_PAGES, SHELL, _blocks

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"

SET_UP = [
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[all]' && gni reproduce",
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]' && pytest",
]


def test_readme_examples_are_run_as_written():
    blocks = _blocks(README)
    assert README in RUNNABLE_PAGES
    assert sum(lang in PYTHON for lang, _, _ in blocks) >= 3
    assert sum(lang in SHELL for lang, _, _ in blocks) >= 4


def test_readme_set_up_commands_are_the_two_documented_lines():
    """A fresh machine: the reproduction, and the test suite (.ci/run runs the second line)."""
    shell = [code.strip() for lang, _, code in _blocks(README) if lang in SHELL]
    assert shell[:2] == SET_UP
    ci = (README.parent / ".ci" / "run").read_text()
    assert re.search(r"^" + re.escape(SET_UP[1]) + r"$", ci, flags=re.M)
