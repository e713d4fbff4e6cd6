"""Shared fixtures: the FMUs are built once per test session (only if stale)."""
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


@pytest.fixture(scope="session")
def fmu_paths():
    import build_fmu

    return build_fmu.ensure_built()
