"""The runners of the host matrix: one function per host (harness/hosts/host_registry.py names them),
each ``(scenario, fmu_paths, package) -> (Trajectory, warnings, where the warnings come from)``.

* our master (harness/master.py) with consistent initial values, feedthrough or Jacobi, and our
  Model Exchange master (harness/me_master.py: CVODE over every FMU's states; the native edition);
* the plain fmpy script (harness/hosts/plain_fmpy.py): Jacobi, or Gauss-Seidel in each order;
* fmpy's SSP simulator and Ecos (ecospy) on the exported SSP (harness/hosts/engines.py);
* libcosim (libcosimpy) on the exported SSP and through its API;
* fmu-manipulation-toolbox containers run by fmpy: parallel (Jacobi), sequential in the causal
  order plant, reference, controller and in the reverse;
* OpenModelica's OMSimulator (harness/hosts/omsimulator.py) on the exported SSP: its co-simulation
  master through its Python API and its C API, and its strongly coupled mode on an
  ``--algorithm me`` package.

Warnings are the FMU log messages with status Warning: from the logger callback where the host
takes one (our master, the plain fmpy script, the container run by fmpy, which forwards its
embedded FMUs' messages), else from what the host prints (libcosim logs them as ``[FMI
status=warning, ...]`` at log level warning): the run captures the process's stdout and stderr and
keeps the lines that say warning (harness/hosts/console_capture.py).  fmpy.ssp and Ecos pass none
of them on (``NOT_CAPTURED``): pythonfmu drops every message of an FMU instantiated with logging off.
"""
from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu

from .. import unpack
from ..fmi import ModelInfo
from ..master import Master, resolve_fmu
from ..me_master import ModelExchangeMaster
from . import engines, omsimulator, plain_fmpy
from .console_capture import captured_console, console_warnings
from .trajectory import Trajectory

COMPONENT_ORDER = ("plant", "reference", "controller")  # the causal order of the loop
#: hosts that do not hand the FMU's log messages to us, and what we found
NOT_CAPTURED = {
    "fmpy-ssp": "not captured: simulate_ssp instantiates the FMUs with logging off and takes no option for it, "
                "and pythonfmu then drops every message (docs/host_robustness.md)",
    "ecos": "not captured: Ecos (ecospy 0.7) prints none of the FMU's log messages, even at log level trace (an "
            "invalid parameter's Error message did not appear, and the run went on); like fmpy.ssp it gives no "
            "handle on the FMUs' logging flag"}


def _infos(scenario, fmu_paths):
    paths = {name: resolve_fmu(spec.fmu, scenario, fmu_paths) for name, spec in scenario.components.items()}
    return paths, {name: ModelInfo.read(path) for name, path in paths.items()}


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
    # its own complaint that it lacks the SSP schema files of its install, and its count of what it logged
    # ("info:    2 warnings"), are not an FMU's warnings
    warnings = [w for w in console_warnings(lines) if "could not load the ssd schema file" not in w
                and not re.fullmatch(r"info:\s+\d+ warnings", w)]
    return Trajectory(time, *(columns[n] for n in names)), warnings, "console (OMSimulator prints the FMUs' messages)"


def run_plain_fmpy(scenario, fmu_paths, package=None, order: tuple | None = None) -> tuple:
    """The plain fmpy script (harness/hosts/plain_fmpy.py): Jacobi (order None) or Gauss-Seidel in ``order``."""
    trajectory, messages = plain_fmpy.run(scenario, fmu_paths, order)
    warnings = [f"{name}: [WARNING] {text}" for name, status, text in messages if status == plain_fmpy.FMI_WARNING]
    return trajectory, warnings, "FMI logger callback"


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
        folder = unpack.unpack_folder("libcosim")
        try:
            unpack.extract_archive(package, folder)
            execution = CosimExecution.from_ssp_file(str(folder))
            indices = {name: execution.slave_index_from_instance_name(name) for name in scenario.components}
            trajectory = _libcosim_trajectory(execution, indices, infos, scenario)
            del execution
        finally:
            unpack.remove_folder(folder)
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
    folder = unpack.unpack_folder("container")
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
        unpack.remove_folder(folder)
    time = np.asarray(result["time"], dtype=float)
    columns = [np.asarray(result[n], dtype=float) for n in names]
    # the container forwards the embedded FMUs' messages as "<FMU file>: ..."; its own banners (status Warning:
    # "FMUContainer 'V2.0'", "Container use PARALLEL mode ...") are not the FMU's and are left out
    warnings = [f"[WARNING] {text}" for status, text in messages if status == 1 and re.match(r"\S+\.fmu: ", text)]
    return Trajectory(time, *columns), warnings, \
        "FMI logger callback of the container, which forwards the embedded FMUs' messages (fmpy)"
