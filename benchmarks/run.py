"""The gnipy benchmark suite (issue 5): one command runs every case and writes ``BENCHMARKS.md``.

Run it from the repository root (``benchmarks/`` is not installed; it imports the installed gnipy)::

    python -m benchmarks                  # the full suite (about 10-15 min on 2 cores)
    python -m benchmarks --quick          # a smoke test (< 2 min): fewer steps and repetitions
    python -m benchmarks --out FILE.md    # write the report elsewhere (default: BENCHMARKS.md at the root)
    python -m benchmarks --sections per-step,batched   # only some sections
    python -m benchmarks --plain          # plain-text console output instead of rich tables

The console shows one line per case as soon as it is measured (with its ratio to the baseline) and
a table at the end of each section; the Markdown report holds the machine description, the exact
command, every table, and a summary of how far each target is met.

What is measured (all gnipy runs in float64, the step size is h = 0.01 unless said otherwise):

1. **per-step** -- the time per step of one trajectory, in µs/step (on the CPU, the median over
   several fresh processes: see the section's note): ``gnipy.simulate(...,
   steps=S, save_every=S)`` (so only the first and last nodes are saved) for the rolling ball
   example 2 (gni-trapezoid, Cayley), the contact oscillator (rattle, gni-midpoint) and the
   physical Chaplygin sphere (gni-trapezoid), after a warm-up call with the same step count (which
   compiles); the time of a call with ``steps=1`` (the same compiled program) is reported as the
   fixed per-call cost. Side by side, the NumPy + ``scipy.optimize.root`` baseline
   (:mod:`benchmarks.numpy_gni`) for the same case and method, and the speed-up
   (NumPy µs/step / gnipy µs/step).
2. **batched** -- the throughput of an ensemble, in trajectory-steps per second:
   ``gnipy.simulate(system, method, Q, V, ...)`` with Q of shape (B, n) and V of shape (B, N)
   (a vmapped ensemble; the members are perturbations of the default initial condition, with V on
   the constraints), for B = 10³, 10⁴, 10⁵, and one unbatched trajectory (B = 1) for comparison.
   Compilation is excluded (warm-up call with the same shapes and step count). The wall time is
   that of the whole ``gnipy.simulate`` call, including its checks of the initial conditions; the
   fixed cost of a call (``steps=1``) and the marginal throughput without it are reported too.
3. **compile** -- the compile latency, in fresh Python processes: the wall time of the first
   ``gnipy.simulate`` call minus that of an identical second call in the same process (= compile
   + first-call overheads), and the time of ``import gnipy``.
4. **memory** -- the peak resident memory (``ru_maxrss``) of a 10⁷-step run with save stride 1000,
   in a fresh process, next to the resident memory after ``import gnipy`` (before the run); for
   ``gnipy.simulate`` and for ``gnipy.streaming.simulate_to_file`` (netCDF, streamed in chunks).
5. **accuracy** -- at matched accuracy against SciPy's DOP853 on the Chaplygin sphere over T = 1000
   (and T = 100): gnipy's gni-trapezoid at several h, its final error against a DOP853 reference
   (rtol 1e-13; its own accuracy is estimated by the rtol 1e-12 solution), then the loosest DOP853
   tolerance reaching the same final error (:func:`benchmarks.continuous.tuned_dop853`) and the
   wall times of both (gnipy without compilation; compilation reported separately).
7. **native** -- the native CPU backend (`backend="native"`, issue 16) against the same GNI steps
   written by hand in Numba (:mod:`benchmarks.numba_gni`), one trajectory and batched, and the
   native build time in fresh processes (:mod:`benchmarks.native`). Sections 1-5 run the XLA
   backend (`backend="xla"`) explicitly.
8. **monitor** -- what checking the verdicts at every node costs (issue 29): µs/step of the same
   loop without and with the check, on both backends (:mod:`benchmarks.monitor`).
9. **startup** -- what `import gnipy` (net of the interpreter, target ≤ 1.5 s) and the `gni`
   command (``gni --help``, ``gni methods``) cost in fresh processes, best of 5, and which optional
   packages `import gnipy` loads (none; issue 30, :mod:`benchmarks.startup`).
10. **bicycle** -- the Whipple bicycle written once (SymBRiM's, a `sympy.physics.mechanics` System)
   in gnipy (`from_sympy`, dla and sgni-trapezoid) and as PyDy users simulate it (Kane's equations,
   PyDy's Cython right-hand side, SciPy's DOP853 at matched accuracy): error, time per simulated
   second, energy and front-contact drift over 100 s (issue 32, :mod:`benchmarks.bicycle`; needs
   the `[bench]` extra, and runs only when named: ``--sections bicycle``).
11. **control** -- optimal control against CasADi + IPOPT on the same discretization: the control
   guide's worked problems at two resolutions, gnipy cold, from a warm compilation cache and the
   solve alone (fresh processes), CasADi's build and solve (issue 34, :mod:`benchmarks.control`;
   needs casadi, the `[bench]` extra, and runs only when named: ``--sections control``).
6. **GPU** -- if JAX sees a GPU, sections 1 and 2 are run on it as well (the CPU rows are always
   run on the CPU device); the subprocess sections (3, 4) run on the CPU (``JAX_PLATFORMS=cpu``).

Timing: ``time.perf_counter()`` around calls that end with ``jax.block_until_ready``; every
timed number is the median (and the minimum) of several timed repetitions after a warm-up
(the count is in the report). A failing case prints its error and the others go on.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import functools
import inspect
import itertools
import json
import math
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
H = 0.01  # the step size of sections 1-4

# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Config:
    """The sizes of one run of the suite (see :data:`FULL` and :data:`QUICK`)."""

    name: str
    reps: int  # timed repetitions of each timed case, after one warm-up call
    per_step_steps: int  # steps of one timed gnipy run (section 1, and B = 1 in section 2)
    per_step_processes: int  # fresh processes that time the gnipy side of section 1 on the CPU
    batch_processes: int  # fresh processes that time section 2 on the CPU
    numpy_steps: int  # steps of one timed run of the NumPy baseline
    batch_sizes: tuple[int, ...]
    batch_work: int  # trajectory-steps per timed batched call: steps = batch_work // B
    compile_runs: int  # fresh processes per model (section 3)
    compile_steps: int
    memory_steps: int
    memory_stride: int
    memory_chunk_steps: int  # chunk length of the streamed run
    accuracy_T: tuple[float, ...]
    accuracy_h: tuple[float, ...]
    dop_reps: int  # timed DOP853 solves at the tuned tolerance
    idle_sample_s: float  # how long the background CPU load is sampled before each section


FULL = Config(
    name="full", reps=5, per_step_steps=2_000, per_step_processes=5, batch_processes=3, numpy_steps=2_000, batch_sizes=(1_000, 10_000, 100_000),
    batch_work=4_000_000, compile_runs=5, compile_steps=1_000, memory_steps=10_000_000, memory_stride=1_000,
    memory_chunk_steps=1_000_000, accuracy_T=(1000.0, 100.0), accuracy_h=(0.02, 0.01, 0.005), dop_reps=5,
    idle_sample_s=1.0,
)
QUICK = Config(
    name="quick", reps=3, per_step_steps=200, per_step_processes=1, batch_processes=1, numpy_steps=200, batch_sizes=(1_000,), batch_work=200_000,
    compile_runs=1, compile_steps=1_000, memory_steps=100_000, memory_stride=1_000, memory_chunk_steps=20_000,
    accuracy_T=(100.0,), accuracy_h=(0.01,), dop_reps=3, idle_sample_s=0.3,
)

SECTIONS = ("per-step", "batched", "compile", "memory", "accuracy", "native", "monitor", "startup", "bicycle", "control")
#: the sections a plain `python -m benchmarks` runs: all but the bicycle's, which needs the [bench]
#: extra (PyDy, Cython) and about 5 minutes (its compilations alone take 2): ask for it by name
DEFAULT_SECTIONS = tuple(s for s in SECTIONS if s not in ("bicycle", "control"))

#: (case, method) of section 1; the case names are those of benchmarks.numpy_gni.
PER_STEP_CASES = (
    ("rolling_ball_ex2", "gni-trapezoid"),
    ("contact_oscillator", "rattle"),
    ("contact_oscillator", "gni-midpoint"),
    ("chaplygin_sphere", "gni-trapezoid"),
)
#: (case, method) of section 2. The contact oscillator runs gni-midpoint, the GNI of its NumPy
#: baseline, so that the B = 1 row is the one of section 1.
BATCH_CASES = (("rolling_ball_ex2", "gni-trapezoid"), ("contact_oscillator", "gni-midpoint"))
#: (case, method) of sections 3 and 4.
COMPILE_CASES = (
    ("rolling_ball_ex2", "gni-trapezoid"),
    ("contact_oscillator", "gni-midpoint"),
    ("chaplygin_sphere", "gni-trapezoid"),
)
#: The rolling ball ex. 2 is not among them: the turntable feeds it energy (its speed grows without bound,
#: ~100x by T = 1000 in DOP853 too), so at T = 10^5 its Newton solves take tens of iterations per step
#: and the run measures that growth rather than the memory. The Chaplygin sphere is the ball case.
MEMORY_CASES = (
    ("contact_oscillator", "gni-midpoint", "simulate"),
    ("contact_oscillator", "gni-midpoint", "stream"),
    ("chaplygin_sphere", "gni-trapezoid", "simulate"),
)

LABELS = {
    "rolling_ball_ex2": "rolling ball ex. 2",
    "contact_oscillator": "contact oscillator",
    "chaplygin_sphere": "Chaplygin sphere",
    "suslov": "Suslov's problem",
}

# targets of issue 5
TARGET_SPEEDUP = 200.0
TARGET_BALL_US = 1.5
TARGET_THROUGHPUT = 1e7
TARGET_COMPILE_S = 3.0
TARGET_RSS_MB = 500.0

# ---------------------------------------------------------------------------------------------
# Small helpers: timing, formatting, machine description
# ---------------------------------------------------------------------------------------------


@dataclass
class Timing:
    """Wall times (s) of repeated calls, and the result of the last call."""

    times: list[float]
    last: object = None

    @property
    def median(self) -> float:
        return statistics.median(self.times)

    @property
    def min(self) -> float:
        return min(self.times)

    @property
    def n(self) -> int:
        return len(self.times)


def time_calls(fn, reps: int) -> Timing:
    """Call `fn()` `reps` times and return the wall times (`fn` must block until its result is ready)."""
    times, out = [], None
    for _ in range(reps):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return Timing(times, out)


def timed(fn):
    """`(result, seconds)` of one call."""
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def g(x, digits: int = 3) -> str:
    """`x` with `digits` significant digits (plain notation where it is short)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    x = float(x)
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 10 ** (digits + 3):
        decimals = max(digits - 1 - math.floor(math.log10(abs(x))), 0)
        return f"{x:,.{decimals}f}"
    return f"{x:.{digits - 1}e}"


def med_min(t: Timing, scale: float = 1.0, digits: int = 3) -> str:
    """'median (min)' of a Timing, times `scale`."""
    return f"{g(t.median * scale, digits)} ({g(t.min * scale, digits)})"


def mrate(x: float) -> str:
    """A rate in millions per second."""
    return g(x / 1e6)


def _read(path: str) -> str:
    try:
        return Path(path).read_text()
    except OSError:
        return ""


def cpu_busy_fraction(interval: float) -> float | None:
    """The fraction of all cores busy over `interval` seconds (from /proc/stat), or None."""

    def sample():
        fields = _read("/proc/stat").splitlines()[0].split()[1:]
        vals = [int(v) for v in fields]
        idle = vals[3] + (vals[4] if len(vals) > 4 else 0)
        return sum(vals), idle

    try:
        t0, i0 = sample()
        time.sleep(interval)
        t1, i1 = sample()
    except (IndexError, ValueError):
        return None
    return None if t1 == t0 else 1.0 - (i1 - i0) / (t1 - t0)


def cpu_ticks() -> tuple[int, int] | None:
    """`(all ticks, steal ticks)` of all cores so far (from /proc/stat), or None. Steal is the time the
    hypervisor gave this virtual machine's cores to someone else: invisible to the load average."""
    try:
        vals = [int(v) for v in _read("/proc/stat").splitlines()[0].split()[1:]]
        return sum(vals[:8]), vals[7]
    except (IndexError, ValueError):
        return None


def git_revision() -> str:
    """The commit of the checkout, and whether the working tree has uncommitted changes."""
    try:
        rev = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], check=False, capture_output=True,
                             text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"],
                               check=False, capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if not rev:
        return "unknown"
    return f"{rev} + uncommitted changes ({len(dirty.splitlines())} modified tracked files)" if dirty else rev


def machine_info() -> dict[str, str]:
    """CPU, cores, memory, OS, Python and library versions, JAX backend and devices."""
    import importlib.metadata as md

    import jax

    cpuinfo = _read("/proc/cpuinfo")
    model = next((ln.split(":", 1)[1].strip() for ln in cpuinfo.splitlines() if ln.startswith("model name")),
                 platform.processor() or "unknown")
    mem_kib = next((int(ln.split()[1]) for ln in _read("/proc/meminfo").splitlines() if ln.startswith("MemTotal")),
                   None)
    os_release = next((ln.split("=", 1)[1].strip('"') for ln in _read("/etc/os-release").splitlines()
                       if ln.startswith("PRETTY_NAME=")), "")
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = os.cpu_count()

    def version(pkg):
        try:
            return md.version(pkg)
        except md.PackageNotFoundError:
            return "not installed"

    info = {
        "CPU": model,
        "cores": f"{os.cpu_count()} logical ({affinity} usable by this process)",
        "memory": f"{mem_kib / 2**20:.1f} GiB" if mem_kib else "unknown",
        "OS": f"{os_release} ({platform.system()} {platform.release()}, {platform.machine()})".strip(),
        "Python": f"{platform.python_implementation()} {platform.python_version()}",
        "jax / jaxlib": f"{version('jax')} / {version('jaxlib')}",
        "numpy / scipy": f"{version('numpy')} / {version('scipy')}",
        "gnipy / equinox / optimistix": f"{version('gnipy')} / {version('equinox')} / {version('optimistix')}",
        "llvmlite / numba": f"{version('llvmlite')} / {version('numba')}",
        "gnipy checkout": git_revision(),
        "JAX backend": jax.default_backend(),
        "JAX devices": ", ".join(f"{d.platform}:{d.id} ({d.device_kind})" for d in jax.devices()),
        "float64": str(bool(jax.config.jax_enable_x64)),
    }
    flags = {k: v for k, v in os.environ.items() if k.startswith(("XLA_", "JAX_")) or k in ("OMP_NUM_THREADS",)}
    if flags:
        info["environment"] = ", ".join(f"{k}={v}" for k, v in sorted(flags.items()))
    return info


# ---------------------------------------------------------------------------------------------
# The report: console output as it goes, Markdown at the end
# ---------------------------------------------------------------------------------------------


@dataclass
class Section:
    """One section of the report: a table with an explanation, notes and errors."""

    key: str
    title: str
    intro: str
    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)
    background_load: float | None = None
    elapsed_s: float = 0.0
    steal: float | None = None  # the fraction of the cores' time stolen by the hypervisor during the section
    skipped: str | None = None


class Report:
    """Collects the sections; prints each case when it is measured and each table when its section ends."""

    def __init__(self, plain: bool = False):
        self.sections: list[Section] = []
        self.console = None
        if not plain:
            try:
                from rich.console import Console

                self.console = Console(highlight=False, width=None if sys.stdout.isatty() else 200)
            except ImportError:
                self.console = None

    def say(self, text: str, style: str | None = None) -> None:
        if self.console is not None:
            self.console.print(text, style=style, markup=False)
        else:
            print(text, flush=True)

    def open(self, key, title, intro, columns, background_load=None) -> Section:
        sec = Section(key, title, intro, list(columns), background_load=background_load)
        self.sections.append(sec)
        self.say("")
        self.say(f"== {title} ==", style="bold")
        if background_load is not None:
            self.say(f"   (background CPU load before the section: {100 * background_load:.0f}% of all cores)")
        return sec

    def row(self, sec: Section, cells, line: str) -> None:
        sec.rows.append([str(c) for c in cells])
        self.say(f"[{sec.key}] {line}")

    def note(self, sec: Section, text: str) -> None:
        sec.notes.append(text)
        self.say(f"[{sec.key}] note: {text}", style="dim")

    @contextlib.contextmanager
    def case(self, sec: Section, label: str):
        """Run one case; a failure is printed and recorded, and the suite goes on."""
        try:
            yield
        except Exception as e:  # noqa: BLE001 -- a failing case must not stop the suite
            msg = f"{label}: {type(e).__name__}: {e}"
            sec.errors.append(msg)
            self.say(f"[{sec.key}] FAILED {msg}", style="bold red")
            self.say(traceback.format_exc(), style="red")

    def close(self, sec: Section) -> None:
        if not sec.rows:
            return
        if self.console is not None:
            from rich.table import Table

            table = Table(title=sec.title, show_lines=False)
            for c in sec.columns:
                table.add_column(c, overflow="fold")
            for r in sec.rows:
                table.add_row(*r)
            self.console.print(table)
        else:
            widths = [max(len(c), *(len(r[i]) for r in sec.rows)) for i, c in enumerate(sec.columns)]
            print("  ".join(c.ljust(w) for c, w in zip(sec.columns, widths)))
            for r in sec.rows:
                print("  ".join(x.ljust(w) for x, w in zip(r, widths)))

    @staticmethod
    def md_table(columns, rows) -> str:
        def esc(s):
            return str(s).replace("|", "\\|")

        lines = ["| " + " | ".join(esc(c) for c in columns) + " |", "|" + "---|" * len(columns)]
        lines += ["| " + " | ".join(esc(x) for x in r) + " |" for r in rows]
        return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# The cases
# ---------------------------------------------------------------------------------------------

def build(name):
    """`(system, q0, v0)` of a benchmark case (q0, v0 None: the model's default initial condition).

    Self-contained: its source is also sent to the child processes of sections 3 and 4.
    """
    import gnipy

    if name == "rolling_ball_ex2":
        from gnipy.models.rolling_ball import example_2

        return example_2()
    return gnipy.make_system(name.replace("_", "-")), None, None


_SYSTEMS: dict[str, tuple] = {}


def case_system(name):
    """`build(name)`, cached (one System object per case for the whole suite)."""
    if name not in _SYSTEMS:
        _SYSTEMS[name] = build(name)
    return _SYSTEMS[name]


def initial_state(system, q0, v0):
    """The (q0, v0) actually used: the given ones or the system's defaults."""
    if q0 is None or v0 is None:
        q0, v0 = system.defaults[0], system.defaults[1]
    return np.asarray(q0, dtype=float), np.asarray(v0, dtype=float)


def ensemble(name, system, q0, v0, B, seed=0):
    """B initial conditions near the case's one, with V on the constraints: `(Q (B, n), V (B, N))`.

    Rolling ball: positions and angular velocities perturbed by 0.05 N(0, 1), the translational
    velocity from the constraints (`velocity_from_constraints`). Contact oscillator: q and (ẏ, ż)
    perturbed by 0.05 N(0, 1), ẋ = −y ż (the constraint ẋ + y ż = 0).
    """
    rng = np.random.default_rng(seed)
    q0, v0 = initial_state(system, q0, v0)
    Q = q0 + 0.05 * rng.standard_normal((B, q0.size))
    if name == "rolling_ball_ex2":
        from gnipy.models.rolling_ball import velocity_from_constraints

        p = system.parameters
        omega = v0[2:] + 0.05 * rng.standard_normal((B, 3))
        V = np.array([velocity_from_constraints(p, Q[i], omega[i]) for i in range(B)])
    elif name == "contact_oscillator":
        V = np.empty((B, 3))
        V[:, 1:] = v0[1:] + 0.05 * rng.standard_normal((B, 2))
        V[:, 0] = -Q[:, 1] * V[:, 2]
    else:
        raise ValueError(f"no ensemble for case {name!r}")
    return Q, V


def gnipy_runner(system, method, q0, v0, h=H):
    """`run(steps)`: one blocking `gnipy.simulate` call saving only the first and last nodes."""
    import jax

    import gnipy

    def run(steps):
        sol = gnipy.simulate(system, method, q0, v0, h=h, steps=steps, save_every=steps, backend="xla")
        jax.block_until_ready(sol.q)
        return sol

    return run


def measure(run, steps: int, reps: int):
    """Time `run(steps)`: `(first call s, Timing of reps calls, Timing of reps calls with steps=1, last result)`.

    The first call is the warm-up (it compiles); the `steps=1` calls run the same compiled program
    when `run` saves only the first and last nodes, and measure the fixed cost of a call.
    """
    sol, first = timed(functools.partial(run, steps))
    t = time_calls(functools.partial(run, steps), reps)
    t1 = time_calls(functools.partial(run, 1), reps)
    return first, t, t1, sol


def device_name(dev) -> str:
    return f"{dev.platform}:{dev.id}"


# ---------------------------------------------------------------------------------------------
# Section 1: per-step time
# ---------------------------------------------------------------------------------------------


def bench_per_step(cfg: Config, rep: Report, devices, results: dict, load) -> None:
    import jax

    from benchmarks import numpy_gni

    P = cfg.per_step_processes
    sec = rep.open(
        "per-step", "1. Per-step time of one trajectory",
        f"One trajectory, h = {H}. **gnipy**: wall time of `gnipy.simulate(system, method, q0, v0, h={H}, "
        f"steps=S, save_every=S)` with S = {cfg.per_step_steps:,} (only the first and last nodes saved; the same "
        f"horizon T = S·h as the NumPy baseline), {cfg.reps} timed calls after one warm-up call "
        "with the same S (the warm-up compiles; its wall time is the 'first call' column), and as many calls with "
        "steps = 1 (the same compiled program: the fixed cost of a `simulate` call, validation and dispatch, "
        "'call cost'). A process's µs/step is the marginal cost of a step, (median(S) − median(1))/(S − 1). "
        f"On the CPU this is measured in {P} fresh processes and the table gives the **median over the "
        "processes** and, in brackets, each process's value: on this 2-core virtual machine a process runs either "
        "in a fast or in a slow mode for its whole life (about 1.5× apart, with the same compiled code; not "
        "explained by core pinning or address-space layout), so one process is not a measurement. 'With call cost' "
        "is median(S)/S (median over the processes). "
        f"**NumPy**: the baseline `benchmarks.numpy_gni` (hand-derived NumPy, one `scipy.optimize.root` per step, "
        f"Python loop) for the same case and method, {cfg.numpy_steps:,} steps per run, median (min) of "
        f"{cfg.reps} runs after a 20-step warm-up. **Speed-up** = NumPy median µs/step ÷ gnipy median µs/step "
        f"(target ≥ {TARGET_SPEEDUP:g}×; rolling ball ex. 2 target ≤ {TARGET_BALL_US} µs/step). "
        "'Newton its/step' is gnipy's mean number of Newton iterations per step (`Solution.iterations`), "
        "'NumPy nfev/step' the mean number of residual evaluations of `scipy.optimize.root` per step "
        "(0: explicit RATTLE).",
        ["device", "case", "method", "gnipy µs/step median (per process)", "with call cost µs/step", "call cost µs",
         "first call s",
         "Newton its/step", "NumPy µs/step median (min)", "NumPy nfev/step", "speed-up ×"],
        background_load=load,
    )
    numpy_times: dict[tuple[str, str], Timing] = {}
    S = cfg.per_step_steps
    children: list[dict] = []
    if any(dev.platform == "cpu" for dev in devices):
        spec = {"runs": [[name, method, 1, S] for name, method in PER_STEP_CASES], "reps": cfg.reps, "h": H}
        for i in range(P):
            rep.say(f"[per-step] gnipy on the CPU: process {i + 1} of {P}")
            children.append(run_child(_CHILD_TIMING, spec)[0])
    for dev in devices:
        for name, method in PER_STEP_CASES:
            label = f"{LABELS[name]} {method} on {device_name(dev)}"
            with rep.case(sec, label), jax.default_device(dev):
                # the marginal cost of a step: the fixed cost of a call (steps = 1) taken out, so that
                # gnipy runs the same horizon as the NumPy baseline (T = S·h) without the call
                # overhead dominating a short run
                if dev.platform == "cpu" and children:
                    runs = [c[f"{name} {method} 1"] for c in children]
                    if any(r["failed"] for r in runs):
                        raise RuntimeError("a step failed")
                    per_process = [(statistics.median(r["S"]) - statistics.median(r["one"])) / (S - 1) * 1e6
                                   for r in runs]
                    us = statistics.median(per_process)
                    with_call = statistics.median(statistics.median(r["S"]) for r in runs) / S * 1e6
                    call = statistics.median(statistics.median(r["one"]) for r in runs)
                    first = statistics.median(r["first_s"] for r in runs)
                    its = runs[0]["its"]
                    shown = f"{g(us)} ({', '.join(g(x) for x in per_process)})"
                else:
                    system, q0, v0 = case_system(name)
                    first, t, t1, sol = measure(gnipy_runner(system, method, q0, v0), S, cfg.reps)
                    its = float(np.asarray(sol.iterations)[0]) / S
                    us = (t.median - t1.median) / (S - 1) * 1e6
                    per_process = [us]
                    with_call, call = t.median / S * 1e6, t1.median
                    shown = g(us)
                if (name, method) not in numpy_times:  # the baseline does not depend on the JAX device
                    case = numpy_gni.get_case(name, method)
                    case.run(20, H)
                    numpy_times[(name, method)] = time_calls(functools.partial(case.run, cfg.numpy_steps, H),
                                                             cfg.reps)
                tn = numpy_times[(name, method)]
                np_us = tn.median / cfg.numpy_steps * 1e6
                results.setdefault("numpy_us", {})[(name, method)] = np_us
                speedup = np_us / us
                results.setdefault("per_step", {})[(device_name(dev), name, method)] = {
                    "us": us, "us_processes": per_process, "np_us": np_us, "speedup": speedup}
                rep.row(
                    sec,
                    [device_name(dev), LABELS[name], method, shown, g(with_call),
                     g(call * 1e6), g(first), g(its), med_min(tn, 1e6 / cfg.numpy_steps),
                     g(tn.last["nfev"] / cfg.numpy_steps), g(speedup)],
                    f"{label}: {shown} µs/step, call cost {g(call * 1e6)} µs, "
                    f"first call {g(first)} s | NumPy {g(np_us)} µs/step | {g(speedup)}× faster",
                )
    rep.note(sec, "The rolling ball ex. 2 gains energy from the turntable (its speed grows steadily, by a factor "
                  "of ~50-100 at T = 1000, in DOP853 as well), and faster steps need more Newton iterations: "
                  f"both gnipy and the NumPy baseline are therefore timed over the same horizon, T = "
                  f"{g(cfg.numpy_steps * H)}.")
    rep.close(sec)


# ---------------------------------------------------------------------------------------------
# Section 2: batched throughput
# ---------------------------------------------------------------------------------------------


def bench_batched(cfg: Config, rep: Report, devices, results: dict, load) -> None:
    import jax

    sec = rep.open(
        "batched", "2. Batched throughput",
        f"B trajectories at once: `gnipy.simulate(system, method, Q, V, h={H}, steps=S, save_every=S)` with Q "
        "(B, n), V (B, N) (a vmapped ensemble; members = the default initial condition perturbed by 0.05·N(0, 1), "
        f"V on the constraints), S = {cfg.batch_work:,} // B. B = 1 is one unbatched trajectory with "
        f"S = {cfg.per_step_steps:,}. Time: median (min) of {cfg.reps} calls after a warm-up call with the same "
        "shapes and S (which compiles), whole `simulate` call (checks of the initial conditions included). "
        f"On the CPU each row is measured in {cfg.batch_processes} fresh processes (see section 1 for why) and "
        "the times are those of the process with the median throughput; 'per process' lists each process's. "
        "**Throughput** = B·S / median time, in millions of trajectory-steps per second (target ≥ 10 M/s). "
        "'Call cost' = median time of a call with steps = 1 (same compiled program; checks, transfers, "
        "dispatch); 'marginal' = B·(S−1) / (median − call cost), the throughput without that fixed cost. "
        "'vs NumPy' = throughput ÷ (1 / NumPy µs/step of section 1), the NumPy baseline running one "
        "trajectory (it has no batch mode).",
        ["device", "case", "method", "B", "S", "time s median (min)", "throughput M/s (per process)", "call cost s",
         "marginal M/s", "vs B=1 ×", "vs NumPy ×"],
        background_load=load,
    )

    def steps_of(B):
        return cfg.per_step_steps if B == 1 else max(cfg.batch_work // B, 10)

    children: list[dict] = []
    if any(dev.platform == "cpu" for dev in devices):
        spec = {"runs": [[name, method, B, steps_of(B)] for name, method in BATCH_CASES
                         for B in (1, *cfg.batch_sizes)], "reps": cfg.reps, "h": H}
        for i in range(cfg.batch_processes):
            rep.say(f"[batched] on the CPU: process {i + 1} of {cfg.batch_processes}")
            children.append(run_child(_CHILD_TIMING, spec, timeout=1800.0)[0])
    for dev in devices:
        for name, method in BATCH_CASES:
            base = None
            for B in (1, *cfg.batch_sizes):
                label = f"{LABELS[name]} {method} B={B} on {device_name(dev)}"
                with rep.case(sec, label), jax.default_device(dev):
                    S = steps_of(B)
                    if dev.platform == "cpu" and children:
                        runs = [c[f"{name} {method} {B}"] for c in children]
                        if any(r["failed"] for r in runs):
                            raise RuntimeError(f"{max(r['failed'] for r in runs)} members failed")
                        rates = [B * S / statistics.median(r["S"]) for r in runs]
                        mid = runs[sorted(range(len(runs)), key=lambda i: rates[i])[len(runs) // 2]]
                        first = mid["first_s"]
                        t, t1 = Timing(mid["S"]), Timing(mid["one"])
                        shown = f"{mrate(B * S / t.median)} ({', '.join(mrate(x) for x in rates)})"
                    else:
                        system, q0, v0 = case_system(name)
                        Q, V = (q0, v0) if B == 1 else ensemble(name, system, q0, v0, B)
                        first, t, t1, sol = measure(gnipy_runner(system, method, Q, V), S, cfg.reps)
                        if int(sol.result) != 0:
                            raise RuntimeError(f"{int(np.sum(np.asarray(sol.results) != 0))} members failed")
                        shown = mrate(B * S / t.median)
                    rate = B * S / t.median
                    marginal = B * (S - 1) / max(t.median - t1.median, 1e-12)
                    if B == 1:
                        base = rate
                    np_us = results.get("numpy_us", {}).get((name, method))
                    vs_np = rate * np_us / 1e6 if np_us else None
                    results.setdefault("batched", {})[(device_name(dev), name, method, B)] = {
                        "rate": rate, "rate_best": B * S / t.min, "marginal": marginal}
                    rep.row(
                        sec,
                        [device_name(dev), LABELS[name], method, f"{B:,}", f"{S:,}", med_min(t), shown,
                         g(t1.median), mrate(marginal), g(rate / base) if base else "–", g(vs_np)],
                        f"{label}: S={S:,}, {g(t.median)} s (min {g(t.min)}), {shown} M traj-steps/s "
                        f"(marginal {mrate(marginal)} M/s, call cost {g(t1.median)} s, first call {g(first)} s)"
                        + (f" | {g(vs_np)}× the NumPy baseline" if vs_np else ""),
                    )
    rep.close(sec)


# ---------------------------------------------------------------------------------------------
# Sections 3 and 4: fresh processes
# ---------------------------------------------------------------------------------------------

_CHILD_COMPILE = r'''
import json, sys, time
t0 = time.perf_counter()
import gnipy
t_import = time.perf_counter() - t0
import jax
import jax.monitoring

# where the first call's time goes: JAX reports the duration of each stage of each compilation
stages = {"jaxpr_trace_duration": "trace_s", "jaxpr_to_mlir_module_duration": "lower_s",
          "backend_compile_duration": "xla_s"}
spent = {v: 0.0 for v in stages.values()}
spent["programs"] = 0
spent["largest_xla_s"] = 0.0

def listener(event, duration, **kwargs):
    key = stages.get(event.rsplit("/", 1)[-1])
    if key is not None:
        spent[key] += duration
        if key == "xla_s":
            spent["programs"] += 1
            spent["largest_xla_s"] = max(spent["largest_xla_s"], duration)

jax.monitoring.register_event_duration_secs_listener(listener)
spec = json.loads(sys.argv[1])
system, q0, v0 = build(spec["case"])

def run():
    sol = gnipy.simulate(system, spec["method"], q0, v0, h=spec["h"], steps=spec["steps"], backend="xla")
    jax.block_until_ready(sol.q)

t = time.perf_counter(); run(); first = time.perf_counter() - t
first_spent = dict(spent)
t = time.perf_counter(); run(); second = time.perf_counter() - t
print(json.dumps({"import_s": t_import, "first_s": first, "second_s": second, **first_spent}))
'''

_CHILD_TIMING = r'''
import json, sys, time
import numpy as np
import gnipy
import jax
spec = json.loads(sys.argv[1])
out = {}
for name, method, B, S in spec["runs"]:
    system, q0, v0 = build(name)
    Q, V = (q0, v0) if B == 1 else ensemble(name, system, q0, v0, B)

    def run(steps):
        sol = gnipy.simulate(system, method, Q, V, h=spec["h"], steps=steps, save_every=steps, backend="xla")
        jax.block_until_ready(sol.q)
        return sol

    def times(steps):
        ts = []
        for _ in range(spec["reps"]):
            t = time.perf_counter()
            run(steps)
            ts.append(time.perf_counter() - t)
        return ts

    t = time.perf_counter()
    sol = run(S)
    first = time.perf_counter() - t
    failed = int(np.sum(np.asarray(sol.results) != 0)) if B > 1 else int(sol.result != 0)
    its = float(np.asarray(sol.iterations)[0]) / (B * S)  # Newton iterations per trajectory-step
    out[f"{name} {method} {B}"] = {"first_s": first, "S": times(S), "one": times(1), "failed": failed, "its": its}
print(json.dumps(out))
'''


_CHILD_MEMORY = r'''
import json, os, resource, sys, tempfile, time

def status_kib(field):
    """A memory field of /proc/self/status (VmRSS: resident now, VmHWM: peak resident), in KiB."""
    for line in open("/proc/self/status"):
        if line.startswith(field + ":"):
            return int(line.split()[1])

import gnipy
import jax
spec = json.loads(sys.argv[1])
system, q0, v0 = build(spec["case"])
if spec["mode"] == "stream":
    try:
        import gnipy.streaming
    except ImportError as e:
        print(json.dumps({"skipped": f"gnipy.streaming is not importable: {e}"}))
        sys.exit(0)
base_peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
base_now = status_kib("VmRSS")
t = time.perf_counter()
out = {}
if spec["mode"] == "simulate":
    # compile first, with a short run that saves as many nodes (the same compiled program), to tell
    # the memory of the compilation from that of the run
    nodes = spec["steps"] // spec["stride"] + 1
    sol = gnipy.simulate(system, spec["method"], q0, v0, h=spec["h"], steps=nodes - 1, save_every=1, backend="xla")
    jax.block_until_ready(sol.q)
    out["compiled_peak_kib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    del sol
    t = time.perf_counter()
    sol = gnipy.simulate(system, spec["method"], q0, v0, h=spec["h"], steps=spec["steps"],
                         save_every=spec["stride"], backend="xla")
    jax.block_until_ready(sol.q)
    out["nodes"] = int(sol.q.shape[0])
else:
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "run.nc")
        res = gnipy.streaming.simulate_to_file(system, spec["method"], q0, v0, path=path, h=spec["h"],
                                               steps=spec["steps"], save_every=spec["stride"],
                                               chunk_steps=spec["chunk_steps"])
        out["nodes"] = int(res.nodes)
        out["chunks"] = int(res.chunks)
        out["file_bytes"] = os.path.getsize(path)
out["run_s"] = time.perf_counter() - t
out["base_peak_kib"] = base_peak
out["base_now_kib"] = base_now
out["peak_kib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
out["end_now_kib"] = status_kib("VmRSS")
out["vmhwm_kib"] = status_kib("VmHWM")
print(json.dumps(out))
'''


#: Starts its arguments as a grandchild and passes its exit code on. Linux carries a process's
#: `ru_maxrss` over fork/vfork + exec (the new process starts with the high-water mark of the address
#: space it was forked from), so a child started directly from this (large) benchmark process would
#: report this process's peak; started from this small launcher, it reports its own.
_LAUNCHER = "import subprocess, sys; sys.exit(subprocess.call(sys.argv[1:]))"


def run_child(source: str, spec: dict, timeout: float = 900.0) -> tuple[dict, float]:
    """Run `source` (with the source of :func:`build` prepended) in a fresh Python process on the CPU.

    The child gets `json.dumps(spec)` as its argument and prints one JSON line last. It is started
    through :data:`_LAUNCHER` so that its `ru_maxrss` is its own. JAX's persistent compilation cache is
    switched off so that every process compiles. Returns `(that dict, wall time of the whole process
    measured here)`.
    """
    env = dict(os.environ, JAX_PLATFORMS="cpu", JAX_ENABLE_COMPILATION_CACHE="false")
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *filter(None, [env.get("PYTHONPATH")])])
    t = time.perf_counter()
    script = "".join(inspect.getsource(f) + "\n\n" for f in (build, initial_state, ensemble)) + source
    cmd = [sys.executable, "-c", _LAUNCHER, sys.executable, "-c", script, json.dumps(spec)]
    proc = subprocess.run(cmd, check=False, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"child process exited with {proc.returncode}: {proc.stderr.strip()[-2000:]}")
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"child process printed no result; stderr: {proc.stderr.strip()[-2000:]}")
    return json.loads(lines[-1]), wall


def bench_compile(cfg: Config, rep: Report, results: dict, load) -> None:
    sec = rep.open(
        "compile", "3. Compile latency (fresh processes)",
        f"For each case, {cfg.compile_runs} fresh Python processes (CPU, JAX persistent compilation cache off) "
        f"each run: `import gnipy` (timed), then the same `gnipy.simulate(system, method, h={H}, "
        f"steps={cfg.compile_steps:,})` twice. **Compile latency** = first call − second call (compilation plus "
        "first-call overheads, e.g. tracing and JAX's own lazy initialisation); median (min) over the processes "
        f"(target ≤ {TARGET_COMPILE_S:g} s). 'process' is the wall time of the whole child process, measured "
        "from outside (interpreter start, imports, both calls). **Where the first call goes** (medians, from "
        "`jax.monitoring`'s compile events): tracing to jaxprs, lowering to MLIR, and XLA's backend compilation, "
        "summed over the programs compiled during the first call; 'largest' is the XLA time of the biggest program "
        "(the jitted integration loop).",
        ["case", "method", "compile latency s median (min)", "first call s", "second call s", "trace s", "lower s",
         "XLA compile s (programs)", "largest XLA s", "import gnipy s median (min)", "process s"],
        background_load=load,
    )
    for name, method in COMPILE_CASES:
        label = f"{LABELS[name]} {method}"
        with rep.case(sec, label):
            outs, walls = [], []
            for _ in range(cfg.compile_runs):  # one after the other: they must not share the cores
                spec = {"case": name, "method": method, "h": H, "steps": cfg.compile_steps}
                out, wall = run_child(_CHILD_COMPILE, spec)
                outs.append(out)
                walls.append(wall)
            lat = Timing([o["first_s"] - o["second_s"] for o in outs])
            imp = Timing([o["import_s"] for o in outs])
            first, second, trace, lower, xla, largest = (
                statistics.median(o[k] for o in outs)
                for k in ("first_s", "second_s", "trace_s", "lower_s", "xla_s", "largest_xla_s"))
            programs = int(statistics.median(o["programs"] for o in outs))
            results.setdefault("compile", {})[(name, method)] = {"latency": lat.median, "import_s": imp.median}
            rep.row(
                sec,
                [LABELS[name], method, med_min(lat), g(first), g(second), g(trace), g(lower), f"{g(xla)} ({programs})",
                 g(largest), med_min(imp), g(statistics.median(walls))],
                f"{label}: compile latency {g(lat.median)} s (min {g(lat.min)}), first call {g(first)} s "
                f"(trace {g(trace)}, lower {g(lower)}, XLA {g(xla)} s over {programs} programs, largest {g(largest)}), "
                f"second {g(second)} s, import gnipy {g(imp.median)} s ({len(outs)} processes)",
            )
    rep.close(sec)


def bench_memory(cfg: Config, rep: Report, results: dict, load) -> None:
    mb = 1024 / 1e6  # KiB -> MB
    sec = rep.open(
        "memory", "4. Peak memory of a long run (fresh processes)",
        f"A fresh Python process (CPU) imports gnipy, builds the case, then runs {cfg.memory_steps:,} steps with "
        f"h = {H} and save stride {cfg.memory_stride:,} ({cfg.memory_steps // cfg.memory_stride + 1:,} saved "
        "nodes), either with `gnipy.simulate(..., save_every=stride)` or streamed with "
        "`gnipy.streaming.simulate_to_file(..., save_every=stride, chunk_steps="
        f"{cfg.memory_chunk_steps:,})` to a netCDF file in a temporary directory. **Peak RSS** = "
        "`resource.getrusage(RUSAGE_SELF).ru_maxrss` at the end (KiB on Linux, shown in MB = 10⁶ bytes; target "
        f"< {TARGET_RSS_MB:g} MB); **after import** = the same right after `import gnipy` and building the "
        "case (before the run). For `simulate`, the process first compiles the program with a short run that "
        "saves as many nodes (steps = nodes − 1, save_every = 1: the same compiled program), so 'after compile' is "
        "the peak up to there (import + compilation) and the long run itself starts compiled; the streamed run "
        "compiles its chunk program inside. 'VmHWM' is the kernel's peak resident size of the process from "
        "/proc/self/status (a cross-check). 'run s' is the wall time of the long run (streamed: compilation and "
        "file writing included). One process per row.",
        ["case", "method", "driver", "steps", "after import MB", "after compile MB", "peak RSS MB",
         "peak − after import MB", "VmHWM MB", "run s", "notes"],
        background_load=load,
    )
    rep.note(sec, "The rolling ball ex. 2 is not run here: the turntable feeds it energy, its speed grows without "
                  "bound (also in DOP853), and over 10⁷ steps its Newton solves need tens of iterations per step, "
                  "so the run would time that growth; the Chaplygin sphere is the ball case (same space, "
                  "R² × SO(3)).")
    for name, method, mode in MEMORY_CASES:
        label = f"{LABELS[name]} {method} {mode}"
        with rep.case(sec, label):
            spec = {"case": name, "method": method, "mode": mode, "h": H, "steps": cfg.memory_steps,
                    "stride": cfg.memory_stride, "chunk_steps": cfg.memory_chunk_steps}
            out, _ = run_child(_CHILD_MEMORY, spec)
            driver = "simulate" if mode == "simulate" else "streaming.simulate_to_file"
            if "skipped" in out:
                cells = [LABELS[name], method, driver, f"{cfg.memory_steps:,}", *["–"] * 6, out["skipped"]]
                rep.row(sec, cells, f"{label}: skipped ({out['skipped']})")
                continue
            base, peak = out["base_peak_kib"] * mb, out["peak_kib"] * mb
            notes = f"{out['nodes']:,} nodes"
            if mode == "stream":
                notes += f", {out['chunks']} chunks, file {out['file_bytes'] / 1e6:.2f} MB"
            results.setdefault("memory", {})[(name, method, mode)] = {"peak_mb": peak, "base_mb": base}
            rep.row(
                sec,
                [LABELS[name], method, driver, f"{cfg.memory_steps:,}", g(base),
                 g(out["compiled_peak_kib"] * mb) if "compiled_peak_kib" in out else "–", g(peak), g(peak - base),
                 g(out["vmhwm_kib"] * mb), g(out["run_s"]), notes],
                f"{label}: peak RSS {g(peak)} MB (after import {g(base)} MB), run {g(out['run_s'])} s, {notes}",
            )
    rep.close(sec)


# ---------------------------------------------------------------------------------------------
# Section 5: matched accuracy against DOP853
# ---------------------------------------------------------------------------------------------


def bench_accuracy(cfg: Config, rep: Report, devices, results: dict, load) -> None:
    import jax

    from benchmarks import continuous

    name = "chaplygin_sphere"
    sec = rep.open(
        "accuracy", "5. Matched accuracy against DOP853 (Chaplygin sphere)",
        "The physical Chaplygin sphere from its default initial condition up to time T. The **reference** is "
        "`benchmarks.continuous` DOP853 at rtol 1e-13, atol 1e-15; its accuracy is estimated by its distance to "
        "the rtol 1e-12 (atol 1e-14) solution. **gnipy**: `gnipy.simulate(system, 'gni-trapezoid', h=h, "
        "steps=T/h, save_every=T/h)` on the CPU, median (min) of "
        f"{cfg.reps} calls after a warm-up; its **error** is `benchmarks.continuous.final_error` (max abs. "
        "difference over the final q, v̄ and R) against the reference. **DOP853**: "
        "`tuned_dop853(error, reference, T)` finds the loosest rtol (atol = rtol·1e-3) whose final error is at most "
        f"gnipy's; its time is the median (min) of {cfg.dop_reps} `solve_ivp(DOP853)` solves at that tolerance. "
        "**Ratio** = DOP853 median ÷ gnipy median (> 1: gnipy faster; target: gnipy faster).",
        ["T", "h", "gnipy error", "gnipy s median (min)", "Newton its/step", "DOP853 rtol", "DOP853 error",
         "DOP853 nfev", "DOP853 s median (min)", "ratio DOP853/gnipy"],
        background_load=load,
    )
    cpu = devices[0]
    case = continuous.get_case(name)
    system, q0, v0 = case_system(name)
    compile_noted = False
    for T in cfg.accuracy_T:
        with rep.case(sec, f"T = {T:g}"):
            ref, t_ref = timed(functools.partial(case.reference, T))
            ref12 = case.solve(T, 1e-12, 1e-14)
            ref_acc = continuous.final_error(ref12, ref)
            rep.note(sec, f"T = {T:g}: the DOP853 reference (rtol 1e-13) took {g(t_ref)} s ({ref['nfev']:,} "
                          f"evaluations); |rtol 1e-12 solution − reference| = {g(ref_acc)}; the size of the final "
                          f"state: max|q| = {g(np.max(np.abs(ref['q'])))}, max|v| = {g(np.max(np.abs(ref['v'])))}.")
            errors = []
            for h in cfg.accuracy_h:
                with rep.case(sec, f"T = {T:g}, h = {h:g}"), jax.default_device(cpu):
                    steps = round(T / h)
                    run = gnipy_runner(system, "gni-trapezoid", q0, v0, h=h)
                    sol, first = timed(functools.partial(run, steps))
                    t = time_calls(functools.partial(run, steps), cfg.reps)
                    if not compile_noted:
                        compile_noted = True
                        fresh = results.get("compile", {}).get((name, "gni-trapezoid"))
                        rep.note(sec, f"gnipy compilation is excluded from the gnipy times. In this process, the first "
                                      f"call (T = {T:g}, h = {h:g}) took {g(first)} s, {g(first - t.median)} s more "
                                      "than the median call (the same program may already have been compiled by "
                                      "section 1: one program serves every h, T and step count that saves two "
                                      "nodes). "
                                      + (f"In a fresh process (section 3), compiling it takes {g(fresh['latency'])} s."
                                         if fresh else "Section 3 measures the compile latency in a fresh process."))
                    final = {"q": np.asarray(sol.q[-1]), "v": np.asarray(sol.v[-1]), "R": np.asarray(sol.R[-1])}
                    err = continuous.final_error(final, ref)
                    errors.append((h, err))
                    its = float(np.asarray(sol.iterations)[0]) / steps
                    rtol, nfev, err_d = case.tuned_dop853(err, ref, T)
                    td = time_calls(functools.partial(case.solve, T, rtol, rtol * 1e-3), cfg.dop_reps)
                    ratio = td.median / t.median
                    results.setdefault("accuracy", {})[(T, h)] = {"ratio": ratio, "err": err, "gnipy_s": t.median,
                                                                   "dop_s": td.median}
                    rep.row(
                        sec,
                        [g(T), g(h), g(err), med_min(t), g(its), g(rtol), g(err_d), f"{nfev:,}", med_min(td),
                         g(ratio)],
                        f"T={T:g} h={h:g}: gnipy error {g(err)} in {g(t.median)} s | DOP853 rtol {g(rtol)} error "
                        f"{g(err_d)} in {g(td.median)} s ({nfev:,} evaluations) | DOP853/gnipy = {g(ratio)}",
                    )
            if err_floor := [e for _, e in errors if e < 10 * ref_acc]:
                rep.note(sec, f"T = {T:g}: {len(err_floor)} gnipy error(s) within 10× of the reference's own "
                              "accuracy: those comparisons are limited by the reference.")
            if len(errors) >= 2:
                orders = [math.log(e1 / e2) / math.log(h1 / h2) for (h1, e1), (h2, e2) in itertools.pairwise(errors)
                          if e1 > 0 and e2 > 0]
                verdict = ("the error converges at order ≈ 2 as h decreases: it is the GNI's discretization error "
                           "(phase drift), not chaotic divergence" if orders and min(orders) > 1.5 else
                           "the error does not converge at order 2: it may be dominated by divergence of nearby "
                           "trajectories rather than by the discretization")
                rep.note(sec, f"T = {T:g}: observed orders between successive h: "
                              f"{', '.join(g(o) for o in orders)}; {verdict}.")
    rep.close(sec)


# ---------------------------------------------------------------------------------------------
# Targets, Markdown, main
# ---------------------------------------------------------------------------------------------


def _how_far(measured: float, target: float, higher_is_better: bool) -> tuple[str, str]:
    """('yes'/'no', 'how far') for a target."""
    f = measured / target if higher_is_better else target / measured
    met = "yes" if f >= 1 else "no"
    if f >= 1:
        return met, f"met with a {g(f)}× margin"
    if 1 / f < 1.1:
        return met, f"missed by {g(100 * (1 / f - 1), 2)}%"
    return met, f"{g(100 * f, 2)}% of the target (needs {g(1 / f)}× more)"


def targets(results: dict) -> list[list[str]]:
    """The rows of the summary table: target, measured, met?, how far."""
    rows = []
    for (dev, name, method), r in results.get("per_step", {}).items():
        met, far = _how_far(r["speedup"], TARGET_SPEEDUP, True)
        rows.append([f"gnipy ≥ {TARGET_SPEEDUP:g}× faster than NumPy per step: {LABELS[name]} {method} ({dev})",
                     f"{g(r['speedup'])}×", met, far])
        if name == "rolling_ball_ex2":
            met, far = _how_far(r["us"], TARGET_BALL_US, False)
            rows.append([f"rolling ball ex. 2 ≤ {TARGET_BALL_US} µs/step ({dev})", f"{g(r['us'])} µs/step", met,
                         far])
    best: dict = {}
    for (dev, name, method, B), r in results.get("batched", {}).items():
        key = (dev, name, method)
        if key not in best or r["rate"] > best[key][1]:
            best[key] = (B, r["rate"])
    for (dev, name, method), (B, rate) in best.items():
        met, far = _how_far(rate, TARGET_THROUGHPUT, True)
        rows.append([f"batched ≥ 10⁷ trajectory-steps/s: {LABELS[name]} {method} ({dev}, best B)",
                     f"{mrate(rate)} M/s at B = {B:,}", met, far])
    for (name, method), r in results.get("compile", {}).items():
        met, far = _how_far(r["latency"], TARGET_COMPILE_S, False)
        rows.append([f"compile latency ≤ {TARGET_COMPILE_S:g} s: {LABELS[name]} {method}", f"{g(r['latency'])} s",
                     met, far])
    for (name, method, mode), r in results.get("memory", {}).items():
        met, far = _how_far(r["peak_mb"], TARGET_RSS_MB, False)
        rows.append([f"peak RSS < {TARGET_RSS_MB:g} MB: {LABELS[name]} {method}, {mode}", f"{g(r['peak_mb'])} MB",
                     met, far])
    for (T, h), r in results.get("accuracy", {}).items():
        met, far = _how_far(r["ratio"], 1.0, True)
        rows.append([f"gnipy faster than DOP853 at matched accuracy: Chaplygin sphere T = {g(T)}, h = {g(h)}",
                     f"DOP853/gnipy = {g(r['ratio'])} (error {g(r['err'])})", met,
                     f"gnipy {g(r['ratio'])}× faster" if r["ratio"] >= 1 else f"gnipy {g(1 / r['ratio'])}× slower"])
    from benchmarks.native import native_targets

    rows += native_targets(results, _how_far, LABELS, g, mrate)
    from benchmarks.startup import startup_targets

    rows += startup_targets(results, _how_far, g)
    from benchmarks.bicycle import bicycle_targets

    rows += bicycle_targets(results, _how_far, g)
    from benchmarks.control import control_targets

    rows += control_targets(results, _how_far, g)
    return rows


def write_markdown(path: Path, rep: Report, info: dict, meta: dict, results: dict, gpu_note: str) -> None:
    cfg: Config = meta["config"]
    out = [
        "# gnipy benchmarks",
        "",
        (f"Generated by `{meta['command']}` on {meta['date']} in {meta['elapsed_min']:.1f} min "
         f"({cfg.name} mode{'; a smoke test, not representative' if cfg.name == 'quick' else ''}). "
         "See `benchmarks/README.md` and the docstring of `benchmarks/run.py` for what is measured."),
        "",
        (f"Timed numbers are the **median (and min) of {cfg.reps} timed repetitions after a warm-up call** "
         f"(DOP853 solves: {cfg.dop_reps}; fresh-process measurements: {cfg.compile_runs} processes per case for "
         "compile latency, one per row for memory), measured with `time.perf_counter()` around calls that end in "
         f"`jax.block_until_ready`. gnipy runs in float64; h = {H} unless said otherwise."),
        "",
        "## Machine",
        "",
        Report.md_table(["", ""], [[k, v] for k, v in info.items()]),
        "",
        meta["load_note"],
        "",
        "## How far each target is met",
        "",
        Report.md_table(["target", "measured", "met?", "how far"], targets(results)) if results else "(no results)",
        "",
    ]
    for sec in rep.sections:
        out += [f"## {sec.title}", ""]
        if sec.skipped:
            out += [sec.skipped, ""]
            continue
        out += [sec.intro, ""]
        if sec.background_load is not None:
            out += [(f"Background CPU load just before this section (other processes; the suite idle): "
                     f"{100 * sec.background_load:.0f}% of all cores. Section wall time: {sec.elapsed_s:.0f} s."
                     + ("" if sec.steal is None else
                        f" Time stolen by the hypervisor during the section: {100 * sec.steal:.1f}% of the cores' "
                        "time.")), ""]
        if sec.rows:
            out += [Report.md_table(sec.columns, sec.rows), ""]
        out += [f"- {n}" for n in sec.notes]
        out += [f"- **failed** — {e}" for e in sec.errors]
        if sec.notes or sec.errors:
            out.append("")
    out += ["## 6. GPU", "", gpu_note, ""]
    path.write_text("\n".join(out))


def _bench_native(cfg, rep, results, load) -> None:
    from benchmarks.native import bench_native

    bench_native(cfg, rep, results, load)


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m benchmarks", description="Run the gnipy benchmark suite (issue 5).")
    p.add_argument("--quick", action="store_true", help="smoke test (< 2 min): fewer steps and repetitions")
    p.add_argument("--out", default=str(REPO / "BENCHMARKS.md"), help="the Markdown report (default: %(default)s)")
    p.add_argument("--sections", default=",".join(DEFAULT_SECTIONS),
                   help=f"comma-separated subset of {', '.join(SECTIONS)} (default: all but bicycle and control)")
    p.add_argument("--plain", action="store_true", help="plain-text console output (no rich tables)")
    args = p.parse_args(argv)
    args.sections = [s.strip() for s in args.sections.split(",") if s.strip()]
    bad = [s for s in args.sections if s not in SECTIONS]
    if bad:
        p.error(f"--sections: unknown {bad}; choose from {SECTIONS}")
    return args


def _bench_monitor(cfg, rep, results, load) -> None:
    from benchmarks.monitor import bench_monitor

    bench_monitor(cfg, rep, results, load)


def _bench_startup(cfg, rep, results, load) -> None:
    from benchmarks.startup import bench_startup

    bench_startup(cfg, rep, results, load)


def _bench_control(cfg, rep, results, load) -> None:
    from benchmarks.control import bench_control

    bench_control(cfg, rep, results, load)


def _bench_bicycle(cfg, rep, results, load) -> None:
    from benchmarks.bicycle import bench_bicycle

    bench_bicycle(cfg, rep, results, load)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parse_args(argv)
    cfg = QUICK if args.quick else FULL
    command = " ".join(["python -m benchmarks", *(shlex.quote(a) for a in argv)])
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    start = time.perf_counter()
    date = dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    load_start = os.getloadavg()
    rep = Report(plain=args.plain)

    import importlib

    import jax

    importlib.import_module("gnipy")  # imported for its side effect: it enables float64

    info = machine_info()
    rep.say(f"gnipy benchmarks ({cfg.name} mode): {command}", style="bold")
    for k, v in info.items():
        rep.say(f"  {k}: {v}")
    cpu = jax.devices("cpu")[0]
    gpus = [d for d in jax.devices() if d.platform == "gpu" or d.platform == "cuda"]
    devices = [cpu, *gpus]
    gpu_note = (f"GPU(s) visible to JAX: {', '.join(f'{device_name(d)} ({d.device_kind})' for d in gpus)}. "
                "Sections 1 and 2 ran on each of them too (rows with device gpu:…); sections 3-5 ran on the CPU."
                if gpus else "No GPU visible to JAX on this machine (`jax.devices()` lists only the CPU), so the "
                "per-step and batched cases ran on the CPU only.")
    rep.say(f"  GPU: {gpu_note}")

    results: dict = {}
    loads = []
    runners = {
        "per-step": lambda load: bench_per_step(cfg, rep, devices, results, load),
        "batched": lambda load: bench_batched(cfg, rep, devices, results, load),
        "compile": lambda load: bench_compile(cfg, rep, results, load),
        "memory": lambda load: bench_memory(cfg, rep, results, load),
        "accuracy": lambda load: bench_accuracy(cfg, rep, devices, results, load),
        "native": lambda load: _bench_native(cfg, rep, results, load),
        "monitor": lambda load: _bench_monitor(cfg, rep, results, load),
        "startup": lambda load: _bench_startup(cfg, rep, results, load),
        "bicycle": lambda load: _bench_bicycle(cfg, rep, results, load),
        "control": lambda load: _bench_control(cfg, rep, results, load),
    }
    for key in SECTIONS:
        if key not in args.sections:
            continue
        load = cpu_busy_fraction(cfg.idle_sample_s)
        if load is not None:
            loads.append(load)
        t = time.perf_counter()
        ticks = cpu_ticks()
        n_before = len(rep.sections)
        try:
            runners[key](load)
        except Exception as e:  # noqa: BLE001 -- one section failing must not stop the others
            rep.say(f"[{key}] SECTION FAILED: {type(e).__name__}: {e}", style="bold red")
            rep.say(traceback.format_exc(), style="red")
            if len(rep.sections) == n_before:
                rep.sections.append(Section(key, key, "", [], errors=[f"{type(e).__name__}: {e}"]))
            else:
                rep.sections[-1].errors.append(f"section aborted: {type(e).__name__}: {e}")
        if len(rep.sections) > n_before:
            rep.sections[-1].elapsed_s = time.perf_counter() - t
            after = cpu_ticks()
            if ticks is not None and after is not None and after[0] > ticks[0]:
                rep.sections[-1].steal = (after[1] - ticks[1]) / (after[0] - ticks[0])
                rep.say(f"   (hypervisor steal during the section: {100 * rep.sections[-1].steal:.0f}% of the cores' time)")

    elapsed = time.perf_counter() - start
    load_end = os.getloadavg()
    ncores = os.cpu_count() or 1
    busy = max(loads) if loads else None
    loaded = busy is not None and busy > 0.25
    load_note = (
        f"**Machine load.** Load average (1/5/15 min) at the start {', '.join(f'{x:.2f}' for x in load_start)}, at "
        f"the end {', '.join(f'{x:.2f}' for x in load_end)} ({ncores} cores). Background CPU use by other processes, "
        "sampled before each section while the suite was idle: "
        + (", ".join(f"{100 * x:.0f}%" for x in loads) if loads else "not available")
        + " of all cores. "
        + ("**The machine was shared with other work during this run (e.g. colleagues' test suites): timings are "
           "pessimistic and noisier than on an idle machine.**" if loaded else
           "The machine looked idle apart from this suite.")
    )
    meta = {"config": cfg, "command": command, "date": date, "elapsed_min": elapsed / 60, "load_note": load_note}
    out = Path(args.out)
    write_markdown(out, rep, info, meta, results, gpu_note)
    rep.say("")
    rep.say("== How far each target is met ==", style="bold")
    for row in targets(results):
        rep.say(f"  [{row[2]:>3}] {row[0]}: {row[1]} — {row[3]}")
    rep.say(f"\nWrote {out} ({elapsed / 60:.1f} min).", style="bold")
    failed = sum(len(s.errors) for s in rep.sections)
    if failed:
        rep.say(f"{failed} case(s) failed; see above and the report.", style="bold red")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
