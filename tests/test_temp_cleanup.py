"""Nothing left behind in the temporary directory, on every exit path.

Each test points the temporary directory (Python's ``tempfile`` and ``TMPDIR``, which
fmpy, Ecos and spawned workers use) at an empty folder of its own, runs a representative
piece of work and checks that the folder is empty again: a master run, a failed
instantiation (alone, and of the last instance of a scenario through the command line), a run
whose FMU rejects a parameter, an Ecos run, the tests' Driven helper, the FMUs extracted once per
process, ``tables`` stopped by SIGTERM or SIGINT while its workers run, a pool worker that ignores
SIGTERM until it is killed, and a run killed with SIGKILL (the next one removes what it left).
"""
import dataclasses
import gc
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time as clock
import zipfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from harness import fmi, termination, unpack
from harness import scenario as scenarios
from harness.cases import Case, run_case
from harness.fmi import Component, FmiError, ModelInfo
from harness.master import simulate
from tests.ctrl_c import with_ctrl_c
from tests.fmu_helpers import Driven


@pytest.fixture
def temp_dir(tmp_path, monkeypatch):
    """An empty folder that is the temporary directory for this test."""
    folder = tmp_path / "temp"
    folder.mkdir()
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def left_in(folder):
    return sorted(os.listdir(folder))


def test_a_master_run_leaves_nothing(fmu_paths, temp_dir):
    result = simulate(scenarios.configure("pendulum_case1", "vud", stop=0.02), fmu_paths=fmu_paths)
    assert result.complete and left_in(temp_dir) == []


def test_a_run_whose_fmu_rejects_a_parameter_leaves_nothing(fmu_paths, temp_dir):
    outcome = run_case(Case("pendulum_case1", "vud", stop=0.02, overrides=(("controller.lambda_ce", 1.0),)),
                       fmu_paths)
    assert outcome["status"] == "failed" and "lambda_ce = 1.0 is invalid" in outcome["reason"]
    assert left_in(temp_dir) == []


def test_a_failed_instantiation_leaves_nothing(fmu_paths, temp_dir):
    info = ModelInfo.read(fmu_paths["InvertedPendulum"])
    wrong = dataclasses.replace(info, model_identifier="NoSuchModel")  # its shared library does not exist
    with pytest.raises(FmiError, match="loading the FMU's shared library"):
        Component("plant", wrong).instantiate()
    assert left_in(temp_dir) == []


def test_an_ecos_run_leaves_nothing(fmu_paths, temp_dir, tmp_path):
    from harness.hosts import engines, ssp

    try:
        engines.import_ecospy()
    except engines.EngineUnavailable as error:
        pytest.skip(str(error))
    scenario = scenarios.configure("pendulum_case1", "vud", stop=0.02)
    package = ssp.export_ssp(scenario, tmp_path / "package" / "case.ssp", fmu_paths=fmu_paths)
    assert left_in(temp_dir) == []
    result = engines.run_ecos(package)
    assert len(result.time) == scenario.steps + 1
    assert left_in(temp_dir) == []  # Ecos unpacked the SSP and the FMUs into a folder removed after the run
    assert os.environ["TMPDIR"] == str(temp_dir)  # and the temporary directory is restored


def test_the_driven_helper_removes_its_extraction(fmu_paths, temp_dir):
    path = fmu_paths["TrackingReference"]
    Driven(path, "freed").initialize().free()
    assert left_in(temp_dir) == []
    forgotten = Driven(path, "forgotten").initialize()  # a test that frees the instance by hand
    forgotten.slave.terminate()
    forgotten.slave.freeInstance()
    assert len(left_in(temp_dir)) == 1
    del forgotten
    gc.collect()
    assert left_in(temp_dir) == []


def test_fmus_extracted_once_per_process_are_shared_renewed_and_removed(fmu_paths, temp_dir, tmp_path, monkeypatch):
    """harness/fmi.py's extracted_fmu: one folder per FMU file and process, a new one when the file
    changes, none left after release_extractions; the first call removes what a killed process left."""
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    killed = temp_dir / f"{unpack.PREFIX}{int(ended.stdout)}-shared-TrackingReference-x"
    running = temp_dir / f"{unpack.PREFIX}{os.getppid()}-shared-TrackingReference-y"
    for folder in (killed, running):
        folder.mkdir()
    monkeypatch.setattr(unpack, "_AT_EXIT", [])  # as in a new process: its first unpack folder sweeps
    path = Path(shutil.copy(fmu_paths["TrackingReference"], tmp_path / "TrackingReference.fmu"))
    info, folder = fmi.extracted_fmu(path)
    assert not killed.exists() and running.exists()
    assert info.model_identifier == "TrackingReference" and (Path(folder) / "modelDescription.xml").is_file()
    again, same = fmi.extracted_fmu(path)
    assert again is info and same == folder
    component = Component("reference", info).instantiate(extracted=folder)
    component.free()
    assert Path(folder).is_dir()  # a shared extraction outlives the instances that use it
    stamp = path.stat()
    os.utime(path, ns=(stamp.st_atime_ns, stamp.st_mtime_ns + 10 ** 9))  # the FMU rebuilt
    _, renewed = fmi.extracted_fmu(path)
    assert renewed != folder and not Path(folder).exists()
    fmi.release_extractions()
    assert left_in(temp_dir) == [running.name]


ROOT = Path(__file__).resolve().parents[1]


def without_binaries(source: Path, target: Path) -> Path:
    """An FMU whose shared libraries are gone: loading it fails."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for info in old.infolist():
            if not info.filename.startswith("binaries/"):
                new.writestr(info, old.read(info))
    return target


def test_a_failed_instantiation_of_the_last_instance_leaves_nothing_of_the_others(fmu_paths, temp_dir, tmp_path,
                                                                                   capsys):
    from harness.cli import main as cli_main

    broken = without_binaries(fmu_paths["AdaptiveFuzzyController"], tmp_path / "NoBinaries.fmu")
    text = (scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text()
    scenario = tmp_path / "broken.toml"  # plant and reference are instantiated before the controller fails
    scenario.write_text(text.replace('fmu = "AdaptiveFuzzyController"', f'fmu = "{broken}"')
                        .replace("stop = 20.0", "stop = 0.01"))
    assert cli_main(["run", str(scenario)]) == 1
    assert "controller: loading the FMU's shared library failed" in capsys.readouterr().err
    assert left_in(temp_dir) == []


def _harness(arguments, temp_dir: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "harness", *arguments], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=dict(os.environ, TMPDIR=str(temp_dir)),
                            preexec_fn=with_ctrl_c)  # its SIGINT a Ctrl-C whatever this process ignores


def _wait_for_unpacked(temp_dir: Path, process, count: int, timeout_s: float = 120.0):
    """Until the run has unpacked ``count`` folders into ``temp_dir`` (its workers are running)."""
    deadline = clock.monotonic() + timeout_s
    while len([n for n in left_in(temp_dir) if n.startswith(unpack.PREFIX)]) < count:
        assert process.poll() is None, process.communicate()
        assert clock.monotonic() < deadline, f"no {count} unpack folders after {timeout_s} s: {left_in(temp_dir)}"
        clock.sleep(0.05)


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_tables_stopped_while_its_workers_run_leaves_nothing(fmu_paths, tmp_path, stop):
    temp_dir = tmp_path / "temp"
    temp_dir.mkdir()
    process = _harness(["tables", "--out", str(tmp_path / "out"), "--jobs", "2"], temp_dir)
    _wait_for_unpacked(temp_dir, process, 4)  # both workers instantiating or running their first case
    process.send_signal(stop)
    _, error = process.communicate(timeout=60)
    assert process.returncode == 128 + stop, error
    assert error.strip().splitlines()[-1] == ("error: terminated (SIGTERM)" if stop == signal.SIGTERM
                                              else "error: interrupted")
    assert left_in(temp_dir) == []


def _unpack_then_ignore_sigterm(_):
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # a worker stuck where SIGTERM cannot unwind it (a C call)
    folder = unpack.unpack_folder("stuck")
    clock.sleep(60)
    return str(folder)


def test_a_worker_killed_before_it_could_unwind_leaves_nothing(temp_dir):
    """end_workers kills a worker that outlives the grace period; what it had unpacked is removed then."""
    pool = ProcessPoolExecutor(max_workers=1)
    future = pool.submit(_unpack_then_ignore_sigterm, None)
    deadline = clock.monotonic() + 60
    while not left_in(temp_dir):
        assert clock.monotonic() < deadline and not future.done()
        clock.sleep(0.05)
    termination.end_workers(pool, grace_s=0.5)
    assert left_in(temp_dir) == []


def test_a_run_killed_with_sigkill_leaves_folders_the_next_run_removes(fmu_paths, tmp_path):
    temp_dir = tmp_path / "temp"
    temp_dir.mkdir()
    killed = _harness(["run", "pendulum_case1"], temp_dir)
    _wait_for_unpacked(temp_dir, killed, 3)
    killed.kill()
    killed.communicate()
    assert len(left_in(temp_dir)) >= 3  # nothing runs after SIGKILL ...
    again = _harness(["run", "pendulum_case1", "--stop", "0.01"], temp_dir)
    _, error = again.communicate(timeout=120)
    assert again.returncode == 0, error
    assert left_in(temp_dir) == []  # ... the next run's first unpacking removes it
