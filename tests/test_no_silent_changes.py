"""No silent changes: whole-step stops, atomic builds, a verified Dask FMU cache."""
import hashlib
import os
import subprocess
import threading
import zipfile

import pytest

from harness.fmu_build import builder as build_fmu
from harness import scenario as scenarios
from harness.executors import tasks
from harness.studies.sweep import grid as sweep_grid
from harness.cases import Case, run_case
from harness.cli import main as cli_main
from harness.scenario import ScenarioError


# ---------------------------------------------------------- whole steps
@pytest.mark.parametrize("step,stop,nearest", [(3e-4, 1e-3, "0.0009"), (4e-4, 0.0101, "0.01 s"),
                                               (1e-3, 0.0026, "0.003")])
def test_a_stop_that_is_not_a_whole_number_of_steps_is_an_error_naming_both_and_the_nearest(step, stop, nearest):
    with pytest.raises(ScenarioError) as error:
        scenarios.configure("pendulum_case1", "vud", step=step, stop=stop)
    message = str(error.value)
    assert f"stop = {stop:g} s" in message and f"steps of {step:g} s" in message, message
    assert f"nearest valid stop: {nearest}" in message, message


def test_the_run_command_refuses_it_in_one_line(capsys):
    assert cli_main(["run", "pendulum_case1", "--step", "0.0003", "--stop", "0.001"]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "nearest valid stop: 0.0009 s" in err, err


@pytest.mark.parametrize("step,stop", [(3e-4, 9e-4), (4e-4, 0.02), (5e-5, 0.3), (0.1, 0.3)])
def test_whole_numbers_of_steps_are_accepted_despite_rounding(step, stop):
    scenario = scenarios.configure("pendulum_case1", "vud", step=step, stop=stop)
    assert scenario.stop == stop and scenario.notes == []


def test_a_changed_step_moves_the_scenario_s_own_stop_and_says_so(capsys):
    scenario = scenarios.configure("pendulum_case1", "vud", step=3e-4)
    assert scenario.stop == pytest.approx(66667 * 3e-4) and scenario.steps == 66667
    assert scenario.notes == ["stop moved from 20 s to 20.0001 s, a whole number of steps (66667) of 0.0003 s"]


def test_a_case_moves_its_stop_and_its_outcome_says_so(fmu_paths):
    outcome = run_case(Case("pendulum_case1", "vud", step=3e-4, stop=1e-3), fmu_paths)
    assert outcome["status"] == "ok" and outcome["stop"] == pytest.approx(9e-4) and outcome["rows"] == 4
    assert outcome["notes"] and "stop moved from 0.001 s to 0.0009 s" in outcome["notes"][0]


@pytest.mark.parametrize("grids,stop,expected", [
    (["stop=0.1,0.1005"], None, "--grid stop=0.1005: stop = 0.1005 s is not a whole number of steps"),
    (["step=1e-3,3e-3"], 0.1, "--grid step=0.003: stop = 0.1 s is not a whole number of steps of 0.003 s"),
])
def test_a_sweep_refuses_stops_off_the_step_grid_before_anything_runs(fmu_paths, grids, stop, expected):
    with pytest.raises(ScenarioError, match=expected):
        sweep_grid.plan_sweep("pendulum_case1", ("vud",), [sweep_grid.parse_grid(g) for g in grids], stop=stop,
                              step=None if "step" in grids[0] else 1e-3, fmu_paths=fmu_paths)


# ---------------------------------------------------------- atomic builds
REFERENCE = next(f for f in build_fmu.FMUS if f.model_identifier == "TrackingReference")


def test_a_build_writes_a_temporary_file_beside_the_fmu_then_replaces_it(tmp_path, monkeypatch):
    target = tmp_path / "TrackingReference.fmu"
    target.write_bytes(b"the previous FMU")
    seen = []
    real_run = subprocess.run

    def watching_run(command, *args, **kwargs):
        destination = command[4]  # python -c CODE SCRIPT DEST PROJECT_FILES...
        seen.append((destination, target.read_bytes()))
        return real_run(command, *args, **kwargs)

    monkeypatch.setattr(build_fmu.subprocess, "run", watching_run)
    build_fmu.build_script(REFERENCE.script, target, REFERENCE.project_files)
    (destination, during), = seen
    assert os.path.dirname(destination) == str(tmp_path) and destination != str(target)
    assert during == b"the previous FMU"  # untouched while the builder wrote
    assert zipfile.ZipFile(target).testzip() is None and "modelDescription.xml" in zipfile.ZipFile(target).namelist()
    assert os.stat(target).st_mode & 0o444 == 0o444  # readable like any built file
    assert sorted(os.listdir(tmp_path)) == ["TrackingReference.fmu"]  # no temporary file left


def test_a_failed_build_keeps_the_previous_fmu_and_leaves_no_temporary_file(tmp_path):
    target = tmp_path / "TrackingReference.fmu"
    target.write_bytes(b"the previous FMU")
    broken = tmp_path / "broken_fmu.py"
    broken.write_text("raise SystemExit('no FMU here')\n")
    with pytest.raises(RuntimeError, match="building TrackingReference.fmu"):
        build_fmu.build_script(broken, target, ())
    assert target.read_bytes() == b"the previous FMU" and sorted(os.listdir(tmp_path)) == sorted(
        ["TrackingReference.fmu", "broken_fmu.py"])


def test_two_builds_at_once_leave_one_whole_fmu(tmp_path):
    target = tmp_path / "TrackingReference.fmu"
    errors = []

    def build():
        try:
            build_fmu.build_script(REFERENCE.script, target, REFERENCE.project_files)
        except Exception as error:  # noqa: BLE001 - reported below
            errors.append(error)

    threads = [threading.Thread(target=build) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert zipfile.ZipFile(target).testzip() is None and sorted(os.listdir(tmp_path)) == ["TrackingReference.fmu"]


# ---------------------------------------------------------- Dask FMU cache
def test_the_worker_cache_replaces_a_file_whose_hash_is_wrong(fmu_paths, tmp_path, monkeypatch):
    monkeypatch.setattr(tasks, "cache_dir", lambda: tmp_path)
    data = fmu_paths["TrackingReference"].read_bytes()
    digest = hashlib.sha256(data).hexdigest()
    cached = tmp_path / digest[:20] / "TrackingReference.fmu"
    cached.parent.mkdir()
    cached.write_bytes(data[:1000])  # a file cut short (or another FMU) already at the cache path
    assert tasks.cached_file(digest, "TrackingReference.fmu", {digest: data}) == cached
    assert cached.read_bytes() == data  # replaced from the bytes received, not trusted
    good = cached.stat().st_mtime_ns
    tasks.cached_file(digest, "TrackingReference.fmu", {digest: data})
    assert cached.stat().st_mtime_ns == good  # a good file is used as it is
    with pytest.raises(RuntimeError, match="do not have the SHA-256"):
        tasks.cached_file("0" * 64, "TrackingReference.fmu", {"0" * 64: data})
    shipment, blobs = tasks.Shipment.of({"reference": fmu_paths["TrackingReference"]})
    assert tasks.local_files(shipment, blobs) == {"reference": cached}  # a worker's files, by name
    tasks.forget_worker_state()


def test_tables_refuse_a_stop_off_the_step_grid_before_any_run(fmu_paths, tmp_path, capsys, monkeypatch):
    from harness import cases

    started = []
    monkeypatch.setattr(cases, "parallel_map", lambda *args, **kwargs: started.append(args) or [])
    assert cli_main(["tables", "--out", str(tmp_path), "--stop", "0.0101", "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 1 and "stop = 0.0101 s is not a whole number of steps of 0.0005 s" in err, err
    assert not started  # refused before any co-simulation started


def test_a_case_with_a_given_stop_and_the_scenario_s_step_must_fit():
    with pytest.raises(ScenarioError, match="nearest valid stop: 0.01 s"):
        Case("pendulum_case1", "vud", stop=0.0101).build()
    assert Case("pendulum_case1", "vud", step=4e-4, stop=0.0101).build().notes  # a case that varies the step
