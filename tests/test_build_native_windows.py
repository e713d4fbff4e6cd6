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
is absent.  It uses its own wine prefix, build/wine-prefix (695 MB, made once in about 7 s),
unless WINEPREFIX is set.
"""
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description

import build_native
import c_toolchain
from harness.scenario import scenario_names
from tests.message_meaning import meaning

ROOT = Path(__file__).resolve().parents[1]
HOST_SOURCE = ROOT / "tests" / "c_host" / "host.c"
HOST_DIR = c_toolchain.WORK_DIR / "hosts"
DEFAULT_PREFIX = ROOT / "build" / "wine-prefix"
# Largest |win64 - linux64| of an output, relative to that output's largest |value| in the run.
# Measured: at most 1.8e-14 (the pendulum case's u) from the one-ulp libm differences; a defect
# (a wrong formula, parameter or input) is many orders above.  Per value the relative difference
# is larger where a signal crosses zero (1.5e-11 on the manipulator's dy, 2e-18 absolute): printed,
# not asserted.
WINDOWS_TOLERANCE = 1e-12
# (scenario, controller, stop): short horizons, 2000-5000 steps each; every plant, every controller
# variant, the pendulum with and without its disturbance d(t)
CASES = (("pendulum_case1", "vud", 1.0), ("pendulum_case2", "fae", 1.0), ("manipulator", "vud", 0.25),
         ("motor_arm", "fixed", 0.25))


def wine_program() -> str | None:
    """wine64 (Debian's wine64 package puts it in /usr/lib/wine), else wine."""
    for candidate in ("wine64", "/usr/lib/wine/wine64", "wine"):
        found = shutil.which(candidate)
        if found:
            return found
    return None


pytestmark = [
    pytest.mark.skipif(not build_native.compiler_available(),
                       reason="zig's C compiler is not installed (pip install -e '.[native]')"),
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


# the binary of an FMU for (FMI version, platform), relative to the extracted FMU, as each host names it
LIBRARIES = {(2, "linux64"): "binaries/linux64/{}.so", (2, "win64"): "binaries\\win64\\{}.dll",
             (3, "linux64"): "binaries/x86_64-linux/{}.so", (3, "win64"): "binaries\\x86_64-windows\\{}.dll"}


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

    def run(self, host: Path, platform: str, wine=None) -> np.ndarray:
        if platform == "win64":
            program, environment = wine
            command = [program, str(host), *self.arguments(platform)]
        else:
            environment = dict(os.environ)
            command = [str(host), *self.arguments(platform)]
        returncode, output, errors = run_with_files(command, self.stdin(), environment, self.folder, platform)
        assert returncode == 0, f"{self.model} (FMI {self.version}, {platform}) exited {returncode}:\n{errors}"
        values = np.array([[float(x) for x in line.split()] for line in output.splitlines()])
        assert values.shape == (len(next(iter(self.inputs.values()))), len(self.outputs)), (platform, values.shape)
        return values


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


# errors a host sees: (model, parameters, inputs per communication point); the controller's outputs
# overflow at the 6th point (NaN outputs), the pendulum's parameter mc is out of its range
FAILING_RUNS = {
    "outputs overflow": ("AdaptiveFuzzyController", {},
                         dict(e=[0.2] * 5 + [1e308] * 3, de=[-0.1] * 8, ym=[0.3] * 8, dym=[0.5] * 8)),
    "invalid parameter": ("InvertedPendulum", dict(mc=-1.0), dict(u=[0.0] * 3)),
}


def _host_errors(run: HostRun, host: Path, platform: str, wine=None) -> list[str]:
    """The FMU's error messages as a C host on the platform logs them (without the instance name)."""
    program, environment = wine if platform == "win64" else (None, dict(os.environ))
    command = [*([program] if program else []), str(host), *run.arguments(platform)]
    returncode, _, errors = run_with_files(command, run.stdin(), environment, run.folder, platform)
    assert returncode == 3, f"{run.model} ({platform}) exited {returncode}, not with the FMU's error:\n{errors}"
    return [line.split(": ", 2)[2] for line in errors.splitlines() if line.startswith("[ERROR] c_host: ")]


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("case", FAILING_RUNS)
def test_the_win64_dlls_under_wine_say_what_the_linux_binaries_say(native, hosts, wine, tmp_path, version, case):
    """The same words and numbers; Windows' C runtime writes a NaN as -nan(ind) where glibc writes -nan."""
    model, parameters, inputs = FAILING_RUNS[case]
    run = HostRun(native[model][version], version, tmp_path / model, 1e-3, parameters,
                  {name: np.array(values) for name, values in inputs.items()},
                  [next(v.name for v in read_model_description(str(native[model][version])).modelVariables
                        if v.causality == "output")])
    linux = _host_errors(run, hosts["linux64"], "linux64")
    windows = _host_errors(run, hosts["win64"], "win64", wine)
    assert len(linux) == 1, linux
    assert [meaning(text) for text in windows] == [meaning(text) for text in linux], (windows, linux)
