"""Shared fixtures: the FMUs are built once per test session (only if stale).

At the end of a session the summary lists what the session left in the temporary
directory (pytest's own pytest-of-USER folder aside): a run should leave nothing.
On a machine where other processes share the folder, their new entries appear too.
"""
import os
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


@pytest.fixture(scope="session")
def fmu_paths():
    import build_fmu

    return build_fmu.ensure_built()


@pytest.fixture(scope="session")
def lag_plant_fmu(tmp_path_factory):
    """A user's plant FMU that the project does not ship (tests/data/first_order_lag_fmu.py), built once."""
    import build_fmu

    return build_fmu.build_script(ROOT / "tests" / "data" / "first_order_lag_fmu.py",
                                  tmp_path_factory.mktemp("lag_plant") / "FirstOrderLag.fmu", [])


@pytest.fixture(scope="module")
def unzipped(fmu_paths, tmp_path_factory):
    """{model identifier: extracted FMU folder}, extracted once per test module."""
    from fmpy import extract

    from tests.fmu_variables import FMU_IDS

    return {fmu_id: extract(str(fmu_paths[fmu_id]), str(tmp_path_factory.mktemp(fmu_id)))
            for fmu_id in FMU_IDS}


_TEMP_BEFORE = set()


def pytest_sessionstart(session):
    _TEMP_BEFORE.update(os.listdir(tempfile.gettempdir()))


def pytest_sessionfinish(session):
    fmi = sys.modules.get("harness.fmi")  # the FMUs it extracted once for the session (harness/fmi.py: extracted_fmu)
    if fmi is not None:
        fmi.release_extractions()


def pytest_terminal_summary(terminalreporter):
    folder = tempfile.gettempdir()
    left = sorted(name for name in set(os.listdir(folder)) - _TEMP_BEFORE if not name.startswith("pytest-of-"))
    if left:
        shown = ", ".join(left[:20]) + (f" and {len(left) - 20} more" if len(left) > 20 else "")
        terminalreporter.write_line(f"temp directory {folder}: {len(left)} new entries since the session started "
                                    f"(left by this run, or by other processes): {shown}", yellow=True)
    else:
        terminalreporter.write_line(f"temp directory {folder}: nothing left behind by this run")
