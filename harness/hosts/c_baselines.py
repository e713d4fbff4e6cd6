"""The two C baselines the benchmark measures our native master against, on pendulum_case1's loop.

* the plain C host (harness/hosts/plain_c_host.c): a host of its own, written apart from the master,
  that loads the native FMI 2.0 binaries of the plant, the reference and the controller, calls
  them through their FMI functions in the master's order and checks every status, with no Python
  between the calls, no plan and no divergence bound;
* the math floor (harness/hosts/math_floor.c): the same closed loop with every equation inlined in
  one C function and no FMI (pendulum_case1's plant and the vud controller of order 2, 2 sets).

Each runs a scenario of that shape and returns a :class:`BaselineRun`: its record (the master's 15 columns,
rows 0 .. steps) and the seconds of its fixed-step loop alone, in wall time and in the thread's CPU time; tests/test_c_baselines.py holds both records
equal to the master's, bit for bit.  Both libraries are built for this machine by zig's C compiler
(harness/fmu_build/toolchain.py), with the native edition's flags, and loaded once per process.
"""
from __future__ import annotations

import ctypes
import time as clock
from dataclasses import dataclass
from pathlib import Path

import fmpy
import numpy as np

from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build import toolchain as c_toolchain
from fmu_src import afc_math

from ..fmi import extracted_fmu
from ..scenario import Scenario
from ..scenario_checks import resolve_fmu

HOST_SOURCE = Path(__file__).with_name("plain_c_host.c")
FLOOR_SOURCE = Path(__file__).with_name("math_floor.c")

SCENARIO, CONTROLLER = "pendulum_case1", "vud"  # the loop both baselines run (the floor: this controller only)
#: the loop both baselines know: instance -> its FMU, and the record's columns (the master's plan order)
COMPONENTS = {"plant": "InvertedPendulum", "reference": "TrackingReference", "controller": "AdaptiveFuzzyController"}
COLUMNS = ("plant.y", "plant.dy", "plant.d", "reference.ym", "reference.dym", "reference.e", "reference.de",
           "controller.u", "controller.E", "controller.dE", "controller.theta1", "controller.theta2",
           "controller.theta3", "controller.theta4", "controller.w_hat")
CONNECTIONS = {("plant.y", "reference.y"), ("plant.dy", "reference.dy"), ("reference.e", "controller.e"),
               ("reference.de", "controller.de"), ("reference.ym", "controller.ym"),
               ("reference.dym", "controller.dym"), ("controller.u", "plant.u")}
#: the value references the host's HostSystem names, in its order
HOST_REFERENCES = (("plant_outputs", "plant", ("y", "dy", "d")), ("plant_input", "plant", ("u",)),
                   ("reference_inputs", "reference", ("y", "dy")),
                   ("reference_outputs", "reference", ("ym", "dym", "e", "de")),
                   ("controller_inputs", "controller", ("e", "de", "ym", "dym")),
                   ("controller_outputs", "controller", ("u", "E", "dE", "theta1", "theta2", "theta3", "theta4",
                                                         "w_hat")))


class BaselineError(RuntimeError):
    """A baseline cannot run this scenario, or one of its FMI calls failed."""


@dataclass
class BaselineRun:
    record: object  # numpy array, rows 0 .. steps x COLUMNS
    loop_s: float  # the fixed-step loop, wall time
    loop_cpu_s: float  # the same, CPU time of the thread that ran it

    def us_per_step(self, cpu: bool = False) -> float:
        return 1e6 * (self.loop_cpu_s if cpu else self.loop_s) / max(len(self.record) - 1, 1)


# ------------------------------------------------------------------ the C structs
_char_p, _double, _size, _vr = ctypes.c_char_p, ctypes.c_double, ctypes.c_size_t, ctypes.c_uint


class HostFmu(ctypes.Structure):
    _fields_ = [("library", _char_p), ("guid", _char_p), ("resources", _char_p), ("name", _char_p),
                ("parameters", _size), ("parameter_kinds", _char_p), ("parameter_references", ctypes.POINTER(_vr)),
                ("parameter_values", ctypes.POINTER(_double))]


class HostSystem(ctypes.Structure):
    _fields_ = [("plant", HostFmu), ("reference", HostFmu), ("controller", HostFmu),
                *((name, _vr * len(variables)) for name, _, variables in HOST_REFERENCES),
                ("start", _double), ("stop", _double), ("step", _double)]


FLOOR_FIELDS = ("gv", "mc", "mp", "lp", "x1_start", "x2_start", "max_internal_step", "amplitude", "omega",
                "universe1", "universe2", "mf_slope", "lambda_ce", "kappa1", "kappa2", "gamma", "m_theta", "delta",
                "lambda_e", "theta0", "p_b1", "p_b2", "start", "step")


class FloorParameters(ctypes.Structure):
    _fields_ = [(name, _double) for name in FLOOR_FIELDS]


# ------------------------------------------------------------------ the libraries
_LOADED: dict = {}
_double_p = ctypes.POINTER(ctypes.c_double)


def _library(name: str, source: Path):
    if name not in _LOADED:
        if not c_toolchain.compiler_available():
            raise BaselineError(f"the {name} needs zig's C compiler: pip install -e '.[native]'")
        library = ctypes.CDLL(str(c_toolchain.host_library(name, (source,))))
        if name == "plain_c_host":
            host_p = ctypes.c_void_p
            library.plain_host_open.argtypes = [ctypes.POINTER(HostSystem), ctypes.POINTER(host_p)]
            library.plain_host_open.restype = ctypes.c_int
            library.plain_host_run.argtypes = [host_p, ctypes.c_int64, _double_p]
            library.plain_host_run.restype = ctypes.c_int
            library.plain_host_close.argtypes = [host_p]
            library.plain_host_close.restype = ctypes.c_int
            library.plain_host_message.argtypes = [host_p]
            library.plain_host_message.restype = ctypes.c_char_p
        else:
            library.math_floor_run.argtypes = [ctypes.POINTER(FloorParameters), ctypes.c_int64, _double_p]
            library.math_floor_run.restype = ctypes.c_int
        _LOADED[name] = library
    return _LOADED[name]


# ------------------------------------------------------------------ the scenario they run
def check_shape(scenario: Scenario) -> None:
    """The baselines run pendulum_case1's loop only: the same three FMUs, connections and record."""
    fmus = {name: spec.fmu for name, spec in scenario.components.items()}
    connections = {(c.source, c.target) for c in scenario.connections}
    if fmus != COMPONENTS or connections != CONNECTIONS or tuple(scenario.record) != COLUMNS:
        raise BaselineError(f"the C baselines run the loop of pendulum_case1 (components {COMPONENTS}, its "
                            f"connections and record); {scenario.name} is another loop")


def parameters(scenario: Scenario, instance: str) -> dict:
    """The instance's parameters: its FMU's declared starts, then the scenario's values."""
    spec = scenario.components[instance]
    declared = {v.name: v.start for v in fmu_catalog.model_class(spec.fmu).VARIABLES if v.causality == "parameter"}
    return {**declared, **spec.parameters}


def _record(scenario: Scenario) -> np.ndarray:
    """The record, its memory touched before the loop is timed (as Master.run touches its own)."""
    record = np.empty((scenario.steps + 1, len(COLUMNS)))
    record.fill(0.0)
    return record


def _binary(info, folder: str) -> Path:
    return Path(folder, "binaries", fmpy.platform, info.model_identifier + fmpy.sharedLibraryExtension)


def plain_host(scenario: Scenario, fmu_paths: dict | None = None) -> BaselineRun:
    """The plain C host's run on the scenario's native FMI 2.0 FMUs (``fmu_paths``: {model identifier: FMU},
    else the edition's)."""
    check_shape(scenario)
    library = _library("plain_c_host", HOST_SOURCE)
    system, keep = HostSystem(), []
    infos = {}
    for instance, spec in scenario.components.items():
        info, folder = extracted_fmu(resolve_fmu(spec.fmu, scenario, fmu_paths))
        if not info.fmi_version.startswith("2"):
            raise BaselineError(f"the plain C host runs FMI 2.0 FMUs; {info.path} is FMI {info.fmi_version}")
        binary = _binary(info, folder)
        if not binary.is_file():
            raise BaselineError(f"{info.path} has no binary for this machine ({binary.name}): the native edition's "
                                "FMUs have one (--edition native)")
        infos[instance] = info
        kinds, references, values = [], [], []
        for name, value in spec.parameters.items():
            variable = info.variables[name]
            kinds.append("i" if variable.type == "Integer" else "r")
            references.append(variable.valueReference)
            values.append(float(value))
        strings = [str(binary).encode(), info.guid.encode(), Path(folder, "resources").as_uri().encode(),
                   instance.encode(), "".join(kinds).encode()]
        arrays = [(_vr * len(references))(*references), (_double * len(values))(*values)]
        keep += strings + arrays
        setattr(system, instance, HostFmu(strings[0], strings[1], strings[2], strings[3], len(kinds), strings[4],
                                          arrays[0], arrays[1]))
    for field, instance, variables in HOST_REFERENCES:
        getattr(system, field)[:] = [infos[instance].variables[v].valueReference for v in variables]
    system.start, system.stop, system.step = scenario.start, scenario.stop, scenario.step
    record = _record(scenario)
    host = ctypes.c_void_p()
    try:
        if library.plain_host_open(ctypes.byref(system), ctypes.byref(host)) != 0:
            raise BaselineError(f"the plain C host: {library.plain_host_message(host).decode()}")
        started, cpu_started = clock.perf_counter(), clock.thread_time()
        status = library.plain_host_run(host, scenario.steps, record.ctypes.data_as(_double_p))
        seconds, cpu_seconds = clock.perf_counter() - started, clock.thread_time() - cpu_started
        if status != 0:
            raise BaselineError(f"the plain C host: {library.plain_host_message(host).decode()}")
    finally:
        closed = library.plain_host_close(host)
    if closed != 0:
        raise BaselineError(f"the plain C host: fmi2Terminate returned {closed}")
    return BaselineRun(record, seconds, cpu_seconds)


def floor_parameters(scenario: Scenario) -> FloorParameters:
    """The floor's constants from the three FMUs' parameters (P B of (30) by afc_math.lyapunov_p)."""
    check_shape(scenario)
    plant, reference, controller = (parameters(scenario, name) for name in COMPONENTS)
    fixed = {"plant": (plant, {"dist_gain": 0.0}),
             "controller": (controller, {"variant": afc_math.VARIANT_VUD, "fls_input": afc_math.FLS_INPUT_ERROR,
                                         "order": 2, "sets": 2, "initial_error": 1})}
    for instance, (values, required) in fixed.items():
        for name, value in required.items():
            if values[name] != value:
                raise BaselineError(f"the math floor inlines pendulum_case1/vud: {instance}.{name} = {values[name]!r}, "
                                    f"it knows {value!r} only")
    p_b = [row[1] for row in afc_math.lyapunov_p((controller["k1"], controller["k2"]),
                                                  (controller["q1"], controller["q2"]))]
    given = {**{name: plant[name] for name in ("gv", "mc", "mp", "lp", "x1_start", "x2_start", "max_internal_step")},
             "amplitude": reference["amplitude"], "omega": reference["omega"],
             "universe1": controller["E1"], "universe2": controller["E2"],
             **{name: controller[name] for name in ("mf_slope", "lambda_ce", "kappa1", "kappa2", "gamma", "m_theta",
                                                    "delta", "lambda_e", "theta0")},
             "p_b1": p_b[0], "p_b2": p_b[1], "start": scenario.start, "step": scenario.step}
    return FloorParameters(**{name: float(given[name]) for name in FLOOR_FIELDS})


def math_floor(scenario: Scenario) -> BaselineRun:
    """The math floor's run of the scenario."""
    constants = floor_parameters(scenario)
    library = _library("math_floor", FLOOR_SOURCE)
    record = _record(scenario)
    started, cpu_started = clock.perf_counter(), clock.thread_time()
    library.math_floor_run(ctypes.byref(constants), scenario.steps, record.ctypes.data_as(_double_p))
    return BaselineRun(record, clock.perf_counter() - started, clock.thread_time() - cpu_started)


__all__ = ["plain_host", "math_floor", "BaselineRun", "floor_parameters", "check_shape", "parameters", "BaselineError", "COLUMNS",
           "COMPONENTS", "HOST_SOURCE", "FLOOR_SOURCE"]
