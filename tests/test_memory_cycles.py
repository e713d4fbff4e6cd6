"""Memory a long-running host keeps per FMU life cycle.

A host that instantiates, initialises, terminates and frees an FMU again and again in one process
(a sweep worker, a test runner, a tool that re-instantiates per run) must not grow without bound.
pythonfmu 0.7's C wrapper keeps some memory at every fmi2Instantiate that no FMU can give back
(``findClass``: a list of the MRO of each class the FMU script binds, the UTF-8 bytes of the repr of
each MRO entry, the class name's bytes, and the resources path it puts in sys.path); a class the
script builds anew at every instantiate stays alive with it. ``afc_slave_base._SlaveMeta`` hands
back the class already defined, hides the script's imported classes from that search and interns
the reprs, so what our FMUs keep is the wrapper's residual for one slave class.

``tests/memory_cycles.py`` measures each FMU in a fresh process and splits the traced memory kept
per cycle by whose code allocated it. The test asserts that our own code keeps less than
OURS_LIMIT_KIB per cycle, that each FMU in all keeps less than LIMIT_KIB (traced and RSS), that
pythonfmu's own example FMU keeps more than PYTHONFMU_EXAMPLE_AT_LEAST_KIB (both measurements see
a leak of a few KiB, and that one is pythonfmu's), and that docs/performance.md quotes the figures
this run measures.
"""
from __future__ import annotations

import pathlib
import re
import subprocess
import sys

import pytest

from harness.fmu_build import builder as build_fmu
from tests import memory_cycles

ROOT = pathlib.Path(__file__).resolve().parents[1]
FMU_IDS = tuple(f.model_identifier for f in build_fmu.FMUS)
#: pythonfmu's example FMU "Resistor", as pythonfmu ships it: nothing of ours
PYTHONFMU_EXAMPLE = ROOT / "tests" / "data" / "pythonfmu_resistor.py"
SECTION = "## Memory per instantiate/free cycle"

WARM_UP, RSS_CYCLES, TRACED_WARM_UP, TRACED_CYCLES, EVERY = 40, 300, 50, 150, 10
#: what our own code (a frame of the FMU's Python sources) may keep per cycle, KiB
OURS_LIMIT_KIB = 0.5
#: what one of our FMUs may keep in all per cycle (pythonfmu's residual for one slave class of 5 or
#: 6 MRO entries, with a margin for the short window of this test), KiB
LIMIT_KIB = 1.5
#: pythonfmu's example FMU keeps at least this per cycle, traced and RSS, KiB
PYTHONFMU_EXAMPLE_AT_LEAST_KIB = 4.0
#: how far a figure of this run may lie from the one docs/performance.md quotes for the same owner, KiB:
#: the page quotes a run of 3000 cycles, this test's window is short, so what is allocated once (a
#: table's resize, a free list's refill) weighs more in it; objects from free lists move a few bytes
DOCS_TOLERANCE_KIB = 0.25
#: ... or this share of the quoted figure, whichever is larger (pythonfmu's example keeps several KiB)
DOCS_TOLERANCE_SHARE = 0.1


@pytest.fixture(scope="module")
def pythonfmu_example_fmu(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pythonfmu_example")
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(PYTHONFMU_EXAMPLE), "-d", str(folder)],
                   check=True, capture_output=True, timeout=120)
    return folder / "Resistor.fmu"


@pytest.fixture(scope="module")
def measured(fmu_paths, pythonfmu_example_fmu, tmp_path_factory):
    fmus = {**{fmu_id: fmu_paths[fmu_id] for fmu_id in FMU_IDS}, "Resistor": pythonfmu_example_fmu}
    return memory_cycles.measure(fmus, tmp_path_factory.mktemp("cycles"), WARM_UP, RSS_CYCLES, TRACED_WARM_UP,
                                 TRACED_CYCLES, EVERY)


def docs_figures() -> dict:
    """{FMU: {column: KiB per cycle}} from the table of docs/performance.md's memory section."""
    text = (ROOT / "docs" / "performance.md").read_text()
    assert SECTION in text, f"docs/performance.md lost its section {SECTION!r}"
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    rows = [[cell.strip() for cell in line.strip().strip("|").split("|")]
            for line in section.splitlines() if line.startswith("|")]
    header, body = rows[0], rows[2:]
    assert header[:5] == ["FMU", "the FMU's code", "pythonfmu's wrapper", "traced, all", "RSS"], header
    return {re.match(r"`(\w+)`", row[0]).group(1): dict(zip(("fmu_sources", "pythonfmu_wrapper", "traced_kib", "rss_kib"),
                                        (float(re.match(r"[\d.]+", cell).group()) for cell in row[1:5])))
            for row in body}


def test_our_code_keeps_next_to_nothing_per_cycle(measured):
    """instantiate, initialise, terminate, free, 540 times per FMU: the memory kept by allocations of
    our own code (a frame of the FMU's sources) is below OURS_LIMIT_KIB per cycle."""
    ours = {fmu_id: measured[fmu_id]["by_owner"] for fmu_id in FMU_IDS}
    too_much = {fmu_id: owners for fmu_id, owners in ours.items() if not owners["fmu_sources"] < OURS_LIMIT_KIB}
    assert not too_much, f"our code keeps over {OURS_LIMIT_KIB} KiB per cycle: {too_much}"


def test_life_cycles_keep_no_more_than_pythonfmus_residual(measured):
    """Each of our FMUs grows by less than LIMIT_KIB per cycle in all (traced memory and RSS);
    pythonfmu's own example by more than PYTHONFMU_EXAMPLE_AT_LEAST_KIB; no instance stays alive,
    sys.path does not grow."""
    example = measured["Resistor"]
    assert example["traced_kib"] > PYTHONFMU_EXAMPLE_AT_LEAST_KIB, example
    assert example["rss_kib"] > PYTHONFMU_EXAMPLE_AT_LEAST_KIB, example
    too_much = {fmu_id: measured[fmu_id] for fmu_id in FMU_IDS
                if not (measured[fmu_id]["traced_kib"] < LIMIT_KIB and measured[fmu_id]["rss_kib"] < LIMIT_KIB)}
    assert not too_much, f"KiB per cycle over {LIMIT_KIB} (pythonfmu's example: {example}): {too_much}"
    for fmu_id in FMU_IDS:
        assert measured[fmu_id]["instances"] == 0 and measured[fmu_id]["sys_path"] < 20, (fmu_id, measured[fmu_id])


def test_the_performance_page_quotes_the_figures_measured(measured):
    """docs/performance.md's table gives, per FMU, the traced memory kept per cycle by our code and by
    pythonfmu's wrapper: this run's figures lie within DOCS_TOLERANCE_KIB (or DOCS_TOLERANCE_SHARE) of them."""
    quoted = docs_figures()
    assert set(quoted) == {*FMU_IDS, "Resistor"}, sorted(quoted)
    off = {}
    for fmu_id, figures in quoted.items():
        for owner in ("fmu_sources", "pythonfmu_wrapper"):
            tolerance = max(DOCS_TOLERANCE_KIB, DOCS_TOLERANCE_SHARE * figures[owner])
            if abs(measured[fmu_id]["by_owner"][owner] - figures[owner]) > tolerance:
                off[(fmu_id, owner)] = (figures[owner], measured[fmu_id]["by_owner"][owner])
    assert not off, f"docs/performance.md quotes (quoted, measured now) KiB per cycle: {off}"


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
