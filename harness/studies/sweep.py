"""Parameter sweeps: ``python -m harness sweep SCENARIO --grid NAME=START:STOP:N ...``.

The cartesian product of the grids (any parameter of any instance, or the
communication ``step`` / the ``stop`` time) times the chosen controllers,
one co-simulation per point, on a local process pool (default: every core)
or on an existing ``dask.distributed`` scheduler (``--scheduler ADDRESS``).

Rows stream to ``DIR/sweep.csv`` as points finish: the controller, the grid
values, every score of docs/model.md section 9 (scores), the wall time of the point, its status
(``ok``, ``diverged``, ``failed``) and the reason.  Run the same command again
after an interruption: points already in the CSV (same controller and grid
values) are skipped.  ``DIR/sweep.json`` holds the settings of the sweep
(scenario, horizon, step, fixed parameters) so a resume with different
settings is refused rather than mixed in.  At the end ``DIR/heatmap_METRIC.png``
shows the metric over the first two grid axes, one panel per controller.

Grid values must be bit-identical wherever the point runs: the parent computes
them, hands them over as Python floats and writes them with ``repr``; workers
run the same FMU files (a Dask worker receives their bytes from the client and
caches them by content hash), so a point gives the same scores on any host.

This module holds the command and the loop that streams rows; the grid and plan are in
``sweep_grid``, the CSV in ``sweep_csv``, the pools in ``sweep_executors``, the heat map
in ``sweep_heatmap``.
"""
from __future__ import annotations

import json
import math
import os
import shutil
import signal
import sys
import time as clock
from dataclasses import dataclass
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from .. import cli_args, termination, variants
from ..cases import STATUSES, Progress, one_line
from ..scenario import ScenarioError
from ..scores import SCORE_KEYS, undefined_reason
from .sweep_csv import CSV_NAME, SETTINGS_NAME, CsvSink, check_settings, read_rows
from .sweep_executors import DaskPool, LocalPool, point_task
from .sweep_grid import SCENARIO_SETTINGS, SweepPlan, parse_grid, plan_sweep, point_key
from .sweep_heatmap import plot_heatmap

DOCS_DIR = Path(__file__).resolve().parents[2] / "docs"  # where --apply copies a sweep's CSV and heat map


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




# --------------------------------------------------------------------- CLI
def sweep_command(args) -> int:
    grids = [parse_grid(text) for text in args.grid]
    controllers = variants.NAMES if args.controller == "all" else (args.controller,)
    plan = plan_sweep(args.scenario, controllers, grids, metric=args.metric, stop=args.stop, step=args.step,
                      algorithm=args.algorithm, fmu_paths=build_fmu.ensure_built())
    out = Path(args.out) if args.out else Path("build") / "sweeps" / plan.scenario.name
    if args.jobs is not None and args.jobs < 1:
        raise ScenarioError(f"--jobs {args.jobs}: need at least 1")
    cli_args.refuse_tracked([out / CSV_NAME, out / SETTINGS_NAME, out / f"heatmap_{plan.metric}.png"])
    parameters = [g for g in plan.grids if "." in g.name]
    for pick in (min, max):  # valid ranges are intervals: the ends of each axis decide
        cli_args.check_assignments(plan.scenario, [(g.name, pick(g.values)) for g in parameters],
                                   plan_fmu_paths(plan), option="--grid")
    shortest = min(plan.grids[plan.names.index("stop")].values) if "stop" in plan.names else plan.scenario.stop
    short = undefined_reason("es1_pct", plan.scenario.start, shortest)
    if short is not None:
        print(f"warning: es1_pct and es2_pct are empty in the rows with stop {shortest:g} s: {short}", file=sys.stderr)
    total = len(plan.points())
    fixed = ", ".join(f"{name} {getattr(plan.scenario, name):g} s" for name in SCENARIO_SETTINGS
                      if name not in plan.names)  # a grid axis has no single value
    print(f"sweep {plan.scenario.name}: {' x '.join(f'{g.name} ({len(g)})' for g in plan.grids)} x "
          f"{len(controllers)} controller{'s' if len(controllers) > 1 else ''} = {total} points"
          + (f", {fixed}" if fixed else "") + f" -> {out}", file=sys.stderr)
    summary = run_sweep(plan, out, jobs=args.jobs, scheduler=args.scheduler,
                        progress=not args.no_progress)
    print(f"{summary.computed} points computed ({summary.executor}) in {summary.wall_s:.1f} s, "
          f"{summary.done_before} already done" + (", INTERRUPTED: run the same command to resume"
                                                     if summary.interrupted else ""))
    rows = current_rows(plan, read_rows(summary.csv_path, plan.names))
    for controller in controllers:
        values = sorted(r["scores"][plan.metric] for r in rows if r["controller"] == controller
                        and r["status"] == "ok" and math.isfinite(r["scores"][plan.metric]))
        counts = summary.counts[controller]
        spread = (f"; {plan.metric} min {values[0]:.4g}, median {values[len(values) // 2]:.4g}, max {values[-1]:.4g}"
                  if values else "")
        print(f"  {controller:5s} ok {counts['ok']}, diverged {counts['diverged']}, failed {counts['failed']} "
              f"of {total // len(controllers)}{spread}")
    print(f"  rows     {summary.csv_path}")
    if summary.heatmap_path:
        print(f"  heat map {summary.heatmap_path}")
    if summary.lost:
        print(f"error: {summary.lost} point(s) not run, their worker was lost ({summary.lost_reason}); "
              "run the same command to retry them", file=sys.stderr)
    if args.apply and not (summary.interrupted or summary.lost):
        for path in apply_to_docs(plan, summary):
            print(f"  applied  {path}")
    return summary.interrupt_status if summary.interrupted else 1 if summary.lost else 0


def plan_fmu_paths(plan: SweepPlan) -> dict:
    """{model identifier or file: path} of the plan's FMUs, as ``resolve_fmu`` takes them."""
    return {plan.scenario.components[instance].fmu: path for instance, path in plan.fmu_files.items()}


def apply_to_docs(plan: SweepPlan, summary: SweepSummary) -> list:
    """Copy the sweep's CSV and heat map into docs/ as docs/sweep_SCENARIO_AXES.csv and ..._METRIC.png."""
    axes = "_".join(name.rpartition(".")[2].split("_")[0] for name in plan.names)  # plant.dist_gain -> dist
    stem = DOCS_DIR / f"sweep_{plan.scenario.name}_{axes}"
    written = [shutil.copyfile(summary.csv_path, stem.with_name(stem.name + ".csv"))]
    if summary.heatmap_path:
        written.append(shutil.copyfile(summary.heatmap_path, stem.with_name(f"{stem.name}_{plan.metric}.png")))
    return [Path(path) for path in written]


def register(commands):
    sweep = commands.add_parser(
        "sweep", help="run a scenario over a grid of parameters (process pool or Dask) and draw heat maps",
        description="One co-simulation per point of the cartesian product of the grids, for each controller. "
                    "Rows stream to OUT/sweep.csv; rerun the same command to resume an interrupted sweep.")
    sweep.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    sweep.add_argument("--controller", choices=(*variants.NAMES, "all"), default=variants.PROPOSED)
    sweep.add_argument("--grid", action="append", required=True, metavar="NAME=START:STOP:N",
                       help="a grid axis: instance.parameter (e.g. plant.mp, controller.kappa1), step or stop; "
                            "N evenly spaced values from START to STOP, START:STOP:N:log for geometric spacing, "
                            "or V1,V2,... (repeat --grid for more axes; the heat map uses the first two)")
    sweep.add_argument("--metric", default="ITAE", choices=SCORE_KEYS, help="the score of the heat map (ITAE)")
    sweep.add_argument("--stop", type=cli_args.positive_float, help="stop time in s (default: the scenario's)")
    sweep.add_argument("--step", type=cli_args.positive_float, help="communication step in s (default: the scenario's)")
    sweep.add_argument("--algorithm", choices=("feedthrough", "jacobi"), default="feedthrough")
    sweep.add_argument("--out", help="output directory (default: build/sweeps/SCENARIO, ignored by git)")
    sweep.add_argument("--apply", action="store_true",
                       help="also copy the CSV and the heat map into docs/ as sweep_SCENARIO_AXES.csv and "
                            "sweep_SCENARIO_AXES_METRIC.png (the README's examples)")
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=cli_args.positive_int, help="local worker processes (default: every core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the points on this dask.distributed scheduler (e.g. tcp://host:8786)")
    sweep.add_argument("--no-progress", action="store_true",
                       help="no progress on stderr (a bar on a terminal, else a line per point at most every 5 s)")
    sweep.set_defaults(handler=sweep_command)
