"""The win64 DLLs' Model Exchange path, executed under wine: what the linux64 binaries compute.

tests/c_host/me_host.c integrates one FMU alone through its Model Exchange interface (fixed-step
RK4 via SetTime / SetContinuousStates / GetDerivatives, events at the step ends); it is built for
Linux and for Windows with zig, as tests/test_build_native_windows.py builds its co-simulation host, and
fed the same inputs.  The test checks

* the Linux host computes what the same sequence of calls through fmpy's FMU2Model / FMU3Model
  computes (tests/me_helpers.py), bit for bit: the host drives the FMU as intended;
* the Windows DLL under wine gives the Linux .so's values to ``WINDOWS_TOLERANCE`` of each
  column's range (the DLL carries zig's libm, one ulp off glibc's on a few percent of arguments:
  tests/test_build_native_windows.py), through the manipulator's friction events (same event count).
"""
import hashlib
import math
import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build import toolchain as c_toolchain
from tests import me_helpers as me
from tests.test_build_native_windows import (DEFAULT_PREFIX, native, run_with_files,  # noqa: F401 - fixtures
                                             scaled_difference, wine, wine_program)

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "tests" / "c_host" / "me_host.c"
WINDOWS_TOLERANCE = 1e-12
STEP, STEPS = 1e-3, 1500

pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(),
                       reason="zig's C compiler is not installed (pip install -e .)"),
    pytest.mark.skipif(wine_program() is None,
                       reason="wine is not installed (apt-get install --no-install-recommends wine64)"),
]


def _inputs(model: str, t: float) -> dict:
    if model == "Manipulator":  # stuck until 0.154 s (break-away), backwards, forwards, backwards
        return {"u": 12.25 if t < 0.6 else (25.0 if t < 1.0 else 12.25)}
    if model == "AdaptiveFuzzyController":
        return dict(e=0.3 * math.cos(3 * t), de=-0.9 * math.sin(3 * t), ym=0.2 * math.sin(t), dym=0.2 * math.cos(t))
    if model == "TrackingReference":
        return {"y": 0.1 * t, "dy": 0.1}
    return {"u": math.sin(3 * t)}


PARAMETERS = {"InvertedPendulum": {"dist_gain": 1.0}, "AdaptiveFuzzyController": {"variant": 3},
              "Manipulator": {"x1_start": 0.0, "x2_start": 0.0}}


def _build(target: str, name: str, *extra: str) -> Path:
    arguments = ["cc", "-target", target, "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", *extra]
    digest = hashlib.sha256("\0".join([c_toolchain.zig_version(), *arguments]).encode() + SOURCE.read_bytes())
    folder = build_native.WORK_DIR / "hosts"
    binary = folder / f"{Path(name).stem}-{digest.hexdigest()[:16]}{Path(name).suffix}"
    if not binary.exists():
        folder.mkdir(parents=True, exist_ok=True)
        environment = dict(os.environ)
        environment.setdefault("ZIG_GLOBAL_CACHE_DIR", str(build_native.WORK_DIR / "zig-cache"))
        environment.setdefault("ZIG_LOCAL_CACHE_DIR", str(build_native.WORK_DIR / "zig-cache"))
        with tempfile.TemporaryDirectory(dir=folder) as scratch:
            built = Path(scratch) / name
            completed = subprocess.run([sys.executable, "-m", "ziglang", *arguments, "-o", str(built), str(SOURCE)],
                                       capture_output=True, text=True, env=environment, cwd=scratch)
            assert completed.returncode == 0, completed.stderr
            os.replace(built, binary)
    return binary


@pytest.fixture(scope="module")
def hosts():
    return {"linux64": _build("x86_64-linux-gnu", "me_host", "-D_POSIX_C_SOURCE=200809L", "-ldl"),
            "win64": _build("x86_64-windows-gnu", "me_host.exe")}


LIBRARIES = {(2, "linux64"): "binaries/linux64/{}.so", (2, "win64"): "binaries\\win64\\{}.dll",
             (3, "linux64"): "binaries/x86_64-linux/{}.so", (3, "win64"): "binaries\\x86_64-windows\\{}.dll"}


def _run_host(host: Path, platform: str, fmu: Path, version: int, folder: Path, model: str, wine_setup=None):
    from fmpy import read_model_description
    md = read_model_description(str(fmu))
    variables = {v.name: v for v in md.modelVariables}
    if not (folder / "modelDescription.xml").exists():
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(folder)
    names = list(_inputs(model, 0.0))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    resources = folder / "resources"
    location = (resources.as_uri() if version == 2 else
                "Z:" + str(resources).replace("/", "\\") if platform == "win64" else str(resources))
    parameters = [f"i:{variables[n].valueReference}={int(v)}" if variables[n].type in ("Integer", "Int32")
                  else f"r:{variables[n].valueReference}={float(v)!r}" for n, v in PARAMETERS.get(model, {}).items()]
    arguments = [LIBRARIES[version, platform].format(md.modelExchange.modelIdentifier), location, md.guid, repr(STEP),
                 str(md.numberOfContinuousStates), str(md.numberOfEventIndicators),
                 ",".join(str(variables[n].valueReference) for n in names) or "-",
                 ",".join(str(variables[n].valueReference) for n in outputs), *parameters]
    stdin = "".join(" ".join(repr(float(v)) for v in _inputs(model, n * STEP).values()) + "\n" for n in range(STEPS))
    if platform == "win64":
        program, environment = wine_setup
        command = [program, str(host), *arguments]
    else:
        environment, command = dict(os.environ), [str(host), *arguments]
    returncode, output, errors = run_with_files(command, stdin, environment, folder, platform)
    assert returncode == 0, f"{model} FMI {version} {platform}: exit {returncode}\n{errors}"
    return np.array([[float(x) for x in line.split()] for line in output.splitlines()]), outputs


def _python_host(fmu: Path, version: int, model: str) -> np.ndarray:
    """The sequence of me_host.c through fmpy (the same calls, in the same order)."""
    instance = me.MeInstance(fmu, version)
    outputs = [v.name for v in instance.md.modelVariables if v.causality == "output"]
    rows = []
    try:
        instance.enter(**PARAMETERS.get(model, {}))
        instance.set(**_inputs(model, 0.0))
        instance.exit()
        instance.fmu.enterContinuousTimeMode()
        z = instance.indicators()
        previous = _inputs(model, 0.0)
        for n in range(STEPS):
            t = n * STEP
            given = _inputs(model, t)
            instance.set(**given)
            if n > 0 and given != previous:
                instance.event()
                z = instance.indicators()
            previous = given
            values = instance.get(*outputs) if len(outputs) > 1 else [instance.get(outputs[0])]
            x0 = instance.states()
            rows.append([*values, *x0.tolist()])
            k = []
            for s, c in enumerate((0.0, 0.5, 0.5, 1.0)):
                instance.set_time(t + c * STEP)
                if instance.nx:
                    instance.set_states(x0 if s == 0 else x0 + c * STEP * k[-1])
                    k.append(instance.derivatives())
            instance.set_time(t + STEP)
            if instance.nx:
                instance.set_states(x0 + STEP / 6.0 * (k[0] + 2.0 * (k[1] + k[2]) + k[3]))
            instance.fmu.completedIntegratorStep()
            if instance.nz:
                after = instance.indicators()
                if np.any((z > 0.0) & (after <= 0.0)):
                    instance.event()
                    after = instance.indicators()
                z = after
    finally:
        instance.free()
    return np.array(rows)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", ["InvertedPendulum", "Manipulator", "DcMotorArm", "AdaptiveFuzzyController",
                                   "TrackingReference"])
def test_the_win64_dlls_model_exchange_under_wine_computes_what_linux_computes(native, hosts, wine, tmp_path, model,
                                                                                version):
    fmu = native[model][version]
    linux, outputs = _run_host(hosts["linux64"], "linux64", fmu, version, tmp_path / "fmu", model)
    np.testing.assert_array_equal(linux, _python_host(fmu, version, model),
                                  err_msg=f"{model} FMI {version}: the C host vs the same calls through fmpy")
    windows, _ = _run_host(hosts["win64"], "win64", fmu, version, tmp_path / "fmu", model, wine)
    assert windows.shape == linux.shape
    scaled = scaled_difference(windows, linux)
    differing = int(np.count_nonzero(windows != linux))
    print(f"{model} FMI {version} model exchange: {linux.shape[0]} RK4 steps x {linux.shape[1]} values, win64 under "
          f"wine vs linux64: {differing} values differ, largest difference {scaled.max():.3g} of the column's range")
    assert np.all(scaled <= WINDOWS_TOLERANCE)
    assert np.ptp(linux, axis=0).max() > 0.0
    if model == "Manipulator":  # the friction modes were visited: it moved, stuck (dy = 0 over steps), moved again
        dy = linux[:, outputs.index("dy")]
        assert np.count_nonzero(dy == 0.0) > 100 and np.count_nonzero(dy < 0.0) > 100 and np.count_nonzero(dy > 0.0) > 100
