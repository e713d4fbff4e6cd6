"""Memory a host process keeps per FMU life cycle, and whose code allocated it.

One cycle is what a host that re-instantiates per run does: instantiate, set up, enter and exit
initialisation, terminate, free (fmpy's ``FMU2Slave``, a new one per cycle). Each FMU is measured in a
fresh process, after a warm-up:

* ``rss_kib``: the slope, in KiB per cycle, of a least-squares line through the resident set size,
  sampled every ``every`` cycles after ``gc.collect()`` (what a user sees; C++ allocations count too);
* ``traced_kib``: the same slope of the memory tracemalloc traces (every Python object, exact), taken
  after the RSS phase (tracemalloc's own tables count in the RSS) and ``traced_warm_up`` cycles
  under tracemalloc (what the first traced cycles allocate once is left out);
* ``by_owner``: the traced memory kept over the traced phase, per cycle, split by the traceback of
  each allocation: ``fmu_sources`` (a frame of the FMU's own Python sources: a file of its resources
  folder outside ``resources/pythonfmu``, or the FMU script that pythonfmu's wrapper runs again at
  every instantiate under its module's name; our code, for our FMUs), ``pythonfmu_python`` (pythonfmu's Python base class, the innermost
  resources frame in ``resources/pythonfmu``), ``pythonfmu_wrapper`` (no Python frame of the FMU: the
  C code of the FMU's binary, pythonfmu's wrapper, called straight from the host's FMI call) and
  ``host`` (the rest: fmpy, ctypes). Objects reused from CPython's free lists keep the traceback of
  their first allocation, so a few bytes per cycle may land with another owner.

Run it by hand to reproduce the figures of docs/performance.md ("Memory per instantiate/free
cycle"), e.g. ``python tests/memory_cycles.py --traced-cycles 3000 --rss-cycles 3000 build/fmus/*.fmu``.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

OWNERS = ("fmu_sources", "pythonfmu_python", "pythonfmu_wrapper", "host")
TRACED_FRAMES = 12  # deep enough to reach from an allocation in numpy's Python code back to the FMU's frame


def _measure_one(path: str, unzip_dir: str, warm_up: int, rss_cycles: int, traced_warm_up: int, traced_cycles: int,
                 every: int) -> dict:
    """The figures of one FMU, in this process (see the module's text)."""
    import gc
    import linecache
    import os
    import tracemalloc

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(path)
    extract(path, unzip_dir)
    model = md.coSimulation.modelIdentifier
    resources = os.path.join(os.path.realpath(unzip_dir), "resources") + os.sep
    pythonfmu_sources = os.path.join(resources, "pythonfmu") + os.sep
    with open(os.path.join(resources, "slavemodule.txt")) as slave_module:
        script_name = slave_module.readline().strip()  # the file name of the script's re-executions

    def rss_kib():
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))

    def cycle(k):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=model, instanceName=f"cycle{k}")
        fmu.instantiate(loggingOn=False)
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.terminate()
        fmu.freeInstance()

    def slope(xs, ys):
        mx, my = sum(xs) / len(xs), sum(ys) / len(ys)
        return sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sum((x - mx) ** 2 for x in xs)

    def growth(cycles, measure):  # KiB per cycle: the slope through a sample every `every` cycles
        done, kib = [], []
        for k in range(1, cycles + 1):
            cycle(k)
            if k % every == 0:
                gc.collect()
                done.append(k)
                kib.append(measure())
        return round(slope(done, kib), 3)

    def owner(traceback):
        for frame in reversed(traceback):  # the most recent frame first
            if frame.filename == script_name:
                return "fmu_sources"
            filename = os.path.realpath(frame.filename)
            if filename.startswith(resources):
                return "pythonfmu_python" if filename.startswith(pythonfmu_sources) else "fmu_sources"
        call = traceback[-1]  # the host's call into the FMU's binary (fmpy: `res = f(*args)`)
        return "pythonfmu_wrapper" if "f(*args)" in linecache.getline(call.filename, call.lineno) else "host"

    for k in range(warm_up):
        cycle(k)
    gc.collect()
    rss = growth(rss_cycles, rss_kib)
    tracemalloc.start(TRACED_FRAMES)
    for k in range(traced_warm_up):
        cycle(k)
    gc.collect()
    before = tracemalloc.take_snapshot()
    traced = growth(traced_cycles, lambda: tracemalloc.get_traced_memory()[0] / 1024)
    gc.collect()
    after = tracemalloc.take_snapshot()
    ignore = [tracemalloc.Filter(False, tracemalloc.__file__), tracemalloc.Filter(False, linecache.__file__)]
    kept = dict.fromkeys(OWNERS, 0)
    for stat in after.filter_traces(ignore).compare_to(before.filter_traces(ignore), "traceback"):
        kept[owner(stat.traceback)] += stat.size_diff
    return {"traced_kib": traced, "rss_kib": rss,
            "by_owner": {name: round(size / 1024 / traced_cycles, 3) for name, size in kept.items()},
            "instances": sum(1 for o in gc.get_objects() if type(o).__name__ == model),
            "sys_path": len(sys.path)}


def measure(fmu_paths: dict, work_dir, warm_up: int, rss_cycles: int, traced_warm_up: int, traced_cycles: int,
            every: int) -> dict:
    """{name: figures} for each FMU of {name: path}, the FMUs in parallel, each in a fresh process."""
    counts = (warm_up, rss_cycles, traced_warm_up, traced_cycles, every)
    processes = {name: subprocess.Popen(
        [sys.executable, __file__, "--one", str(path), str(pathlib.Path(work_dir) / name), *map(str, counts)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for name, path in fmu_paths.items()}
    measured = {}
    for name, process in processes.items():
        stdout, stderr = process.communicate(timeout=1800)
        if process.returncode != 0:
            raise RuntimeError(f"{name}: exit {process.returncode}\n{stderr}")
        measured[name] = json.loads(stdout)
    return measured


def main(argv=None) -> None:
    if argv is None and sys.argv[1:2] == ["--one"]:
        path, unzip_dir, *counts = sys.argv[2:]
        print(json.dumps(_measure_one(path, unzip_dir, *map(int, counts))), flush=True)
        # a pythonfmu 0.7 library without our exit handler may abort in the C++ exit handlers
        # (docs/using_fmus.md): the figures are written, so the process ends before them
        os._exit(0)
    parser = argparse.ArgumentParser(description="memory kept per instantiate/free cycle, per FMU")
    parser.add_argument("fmus", nargs="+", type=pathlib.Path)
    parser.add_argument("--warm-up", type=int, default=40)
    parser.add_argument("--rss-cycles", type=int, default=300)
    parser.add_argument("--traced-warm-up", type=int, default=0)
    parser.add_argument("--traced-cycles", type=int, default=150)
    parser.add_argument("--every", type=int, default=10)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as work_dir:
        measured = measure({path.stem: path.resolve() for path in args.fmus}, work_dir,
                           args.warm_up, args.rss_cycles, args.traced_warm_up, args.traced_cycles, args.every)
    print(json.dumps(measured, indent=1))


if __name__ == "__main__":
    main()
