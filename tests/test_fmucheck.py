"""The FMU Compliance Checker (fmuCheck, built from source) passes every FMU we build, strictly.

The checker and its wrapper live in ``<repo>/../shared/tools/fmucheck/`` (not part of a
clone): the tests skip with that reason when it is absent.  ``--strict``: 0 errors and
0 warnings from the checker, and no FMU log message with status Warning or worse.
"""
import os
import subprocess
import sys
from pathlib import Path

import pytest

from harness.fmu_build import builder as build_fmu

ROOT = Path(__file__).resolve().parents[1]
CHECKER = ROOT.parent / "shared" / "tools" / "fmucheck" / "fmucheck.sh"
pytestmark = pytest.mark.skipif(not CHECKER.exists(),
                                reason=f"the FMU Compliance Checker is not here ({CHECKER}: ../shared is "
                                       "absent outside the project's machines)")


def fmucheck(fmu: Path, *options: str) -> subprocess.CompletedProcess:
    environment = dict(os.environ, FMUCHECK_PYTHON=sys.executable)  # the interpreter whose pythonfmu built it
    return subprocess.run([str(CHECKER), "--strict", str(fmu), *options], capture_output=True, text=True,
                          env=environment, timeout=120)


def assert_strict_pass(check: subprocess.CompletedProcess, name: str):
    text = check.stdout + check.stderr
    assert check.returncode == 0, text
    assert f"fmucheck: PASS {name}: checker 0 error(s), 0 warning(s); FMU 0 error(s), 0 warning(s)" in text, text


@pytest.mark.parametrize("identifier", [f.model_identifier for f in build_fmu.FMUS])
def test_every_fmu_passes_the_compliance_checker_strictly(fmu_paths, identifier):
    assert_strict_pass(fmucheck(fmu_paths[identifier]), identifier)


def test_the_controller_passes_at_its_default_experiment_step(fmu_paths):
    from fmpy import read_model_description

    experiment = read_model_description(str(fmu_paths["AdaptiveFuzzyController"])).defaultExperiment
    assert experiment is not None and experiment.stepSize
    assert_strict_pass(fmucheck(fmu_paths["AdaptiveFuzzyController"], "-h", str(experiment.stepSize), "-s", "2"),
                       "AdaptiveFuzzyController")


def test_the_benchmark_floor_fmus_pass_too(tmp_path):
    from harness.hosts.bench import build_null_fmus

    for path in build_null_fmus(tmp_path).values():
        assert_strict_pass(fmucheck(path), path.stem)
