"""One sample of a Monte Carlo study on one controller, as a task of the executor layer
(harness/executors/): :func:`run_sample`, a module-level function that travels to the workers.

What costs outside the loop is paid once per worker (``worker_state``): the scenario configured,
the FMUs read, extracted and instantiated (:class:`~.kept_instances.KeptInstancesMaster`, the
instances reset between samples), the record cut to the signals the scores read.  A sample then
sets its parameter values and the controller variant in place, runs, and is scored in numpy
(harness/scores.py); a run that fails or diverges is a row with its status, never an exception.
"""
from __future__ import annotations

import copy
import re
import time as clock
from dataclasses import dataclass

from ...cases import one_line, status_of
from ...executors import worker_state
from ...master import SimulationFailed
from ...scores import SCORE_KEYS, score_run
from ...variants import CONTROLLER_VARIANTS
from .kept_instances import KeptInstancesMaster

CHATTER_MARK = "u chatters"  # the controller FMU's chatter warning (fmu_src/chatter_monitor.py: warning)


@dataclass(frozen=True)
class SampleContext:
    """What every sample of a study shares (it travels once per task): the scenario configured (its
    stop, step, hardware), the names of the drawn parameters, the noise seed's parameter (or ""),
    the algorithm, and a fingerprint naming the worker's kept state."""

    scenario: object
    names: tuple
    seed_parameter: str
    algorithm: str
    fingerprint: str


class SampleRunner:
    """A worker's master for one study: the scenario with only the scored signals recorded, its FMUs
    those of this host (``files``), the instances kept between samples."""

    def __init__(self, context: SampleContext, files: dict):
        scenario = copy.deepcopy(context.scenario)
        for instance, path in files.items():
            scenario.components[instance].fmu = str(path)
        scenario.record = list(dict.fromkeys(scenario.signals.values()))  # what the scores read, nothing more
        self.scenario, self.context = scenario, context
        self.master = KeptInstancesMaster(scenario, context.algorithm)
        self.targets = [name.partition(".") for name in (*context.names, context.seed_parameter) if name]

    def run(self, controller: str, values) -> dict:
        scenario = self.scenario
        scenario.components[scenario.controller_instance].parameters["variant"] = CONTROLLER_VARIANTS[controller]
        for (instance, _, parameter), value in zip(self.targets, values):
            scenario.components[instance].parameters[parameter] = value
        began, cpu = clock.perf_counter(), clock.thread_time()
        row = {"values": values, "status": "ok", "reason": "", "chatter": 0, "scores": {}, "loop_s": float("nan"),
               "loop_cpu_s": float("nan")}
        try:
            result = self.master.run_scenario(scenario)
            row["scores"] = score_run(result)
            row["loop_s"], row["loop_cpu_s"] = result.loop_s, self.master.loop_cpu_s
        except SimulationFailed as failure:
            row.update(status=status_of(failure), reason=one_line(failure))
        except Exception as error:  # noqa: BLE001 - a sample that cannot run is a row, the study goes on
            row.update(status="failed", reason=one_line(f"{type(error).__name__}: {error}"))
        chatter = next((line for line in self.master.logs.get(scenario.controller_instance, ())
                        if CHATTER_MARK in line), None)
        if chatter is not None:
            row.update(chatter=1, reason=row["reason"] or re.sub(r"^\[\w+\]\s*", "", chatter).split(": over the")[0])
        row["wall_s"], row["cpu_s"] = clock.perf_counter() - began, clock.thread_time() - cpu
        return row

    def close(self):
        self.master.close()


def run_sample(context: SampleContext, item, files: dict) -> dict:
    """In a worker: the row of one (controller, parameter values, noise seed) item."""
    controller, values = item
    runner = worker_state(("robustness", context.fingerprint, tuple(sorted(files.items()))),
                          lambda: SampleRunner(context, files))
    return runner.run(controller, values)


__all__ = ["SampleContext", "SampleRunner", "run_sample", "CHATTER_MARK", "SCORE_KEYS"]
