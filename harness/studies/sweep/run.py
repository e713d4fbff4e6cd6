"""The loop of a sweep: every point of the plan not yet in ``DIR/sweep.csv`` runs on the executor,
its row streams to the CSV as it finishes, the heat map is drawn at the end (:func:`run_sweep`)."""
from __future__ import annotations

import json
import os
import signal
import time as clock
from dataclasses import dataclass
from pathlib import Path

from ... import termination
from ...cases import STATUSES, Progress, one_line
from .csv_rows import CSV_NAME, SETTINGS_NAME, CsvSink, check_settings, read_rows
from .executors import DaskPool, LocalPool, point_task
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


def run_sweep(plan: SweepPlan, out, jobs: int | None = None, scheduler: str | None = None,
              progress: bool = True, on_row=None, plot: bool = True, point_function=None) -> SweepSummary:
    """Run every point of the plan not yet in ``out/sweep.csv``; stream rows; draw the heat map.

    ``on_row(row, done)`` is called after each row is written (tests interrupt
    the sweep from there by raising KeyboardInterrupt).  A point whose worker
    is lost (a crash in an FMU, a killed Dask worker) is not recorded: the
    summary counts it and a resume runs it again.  ``point_function``
    replaces ``run_point`` on the local pool (tests).
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
    interrupted, computed, pool, lost, lost_reason, interrupt_status = False, 0, None, 0, "", 0
    if todo:
        try:
            pool = (DaskPool(scheduler, plan) if scheduler else
                    LocalPool(min(jobs or os.cpu_count() or 1, len(todo)), point_function))
        except BaseException:
            sink.close()
            raise
    bar = Progress(len(wanted), f"sweep {plan.scenario.name}", unit="pt", enabled=progress, initial=done_before,
                   dynamic_ncols=True)  # a bar on a terminal, lines elsewhere
    previous_sigterm = _sigterm_as_interrupt()
    try:
        if todo:
            troubled = 0
            for row, error in pool.run([point_task(plan, c, v) for c, v in todo]):
                bar.update(1)
                if error is not None:
                    lost += 1
                    lost_reason = lost_reason or one_line(f"{type(error).__name__}: {error}", 300)
                    bar.set_postfix(not_ok=troubled, lost=lost)
                    continue
                sink.write(row)
                computed += 1
                troubled += row["status"] != "ok"
                if troubled:
                    bar.set_postfix(not_ok=troubled, lost=lost)
                if on_row is not None:
                    on_row(row, computed)
    except KeyboardInterrupt as interrupt:
        interrupted, interrupt_status = True, termination.exit_status(interrupt)
    finally:
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)
        bar.close()
        sink.close()
        if pool is not None:
            pool.close(cancel=interrupted)
    wall_s = clock.perf_counter() - wall_start
    rows = current_rows(plan, read_rows(csv_path, plan.names))
    counts = {c: {s: 0 for s in STATUSES} for c in plan.controllers}
    for row in rows:
        counts[row["controller"]][row["status"]] += 1
    heatmap_path = None
    if plot and rows:
        heatmap_path = plot_heatmap(plan, rows, out / f"heatmap_{plan.metric}.png")
    return SweepSummary(csv_path, heatmap_path, len(wanted), done_before, computed, counts, wall_s,
                        interrupted, pool.describe() if pool else "nothing to run", lost, lost_reason,
                        interrupt_status)


def _sigterm_as_interrupt():
    """SIGTERM stops the sweep as Ctrl-C does (the previous handler, or None off the main thread)."""
    def handler(signum, frame):
        raise termination.Terminated()

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # signals can only be handled in the main thread
        return None


def current_rows(plan: SweepPlan, rows: list) -> list:
    """The rows of the CSV that belong to the plan's points (a CSV may hold more after a grid change)."""
    wanted = {point_key(c, v) for c, v in plan.points()}
    return [row for row in rows if point_key(row["controller"], row["values"]) in wanted]
