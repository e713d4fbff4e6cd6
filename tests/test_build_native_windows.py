"""The native edition's win64 DLLs, executed: under wine, they compute what the linux64 binaries compute.

Each FMU of a closed loop (controller, plant, tracking reference) is driven alone by the C host
of tests/c_host/host.c, built twice with zig: for Linux (it loads binaries/linux64/*.so) and
for Windows (it loads binaries/win64/*.dll, run under wine).  Both are fed the inputs that
our master handed that FMU in a Linux run of the native edition, and print every output it
recorded, with %.17g.  The test checks

* the Linux host reproduces the master's recorded outputs exactly (the host drives the FMU
  as the master does: same parameters, same initial inputs, same sequence of calls);
* the Windows DLL under wine gives the Linux .so's outputs to ``WINDOWS_TOLERANCE``.  They are
  not bit-identical: the .so calls glibc's sin, cos and exp, the DLL carries the libm zig links
  into it (it imports none), which differs from glibc's by one ulp on 3 % (sin, cos) to 10 % (exp)
  of arguments; those last bits then travel through the integration and adaptation
  (docs/native.md has the figures).  Since the DLL brings its own libm, a real Windows machine
  computes what wine computes here.

Wine is Debian's (``apt-get install --no-install-recommends wine64``); the test skips when it
is absent.  It uses its own wine prefix, outside the checkout (its drive z: is a link to /, which
a tool walking the checkout, such as setuptools collecting package data, would follow into the
whole file system): $XDG_CACHE_HOME/afc-fmi/wine-prefix (~/.cache by default), unless WINEPREFIX is set.
"""
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from harness.fmu_build import native as build_native
from harness.scenario import scenario_names
from tests.message_meaning import meaning
from tests.native_hosts import (CASES, FAILING_RUNS, failing_run, first_program, recorded_runs,
                                relative_difference, run_with_files, scaled_difference, zig_build)

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PREFIX = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "afc-fmi" / "wine-prefix"
# Largest |win64 - linux64| of an output, relative to that output's largest |value| in the run.
# The one-ulp libm differences stay orders below it (docs/native.md); a defect (a wrong formula,
# parameter or input) is many orders above.  Per value the relative difference is larger where a
# signal crosses zero: printed, not asserted.
WINDOWS_TOLERANCE = 1e-12


def wine_program() -> str | None:
    """wine64 (Debian's wine64 package puts it in /usr/lib/wine), else wine."""
    return first_program("wine64", "/usr/lib/wine/wine64", "wine")


pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(),
                       reason="zig's C compiler is not installed (pip install -e .)"),
    pytest.mark.skipif(wine_program() is None,
                       reason="wine is not installed (apt-get install --no-install-recommends wine64)"),
]


def wineserver_program(wine: str) -> str | None:
    """The wineserver beside wine (Debian: /usr/lib/wine/wineserver), else on the PATH."""
    for folder in (Path(wine).parent, Path(wine).resolve().parent, Path("/usr/lib/wine")):
        if (folder / "wineserver").exists():
            return str(folder / "wineserver")
    return shutil.which("wineserver")


def wine_environment() -> dict:
    """Quiet and headless: no debug channels, no display, no Mono/Gecko installers."""
    environment = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    environment.update(WINEDEBUG="-all", WINEDLLOVERRIDES="mscoree,mshtml=")
    if "WINEPREFIX" not in environment:
        environment["WINEPREFIX"] = str(DEFAULT_PREFIX)
        # our prefix's wineserver keeps its socket folder (wine-XXXXXX) there, not in /tmp (a prefix
        # of the user's keeps the TMPDIR of its running server: one prefix, one server)
        environment["TMPDIR"] = str(DEFAULT_PREFIX / "server-tmp")
        Path(environment["TMPDIR"]).mkdir(parents=True, exist_ok=True)
    return environment


@pytest.fixture(scope="module")
def wine(tmp_path_factory):
    """(wine program, environment) with an initialised prefix."""
    program, environment = wine_program(), wine_environment()
    prefix = Path(environment["WINEPREFIX"])
    if not (prefix / "system.reg").exists():
        returncode, _, errors = run_with_files([program, "wineboot", "--init"], "", environment,
                                               tmp_path_factory.mktemp("wineboot"), "wineboot")
        server = wineserver_program(program)
        if server is not None:  # the registry files are written when the server quits
            subprocess.run([server, "-w"], env=environment, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, timeout=120)
        assert returncode == 0 and (prefix / "system.reg").exists(), (
            f"wineboot could not make the prefix {prefix}:\n{errors}")
    return program, environment


@pytest.fixture(scope="module")
def hosts():
    """{platform: host binary} for linux64 and win64."""
    return {"linux64": zig_build("x86_64-linux-gnu", Path("host"), "-D_POSIX_C_SOURCE=200809L", "-ldl"),
            "win64": zig_build("x86_64-windows-gnu", Path("host.exe"))}


@pytest.fixture(scope="module")
def native():
    platforms = os.environ.get("AFC_NATIVE_PLATFORMS", "")
    chosen = tuple(p for p in platforms.split(",") if p) or build_native.PLATFORMS
    if not {"linux64", "win64"} <= set(chosen):
        pytest.skip(f"AFC_NATIVE_PLATFORMS={platforms} does not build both linux64 and win64")
    return build_native.ensure_built()


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("scenario_name,controller,stop", CASES)
def test_the_win64_dlls_under_wine_compute_what_the_linux_binaries_compute(native, hosts, wine, tmp_path, version,
                                                                            scenario_name, controller, stop):
    if scenario_name not in scenario_names():
        pytest.skip(f"no scenario {scenario_name} here")
    runs = recorded_runs(scenario_name, controller, stop, native, version, tmp_path)
    assert {run.model for run, _ in runs.values()} >= {"AdaptiveFuzzyController", "TrackingReference"}
    for name, (run, recorded) in runs.items():
        linux = run.run(hosts["linux64"], "linux64")
        # the host replays the master's calls: the Linux binary gives back the recorded outputs
        np.testing.assert_array_equal(linux, recorded, err_msg=f"{name} ({run.model}, FMI {version}): Linux host vs "
                                                               "master")
        windows = run.run(hosts["win64"], "win64", wine)
        differing = int(np.count_nonzero(windows != linux))
        scaled = scaled_difference(windows, linux)
        worst = run.outputs[int(np.argmax(scaled))]
        print(f"{scenario_name} {controller} {run.model} FMI {version}: {linux.shape[0]} steps x {len(run.outputs)} "
              f"outputs, win64 under wine vs linux64: {differing} values differ, largest difference {scaled.max():.3g} of the output's "
              f"range ({worst}), per value up to {relative_difference(windows, linux):.3g} relative")
        assert np.all(scaled <= WINDOWS_TOLERANCE), (
            f"{run.model} (FMI {version}): win64 under wine differs from linux64 in {differing} values, up to {scaled.max():.3g} "
            f"of the range of {worst} (tolerance {WINDOWS_TOLERANCE:g}); outputs {run.outputs}")
        assert np.ptp(linux, axis=0).max() > 0.0  # the outputs moved


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", FAILING_RUNS)
def test_the_win64_dlls_under_wine_say_what_the_linux_binaries_say(native, hosts, wine, tmp_path, version, case):
    """The same words and numbers; Windows' C runtime writes a NaN as -nan(ind) where glibc writes -nan."""
    run = failing_run(case, native, version, tmp_path)
    linux = run.errors(hosts["linux64"], "linux64")
    windows = run.errors(hosts["win64"], "win64", wine)
    assert len(linux) == 1, linux
    assert [meaning(text) for text in windows] == [meaning(text) for text in linux], (windows, linux)
