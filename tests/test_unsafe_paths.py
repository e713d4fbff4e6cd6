"""The FMUs run from folders whose names a URI escapes (é, &, %), in our master and in fmpy, in both editions.

pythonfmu 0.7's C++ wrapper decodes only ``%20`` of the resource URI a host gives: unpacked where the path
holds such a character, a pythonfmu FMU finds no Python class and crashes its host (a segmentation
fault, exit 139).  Our master unpacks into a folder whose URI needs no escape (harness/unpack.py) and
says so in one line where it cannot; fmpy users unpack where the path is plain (docs/using_fmus.md).
Every run is a subprocess: a crash must fail the test, not end the session.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from harness import scenario as scenarios
from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native

ROOT = Path(__file__).resolve().parents[1]
UNSAFE = "unsafé & 100%"  # a non-ASCII letter and two characters a URI escapes (the space it keeps as %20)
SEGMENTATION_FAULT = -11  # subprocess's return code for a child killed by SIGSEGV (a shell says 139)


@pytest.fixture(params=["python", "native"])
def edition(request):
    if request.param == "native" and not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e '.[native]')")
    return request.param


@pytest.fixture
def edition_fmus(edition, fmu_paths):
    return fmu_paths if edition == "python" else build_fmu.ensure_built(edition="native")


def python(code_or_arguments, cwd: Path, **environment):
    arguments = ["-c", code_or_arguments] if isinstance(code_or_arguments, str) else code_or_arguments
    return subprocess.run([sys.executable, *arguments], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env={**os.environ, "AFC_MASTER_LOOP": "python", **environment})


def unsafe_copies(fmus: dict, tmp_path: Path) -> tuple[Path, dict]:
    """The FMUs copied into a folder named UNSAFE, and a temporary folder beside them named so too."""
    folder = tmp_path / UNSAFE / "fmus"
    folder.mkdir(parents=True)
    temporary = tmp_path / UNSAFE / "temp"
    temporary.mkdir()
    return temporary, {name: Path(shutil.copy(path, folder / path.name)) for name, path in fmus.items()}


def test_our_master_runs_the_fmus_from_such_a_folder_with_such_a_temporary_folder(edition, edition_fmus, tmp_path):
    temporary, copies = unsafe_copies(edition_fmus, tmp_path)
    text = (scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text()
    for model in ("InvertedPendulum", "TrackingReference", "AdaptiveFuzzyController"):
        text = text.replace(f'fmu = "{model}"', f'fmu = "{copies[model].as_posix()}"')
    scenario = tmp_path / UNSAFE / "case.toml"
    scenario.write_text(text.replace("stop = 20.0", "stop = 0.01"))
    completed = python(["-m", "harness", "run", str(scenario), "--edition", edition], ROOT, TMPDIR=str(temporary))
    assert completed.returncode == 0, (completed.returncode, completed.stderr)
    assert "20 steps" in completed.stdout and "ITAE" in completed.stdout
    assert os.listdir(temporary) == []  # unpacked elsewhere (a URI-safe folder) and removed


def test_an_unpack_folder_that_needs_escapes_is_refused_in_one_line(tmp_path):
    unsafe = tmp_path / UNSAFE
    unsafe.mkdir()
    completed = python(["-m", "harness", "run", "pendulum_case1", "--stop", "0.01"], ROOT,
                       AFC_UNPACK_DIR=str(unsafe))
    assert completed.returncode == 2
    assert completed.stderr.strip() == (f"error: AFC_UNPACK_DIR={unsafe}: its file: URI needs percent-escapes; give "
                                        "a folder whose path holds ASCII letters, digits, '-', '_', '.', '~' and "
                                        "spaces only")


SIMULATE = """
import sys
from fmpy import simulate_fmu
for path in sys.argv[1:]:
    result = simulate_fmu(path, stop_time=0.01, step_size=1e-3, output_interval=1e-3)
    print(path, len(result))
"""


def test_fmpy_simulates_the_controller_and_a_plant_from_such_a_folder(edition, edition_fmus, tmp_path):
    """fmpy unpacks into the temporary folder: an FMU file in a folder named with é, & and % runs; the native
    edition also from a temporary folder named so."""
    temporary, copies = unsafe_copies(edition_fmus, tmp_path)
    files = [str(copies["AdaptiveFuzzyController"]), str(copies["InvertedPendulum"])]
    completed = python(["-c", SIMULATE, *files], tmp_path)
    assert completed.returncode == 0, (completed.returncode, completed.stderr)
    assert [line.split()[-1] for line in completed.stdout.splitlines()] == ["11", "11"]
    if edition == "native":
        completed = python(["-c", SIMULATE, *files], tmp_path, TMPDIR=str(temporary))
        assert completed.returncode == 0, (completed.returncode, completed.stderr)


def test_pythonfmus_wrapper_still_crashes_when_unpacked_where_the_uri_needs_escapes(fmu_paths, tmp_path):
    """The limitation docs/using_fmus.md states, held to pythonfmu's behaviour: when this fails, pythonfmu
    decodes the URI and the docs and harness/unpack.py's safe folder can go."""
    folder = tmp_path / UNSAFE / "controller"
    code = (f"import fmpy; fmpy.extract({str(fmu_paths['AdaptiveFuzzyController'])!r}, {str(folder)!r}); "
            f"fmpy.simulate_fmu({str(folder)!r}, stop_time=0.01, step_size=1e-3)")
    crashed = python(code, tmp_path)
    assert crashed.returncode == SEGMENTATION_FAULT, (crashed.returncode, crashed.stderr[-500:])
    plain = tmp_path / "plain" / "controller"
    works = python(code.replace(repr(str(folder)), repr(str(plain))), tmp_path)
    assert works.returncode == 0, works.stderr
