"""Instructions a step: gnipy's native loop against the hand-written kernel, counted by valgrind.

On a virtual machine without hardware counters (`perf stat` says "not supported") the time of a
step cannot be split by instruction; valgrind's callgrind counts every instruction executed, with
its address. Each count runs in a fresh process under callgrind with collection off until the
timed call: `callgrind_control -i on/off` switches it around `NativeLoop.run` (gnipy's compiled
loop from gnipy's start state, as section 7 times it) or around the hand-written kernel's run
(`benchmarks.numba_gni`). The difference between runs of 2S and S steps is S steps' worth, without
the call's fixed cost. The native code has no symbols: its object code is kept when gnipy compiles
it (`gnipy.native.engine.compile_ir`, wrapped here), callgrind's addresses (`--dump-instr=yes`)
are taken relative to the loop's address in the engine and matched with the disassembly
(`objdump -d`), which gives gnipy's divisions and square roots a step (`vdivsd`, `vsqrtsd`) and
how often each part of the loop runs a step (`--blocks`).

    python -m benchmarks.instructions                      # rolling ball ex. 2, gni-trapezoid
    python -m benchmarks.instructions --case chaplygin_sphere --method gni-trapezoid --hand chaplygin-sphere

Needs valgrind (with callgrind_control) and binutils' objdump; 3-4 minutes a case on the 2-core machine. The numbers
are in docs/user-guide/native-design.md ("Where a native step's time goes").
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r'''
import os, subprocess, sys
import gnipy.native.engine as engine
from benchmarks import numba_gni
from benchmarks.native import compiled_loop
from benchmarks.run import build

name, method, hand, S, which, obj_path = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5], sys.argv[6]
compile_ir = engine.compile_ir

def keep(ir):  # the object code of the loop, kept for its disassembly
    obj = compile_ir(ir)
    with open(obj_path, "wb") as f:
        f.write(obj)
    return obj

engine.compile_ir = keep
h = 0.01
system, q0, v0 = build(name)
case = numba_gni.CASES[hand]
s0 = case.initial_state(h)
loop, carry0 = compiled_loop(system, q0, v0, method, h, S)
loop.run(carry0, h, [S])
case.run(s0, h, S)
print("ADDRESS", hex(loop._engine.get_function_address("gnipy_run")), flush=True)  # (the loaded engine)

def collect(on):
    subprocess.run(["callgrind_control", "-i", "on" if on else "off", str(os.getpid())], check=True,
                   capture_output=True)

collect(True)
if which == "hand":
    case.run(s0, h, S)
else:
    loop.run(carry0, h, [S])
collect(False)
'''


def _run(case: str, method: str, hand: str, steps: int, which: str, folder: Path) -> tuple[Path, Path, int]:
    """One process under callgrind: (its profile, the loop's object code, the loop's address)."""
    out, obj = folder / f"{which}-{steps}.callgrind", folder / f"{which}-{steps}.o"
    env = dict(os.environ, GNIPY_NATIVE_CACHE="0", PYTHONPATH=str(ROOT))  # compiled here: its object code kept
    proc = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", "--dump-instr=yes",
                           f"--callgrind-out-file={out}", sys.executable, "-c", _CHILD, case, method, hand,
                           str(steps), which, str(obj)], capture_output=True, text=True, env=env, cwd=ROOT)
    match = re.search(r"^ADDRESS (0x[0-9a-f]+)$", proc.stdout, flags=re.M)
    if proc.returncode != 0 or match is None:
        raise RuntimeError(f"callgrind run failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return out, obj, int(match.group(1), 16)


def _costs(profile: Path) -> collections.Counter:
    """Instructions executed at each address (callgrind's `positions: instr line`, compressed:
    `+n`/`-n` relative to the previous address, `*` the same; a `calls=` line's cost line is the
    callee's inclusive cost, not counted here)."""
    costs, last, callee = collections.Counter(), 0, False
    for line in profile.read_text().splitlines():
        if not line or line[0] not in "0123456789+-*":
            callee = callee or line.startswith("calls=")
            continue
        fields = line.split()
        a = fields[0]
        last = (int(a, 16) if a.startswith("0x") else last + int(a[1:]) if a[0] == "+"
                else last - int(a[1:]) if a[0] == "-" else last if a == "*" else int(a))
        if callee:
            callee = False
            continue
        if len(fields) >= 3:
            costs[last] += int(fields[2])
    return costs


def _disassembly(obj: Path) -> tuple[dict[int, str], int]:
    """`({offset: mnemonic}, size)` of `gnipy_run` in the object code."""
    size = 0
    for line in subprocess.run(["objdump", "-t", str(obj)], capture_output=True, text=True, check=True).stdout.splitlines():
        fields = line.split()
        if fields and fields[-1] == "gnipy_run" and " F " in line:
            size = int(fields[-2], 16)
    ops = {}
    for line in subprocess.run(["objdump", "-d", "--no-show-raw-insn", "-M", "intel", str(obj)], capture_output=True,
                               text=True, check=True).stdout.splitlines():
        m = re.match(r"\s+([0-9a-f]+):\s+(\S+)", line)
        if m and int(m.group(1), 16) < size:
            ops[int(m.group(1), 16)] = m.group(2)
    return ops, size


def count(case: str = "rolling_ball_ex2", method: str = "gni-trapezoid", hand: str = "rolling-ball-ex2",
          steps: int = 2000) -> dict:
    """Instructions a step of gnipy's loop (with its divisions, square roots and how often its
    instructions run a step) and of the hand-written kernel, from runs of `steps` and 2·`steps`."""
    with tempfile.TemporaryDirectory(prefix="gnipy-instructions-") as tmp:
        folder = Path(tmp)

        def at(s, which):  # (all instructions, those of gnipy_run by offset, its disassembly)
            profile, obj, address = _run(case, method, hand, s, which, folder)
            costs = _costs(profile)
            ops, size = _disassembly(obj)
            inside = {a - address: c for a, c in costs.items() if address <= a < address + size}
            return sum(costs.values()), inside, ops

        (h1, _, _), (h2, _, _) = at(steps, "hand"), at(2 * steps, "hand")
        (t1, in1, ops), (t2, in2, _) = at(steps, "loop"), at(2 * steps, "loop")
        diff = {a: in2.get(a, 0) - in1.get(a, 0) for a in set(in1) | set(in2)}
        by_freq = collections.Counter()
        for c in diff.values():
            by_freq[round(c / steps, 2)] += c / steps
        return {"hand": (h2 - h1) / steps, "loop": (t2 - t1) / steps,
                "divisions": sum(c for a, c in diff.items() if ops.get(a, "").startswith(("vdiv", "div"))) / steps,
                "square_roots": sum(c for a, c in diff.items() if "sqrt" in ops.get(a, "")) / steps,
                "by_frequency": {f: n for f, n in sorted(by_freq.items()) if n >= 1.0}}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="rolling_ball_ex2", help="benchmarks.run's case name")
    parser.add_argument("--method", default="gni-trapezoid")
    parser.add_argument("--hand", default="rolling-ball-ex2", help="benchmarks.numba_gni's case name")
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--blocks", action="store_true", help="also how often gnipy's instructions run a step")
    args = parser.parse_args(argv)
    for tool in ("valgrind", "callgrind_control", "objdump"):
        if shutil.which(tool) is None:
            sys.exit(f"benchmarks.instructions needs {tool} on PATH")
    r = count(args.case, args.method, args.hand, args.steps)
    print(f"{args.case}, {args.method}: gnipy's native loop {r['loop']:.0f} instructions a step "
          f"({r['divisions']:.1f} divisions, {r['square_roots']:.1f} square roots); hand-written ({args.hand}) "
          f"{r['hand']:.0f}: {r['loop'] / r['hand']:.2f}x")
    if args.blocks:
        for freq, n in r["by_frequency"].items():
            print(f"  instructions that run {freq:g} times a step: {n:.0f} a step")


if __name__ == "__main__":
    main()
