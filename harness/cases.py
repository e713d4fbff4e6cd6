"""Run many co-simulations in parallel processes: one case = scenario x controller x settings."""
from __future__ import annotations

import functools
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np

from . import scenario as scenarios
from .master import Divergence, SimulationFailed, simulate
from .scores import score_run

FIGURE_SIGNALS = ("plant.y", "plant.dy", "reference.ym", "reference.dym", "reference.e", "reference.de",
                  "controller.u")


@dataclass(frozen=True)
class Case:
    scenario: str
    controller: str
    step: float | None = None  # None: the scenario's step
    stop: float | None = None  # None: the scenario's stop time
    algorithm: str = "feedthrough"
    overrides: tuple = field(default=())  # (("plant.mp", 1.0), ...)
    figure_interval: float | None = None  # return signals thinned to this interval (figures)

    def build(self) -> scenarios.Scenario:
        return scenarios.configure(self.scenario, self.controller, self.step, self.stop, self.overrides)


def run_case(case: Case, fmu_paths: dict | None = None) -> dict:
    """Scores of one case; a diverged or failed run is a row with its reason, not an exception."""
    scenario = case.build()
    outcome = {"scenario": case.scenario, "controller": case.controller, "step": scenario.step,
               "algorithm": case.algorithm}
    try:
        result = simulate(scenario, algorithm=case.algorithm, fmu_paths=fmu_paths)
    except SimulationFailed as failure:
        status = "diverged" if isinstance(failure.cause, Divergence) else "failed"
        outcome.update(status=status, reason=str(failure).splitlines()[0],
                       wall_s=failure.result.wall_s, rows=failure.result.rows)
        return outcome
    outcome.update(status="ok", reason="", **score_run(result), wall_s=result.wall_s,
                   us_per_step=result.us_per_step, rows=result.rows)
    if case.figure_interval:
        every = max(1, round(case.figure_interval / scenario.step))
        outcome["signals"] = {"time": result.time[::every],
                              **{name: result.signal(name)[::every] for name in FIGURE_SIGNALS}}
    return outcome


def default_jobs() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def parallel_map(function, items: list, jobs: int | None = None, description: str = "",
                 progress: bool | None = False) -> list:
    """[function(item) for item in items] on ``jobs`` processes (default every core), in order.

    Workers are spawned, clean interpreters: loaded FMUs (and Ecos's threads) never cross a
    fork.  ``function`` must be picklable (a module-level function or a functools.partial).
    """
    from tqdm import tqdm

    jobs = max(1, min(len(items), jobs or default_jobs()))
    show = sys.stderr.isatty() if progress is None else progress
    results = [None] * len(items)
    with tqdm(total=len(items), desc=description, unit="run", disable=not show, file=sys.stderr) as bar:
        if jobs == 1:
            for index, item in enumerate(items):
                results[index] = function(item)
                bar.update()
            return results
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(function, item): index for index, item in enumerate(items)}
            for future in as_completed(futures):
                results[futures[future]] = future.result()
                bar.update()
    return results


def run_cases(cases: list, jobs: int | None = None, description: str = "co-simulations",
              progress: bool | None = None) -> list:
    """Outcomes of ``cases`` in their order, computed on ``jobs`` processes with one progress bar."""
    import build_fmu

    fmu_paths = build_fmu.ensure_built()  # once, before the workers start
    return parallel_map(functools.partial(run_case, fmu_paths=fmu_paths), cases, jobs, description, progress)


def as_float(value) -> float:
    return float(value) if value is not None else float("nan")


__all__ = ["Case", "run_case", "run_cases", "default_jobs", "np"]
