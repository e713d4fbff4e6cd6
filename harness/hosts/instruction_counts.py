"""Instructions per communication step of the benchmark's three native loops, counted by valgrind's callgrind.

Wall-clock figures move with the load of a shared machine; the instructions a loop executes do not.
For each loop (our master's compiled loop on the native FMUs, the plain C host, the math floor:
harness/hosts/c_baselines.py) a child Python process runs pendulum_case1/vud once under
``valgrind --tool=callgrind``, collecting only inside libffi's ``ffi_call``: every call from Python
into C (the loops, the FMI calls of instantiation, initialisation and clean-up), none of Python's own
work.  The count at two horizons, subtracted and divided by the difference of their steps, is the
cost of one communication step with every fixed cost removed:

    instructions per step = (Ir(long) - Ir(short)) / (steps(long) - steps(short))

split by where the instructions ran: libm, the FMUs' binaries, the loop's own C (master_loop.c with
loop_interface.h, plain_c_host.c, math_floor.c), the rest (libffi, libc, the dynamic loader).  Run
``python -m harness.hosts.instruction_counts LOOP STOP`` for one child's loop alone.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from harness.fmu_build import native as build_native

from .. import scenario as scenarios
from ..master import Master
from . import c_baselines

LOOPS = ("master", "host", "floor")
CATEGORIES = ("libm", "fmus", "loop", "other")
COLLECTED = "ffi_call"  # callgrind collects inside this function only (Python -> C calls)
LOOP_SOURCES = ("master_loop.c", "loop_interface.h", "plain_c_host.c", "math_floor.c")
SCENARIO, CONTROLLER = c_baselines.SCENARIO, c_baselines.CONTROLLER


class InstructionCountError(RuntimeError):
    """valgrind is missing, or a counted run failed."""


def native_fmus() -> dict:
    """{model identifier: native FMI 2.0 FMU}, built if they are not (before a count: never under valgrind)."""
    return {name: paths[2] for name, paths in build_native.ensure_built().items()}


def run_loop(loop: str, stop: float, fmu_paths: dict | None) -> None:
    """One run of ``loop`` on pendulum_case1/vud over ``stop`` seconds (what a child counts)."""
    scenario = scenarios.configure(SCENARIO, CONTROLLER, None, stop)
    if loop == "master":
        Master(scenario, "feedthrough", fmu_paths).run()
    elif loop == "host":
        c_baselines.plain_host(scenario, fmu_paths)
    elif loop == "floor":
        c_baselines.math_floor(scenario)
    else:
        raise ValueError(f"loop {loop!r}; valid: {', '.join(LOOPS)}")


def self_costs(callgrind_file: Path) -> dict:
    """{category: instructions} of a callgrind output file (events Ir, positions line): each cost line's
    self cost, by the object (ob=) and source file (fl=, fi=, fe=) it ran in; the inclusive cost that
    follows a calls= line is not counted again."""
    names = {"ob": {}, "fl": {}}
    current = {"ob": "", "fl": ""}
    file = ""
    totals = dict.fromkeys(CATEGORIES, 0)
    after_call = False
    compressed = re.compile(r"^\((\d+)\)(?: (.*))?$")

    def resolve(kind: str, value: str) -> str:
        found = compressed.match(value)
        if not found:
            return value
        key, name = found.groups()
        table = names["ob" if kind == "ob" else "fl"]
        if name is not None:
            table[key] = name
        return table.get(key, "")

    for line in callgrind_file.read_text(errors="replace").splitlines():
        if not line or line[0] in "#":
            continue
        if line[0].isdigit() or line[0] in "+-*":
            if after_call:
                after_call = False
                continue
            parts = line.split()
            if len(parts) < 2:
                continue
            totals[_category(current["ob"], file)] += int(parts[1])
            continue
        key, _, value = line.partition("=")
        if key in ("ob", "cob"):
            name = resolve("ob", value)
            if key == "ob":
                current["ob"] = name
        elif key in ("fl", "fi", "fe", "cfi", "cfl"):
            name = resolve("fl", value)
            if key == "fl":
                current["fl"] = file = name
            elif key in ("fi", "fe"):
                file = name
        elif key == "fn":
            file = current["fl"]
        elif key == "calls":
            after_call = True
    return totals


def _category(obj: str, file: str) -> str:
    if "libm.so" in obj or "libm-" in obj:
        return "libm"
    if "/binaries/" in obj:
        return "fmus"
    if Path(file).name in LOOP_SOURCES:
        return "loop"
    return "other"


def count(loop: str, stop: float) -> tuple:
    """(steps, {category: instructions}) of one child run of ``loop`` under callgrind."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        raise InstructionCountError("valgrind is not installed (apt-get install valgrind): instruction counts "
                                    "need it")
    steps = scenarios.configure(SCENARIO, CONTROLLER, None, stop).steps
    native_fmus()
    with tempfile.TemporaryDirectory(prefix="afc_callgrind_") as folder:
        output = Path(folder) / "callgrind.out"
        environment = {**os.environ, "PYTHONHASHSEED": "0"}
        completed = subprocess.run(
            [valgrind, "--tool=callgrind", "--vgdb=no", "--collect-atstart=no", f"--toggle-collect={COLLECTED}",
             f"--callgrind-out-file={output}", sys.executable, "-m", __name__, loop, repr(stop)],
            capture_output=True, text=True, env=environment)
        if completed.returncode != 0 or not output.is_file():
            last = (completed.stderr.strip().splitlines() or ["no message"])[-1]
            raise InstructionCountError(f"the callgrind run of the {loop} loop failed: {last}")
        return steps, self_costs(output)


def per_step(loop: str, short: float, long: float, counts=None) -> dict:
    """{category: instructions per step, "total": their sum} of ``loop``, from runs over ``short`` and
    ``long`` seconds (``counts``: the counting function, for tests)."""
    counts = counts or count
    steps_short, short_costs = counts(loop, short)
    steps_long, long_costs = counts(loop, long)
    if steps_long <= steps_short:
        raise ValueError(f"the long horizon ({long:g} s) must have more steps than the short one ({short:g} s)")
    figures = {key: (long_costs[key] - short_costs[key]) / (steps_long - steps_short) for key in CATEGORIES}
    figures["total"] = sum(figures[key] for key in CATEGORIES)
    return figures


def main(argv=None) -> int:
    """The child: ``python -m harness.hosts.instruction_counts LOOP STOP`` runs one loop once."""
    loop, stop = (argv if argv is not None else sys.argv[1:])
    run_loop(loop, float(stop), native_fmus())
    return 0


if __name__ == "__main__":
    sys.exit(main())
