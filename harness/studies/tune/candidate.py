"""Running a candidate: the controller's values on every plant variation, scored, and re-run at half
the step when it would be the best so far.

A candidate whose run diverges (the master's divergence stop, or an FMU that reports its state or
adaptation diverged), fails, or makes u chatter (the controller FMU's own monitor, a warning in its
log) comes back with that status and the reason; so does one that beats the best so far and whose
objective moves by more than the tolerance when the run is repeated at half the step (a numerical
artefact, not the controller).  Never raises for a failing run.
"""
from __future__ import annotations

import copy
import math
import re
import time as clock

from ... import cli_args
from ... import scenario as scenarios
from ...cases import status_of
from ...fmi import extracted_fmu
from ...master import Master, SimulationFailed, resolve_fmu
from ...scores import SCORE_KEYS, score_run, value_text, why_none
from .. import step_study

CHATTER_MARK = "u chatters"  # the controller FMU's chatter warning (fmu_src/chatter_monitor.py: warning)


def with_values(scenario, controller_values: dict, variation=()) -> "scenarios.Scenario":
    """A copy of ``scenario`` with the controller's values and a plant variation set."""
    result = copy.deepcopy(scenario)
    result.components[scenario.controller_instance].parameters.update(controller_values)
    for dotted, value in variation:
        instance, _, name = dotted.partition(".")
        result.components[instance].parameters[name] = value
    return result


def half_step(scenario) -> "scenarios.Scenario":
    """The same run at half the communication step (twice the steps over the same horizon)."""
    result = copy.deepcopy(scenario)
    result.step = scenario.step / 2.0
    return result


def prepared_fmus(scenario, fmu_paths: dict) -> dict:
    """{FMU path: (ModelInfo, folder)} of the scenario's FMUs, read and extracted once per process
    (harness/fmi.py: extracted_fmu): a trial's runs reuse them."""
    paths = (resolve_fmu(spec.fmu, scenario, fmu_paths) for spec in scenario.components.values())
    return {path: extracted_fmu(path) for path in paths}


def run_point(scenario, fmu_paths: dict) -> dict:
    """One run: {"status", "reason", "scores", "wall_s"}; never raises for a failing run.

    ``chatter``: the run completed, but the controller FMU warned that u chatters (its own monitor,
    read from the FMU log the master keeps: ``Master.logs``).
    """

    began = clock.perf_counter()
    try:
        master = Master(scenario, fmu_paths=fmu_paths, prepared=prepared_fmus(scenario, fmu_paths))
        result = master.run()
    except SimulationFailed as failure:
        return {"status": status_of(failure), "reason": cli_args.one_line(failure), "scores": None,
                "wall_s": clock.perf_counter() - began}
    except Exception as error:  # noqa: BLE001 - a candidate that cannot run is an outcome
        return {"status": "failed", "reason": cli_args.one_line(error), "scores": None,
                "wall_s": clock.perf_counter() - began}
    scores = score_run(result)
    outcome = {"status": "ok", "reason": "", "scores": scores, "wall_s": clock.perf_counter() - began}
    chatter = next((line for line in master.logs.get(scenario.controller_instance, ()) if CHATTER_MARK in line),
                   None)
    if chatter is not None:
        outcome.update(status="chatter", reason=re.sub(r"^\[\w+\]\s*", "", chatter).split(": over the")[0])
    elif not all(value is None or math.isfinite(value) for value in scores.values()):  # None: scores.why_none
        outcome.update(status="failed", reason=f"a score is not finite: {scores}")
    return outcome


def worst_case(points: list) -> dict:
    """Every score's worst (largest) value over the grid points (every score: smaller is better)."""
    return {key: None if any(point["scores"][key] is None for point in points)  # not settled somewhere
            else max(point["scores"][key] for point in points) for key in SCORE_KEYS}


def relative_change(fine: float, coarse: float) -> float:
    return abs(fine - coarse) / abs(coarse) if coarse else (0.0 if fine == coarse else math.inf)


def richardson(fine: dict, coarse: dict) -> dict:
    """2 f(h/2) - f(h) for every score (the step study's extrapolation)."""
    return step_study.richardson(fine, coarse, metrics=defined_in_both(fine, coarse))


def error_estimates(fine: dict, coarse: dict) -> dict:
    """|f(h) - (2 f(h/2) - f(h))| = 2 |f(h) - f(h/2)|: the estimated error of the score at step h."""
    return {key: 2.0 * abs(coarse[key] - fine[key]) for key in defined_in_both(fine, coarse)}


def defined_in_both(fine: dict, coarse: dict) -> tuple:
    """The scores both runs define (ts is None where a run does not settle: scores.why_none)."""
    return tuple(key for key in coarse if coarse[key] is not None and fine.get(key) is not None)


def evaluate(task: dict) -> dict:
    """One candidate on every grid point (worker side; never raises for a failing run).

    ``task``: scenario (configured), values (controller parameters), grid, fmu_paths, objective,
    verify_below (re-run at half the step if the objective is below it), tolerance.
    """
    began = clock.perf_counter()
    scenario, grid = task["scenario"], task["grid"]
    points = []
    for variation in grid:
        point = run_point(with_values(scenario, task["values"], variation), task["fmu_paths"])
        point["variation"] = [list(item) for item in variation]
        points.append(point)
        if point["status"] != "ok":
            break
    outcome = {"status": "ok", "reason": "", "scores": None, "half_step": None, "points": points}
    bad = next((point for point in points if point["status"] != "ok"), None)
    if bad is not None:
        where = f" (at {', '.join(f'{d}={v:g}' for d, v in bad['variation'])})" if len(grid) > 1 else ""
        outcome.update(status=bad["status"], reason=bad["reason"] + where, scores=bad["scores"])
    else:
        outcome["scores"] = worst_case(points)
        objective = task["objective"]
        if outcome["scores"][objective] is None:  # ts of a run that never settles: no value to rank
            outcome.update(status="undefined",
                           reason=f"{objective}: {why_none(objective, scenario.start, scenario.stop)}")
        elif outcome["scores"][objective] < task["verify_below"]:
            halves = [run_point(half_step(with_values(scenario, task["values"], variation)), task["fmu_paths"])
                      for variation in grid]
            failed = next((half for half in halves if half["status"] != "ok"), None)
            if failed is not None:
                outcome.update(status="step-dependent", reason=f"at half the step: {failed['status']}: "
                                                               f"{failed['reason']}")
            else:
                fine = worst_case(halves)
                change = (math.inf if fine[objective] is None
                          else relative_change(fine[objective], outcome["scores"][objective]))
                outcome["half_step"] = {"step": scenario.step / 2.0, "scores": fine, "change": change,
                                        "richardson": richardson(fine, outcome["scores"]),
                                        "error": error_estimates(fine, outcome["scores"])}
                if change > task["tolerance"]:
                    coarse = outcome["scores"][objective]
                    fine_text = value_text(objective, fine[objective], scenario.start, scenario.stop)
                    outcome.update(status="step-dependent",
                                   reason=f"{objective} {coarse:.6g} at step {scenario.step:g} s, "
                                          f"{fine_text} at half the step ({100 * change:.3g} % > "
                                          f"{100 * task['tolerance']:g} %)")
    outcome["wall_s"] = clock.perf_counter() - began
    return outcome


def evaluate_here(task: dict, files: dict) -> dict:
    """:func:`evaluate` where the task landed: ``files`` is {instance: its FMU file on this host}
    (harness/executors/: the same files on this machine, a Dask worker's cached copies elsewhere)."""
    scenario = copy.deepcopy(task["scenario"])
    for instance, path in files.items():
        scenario.components[instance].fmu = str(path)
    return evaluate({**task, "scenario": scenario, "fmu_paths": {}})
