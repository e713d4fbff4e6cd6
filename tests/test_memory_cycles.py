"""Memory a long-running host keeps per FMU life cycle.

A host that instantiates, initialises, terminates and frees an FMU again and again in one
process (a sweep worker, a test runner, a tool that re-instantiates per run) must not grow
without bound.  pythonfmu 0.7's C wrapper keeps some memory at every fmi2Instantiate that
no FMU can give back (``findClass``: a list of the MRO of each class the FMU script binds,
the repr and UTF-8 bytes of each MRO entry, the class name's bytes, and the resources path
it puts in sys.path).  A bare pythonfmu FMU (one class, one input, one output, built here
from :data:`BARE_SCRIPT`) keeps about 7 KiB per cycle: findClass also keeps the class it
builds anew at every instantiate.  Our FMUs kept 2.0 to 2.7 KiB per cycle until
``afc_slave_base`` hid the script's imported classes from findClass and interned the
slave classes' reprs; now they keep pythonfmu's residual for one class of 5 or 6 MRO
entries, 0.82 to 0.88 KiB per cycle (figures over 1000 cycles, at LIMIT_KIB below).

Growth per cycle is the slope of a least-squares line through samples taken after a
warm-up, each after gc.collect(): of the resident set size (what a user sees; C++
allocations count there too), then of the memory traced by tracemalloc (every Python
object the wrapper makes, exact, free of the allocator's reuse of free slots).
"""
from __future__ import annotations

import json
import pathlib
import subprocess
import sys
import textwrap

import pytest

import build_fmu

ROOT = pathlib.Path(__file__).resolve().parents[1]
FMU_IDS = tuple(f.model_identifier for f in build_fmu.FMUS)

CYCLES_SCRIPT = textwrap.dedent("""
    import gc, json, sys, tracemalloc
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path, unzip_dir = sys.argv[1], sys.argv[2]
    warm_up, rss_cycles, traced_cycles, every = (int(a) for a in sys.argv[3:7])
    md = read_model_description(path)
    extract(path, unzip_dir)
    model = md.coSimulation.modelIdentifier

    def rss_kib():
        with open("/proc/self/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))

    def cycle(k):
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir, modelIdentifier=model,
                        instanceName=f"cycle{k}")
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

    for k in range(warm_up):
        cycle(k)
    gc.collect()
    rss = growth(rss_cycles, rss_kib)  # first: tracemalloc's own tables count in the RSS
    tracemalloc.start(1)
    traced = growth(traced_cycles, lambda: tracemalloc.get_traced_memory()[0] / 1024)
    print(json.dumps({"traced_kib": traced, "rss_kib": rss,
                      "instances": sum(1 for o in gc.get_objects() if type(o).__name__ == model),
                      "sys_path": len(sys.path)}))
""")

# A minimal pythonfmu 0.7 slave as pythonfmu's own examples write it: nothing of ours.
BARE_SCRIPT = textwrap.dedent("""
    from pythonfmu import Fmi2Causality, Fmi2Slave, Real


    class BareSlave(Fmi2Slave):

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.u = 0.0
            self.y = 0.0
            self.register_variable(Real("u", causality=Fmi2Causality.input))
            self.register_variable(Real("y", causality=Fmi2Causality.output))

        def do_step(self, current_time, step_size):
            self.y = self.u
            return True
""")

WARM_UP, RSS_CYCLES, TRACED_CYCLES, EVERY = 40, 300, 150, 10
# pythonfmu 0.7's residual with our FMUs (5 or 6 MRO entries), traced memory per cycle:
# 0.82 - 0.88 KiB over 1000 cycles, 0.95 - 1.1 KiB over this test's 150 (the same host with
# a native FMU: 0.003 KiB, so fmpy itself keeps nothing).  Before the fix: 2.0 - 2.7 KiB over 1000
# cycles, 2.2 - 3.0 over 150.  The RSS slope over a short window sees less (the leaked
# objects first fill free slots of the allocator's pools): after the fix 0 - 0.4 KiB over
# 300 cycles, 0.45 - 0.85 from cycle 1000 to 3000; before 1.5 - 2.1 over 300 cycles,
# 2.2 - 2.9 from cycle 1000 to 3000.  The limit is the residual with a 40 % margin.
LIMIT_KIB = 1.5
# The bare pythonfmu FMU: 6.8 - 7.0 KiB traced, 5.2 - 7.3 KiB RSS per cycle.  Seeing it proves
# that both measurements see a leak of a few KiB per cycle, and that this one is pythonfmu's.
BARE_AT_LEAST_KIB = 4.0


def run_cycles(fmu_paths: dict, tmp_path) -> dict:
    """{name: measured} for each FMU, the FMUs in parallel, each in a fresh process."""
    script = tmp_path / "cycles.py"
    script.write_text(CYCLES_SCRIPT)
    processes = {name: subprocess.Popen(
        [sys.executable, str(script), str(path), str(tmp_path / name),
         *(str(n) for n in (WARM_UP, RSS_CYCLES, TRACED_CYCLES, EVERY))],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for name, path in fmu_paths.items()}
    measured = {}
    for name, process in processes.items():
        stdout, stderr = process.communicate(timeout=180)
        assert process.returncode == 0, f"{name}: exit {process.returncode}\n{stderr}"
        measured[name] = json.loads(stdout)
    return measured


@pytest.fixture(scope="module")
def bare_fmu(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bare")
    (folder / "BareSlave.py").write_text(BARE_SCRIPT)
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(folder / "BareSlave.py"),
                    "-d", str(folder)], check=True, capture_output=True, timeout=120)
    return folder / "BareSlave.fmu"


def test_life_cycles_keep_no_more_than_pythonfmus_residual(fmu_paths, bare_fmu, tmp_path):
    """instantiate, initialise, terminate, free, 490 times per FMU: each of our FMUs grows
    by less than LIMIT_KIB per cycle (traced memory and RSS); the bare pythonfmu FMU by more
    than BARE_AT_LEAST_KIB; no instance stays alive, sys.path does not grow."""
    measured = run_cycles({**{fmu_id: fmu_paths[fmu_id] for fmu_id in FMU_IDS}, "bare": bare_fmu}, tmp_path)
    bare = measured.pop("bare")
    assert bare["traced_kib"] > BARE_AT_LEAST_KIB and bare["rss_kib"] > BARE_AT_LEAST_KIB, bare
    too_much = {fmu_id: m for fmu_id, m in measured.items()
                if not (m["traced_kib"] < LIMIT_KIB and m["rss_kib"] < LIMIT_KIB)}
    assert not too_much, f"KiB per cycle over {LIMIT_KIB} (bare pythonfmu FMU: {bare}): {too_much}"
    for fmu_id, m in measured.items():
        assert m["instances"] == 0 and m["sys_path"] < 20, (fmu_id, m)


def test_reexecuted_script_shows_pythonfmu_one_class_with_interned_reprs():
    """What pythonfmu 0.7's findClass does at each fmi2Instantiate, done here in Python: run
    the FMU script again in its module's globals with a fresh locals dict.  The only class
    left in the locals is the slave class (the one findClass must find), the module's own;
    every class of its MRO gives the same repr object each time."""
    for fmu in build_fmu.FMUS:
        slave_class = build_fmu.model_class(fmu.model_identifier)
        module = sys.modules[slave_class.__module__]
        code = compile(fmu.script.read_text(), fmu.script.stem, "exec")
        for _ in range(2):
            script_locals = {}
            exec(code, module.__dict__, script_locals)
            classes = {name: value for name, value in script_locals.items() if isinstance(value, type)}
            assert classes == {fmu.model_identifier: slave_class}, (fmu.model_identifier, classes)
        ours = [c for c in slave_class.__mro__ if c.__module__ not in ("pythonfmu.fmi2slave", "abc", "builtins")]
        assert len(ours) >= 2, slave_class.__mro__
        for c in ours:
            assert repr(c) is repr(c) and repr(c) == f"<class '{c.__module__}.{c.__qualname__}'>", c
