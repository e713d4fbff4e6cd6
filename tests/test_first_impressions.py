"""What a new user meets first says what is true: ``harness --help`` counts the runs ``tables`` makes, and the
test session says which FMUs it builds before the first test (the time left of ``harness run``:
tests/test_progress.py)."""
from __future__ import annotations

import re

from harness.cli import main as cli_main
from harness.studies import tables
from tests import conftest


class Stop(Exception):
    """Raised in place of the runs: the test wants the cases, not their results."""


def test_help_counts_the_runs_tables_makes(monkeypatch, tmp_path, capsys):
    """--help said "12 co-simulations" and README 32: the help now counts from the cases the command builds."""
    assert cli_main(["--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    found = re.search(r"tables run Table I/II and write the report: (\d+) co-simulations in one pool \(the (\d+) "
                      r"cases at their step and at half of it, (\d+) of the third-order plant", text)
    assert found, text
    pooled, paper, beyond = map(int, found.groups())
    seen = []

    def first_pool(cases, **options):
        seen.extend(cases)
        raise Stop()

    monkeypatch.setattr(tables, "run_cases", first_pool)
    assert cli_main(["tables", "--out", str(tmp_path / "out")]) == 1  # Stop: one line, exit 1
    assert len(seen) == pooled == 2 * paper + beyond
    assert sum(dict(case.overrides).get("controller.sets") is not None for case in seen) == beyond


def test_the_session_says_which_fmus_it_builds_before_it_builds_them(monkeypatch):
    from harness.fmu_build import builder as build_fmu
    from harness.fmu_build import native as build_native

    events = []
    model = build_native.models()[0]
    monkeypatch.setattr(build_fmu, "is_stale", lambda fmu: fmu.model_identifier == "TrackingReference")
    monkeypatch.setattr(build_fmu, "ensure_built", lambda **options: events.append("built pythonfmu FMUs"))
    monkeypatch.setattr(build_native, "compiler_available", lambda: True)
    monkeypatch.setattr(build_native, "stale_models", lambda platforms=None: [model])

    def native_build(announce=None, **options):
        announce(model, ["x86_64-linux-gnu.2.17", "x86_64-windows-gnu"])
        events.append("built native FMUs")

    monkeypatch.setattr(build_native, "ensure_built", native_build)
    conftest._build_before_the_workers_start(events.append)
    assert events[0] == "building the pythonfmu FMUs before the tests: TrackingReference"
    assert events[1] == "built pythonfmu FMUs"
    assert events[2].startswith("building 1 native FMUs before the tests")
    assert events[3] == (f"  {model.model_identifier}: FMI 2.0 and 3.0 for x86_64-linux-gnu.2.17, x86_64-windows-gnu "
                         "(4 binaries)")
    assert events[4] == "built native FMUs" and re.fullmatch(r"FMUs built in \d+ s", events[5])
    events.clear()
    conftest._announce_stale_fmus(events.append)  # a serial session: named, built when a test needs them
    assert events == ["FMUs to build (pythonfmu, seconds each) when a test first needs them: TrackingReference",
                      "native FMUs to build (FMI 2.0 and 3.0 for every target, minutes on a cold zig cache) when a "
                      f"test first needs them: {model.model_identifier}"]


def test_a_session_with_nothing_stale_says_nothing(monkeypatch):
    from harness.fmu_build import builder as build_fmu
    from harness.fmu_build import native as build_native

    events = []
    monkeypatch.setattr(build_fmu, "is_stale", lambda fmu: False)
    monkeypatch.setattr(build_fmu, "ensure_built", lambda **options: None)
    monkeypatch.setattr(build_native, "compiler_available", lambda: True)
    monkeypatch.setattr(build_native, "stale_models", lambda platforms=None: [])
    monkeypatch.setattr(build_native, "ensure_built", lambda **options: None)
    conftest._build_before_the_workers_start(events.append)
    conftest._announce_stale_fmus(events.append)
    assert events == []
