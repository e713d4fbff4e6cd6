"""The hardware study (harness/studies/hardware.py, ``python -m harness hardware``; docs/studies.md, "On a rig"):
its runs, the page's section rendered from the committed CSV (no figure pasted by hand), the CSV what the
command computes, the command's options and its mistakes in one line."""
from __future__ import annotations

import csv
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from harness import scenario as scenarios
from harness.cli import main as cli_main
from harness.studies import hardware

ROOT = Path(__file__).resolve().parents[1]


def test_every_setting_of_every_hardware_scenario_is_run_for_the_three_controllers():
    work = hardware.items()
    assert len(work) == len(hardware.HARDWARE_SCENARIOS) * len(hardware.SETTINGS) * 3
    assert {item[1] for item in work} == {"none", "rig", "sampling", "delay", "noise", "quantisation", "limits",
                                          "clock_step"}
    clocked = hardware.scenario_of("pendulum_case2_hardware", "clock_step", "vud")
    assert clocked.step == 1e-3 and "sensor" not in clocked.components and clocked.stop == 20.0
    table = scenarios.load("pendulum_case2_hardware").hardware
    plain = hardware.scenario_of("pendulum_case2_hardware", "none", "vud")
    assert "sensor" not in plain.components and plain.step == scenarios.load("pendulum_case2_hardware").step
    noise = hardware.scenario_of("pendulum_case2_hardware", "noise", "vud")
    sensor, actuator = noise.components["sensor"].parameters, noise.components["actuator"].parameters
    assert sensor["noise_dy"] == table["noise_dy"] and sensor["quantum_y"] == 0.0 and sensor["delay_samples"] == 0
    assert actuator["u_max"] == 0.0 and actuator["sample_period"] == table["sample_period"]
    limits = hardware.scenario_of("pendulum_case2_hardware", "limits", "fae")
    assert limits.components["actuator"].parameters["u_max"] == table["u_max"]
    assert limits.components["sensor"].parameters["sample_period"] == 0.0
    assert limits.components["controller"].parameters["variant"] == 3
    rig = hardware.scenario_of("manipulator_hardware", "rig", "fixed", stop=0.5)
    assert rig.stop == 0.5 and {"controller.alpha1", "truth.e"} <= set(rig.record)


def _committed_rows() -> list:
    return hardware.read_csv(hardware.DOCS_CSV)


def test_the_section_of_the_studies_page_is_rendered_from_the_committed_csv():
    page = hardware.STUDIES_PAGE.read_text()
    generated = re.search(re.escape(hardware.BEGIN) + ".*?" + re.escape(hardware.END), page, re.S).group(0)
    assert generated == hardware.section(_committed_rows()), "run: python -m harness hardware --edition native --apply"


def test_the_committed_csv_holds_every_run_complete():
    rows = _committed_rows()
    assert [(r["scenario"], r["setting"], r["controller"]) for r in rows] == [item[:3] for item in hardware.items()]
    assert all(r["status"] == "ok" for r in rows), [r for r in rows if r["status"] != "ok"]
    for row in rows:
        if row["setting"] not in ("none", "limits", "clock_step"):
            assert float(row["e_noise_rms"]) >= 0.0 and row["saturated_pct"] != ""


def test_the_findings_follow_the_numbers():
    """The paragraph under each table names the controller with the lowest ITAE with and without the rig."""
    rows = [dict(r) for r in _committed_rows()]
    name = hardware.HARDWARE_SCENARIOS[0]
    text = hardware._findings(rows, name, ("vud", "fixed", "fae"))
    for row in rows:  # make fae the best on the rig by far: the text must say so
        if row["scenario"] == name and row["setting"] == "rig" and row["controller"] == "fae":
            row["ITAE"] = "1e-9"
    changed = hardware._findings(rows, name, ("vud", "fixed", "fae"))
    assert "to fae (on it)" in changed and changed != text


def test_apply_with_a_short_horizon_and_a_tracked_output_are_refused_in_one_line(capsys):
    assert cli_main(["hardware", "--out", "docs", "--stop", "0.01"]) == 2
    assert "would overwrite committed files" in capsys.readouterr().err
    assert cli_main(["hardware", "--stop", "-1"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_the_committed_csv_is_what_the_command_computes(tmp_path):
    """A full run of the study (native edition) gives the committed CSV's numbers."""
    pytest.importorskip("ziglang", reason="the native edition needs zig's C compiler (pip install -e '.[test]')")
    completed = subprocess.run([sys.executable, "-m", "harness", "hardware", "--edition", "native", "--jobs", "2",
                                "--no-progress", "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                               timeout=3600)
    assert completed.returncode == 0, completed.stderr[-3000:]
    fresh = hardware.read_csv(tmp_path / "hardware_study.csv")
    committed = _committed_rows()
    assert len(fresh) == len(committed)
    for new, old in zip(fresh, committed):
        for key in hardware.COLUMNS:
            if old[key] and re.fullmatch(r"-?[\d.]+(e-?\d+)?", old[key]):
                assert math.isclose(float(new[key]), float(old[key]), rel_tol=1e-6, abs_tol=1e-12), \
                    (old["scenario"], old["setting"], old["controller"], key, new[key], old[key])
            else:
                assert new[key] == old[key], (old["scenario"], old["setting"], old["controller"], key)
    assert (tmp_path / "hardware_study.md").read_text() == hardware.section(committed) + "\n"


def test_a_short_run_of_the_command_writes_its_csv_and_section(tmp_path, capsys):
    assert cli_main(["hardware", "--edition", "native", "--stop", "0.05", "--jobs", "2", "--no-progress",
                     "--out", str(tmp_path)]) == 0
    assert "48 runs (0 failed)" in capsys.readouterr().out
    with open(tmp_path / "hardware_study.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == 48 and all(r["status"] == "ok" for r in rows)
    assert (tmp_path / "hardware_study.md").read_text().startswith(hardware.BEGIN)
    assert cli_main(["hardware", "--stop", "0.05", "--apply", "--out", str(tmp_path)]) == 2  # not from short runs


# ------------------------------------------------------------------ the robust cures (--cures)
from harness.studies import hardware_cures  # noqa: E402


def test_the_cures_rules_follow_the_rigs_data_sheet_and_the_controller():
    """Each rule's value from its formula (harness/studies/hardware_cures.py), so a changed rig or design
    moves it: the pendulum's floor is its gyro's noise rule, the manipulator's its step rule."""
    pendulum = hardware_cures.rule_values("pendulum_case2_hardware")
    table = scenarios.load("pendulum_case2_hardware").hardware
    sigma_dy = math.sqrt(table["noise_dy"] ** 2 + table["quantum_dy"] ** 2 / 12)
    assert pendulum["alpha_min"] == pytest.approx(3 * 7.0 * sigma_dy)  # 3 s sigma beats (1 - 0.99) 1 ms / 0.4 ms
    sigma_y = table["quantum_y"] / math.sqrt(12)
    assert pendulum["dead_zone"] == pytest.approx(3 * math.hypot(5.0 * sigma_y, 5.0 * sigma_dy))  # P B = (5, 5)
    assert pendulum["sigma"] == pytest.approx(1 / (2 * math.pi)) and pendulum["filter_time_constant"] == 0.1
    manipulator = hardware_cures.rule_values("manipulator_hardware")
    assert manipulator["alpha_min"] == pytest.approx((1 - 0.995) * 1e-3 / 5e-5)  # the step rule beats 3 s sigma
    assert hardware_cures.cure_values("manipulator_hardware", "alpha_floor", 30.0) == {"alpha_min": 1.0}
    assert set(hardware_cures.cure_values("pendulum_case2_hardware", "floor+dead_zone", 3.0)) == {"alpha_min",
                                                                                                  "dead_zone"}


def test_every_cure_at_every_scale_is_run_with_the_three_controllers():
    work = hardware_cures.items()
    per_scenario = 2 * (3 + len(hardware_cures.CURES) * len(hardware_cures.SCALES))
    assert len(work) == len(hardware.HARDWARE_SCENARIOS) * per_scenario
    assert {(item[2], item[3]) for item in work} >= {("fae", ""), ("vud", "sigma"), ("vud", "floor+dead_zone")}


def test_the_cures_section_of_the_studies_page_is_rendered_from_the_committed_csv():
    page = hardware.STUDIES_PAGE.read_text()
    generated = re.search(re.escape(hardware_cures.BEGIN) + ".*?" + re.escape(hardware_cures.END), page, re.S)
    rows = hardware.read_csv(hardware_cures.DOCS_CSV)
    assert generated.group(0) == hardware_cures.section(rows), \
        "run: python -m harness hardware --cures --edition native --apply"
    assert [(r["scenario"], r["setting"], r["controller"], r["cure"], float(r["scale"])) for r in rows] == \
        [item[:5] for item in hardware_cures.items()]
    assert all(r["status"] == "ok" for r in rows if not r["cure"])  # the three controllers all finish


def test_the_cures_findings_follow_the_numbers():
    """The paragraph names the cure that restores the advantage when the rows say one does."""
    rows = [dict(r) for r in hardware.read_csv(hardware_cures.DOCS_CSV)]
    name = hardware.HARDWARE_SCENARIOS[0]
    assert "no cure restores" in hardware_cures._findings(rows, name)
    for row in rows:
        if (row["scenario"], row["setting"], row["cure"], row["scale"]) == (name, "rig", "sigma", "3.0"):
            row["ITAE"] = "1e-3"
    changed = hardware_cures._findings(rows, name)
    assert "sigma at x3 the rule: it restores vud's tracking advantage over fae" in changed


def test_the_committed_cures_csv_is_what_the_command_computes(tmp_path):
    """A full run of the cures' study (native edition) gives the committed CSV's numbers."""
    pytest.importorskip("ziglang", reason="the native edition needs zig's C compiler (pip install -e '.[test]')")
    completed = subprocess.run([sys.executable, "-m", "harness", "hardware", "--cures", "--edition", "native", "--jobs",
                                "2", "--no-progress", "--out", str(tmp_path)], cwd=ROOT, capture_output=True, text=True,
                               timeout=3600)
    assert completed.returncode == 0, completed.stderr[-3000:]
    fresh = hardware.read_csv(tmp_path / "hardware_cures.csv")
    committed = hardware.read_csv(hardware_cures.DOCS_CSV)
    assert len(fresh) == len(committed)
    for new, old in zip(fresh, committed):
        for key in hardware_cures.COLUMNS:
            if old[key] and re.fullmatch(r"-?[\d.]+(e-?\d+)?", old[key]):
                assert math.isclose(float(new[key]), float(old[key]), rel_tol=1e-6, abs_tol=1e-12), \
                    (old["scenario"], old["setting"], old["cure"], old["scale"], key, new[key], old[key])
            else:
                assert new[key] == old[key], (old["scenario"], old["setting"], old["cure"], old["scale"], key)


def test_a_short_run_of_the_cures_writes_its_csv_and_section(tmp_path, capsys):
    assert cli_main(["hardware", "--cures", "--edition", "native", "--stop", "0.05", "--jobs", "2", "--no-progress",
                     "--out", str(tmp_path)]) == 0
    assert "112 runs" in capsys.readouterr().out
    assert (tmp_path / "hardware_cures.md").read_text().startswith(hardware_cures.BEGIN)
    assert len(hardware.read_csv(tmp_path / "hardware_cures.csv")) == 112
    assert cli_main(["hardware", "--cures", "--stop", "0.05", "--apply", "--out", str(tmp_path)]) == 2
    assert cli_main(["hardware", "--cures", "--out", "docs", "--stop", "0.01"]) == 2  # a tracked output


class _DiskFull:
    def __str__(self):
        raise OSError(28, "No space left on device")


@pytest.mark.parametrize("study", ["hardware", "hardware_cures"])
def test_a_csv_that_fails_mid_write_leaves_the_previous_file_and_names_it(tmp_path, study):
    from harness.atomic_files import OutputError

    module = {"hardware": hardware, "hardware_cures": hardware_cures}[study]
    path = tmp_path / "study.csv"
    path.write_text("the previous file\n")
    rows = [{"scenario": "pendulum_case2_hardware"}, {"scenario": _DiskFull()}]
    with pytest.raises(OutputError, match=re.escape(f"cannot write {path}: No space left on device; the previous")):
        module.write_csv(rows, path)
    assert path.read_text() == "the previous file\n"
    assert [p.name for p in tmp_path.iterdir()] == ["study.csv"]  # no partial file left
