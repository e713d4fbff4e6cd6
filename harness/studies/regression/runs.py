"""The regression's cases and their runs: which cases, which signals, each run resampled for comparison.

A *case* is one scenario with one controller: the built-in scenarios x the three controllers, or any
scenario file of a user's (their plant FMU, our controller).  The compared signals are the nine of
``SIGNALS`` for a built-in scenario, the scenario's ``[record] variables`` for a user's; every run is
resampled to ``POINTS`` points over the scenario's whole horizon.  The cases run with the shared
runner (harness/cases.py: a ``spawn`` process pool, every core by default).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ... import cases as shared
from ... import scenario as scenarios
from ... import variants
from ...cases import Case

SIGNALS = ("plant.y", "plant.dy", "controller.u", "controller.theta1", "controller.theta2", "controller.theta3",
           "controller.theta4", "reference.e", "reference.de")
POINTS = 2001


def all_cases(names=None, controllers=None, overrides=(), algorithm: str = "feedthrough") -> list[Case]:
    """``algorithm="me"``: the same cases in Model Exchange, held to the same (co-simulation) references."""
    names = list(names or scenarios.scenario_names())
    controllers = list(controllers or variants.NAMES)
    return [Case(n, c, overrides=tuple(overrides), algorithm=algorithm) for n in names for c in controllers]


def is_builtin(case: Case) -> bool:
    """A scenario of harness/scenarios/ (its references are the committed ones)."""
    path = scenarios.load(case.scenario).path
    return path is not None and path.resolve().parent == scenarios.SCENARIO_DIR.resolve()


def case_signals(case: Case) -> tuple:
    """The compared signals: the nine of SIGNALS for a built-in scenario, the recorded ones for a user's."""
    return SIGNALS if is_builtin(case) else tuple(scenarios.load(case.scenario).record)


@dataclass
class CaseRun:
    case: Case
    start: float
    stop: float
    step: float
    time: np.ndarray  # the resampled grid
    signals: dict  # name -> resampled values (the compared signals, in order)
    wall_s: float
    error: str | None = None  # the run failed (message); signals then hold what was computed


def run_cases(cases, workers: int | None = None, fmu_paths: dict | None = None, points: int = POINTS) -> list:
    """Run the cases with the shared runner (a process pool, every core by default), resampled for comparison.

    Results in the order of ``cases``; a failed run keeps what it computed (NaN after it stopped).
    """
    wanted = [dataclasses.replace(case, points=points, signals=case_signals(case), figure_interval=None)
              for case in cases]
    outcomes = shared.run_cases(wanted, jobs=workers, fmu_paths=fmu_paths, progress=False)
    return [CaseRun(case, outcome["start"], outcome["stop"], outcome["step"], outcome["time"], outcome["signals"],
                    outcome["wall_s"], outcome["reason"] if outcome["status"] != "ok" else None)
            for case, outcome in zip(cases, outcomes)]
