"""The native FMUs are source FMUs: an importer rebuilds each from its own ``sources/`` and gets the
shipped FMU's results bit for bit.

FMI 2.0: fmpy's ``fmpy.build.build_platform_binary`` compiles the files of ``<SourceFiles>`` with
CMake; FMI 3.0: ``fmi-bd2cmake`` turns ``sources/buildDescription.xml`` into a CMake project, which
CMake builds. The binaries are removed first; both FMUs are simulated by fmpy on the same inputs and
every recorded array must be equal. The tests skip when zig (the native build), CMake, a C compiler
or fmi-bd2cmake is missing.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu
from fmpy.build import build_platform_binary
from fmpy.validation import validate_fmu

from harness.fmu_build import native as build_native
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.native_stages import compiler, sources

MODELS = [m.model_identifier for m in build_native.models()]
STOP, STEP = 0.2, 1e-3  # s: a short run of each FMU on smooth inputs

pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(),
                       reason="zig's C compiler is not installed (pip install -e .)"),
    pytest.mark.skipif(shutil.which("cmake") is None or shutil.which("cc") is None,
                       reason="rebuilding a source FMU needs CMake and a C compiler (cc)"),
]


def bd2cmake() -> list[str] | None:
    """The fmi-bd2cmake command of this environment, or None."""
    try:
        import fmi_bd2cmake  # noqa: F401 (pip install fmi-bd2cmake, in the test extra)
    except ImportError:
        return None
    return [sys.executable, "-m", "fmi_bd2cmake.cli"]


@pytest.fixture(scope="module")
def native():
    return build_native.ensure_built()


def unpacked_without_binaries(fmu: Path, folder: Path) -> Path:
    with zipfile.ZipFile(fmu) as archive:
        archive.extractall(folder)
    shutil.rmtree(folder / "binaries")
    return folder


def inputs_of(fmu) -> np.ndarray | None:
    """Smooth, distinct inputs: input i is 0.1 (i + 1) sin((i + 2) t)."""
    names = [v.name for v in read_model_description(str(fmu)).modelVariables if v.causality == "input"]
    if not names:
        return None
    time = np.arange(0.0, STOP + STEP / 2, STEP)
    table = np.zeros(len(time), dtype=[("time", np.float64)] + [(name, np.float64) for name in names])
    table["time"] = time
    for i, name in enumerate(names):
        table[name] = 0.1 * (i + 1) * np.sin((i + 2) * time)
    return table


def records(fmu, inputs) -> np.ndarray:
    return simulate_fmu(str(fmu), stop_time=STOP, output_interval=STEP, step_size=STEP, input=inputs,
                        fmi_type="CoSimulation")


def largest_difference(a: np.ndarray, b: np.ndarray) -> float:
    assert a.dtype.names == b.dtype.names and len(a) == len(b)
    return max(float(np.max(np.abs(a[name] - b[name]))) for name in a.dtype.names)


def assert_same_records(shipped: Path, rebuilt: Path):
    inputs = inputs_of(shipped)
    expected, got = records(shipped, inputs), records(rebuilt, inputs)
    assert largest_difference(expected, got) == 0.0
    for name in expected.dtype.names:
        assert np.array_equal(expected[name], got[name]), f"{name} differs after rebuilding from sources/"


@pytest.mark.parametrize("model", MODELS)
def test_fmi2_sources_rebuild_to_the_same_results(model, native, tmp_path):
    folder = unpacked_without_binaries(native[model][2], tmp_path / "fmu")
    description = read_model_description(str(folder))
    units = description.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert units == list(sources.compilation_units(fmu_catalog.fmu(model), 2))
    (tmp_path / "build").mkdir()
    build_platform_binary(folder, tmp_path / "build")
    assert any((folder / "binaries").rglob(f"{model}.*")), "fmpy built no binary from <SourceFiles>"
    assert_same_records(native[model][2], folder)


@pytest.mark.parametrize("model", MODELS)
def test_fmi3_build_description_rebuilds_to_the_same_results(model, native, tmp_path):
    command = bd2cmake()
    if command is None:
        pytest.skip("fmi-bd2cmake is not installed (pip install fmi-bd2cmake)")
    folder = unpacked_without_binaries(native[model][3], tmp_path / "fmu")
    subprocess.run([*command, "--input", "sources/buildDescription.xml", "--output", "CMakeLists.txt"],
                   cwd=folder, check=True, capture_output=True)
    subprocess.run(["cmake", "-S", ".", "-B", "build", "-DCMAKE_BUILD_TYPE=Release",
                    f"-DFMI_HEADERS_DIR={compiler.fmi_headers()}"], cwd=folder, check=True, capture_output=True)
    subprocess.run(["cmake", "--build", "build"], cwd=folder, check=True, capture_output=True)
    subprocess.run(["cmake", "--install", "build"], cwd=folder, check=True, capture_output=True)
    for scratch in ("build", "CMakeLists.txt"):  # the FMU again: only what the archive holds, and the binary
        shutil.rmtree(folder / scratch) if (folder / scratch).is_dir() else (folder / scratch).unlink()
    assert any((folder / "binaries").rglob(f"{model}.*")), "CMake built no binary from buildDescription.xml"
    assert_same_records(native[model][3], folder)


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("model", MODELS)
def test_source_fmus_validate(model, version, native):
    """fmpy's validation (the schemas, buildDescription.xml included) finds nothing to report."""
    assert validate_fmu(str(native[model][version])) == []


@pytest.mark.parametrize("model", MODELS)
def test_each_compilation_unit_is_shipped(model, native):
    with zipfile.ZipFile(native[model][2]) as archive:
        names = set(archive.namelist())
    row = fmu_catalog.fmu(model)
    assert {f"sources/{unit}" for unit in sources.compilation_units(row, 2)} <= names
    with zipfile.ZipFile(native[model][3]) as archive:
        names = set(archive.namelist())
    assert {f"sources/{unit}" for unit in sources.compilation_units(row, 3)} <= names
