"""The loop of a Monte Carlo study (:func:`run_study`): the (sample, controller) items not yet in
``DIR/robustness.csv`` stream through the executor layer (harness/executors/stream.py: keyed, several
per task, a bounded window), each row written as it finishes; then the summary (statistics,
influence) from the rows of the file, ``DIR/summary.json`` and the figure."""
from __future__ import annotations

import functools
import json
import math
import os
import resource
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

from ... import termination
from ...cases import Progress, one_line
from ...executors import SchedulerLost, open_executor, stream_tasks
from .figure import plot_study
from .influence import rank_parameters
from .plan import StudyPlan
from .rows import CSV_NAME, SETTINGS_NAME, RowSink, check_settings, read_rows, write_settings
from .sample_run import SampleContext, run_sample
from .statistics import controller_summary, paired_differences

SUMMARY_NAME = "summary.json"
DEFAULT_SCORES = ("ITAE", "es1_pct", "umax", "tv_u")  # the scores the summary gives quantiles of


@dataclass
class StudyOutcome:
    csv_path: Path
    summary_path: Path | None
    figure_path: Path | None
    total: int  # items (samples x controllers) of the plan
    done_before: int
    computed: int
    wall_s: float
    executor: str
    summary: dict = field(default_factory=dict)
    lost: int = 0  # items whose worker was lost, or whose task raised: not written, run again on resume
    lost_reason: str = ""
    interrupted: bool = False
    interrupt_status: int = 0
    scheduler_lost: str = ""
    slots: int = 0  # runs at once (the local pool's processes, the Dask workers' threads)
    loop_s: float = 0.0  # the computed runs' loops, wall time summed (the study's speed figures)
    loop_cpu_s: float = 0.0  # their loops' CPU time, summed
    run_cpu_s: float = 0.0  # the computed runs' CPU time in their workers, summed (the loop and what surrounds it)
    process_cpu_s: float = math.nan  # the CPU time of this process and of its local workers over the run

    def speed(self) -> dict:
        """The study's cost against its runs' loops: ``wall_ratio`` = wall time / (loops' wall time / slots),
        ``cpu_ratio`` = the processes' CPU time / the loops' CPU time (1: nothing but the loops)."""
        figures = {"runs": self.computed, "slots": self.slots, "wall_s": self.wall_s, "loop_s": self.loop_s,
                   "loop_cpu_s": self.loop_cpu_s, "run_cpu_s": self.run_cpu_s, "process_cpu_s": self.process_cpu_s}
        if self.computed and self.loop_s > 0 and self.slots:
            figures["wall_ratio"] = self.wall_s / (self.loop_s / self.slots)
        if self.computed and self.loop_cpu_s > 0:
            figures["run_cpu_ratio"] = self.run_cpu_s / self.loop_cpu_s
            if math.isfinite(self.process_cpu_s):
                figures["cpu_ratio"] = self.process_cpu_s / self.loop_cpu_s
        return figures


def _cpu_s() -> float:
    """The CPU time of this process and of its children that have ended."""
    mine, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return mine.ru_utime + mine.ru_stime + children.ru_utime + children.ru_stime


def row_names(plan: StudyPlan) -> tuple:
    """The CSV's value columns: the drawn parameters, then the noise seed's parameter."""
    return (*plan.names, *((plan.seed_parameter,) if plan.seed_parameter else ()))


def context_of(plan: StudyPlan) -> SampleContext:
    return SampleContext(plan.scenario, plan.names, plan.seed_parameter, plan.algorithm, plan.fingerprint())


def current_rows(plan: StudyPlan, rows: list) -> list:
    """The rows of the plan's samples and controllers (a file may hold more: a smaller rerun)."""
    return [row for row in rows if row["sample"] < plan.samples and row["controller"] in plan.controllers]


def run_study(plan: StudyPlan, out, jobs: int | None = None, scheduler: str | None = None, batch: int = 4,
              spec=None, scores=DEFAULT_SCORES, progress: bool = True, on_row=None, plot: bool = True) -> StudyOutcome:
    """Run every item of the plan not yet recorded, stream the rows, summarise the file's rows.

    ``on_row(row, computed)`` is called after each row is written (tests stop or disturb the run from
    there).  An item whose task failed or whose worker was lost is not written (the rerun runs it);
    the scheduler gone stops the run with what finished written.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, settings_path = out / CSV_NAME, out / SETTINGS_NAME
    settings = plan.settings()
    check_settings(settings_path, settings)
    names = row_names(plan)
    kept = read_rows(csv_path, names)
    done = {(row["sample"], row["controller"]) for row in kept}
    total = plan.samples * len(plan.controllers)
    done_before = sum(1 for key in done if key[0] < plan.samples and key[1] in plan.controllers)
    write_settings(settings_path, settings)
    sink = RowSink(csv_path, names, kept)
    outcome = StudyOutcome(csv_path, None, None, total, done_before, 0, 0.0, "nothing to run")
    began, cpu_before = clock.perf_counter(), _cpu_s()
    executor = None
    try:
        if done_before < total:
            executor = open_executor(jobs, scheduler, files={k: str(v) for k, v in plan.fmu_files.items()},
                                     tasks=-(-(total - done_before) // batch))
            outcome.executor, outcome.slots = executor.describe(), executor.slots
        bar = Progress(total, f"robustness {plan.scenario.name}", unit="run", enabled=progress, initial=done_before,
                       dynamic_ncols=True)
        task = functools.partial(run_sample, context_of(plan))
        try:
            with termination.sigterm_as_interrupt():
                troubled = 0
                for finished in (stream_tasks(executor, task, plan.items(), done=done, batch=batch) if executor else ()):
                    bar.update(1)
                    if not finished.ok:
                        outcome.lost += 1
                        outcome.lost_reason = outcome.lost_reason or one_line(
                            f"{type(finished.error).__name__}: {finished.error}", 300)
                        bar.set_postfix(not_ok=troubled, lost=outcome.lost)
                        continue
                    row = finished.value
                    sink.write(finished.key, row["values"], row)
                    outcome.computed += 1
                    if row["loop_s"] == row["loop_s"]:
                        outcome.loop_s += row["loop_s"]
                        outcome.loop_cpu_s += row["loop_cpu_s"]
                    outcome.run_cpu_s += row["cpu_s"]
                    troubled += row["status"] != "ok" or row["chatter"]
                    if troubled:
                        bar.set_postfix(not_ok=troubled, lost=outcome.lost)
                    if on_row is not None:
                        on_row(row, outcome.computed)
        except KeyboardInterrupt as interrupt:
            outcome.interrupted, outcome.interrupt_status = True, termination.exit_status(interrupt)
        except SchedulerLost as error:
            outcome.scheduler_lost = str(error)
        finally:
            bar.close()
    finally:
        sink.close()
        if executor is not None:
            executor.close(cancel=outcome.interrupted or bool(outcome.scheduler_lost))
    outcome.wall_s = clock.perf_counter() - began
    if scheduler is None:  # the local pool's workers are reaped when it closes: their CPU time is ours to read
        outcome.process_cpu_s = _cpu_s() - cpu_before
    rows = current_rows(plan, read_rows(csv_path, names))
    if rows:
        outcome.summary = summarise(plan, rows, spec, scores)
        outcome.summary_path = out / SUMMARY_NAME
        partial = outcome.summary_path.with_name(SUMMARY_NAME + ".part")
        partial.write_text(json.dumps(outcome.summary, indent=2))
        os.replace(partial, outcome.summary_path)
        if plot:
            outcome.figure_path = plot_study(plan, rows, outcome.summary["influence"].get(plan.controllers[0], {}),
                                             out / f"robustness_{plan.objective}.png")
    return outcome


def summarise(plan: StudyPlan, rows: list, spec=None, scores=DEFAULT_SCORES) -> dict:
    """The summary of the rows (harness/studies/robustness/statistics.py and influence.py), taken in sample
    order: a function of the rows alone, whatever order the workers finished them in (the bootstrap
    resamples by position)."""
    bounds = [d.support() for d in plan.distributions]
    rows = sorted(rows, key=lambda row: row["sample"])
    per_controller, influence = {}, {}
    for controller in plan.controllers:
        mine = [row for row in rows if row["controller"] == controller]
        per_controller[controller] = controller_summary(mine, scores, spec, plan.seed)
        influence[controller] = rank_parameters(mine, plan.names, bounds, plan.objective, plan.seed)
    return {"scenario": plan.scenario.name, "samples": len({row["sample"] for row in rows}),
            "objective": plan.objective, "spec": spec.text() if spec is not None else None,
            "sampler": plan.sampler, "seed": plan.seed,
            "distributions": {d.name: d.settings() for d in plan.distributions},
            "noise_seed": plan.seed_parameter or None,
            "controllers": per_controller,
            "paired": paired_differences(rows, plan.controllers, plan.objective, plan.seed),
            "influence": influence}


__all__ = ["run_study", "summarise", "StudyOutcome", "row_names", "current_rows", "SUMMARY_NAME", "DEFAULT_SCORES"]
