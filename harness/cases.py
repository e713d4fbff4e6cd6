"""One case model and one runner for every study: tables, regression, sweeps, the step study.

A :class:`Case` is one co-simulation: a scenario x a controller x settings (step, stop,
master algorithm, parameter overrides, FMU files) and what to bring back besides the
scores (signals thinned to an interval, or resampled to a number of points).
:func:`run_case` runs it and returns its *outcome*: a plain dict (it travels between
processes and into CSV/JSON files) with the scores of docs/model.md section 9 (scores) and a status:

* ``ok``: the run completed; every score is there;
* ``diverged``: the master's divergence bound stopped it, or a plant FMU reported that
  its state diverged inside doStep;
* ``failed``: any other failure (an FMU rejected a parameter, a call failed, ...).

A diverged or failed run is an outcome with its ``reason`` on one line, never an
exception: a study of many cases goes on.  :func:`run_cases` runs many on a process pool.
"""
from __future__ import annotations

import functools
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from harness.fmu_build import builder as build_fmu

from . import master_loop, me_loop, me_master
from . import progress as progress_module
from . import scenario as scenarios
from .executors import default_jobs, open_executor
from .fmi import FmiError
from .master import ALGORITHMS as CO_SIMULATION_ALGORITHMS
from .master import Divergence, SimulationFailed, simulate
from .progress import Progress, WorkBoard
from .scores import score_run

#: every algorithm a run can use: our co-simulation masters and Model Exchange (harness/me_master.py)
ALGORITHMS = (*CO_SIMULATION_ALGORITHMS, me_master.ALGORITHM)
SOLVER_KEYS = ("steps", "derivative_evaluations", "state_events")  # what an outcome keeps of an ME run's solver

FIGURE_SIGNALS = ("plant.y", "plant.dy", "reference.ym", "reference.dym", "reference.e", "reference.de",
                  "controller.u")
STATUSES = ("ok", "diverged", "failed")
REASON_LIMIT = 600  # characters of a failure's reason (one line)


@dataclass(frozen=True)
class Case:
    """One co-simulation.  ``scenario``: a name, a .toml path or a :class:`~harness.scenario.Scenario`."""

    scenario: object
    controller: str
    step: float | None = None  # None: the scenario's step
    stop: float | None = None  # None: the scenario's stop time
    algorithm: str = "feedthrough"
    overrides: tuple = field(default=())  # (("plant.mp", 1.0), ("step", 1e-3), ...), applied last
    figure_interval: float | None = None  # bring back ``signals`` thinned to this interval (figures)
    points: int | None = None  # bring back ``signals`` resampled to this many points over [start, stop]
    signals: tuple = FIGURE_SIGNALS  # the signals brought back (with figure_interval or points)
    fmu_files: tuple = field(default=())  # (("plant", "/path/InvertedPendulum.fmu"), ...): FMU of an instance
    rtol: float | None = None  # --algorithm me: CVODE's relative tolerance (None: me_master.DEFAULT_RTOL)
    atol: float | None = None  # --algorithm me: absolute tolerance (None: rtol)

    @property
    def scenario_name(self) -> str:
        """The scenario's name; for a .toml path, the file's stem (regress names reference files after it)."""
        if isinstance(self.scenario, scenarios.Scenario):
            return self.scenario.name
        text = str(self.scenario)
        return Path(text).stem if text.endswith(".toml") else text

    @property
    def name(self) -> str:
        """``scenario_controller`` (the regression's reference files are named after it)."""
        return f"{self.scenario_name}_{self.controller}"

    @property
    def label(self) -> str:
        """The name and every setting that differs from the scenario's."""
        settings = [f"{key}={value:g}" for key, value in (("step", self.step), ("stop", self.stop))
                    if value is not None]
        settings += [f"{k}={v:g}" for k, v in self.overrides]
        if self.algorithm != "feedthrough":
            settings.append(self.algorithm)
        settings += [f"{key}={value:g}" for key, value in (("rtol", self.rtol), ("atol", self.atol)) if value is not None]
        return self.name + (" [" + ", ".join(settings) + "]" if settings else "")

    def build(self) -> scenarios.Scenario:
        """The scenario with the controller, step, stop, overrides and FMU files set.

        The run covers a whole number of steps.  A case that varies the step (``step``, or
        a ``step`` override: the step study, sweeps over the step) moves a stop off its
        step grid to the nearest whole number of steps, and the outcome's ``notes`` say
        so; otherwise a given stop off the step grid is an error (ScenarioError).
        """
        varies_step = self.step is not None or any(name == "step" for name, _ in self.overrides)
        scenario = scenarios.configure(self.scenario, self.controller, self.step, self.stop, self.overrides,
                                       fit_stop="move" if varies_step else "error")
        for instance, path in self.fmu_files:
            scenario.components[instance].fmu = str(path)
        return scenario


def one_line(text: str, limit: int = REASON_LIMIT) -> str:
    line = " | ".join(part.strip() for part in str(text).splitlines() if part.strip())
    return line if len(line) <= limit else line[:limit - 3] + "..."


def status_of(error: BaseException) -> str:
    """``diverged`` or ``failed`` for the exception that stopped a run."""
    cause = getattr(error, "cause", error)
    if isinstance(cause, Divergence):
        return "diverged"
    # the plant FMUs stop a run themselves when their state blows up inside doStep
    if isinstance(cause, FmiError) and any("state diverged" in line for line in cause.log):
        return "diverged"
    return "failed"


def resample(time: np.ndarray, values: np.ndarray, start: float, stop: float, points: int) -> tuple:
    """(grid, values) on ``points`` evenly spaced times over [start, stop]; NaN after the run stopped."""
    grid = np.linspace(start, stop, points)
    if len(time) == 0:
        return grid, np.full(points, np.nan)
    inside = grid <= time[-1] + 1e-12
    resampled = np.full(points, np.nan)
    resampled[inside] = np.interp(grid[inside], time, values)
    return grid, resampled


def simulate_any(scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None, progress=None,
                 rtol: float | None = None, atol: float | None = None):
    """One run with any algorithm: our co-simulation master, or the Model Exchange master for "me"."""
    if algorithm == me_master.ALGORITHM:
        return me_master.simulate(scenario, fmu_paths, me_master.DEFAULT_RTOL if rtol is None else rtol, atol,
                                  progress=progress)
    if rtol is not None or atol is not None:
        raise scenarios.ScenarioError(f"rtol and atol are tolerances of --algorithm me, not of {algorithm}")
    return simulate(scenario, algorithm=algorithm, fmu_paths=fmu_paths, progress=progress)


def run_case(case: Case, fmu_paths: dict | None = None) -> dict:
    """The outcome of one case (see the module's doc); never raises for a failing simulation."""
    scenario = case.build()
    outcome = {"scenario": case.scenario_name, "controller": case.controller, "step": scenario.step,
               "start": scenario.start, "stop": scenario.stop, "algorithm": case.algorithm,
               "notes": list(scenario.notes)}
    wall = clock.perf_counter()
    result = None
    try:
        result = simulate_any(scenario, case.algorithm, fmu_paths, progress=progress_module.step_reporter(),
                              rtol=case.rtol, atol=case.atol)
        outcome.update(status="ok", reason="", **score_run(result), us_per_step=result.us_per_step)
    except Exception as error:  # noqa: BLE001 - every failure of a case is an outcome, the study goes on
        if isinstance(error, SimulationFailed):
            result = error.result
        message = str(error) or type(error).__name__
        if not isinstance(error, SimulationFailed):
            message = f"{type(error).__name__}: {message}"
        outcome.update(status=status_of(error), reason=one_line(message))
    outcome["wall_s"] = clock.perf_counter() - wall
    outcome["rows"] = result.rows if result is not None else 0
    if result is not None and result.solver:
        outcome.update(rtol=result.solver["rtol"], atol=result.solver["atol"],
                       **{key: result.solver[key] for key in SOLVER_KEYS})
    if case.points and result is not None:
        signals, grid = {}, None
        for name in case.signals:
            grid, signals[name] = resample(result.time, result.signal(name), scenario.start, scenario.stop,
                                           case.points)
        outcome.update(time=grid, signals=signals)
    elif case.points:
        grid = np.linspace(scenario.start, scenario.stop, case.points)
        outcome.update(time=grid, signals={name: np.full(case.points, np.nan) for name in case.signals})
    elif case.figure_interval and result is not None and outcome["status"] == "ok":
        every = max(1, round(case.figure_interval / scenario.step))
        outcome["signals"] = {"time": result.time[::every],
                              **{name: result.signal(name)[::every] for name in case.signals}}
    return outcome


def _run_item(function, index: int, item):
    """One item in a worker: its progress goes to its slot of the board."""
    progress_module.set_item(index)
    try:
        return function(item)
    finally:
        progress_module.set_item(None)


def parallel_map(function, items: list, jobs: int | None = None, description: str = "",
                 progress: bool | None = False, label=None, weights=None, unit: str = "") -> list:
    """[function(item) for item in items] on ``jobs`` processes (default every core), in order.

    The executor layer runs them (harness/executors/: workers are spawned, clean interpreters, so
    loaded FMUs (and Ecos's threads) never cross a fork; they end with the command, SIGKILL included;
    the items of a lost worker run again).  ``function`` must be picklable (a module-level function
    or a functools.partial).
    ``progress`` (None or True: on; False: off) is a :class:`Progress` on stderr: a bar on a
    terminal, lines elsewhere; ``label(item)`` names a finished item in those lines.  ``weights``:
    each item's work in ``unit`` (a co-simulation's steps; default 1 per item), which the time left is
    estimated from, with the fractions ``function`` reports through harness.progress.step_reporter.
    A KeyboardInterrupt (Ctrl-C, or SIGTERM as harness.termination.Terminated) ends the workers; an
    item that raised raises here.
    """
    results = [None] * len(items)
    name = label or (lambda item: "")
    board = WorkBoard(weights if weights is not None else [1] * len(items), unit if weights is not None else "")
    outer = progress_module.attach(board.fractions), progress_module.set_item(None)
    try:
        executor = open_executor(jobs, tasks=len(items), inline_single=True, initializer=progress_module.attach,
                                 initargs=(board.fractions,))
        with Progress(len(items), description or "runs", enabled=progress is not False, board=board,
                      workers=executor.slots) as bar, executor:
            for index, item in enumerate(items):
                executor.submit(functools.partial(_run_item, function, index), item, key=index)
            for done in executor.as_completed():
                if done.error is not None:
                    raise done.error
                results[done.key] = done.value
                board.finish(done.key)
                bar.update(label=name(items[done.key]))
    finally:
        progress_module.attach(outer[0])
        progress_module.set_item(outer[1])
    return results


def run_cases(cases: list, jobs: int | None = None, description: str = "co-simulations",
              progress: bool | None = None, fmu_paths: dict | None = None) -> list:
    """Outcomes of ``cases`` in their order, computed on ``jobs`` processes with one progress bar."""
    # a mistake in a case (a stop off the step grid, ...) is one error before any run; each run's steps weigh it
    steps = [max(1, case.build().steps) for case in cases]
    if fmu_paths is None:
        fmu_paths = build_fmu.ensure_built()  # once, before the workers start
    master_loop.library()  # the compiled loop too (when zig is installed), so no two workers compile it
    if any(case.algorithm == me_master.ALGORITHM for case in cases):
        me_loop.library()
    return parallel_map(functools.partial(run_case, fmu_paths=fmu_paths), cases, jobs, description, progress,
                        label=lambda case: case.label, weights=steps, unit="step")


__all__ = ["Case", "Progress", "run_case", "run_cases", "simulate_any", "ALGORITHMS", "parallel_map", "default_jobs",
           "status_of", "one_line", "resample"]
