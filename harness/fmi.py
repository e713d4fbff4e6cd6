"""Every FMI call of the harness, in one module (as fmpy keeps its own).

:class:`Component` wraps one FMI 2.0 co-simulation instance loaded through
fmpy's low-level ``FMU2Slave`` (``FMU3Slave`` for FMI 3.0); :class:`ModelExchangeComponent`
one Model Exchange instance (``FMU2Model`` / ``FMU3Model``) for harness/me_master.py.  Life-cycle calls go through fmpy (which
raises ``FMICallException`` on a status >= error); the per-step calls
(``real_reader``, ``real_writer``, ``stepper``) are fmpy's raw ctypes functions
bound once to the instance and to value-reference and value arrays prepared
once; they return the FMI status so the caller decides, without allocation
or exceptions per step.  :func:`extracted_fmu` reads and extracts an FMU once
per process for callers that run the same FMUs many times.
"""
from __future__ import annotations

import ctypes
import functools
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Real,
                       fmi2ValueReference)
from fmpy.fmi2 import defaultCallbacks as _fmpy_default_callbacks
from fmpy.fmi3 import FMU3Model, FMU3Slave, fmi3Boolean, fmi3Float64

from . import unpack
from .unpack import process_alive

STATUS_NAMES = ("ok", "warning", "discard", "error", "fatal", "pending")
FMI3_TYPE_NAMES = {"Float64": "Real", "Int32": "Integer"}
FMI_ERROR = 3
FMI3_FUNCTIONS = {"fmi2GetReal": "fmi3GetFloat64", "fmi2SetReal": "fmi3SetFloat64", "fmi2DoStep": "fmi3DoStep",
                  "fmi2SetTime": "fmi3SetTime", "fmi2SetContinuousStates": "fmi3SetContinuousStates",
                  "fmi2GetDerivatives": "fmi3GetContinuousStateDerivatives",
                  "fmi2GetEventIndicators": "fmi3GetEventIndicators",
                  "fmi2CompletedIntegratorStep": "fmi3CompletedIntegratorStep",
                  "fmi2EnterEventMode": "fmi3EnterEventMode", "fmi2NewDiscreteStates": "fmi3UpdateDiscreteStates",
                  "fmi2EnterContinuousTimeMode": "fmi3EnterContinuousTimeMode",
                  "fmi2GetContinuousStates": "fmi3GetContinuousStates",
                  "fmi2GetNominalsOfContinuousStates": "fmi3GetNominalsOfContinuousStates"}
CO_SIMULATION, MODEL_EXCHANGE = "co-simulation", "model exchange"
INTERFACES = (CO_SIMULATION, MODEL_EXCHANGE)


class FmiError(RuntimeError):
    """An FMI call returned a status >= error: names instance, function, time and log."""

    def __init__(self, instance: str, function: str, status: int, time: float, log: list[str]):
        self.instance, self.function, self.status, self.time, self.log = instance, function, status, time, log
        label = STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else str(status)
        text = f"{instance}: {function} returned {label} at t = {time:.6g}"
        if log:
            text += "\n  FMU log:\n" + "\n".join(f"    {line}" for line in log)
        super().__init__(text)


class FmuFileError(ValueError):
    """A file given as an FMU is not one: empty, not a zip archive, no modelDescription.xml in it,
    or a model description that cannot be read.  The message names the file and what it is."""


FMU_IS = "an FMU is a zip archive holding modelDescription.xml"


def check_fmu_file(path: Path) -> None:
    """Raise FmuFileError, naming ``path``, unless it is a zip archive holding modelDescription.xml."""
    if path.is_dir():
        raise FmuFileError(f"{path} is a folder, not an FMU file ({FMU_IS})")
    size = path.stat().st_size
    if size == 0:
        raise FmuFileError(f"{path} is empty (0 bytes), not an FMU ({FMU_IS})")
    if not zipfile.is_zipfile(path):
        with open(path, "rb") as stream:
            head = stream.read(4)
        what = "a truncated or damaged zip archive" if head.startswith(b"PK") else "not a zip archive"
        raise FmuFileError(f"{path} is not an FMU: {what} ({size} bytes; {FMU_IS})")
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError) as error:
        raise FmuFileError(f"{path} is not an FMU: a damaged zip archive ({error})") from None
    if "modelDescription.xml" not in names:
        held = ", ".join(names[:4]) + (f" and {len(names) - 4} more" if len(names) > 4 else "")
        raise FmuFileError(f"{path} is not an FMU: no modelDescription.xml in the zip archive "
                           f"(it holds {held or 'nothing'})")
    try:  # before any of it is read: sizes, links, paths (harness/unpack.py)
        unpack.check_archive(path)
    except unpack.ArchiveError as error:
        raise FmuFileError(str(error)) from None


def _description_problem(error: BaseException) -> str:
    """What fmpy or lxml said of a model description, on one line, without the path lxml reads it from
    (a folder of fmpy's or the working directory: not where the user's file is)."""
    text = " | ".join(line.strip() for line in str(error).splitlines() if line.strip()) or type(error).__name__
    text = re.sub(r"Error reading file '[^']*':\s*", "", text)
    text = re.sub(r"'?[^\s']*modelDescription\.xml'?", "modelDescription.xml", text)
    if "encoding" in text.lower():
        text += " (FMI model descriptions are UTF-8 XML)"
    return text


@dataclass
class ModelInfo:
    """What the master needs of a modelDescription.xml."""

    path: Path
    model_identifier: str
    guid: str
    variables: dict  # name -> fmpy ScalarVariable
    direct_dependencies: dict  # output name -> tuple of input names it depends on directly
    fmi_version: str = "2.0"  # "3.0": driven through fmpy's FMU3Slave (the native edition's FMI 3.0 FMUs)
    interface: str = CO_SIMULATION  # the interface this info was read for: CO_SIMULATION or MODEL_EXCHANGE
    states: int = 0  # Model Exchange: numberOfContinuousStates
    event_indicators: int = 0  # Model Exchange: numberOfEventIndicators
    needs_completed_integrator_step: bool = False  # Model Exchange: completedIntegratorStepNotNeeded = false
    generation_tool: str = ""

    @classmethod
    def read(cls, path, interface: str = CO_SIMULATION) -> "ModelInfo":
        """The description of the FMU at ``path`` for ``interface``; ValueError if it lacks it."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"FMU file not found: {path}")
        if interface not in INTERFACES:
            raise ValueError(f"interface {interface!r}; valid: {', '.join(INTERFACES)}")
        check_fmu_file(path)
        try:
            md = read_model_description(str(path))
        except Exception as error:  # noqa: BLE001 - fmpy raises what lxml or its own checks raise
            raise FmuFileError(f"{path}: its modelDescription.xml cannot be read: {_description_problem(error)}") \
                from None
        declared = md.coSimulation if interface == CO_SIMULATION else md.modelExchange
        if declared is None:
            element = "CoSimulation" if interface == CO_SIMULATION else "ModelExchange"
            raise FmuFileError(f"{path} is not a {interface} FMU (its modelDescription.xml declares no <{element}>)")
        if md.fmiVersion.startswith("3"):
            for v in md.modelVariables:  # the FMI 2.0 type names the harness checks
                v.type = FMI3_TYPE_NAMES.get(v.type, v.type)
        variables = {v.name: v for v in md.modelVariables}
        inputs = tuple(v.name for v in md.modelVariables if v.causality == "input")
        dependencies = {}
        for unknown in md.outputs:
            if unknown.dependencies is None:
                # FMI 2.0: no dependencies attribute means "depends on every input"
                dependencies[unknown.variable.name] = inputs
            else:
                dependencies[unknown.variable.name] = tuple(
                    d.name for d in unknown.dependencies if d.causality == "input")
        if interface == CO_SIMULATION:
            return cls(path, declared.modelIdentifier, md.guid, variables, dependencies, md.fmiVersion,
                       generation_tool=md.generationTool or "")
        return cls(path, declared.modelIdentifier, md.guid, variables, dependencies, md.fmiVersion, interface,
                   md.numberOfContinuousStates, md.numberOfEventIndicators,
                   bool(declared.needsCompletedIntegratorStep), md.generationTool or "")


# ------------------------------------------------------------ FMUs extracted once per process
_EXTRACTIONS: dict = {}  # FMU path -> (ModelInfo, extracted folder, (mtime, size)) of this process


def extract_fmu(path, label: str) -> Path:
    """The FMU at ``path`` unpacked (checked and bounded: harness/unpack.py) into a new folder of
    :func:`harness.unpack.unpack_folder`, which the caller removes with :func:`harness.unpack.remove_folder`;
    on failure nothing is left."""
    folder = unpack.unpack_folder(label)
    try:
        unpack.extract_archive(path, folder)
    except BaseException:
        unpack.remove_folder(folder)
        raise
    return folder


def extracted_fmu(path) -> tuple:
    """(ModelInfo, folder) of the co-simulation FMU at ``path``, read and extracted once per process.

    For callers that run the same FMUs many times (tune's trials, the plain fmpy host): the folder
    is shared, never written after extraction, extracted again when the file changes (mtime or
    size), and removed when the process ends (:func:`release_extractions`, and harness/unpack.py's
    exit handler); the folders killed processes of this host left behind are removed by the first
    unpacking of a process.
    """
    path = Path(path)
    stat = path.stat()
    stamp = (stat.st_mtime_ns, stat.st_size)
    known = _EXTRACTIONS.get(path)
    if known is None or known[2] != stamp:
        if known is not None:  # rebuilt meanwhile: extract the new one
            unpack.remove_folder(_EXTRACTIONS.pop(path)[1])
        info = ModelInfo.read(path)
        folder = extract_fmu(path, f"shared-{_label(path.stem)}")
        try:
            check_runs_from(info, folder)
        except unpack.UnsafeFolder:
            unpack.remove_folder(folder)
            raise
        _EXTRACTIONS[path] = (info, str(folder), stamp)
    info, folder, _ = _EXTRACTIONS[path]
    return info, folder


def release_extractions() -> None:
    """Remove this process's extracted FMUs (:func:`extracted_fmu`) and every other folder it unpacked
    into and has not removed (a worker stopped by SIGTERM calls this before it exits)."""
    while _EXTRACTIONS:
        _, (_, folder, _) = _EXTRACTIONS.popitem()
        unpack.remove_folder(folder)
    unpack.remove_owned()


def _label(name: str) -> str:
    """A folder-name part from an instance name (the scenario allows letters, digits and '_'; other callers
    may pass anything)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", name)[:40] or "instance"


PYTHONFMU = "PythonFMU"  # how pythonfmu names itself in modelDescription.xml's generationTool


def check_runs_from(info: ModelInfo, folder) -> None:
    """Refuse to load an FMU pythonfmu built from a folder whose resource URI needs percent-escapes: its C++
    wrapper decodes only %20, finds no Python class and crashes the process (harness/unpack.py)."""
    if info.generation_tool.startswith(PYTHONFMU) and not unpack.uri_safe(folder):
        raise unpack.UnsafeFolder(
            f"{info.path}: an FMU built by pythonfmu cannot run from {folder} (pythonfmu decodes no %-escape of "
            f"its resource URI but %20 and crashes its host); set {unpack.UNPACK_DIR_VARIABLE} to a folder whose "
            "path holds ASCII letters, digits, '-', '_', '.', '~' and spaces only (docs/using_fmus.md)")


@dataclass
class BoundArrayCall:
    """One getReal or setReal bound to an instance and to value-reference and value arrays."""

    values: object  # ctypes double array the call fills or sends
    call: object  # () -> FMI status
    references: object  # ctypes value-reference array
    function_address: int  # of fmi2GetReal / fmi2SetReal (or fmi3GetFloat64 / fmi3SetFloat64)


@dataclass
class Component:
    """One FMU instance; the fast per-step interface of the master."""

    name: str
    info: ModelInfo
    unzip_dir: str = ""
    log: list = field(default_factory=list)
    time: float = 0.0

    @property
    def fmi3(self) -> bool:
        return self.info.fmi_version.startswith("3")

    def instantiate(self, logging_on: bool = False, extracted: str | None = None):
        """Extract and instantiate; on failure the extraction is removed before the error propagates.

        ``extracted``: a folder the FMU is already extracted to, kept by the caller (a study that runs the
        same FMUs thousands of times extracts them once); it is neither written nor removed here.
        """
        self._owns_dir = extracted is None
        self.unzip_dir = str(extract_fmu(self.info.path, f"run-{_label(self.name)}")) if extracted is None \
            else str(extracted)
        try:
            check_runs_from(self.info, self.unzip_dir)
            if self.fmi3:
                self._instantiate3(logging_on)
            else:
                self._instantiate2(logging_on)
        except BaseException:
            if self._owns_dir:
                unpack.remove_folder(self.unzip_dir)
            raise
        return self

    def _load_and_instantiate2(self, fmu_class, logging_on: bool):
        """Load the shared library as ``fmu_class`` (fmpy's FMU2Slave or FMU2Model) and fmi2Instantiate it
        with our logger."""
        self.slave = self._call("loading the FMU's shared library", lambda: fmu_class(
            guid=self.info.guid, unzipDirectory=self.unzip_dir,
            modelIdentifier=self.info.model_identifier, instanceName=self.name))
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(self._log_message)
        callbacks.allocateMemory = _fmpy_default_callbacks.allocateMemory
        callbacks.freeMemory = _fmpy_default_callbacks.freeMemory
        self._callbacks = callbacks  # keep alive while the instance lives
        self._call("fmi2Instantiate", lambda: self.slave.instantiate(callbacks=callbacks, loggingOn=logging_on))

    def _instantiate2(self, logging_on: bool):
        self._load_and_instantiate2(FMU2Slave, logging_on)
        functions = self.slave._functions
        self._raw_set_real = functions["fmi2SetReal"]
        self._raw_get_real = functions["fmi2GetReal"]
        self._raw_do_step = functions["fmi2DoStep"]
        self._component = self.slave.component

    def _instantiate3(self, logging_on: bool):
        """FMI 3.0 co-simulation through fmpy's FMU3Slave; the same per-step interface."""
        self.slave = self._call("loading the FMU's shared library", lambda: FMU3Slave(
            guid=self.info.guid, unzipDirectory=self.unzip_dir,
            modelIdentifier=self.info.model_identifier, instanceName=self.name))
        self._call("fmi3InstantiateCoSimulation", lambda: self.slave.instantiate(
            loggingOn=logging_on, logMessage=self._log_message3))
        functions = self.slave._functions
        self._raw_set_real = functions["fmi3SetFloat64"]
        self._raw_get_real = functions["fmi3GetFloat64"]
        self._raw_do_step3 = functions["fmi3DoStep"]
        self._component = self.slave.component
        self._step_outputs = tuple(ctypes.byref(value) for value in
                                   (fmi3Boolean(), fmi3Boolean(), fmi3Boolean(), fmi3Float64()))
        return self

    def _log_message3(self, env, status, category, message):
        self._log_message(env, None, status, category, message)

    def _log_message(self, env, instance, status, category, message):
        label = STATUS_NAMES[status].upper() if 0 <= status < len(STATUS_NAMES) else str(status)
        self.log.append(f"[{label}] {message.decode('utf-8', 'replace')}")

    def _call(self, function: str, call):
        try:
            return call()
        except Exception as error:  # fmpy raises FMICallException or a plain Exception
            status = getattr(error, "status", FMI_ERROR)
            raise FmiError(self.name, function, status, self.time, list(self.log)) from error

    # ------------------------------------------------------------ life cycle
    def value_reference(self, name: str) -> int:
        return self.info.variables[name].valueReference

    def setup(self, start_time: float, stop_time: float | None = None):
        self.time = start_time
        if self.fmi3:
            self._call("fmi3EnterInitializationMode",
                       lambda: self.slave.enterInitializationMode(startTime=start_time, stopTime=stop_time))
            return
        self._call("fmi2SetupExperiment", lambda: self.slave.setupExperiment(startTime=start_time, stopTime=stop_time))
        self._call("fmi2EnterInitializationMode", self.slave.enterInitializationMode)

    def set_parameters(self, values: dict):
        for name, value in values.items():
            variable = self.info.variables[name]
            vr = [variable.valueReference]
            if variable.type == "Integer" and self.fmi3:
                self._call("fmi3SetInt32", lambda: self.slave.setInt32(vr, [int(value)]))
            elif variable.type == "Real" and self.fmi3:
                self._call("fmi3SetFloat64", lambda: self.slave.setFloat64(vr, [float(value)]))
            elif variable.type == "Integer":
                self._call("fmi2SetInteger", lambda: self.slave.setInteger(vr, [int(value)]))
            elif variable.type == "Boolean":
                self._call("fmi2SetBoolean", lambda: self.slave.setBoolean(vr, [bool(value)]))
            else:
                self._call("fmi2SetReal", lambda: self.slave.setReal(vr, [float(value)]))

    def exit_initialization(self):
        self._call("fmi2ExitInitializationMode", self.slave.exitInitializationMode)

    def free(self):
        try:
            self.slave.terminate()
        except Exception:
            pass
        try:
            self.slave.freeInstance()
        finally:
            if getattr(self, "_owns_dir", True):
                unpack.remove_folder(self.unzip_dir)

    # -------------------------------------------------------------- per step
    def real_buffer(self, names) -> tuple:
        """(value-reference array, value array, count) for a fixed list of Real variables."""
        count = len(names)
        references = (fmi2ValueReference * count)(*[self.value_reference(n) for n in names])
        values = (fmi2Real * count)()
        return references, values, count

    def _bound_array_call(self, function, names) -> "BoundArrayCall":
        """``function(instance, references, count, values[, count])`` with every argument prepared
        once as a ctypes object and no per-call argument conversion (a C function pointer without
        argtypes, cheaper per call than fmpy's wrappers)."""
        references, values, count = self.real_buffer(names)
        address = ctypes.cast(function, ctypes.c_void_p).value
        bare = ctypes.CFUNCTYPE(ctypes.c_int)(address)
        arguments = [ctypes.c_void_p(self._component), references, ctypes.c_size_t(count), values]
        if self.fmi3:
            arguments.append(ctypes.c_size_t(count))
        return BoundArrayCall(values, functools.partial(bare, *arguments), references, address)

    def real_reader(self, names) -> "BoundArrayCall":
        """``.call()`` reads ``names`` into ``.values`` and returns the status."""
        return self._bound_array_call(self._raw_get_real, names)

    def real_writer(self, names) -> "BoundArrayCall":
        """``.call()`` writes ``.values`` to ``names`` and returns the status."""
        return self._bound_array_call(self._raw_set_real, names)

    @property
    def instance_address(self) -> int:
        """The FMU instance (fmi2Component / fmi3Instance) as an address, for harness/master_loop.c."""
        return ctypes.c_void_p(self._component).value

    @property
    def do_step_address(self) -> int:
        """The address of fmi2DoStep (or fmi3DoStep), for harness/master_loop.c."""
        return ctypes.cast(self._raw_do_step3 if self.fmi3 else self._raw_do_step, ctypes.c_void_p).value

    def stepper(self):
        """call(time, step, 1) -> status: fmi2DoStep (or fmi3DoStep) bound to this instance."""
        if self.fmi3:
            do_step, component, outputs = self._raw_do_step3, self._component, self._step_outputs
            return lambda time, step, no_prior_state: do_step(component, time, step, no_prior_state, *outputs)
        return functools.partial(self._raw_do_step, self._component)

    def fail(self, function: str, status: int, time: float):
        """Raise the FmiError for a status >= error returned by a per-step call (named by its
        FMI 2.0 name; an FMI 3.0 instance reports the FMI 3.0 function)."""
        self.time = time
        if self.fmi3:
            function = FMI3_FUNCTIONS.get(function, function)
        raise FmiError(self.name, function, status, time, list(self.log))


# the Model Exchange calls of one integration step, with their C prototypes (FMI 2.0 and 3.0 share them)
_SET_TIME = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double)
_ARRAY_CALL = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t)


@dataclass
class ContinuousBlock:
    """The continuous states and event indicators of one Model Exchange instance, bound to its slices of
    the integrator's vectors: every call is prepared once and takes no argument."""

    component: "ModelExchangeComponent"
    offset: int  # of its states in the integrator's state vector
    states: int
    indicator_offset: int  # of its indicators in the vector of every event indicator
    indicators: int
    set_states: object  # () -> status: SetContinuousStates from the shared state array
    get_derivatives: object  # () -> status: GetDerivatives into the shared derivative array
    get_indicators: object  # () -> status: GetEventIndicators into the shared indicator array


class ModelExchangeComponent(Component):
    """One FMU instance for Model Exchange (fmpy's FMU2Model / FMU3Model).

    The value reads and writes of the master's plan (``real_reader``, ``real_writer``) are those of
    :class:`Component`; the integration adds ``set_time``, the state and derivative calls bound to
    the integrator's arrays (:meth:`continuous_block`), and the event-mode calls.  Every call that a
    derivative evaluation makes is a raw C function bound once (no argument conversion per call
    beyond the time).
    """

    def _instantiate2(self, logging_on: bool):
        self._load_and_instantiate2(FMU2Model, logging_on)
        self._bind(2)

    def _instantiate3(self, logging_on: bool):
        self.slave = self._call("loading the FMU's shared library", lambda: FMU3Model(
            guid=self.info.guid, unzipDirectory=self.unzip_dir,
            modelIdentifier=self.info.model_identifier, instanceName=self.name))
        self._call("fmi3InstantiateModelExchange", lambda: self.slave.instantiate(
            loggingOn=logging_on, logMessage=self._log_message3))
        self._bind(3)

    def _bind(self, version: int):
        functions = self.slave._functions
        prefix = f"fmi{version}"
        names = {"set_real": "fmi2SetReal", "get_real": "fmi2GetReal", "set_time": "fmi2SetTime",
                 "set_states": "fmi2SetContinuousStates", "get_derivatives": "fmi2GetDerivatives",
                 "get_indicators": "fmi2GetEventIndicators",
                 "completed_step": "fmi2CompletedIntegratorStep"}
        if version == 3:
            names = {key: FMI3_FUNCTIONS[name] for key, name in names.items()}
        self.addresses = {key: ctypes.cast(functions[name], ctypes.c_void_p).value for key, name in names.items()}
        self._raw_set_real = functions[f"{prefix}SetFloat64" if version == 3 else "fmi2SetReal"]
        self._raw_get_real = functions[f"{prefix}GetFloat64" if version == 3 else "fmi2GetReal"]
        self._component = self.slave.component
        self._instance = ctypes.c_void_p(self._component)
        self._set_time = functools.partial(_SET_TIME(self.addresses["set_time"]), self._instance)

    # -------------------------------------------------- the integration's calls
    def time_setter(self):
        """call(t) -> status: SetTime on this instance."""
        return self._set_time

    def continuous_block(self, offset: int, x, dx, indicator_offset: int, z) -> ContinuousBlock:
        """The state, derivative and indicator calls bound to slices of ``x``, ``dx`` and ``z`` (ctypes
        double arrays shared by every instance of the loop)."""
        states, indicators = self.info.states, self.info.event_indicators

        def bound(key, array, first, count):
            pointer = ctypes.c_void_p(ctypes.addressof(array) + 8 * first)
            return functools.partial(_ARRAY_CALL(self.addresses[key]), self._instance, pointer,
                                     ctypes.c_size_t(count))

        return ContinuousBlock(self, offset, states, indicator_offset, indicators,
                               bound("set_states", x, offset, states), bound("get_derivatives", dx, offset, states),
                               bound("get_indicators", z, indicator_offset, indicators))

    def get_states(self, values) -> None:
        """The continuous states into ``values`` (a ctypes double array or pointer of their length)."""
        if self.info.states:
            self._call(self._fmi("fmi2GetContinuousStates"),
                       lambda: self.slave.getContinuousStates(values, self.info.states))

    def get_nominals(self, values) -> None:
        if self.info.states:
            self._call(self._fmi("fmi2GetNominalsOfContinuousStates"),
                       lambda: self.slave.getNominalsOfContinuousStates(values, self.info.states))

    def enter_event_mode(self):
        self._call(self._fmi("fmi2EnterEventMode"), self.slave.enterEventMode)

    def update_discrete_states(self) -> tuple:
        """NewDiscreteStates (FMI 3.0: UpdateDiscreteStates): (another pass needed, terminate, values of
        continuous states changed, next event time or None)."""
        if self.fmi3:
            again, terminate, _, changed, timed, next_time = self._call(
                "fmi3UpdateDiscreteStates", self.slave.updateDiscreteStates)
        else:
            again, terminate, _, changed, timed, next_time = self._call(
                "fmi2NewDiscreteStates", self.slave.newDiscreteStates)
        return bool(again), bool(terminate), bool(changed), (float(next_time) if timed else None)

    def enter_continuous_time_mode(self):
        self._call(self._fmi("fmi2EnterContinuousTimeMode"), self.slave.enterContinuousTimeMode)

    def completed_integrator_step(self) -> tuple:
        """CompletedIntegratorStep: (enter event mode, terminate)."""
        enter, terminate = self._call(self._fmi("fmi2CompletedIntegratorStep"),
                                      lambda: self.slave.completedIntegratorStep(True))
        return bool(enter), bool(terminate)

    def _fmi(self, function: str) -> str:
        return FMI3_FUNCTIONS.get(function, function) if self.fmi3 else function

    @property
    def do_step_address(self) -> int:
        raise TypeError(f"{self.name} is a Model Exchange instance: it has no doStep")

    def stepper(self):
        raise TypeError(f"{self.name} is a Model Exchange instance: it has no doStep")


__all__ = ["BoundArrayCall", "Component", "ContinuousBlock", "FmiError", "FmuFileError", "ModelExchangeComponent",
           "ModelInfo", "check_fmu_file", "check_runs_from", "extract_fmu", "extracted_fmu", "process_alive",
           "release_extractions", "CO_SIMULATION", "MODEL_EXCHANGE"]
