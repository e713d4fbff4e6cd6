"""The command line: ``python -m harness tune`` (its options, ``--bench``, ``--compare``) and what it
prints."""
from __future__ import annotations

import argparse
import copy
import importlib
import json
import os
import re
import sys
import tempfile
import time as clock
from pathlib import Path

from harness.fmu_build import toolchain as c_toolchain
from harness.fmu_build import catalog as fmu_catalog

from ... import cli_args, variants
from ... import scenario as scenarios
from ...cases import default_jobs
from ...scores import SCORE_KEYS
from .comparison import compare_rows, overall_verdicts, verdicts_for
from .config import DEFAULT_OUT, DEFAULT_TRIALS, SAMPLERS, VERIFY_TOLERANCE, TuneConfig, prepare
from .errors import TuneError
from .objective import ROBUST_GRIDS, Constraint, parse_constraint, parse_vary, score_name
from .report import comparison_markdown, number_text, write_report
from .space import parse_range
from .storage import check_existing
from .study import study_outputs, tune

NEEDS = (("optuna", "Optuna"), ("tomlkit", "tomlkit"))  # (module, name) of what the tune extra brings
TUNE_EXTRA = "optuna, optuna-dashboard, cmaes, tomlkit"  # pyproject.toml's tune extra


def default_edition() -> str:
    """$AFC_EDITION if set, else native when zig's C compiler is there to build it, else python."""
    chosen = os.environ.get(fmu_catalog.EDITION_VARIABLE)
    if chosen:
        return chosen
    return "native" if c_toolchain.compiler_available() else "python"


def _config_from(args, scenario, controller: str, out: Path) -> TuneConfig:
    return TuneConfig(scenario=scenario, controller=controller, objective=args.objective,
                      constraints=tuple(args.constraint or ()), trials=args.trials, seed=args.seed,
                      storage=args.storage, study=args.study, sampler=args.sampler,
                      jobs=args.jobs or default_jobs(), scheduler=args.scheduler, stop=args.stop, edition=args.edition or default_edition(),
                      robust=args.robust, vary=tuple(args.vary or ()), params=tuple(args.params or ()),
                      ranges=tuple(args.range or ()), out=out, tolerance=args.verify_tolerance / 100.0,
                      held_out=tuple(args.held_out) if args.held_out is not None else None)


def bench(args) -> int:
    """``--bench``: the trials of one study in a scratch database; prints trials per second."""
    scenario = args.scenarios[0]
    with tempfile.TemporaryDirectory(prefix="afc_tune_bench_") as scratch:
        config = _config_from(args, scenario, args.controller, Path(scratch))
        config.storage = f"sqlite:///{Path(scratch) / 'bench.db'}"
        prepare(config)  # usage errors first; builds the FMUs (not timed)
        began = clock.perf_counter()
        summary = tune(config, outputs=False)
        wall = clock.perf_counter() - began
    run = summary["run"]
    best = summary.get("best")
    target = "met" if run["ran"] >= 200 and wall <= 60.0 else "not met"
    print(f"bench: {run['ran']} trials of {summary['scenario']}/{config.controller} ({summary['stop']:g} s horizon, "
          f"step {summary['step']:g} s, {config.edition} edition) in {wall:.1f} s wall on {config.jobs} "
          f"process(es): {run['ran'] / wall:.2f} trials/s, {run['simulated_s'] / max(run['ran'], 1):.3f} s of "
          f"co-simulation per trial; best {summary['objective']} "
          f"{number_text(best['value']) if best else 'n/a'} (#{best['number'] if best else '-'}); "
          f"target 200 trials within 60 s: {target}")
    return 0


def compare_command(args, out: Path, log) -> int:
    """``--compare``: vud, fixed and fae (the paper's variants) tuned with the same budget on each scenario,
    ``--repeats`` seeds."""
    controllers = variants.PAPER
    objective = score_name(args.objective)
    seeds = [args.seed + r for r in range(args.repeats)]
    plan = []
    for name in args.scenarios:
        scenario_name = scenarios.load(name).name
        for seed in seeds:
            for controller in controllers:
                config = _config_from(args, name, controller, out)
                config.seed = seed  # the study of each seed is the one a plain `tune --seed` makes
                plan.append((scenario_name, seed, config))
    outputs = [out / "comparison.json"]
    for _, _, config in plan:  # every usage error (and a study of the same name made otherwise) before any trial
        prepared = prepare(copy.copy(config))
        check_existing(prepared)
        outputs += study_outputs(prepared)
    cli_args.check_writable(outputs)
    summaries = [(scenario_name, seed, tune(config, log)) for scenario_name, seed, config in plan]
    comparison = {"trials": args.trials, "seeds": seeds, "sampler": args.sampler, "objective": objective,
                  "constraints": [c.text for c in prepare(copy.copy(plan[0][2])).constraints], "scenarios": {}}
    for name in args.scenarios:
        scenario = scenarios.load(name)
        order = int(scenario.components[scenario.controller_instance].parameters.get("order", 2))
        repeats = []
        for seed in seeds:
            rows = compare_rows([s for n, sd, s in summaries if n == scenario.name and sd == seed])
            repeats.append({"seed": seed, "rows": rows,
                            "verdicts": verdicts_for(scenario.name, order, rows, objective)})
        comparison["scenarios"][scenario.name] = {
            "order": order, "repeats": repeats,
            "overall": overall_verdicts(scenario.name, order, repeats, objective) if len(seeds) > 1 else []}
    (out / "comparison.json").write_text(json.dumps(comparison, indent=1, default=str))
    report = write_report(out)
    print(comparison_markdown(comparison))
    print(f"report: {report}")
    return 0


def tune_command(args) -> int:
    for module, name in NEEDS:
        try:
            importlib.import_module(module)  # optional: the tune extra
        except ImportError:
            raise TuneError(f"tune needs {name}: pip install -e '.[tune]' ({TUNE_EXTRA})") from None
    log = None if args.quiet else (lambda line: print(line, file=sys.stderr, flush=True))
    if args.bench:
        if len(args.scenarios) != 1 or args.compare:
            raise TuneError("--bench takes one scenario and no --compare")
        return bench(args)
    if not args.compare and len(args.scenarios) != 1:
        raise TuneError(f"give one scenario (or --compare for the equal-effort comparison of several); got "
                        f"{len(args.scenarios)}")
    out = Path(args.out)
    if args.compare:
        if args.study:
            raise TuneError("--compare names its studies itself: drop --study")
        return compare_command(args, out, log)
    if args.repeats != 1:
        raise TuneError("--repeats is for --compare")
    config = _config_from(args, args.scenarios[0], args.controller, out)
    summary = tune(config, log)
    best = summary.get("best")
    if best is None:
        print(f"study {summary['study']}: no trial finished complete, feasible and verified at half the step "
              f"({summary['counts']}); report: {out / 'report.md'}")
        return cli_args.FAILED_EXIT
    start = summary.get("start")
    print(f"study {summary['study']}: best {summary['objective']} {best['value']!r} (trial #{best['number']}"
          + (f"; starting parameters {start['value']:.6g}" if start else "") + f"), {summary['finished']} trials "
          f"finished ({', '.join(f'{v} {k}' for k, v in sorted(summary['counts'].items()))})")
    print(f"  scenario file {summary['study_file']}  (python -m harness run {summary['study_file']} --controller "
          f"{config.controller} --edition {config.edition})")
    print(f"  report {out / 'report.md'}; dashboard: optuna-dashboard {summary['dashboard']}"
          + ("  (the password from PGPASSWORD or ~/.pgpass)" if summary["storage"] != summary["dashboard"] else ""))
    return 0


def _without_option(error) -> str:
    """The message without its leading "--option 'text': " (argparse names the option itself)."""
    return re.sub(r"^--[\w-]+ '[^']*': ", "", str(error))


def _range_argument(text: str) -> tuple:
    try:
        return parse_range(text)
    except TuneError as error:
        raise argparse.ArgumentTypeError(_without_option(error)) from None


def _score_argument(text: str) -> str:
    try:
        return score_name(text)
    except TuneError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _constraint_argument(text: str) -> Constraint:
    try:
        return parse_constraint(text)
    except TuneError as error:
        raise argparse.ArgumentTypeError(_without_option(error)) from None


def _vary_argument(text: str) -> tuple:
    try:
        return parse_vary(text)
    except TuneError as error:
        raise argparse.ArgumentTypeError(_without_option(error)) from None


def _params_argument(text: str) -> list:
    return [name.strip() for name in text.split(",") if name.strip()]


def register(commands):
    command = commands.add_parser("tune", help="tune the controller's design parameters for a scenario (Optuna; "
                                               "docs/tuning.md)")
    command.add_argument("scenarios", nargs="+", metavar="SCENARIO", type=cli_args.scenario,
                         help=cli_args.scenario_help() + "; several with --compare")
    command.add_argument("--controller", choices=variants.NAMES, default="vud")
    command.add_argument("--objective", type=_score_argument, default="ITAE",
                         help=f"the score to minimise (default ITAE; {', '.join(SCORE_KEYS)})")
    command.add_argument("--constraint", action="append", type=_constraint_argument, metavar="SCORE<=LIMIT",
                         help="a score limit every reported candidate meets, e.g. \"umax<=20\" (repeatable)")
    command.add_argument("--trials", type=cli_args.positive_int, default=DEFAULT_TRIALS,
                         help=f"finished trials the study should hold (default {DEFAULT_TRIALS}); a resumed study "
                              "adds only the missing ones")
    command.add_argument("--seed", type=cli_args.non_negative_int, default=0,
                         help="sampler seed (default 0): the same seed gives the same trials (module text)")
    command.add_argument("--sampler", choices=SAMPLERS, default="tpe", help="Optuna sampler (default tpe)")
    command.add_argument("--storage", metavar="URL",
                         help="Optuna RDB storage URL (default sqlite:///OUT/SCENARIO.db); several tune "
                              "processes may share one")
    command.add_argument("--study", metavar="NAME",
                         help="study name (default SCENARIO-CONTROLLER-OBJECTIVE[-CONSTRAINTS][-robust])")
    where = command.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the trials on this dask.distributed scheduler's workers (e.g. tcp://host:8786); "
                            "the study stays in --storage (docs/tuning.md, on a cluster)")
    command.add_argument("--stop", type=cli_args.positive_float, help="stop time in s (default: the scenario's)")
    command.add_argument("--robust", action="store_true",
                         help="score each candidate's worst case over a grid of plant variations (default grid of "
                              f"the plant FMU: {', '.join(ROBUST_GRIDS)}; or --vary)")
    command.add_argument("--vary", action="append", type=_vary_argument, metavar="INSTANCE.PARAMETER=V1,V2",
                         help="a plant variation axis of the robust grid (numbers or xF), e.g. plant.mp=0.1,1 "
                              "(repeatable; implies --robust)")
    command.add_argument("--params", type=_params_argument, metavar="NAME,NAME",
                         help="search only these parameters (default: every tunable one that acts)")
    command.add_argument("--range", action="append", type=_range_argument, metavar="NAME=LOW:HIGH",
                         help="replace a parameter's declared search range (its scale stays; repeatable)")
    command.add_argument("--verify-tolerance", type=cli_args.positive_float, default=100 * VERIFY_TOLERANCE,
                         metavar="PERCENT", help="a best candidate whose objective moves by more at half the "
                                                 "step is pruned (default 1)")
    command.add_argument("--held-out", nargs="*", metavar="SCENARIO", type=cli_args.scenario,
                         help="scenarios to compare tuned and starting parameters on (default: pendulum_case2, 3 "
                              "for pendulum_case1)")
    command.add_argument("--compare", action="store_true",
                         help="the equal-effort comparison: tune vud, fixed and fae on each SCENARIO with the same "
                              "budget and report the paper's claims re-checked")
    command.add_argument("--repeats", type=cli_args.positive_int, default=1,
                         help="--compare: run every study with this many seeds (SEED, SEED+1, ...; default 1)")
    command.add_argument("--bench", action="store_true",
                         help="time the study in a scratch database (no outputs): trials per second")
    command.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/)")
    command.add_argument("--quiet", action="store_true", help="no progress line per trial")
    command.set_defaults(handler=tune_command)
