"""Every code block of README.md and of docs/**/*.md runs as written.

The blocks are found, not listed: a page's fenced blocks run in the order of the page, in one
temporary directory per page (files written by a block are there for the later ones):

- ```python blocks are executed in one namespace per page (a later block uses the names of the
  earlier ones); one whose first line is a comment naming a file (`# my_sleigh.py`) is also written
  to that file, which later commands of the page name (`gni run my_sleigh.py:make_sleigh`);
- ```bash, ```sh, ```shell, ```console (the `$ ` lines) and unlabelled blocks are shell commands:
  each command line (with its `\\` continuations) must exit with 0 and print no Python traceback.
  A plain `gni ...` line (no pipe, redirection, variable or other shell syntax: :func:`_gni_argv`)
  runs in the page's process through the entry point of the installed `gni` script
  (`gnipy.__main__.main`, with `sys.argv` the line's words as bash splits them), its output
  captured at the file descriptors, so that child processes' output (dask workers) is seen too;
  every other line runs with bash, the virtual environment's `gni` and `python` first on PATH (at
  least one `gni` line of the docs does, so the script itself runs here too). In the page's
  process a command costs what its work costs: a `gni` process of its own first imports JAX,
  gnipy and the file libraries and traces its programs again (about 2-3 s a command, measured;
  the 44 `gni` lines of the docs took 210 s of the module's 381 s of CPU);
- ```toml blocks are parsed; one whose first line is a comment naming a file (`# disk.toml`) is
  written to that file, which later commands of the page read;
- ```text blocks are not commands (usage synopses with placeholders such as MODEL); a ```text block
  holding a `gni` line without a placeholder is an error.

The only commands that do not run are those of :data:`NOT_RUN`, each with the test that covers it.
A few pages get an input file from a documented command first (:data:`PAGE_INPUTS`), and some
pages' results are checked beyond running (:data:`CHECKS`).

Each page runs in its own temporary directory and its own namespace, in one of two child
processes (lanes) that run pages at the same time; a lane runs its pages one after the other, so a
page reuses the programs an earlier page of its lane traced and compiled. A failure names the page
and the line of the block (a Python traceback points into the page itself); a page that fails does
not stop the next.
"""

from __future__ import annotations

import os
import pathlib
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]

PYTHON = {"python", "py"}
SHELL = {"bash", "sh", "shell", "console", ""}
DATA = {"toml"}
NOT_CODE = {"text"}

#: Commands of the docs that are not run here, with the test that covers each.
NOT_RUN = {
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[all]' && gni reproduce":
        "set-up on a fresh machine: .ci/run installs from scratch the same way, with the [test] extra "
        "(tests/test_readme.py::test_readme_set_up_commands_are_the_two_documented_lines); the reproduction "
        "(about 2 minutes) runs in its quick form in tests/experiments/test_reproduce.py::test_gni_reproduce_quick",
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]' && pytest":
        "the CI job itself: .ci/run is this line "
        "(tests/test_readme.py::test_readme_set_up_commands_are_the_two_documented_lines)",
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[all]'":
        "set-up on a fresh machine: .ci/run installs from scratch the same way, with the [test] extra that "
        "includes [all] (tests/test_readme.py::test_readme_set_up_commands_are_the_two_documented_lines, "
        "tests/test_extras.py::test_every_require_in_the_source_names_an_extra_that_installs_the_package)",
    "pip install '.[cli]'":
        "set-up: .ci/run installs the package the same way, with every extra "
        "(tests/test_readme.py::test_readme_set_up_commands_are_the_two_documented_lines); the extras' "
        "packages are those the code asks for "
        "(tests/test_extras.py::test_every_require_in_the_source_names_an_extra_that_installs_the_package)",
    "gni reproduce --out report/":
        "the full reproduction takes about 2 minutes; with --quick it runs in "
        "tests/experiments/test_reproduce.py::test_gni_reproduce_quick",
    "gni reproduce --out gnipy-reproduction/":
        "the full reproduction takes about 2 minutes; with --quick it runs in "
        "tests/experiments/test_reproduce.py::test_gni_reproduce_quick",
    "gni reproduce --out quick/ --quick":
        "about a minute: this very command (--out in a temporary directory) runs in "
        "tests/experiments/test_reproduce.py::test_gni_reproduce_quick",
    "gni atlas --out gnipy-atlas/":
        "the full atlas takes about 20 minutes on 2 cores; its measurement and report run small in "
        "tests/experiments/test_atlas.py::test_report_files_hold_every_measured_pair and through the CLI in "
        "tests/experiments/test_atlas.py::test_gni_atlas_quick_cli",
    "gni atlas --quick --out atlas-quick/":
        "1.5-2.5 minutes: gni atlas --quick with --models and --methods runs in "
        "tests/experiments/test_atlas.py::test_gni_atlas_quick_cli, and the small command of the atlas page here",
    "gni open-questions --out gnipy-open-questions/":
        "the full study takes about an hour on 2 cores; its report writer runs in "
        "tests/experiments/test_open_questions.py::test_the_report_states_the_verdicts_its_rules_give_and_writes_every_file, "
        "its measurements in tests/analysis/test_sister.py and tests/analysis/test_modified_equations.py",
    "gni open-questions --quick --out oq-quick/":
        "about 3 minutes: the command's folder checks run in "
        "tests/experiments/test_open_questions.py::test_the_command_refuses_a_folder_it_did_not_create_before_computing, "
        "its report writer in tests/experiments/test_open_questions.py::test_the_report_states_the_verdicts_its_rules_give_and_writes_every_file",
    "gni control --example ball-plate --starts 8 --out ball-starts.nc":
        "about 45 s: the multistart runs in tests/control/test_optimal_control.py::"
        "test_a_multistart_reuses_the_compiled_problem_and_lists_the_optima, and --starts through the CLI in the "
        "control page's sleigh-steering command here",
    "mkdocs build --strict":
        "tests/test_docs.py::test_site_builds_strict builds the site with --strict",
    "python -m benchmarks":
        "rewrites the repository's BENCHMARKS.md and takes many minutes; the benchmark baselines are "
        "checked against gnipy in tests/test_benchmark_baselines.py::test_numpy_gni_matches_gnipy and "
        "tests/test_benchmark_baselines.py::test_dop853_rhs_matches_gnipy_equations",
    "dask scheduler":
        "a server of a cluster of several machines (runs until stopped); gni sweep on an existing cluster "
        "(--scheduler) runs in tests/test_sweep.py::test_interrupted_cli_sweep_resumes_without_recomputing",
    "dask worker tcp://HOST:8786 --nthreads 1":
        "a worker of that cluster (HOST: the user's scheduler); gni sweep --scheduler runs in "
        "tests/test_sweep.py::test_interrupted_cli_sweep_resumes_without_recomputing",
    "gni sweep rolling-ball --grid Omega=0:2:200 --grid q0.x=-1:1:500 --h 0.01 --t-final 10 "
    "--scheduler tcp://HOST:8786 --out ball-sweep.zarr":
        "needs the cluster above (HOST); gni sweep --scheduler runs in "
        "tests/test_sweep.py::test_interrupted_cli_sweep_resumes_without_recomputing",
}

#: Input files a page reads without writing them: made first by the documented command shown.
PAGE_INPUTS = {
    # files.md reads disk.nc: the file of README.md's and getting-started.md's `gni run vertical-disk`
    "docs/user-guide/files.md": [
        "gni run vertical-disk --method gni-midpoint --h 0.05 --steps 400 --set I_rot=2 --save-every 10 --out disk.nc",
    ],
}


# ------------------------------------------------------------------------------------------------
# Finding the blocks and their commands
# ------------------------------------------------------------------------------------------------
FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>```+|~~~+)[ \t]*(?P<info>[^\n`]*)\n(?P<body>.*?)^(?P=indent)(?P=fence)[ \t]*$",
                   re.M | re.S)


def _blocks(page: pathlib.Path) -> list[tuple[str, int, str]]:
    """`(language, line of the block's first line, code)` for each fenced block of the page."""
    text = page.read_text()
    out = []
    for m in FENCE.finditer(text):
        lang = m.group("info").strip().split()[0].lower() if m.group("info").strip() else ""
        lang = lang.lstrip("{.").rstrip("}")
        first = text.count("\n", 0, m.start("body")) + 1
        body = m.group("body")
        if m.group("indent"):
            body = "".join(line[len(m.group("indent")):] for line in body.splitlines(keepends=True))
        out.append((lang, first, body))
    return out


def _commands(lang: str, code: str, first: int) -> list[tuple[int, str]]:
    """`(line, command)` for each command line of a shell block: `\\` continuations joined, blank
    and comment-only lines dropped; in a console block only the `$ ` lines are commands."""
    lines = code.splitlines()
    if lang == "console":
        lines = [line[2:] if line.startswith("$ ") else "#" for line in lines]
    out, current, start = [], "", None
    for i, line in enumerate(lines):
        if start is None:
            start = first + i
        if line.rstrip().endswith("\\"):
            current += line.rstrip()[:-1] + " "
            continue
        current += line
        if current.strip() and not current.strip().startswith("#"):
            out.append((start, current.strip()))
        current, start = "", None
    assert not current, f"a command ends with a line continuation at line {start}"
    return out


def _key(command: str) -> str:
    """The command without its trailing comment and with single spaces (for :data:`NOT_RUN`); the
    comment is cut only where shell-splitting the command agrees that it is one."""
    plain = re.sub(r"\s+#.*$", "", command)
    if shlex.split(plain) != shlex.split(command, comments=True):
        plain = command
    return " ".join(plain.split())


def _rel(page: pathlib.Path) -> str:
    return page.relative_to(ROOT).as_posix()


def _is_synopsis(line: str) -> bool:
    """A usage line: it has placeholders (MODEL, FILE.nc, ...) or optional parts ([...], a | b)."""
    return bool(re.search(r"\[|\||\b[A-Z]{2,}[A-Z0-9_]*\b", line))


RUNNABLE_PAGES = [p for p in PAGES if any(lang not in NOT_CODE for lang, _, _ in _blocks(p))]


# ------------------------------------------------------------------------------------------------
# Running a page
# ------------------------------------------------------------------------------------------------
_CACHE_DIR: list[str] = []


def _cache_dir() -> str:
    """A private folder (0700, removed at exit) for the compiled programs of this module's `gni`
    commands: many pages run the same model with the same method, and JAX's compilation cache
    (gnipy.compilation, opt-in with GNIPY_COMPILATION_CACHE) lets a later command load the program an
    earlier one compiled. It changes how long a command takes, not what it computes. The session's
    cache (conftest.SESSION_CACHE) where there is one, so that the pages load what the tests compiled."""
    if not _CACHE_DIR and os.environ.get("GNIPY_TEST_SESSION_CACHE"):
        _CACHE_DIR.append(os.environ["GNIPY_TEST_SESSION_CACHE"])
    if not _CACHE_DIR:
        import atexit
        import shutil
        import tempfile

        _CACHE_DIR.append(tempfile.mkdtemp(prefix="gnipy-doc-examples-"))
        atexit.register(shutil.rmtree, _CACHE_DIR[0], True)
    return _CACHE_DIR[0]


def _shell_env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("GNIPY_", "PYTEST_"))}
    env["PATH"] = os.pathsep.join([str(pathlib.Path(sys.executable).parent), env.get("PATH", "")])
    env["PYTHONUNBUFFERED"] = "1"
    env["GNIPY_CACHE_DIR"] = _cache_dir()
    env["GNIPY_COMPILATION_CACHE"] = "1"
    return env


def _run_shell(command: str, where: str, cwd: pathlib.Path) -> None:
    start = time.perf_counter()
    res = subprocess.run(
        ["bash", "-o", "pipefail", "-c", command], cwd=cwd, env=_shell_env(), stdin=subprocess.DEVNULL,
        capture_output=True, text=True, timeout=300, check=False,
    )
    output = res.stdout + res.stderr
    print(f"{where}: {time.perf_counter() - start:.1f} s  {command}", flush=True)
    assert res.returncode == 0, f"{where}: `{command}` exited with {res.returncode}:\n{output[-4000:]}"
    assert "Traceback" not in output, f"{where}: `{command}` printed a traceback:\n{output[-4000:]}"


#: Characters that bash gives a meaning outside quotes (pipes, redirections, lists, subshells,
#: expansions, globs, escapes); inside double quotes, `$`, backquote and backslash keep theirs.
_SHELL_SYNTAX, _DOUBLE_QUOTED_SYNTAX = set("|&;<>()$`{}*?[]~\\!"), set("$`\\!")


def _gni_argv(command: str) -> list[str] | None:
    """The arguments of a plain `gni` line, as bash splits it (its comment cut), or None for any
    other line: one whose first word is not `gni`, or that uses shell syntax outside single quotes
    (a pipe, a redirection, a variable, a glob, an assignment in front, ...)."""
    quote = None
    for i, ch in enumerate(command):
        if quote == "'":
            quote = None if ch == "'" else quote
        elif quote == '"':
            if ch in _DOUBLE_QUOTED_SYNTAX:
                return None
            quote = None if ch == '"' else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or command[i - 1].isspace()):
            break  # the comment: bash reads no further
        elif ch in _SHELL_SYNTAX:
            return None
    if quote is not None:
        return None
    words = shlex.split(command, comments=True)
    return words[1:] if words and words[0] == "gni" else None


def _run_gni(argv: list[str], command: str, where: str) -> None:
    """Run `gni ARGV` in this process as the `gni` script does (`gnipy.__main__.main`), its
    output (and that of any process it starts) captured at file descriptors 1 and 2."""
    import tempfile
    import traceback
    import warnings

    from gnipy.__main__ import main

    start = time.perf_counter()
    code, error = 0, ""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    old_argv = sys.argv
    with tempfile.TemporaryFile() as out:
        os.dup2(out.fileno(), 1)
        os.dup2(out.fileno(), 2)
        try:
            sys.argv = ["gni", *argv]
            with warnings.catch_warnings():  # the command's warning filters stay its own
                main()
        except SystemExit as e:
            code = 0 if e.code is None else e.code if isinstance(e.code, int) else 1
            error = "" if isinstance(e.code, int) or e.code is None else str(e.code)
        except BaseException:  # noqa: BLE001 (reported as the command's failure, below)
            code, error = 1, traceback.format_exc()
        finally:
            sys.argv = old_argv
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        out.seek(0)
        output = out.read().decode(errors="replace") + error
    print(f"{where}: {time.perf_counter() - start:.1f} s  {command}  (in this process)", flush=True)
    assert code == 0, f"{where}: `{command}` exited with {code}:\n{output[-4000:]}"
    assert "Traceback" not in output, f"{where}: `{command}` printed a traceback:\n{output[-4000:]}"


def run_page(page: pathlib.Path, cwd: pathlib.Path) -> dict:
    """Run every block of `page` in order in `cwd` (the current directory); return the namespace of
    its Python blocks."""
    rel = _rel(page)
    for command in PAGE_INPUTS.get(rel, []):
        _run_shell(command, f"{rel} (input)", cwd)
    namespace: dict = {"__name__": "__main__"}
    for lang, first, code in _blocks(page):
        where = f"{rel}:{first}"
        if lang in PYTHON:
            name = re.match(r"#\s*(\S+\.py)\s*$", code.splitlines()[0])
            if name:  # a file of the reader's (`# my_sleigh.py`): written, for the later commands, and run
                (cwd / name.group(1)).write_text(code)
                os.chmod(cwd / name.group(1), 0o644)  # whatever the umask: gnipy runs only files others cannot write
            start = time.perf_counter()
            # blank lines in front: tracebacks give the page's own line numbers
            exec(compile("\n" * (first - 1) + code, str(page), "exec"), namespace)  # noqa: S102
            print(f"{where}: {time.perf_counter() - start:.1f} s  (python block)", flush=True)
        elif lang in SHELL:
            for line, command in _commands(lang, code, first):
                if _key(command) in NOT_RUN:
                    continue
                argv = _gni_argv(command)
                if argv is None:
                    _run_shell(command, f"{rel}:{line}", cwd)
                else:
                    _run_gni(argv, command, f"{rel}:{line}")
        elif lang in DATA:
            data = tomllib.loads(code)
            name = re.match(r"#\s*(\S+\.toml)\s*$", code.splitlines()[0])
            if name:
                (cwd / name.group(1)).write_text(code)
            assert data, where
        else:
            assert lang in NOT_CODE, f"{where}: a ```{lang} block: run it here or label it ```text"
    return namespace


# ------------------------------------------------------------------------------------------------
# What some pages promise beyond running
# ------------------------------------------------------------------------------------------------
def _orthogonal(R) -> None:
    R = np.asarray(R)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)


def _check_readme(ns, cwd):
    assert (cwd / "particle.nc").is_file()  # the first example writes its file
    _orthogonal(ns["sol"].R[-1])  # the second reconstructs orientations
    ensemble = ns["ensemble"]  # the parameter batch: each member on its own constraints
    assert ensemble.batch_size == 50 and ensemble.q.shape == (50, 11, 2)
    assert np.max(np.abs(np.asarray(ensemble.constraint_residual))) <= 1e-12
    np.testing.assert_allclose(ensemble.member_params["Omega"], np.linspace(0.0, 1.0, 50))
    assert (cwd / "disk.png").is_file() and (cwd / "conv").is_dir() and (cwd / "sweep.zarr").is_dir()


def _check_getting_started(ns, cwd):
    assert (cwd / "ball.png").is_file() and (cwd / "particle.nc").is_file()
    _orthogonal(ns["sol"].R[-1])


def _check_systems(ns, cwd):
    _orthogonal(ns["sol"].R[-1])
    assert ns["disk"].name == "my-disk"
    # the blade from SymPy slides down the slope (x grows) and keeps its constraint
    assert ns["run"].healthy and float(ns["run"].q[-1, 0]) > 0.1
    assert float(abs(ns["run"].constraint_residual).max()) <= 1e-12
    # the pendulum with a holonomic constraint stays on |q| = 1 at round-off
    q = np.asarray(ns["swing"].q)
    assert ns["swing"].constraint_residual.shape == (1001, 2)
    assert np.max(np.abs(np.sum(q * q, axis=1) - 1.0)) < 1e-15


def _check_files(ns, cwd):
    ns["ds"].close()
    assert (cwd / "disk.png").is_file()


def _check_performance(ns, cwd):
    sol = ns["sol"]
    assert sol.batch_size == 50 and sol.q.shape == (50, 1001, 2)
    np.testing.assert_allclose(sol.member_params["Omega"], np.linspace(0.0, 1.0, 50))
    assert ns["first"].q.shape == (21, 2)
    assert ns["result"].nodes == 20001 and (cwd / "ball.nc").is_file()


def _check_sweeps(ns, cwd):
    assert ns["ds"]["q"].dims == ("Omega", "q0_x", "time", "coordinate")
    assert ns["report"].failed_members == 0


def _check_cli(ns, cwd):
    for name in ("disk.nc", "disk.png", "fine.nc", "study/convergence.csv", "study2/convergence.csv"):
        assert (cwd / name).is_file(), name


CHECKS = {
    "README.md": _check_readme,
    "docs/getting-started.md": _check_getting_started,
    "docs/user-guide/systems.md": _check_systems,
    "docs/user-guide/files.md": _check_files,
    "docs/user-guide/performance.md": _check_performance,
    "docs/user-guide/sweeps.md": _check_sweeps,
    "docs/user-guide/cli.md": _check_cli,
}


def page_main(rel: str, cwd: str) -> None:
    """Run the page `rel` in `cwd`, then its :data:`CHECKS`."""
    cwd_path = pathlib.Path(cwd)
    os.chdir(cwd_path)
    namespace = run_page(ROOT / rel, cwd_path)
    check = CHECKS.get(rel)
    if check is not None:
        check(namespace, cwd_path)
    print(f"{rel}: all blocks ran", flush=True)


#: the line that ends a page's output in a lane's process: `END_MARK rel returncode`
END_MARK = "@@gnipy-doc-page-end@@"


def lane_main(*pairs: str) -> None:
    """The child process of one lane: the pages `rel1 cwd1 rel2 cwd2 ...` one after the other, each
    in its own directory and namespace, each page's end marked with its outcome; a page that fails
    does not stop the next."""
    import traceback

    if os.environ.get("GNIPY_COMPILATION_CACHE") == "1":  # the Python blocks too (:func:`_cache_dir`)
        from gnipy.compilation import enable_compilation_cache

        enable_compilation_cache()
    for rel, cwd in zip(pairs[::2], pairs[1::2]):
        code, start = 0, time.perf_counter()
        try:
            page_main(rel, cwd)
        except BaseException:  # noqa: BLE001 (reported as the page's failure)
            traceback.print_exc()
            code = 1
        sys.stdout.flush()
        sys.stderr.flush()
        print(f"({rel}: {time.perf_counter() - start:.1f} s in this lane)")
        print(f"\n{END_MARK} {rel} {code}", flush=True)


#: Processes that run pages at the same time (two on the 2-core machine; `DOC_EXAMPLES_LANES=1`
#: runs them all in one).
LANES = max(1, int(os.environ.get("DOC_EXAMPLES_LANES", "2")))


def _cost(page: pathlib.Path) -> int:
    """A rough cost (most first keeps the lanes busy to the end): the commands run and the Python blocks."""
    rel = _rel(page)
    commands = [c for lang, first, code in _blocks(page) if lang in SHELL for _, c in _commands(lang, code, first)]
    python = sum(lang in PYTHON for lang, _, _ in _blocks(page))
    return len(PAGE_INPUTS.get(rel, [])) + sum(_key(c) not in NOT_RUN for c in commands) + python


def _lanes(pages: list[str]) -> list[list[str]]:
    """The pages shared among :data:`LANES` lanes, the costliest first, each to the lane with the
    least cost so far."""
    lanes = [[] for _ in range(min(LANES, len(pages)) or 1)]
    load = [0] * len(lanes)
    for rel in sorted(pages, key=lambda rel: -_cost(ROOT / rel)):
        i = load.index(min(load))
        lanes[i].append(rel)
        load[i] += _cost(ROOT / rel)
    return [lane for lane in lanes if lane]


class _PageRuns:
    """The selected pages, run by `lane_main` in :data:`LANES` child processes, each page in its own
    directory and namespace. The pages of a lane share its process (not each a fresh one): a page's
    programs traced and compiled by an earlier page of the lane are reused, which took the module
    from about 200 s of CPU in 15 processes to less (tests/conftest.py's budget)."""

    def __init__(self, pages: list[str], base: pathlib.Path):
        self.base, self.procs, self.closed = base, [], False
        self.lock = threading.Lock()
        lanes = _lanes(pages)
        self.pool = ThreadPoolExecutor(len(lanes))
        self.futures = {}
        for lane in lanes:
            future = self.pool.submit(self._run, lane)
            for rel in lane:
                self.futures[rel] = (future, rel)

    def _run(self, lane: list[str]) -> dict[str, tuple[int, str, float]]:
        pairs = []
        for rel in lane:
            cwd = self.base / re.sub(r"[^\w.-]", "_", rel)
            cwd.mkdir()
            pairs += [rel, str(cwd)]
        code = f"import sys; sys.path.insert(0, {str(ROOT / 'tests')!r}); import test_doc_examples as t; t.lane_main(*sys.argv[1:])"
        start = time.perf_counter()
        with self.lock:
            if self.closed:
                return {rel: (-1, "not run: the session ended", 0.0) for rel in lane}
            proc = subprocess.Popen(
                [sys.executable, "-c", code, *pairs], cwd=self.base, env=_shell_env(), stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
            )
            self.procs.append(proc)
        try:
            output, _ = proc.communicate(timeout=900 * len(lane))
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            output = proc.communicate()[0] + f"\n(killed after {900 * len(lane)} s)"
        seconds = time.perf_counter() - start
        results, rest = {}, output
        for rel in lane:
            mark = re.search(rf"^{re.escape(END_MARK)} {re.escape(rel)} (\d+)$", rest, flags=re.M)
            if mark is None:  # the process ended (or was killed) before this page's end
                results[rel] = (proc.returncode or -1, f"{rest}\n(the lane's process ended, code {proc.returncode}, "
                                                         f"before {rel} finished)", seconds)
                rest = ""
                continue
            results[rel] = (int(mark.group(1)), rest[:mark.start()], seconds)
            rest = rest[mark.end():]
        return results

    def result(self, rel: str) -> tuple[int, str, float]:
        future, rel = self.futures[rel]
        return future.result()[rel]

    def close(self) -> None:
        with self.lock:
            self.closed = True
            for proc in self.procs:
                if proc.poll() is None:
                    try:
                        os.killpg(proc.pid, signal.SIGKILL)  # the lane's process and its commands
                    except ProcessLookupError:
                        pass
        self.pool.shutdown(wait=True, cancel_futures=True)


@pytest.fixture(scope="module")
def page_runs(request, tmp_path_factory):
    """Starts every page selected in this session (`-k` respected) at the first page's test."""
    pages = [item.callspec.params["page"] for item in request.session.items
             if getattr(item, "originalname", None) == "test_page_runs_as_written" and item.module is request.module]
    runs = _PageRuns([_rel(p) for p in pages], tmp_path_factory.mktemp("doc-pages"))
    yield runs
    runs.close()


@pytest.mark.parametrize("page", RUNNABLE_PAGES, ids=_rel)
def test_page_runs_as_written(page, page_runs):
    returncode, output, seconds = page_runs.result(_rel(page))
    print(output)
    assert returncode == 0, f"{_rel(page)} (its lane's process, {seconds:.0f} s) failed:\n{output[-12000:]}"


# ------------------------------------------------------------------------------------------------
# The bookkeeping: nothing escapes, nothing is skipped without a reason
# ------------------------------------------------------------------------------------------------
def test_every_block_is_found_and_run_or_declared():
    langs = {}
    for page in PAGES:
        for lang, first, code in _blocks(page):
            where = f"{_rel(page)}:{first}"
            assert lang in PYTHON | SHELL | DATA | NOT_CODE, f"{where}: unknown block language {lang!r}"
            langs[lang] = langs.get(lang, 0) + 1
            if lang in NOT_CODE:  # a synopsis, not a command
                for line in code.splitlines():
                    if line.strip().startswith("gni "):
                        assert _is_synopsis(line), f"{where}: a runnable command in a ```text block: {line}"
    assert langs.get("python", 0) >= 10 and langs.get("bash", 0) >= 10, langs
    # every opening fence of every page was found (an odd fence count would hide blocks)
    for page in PAGES:
        fences = re.findall(r"^[ \t]*(?:```|~~~)", page.read_text(), flags=re.M)
        assert len(fences) == 2 * len(_blocks(page)), _rel(page)


def test_commands_not_run_are_in_the_docs_and_covered_elsewhere():
    commands = {_key(command) for page in PAGES for lang, first, code in _blocks(page) if lang in SHELL
                for _, command in _commands(lang, code, first)}
    for command, reason in NOT_RUN.items():
        assert command in commands, f"not in the docs any more: {command}"
        tests = re.findall(r"(tests/[\w/]+\.py)::(\w+)", reason)
        assert tests, f"no covering test named for: {command}"
        for path, name in tests:
            assert re.search(rf"^def {name}\(", (ROOT / path).read_text(), flags=re.M), f"{path}::{name}"
    assert all(command in commands for cmds in PAGE_INPUTS.values() for command in cmds)


def test_plain_gni_lines_run_in_the_page_process_and_the_others_with_bash():
    assert _gni_argv("gni run a --grid 'Omega=linspace(0, 2, 5)' --h 1   # a comment; | >") == [
        "run", "a", "--grid", "Omega=linspace(0, 2, 5)", "--h", "1"]
    for line in ("gni control --example x --print > x.toml", "gni info a.nc | head", "gni run $MODEL",
                 "FOO=1 gni run a", "gni run a && gni info b", "gni run \"$(cat m)\"", "gni info *.nc",
                 "python -c 'print(1)'", "gni run 'unclosed"):
        assert _gni_argv(line) is None, line
    # the installed `gni` script itself runs here too: some documented gni line is bash's
    commands = [c for page in PAGES for lang, first, code in _blocks(page) if lang in SHELL
                for _, c in _commands(lang, code, first) if _key(c) not in NOT_RUN]
    assert any(c.startswith("gni ") and _gni_argv(c) is None for c in commands)
    assert sum(_gni_argv(c) is not None for c in commands) >= 30


def test_command_lines_are_split_as_bash_reads_them():
    code = "gni run a \\\n    --h 1   # comment\n# only a comment\n\ngni info x.nc\n"
    assert _commands("bash", code, 10) == [(10, "gni run a      --h 1   # comment"), (14, "gni info x.nc")]
    assert _key("gni run a      --h 1   # comment") == "gni run a --h 1"
    assert _key("echo '# not a comment'") == "echo '# not a comment'"
    assert _commands("console", "$ gni models\nname  params\n", 1) == [(1, "gni models")]
