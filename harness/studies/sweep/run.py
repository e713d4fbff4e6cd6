"""The loop of a sweep: every point of the plan not yet in ``DIR/sweep.csv`` runs on the executor,
its row streams to the CSV as it finishes, the heat map is drawn at the end (:func:`run_sweep`)."""
from __future__ import annotations

import json
import time as clock
from dataclasses import dataclass
from pathlib import Path

from ... import termination
from ...cases import STATUSES, Progress, one_line
from ...executors import SchedulerLost, open_executor
from .csv_rows import CSV_NAME, SETTINGS_NAME, CsvSink, check_settings, read_rows
from .executors import point_files, point_task, run_point
from .grid import SweepPlan, point_key
from .heatmap import plot_heatmap


# ------------------------------------------------------------------- sweep
@dataclass
class SweepSummary:
    csv_path: Path
    heatmap_path: Path | None
    total: int
    done_before: int
    computed: int
    counts: dict  # controller -> {status: n}
    wall_s: float
    interrupted: bool
    executor: str
    lost: int = 0  # points whose worker was lost (crash, killed worker): not recorded, rerun on resume
    lost_reason: str = ""
    interrupt_status: int = 0  # interrupted: 130 (Ctrl-C) or 143 (SIGTERM), harness/termination.py
    scheduler_lost: str = ""  # the Dask scheduler went away mid-sweep (one line): the rest is not run


def run_sweep(plan: SweepPlan, out, jobs: int | None = None, scheduler: str | None = None,
              progress: bool = True, on_row=None, plot: bool = True, point_function=None) -> SweepSummary:
    """Run every point of the plan not yet in ``out/sweep.csv``; stream rows; draw the heat map.

    ``on_row(row, done)`` is called after each row is written (tests interrupt
    the sweep from there by raising KeyboardInterrupt).  A point whose worker is lost
    is run again by the executor; one lost for good (its worker died again while it ran alone,
    harness/executors/local_pool.py) is not recorded: the summary counts it and a resume runs it
    again.  The Dask scheduler gone stops the sweep with what finished recorded.  ``point_function``
    replaces ``run_point`` (tests; a module-level function of (task, files)).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, settings_path = out / CSV_NAME, out / SETTINGS_NAME
    settings = plan.settings()
    check_settings(settings_path, settings)
    kept = read_rows(csv_path, plan.names)
    wanted = {point_key(c, v): (c, v) for c, v in plan.points()}
    done = {point_key(row["controller"], row["values"]) for row in kept}
    todo = [(c, v) for key, (c, v) in wanted.items() if key not in done]
    done_before = len(wanted) - len(todo)
    settings_path.write_text(json.dumps({**settings, "grid_values": {g.name: list(g.values) for g in plan.grids},
                                         "controllers": list(plan.controllers), "metric": plan.metric}, indent=2))
    sink = CsvSink(csv_path, plan.names, kept)
    wall_start = clock.perf_counter()
    interrupted, computed, executor, lost, lost_reason, interrupt_status = False, 0, None, 0, "", 0
    scheduler_lost, where = "", "nothing to run"
    if todo:
        try:
            executor = open_executor(jobs, scheduler, files=point_files(plan), tasks=len(todo))
            where = executor.describe()
        except BaseException:
            sink.close()
            raise
    bar = Progress(len(wanted), f"sweep {plan.scenario.name}", unit="pt", enabled=progress, initial=done_before,
                   dynamic_ncols=True)  # a bar on a terminal, lines elsewhere
    function = point_function or run_point
    try:
        with termination.sigterm_as_interrupt():
            troubled = 0
            for controller, values in todo:
                executor.submit(function, point_task(plan, controller, values))
            for finished in (executor.as_completed() if executor else ()):
                bar.update(1)
                if finished.error is not None:
                    lost += 1
                    lost_reason = lost_reason or one_line(f"{type(finished.error).__name__}: {finished.error}", 300)
                    bar.set_postfix(not_ok=troubled, lost=lost)
                    continue
                row = finished.value
                sink.write(row)
                computed += 1
                troubled += row["status"] != "ok"
                if troubled:
                    bar.set_postfix(not_ok=troubled, lost=lost)
                if on_row is not None:
                    on_row(row, computed)
    except KeyboardInterrupt as interrupt:
        interrupted, interrupt_status = True, termination.exit_status(interrupt)
    except SchedulerLost as error:
        scheduler_lost = str(error)
    finally:
        bar.close()
        sink.close()
        if executor is not None:
            executor.close(cancel=interrupted or bool(scheduler_lost))
    wall_s = clock.perf_counter() - wall_start
    rows = current_rows(plan, read_rows(csv_path, plan.names))
    counts = {c: {s: 0 for s in STATUSES} for c in plan.controllers}
    for row in rows:
        counts[row["controller"]][row["status"]] += 1
    heatmap_path = None
    if plot and rows:
        heatmap_path = plot_heatmap(plan, rows, out / f"heatmap_{plan.metric}.png")
    return SweepSummary(csv_path, heatmap_path, len(wanted), done_before, computed, counts, wall_s,
                        interrupted, where, lost, lost_reason, interrupt_status, scheduler_lost)


def current_rows(plan: SweepPlan, rows: list) -> list:
    """The rows of the CSV that belong to the plan's points (a CSV may hold more after a grid change)."""
    wanted = {point_key(c, v) for c, v in plan.points()}
    return [row for row in rows if point_key(row["controller"], row["values"]) in wanted]
