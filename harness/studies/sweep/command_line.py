"""``python -m harness sweep SCENARIO --grid NAME=START:STOP:N ...``: its options, what it prints,
and ``--apply`` (the sweep's CSV and heat map copied into docs/)."""
from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from ... import cli_args, variants
from ...scenario import ScenarioError
from ...scores import SCORE_KEYS, undefined_reason
from .csv_rows import CSV_NAME, SETTINGS_NAME, read_rows
from .grid import SCENARIO_SETTINGS, parse_grid, plan_sweep
from .run import SweepSummary, current_rows, run_sweep

DOCS_DIR = Path(__file__).resolve().parents[3] / "docs"  # where --apply copies a sweep's CSV and heat map


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
    if summary.scheduler_lost:
        missing = summary.total - summary.done_before - summary.computed - summary.lost
        print(f"error: {summary.scheduler_lost}: {missing} point(s) not run, the finished ones are in "
              f"{summary.csv_path}; run the same command to resume", file=sys.stderr)
    if args.apply and not (summary.interrupted or summary.lost or summary.scheduler_lost):
        for path in apply_to_docs(plan, summary):
            print(f"  applied  {path}")
    if summary.interrupted:
        return summary.interrupt_status
    return cli_args.FAILED_EXIT if summary.lost or summary.scheduler_lost else 0


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
