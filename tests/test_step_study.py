"""The step study by accuracy (harness/studies/step_study.py): search, criterion, outputs, and what uses it."""
import copy
import json
import math
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from fmu_src import chatter_monitor
from harness import scenario as scenarios
from harness import variants
from harness.studies import step_study
from harness.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = ("pendulum_case1", "pendulum_case2", "pendulum_case3")


def level(step, itae, iae=1.0, ec=100.0, status="ok"):
    return {"step": step, "status": status, "ITAE": itae, "IAE": iae, "Ec": ec}


# ------------------------------------------------------------ pure pieces
def test_ladder_rungs_between_a_step_and_its_double():
    assert step_study.ladder_between(1e-4, 2e-4) == pytest.approx([1.25e-4, 1.6e-4])
    assert step_study.ladder_between(4e-4, 8e-4) == pytest.approx([5e-4, 6.4e-4])
    assert step_study.ladder_between(8e-4, 1.6e-3) == pytest.approx([1e-3, 1.25e-3])
    for rung in step_study.ladder_between(1e-6, 0.051):  # every rung up to the 0.05 s limit divides 20 s
        assert abs(20.0 / rung - round(20.0 / rung)) < 1e-6


@pytest.mark.parametrize("limit_true, start, expected", [
    (3.7e-4, 4e-4, 3.2e-4),  # start outside: halve to 2e-4, then the rungs 2.5e-4, 3.2e-4
    (3.7e-4, 1e-4, 3.2e-4),  # start inside: double to 2e-4, 4e-4 fails, then the rungs
    (1.3e-4, 1e-4, 1.25e-4),
    (1.1e-4, 4e-4, 1e-4),
    (9.9e-4, 5e-5, 8e-4),
])
def test_search_finds_the_largest_rung_within(limit_true, start, expected):
    tried = []

    def within(step):
        tried.append(step)
        return step <= limit_true

    found, note = step_study.search_validated(within, start, finest=start / 16, limit=0.05)
    assert found == pytest.approx(expected) and note is None
    assert len(tried) == len(set(tried))  # no step run twice


def test_search_says_when_it_falls_back():
    found, note = step_study.search_validated(lambda step: False, 4e-4, finest=1e-4, limit=0.05)
    assert found is None and "no step within 1 % down to the finest step 0.0001" in note
    found, note = step_study.search_validated(lambda step: True, 4e-4, finest=1e-4, limit=2e-3)
    assert found == pytest.approx(1.6e-3) and "search limit" in note


def test_relative_error_takes_the_worst_metric_and_fails_a_failed_run():
    converged = {"ITAE": 1.0, "IAE": 2.0, "Ec": 100.0}
    assert step_study.relative_error(level(1e-4, 1.005, 2.0, 101.5), converged) == pytest.approx(0.015)
    assert step_study.relative_error(level(1e-4, 1.0, 2.0, 100.0, status="diverged"), converged) == math.inf


def test_halving_converges_below_0_1_percent_or_in_the_first_order_regime():
    assert step_study.halving_converged([level(4e-4, 1.0), level(2e-4, 1.0009)])
    assert not step_study.halving_converged([level(4e-4, 1.0), level(2e-4, 1.003)])
    # 0.6 % then 0.3 %: first order (ratio 2), below 0.5 %
    assert step_study.halving_converged([level(4e-4, 1.009), level(2e-4, 1.003), level(1e-4, 1.0)])
    # 0.6 % then 0.4 %: ratio 1.5, not yet first order
    assert not step_study.halving_converged([level(4e-4, 1.01), level(2e-4, 1.004), level(1e-4, 1.0)])


def test_richardson_removes_the_first_order_error():
    # f(h) = 1 + c h: f(h), f(h/2) extrapolate to 1
    fine, coarse = level(1e-4, 1.0 + 0.5, 2.0 + 1.0, 100 + 5), level(2e-4, 1.0 + 1.0, 2.0 + 2.0, 100 + 10)
    assert step_study.richardson(fine, coarse) == pytest.approx({"ITAE": 1.0, "IAE": 2.0, "Ec": 100.0})


def test_step_warning_only_beyond_the_validated_step():
    study = {"scenarios": {"s": {"controllers": {"vud": {"validated_step": {"jacobi": 1e-4, "feedthrough": 4e-4}}}}}}
    assert step_study.step_warning("s", "vud", "jacobi", 1e-4, study) is None
    text = step_study.step_warning("s", "vud", "jacobi", 4e-4, study)
    assert "0.0004 s is beyond the validated step (1 %) 0.0001 s" in text and "--step 0.0001" in text
    assert step_study.step_warning("s", "vud", "feedthrough", 4e-4, study) is None


# ------------------------------------------------------------ end to end
def tracked_state():
    return {p: p.read_bytes() for p in [step_study.CONVERGENCE_JSON, step_study.CONVERGENCE_MD,
                                        *scenarios.SCENARIO_DIR.glob("*.toml")]}


def test_quick_study_writes_only_into_its_output_folder(fmu_paths, tmp_path):
    before = tracked_state()
    code = cli_main(["convergence", "pendulum_case1", "--quick", "--out", str(tmp_path), "--jobs", "1"])
    assert code == 0
    assert tracked_state() == before
    study = json.loads((tmp_path / "convergence.json").read_text())
    result = study["scenarios"]["pendulum_case1"]["controllers"]["vud"]
    assert result["converged"]["ITAE"] > 0 and "Richardson" in result["converged"]["method"]
    for algorithm in ("feedthrough", "jacobi"):
        found = result["validated_step"][algorithm]
        run = next(r for r in result["runs"] if r["algorithm"] == algorithm and r["step"] == found)
        assert max(abs(v) for v in run["error_pct"].values()) <= 1.0
        coarser = [r for r in result["runs"] if r["algorithm"] == algorithm and r["step"] > found]
        assert coarser and all(max(abs(v) for v in r.get("error_pct", {"x": 99}).values()) > 1.0
                               for r in coarser if r["step"] == min(c["step"] for c in coarser))
    text = (tmp_path / "convergence.md").read_text()
    assert "validated step (1 %)" in text and "stable" not in text


def test_apply_needs_the_full_study(tmp_path):
    assert cli_main(["convergence", "pendulum_case1", "--quick", "--apply", "--out", str(tmp_path)]) == 2


def test_apply_of_one_scenario_keeps_every_other_scenarios_entry(tmp_path, monkeypatch, capsys):
    """A new plant's recipe runs `convergence NAME --apply`: the committed entries of the others stay."""
    committed = step_study.load_convergence()
    scenario_dir = tmp_path / "scenarios"
    scenario_dir.mkdir()
    (scenario_dir / "pendulum_case1.toml").write_text((scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text())
    monkeypatch.setattr(scenarios, "SCENARIO_DIR", scenario_dir)
    monkeypatch.setattr(step_study, "CONVERGENCE_JSON", tmp_path / "convergence.json")
    monkeypatch.setattr(step_study, "CONVERGENCE_MD", tmp_path / "convergence.md")
    step_study.CONVERGENCE_JSON.write_text(json.dumps(committed))
    entry = copy.deepcopy(committed["scenarios"]["pendulum_case1"])
    for controller in step_study.CONTROLLERS:  # --apply takes a study of every variant (a new one: as vud)
        entry["controllers"].setdefault(controller, entry["controllers"][variants.PROPOSED])
    one = dict(committed, scenarios={"pendulum_case1": entry}, wall_s=12.0)
    (tmp_path / "one.json").write_text(json.dumps(one))
    assert cli_main(["convergence", "pendulum_case1", "--from-json", str(tmp_path / "one.json"), "--apply",
                     "--out", str(tmp_path / "out")]) == 0
    written = json.loads(step_study.CONVERGENCE_JSON.read_text())
    assert list(written["scenarios"]) == [*(n for n in committed["scenarios"] if n != "pendulum_case1"),
                                          "pendulum_case1"]
    others = [name for name in committed["scenarios"] if name != "pendulum_case1"]
    assert others and all(written["scenarios"][name] == committed["scenarios"][name] for name in others)
    assert written["scenarios"]["pendulum_case1"] == entry
    assert written["studied"] == ["pendulum_case1"] and written["wall_s"] == 12.0
    text = step_study.CONVERGENCE_MD.read_text()
    assert f"(the last run, of pendulum_case1: 12 s wall on 2 cores shared with other jobs; {', '.join(others)} " \
           "from earlier runs of the study, horizon" in text
    assert all(f"## {name}" in text for name in committed["scenarios"])
    assert "out/convergence.json" in capsys.readouterr().out  # the study itself, unmerged, in --out
    assert list(json.loads((tmp_path / "out" / "convergence.json").read_text())["scenarios"]) == ["pendulum_case1"]


# ------------------------------------------------------ the committed study
@pytest.fixture(scope="module")
def committed():
    study = step_study.load_convergence()
    assert study.get("criterion", "").startswith("validated step (1 %)"), "run: python -m harness convergence --apply"
    return study


def test_each_scenario_runs_at_its_smallest_feedthrough_validated_step(committed):
    for name in ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator"):
        entry = committed["scenarios"][name]
        steps = [step_study.validated_step(committed, name, c, "feedthrough") for c in ("vud", "fixed", "fae")]
        assert all(steps) and entry["chosen_step"] == min(steps) and entry["chosen_note"] is None
        assert scenarios.load(name).step == pytest.approx(entry["chosen_step"])
        for controller in ("vud", "fixed", "fae"):  # feedthrough affords at least the Jacobi step
            assert step_study.validated_step(committed, name, controller, "jacobi") <= \
                step_study.validated_step(committed, name, controller, "feedthrough")


def test_docs_speak_of_validated_steps_not_stability():
    text = step_study.CONVERGENCE_MD.read_text()
    assert "validated step (1 %)" in text and "stable" not in text.lower()


def test_run_warns_beyond_the_validated_step(fmu_paths, committed):
    limit = step_study.validated_step(committed, "pendulum_case1", "vud", "jacobi")
    command = [sys.executable, "-m", "harness", "run", "pendulum_case1", "--algorithm", "jacobi", "--stop", "0.02"]
    beyond = subprocess.run(command + ["--step", str(2 * limit)], capture_output=True, text=True, cwd=ROOT)
    assert beyond.returncode == 0
    warnings = [line for line in beyond.stderr.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and f"validated step (1 %) {limit:g} s" in warnings[0]
    inside = subprocess.run(command + ["--step", str(limit)], capture_output=True, text=True, cwd=ROOT)
    assert inside.returncode == 0 and "warning" not in inside.stderr


def test_controller_default_experiment_is_jacobi_safe_on_the_pendulum(fmu_paths, committed):
    from fmpy import read_model_description

    experiment = read_model_description(str(fmu_paths["AdaptiveFuzzyController"])).defaultExperiment
    jacobi = [step_study.validated_step(committed, name, c, "jacobi") for name in PENDULUM
              for c in ("vud", "fixed", "fae")]
    assert experiment.stepSize is not None and float(experiment.stepSize) <= min(jacobi) * (1 + 1e-9)


def test_export_ssp_carries_the_jacobi_validated_step_unless_given(fmu_paths, committed, tmp_path):
    from harness.hosts.engines import read_package

    package = tmp_path / "p.ssp"
    assert cli_main(["export-ssp", "manipulator", "--controller", "fae", "--out", str(package)]) == 0
    assert read_package(package).step == step_study.validated_step(committed, "manipulator", "fae", "jacobi")
    with zipfile.ZipFile(package) as archive:  # libcosim's algorithm: the same step, no worker threads
        ssd = archive.read("SystemStructure.ssd").decode()
    assert f'baseStepSize="{read_package(package).step!r}" numWorkerThreads="0"' in ssd
    assert cli_main(["export-ssp", "manipulator", "--out", str(package), "--step", "1e-3"]) == 0
    assert read_package(package).step == 1e-3


def test_runs_are_scored_on_the_true_tracking_error(fmu_paths):
    """With every link delayed, the reference's e(t_n) = ym(t_n) - y(t_{n-1}): the study scores ym - y instead."""
    from harness.master import simulate
    from harness.scores import itae

    scored = step_study.run_scored("pendulum_case1", "vud", 2e-4, 2.0, "jacobi", fmu_paths)
    result = simulate(scenarios.configure("pendulum_case1", "vud", 2e-4, 2.0), "jacobi", fmu_paths)
    s = result.signal
    true = itae(result.time, s("reference.ym") - s("plant.y"), s("reference.dym") - s("plant.dy"))
    delayed = itae(result.time, s("reference.e"), s("reference.de"))
    assert scored["ITAE"] == true
    assert abs(delayed / true - 1) > 1e-3, (delayed, true)


def test_the_chatter_warning_names_the_jacobi_steps_of_the_study(committed):

    families = {"the paper's pendulum scenarios": PENDULUM, "the manipulator": ("manipulator",)}
    for family, names in families.items():
        assert chatter_monitor.JACOBI_VALIDATED_STEP[family] == min(
            step_study.jacobi_safe_step(committed, name) for name in names), family
    c_source = (ROOT / "fmu_src" / "chatter_monitor.c").read_text()  # the C twin prints the same steps
    in_c = re.search(r"CHATTER_CONVERGED_HZ, ([0-9.e+-]+), ([0-9.e+-]+)\);", c_source)
    assert [float(v) for v in in_c.groups()] == list(chatter_monitor.JACOBI_VALIDATED_STEP.values())
