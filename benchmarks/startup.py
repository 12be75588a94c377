"""Section 9 of the suite: start-up (issue 30): what `import gnipy` and the `gni` command cost
before they do anything.

Each command runs in fresh processes, one after the other, and the best of `runs` is kept (the
start-up of an interpreter is a fixed cost plus the machine's noise: the minimum is the cost).
`import gnipy` is the wall time of ``python -c "import gnipy"`` minus that of
``python -c "pass"`` (the interpreter itself); the `gni` commands are timed whole (``gni --help``,
``gni methods``). Beside each wall time, the CPU time (user + system) of the process, which a
shared machine inflates less. The section also lists the optional packages (:mod:`gnipy.extras`)
that `import gnipy` loads: none.

    python -m benchmarks.startup            # this section alone, printed (best of 5)
"""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

#: the target of issue 30: `import gnipy` at most this many seconds
TARGET_IMPORT_S = 1.5

#: the packages of gnipy's extras (pyproject.toml), none of which `import gnipy` may load
OPTIONAL = ("xarray", "netCDF4", "zarr", "matplotlib", "typer", "rich", "dask", "distributed", "llvmlite")

#: run with the names of :data:`OPTIONAL`: prints those that `import gnipy` loaded, then the
#: gnipy.cli and gnipy.experiments modules it loaded (two comma-separated lines)
_PROBE = """import sys
import gnipy
print(",".join(m for m in sys.argv[1:] if m in sys.modules))
print(",".join(sorted(m for m in sys.modules if m.startswith(("gnipy.cli", "gnipy.experiments")))))
"""


def gni_command() -> str:
    """The `gni` script beside this interpreter (a virtual environment's), else the one on PATH."""
    beside = Path(sys.executable).with_name("gni")
    return str(beside) if beside.exists() else (shutil.which("gni") or "gni")


def time_process(cmd: list[str], runs: int) -> tuple[float, float]:
    """`(best wall s, best CPU s)` of `runs` fresh runs of `cmd` (output discarded; it must exit 0)."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    walls, cpus = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        walls.append(time.perf_counter() - t)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return min(walls), min(cpus)


def measure(runs: int = 5) -> dict:
    """The section's numbers: `{"python": (wall, cpu), "import": (wall, cpu), "gni --help": ...,
    "gni methods": ..., "loaded": optional packages loaded by import gnipy, "modules": gnipy.cli /
    gnipy.experiments modules loaded by it}`; the import's times are net of the interpreter's."""
    py = sys.executable
    bare = time_process([py, "-c", "pass"], runs)
    full = time_process([py, "-c", "import gnipy"], runs)
    out = {"python": bare, "import": (full[0] - bare[0], full[1] - bare[1])}
    for args in (["--help"], ["methods"]):
        out["gni " + " ".join(args)] = time_process([gni_command(), *args], runs)
    probe = subprocess.run([py, "-c", _PROBE, *OPTIONAL], check=True, capture_output=True, text=True)
    loaded, modules = (probe.stdout + "\n\n").split("\n")[:2]
    out["loaded"], out["modules"] = [m for m in loaded.split(",") if m], [m for m in modules.split(",") if m]
    return out


def bench_startup(cfg, rep, results: dict, load) -> None:
    """The section: `import gnipy` (net of the interpreter) and `gni --help`, `gni methods`."""
    from benchmarks.run import g

    runs = 5 if cfg.name == "full" else 3
    sec = rep.open(
        "startup", "9. Start-up: import gnipy and the gni command (issue 30)",
        f"Fresh processes (CPU), best of {runs}: `python -c \"import gnipy\"` minus `python -c \"pass\"`, and the "
        f"`gni` commands whole (interpreter included); CPU = user + system time of the process (target: import "
        f"gnipy ≤ {TARGET_IMPORT_S:g} s).",
        ["command", "wall s (best)", "CPU s (best)"], background_load=load)
    with rep.case(sec, "start-up"):
        m = measure(runs)
        results["startup"] = {"import_s": m["import"][0]}
        rep.row(sec, ["python -c \"pass\"", g(m["python"][0]), g(m["python"][1])],
                f"python -c 'pass': {g(m['python'][0])} s")
        for key in ("import", "gni --help", "gni methods"):
            label = "import gnipy (net)" if key == "import" else key
            rep.row(sec, [label, g(m[key][0]), g(m[key][1])], f"{label}: {g(m[key][0])} s (CPU {g(m[key][1])} s)")
        rep.note(sec, "optional packages loaded by `import gnipy`: " + (", ".join(m["loaded"]) or "none")
                 + "; gnipy.cli / gnipy.experiments modules: " + (", ".join(m["modules"]) or "none"))
    rep.close(sec)


def startup_targets(results: dict, how_far, g) -> list[list[str]]:
    """The summary rows of this section (see :func:`benchmarks.run.targets`)."""
    r = results.get("startup")
    if not r:
        return []
    met, far = how_far(r["import_s"], TARGET_IMPORT_S, False)
    return [[f"import gnipy ≤ {TARGET_IMPORT_S:g} s (fresh process, net of the interpreter)", f"{g(r['import_s'])} s",
             met, far]]


def main() -> int:
    """Print the section's numbers against the target."""
    m = measure()
    print(f"python -c 'pass'     {m['python'][0]:.3f} s (CPU {m['python'][1]:.3f} s)")
    ok = "met" if m["import"][0] <= TARGET_IMPORT_S else "MISSED"
    print(f"import gnipy (net)   {m['import'][0]:.3f} s (CPU {m['import'][1]:.3f} s); "
          f"target <= {TARGET_IMPORT_S} s: {ok}")
    for key in ("gni --help", "gni methods"):
        print(f"{key:<20} {m[key][0]:.3f} s (CPU {m[key][1]:.3f} s)")
    print("optional packages loaded by import gnipy:", ", ".join(m["loaded"]) or "none")
    print("gnipy.cli / gnipy.experiments modules loaded by import gnipy:", ", ".join(m["modules"]) or "none")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
