"""The native edition's aarch64-linux binaries, executed under qemu-user: they compute what the linux64
(x86-64) binaries compute.

Each FMU of a closed loop (controller, plant, tracking reference) is driven alone by the C host of
tests/c_host/host.c, built with zig for x86-64 Linux (it loads binaries/linux64 or x86_64-linux) and
for aarch64 Linux (it loads binaries/aarch64-linux, run by qemu-aarch64 with Debian's arm64 glibc as
its sysroot).  Both are fed the inputs our master handed that FMU in a Linux run and print every
output with %.17g.  Per output the test says whether the two platforms agree to the last bit or by
how much they differ.  Both binaries perform the same IEEE operations in the same order (no fused
multiply-add: -ffp-contract=off) and call glibc's sin, cos and exp, so with the same glibc release
on both sides every output must be identical to the last bit; with different releases (each
architecture has its own libm code) within ``ARM_TOLERANCE`` of the output's range.

qemu-user and the sysroot are Debian's (``apt-get install qemu-user libc6-arm64-cross``); the test
skips when either is absent.  ``QEMU_LD_PREFIX`` names another sysroot.
"""
import os
import re
import time
from pathlib import Path

import numpy as np
import pytest

from harness.fmu_build import native as build_native
from harness.scenario import scenario_names
from tests.message_meaning import meaning
from tests.native_hosts import (CASES, FAILING_RUNS, failing_run, first_program, linux_host, recorded_runs,
                                scaled_difference)

SYSROOT = Path(os.environ.get("QEMU_LD_PREFIX", "/usr/aarch64-linux-gnu"))
# Largest |aarch64 - x86_64| of an output, relative to that output's largest |value| in the run;
# a defect (a wrong formula, parameter or input) is many orders above.
ARM_TOLERANCE = 1e-12


def glibc_release(libc: Path) -> str:
    """The release a glibc's libc.so.6 names itself with ("2.36"), or "" when it does not say."""
    found = re.search(rb"release version (\d+\.\d+)", libc.read_bytes()) if libc.exists() else None
    return found.group(1).decode() if found else ""


def same_glibc() -> bool:
    """True when this machine's glibc and the aarch64 sysroot's are the same release."""
    here = os.confstr("CS_GNU_LIBC_VERSION") or ""
    return here.startswith("glibc ") and here.split()[1] == glibc_release(SYSROOT / "lib" / "libc.so.6")


def qemu_program() -> str | None:
    """qemu-user's aarch64 emulator (Debian: qemu-user, or qemu-user-static)."""
    return first_program("qemu-aarch64", "qemu-aarch64-static")


pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(),
                       reason="zig's C compiler is not installed (pip install -e .)"),
    pytest.mark.skipif(qemu_program() is None or not (SYSROOT / "lib" / "ld-linux-aarch64.so.1").exists(),
                       reason=f"qemu-user or the arm64 glibc in {SYSROOT} is not installed "
                              "(apt-get install qemu-user libc6-arm64-cross)"),
]


@pytest.fixture(scope="module")
def native():
    platforms = os.environ.get("AFC_NATIVE_PLATFORMS", "")
    chosen = tuple(p for p in platforms.split(",") if p) or build_native.PLATFORMS
    if not {"linux64", "aarch64-linux"} <= set(chosen):
        pytest.skip(f"AFC_NATIVE_PLATFORMS={platforms} does not build both linux64 and aarch64-linux")
    return build_native.ensure_built()


@pytest.fixture(scope="module")
def hosts():
    """{platform: host binary} for linux64 and aarch64-linux."""
    return {"linux64": linux_host("x86_64"), "aarch64-linux": linux_host("aarch64")}


@pytest.fixture(scope="module")
def qemu():
    """(qemu-aarch64 -L SYSROOT, environment): the launcher of the aarch64 host."""
    return [qemu_program(), "-L", str(SYSROOT)], dict(os.environ)


def agreement(arm: np.ndarray, x86: np.ndarray, outputs: list) -> dict:
    """Per output: "identical" (every value to the last bit) or its largest difference, relative to its range."""
    scaled = scaled_difference(arm, x86)
    return {name: "identical" if np.array_equal(arm[:, k], x86[:, k]) else f"{scaled[k]:.2g} of its range"
            for k, name in enumerate(outputs)}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("scenario_name,controller,stop", CASES)
def test_the_aarch64_binaries_under_qemu_compute_what_the_linux64_binaries_compute(native, hosts, qemu, tmp_path,
                                                                                   version, scenario_name, controller,
                                                                                   stop):
    if scenario_name not in scenario_names():
        pytest.skip(f"no scenario {scenario_name} here")
    runs = recorded_runs(scenario_name, controller, stop, native, version, tmp_path)
    assert {run.model for run, _ in runs.values()} >= {"AdaptiveFuzzyController", "TrackingReference"}
    for name, (run, recorded) in runs.items():
        x86 = run.run(hosts["linux64"], "linux64")
        np.testing.assert_array_equal(x86, recorded, err_msg=f"{name} ({run.model}, FMI {version}): x86-64 host vs "
                                                             "master")
        started = time.perf_counter()
        arm = run.run(hosts["aarch64-linux"], "aarch64-linux", qemu)
        seconds = time.perf_counter() - started
        per_output = agreement(arm, x86, run.outputs)
        print(f"{scenario_name} {controller} {run.model} FMI {version}: {x86.shape[0]} steps under qemu in "
              f"{seconds:.2f} s; aarch64 vs x86_64: " + ", ".join(f"{k} {v}" for k, v in per_output.items()))
        if same_glibc():
            assert set(per_output.values()) == {"identical"}, (
                f"{run.model} (FMI {version}): with the same glibc release on both sides, aarch64 under qemu must "
                f"give x86_64's values to the last bit: {per_output}")
        scaled = scaled_difference(arm, x86)
        assert np.all(scaled <= ARM_TOLERANCE), (
            f"{run.model} (FMI {version}): aarch64 under qemu differs from x86_64 by up to {scaled.max():.3g} of an "
            f"output's range (tolerance {ARM_TOLERANCE:g}): {per_output}")
        assert np.ptp(x86, axis=0).max() > 0.0  # the outputs moved


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", FAILING_RUNS)
def test_the_aarch64_binaries_under_qemu_say_what_the_linux64_binaries_say(native, hosts, qemu, tmp_path, version,
                                                                           case):
    """The same words and numbers; a NaN the C code computed reads -nan on x86-64 (its default NaN has the
    sign bit set) and nan on aarch64 (its default NaN has not)."""
    run = failing_run(case, native, version, tmp_path)
    x86 = run.errors(hosts["linux64"], "linux64")
    arm = run.errors(hosts["aarch64-linux"], "aarch64-linux", qemu)
    assert len(x86) == 1, x86
    assert [meaning(text) for text in arm] == [meaning(text) for text in x86], (arm, x86)
