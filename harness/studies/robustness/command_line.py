"""``python -m harness robustness SCENARIO --samples N --param NAME=KIND:VALUES ...``: its options and
what it prints (the summary of harness/studies/robustness/statistics.py and influence.py)."""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from ... import cli_args, variants
from ...scenario import ScenarioError
from ...scores import SCORE_KEYS
from .distributions import KINDS, combine, load_file, parse_param
from .draws import SAMPLERS
from .plan import plan_study
from .rows import CSV_NAME, SETTINGS_NAME
from .run import DEFAULT_SCORES, SUMMARY_NAME, run_study
from .spec import parse_spec

SCIPY_EXTRA = "pip install -e '.[robustness]'"
DOCS_DIR = Path(__file__).resolve().parents[3] / "docs"  # where --apply copies a study's summary and figure


def apply_to_docs(plan, outcome) -> list:
    """Copy the summary and the figure into docs/ as robustness_SCENARIO.json and robustness_SCENARIO_OBJECTIVE.png."""
    stem = DOCS_DIR / f"robustness_{plan.scenario.name}"
    written = [shutil.copyfile(outcome.summary_path, stem.with_suffix(".json"))]
    if outcome.figure_path:
        written.append(shutil.copyfile(outcome.figure_path, stem.with_name(f"{stem.name}_{plan.objective}.png")))
    return [Path(path) for path in written]


def _check_extra() -> None:
    import importlib.util

    missing = [name for name in ("scipy", "SALib") if importlib.util.find_spec(name) is None]
    if missing:
        raise cli_args.UsageError(f"robustness needs {' and '.join(missing)}, in the robustness extra: {SCIPY_EXTRA}")


def _interval(entry, digits: int = 3, percent: bool = False) -> str:
    if entry is None:
        return "-"
    if percent:
        return (f"{100 * entry['share']:.{digits - 2}f} % [{100 * entry['low']:.{digits - 2}f}, "
                f"{100 * entry['high']:.{digits - 2}f}] ({entry['count']}/{entry['total']})")
    low, high = entry.get("low"), entry.get("high")
    return f"{entry['value']:.{digits}g}" + (f" [{low:.{digits}g}, {high:.{digits}g}]" if low is not None else "")


def summary_lines(summary: dict) -> list:
    """The summary as the command prints it."""
    lines = [f"{summary['samples']} samples of {summary['scenario']} ({summary['sampler']}, seed {summary['seed']}); "
             "95 % intervals: Wilson for shares, bootstrap for quantiles and differences"]
    for controller, entry in summary["controllers"].items():
        lines.append(f"  {controller}: {entry['ok']} of {entry['runs']} completed, {entry['failed']} failed")
        lines.append(f"    diverged   {_interval(entry['diverged'], percent=True)}")
        lines.append(f"    chattered  {_interval(entry['chattered'], percent=True)}")
        if entry["spec"] is not None:
            lines.append(f"    meets {summary['spec']}  {_interval(entry['spec'], percent=True)}")
        for score, values in entry["scores"].items():
            if values["n"]:
                lines.append(f"    {score:8s} median {_interval(values['median'])}, 5 % {_interval(values['q05'])}, "
                             f"95 % {_interval(values['q95'])}")
        ranking = summary["influence"][controller]
        if "ranking" in ranking:
            lines.append("    influence on " + summary["objective"] + " (RBD-FAST S1): " + ", ".join(
                f"{e['name']} {e['S1']:.2f}+-{e['S1_conf']:.2f}" for e in ranking["ranking"]))
        else:
            lines.append(f"    influence: {ranking['reason']}")
    for pair in summary["paired"]:
        if pair["paired"]:
            lines.append(f"  {pair['a']} - {pair['b']} ({pair['objective']}, {pair['paired']} paired samples): "
                         f"median {_interval(pair['median'])}, mean {_interval(pair['mean'])}; "
                         f"{pair['a']} lower in {_interval(pair['a_lower'], percent=True)}: {pair['verdict']}")
        else:
            lines.append(f"  {pair['a']} - {pair['b']}: no sample completed by both")
    return lines


def robustness_command(args) -> int:
    _check_extra()
    spec = parse_spec(args.spec) if args.spec else None
    from_file = load_file(args.distributions) if args.distributions else []
    distributions = combine(from_file, [parse_param(text) for text in args.param])
    if args.jobs is not None and args.jobs < 1:
        raise ScenarioError(f"--jobs {args.jobs}: need at least 1")
    scores = tuple(dict.fromkeys((*DEFAULT_SCORES, *(b.score for b in spec.bounds)) if spec else DEFAULT_SCORES))
    controllers = variants.PAPER if args.controller == "all" else (args.controller,)
    plan = plan_study(args.scenario, controllers, distributions, args.samples, sampler=args.sampler, seed=args.seed,
                      objective=args.objective, stop=args.stop, step=args.step, algorithm=args.algorithm,
                      fmu_paths=build_fmu.ensure_built())
    out = Path(args.out) if args.out else Path("build") / "robustness" / plan.scenario.name
    cli_args.refuse_tracked([out / CSV_NAME, out / SETTINGS_NAME, out / SUMMARY_NAME,
                             out / f"robustness_{plan.objective}.png"])
    drawn = ", ".join(d.text() for d in plan.distributions)
    noise = f"; the noise seed {plan.seed_parameter} drawn per sample" if plan.seed_parameter else ""
    print(f"robustness {plan.scenario.name}: {plan.samples} samples x {len(plan.controllers)} controllers "
          f"({', '.join(plan.controllers)}), {plan.scenario.stop - plan.scenario.start:g} s at step "
          f"{plan.scenario.step:g} s; {drawn}{noise} -> {out}", file=sys.stderr)
    outcome = run_study(plan, out, jobs=args.jobs, scheduler=args.scheduler, batch=args.batch, spec=spec,
                        scores=scores, progress=not args.no_progress)
    print(f"{outcome.computed} runs computed ({outcome.executor}) in {outcome.wall_s:.1f} s, "
          f"{outcome.done_before} already done" + (", INTERRUPTED: run the same command to resume"
                                                   if outcome.interrupted else ""))
    speed = outcome.speed()
    if "wall_ratio" in speed:
        cpu = (f"; CPU {speed['process_cpu_s']:.1f} s (this process and its workers) against the loops' "
               f"{speed['loop_cpu_s']:.1f} s: {speed['cpu_ratio']:.2f}x" if "cpu_ratio" in speed else "")
        print(f"  speed: {speed['runs']} runs, their loops {speed['loop_s']:.1f} s over {speed['slots']} slots: "
              f"wall time {speed['wall_ratio']:.2f}x the loops'{cpu}; a run's own CPU {speed['run_cpu_ratio']:.2f}x "
              "its loop's")
    if outcome.summary:
        print("\n".join(summary_lines(outcome.summary)))
    print(f"  rows     {outcome.csv_path}")
    if outcome.summary_path:
        print(f"  summary  {outcome.summary_path}")
    if outcome.figure_path:
        print(f"  figure   {outcome.figure_path}")
    if args.apply and outcome.summary_path and not (outcome.interrupted or outcome.lost or outcome.scheduler_lost):
        for path in apply_to_docs(plan, outcome):
            print(f"  applied  {path}")
    if outcome.lost:
        print(f"error: {outcome.lost} run(s) not done, their worker was lost or their task failed "
              f"({outcome.lost_reason}); run the same command to retry them", file=sys.stderr)
    if outcome.scheduler_lost:
        missing = outcome.total - outcome.done_before - outcome.computed - outcome.lost
        print(f"error: {outcome.scheduler_lost}: {missing} run(s) not done, the finished ones are in "
              f"{outcome.csv_path}; run the same command to resume", file=sys.stderr)
    if outcome.interrupted:
        return outcome.interrupt_status
    return cli_args.FAILED_EXIT if outcome.lost or outcome.scheduler_lost else 0


def register(commands):
    study = commands.add_parser(
        "robustness", help="a Monte Carlo study: the controllers over random plant parameters and noise seeds",
        description="Every controller on the same draws of the uncertain parameters (scipy.stats.qmc), rows "
                    "streamed to OUT/robustness.csv (rerun the same command to resume), a summary with 95 % "
                    "intervals, the parameters ranked by influence (SALib RBD-FAST) and a figure.")
    study.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    study.add_argument("--samples", type=cli_args.positive_int, required=True,
                       help="samples of the uncertain parameters (each run with every controller)")
    study.add_argument("--param", action="append", default=[], metavar="NAME=KIND:VALUES",
                       help="an uncertain parameter instance.parameter and its distribution: "
                            + ", ".join(f"{kind}:{':'.join(keys).upper()}" for kind, keys in KINDS.items())
                            + " (e.g. plant.mp=loguniform:0.05:2; repeat for more)")
    study.add_argument("--distributions", type=cli_args.existing_file, metavar="FILE",
                       help="a TOML file with a table per parameter: [\"plant.mp\"] distribution = \"loguniform\", "
                            "low = 0.05, high = 2.0")
    study.add_argument("--sampler", choices=SAMPLERS, default="sobol",
                       help="the design: a scrambled Sobol' sequence (default; a study can grow) or a Latin hypercube")
    study.add_argument("--seed", type=cli_args.non_negative_int, default=0, help="the design's and the noise seeds' seed")
    study.add_argument("--controller", choices=(*variants.PAPER, "all"), default="all")
    study.add_argument("--objective", choices=SCORE_KEYS, default="ITAE",
                       help="the score of the figure, the paired differences and the influence ranking (ITAE)")
    study.add_argument("--spec", metavar="BOUNDS", help='a specification, e.g. "ITAE<0.6,umax<50": the probability '
                                                        "of meeting it per controller")
    study.add_argument("--stop", type=cli_args.positive_float, help="stop time in s (default: the scenario's)")
    study.add_argument("--step", type=cli_args.positive_float, help="communication step in s (default: the scenario's)")
    study.add_argument("--algorithm", choices=("feedthrough", "jacobi"), default="feedthrough")
    study.add_argument("--batch", type=cli_args.positive_int, default=4,
                       help="runs per task (4; more on a Dask cluster: a task's own cost is paid once per batch)")
    study.add_argument("--out", help="output directory (default: build/robustness/SCENARIO, ignored by git)")
    study.add_argument("--apply", action="store_true",
                       help="also copy the summary and the figure into docs/ as robustness_SCENARIO.json and "
                            "robustness_SCENARIO_OBJECTIVE.png (docs/studies.md's example)")
    where = study.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=cli_args.positive_int, help="local worker processes (default: every core)")
    where.add_argument("--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler (tcp://host:8786)")
    study.add_argument("--no-progress", action="store_true",
                       help="no progress on stderr (a bar on a terminal, else a line at most every 5 s, with the time left)")
    study.set_defaults(handler=robustness_command)
