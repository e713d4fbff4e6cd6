"""Every FMI call of the harness, in one module (as fmpy keeps its own).

:class:`Component` wraps one FMI 2.0 co-simulation instance loaded through
fmpy's low-level ``FMU2Slave``.  Life-cycle calls go through fmpy (which
raises ``FMICallException`` on a status >= error); the per-step calls
(``real_reader``, ``real_writer``, ``stepper``) are fmpy's raw ctypes functions
bound once to the instance and to value-reference and value arrays prepared
once; they return the FMI status so the caller decides, without allocation
or exceptions per step.
"""
from __future__ import annotations

import ctypes
import functools
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from fmpy import extract, read_model_description
from fmpy.fmi2 import (FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2Real,
                       fmi2ValueReference)
from fmpy.fmi2 import defaultCallbacks as _fmpy_default_callbacks
from fmpy.fmi3 import FMU3Slave, fmi3Boolean, fmi3Float64

STATUS_NAMES = ("ok", "warning", "discard", "error", "fatal", "pending")
FMI3_TYPE_NAMES = {"Float64": "Real", "Int32": "Integer"}
FMI_ERROR = 3
FMI3_FUNCTIONS = {"fmi2GetReal": "fmi3GetFloat64", "fmi2SetReal": "fmi3SetFloat64", "fmi2DoStep": "fmi3DoStep"}


class FmiError(RuntimeError):
    """An FMI call returned a status >= error: names instance, function, time and log."""

    def __init__(self, instance: str, function: str, status: int, time: float, log: list[str]):
        self.instance, self.function, self.status, self.time, self.log = instance, function, status, time, log
        label = STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else str(status)
        text = f"{instance}: {function} returned {label} at t = {time:.6g}"
        if log:
            text += "\n  FMU log:\n" + "\n".join(f"    {line}" for line in log)
        super().__init__(text)


@dataclass
class ModelInfo:
    """What the master needs of a modelDescription.xml."""

    path: Path
    model_identifier: str
    guid: str
    variables: dict  # name -> fmpy ScalarVariable
    direct_dependencies: dict  # output name -> tuple of input names it depends on directly
    fmi_version: str = "2.0"  # "3.0": driven through fmpy's FMU3Slave (the native edition's FMI 3.0 FMUs)

    @classmethod
    def read(cls, path) -> "ModelInfo":
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"FMU file not found: {path}")
        md = read_model_description(str(path))
        if md.coSimulation is None:
            raise ValueError(f"{path.name} is not a co-simulation FMU")
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
        return cls(path, md.coSimulation.modelIdentifier, md.guid, variables, dependencies, md.fmiVersion)


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
        self.unzip_dir = tempfile.mkdtemp(prefix=f"afc_{self.name}_") if extracted is None else str(extracted)
        try:
            if self._owns_dir:
                extract(str(self.info.path), self.unzip_dir)
            if self.fmi3:
                self._instantiate3(logging_on)
            else:
                self._instantiate2(logging_on)
        except BaseException:
            if self._owns_dir:
                shutil.rmtree(self.unzip_dir, ignore_errors=True)
            raise
        return self

    def _instantiate2(self, logging_on: bool):
        self.slave = self._call("loading the FMU's shared library", lambda: FMU2Slave(
            guid=self.info.guid, unzipDirectory=self.unzip_dir,
            modelIdentifier=self.info.model_identifier, instanceName=self.name))
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = fmi2CallbackLoggerTYPE(self._log_message)
        callbacks.allocateMemory = _fmpy_default_callbacks.allocateMemory
        callbacks.freeMemory = _fmpy_default_callbacks.freeMemory
        self._callbacks = callbacks  # keep alive while the instance lives
        self._call("fmi2Instantiate", lambda: self.slave.instantiate(callbacks=callbacks, loggingOn=logging_on))
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
                shutil.rmtree(self.unzip_dir, ignore_errors=True)

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
        argtypes: 0.4 us per call instead of 0.9 us through fmpy's)."""
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


__all__ = ["BoundArrayCall", "Component", "FmiError", "ModelInfo"]
