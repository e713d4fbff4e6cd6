"""End-to-end: `tables` on a shortened horizon; the step study: tests/test_step_study.py."""
import csv
import math
import re

import matplotlib
import numpy as np
import pytest

from harness.fmu_build import native as build_native

from harness import cases, progress
from harness.cli import main as cli_main
from harness.studies import tables

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after choosing the backend


def test_tables_writes_tables_report_and_figures(fmu_paths, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(progress, "PROGRESS_LINE_EVERY_S", 0.0)  # a line per finished run even on a fast machine
    code = cli_main(["tables", "--out", str(tmp_path), "--stop", "0.3", "--jobs", "2", "--refine", "0"])
    captured = capsys.readouterr()
    out = captured.out
    assert code == 0
    for name, scenarios in (("table1.csv", {"pendulum_case1", "pendulum_case2", "pendulum_case3"}),
                            ("table2.csv", {"manipulator"})):
        with open(tmp_path / name) as stream:
            header = stream.readline().strip()
            assert header.startswith("scenario,controller,ts,es1_pct,es2_pct,ITAE,IAE,Ec")
            stream.seek(0)
            rows = list(csv.DictReader(stream))
        assert {r["scenario"] for r in rows} == scenarios
        assert sorted(r["controller"] for r in rows) == sorted(["vud", "fixed", "fae"] * len(scenarios))
        assert all(r["status"] == "ok" and float(r["ITAE"]) > 0 for r in rows)
    report = (tmp_path / "report.md").read_text()
    assert "## Table I: inverted pendulum" in report and "## Table II" in report
    assert "## Claims of the paper, checked" in report
    verdicts = re.findall(r"(?m)^- \*\*([^*]+)\*\*: The ", report)
    assert len(verdicts) == 8, verdicts  # every claim has exactly one verdict...
    assert set(verdicts) <= {"reproduced", "not reproduced", "not decided at this accuracy"}, verdicts
    assert report.count(" ± ") >= 5 * 3  # ...stated with the numbers and their errors
    assert "(h = 0.00025 s, plant step 0.000125 s" in report and "(h = 2.5e-05 s, plant step 3.13e-06 s" in report
    assert "(h = 0.0004 s" not in report and "(h = 0.0001 s" not in report
    for name in ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator"):
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000
        assert f"({name}.png)" in report
    assert "claims (decided on the step ladders" in out
    with open(tmp_path / "table3_beyond_paper.csv") as stream:  # the third-order plant
        beyond = list(csv.DictReader(stream))
    assert sorted((r["controller"], r["sets"]) for r in beyond) == sorted(
        (c, m) for c in ("vud", "fixed", "fae") for m in ("2", "3"))
    assert all(r["scenario"] == "motor_arm" and r["status"] == "ok" and float(r["ITAE"]) > 0 for r in beyond)
    assert "## Beyond the paper: a third-order plant" in report and "| vud | 3 (27) |" in report


    # one horizon, one answer: es1, es2 undefined on 0.3 s everywhere, ts not settled
    assert "from 0 to 0.3 s at the scenario's communication step. On this horizon es1 and es2 are not defined" \
        in report and "from 0 to 20 s" not in report
    assert "| vud | not settled | n/a | n/a | " in report and "| vud | 3 (27) | not settled | n/a | n/a | " in report
    assert all(r["es1_pct"] == "" and r["es2_pct"] == "" and r["ts"] == "" for r in beyond)
    for metric in ("es1", "es2"):
        claim = report.split(f"smallest steady-state error {metric} in all four scenarios.")[1].split("\n- **")[0]
        assert report.count(f"- **not decided at this accuracy**: The proposed AFC has the smallest steady-state "
                            f"error {metric}") == 1
        assert " ± " not in claim and f"no {metric}_pct (vud, fixed, fae: the horizon 0.3 s is shorter" in claim, claim
    assert "es1 and es2 are n/a in every table and their claims are not decided" in captured.err
    # stderr is not a terminal here (as under `| cat` or in a CI log): progress lines, not silence
    native = build_native.compiler_available()  # the ladders' own runs then take the native FMUs, in a pool first
    if native:
        ladder_words = "claims' ladders on the native FMUs (h/2 and h with another plant step)"
        assert f"{ladder_words}: 1/15 runs done in " in captured.err, captured.err
        assert re.search(rf"{re.escape(ladder_words)}: 15/15 runs done in \d+ s\n", captured.err)
        words, pooled = "Table I/II at h, third-order plant", 18
    else:
        words, pooled = "Table I/II at h, h/2 and h with another plant step, third-order plant", 33
    assert f"{words}: 1/{pooled} runs done in " in captured.err, captured.err
    assert re.search(rf"{re.escape(words)}: {pooled}/{pooled} runs done in \d+ s\n", captured.err)
    # the first line counts every run the progress lines count, with the steps of each run's horizon and step
    where = ("two pools", "; the ladders' runs at h/2 and h with another plant step and finer on the native FMUs") \
        if native else ("one pool", "")
    first = re.fullmatch(rf"33 runs: 33 in {where[0]} in [\d.]+ s \(the 12 cases of Tables I/II at h, h/2 and h with "
                         rf"another plant step, 6 of the third-order plant{re.escape(where[1])}\), 0 finer for open "
                         r"claims in [\d.]+ s; (\d+) communication steps, (\d+) plant RK4 steps, [\d.]+ s wall on 2 "
                         r"processes; peak memory \d+ MiB \(largest process\)", out.splitlines()[0])
    assert first, out.splitlines()[0]
    if native:
        assert "The tables' runs at h are the pythonfmu FMUs' and the first rung of each ladder" in report
    paper = [row for name in ("table1.csv", "table2.csv") for row in csv.DictReader(open(tmp_path / name))]
    # h, h/2 (twice the steps) of each paper case, h with another plant step where the plant switches (the
    # manipulator), the third-order runs
    axis = {"pendulum_case1": 0, "pendulum_case2": 0, "pendulum_case3": 0, "manipulator": 1}
    assert int(first.group(1)) == sum((3 + axis[r["scenario"]]) * round(0.3 / float(r["step"])) for r in paper) + \
        sum(round(0.3 / float(r["step"])) for r in beyond)
    internal = {"pendulum_case1": 2.5e-4, "pendulum_case2": 4e-4, "pendulum_case3": 4e-4, "manipulator": 6.25e-6}
    plant_axis = {"pendulum_case1": 0, "pendulum_case2": 0, "pendulum_case3": 0, "manipulator": 0.5}  # 2 h_p: half
    assert int(first.group(2)) == sum(round(0.3 / internal[r["scenario"]] * (1 + 2 + plant_axis[r["scenario"]]))
                                      for r in paper) + sum(round(0.3 / 6.25e-5) for r in beyond)
    # the report read by a control engineer
    for definition in ("- `vud` (variant 1): proposed AFC (variable universes)",
                       "- `fixed` (variant 2): stand-in for [46] (fixed universes)",
                       "- `fae` (variant 3): stand-in for [28] (fixed universes + error estimator)",
                       "- ITAE [rad.s2]: ",
                       "- Ec [N2.s in pendulum_case1, pendulum_case2, pendulum_case3; (N.m)2.s in manipulator; "
                       "V2.s in motor_arm]: ",
                       "- umax [N in pendulum_case1, pendulum_case2, pendulum_case3; N.m in manipulator; V in motor_arm]: ",
                       "- TV(u)/s [N/s in pendulum_case1, pendulum_case2, pendulum_case3; N.m/s in manipulator; "
                       "V/s in motor_arm]: "):
        assert definition in report, definition
    assert report.count("| controller | ts (s) | es1 (%) | es2 (%) | ITAE (rad.s2) | IAE (rad.s) | Ec (N2.s) | "
                        "umax (N) | TV(u)/s (N/s) |") == 3
    assert "| Ec ((N.m)2.s) | umax (N.m) | TV(u)/s (N.m/s) |" in report and "| Ec (V2.s) | umax (V) |" in report
    assert report.count("The claims below read the same scores at the finest step run (h/2 or finer) with their "
                        "numerical error") == 4
    assert "At the scenario's step h = 0.0005 s, the plant's RK4 in internal steps of 0.00025 s." in report
    assert "At the scenario's step h = 5e-05 s, the plant's RK4 in internal steps of 6.25e-06 s." in report
    assert "The paper's Tables I and II are not in the text of the paper we have" in report
    assert "one decided by a gap under 1 % of the values says *close*" in report
    for number, name in enumerate(("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator"), 1):
        assert f"({name}.png)\n\n*Figure {number}: {name}, " in report
    assert report.count("Grey band on e: ±5 % of max|ym|, the band of the settling time ts.") == 4


def test_figures_define_the_controllers_and_draw_the_settling_band(fmu_paths):
    """The legends say what vud, fixed, fae are; e carries the 5 % band of ts."""
    time = np.linspace(0.0, 1.0, 11)
    signals = {"time": time, **{name: np.sin(time) for name in ("plant.y", "plant.dy", "reference.de", "controller.u",
                                                                 "reference.dym")},
               "reference.ym": 2.0 * np.sin(3 * time), "reference.e": 0.1 * time}
    runs = [{"scenario": "pendulum_case1", "controller": c, "signals": signals} for c in ("vud", "fixed", "fae")]
    fig = tables.draw_figure("pendulum_case1", runs, plt)
    try:
        top, error = fig.axes[0], fig.axes[2]
        assert [t.get_text() for t in top.get_legend().get_texts()] == [
            "fixed: stand-in for [46] (fixed universes)", "fae: stand-in for [28] (fixed universes + error estimator)",
            "vud: proposed AFC (variable universes)", "ym"]
        band = 0.05 * float(np.max(np.abs(signals["reference.ym"])))
        patches = [p for p in error.patches if p.get_label() == "5 % band of max|ym| (ts)"]
        assert len(patches) == 1
        corners = patches[0].get_path().transformed(patches[0].get_patch_transform()).vertices[:, 1]
        assert np.allclose(sorted(set(np.round(corners, 12))), [-band, band])
        assert [t.get_text() for t in error.get_legend().get_texts()] == ["5 % band of max|ym| (ts)"]
    finally:
        plt.close(fig)


def test_the_choices_say_the_settling_dwell_and_the_plant_steps_the_code_runs(monkeypatch):
    """The report's choices are the code's: the dwell of ts (harness/scores.py) and each scenario's communication
    step, internal RK4 step and plant-axis step (the scenarios, harness/studies/ladders.py); they follow a change."""
    from harness import scores
    from harness.cases import Case
    from harness.studies import ladders

    text = tables.choices_text()
    assert "for at least one reference period (2 pi s) inside the band" not in text  # the old ts wording
    assert f"<= {100 * scores.SETTLING_BAND:g} % of max|ym|" in text
    assert "provided that leaves at least one reference period (2 pi s) inside the band" in text
    assert "not settled within the horizon" in text and "internal steps <= 0.1 ms" not in text
    line = next(line for line in text.splitlines() if "RK4" in line)
    for name in tables.ALL_SCENARIOS:
        case = Case(name, "vud")
        scenario = case.build()
        internal = ladders.plant_step(scenario)
        count = round(scenario.step / internal)
        words = f"h = {tables._seconds(scenario.step)}, {count} RK4 step{'s' if count > 1 else ''} of " \
                f"{tables._seconds(internal)}"
        axis = ladders.plant_step_case(case)
        if axis is not None:
            words += f" (the plant axis: {tables._seconds(ladders.plant_step(axis.build()))})"
        group = next(part for part in line.split("; ") if name in part)
        assert words in group, (name, words, line)
    assert tables._seconds(6.25e-6) == "6.25 us" and tables._seconds(4e-4) == "0.4 ms"
    # the line follows the constants it states
    monkeypatch.setattr(scores, "SETTLING_DWELL", 3.0)
    monkeypatch.setattr(scores, "SETTLING_BAND", 0.02)
    changed = tables.choices_text()
    assert "at least 3 s inside the band" in changed and "<= 2 % of max|ym|" in changed
    monkeypatch.setattr(ladders.plant_integration, "internal_step_count", lambda step, limit: 5)
    assert "5 RK4 steps of 0.1 ms" in tables.choices_text()  # pendulum_case1: 0.5 ms in 5


def score_difference(one: dict, other: dict) -> float:
    """The largest relative difference of a score between two outcomes of one case (infinite where one gives a
    score the other does not)."""
    from harness.scores import SCORE_KEYS

    assert one["status"] == other["status"] == "ok", (one.get("reason"), other.get("reason"))
    worst = 0.0
    for metric in SCORE_KEYS:
        a, b = one[metric], other[metric]
        if a is None or b is None:
            worst = worst if a is b else math.inf
            continue
        scale = max(abs(a), abs(b))
        worst = max(worst, abs(a - b) / scale if scale else 0.0)
    return worst


def test_the_native_ladders_give_the_pythonfmu_editions_scores(fmu_paths, monkeypatch):
    """The pythonfmu tables run their ladders' own runs (h/2, the plant axis) on the native FMUs: every one of them
    gives the scores the pythonfmu FMUs give (over 1 s: CI time)."""
    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e .)")
    from harness.studies import ladders

    monkeypatch.delenv("AFC_EDITION", raising=False)
    native = ladders.native_ladder_fmus()
    assert native is not None and all("native" in str(path) for path in native.values())
    runs = [c for case in tables.table_cases(stop=1.0) for c in ladders.ladder_cases(case)]
    assert len(runs) == 15  # h/2 of the 12 cases, the plant axis of the manipulator's 3
    python = cases.run_cases(runs, jobs=2, progress=False, fmu_paths=fmu_paths)
    in_c = cases.run_cases(runs, jobs=2, progress=False, fmu_paths=native)
    differences = {run.label: score_difference(a, b) for run, a, b in zip(runs, python, in_c)}
    assert max(differences.values()) <= 1e-9, differences
    monkeypatch.setenv("AFC_EDITION", "native")
    assert ladders.native_ladder_fmus() is None  # a native edition's tables run their ladders on their own FMUs


def test_tables_in_model_exchange_decide_the_claims_on_tolerance_ladders(tmp_path, capsys, monkeypatch):
    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e .)")
    code = cli_main(["tables", "--edition", "native", "--algorithm", "me", "--rtol", "1e-8", "--out", str(tmp_path),
                     "--stop", "0.3", "--jobs", "2", "--refine", "0"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    first = captured.out.splitlines()[0]
    assert first.startswith("30 runs: 30 in one pool in ") and "(the 12 cases of Tables I/II at rtol and 10 rtol, 6 of " \
        "the third-order plant), 0 finer for open claims" in first and "communication steps" not in first, first
    with open(tmp_path / "table2.csv") as stream:
        rows = list(csv.DictReader(stream))
    assert all(r["status"] == "ok" and r["validated_step"] == "" for r in rows)
    report = (tmp_path / "report.md").read_text()
    assert "one Model Exchange run (the native FMUs integrated together by CVODE, rtol 1e-08" in report
    assert "tolerance ladders" in report and report.count(" ± ") >= 8 * 3
    assert cli_main(["tables", "--rtol", "1e-8", "--out", str(tmp_path), "--stop", "0.1"]) == 2
    assert "--rtol is the tolerance of --algorithm me" in capsys.readouterr().err
