"""The host matrix: ``python -m harness hosts`` runs the closed loops in every FMI host this machine has.

Each row is one scenario x controller x host x step, scored the same way for
every host (ITAE, IAE from the true error ym - y of the plant's and the
reference's outputs, Ec from the u the plant was given) and compared with our
converged result (harness/studies/step_study.py) over the same horizon.  Hosts
(one row each in ``HOSTS``, the host registry, with the function that runs it):

* ``ours-feedthrough`` / ``ours-jacobi``: our master (harness/master.py), with
  consistent initial values.
* ``fmpy-jacobi`` and ``fmpy-gs-<order>``: a plain fmpy script as a user writes
  one (``FMU2Slave``; instantiate, set parameters in initialisation mode, exit
  initialisation, loop): Jacobi, or Gauss-Seidel in each of the six orders;
  no initial-value propagation (connected inputs keep their start values until
  the first step).
* ``fmpy-ssp``: fmpy's SSP simulator on the exported SSP (harness/hosts/engines.py).
* ``ecos``: Ecos (ecospy) on the exported SSP.
* ``libcosim-ssp``: libcosim (libcosimpy) on the exported SSP, whose OSP
  annotation asks for 0 worker threads; ``libcosim-api``: the FMUs wired
  through libcosimpy's API (default worker threads).
* ``fmutool-parallel`` / ``fmutool-seq-forward`` / ``fmutool-seq-reverse``:
  fmu-manipulation-toolbox containers run by fmpy: parallel (Jacobi),
  sequential in the order plant, reference, controller and in the reverse.
* ``ours-me``: our Model Exchange master (harness/me_master.py: CVODE over every FMU's states,
  no communication step; the native edition).
* ``omsimulator-wc`` / ``omsimulator-wc-capi`` / ``omsimulator-sc``: OpenModelica's OMSimulator
  (harness/hosts/omsimulator.py) on the exported SSP: its co-simulation master through its Python
  API (step set by hand) and through its C API (step from the SSP's annotation), and its strongly
  coupled mode on an ``--algorithm me`` package (its CVODE over the Model Exchange FMUs).

Warnings are the FMU log messages with status Warning: from the logger
callback where the host takes one (our master, the plain fmpy script, the
container run by fmpy, which forwards its embedded FMUs' messages), else from
what the host prints (libcosim logs them as ``[FMI status=warning, ...]`` at
log level warning): the run captures the process's stdout and stderr and
keeps the lines that say warning.  fmpy.ssp and Ecos pass none of them on
(``NOT_CAPTURED``): pythonfmu drops every message of an FMU instantiated
with logging off.

Nothing the repository tracks is written unless asked: the matrix goes to
``results/hosts/`` (``--out``); ``--apply`` also writes docs/hosts.md.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import importlib.util
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time as clock
import zipfile
from dataclasses import dataclass
from itertools import permutations
from pathlib import Path
from typing import Callable

import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

import build_fmu
import build_native

from .. import cli_args, variants
from .. import scenario as scenarios
from ..cases import Case, parallel_map, run_case
from ..fmi import ModelInfo
from ..master import Master, resolve_fmu
from ..me_master import DEFAULT_RTOL, ModelExchangeMaster
from ..scores import control_energy, iae, itae, total_variation_rate
from ..studies.step_study import CONTROLLERS, load_convergence, richardson, validated_step
from . import engines, omsimulator
from .ssp import export_ssp

ROOT = Path(__file__).resolve().parents[2]
HOSTS_MD = ROOT / "docs" / "hosts.md"
DEFAULT_OUT = Path("results") / "hosts"  # under the working directory, like tables and regress
METRICS = ("ITAE", "IAE", "Ec")
ACCURACY = 0.01
COMPONENT_ORDER = ("plant", "reference", "controller")  # the causal order of the loop


@dataclass(frozen=True)
class Host:
    """One row of the host registry (``HOSTS``, below the functions that run the hosts)."""

    key: str
    name: str
    settings: str
    family: str  # "feedthrough": our master's validated step applies; "jacobi": the Jacobi one
    run: Callable  # (scenario, fmu_paths, package) -> (Trajectory, warnings, where the warnings come from)
    package: str | None = None  # the PyPI distribution it needs beyond the project's dependencies
    module: str | None = None  # that distribution's import name (checked before the host runs)
    needs_ssp: bool = False  # runs the scenario exported as an SSP package (handed to ``run`` as ``package``)
    ssp_rtol: float | None = None  # the package is an --algorithm me one with this CVODE tolerance
    unavailable: Callable | None = None  # () -> why the host cannot run here, or None (instead of ``module``)
    edition: str | None = None  # "native": the native FMUs (FMI 2.0) whatever edition the matrix runs
    max_steps: int | None = None  # the longest run it is given, in communication steps (its memory grows per step)

    @property
    def model_exchange(self) -> bool:
        return self.family == "me"

    def horizon(self, stop: float, step: float) -> float:
        """The stop time of its run: ``stop``, or the last whole step within ``max_steps``."""
        if self.max_steps is None or stop <= self.max_steps * step:
            return stop
        return round(self.max_steps * step, 12)


#: hosts that do not hand the FMU's log messages to us, and what we found
NOT_CAPTURED = {
    "fmpy-ssp": "not captured: simulate_ssp instantiates the FMUs with logging off and takes no option for it, "
                "and pythonfmu then drops every message (docs/host_robustness.md)",
    "ecos": "not captured: Ecos (ecospy 0.7) prints none of the FMU's log messages, even at log level trace (an "
            "invalid parameter's Error message did not appear, and the run went on); like fmpy.ssp it gives no "
            "handle on the FMUs' logging flag"}


def host_available(host: Host) -> str | None:
    """None if the host can run here, else the reason."""
    if host.module and importlib.util.find_spec(host.module) is None:
        return f"{host.package} is not installed (pip install -e '.[hosts]')"
    if host.unavailable is not None and host.unavailable():
        return host.unavailable()
    if host.edition == "native" and not build_native.compiler_available():
        return "it runs the native edition's FMUs, and zig's C compiler is not installed (pip install -e '.[native]')"
    return None


# ---------------------------------------------------------------- a run
@dataclass
class Trajectory:
    """What every host yields: the plant's and reference's outputs and the u applied, on one grid."""

    time: np.ndarray
    y: np.ndarray
    dy: np.ndarray
    ym: np.ndarray
    dym: np.ndarray
    u: np.ndarray  # applied over [t_k, t_k + h]

    def scores(self) -> dict:
        e, de = self.ym - self.y, self.dym - self.dy
        return {"ITAE": itae(self.time, e, de), "IAE": iae(self.time, e, de), "Ec": control_energy(self.time, self.u),
                "tv_u": total_variation_rate(self.time, self.u)}


@contextlib.contextmanager
def captured_console():
    """Capture the process's stdout and stderr (file descriptors 1, 2: C hosts print there too)."""
    lines: list = []
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 1)
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            libc.fflush(None)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            lines.extend(sink.read().decode("utf-8", "replace").splitlines())


def console_warnings(lines: list) -> list:
    return [line.strip() for line in lines if re.search(r"warn", line, re.IGNORECASE)]


def _infos(scenario, fmu_paths):
    paths = {name: resolve_fmu(spec.fmu, scenario, fmu_paths) for name, spec in scenario.components.items()}
    return paths, {name: ModelInfo.read(path) for name, path in paths.items()}


def _applied_input(scenario) -> str:
    """The input the control goes to (``plant.u``)."""
    source = scenario.signals["u"]
    return next(c.target for c in scenario.connections if c.source == source)


def run_ours(scenario, fmu_paths, package=None, algorithm: str = "feedthrough") -> tuple:
    master = Master(scenario, algorithm, fmu_paths)
    result = master.run()
    warnings = [f"{name}: {line}" for name, log in master.logs.items() for line in log if line.startswith("[WARNING]")]
    s = result.signal
    return Trajectory(result.time, s("plant.y"), s("plant.dy"), s("reference.ym"), s("reference.dym"),
                      s(scenario.signals["u"])), warnings, "FMI logger callback"


def run_ours_me(scenario, fmu_paths, package=None) -> tuple:
    master = ModelExchangeMaster(scenario, fmu_paths)
    result = master.run()
    warnings = [f"{name}: {line}" for name, log in master.logs.items() for line in log if line.startswith("[WARNING]")]
    s = result.signal
    return Trajectory(result.time, s("plant.y"), s("plant.dy"), s("reference.ym"), s("reference.dym"),
                      s(scenario.signals["u"])), warnings, "FMI logger callback"


def run_omsimulator(scenario, fmu_paths, package: Path, api: str = "python") -> tuple:
    """OMSimulator on the exported package: "python" (its co-simulation master, the step set by hand), "capi"
    (the step from the package's annotation) or "sc" (strongly coupled, its CVODE on the Model Exchange FMUs)."""
    names = ["plant.y", "plant.dy", "reference.ym", "reference.dym", scenario.signals["u"]]
    with captured_console() as lines:
        if api == "capi":
            time, columns = omsimulator.run_c_api(package, scenario.stop, names)
        elif api == "sc":
            time, columns = omsimulator.run_python_api(package, scenario.stop, names, output_step=scenario.step)
        else:
            time, columns = omsimulator.run_python_api(package, scenario.stop, names, fixed_step=scenario.step)
    # its own complaint that it lacks the SSP schema files of its install is not an FMU's warning
    warnings = [w for w in console_warnings(lines) if "could not load the ssd schema file" not in w]
    return Trajectory(time, *(columns[n] for n in names)), warnings, "console (OMSimulator prints the FMUs' messages)"


def run_plain_fmpy(scenario, fmu_paths, package=None, order: tuple | None = None) -> tuple:
    """A plain fmpy script: no initial-value propagation; Jacobi (order None) or Gauss-Seidel in ``order``."""
    paths, _ = _infos(scenario, fmu_paths)
    messages, slaves, folders, keep_alive = [], {}, [], []
    outputs, vrs = {}, {}
    for name, spec in scenario.components.items():
        md = read_model_description(str(paths[name]))
        folder = extract(str(paths[name]))
        folders.append(folder)
        slave = FMU2Slave(guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier,
                          instanceName=name)
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(
            lambda env, instance, status, category, message, name=name:
            messages.append((name, status, message.decode("utf-8", "replace"))))
        callbacks.allocateMemory = defaultCallbacks.allocateMemory
        callbacks.freeMemory = defaultCallbacks.freeMemory
        keep_alive.append(callbacks)
        slave.instantiate(callbacks=callbacks, loggingOn=True)
        variables = {v.name: v for v in md.modelVariables}
        vrs[name] = {n: v.valueReference for n, v in variables.items()}
        outputs[name] = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        slave.setupExperiment(startTime=scenario.start)
        slave.enterInitializationMode()
        for parameter, value in spec.parameters.items():
            if variables[parameter].type == "Integer":
                slave.setInteger([vrs[name][parameter]], [int(value)])
            else:
                slave.setReal([vrs[name][parameter]], [float(value)])
        slave.exitInitializationMode()
        slaves[name] = slave
    incoming = {name: [c for c in scenario.connections if c.target_instance == name] for name in slaves}
    applied = _applied_input(scenario)
    steps, h = scenario.steps, scenario.step
    rows = np.empty((steps + 1, 5))
    latest = {}

    def read(name):
        for variable, value in zip(outputs[name], slaves[name].getReal([vrs[name][o] for o in outputs[name]])):
            latest[f"{name}.{variable}"] = value

    def write(name):
        if incoming[name]:
            slaves[name].setReal([vrs[name][c.target_variable] for c in incoming[name]],
                                 [latest[c.source] for c in incoming[name]])

    def record(n):
        rows[n, :4] = latest["plant.y"], latest["plant.dy"], latest["reference.ym"], latest["reference.dym"]

    try:
        for name in slaves:
            read(name)
        for n in range(steps):
            t = scenario.start + n * h
            record(n)
            rows[n, 4] = latest[scenario.signals["u"]]
            if order is None:  # Jacobi: every input from the outputs at t, then every doStep
                for name in slaves:
                    write(name)
                for name in slaves:
                    slaves[name].doStep(currentCommunicationPoint=t, communicationStepSize=h)
                for name in slaves:
                    read(name)
            else:  # Gauss-Seidel: each in turn takes the latest values, steps, publishes
                for name in order:
                    write(name)
                    if name == applied.split(".", 1)[0]:
                        rows[n, 4] = latest[next(c.source for c in incoming[name] if c.target == applied)]
                    slaves[name].doStep(currentCommunicationPoint=t, communicationStepSize=h)
                    read(name)
        record(steps)
        rows[steps, 4] = latest[scenario.signals["u"]]
    finally:
        for slave in slaves.values():
            slave.terminate()
            slave.freeInstance()
        for folder in folders:
            shutil.rmtree(folder, ignore_errors=True)
    time = scenario.start + np.arange(steps + 1) * h
    warnings = [f"{name}: [WARNING] {text}" for name, status, text in messages if status == 1]
    return Trajectory(time, *rows.T), warnings, "FMI logger callback"


def _from_engine(result, u_column: str) -> Trajectory:
    s = result.signal
    return Trajectory(result.time, s("plant.y"), s("plant.dy"), s("reference.ym"), s("reference.dym"), s(u_column))


def run_fmpy_ssp(scenario, fmu_paths, package: Path) -> tuple:
    with captured_console() as lines:
        result = engines.run_fmpy_ssp(package, stop=scenario.stop, step=scenario.step)
    return _from_engine(result, "controller.u"), console_warnings(lines), NOT_CAPTURED["fmpy-ssp"]


def run_ecos(scenario, fmu_paths, package: Path) -> tuple:
    with engines.ecos_temp_dir(), captured_console() as lines:  # Ecos leaves its ecos_* folders in TMPDIR: its own
        result = engines.run_ecos(package, stop=scenario.stop, step=scenario.step, log_level="warn")
    return _from_engine(result, "plant.u"), console_warnings(lines), NOT_CAPTURED["ecos"]


def _libcosim_trajectory(execution, indices: dict, infos: dict, scenario) -> Trajectory:
    # libcosimpy here and below, not at module level: optional (the hosts and test extras)
    from libcosimpy.CosimObserver import CosimObserver

    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    wanted = {"plant": ["y", "dy", "u"], "reference": ["ym", "dym"]}
    references = {name: [infos[name].variables[v].valueReference for v in names] for name, names in wanted.items()}
    steps = scenario.steps
    rows = np.empty((steps, 5))
    for n in range(steps):
        execution.step()
        plant = observer.last_real_values(indices["plant"], references["plant"])
        reference = observer.last_real_values(indices["reference"], references["reference"])
        rows[n] = plant[0], plant[1], reference[0], reference[1], plant[2]
    time = scenario.start + (np.arange(steps) + 1) * scenario.step  # after step n: values at t_{n+1}
    return Trajectory(time[:-1], *rows[:-1].T)  # the last u would be applied after the stop time


def _libcosim_logging():
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel.WARNING)


def run_libcosim_ssp(scenario, fmu_paths, package: Path) -> tuple:
    from libcosimpy.CosimExecution import CosimExecution

    _, infos = _infos(scenario, fmu_paths)
    with captured_console() as lines:
        _libcosim_logging()
        folder = Path(tempfile.mkdtemp(prefix="afc_libcosim_"))
        try:
            with zipfile.ZipFile(package) as archive:
                archive.extractall(folder)
            execution = CosimExecution.from_ssp_file(str(folder))
            indices = {name: execution.slave_index_from_instance_name(name) for name in scenario.components}
            trajectory = _libcosim_trajectory(execution, indices, infos, scenario)
            del execution
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    return trajectory, console_warnings(lines), "console (libcosim log level warning)"


def run_libcosim_api(scenario, fmu_paths, package=None) -> tuple:
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimSlave import CosimLocalSlave

    paths, infos = _infos(scenario, fmu_paths)
    with captured_console() as lines:
        _libcosim_logging()
        execution = CosimExecution.from_step_size(step_size=int(round(scenario.step * 1e9)))
        indices = {}
        for name, spec in scenario.components.items():
            indices[name] = execution.add_local_slave(CosimLocalSlave(fmu_path=str(paths[name]), instance_name=name))
            for parameter, value in spec.parameters.items():
                variable = infos[name].variables[parameter]
                if variable.type == "Integer":
                    execution.integer_initial_value(indices[name], variable.valueReference, int(value))
                else:
                    execution.real_initial_value(indices[name], variable.valueReference, float(value))
        for c in scenario.connections:
            ok = execution.connect_real_variables(
                indices[c.source_instance], infos[c.source_instance].variables[c.source_variable].valueReference,
                indices[c.target_instance], infos[c.target_instance].variables[c.target_variable].valueReference)
            if ok not in (True, 0):
                raise RuntimeError(f"libcosim refused the connection {c.source} -> {c.target}")
        trajectory = _libcosim_trajectory(execution, indices, infos, scenario)
        del execution
    return trajectory, console_warnings(lines), "console (libcosim log level warning)"


def container_description(scenario, fmu_files: dict, order: tuple, sequential: bool) -> dict:
    """The fmu-manipulation-toolbox JSON description of the closed loop (start values = parameters only)."""
    link = [[fmu_files[c.source_instance], c.source_variable, fmu_files[c.target_instance], c.target_variable]
            for c in scenario.connections]
    exposed = [("plant", "y"), ("plant", "dy"), ("reference", "ym"), ("reference", "dym"), ("controller", "u")]
    start = [[fmu_files[name], parameter, repr(float(value)) if not isinstance(value, int) else str(value)]
             for name, spec in scenario.components.items() for parameter, value in spec.parameters.items()]
    return {"name": "loop.fmu", "step_size": scenario.step, "mt": False, "sequential": sequential,
            "auto_link": False, "auto_input": False, "auto_output": False, "auto_parameter": False,
            "fmu": [fmu_files[name] for name in order], "link": link,
            "output": [[fmu_files[i], v, f"{i}_{v}"] for i, v in exposed], "start": start}


def run_container(scenario, fmu_paths, package=None, mode: str = "parallel") -> tuple:
    from fmu_manipulation_toolbox.assembly import Assembly  # optional (the hosts and test extras)

    paths, infos = _infos(scenario, fmu_paths)
    fmu_files = {name: f"{infos[name].model_identifier}.fmu" for name in scenario.components}
    order = tuple(reversed(COMPONENT_ORDER)) if mode == "seq-reverse" else COMPONENT_ORDER
    folder = Path(tempfile.mkdtemp(prefix="afc_container_"))
    messages = []
    try:
        for name in scenario.components:
            shutil.copy(paths[name], folder / fmu_files[name])
        description = folder / "loop.json"
        description.write_text(json.dumps(container_description(scenario, fmu_files, order, mode != "parallel")))
        with captured_console() as build_lines:
            Assembly("loop.json", fmu_directory=folder).make_fmu()
        container = folder / "loop.fmu"
        if not container.exists():
            raise RuntimeError("fmucontainer built no FMU: " + " | ".join(build_lines[-5:]))

        def logger(component, instance, status, category, message):
            messages.append((status, message.decode("utf-8", "replace")))

        names = ["plant_y", "plant_dy", "reference_ym", "reference_dym", "controller_u"]
        result = simulate_fmu(str(container), start_time=scenario.start, stop_time=scenario.stop,
                              step_size=scenario.step, output_interval=scenario.step, output=names, logger=logger,
                              debug_logging=True)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    time = np.asarray(result["time"], dtype=float)
    columns = [np.asarray(result[n], dtype=float) for n in names]
    # the container forwards the embedded FMUs' messages as "<FMU file>: ..."; its own banners (status Warning:
    # "FMUContainer 'V2.0'", "Container use PARALLEL mode ...") are not the FMU's and are left out
    warnings = [f"[WARNING] {text}" for status, text in messages if status == 1 and re.match(r"\S+\.fmu: ", text)]
    return Trajectory(time, *columns), warnings, \
        "FMI logger callback of the container, which forwards the embedded FMUs' messages (fmpy)"


#: OMSimulator keeps what it simulates in memory: 2.8 GB for the pendulum's 40 000 steps (measured, either
#: API), so 20 s of the manipulator's 50 us steps would need some 28 GB: its runs stop after this many steps
OMSIMULATOR_MAX_STEPS = 40_000

# ------------------------------------------------------- the host registry
#: one row per host: a new host is its run function above and its row here
HOSTS = [
    Host("ours-feedthrough", "our master", "feedthrough-aware; consistent initial values", "feedthrough",
         functools.partial(run_ours, algorithm="feedthrough")),
    Host("ours-jacobi", "our master", "--algorithm jacobi; consistent initial values", "jacobi",
         functools.partial(run_ours, algorithm="jacobi")),
    Host("fmpy-jacobi", "plain fmpy script (FMU2Slave)", "Jacobi; no initial-value propagation", "jacobi",
         run_plain_fmpy),
    *(Host(f"fmpy-gs-{'-'.join(order)}", "plain fmpy script (FMU2Slave)",
           f"Gauss-Seidel {' > '.join(order)}; no initial-value propagation", "jacobi",
           functools.partial(run_plain_fmpy, order=order)) for order in permutations(COMPONENT_ORDER)),
    Host("fmpy-ssp", "fmpy.ssp (simulate_ssp)", "exported SSP with start values of the inputs; Jacobi", "jacobi",
         run_fmpy_ssp, needs_ssp=True),
    Host("ecos", "Ecos (ecospy)", "exported SSP; Jacobi; propagates initial values", "jacobi", run_ecos,
         "ecospy", "ecospy", needs_ssp=True),
    Host("libcosim-ssp", "libcosim (libcosimpy)", "exported SSP, OSP annotation numWorkerThreads=0; Jacobi",
         "jacobi", run_libcosim_ssp, "libcosimpy", "libcosimpy", needs_ssp=True),
    Host("libcosim-api", "libcosim (libcosimpy)", "FMUs wired through its API, default worker threads; Jacobi",
         "jacobi", run_libcosim_api, "libcosimpy", "libcosimpy"),
    Host("fmutool-parallel", "fmu-manipulation-toolbox container", "parallel (Jacobi); run by fmpy", "jacobi",
         functools.partial(run_container, mode="parallel"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("fmutool-seq-forward", "fmu-manipulation-toolbox container",
         "sequential plant > reference > controller; run by fmpy", "jacobi",
         functools.partial(run_container, mode="seq-forward"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("fmutool-seq-reverse", "fmu-manipulation-toolbox container",
         "sequential controller > reference > plant; run by fmpy", "jacobi",
         functools.partial(run_container, mode="seq-reverse"), "fmu-manipulation-toolbox", "fmu_manipulation_toolbox"),
    Host("ours-me", "our master", f"--algorithm me: Model Exchange, CVODE rtol {DEFAULT_RTOL:g}; native edition", "me",
         run_ours_me, edition="native"),
    Host("omsimulator-wc", "OMSimulator 3 (Python API)", "exported SSP; its co-simulation master, step set by hand "
         "(setFixedStepSize: this API reads no step annotation)", "feedthrough",
         functools.partial(run_omsimulator, api="python"), needs_ssp=True, unavailable=omsimulator.unavailable,
         edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
    Host("omsimulator-wc-capi", "OMSimulator 3 (C API oms_importFile)", "exported SSP; its co-simulation master, "
         "step from the SSP's org.openmodelica annotation", "feedthrough",
         functools.partial(run_omsimulator, api="capi"), needs_ssp=True, unavailable=omsimulator.unavailable,
         edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
    Host("omsimulator-sc", "OMSimulator 3 (Python API)", "export-ssp --algorithm me --rtol 1e-8: strongly coupled, "
         "its CVODE over the Model Exchange FMUs; native edition", "me",
         functools.partial(run_omsimulator, api="sc"), needs_ssp=True, ssp_rtol=1e-8,
         unavailable=omsimulator.unavailable, edition="native", max_steps=OMSIMULATOR_MAX_STEPS),
]
HOSTS_BY_KEY = {h.key: h for h in HOSTS}


def host_row(task: tuple) -> dict:
    """One row of the matrix (in a worker process): run, score, compare with the converged values."""
    key, name, controller, step, stop, converged, fmu_paths, package, step_kind = task
    scenario = scenarios.configure(name, controller, step, stop)
    row = {"scenario": name, "controller": controller, "host": key, "step": step, "stop": scenario.stop,
           "step_kind": step_kind, "converged": converged}
    began = clock.perf_counter()
    try:
        trajectory, warnings, where = HOSTS_BY_KEY[key].run(scenario, fmu_paths, package)
        scores = trajectory.scores()
        finite = all(math.isfinite(v) for v in scores.values())
        row.update(status="ok" if finite else "diverged", **scores, warnings=warnings, warnings_from=where,
                   error={m: scores[m] / converged[m] - 1 for m in METRICS} if finite else None)
    except Exception as error:  # a host failing is a row with its reason
        first_line = str(error).splitlines()[0] if str(error) else ""
        row.update(status="failed", reason=f"{type(error).__name__}: {first_line}",
                   warnings=[], error=None)
    row["wall_s"] = clock.perf_counter() - began
    return row


# --------------------------------------------------------- the matrix
def converged_values(name: str, controller: str, stop: float | None, fmu_paths, convergence: dict) -> dict:
    """Our converged ITAE, IAE, Ec: the study's for the full horizon, else Richardson over ``stop``."""
    scenario = scenarios.load(name)
    entry = convergence.get("scenarios", {}).get(name, {}).get("controllers", {}).get(controller, {})
    if (stop is None or stop >= scenario.stop) and entry.get("converged") and not convergence.get("stop"):
        return {m: entry["converged"][m] for m in METRICS}
    fine = entry.get("levels", [scenario.step])[-1] if entry else scenario.step / 4
    coarse, finer = (run_case(Case(name, controller, step=h, stop=stop), fmu_paths) for h in (fine, fine / 2))
    if coarse["status"] != "ok" or finer["status"] != "ok":
        raise RuntimeError(f"{name}/{controller}: our reference runs failed: {coarse['reason'] or finer['reason']}")
    return richardson(finer, coarse)


def plan(names, controllers, host_keys, step_kinds, convergence) -> list:
    """(host, scenario, controller, step, step kind) of every row."""
    rows = []
    for name in names:
        scenario_step = scenarios.load(name).step
        for controller in controllers:
            for key in host_keys:
                host = HOSTS_BY_KEY[key]
                steps = {}
                if host.model_exchange:  # no communication step: the scenario's step is the output grid
                    rows.append((key, name, controller, scenario_step, "output grid"))
                    continue
                if "validated" in step_kinds:
                    validated = validated_step(convergence, name, controller, host.family)
                    if validated is None:
                        print(f"note: {name}/{controller}: no {host.family} validated step in the study; "
                              f"using the scenario's step", file=sys.stderr)
                        validated = scenario_step
                    steps[validated] = "validated"
                if "scenario" in step_kinds:
                    steps.setdefault(scenario_step, "scenario")
                for step, kind in steps.items():
                    rows.append((key, name, controller, step, kind))
    return rows


def hosts_matrix(names, controllers=(variants.PROPOSED,), host_keys=None, step_kinds=("validated", "scenario"),
                 stop=None, jobs: int | None = None, convergence: dict | None = None) -> dict:
    """The rows of the matrix; ``stop``: one horizon for every scenario, or {scenario: horizon} (None: 20 s)."""
    stops = stop if isinstance(stop, dict) else {name: stop for name in names}
    convergence = load_convergence() if convergence is None else convergence
    folder = Path(tempfile.mkdtemp(prefix="afc_hosts_"))  # SSP packages and a private copy of the FMUs
    fmu_paths = {name: Path(shutil.copy(path, folder / path.name)) for name, path in build_fmu.ensure_built().items()}
    host_keys = list(host_keys or HOSTS_BY_KEY)
    native_paths = None
    if any(HOSTS_BY_KEY[k].edition == "native" for k in host_keys) and build_native.compiler_available():
        (folder / "native").mkdir()
        native_paths = {name: Path(shutil.copy(path, folder / "native" / path.name))
                        for name, path in build_fmu.ensure_built(edition="native").items()}
    skipped = {}
    for key in list(host_keys):
        reason = host_available(HOSTS_BY_KEY[key])
        if reason:
            skipped[key] = reason
            host_keys.remove(key)
    began = clock.perf_counter()
    planned = plan(names, controllers, host_keys, step_kinds, convergence)
    try:
        references = {}
        tasks = []
        for key, name, controller, step, kind in planned:
            package = None
            host = HOSTS_BY_KEY[key]
            full = stops.get(name) or scenarios.load(name).stop
            stop = None if host.horizon(full, step) == full else host.horizon(full, step)
            stop = stops.get(name) if stop is None else stop
            if (name, controller, stop) not in references:
                references[(name, controller, stop)] = converged_values(name, controller, stop, fmu_paths, convergence)
            paths = native_paths if host.edition == "native" else fmu_paths
            if host.needs_ssp:
                interface = f"me{host.ssp_rtol:g}" if host.ssp_rtol else "cs"
                package = folder / f"{name}_{controller}_{step:g}_{stop}_{interface}_{host.edition or 'selected'}.ssp"
                if not package.exists():
                    export_ssp(scenarios.configure(name, controller, step, stop), package,
                               fmu_paths=paths, rtol=host.ssp_rtol)
            tasks.append((key, name, controller, step, stop, references[(name, controller, stop)], paths,
                          package, kind))
        tasks.sort(key=lambda t: t[3])  # the finest steps (longest runs) first
        rows = parallel_map(host_row, tasks, jobs, description="host matrix", progress=None)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    order = {key: i for i, key in enumerate(HOSTS_BY_KEY)}
    rows.sort(key=lambda r: (names.index(r["scenario"]), r["controller"], order[r["host"]], r["step"]))
    return {"rows": rows, "skipped": skipped, "wall_s": clock.perf_counter() - began, "stops": stops,
            "accuracy": ACCURACY}


def within(row: dict) -> bool:
    return row.get("status") == "ok" and all(abs(row["error"][m]) <= ACCURACY for m in METRICS)


def warning_kind(text: str) -> str:
    """A warning in a few words for the table (hosts.json keeps the whole text)."""
    chatter = re.search(r"u chatters with communication step (\S+) s", text)
    if chatter:
        return f"u chatters (step {chatter.group(1)} s)"
    if "initial error re-latched" in text:
        return "initial error re-latched"
    return text.replace("|", "/")[:100]


def _pct(value: float) -> str:
    return f"{100 * value:+.3g} %"


#: what a user of another FMI tool must know (docs/hosts.md; the README gives the same in three lines)
USER_NOTES = """## What a user of another FMI tool must know

- **Step**: a host that delays every connection one step (Jacobi: nearly every engine) needs much smaller
  steps than our feedthrough-aware master for the same 1 % (3-5x for `vud`, up to 50x for `fixed`:
  docs/convergence.md): the controller FMU's DefaultExperiment stepSize (64 us) is safe on the pendulum, the
  manipulator needs the step in the table below; `export-ssp` writes the right one into the SSP. Beyond it the
  results drift by more than 1 %, and from about 0.4 ms the pendulum loop chatters (ITAE 12x, Ec 85x over 20 s)
  without failing.
- **Initial values**: with or without initial-value propagation the controller gets e(0), de(0) right: when the
  inputs it saw at initialisation were placeholders it re-latches them from the first steps
  (docs/host_robustness.md).
- **Warnings** (switch the FMU's logging on: pythonfmu drops every message otherwise): "initial error
  re-latched" = the host did not propagate initial values, the result is still right; "u chatters with
  communication step" = the step is too large for the host's coupling, the result is wrong: use a smaller
  step or a feedthrough-aware master. The matrix lists what each host passed on.
- **The step in an SSP**: `export-ssp` writes it in every annotation we know an engine reads: ours,
  libcosim's (`osp:FixedStepAlgorithm`, which libcosim takes) and OpenModelica's (`oms:FixedStepMaster`,
  which OMSimulator's C API `oms_importFile` takes). OMSimulator's Python API, fmpy's SSP simulator and
  Ecos read none: set the step by hand (`setFixedStepSize`, `step_size=`); docs/other_hosts.md has the table.
- **Model Exchange** (the native FMUs): no communication step. Our master integrates them with CVODE
  (`--algorithm me`; docs/model_exchange.md); OMSimulator runs an `export-ssp --algorithm me` package
  strongly coupled (its CVODE; FMI 2.0 only), first order in its maximum step, which is also its output
  interval (here the scenario's step). Their rows are on the scenario's step as output grid."""


def steps_for_hosts(convergence: dict) -> list:
    """The validated steps a user of another host needs, per scenario (smallest over the three controllers)."""
    lines = ["## The step to use", "",
             "The validated step (1 %) of docs/convergence.md, smallest over the three controllers. A host "
             "that delays every connection one step (Jacobi: Ecos, libcosim, fmpy.ssp, fmu-manipulation-toolbox "
             "containers, a plain script) needs the Jacobi column; the controller FMU's DefaultExperiment "
             "stepSize is the pendulum's, and `export-ssp` writes the Jacobi step of its scenario and controller "
             "into the SSP.", "",
             "| scenario | Jacobi host (s) | feedthrough-aware master (s) |", "|---|---|---|"]
    for name in convergence.get("scenarios", {}):
        jacobi = [validated_step(convergence, name, c, "jacobi") for c in CONTROLLERS]
        ours = [validated_step(convergence, name, c, "feedthrough") for c in CONTROLLERS]
        smallest = [f"{min(s for s in steps if s):g}" if any(steps) else "n/a" for steps in (jacobi, ours)]
        lines.append(f"| {name} | {smallest[0]} | {smallest[1]} |")
    return lines


def matrix_markdown(matrix: dict) -> str:
    convergence = load_convergence()
    horizon = ", ".join(f"{name} {stop:g} s" if stop else f"{name} 20 s" for name, stop in matrix["stops"].items())
    lines = ["# The FMUs in other FMI hosts", "",
             f"Generated by `python -m harness hosts --apply` ({matrix['wall_s']:.0f} s wall on 2 cores; horizon "
             f"{horizon}). Each row runs the closed loop (controller `vud` unless said) in one host at one "
             "communication step and compares ITAE, IAE and Ec with our converged result over the same horizon "
             "(harness/studies/step_study.py; within 1 % = **ok**; results/hosts/hosts.json keeps every warning's text). "
             "*validated* is the validated step (1 %) of "
             "docs/convergence.md for the host's scheme and the row's controller (our feedthrough master's for ours and "
             "for OMSimulator's co-simulation master, which respects direct feedthrough; Jacobi for every other "
             "co-simulation host; a Model Exchange row has no step: the scenario's step is its output grid); "
             "*scenario* is the scenario's own step (Table I/II). Warnings are the FMU's log messages with status "
             "Warning, and where the host gives them to us.", "",
             "```bash",
             "pip install -e '.[hosts]'      # ecospy, tbb, libcosimpy, fmu-manipulation-toolbox (fmpy: always)",
             "python -m harness hosts pendulum_case1 manipulator --stop manipulator=5   # results/hosts/",
             "python -m harness hosts --host ecos libcosim-api --steps validated  # results/hosts/ only: --apply on a full run",
             "```", ""]
    lines += [USER_NOTES, ""] + steps_for_hosts(convergence) + [""]
    for host in HOSTS:
        if host.key in matrix.get("skipped", {}):
            lines.append(f"- `{host.key}` not run: {matrix['skipped'][host.key]}")
    lines += ["", "## The matrix", "", "Error of ITAE, IAE and Ec against our converged result.", "",
              "| scenario | host | settings | step (s) | ITAE | IAE | Ec | verdict | FMU warnings |",
              "|---|---|---|---|---|---|---|---|---|"]
    for row in matrix["rows"]:
        host = HOSTS_BY_KEY[row["host"]]
        limit = validated_step(convergence, row["scenario"], row["controller"], host.family)
        step = f"{row['step']:g} ({row['step_kind']})"
        full = matrix["stops"].get(row["scenario"]) or scenarios.load(row["scenario"]).stop
        if host.max_steps and row["stop"] is not None and row["stop"] < full - 1e-12:
            step += f", over {row['stop']:g} s ({host.max_steps} steps: its memory)"
        if row["status"] != "ok":
            lines.append(f"| {row['scenario']} | {host.name} (`{host.key}`) | {host.settings} | {step} | "
                         f"{row['status']}: {row.get('reason', '')} |||||")
            continue
        error = row["error"]
        verdict = "**ok**" if within(row) else ("off" + (f" (step > validated {limit:g})"
                                                         if limit and row["step"] > limit * (1 + 1e-9) else ""))
        warnings = "; ".join(warning_kind(w) for w in row["warnings"]) or "none"
        lines.append(f"| {row['scenario']} | {host.name} (`{host.key}`) | {host.settings} | {step} | "
                     f"{_pct(error['ITAE'])} | {_pct(error['IAE'])} | {_pct(error['Ec'])} | {verdict} | "
                     f"{warnings} |")
    examples = {}
    for row in matrix["rows"]:
        for text in row["warnings"]:
            examples.setdefault(warning_kind(text).split(" (")[0], (row["host"], text))
    if examples:
        lines += ["", "The messages in full (one example of each):", ""]
        lines += [f"- `{host}`: {text}" for host, text in examples.values()]
    lines += ["", "Where the warnings come from: " + "; ".join(sorted({f"`{r['host']}`: {r['warnings_from']}"
                                                                     for r in matrix["rows"]
                                                                     if r.get("warnings_from")})) + ".", ""]
    return "\n".join(lines)


def hosts_command(args) -> int:
    cli_args.refuse_tracked([Path(args.out) / "hosts.json", Path(args.out) / "hosts.md"])
    names = args.scenarios or ["pendulum_case1", "manipulator"]
    for name in names:
        scenarios.load(name)
    keys = args.host or list(HOSTS_BY_KEY)
    for key in keys:
        if key not in HOSTS_BY_KEY:
            print(f"error: unknown host {key!r}; valid: {', '.join(HOSTS_BY_KEY)}", file=sys.stderr)
            return 2
    stops = {}
    for item in args.stop or []:
        name, _, value = item.rpartition("=")
        try:
            seconds = float(value)
        except ValueError:
            seconds = math.nan
        if not (math.isfinite(seconds) and seconds > 0) or (name and name not in names):
            print(f"error: --stop {item!r}: give seconds > 0, or SCENARIO=seconds with SCENARIO one of "
                  f"{', '.join(names)}", file=sys.stderr)
            return 2
        for target in ([name] if name else names):
            stops[target] = seconds
    if args.from_json:  # rewrite the outputs (and --apply them) from a matrix already run
        matrix = json.loads(Path(args.from_json).read_text())
    else:
        matrix = hosts_matrix(names, tuple(args.controller), keys, tuple(args.steps),
                              {name: stops.get(name) for name in names}, args.jobs)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "hosts.json").write_text(json.dumps(matrix, indent=1))
    text = matrix_markdown(matrix)
    (out / "hosts.md").write_text(text)
    written = [out / "hosts.json", out / "hosts.md"]
    if args.apply:
        HOSTS_MD.write_text(text)
        written.append(HOSTS_MD)
    for row in matrix["rows"]:
        error = row.get("error")
        summary = " / ".join(_pct(error[m]) for m in METRICS) if error else row.get("reason", row["status"])
        print(f"{row['scenario']:15s} {row['controller']:5s} {row['host']:38s} {row['step']:<8g} {summary}"
              f"{'  ok' if within(row) else ''}  warnings: {len(row['warnings'])}  [{row['wall_s']:.0f} s]")
    for key, reason in matrix["skipped"].items():
        print(f"skipped {key}: {reason}")
    print(f"host matrix: {len(matrix['rows'])} rows in {matrix['wall_s']:.1f} s wall")
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def register(commands):
    command = commands.add_parser("hosts", help="run the closed loops in every FMI host installed here and compare "
                                                "with our converged result")
    command.add_argument("scenarios", nargs="*", type=cli_args.scenario, help="default: pendulum_case1 manipulator")
    command.add_argument("--controller", nargs="+", choices=variants.NAMES, default=[variants.PROPOSED])
    command.add_argument("--host", nargs="+", help=f"hosts to run (default all): {', '.join(HOSTS_BY_KEY)}")
    command.add_argument("--steps", nargs="+", choices=("validated", "scenario"), default=["validated", "scenario"],
                         help="which steps: the host scheme's validated step, the scenario's step (default both)")
    command.add_argument("--stop", nargs="+", metavar="[SCENARIO=]SECONDS",
                         help="shorter horizon, for every scenario or one (compared with our converged result over "
                              "the same horizon); default the scenarios' 20 s")
    command.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    command.add_argument("--out", default=str(DEFAULT_OUT),
                         help=f"output folder (default {DEFAULT_OUT}/ under the working directory)")
    command.add_argument("--from-json", type=cli_args.existing_file,
                         help="do not run: rewrite the outputs from this matrix's hosts.json")
    command.add_argument("--apply", action="store_true", help="also write docs/hosts.md (a tracked file)")
    command.set_defaults(handler=hosts_command)
