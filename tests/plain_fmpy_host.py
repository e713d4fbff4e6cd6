"""A closed loop wired as a user's plain fmpy script would wire it: no harness master.

Each FMU is driven through fmpy.fmi2.FMU2Slave: instantiate (logging on), setupExperiment,
enterInitializationMode, set the scenario's parameters, exitInitializationMode, without
setting any input (no initial-value propagation: connected inputs keep their start values
until the loop sets them).  Then, at every communication point t:

* ``jacobi``: read every connected output, set every input, doStep every FMU;
* ``gauss_seidel`` in a given order: for each FMU in turn, set its inputs from the latest
  outputs of their sources (so an FMU stepped earlier hands its values at t + h), doStep it.

Scores use the true tracking error e = ym - y, de = dym - dy (plant and reference outputs at
t, which do not depend on inputs) and the u the plant was given for the step from t.
The scenario (harness/scenarios) gives only the FMUs, parameters and connections.
"""
from __future__ import annotations

import atexit
import shutil

import numpy as np

from harness.scores import score
from fmpy import extract

from tests.fmu_helpers import Driven

_UNZIPPED = {}  # FMU path -> its extracted folder, shared by the instances of a test session


def remove_extractions():
    """Remove the extracted folders (the test session calls this when it ends)."""
    while _UNZIPPED:
        shutil.rmtree(_UNZIPPED.popitem()[1], ignore_errors=True)


def run(scenario, fmu_paths: dict, algorithm: str = "jacobi", order: tuple = (), stop: float | None = None,
        step: float | None = None, overrides: dict | None = None) -> dict:
    """Scores, recorded signals and every FMU's log messages of one plain-host run."""
    step = step or scenario.step
    stop = stop if stop is not None else scenario.stop
    steps = round((stop - scenario.start) / step)
    units = {}
    try:
        for name, spec in scenario.components.items():
            path = str(fmu_paths[spec.fmu])
            if path not in _UNZIPPED:
                _UNZIPPED[path] = extract(path)
                atexit.register(remove_extractions)  # leave no extraction behind (conftest: at session end)
            unit = Driven(path, instance_name=name, unzip_dir=_UNZIPPED[path])
            units[name] = unit
            parameters = dict(spec.parameters, **(overrides or {}).get(name, {}))
            unit.enter(scenario.start, **parameters)
            unit.slave.exitInitializationMode()
        incoming = {name: [c for c in scenario.connections if c.target_instance == name] for name in units}
        recorded = {"plant": ["y", "dy"], "reference": ["ym", "dym"]}
        reads = {name: list(dict.fromkeys(recorded.get(name, []) + [c.source_variable for c in scenario.connections
                                                                    if c.source_instance == name]))
                 for name in units}
        read_vrs = {name: [units[name].vr[v] for v in reads[name]] for name in units}
        write_vrs = {name: [units[name].vr[c.target_variable] for c in incoming[name]] for name in units}
        latest = {}

        def read(name):
            latest.update(zip(((name, v) for v in reads[name]), units[name].slave.getReal(read_vrs[name])))

        def write(name):
            values = [latest[c.source_instance, c.source_variable] for c in incoming[name]]
            units[name].slave.setReal(write_vrs[name], values)
            return values

        order = tuple(order) or tuple(units)
        time = scenario.start + np.arange(steps + 1) * step
        y, dy, ym, dym, u = (np.empty(steps + 1) for _ in range(5))
        for k in range(steps + 1):
            t = scenario.start + k * step
            for name in units:
                read(name)
            y[k], dy[k] = latest["plant", "y"], latest["plant", "dy"]
            ym[k], dym[k] = latest["reference", "ym"], latest["reference", "dym"]
            if algorithm == "jacobi":
                for name in units:
                    values = write(name)
                    if name == "plant":
                        u[k] = values[0]
                if k < steps:
                    for unit in units.values():
                        unit.slave.doStep(t, step)
            else:
                for name in order:
                    for source in {c.source_instance for c in incoming[name]}:
                        read(source)  # the latest outputs: after their own doStep when stepped earlier
                    values = write(name)
                    if name == "plant":
                        u[k] = values[0]
                    if k < steps:
                        units[name].slave.doStep(t, step)
        e, de = ym - y, dym - dy
        return {"scores": score(time, e, de, ym, dym, u), "time": time, "e": e, "de": de, "u": u,
                "messages": {name: list(unit.messages) for name, unit in units.items()}}
    finally:
        for unit in units.values():
            unit.free()
