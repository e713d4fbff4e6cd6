"""A closed loop wired as a user's plain fmpy script would wire it: no harness master.

Each FMU is driven through fmpy's ``FMU2Slave``: instantiate (logging on), setupExperiment,
enterInitializationMode, set the scenario's parameters, exitInitializationMode, without setting
any input (no initial-value propagation: connected inputs keep their start values until the loop
sets them).  Then, at every communication point t:

* Jacobi (``order`` None): every input from the outputs at t, then every doStep;
* Gauss-Seidel in ``order``: each FMU in turn takes the latest outputs of its sources (an FMU
  stepped earlier hands its values at t + h), steps, and publishes its outputs.

The trajectory holds the plant's and the reference's outputs at t (they do not depend on inputs)
and the u the plant was given for the step from t.  The scenario gives only the FMUs, parameters
and connections.  The host matrix runs it as its ``fmpy-jacobi`` and ``fmpy-gs-*`` hosts
(harness/hosts/host_runners.py); tests/test_host_robustness.py runs it as a user's host.  The FMUs
are extracted once per process (harness/fmi.py: extracted_fmu).
"""
from __future__ import annotations

import numpy as np
from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

from ..fmi import extracted_fmu
from ..master import resolve_fmu
from .trajectory import Trajectory

FMI_WARNING = 1  # fmi2Warning: the status of a log message that is a warning


def applied_input(scenario) -> str:
    """The input the control goes to (``plant.u``)."""
    source = scenario.signals["u"]
    return next(c.target for c in scenario.connections if c.source == source)


def run(scenario, fmu_paths, order: tuple | None = None) -> tuple:
    """(Trajectory, every FMU log message as (instance, status, text) in the order they came) of one run
    over the scenario's horizon at its step: Jacobi (``order`` None) or Gauss-Seidel in ``order``
    (instance names)."""
    messages, slaves, keep_alive = [], {}, []
    outputs, vrs = {}, {}
    try:
        for name, spec in scenario.components.items():
            info, folder = extracted_fmu(resolve_fmu(spec.fmu, scenario, fmu_paths))
            slave = FMU2Slave(guid=info.guid, unzipDirectory=folder, modelIdentifier=info.model_identifier,
                              instanceName=name)
            callbacks = fmi2CallbackFunctions()
            callbacks.logger = fmi2CallbackLoggerTYPE(
                lambda env, instance, status, category, message, name=name:
                messages.append((name, status, message.decode("utf-8", "replace"))))
            callbacks.allocateMemory = defaultCallbacks.allocateMemory
            callbacks.freeMemory = defaultCallbacks.freeMemory
            keep_alive.append(callbacks)
            slave.instantiate(callbacks=callbacks, loggingOn=True)
            slaves[name] = slave
            vrs[name] = {n: v.valueReference for n, v in info.variables.items()}
            outputs[name] = [v.name for v in info.variables.values() if v.causality == "output" and v.type == "Real"]
            slave.setupExperiment(startTime=scenario.start)
            slave.enterInitializationMode()
            for parameter, value in spec.parameters.items():
                if info.variables[parameter].type == "Integer":
                    slave.setInteger([vrs[name][parameter]], [int(value)])
                else:
                    slave.setReal([vrs[name][parameter]], [float(value)])
            slave.exitInitializationMode()
        rows = _loop(scenario, slaves, outputs, vrs, order)
    finally:
        for slave in slaves.values():
            try:
                slave.terminate()
            except Exception:  # noqa: BLE001 - an instance that failed before its initialisation ended
                pass
            slave.freeInstance()
    time = scenario.start + np.arange(scenario.steps + 1) * scenario.step
    return Trajectory(time, *rows.T), messages


def _loop(scenario, slaves: dict, outputs: dict, vrs: dict, order: tuple | None) -> np.ndarray:
    """The communication steps: rows of (y, dy, ym, dym, u) at every communication point."""
    incoming = {name: [c for c in scenario.connections if c.target_instance == name] for name in slaves}
    applied = applied_input(scenario)
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
    return rows
