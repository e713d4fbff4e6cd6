"""The C host of tests/c_host/host.c, built by zig for each platform whose native binaries the tests
execute, and the replay of a recorded closed-loop run through it, one FMU at a time.

A platform's host is run directly (linux64) or through a launcher: wine for win64, qemu-user for
aarch64-linux.  Each host is fed the inputs our master handed an FMU in a Linux run of the native
edition and prints every output it recorded with %.17g, so two platforms' outputs compare value for
value (tests/test_build_native_windows.py, tests/test_aarch64_linux.py).
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
from fmpy import read_model_description

from harness.fmu_build import toolchain as c_toolchain

ROOT = Path(__file__).resolve().parents[1]
HOST_SOURCE = ROOT / "tests" / "c_host" / "host.c"
HOST_DIR = c_toolchain.WORK_DIR / "hosts"
# (scenario, controller, stop): short horizons, 2000-5000 steps each; every plant, every controller
# variant, the pendulum with and without its disturbance d(t)
CASES = (("pendulum_case1", "vud", 1.0), ("pendulum_case2", "fae", 1.0), ("manipulator", "vud", 0.25),
         ("motor_arm", "fixed", 0.25))
# the binary of an FMU for (FMI version, platform), relative to the extracted FMU, as each host names it
LIBRARIES = {(2, "linux64"): "binaries/linux64/{}.so", (2, "win64"): "binaries\\win64\\{}.dll",
             (2, "aarch64-linux"): "binaries/aarch64-linux/{}.so",
             (3, "linux64"): "binaries/x86_64-linux/{}.so", (3, "win64"): "binaries\\x86_64-windows\\{}.dll",
             (3, "aarch64-linux"): "binaries/aarch64-linux/{}.so"}
# errors a host sees: (model, parameters, inputs per communication point); the controller's outputs
# overflow at the 6th point (NaN outputs), the pendulum's parameter mc is out of its range
FAILING_RUNS = {
    "outputs overflow": ("AdaptiveFuzzyController", {},
                         dict(e=[0.2] * 5 + [1e308] * 3, de=[-0.1] * 8, ym=[0.3] * 8, dym=[0.5] * 8)),
    "invalid parameter": ("InvertedPendulum", dict(mc=-1.0), dict(u=[0.0] * 3)),
}


def first_program(*candidates: str) -> str | None:
    """The first of ``candidates`` found on PATH (or as a path), else None."""
    return next((found for found in map(shutil.which, candidates) if found), None)


def zig_build(target: str, output: Path, *extra: str) -> Path:
    """Compile the C host for a zig target; cached by the source, the target and zig's version."""
    arguments = ["cc", "-target", target, "-std=c11", "-O2", "-Wall", "-Wextra", "-Werror", *extra]
    digest = hashlib.sha256("\0".join([c_toolchain.zig_version(), *arguments]).encode() + HOST_SOURCE.read_bytes())
    binary = HOST_DIR / f"{output.stem}-{digest.hexdigest()[:16]}{output.suffix}"
    if not binary.exists():
        HOST_DIR.mkdir(parents=True, exist_ok=True)
        environment = dict(os.environ)
        environment.setdefault("ZIG_GLOBAL_CACHE_DIR", str(c_toolchain.WORK_DIR / "zig-cache"))
        environment.setdefault("ZIG_LOCAL_CACHE_DIR", str(c_toolchain.WORK_DIR / "zig-cache"))
        with tempfile.TemporaryDirectory(dir=HOST_DIR) as scratch:  # zig writes a .pdb beside a .exe
            built = Path(scratch) / output.name
            completed = subprocess.run([sys.executable, "-m", "ziglang", *arguments, "-o", str(built), str(HOST_SOURCE)],
                                       capture_output=True, text=True, env=environment, cwd=scratch)
            assert completed.returncode == 0, f"compiling {HOST_SOURCE.name} for {target} failed:\n{completed.stderr}"
            os.replace(built, binary)
    return binary


def linux_host(architecture: str) -> Path:
    """The host for glibc Linux on ``architecture`` (x86_64, aarch64): it loads the .so with dlopen."""
    return zig_build(f"{architecture}-linux-gnu", Path(f"host-{architecture}-linux"), "-D_POSIX_C_SOURCE=200809L",
                     "-ldl")


def run_with_files(command: list, stdin: str, environment: dict, folder: Path, name: str) -> tuple:
    """(exit status, stdout, stderr) of a command whose standard streams are files in ``folder``.

    Not pipes: the first wine process of a session starts wine's services (winedevice.exe ...),
    which inherit its standard streams and live on for seconds after it, so a pipe's end of
    file would come only when they quit (~2.5 s a run)."""
    paths = [folder / f"{name}.{stream}" for stream in ("stdin", "stdout", "stderr")]
    paths[0].write_text(stdin)
    with paths[0].open("rb") as given, paths[1].open("wb") as output, paths[2].open("wb") as errors:
        completed = subprocess.run(command, stdin=given, stdout=output, stderr=errors, env=environment,
                                   cwd=folder, timeout=300)
    return completed.returncode, paths[1].read_text(), paths[2].read_text(errors="replace")


def launched(host: Path, arguments: list, launcher=None) -> tuple[list, dict]:
    """(command, environment) running ``host`` directly, or through ``launcher``: (program, environment),
    the program a path or a command line prefix (wine; qemu-aarch64 -L SYSROOT)."""
    if launcher is None:
        return [str(host), *arguments], dict(os.environ)
    program, environment = launcher
    prefix = [program] if isinstance(program, (str, Path)) else list(program)
    return [*map(str, prefix), str(host), *arguments], environment


class HostRun:
    """One FMU of a recorded closed-loop run, to be replayed by the C host (FMI 2.0 or 3.0)."""

    def __init__(self, fmu: Path, version: int, folder: Path, step: float, parameters: dict, inputs: dict,
                 outputs: list):
        self.fmu, self.version, self.folder, self.step = fmu, version, folder, step
        md = read_model_description(str(fmu))
        self.model = md.coSimulation.modelIdentifier
        self.guid = md.guid
        self.variables = {v.name: v for v in md.modelVariables}
        self.parameters, self.inputs, self.outputs = parameters, inputs, outputs
        folder.mkdir(parents=True, exist_ok=True)
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(folder)

    def arguments(self, platform: str) -> list[str]:
        names = list(self.inputs)
        parameters = [f"i:{self.variables[n].valueReference}={int(value)}"
                      if self.variables[n].type in ("Integer", "Int32")
                      else f"r:{self.variables[n].valueReference}={float(value)!r}"
                      for n, value in self.parameters.items()]
        resources = self.folder / "resources"  # FMI 2.0: a URI; FMI 3.0: a path (on Windows, wine's Z: drive)
        location = (resources.as_uri() if self.version == 2 else
                    "Z:" + str(resources).replace("/", "\\") if platform == "win64" else str(resources))
        return [LIBRARIES[self.version, platform].format(self.model), location, self.guid, repr(self.step),
                ",".join(str(self.variables[n].valueReference) for n in names),
                ",".join(str(self.variables[n].valueReference) for n in self.outputs), *parameters]

    def stdin(self) -> str:
        columns = np.column_stack(list(self.inputs.values()))
        return "".join(" ".join(repr(float(x)) for x in row) + "\n" for row in columns)

    def run(self, host: Path, platform: str, launcher=None) -> np.ndarray:
        command, environment = launched(host, self.arguments(platform), launcher)
        returncode, output, errors = run_with_files(command, self.stdin(), environment, self.folder, platform)
        assert returncode == 0, f"{self.model} (FMI {self.version}, {platform}) exited {returncode}:\n{errors}"
        values = np.array([[float(x) for x in line.split()] for line in output.splitlines()])
        assert values.shape == (len(next(iter(self.inputs.values()))), len(self.outputs)), (platform, values.shape)
        return values

    def errors(self, host: Path, platform: str, launcher=None) -> list[str]:
        """The FMU's error messages as the host on ``platform`` logs them (without the instance name);
        the run must end in the FMU's error (the host's exit status 3)."""
        command, environment = launched(host, self.arguments(platform), launcher)
        returncode, _, errors = run_with_files(command, self.stdin(), environment, self.folder, platform)
        assert returncode == 3, f"{self.model} ({platform}) exited {returncode}, not with the FMU's error:\n{errors}"
        return [line.split(": ", 2)[2] for line in errors.splitlines() if line.startswith("[ERROR] c_host: ")]


def failing_run(case: str, fmus: dict, version: int, folder: Path) -> HostRun:
    """The HostRun of FAILING_RUNS[case] with the FMI ``version`` FMU of ``fmus`` ({model: {version: path}})."""
    model, parameters, inputs = FAILING_RUNS[case]
    path = fmus[model][version]
    output = next(v.name for v in read_model_description(str(path)).modelVariables if v.causality == "output")
    return HostRun(path, version, folder / model, 1e-3, parameters,
                   {name: np.array(values) for name, values in inputs.items()}, [output])


def recorded_runs(scenario_name: str, controller: str, stop: float, native: dict, version: int, folder: Path) -> dict:
    """A Linux run of the native FMI 2.0 edition by our master; each FMU's inputs and outputs in it,
    to replay with that FMU's FMI ``version`` binaries (the FMI 3.0 ones compute the same)."""
    from harness import scenario as scenarios
    from harness.master import simulate

    configured = scenarios.configure(scenario_name, controller, None, stop)
    sources = [c.source for c in configured.connections]
    configured.record = list(dict.fromkeys([*configured.record, *sources]))  # every connected value too
    result = simulate(configured, fmu_paths={name: paths[2] for name, paths in native.items()})
    assert result.complete
    runs = {}
    for name, spec in configured.components.items():
        inputs = {c.target_variable: result.signal(c.source) for c in configured.connections
                  if c.target_instance == name}
        outputs = [column.split(".", 1)[1] for column in result.columns if column.split(".", 1)[0] == name]
        runs[name] = (HostRun(native[spec.fmu][version], version, folder / name, configured.step, spec.parameters,
                              inputs, outputs),
                      np.column_stack([result.signal(f"{name}.{v}") for v in outputs]))
    return runs


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """The largest |a - b| / max(|a|, |b|) over all values."""
    scale = np.maximum(np.abs(a), np.abs(b))
    with np.errstate(invalid="ignore", divide="ignore"):
        return float(np.max(np.where(a == b, 0.0, np.abs(a - b) / scale)))


def scaled_difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per column: the largest |a - b| relative to the column's largest |value|."""
    scale = np.max(np.maximum(np.abs(a), np.abs(b)), axis=0)
    return np.max(np.abs(a - b), axis=0) / np.where(scale > 0.0, scale, 1.0)
