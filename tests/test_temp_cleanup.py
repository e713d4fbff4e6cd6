"""Nothing left behind in the temporary directory.

Each test points the temporary directory (Python's ``tempfile`` and ``TMPDIR``, which
fmpy, Ecos and spawned workers use) at an empty folder of its own, runs a representative
piece of work and checks that the folder is empty again: a master run, a failed
instantiation, a run whose FMU rejects a parameter, an Ecos run, the tests' Driven helper, the
FMUs extracted once per process.
"""
import dataclasses
import gc
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from harness import fmi, unpack
from harness import scenario as scenarios
from harness.cases import Case, run_case
from harness.fmi import Component, FmiError, ModelInfo
from harness.master import simulate
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
