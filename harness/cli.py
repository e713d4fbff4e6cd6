"""Command line: ``python -m harness run SCENARIO --controller vud`` (also ``afc-harness``).

The composition root of the harness: it registers every subcommand (``run`` here; each study and
host runner in its own module's ``register(commands)``) and so is the one core module that imports
the studies (harness/studies/) and the host runners (harness/hosts/).
"""
from __future__ import annotations

import argparse
import json
import os
import sys

from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.toolchain import NativeBuildError

from . import cli_args, progress, termination, variants
from . import scenario as scenarios
from .cases import Progress
from .hosts import bench, engines, matrix, ssp
from .cases import ALGORITHMS, simulate_any
from .master import SimulationFailed
from .me_master import ALGORITHM as MODEL_EXCHANGE
from .me_master import DEFAULT_RTOL
from .scores import SCORE_KEYS, score_run, value_text, why_none
from .studies import (compat, hardware_cures, me_accuracy, mutation, regression, robustness, step_study, sweep, tables, tune,
                      work_precision)


def _progress(total: int, description: str, enabled: bool):
    """(callback for the master, close): a bar on a terminal, lines on stderr elsewhere (harness.progress.Progress)."""
    if not enabled:
        return None, lambda: None
    bar = Progress(total, description, unit="step", unit_scale=True, leave=False)

    def update(done, _total):
        bar.update(done - bar.done)

    return update, bar.close


def run_command(args) -> int:
    me = args.algorithm == MODEL_EXCHANGE
    if not me and (args.rtol is not None or args.atol is not None):
        raise cli_args.UsageError(f"--rtol and --atol are tolerances of --algorithm me; --algorithm {args.algorithm} "
                                  "has a communication step (--step)")
    scenario = scenarios.configure(args.scenario, args.controller, args.step, args.stop, hardware=args.hardware)
    cli_args.check_output_interval(args.output_interval, scenario.step)
    if args.out:
        cli_args.check_writable([args.out])
    progress, close = _progress(scenario.steps, f"{scenario.name}/{args.controller}", enabled=not args.json)
    for note in scenario.notes:  # e.g. the stop moved to a whole number of steps
        print(f"note: {note}", file=sys.stderr)
    try:
        result = simulate_any(scenario, args.algorithm, progress=progress,
                              rtol=(args.rtol if args.rtol is not None else DEFAULT_RTOL) if me else None,
                              atol=args.atol if me else None)
    except SimulationFailed as failure:
        close()
        if args.out:
            failure.result.write_csv(args.out, args.output_interval)
            print(f"partial result ({failure.result.rows} rows) written to {args.out}")
        return cli_args.report(failure)
    finally:
        close()  # also when the scenario is refused before the first step
    if not me and scenario.path is not None and scenario.path.parent == scenarios.SCENARIO_DIR:  # one the study covers
        # after the run: a failed run says one line, its error
        warning = step_study.step_warning(scenario.name, args.controller, args.algorithm, scenario.step)
        if warning:
            print(warning, file=sys.stderr)
    if args.out:
        result.write_csv(args.out, args.output_interval)
    scores = score_run(result)
    summary = {"scenario": scenario.name, "controller": args.controller, "step": scenario.step,
               **scores, "wall_s": result.wall_s, "us_per_step": result.us_per_step}
    if me:  # no communication step: the step is the output interval; the integrator's statistics instead
        summary.pop("us_per_step")
        summary.update(algorithm=MODEL_EXCHANGE, output_interval=summary.pop("step"),
                       **{key: value for key, value in result.solver.items() if key != "loop"})
    undefined = {key: why_none(key, scenario.start, scenario.stop) for key in SCORE_KEYS if scores[key] is None}
    if args.json:
        if undefined:  # each null score with its reason
            summary["warnings"] = [f"{key} {value_text(key, None, scenario.start, scenario.stop)}: {reason}"
                                   for key, reason in undefined.items()]
        print(json.dumps(summary))
    else:
        if me:
            solver = result.solver
            print(f"{scenario.name} / {args.controller} (Model Exchange, {solver['integrator']}), rtol "
                  f"{solver['rtol']:g}, atol {solver['atol']:g}: {solver['steps']} steps, "
                  f"{solver['derivative_evaluations']} derivative evaluations ({solver['jacobians']} Jacobians), "
                  f"{solver['state_events']} state events, {result.rows} rows every {scenario.step:g} s in "
                  f"{result.wall_s:.2f} s")
        else:
            print(f"{scenario.name} / {args.controller} ({args.algorithm}), step {scenario.step:g} s, "
                  f"{result.rows - 1} steps in {result.wall_s:.2f} s ({result.us_per_step:.3f} us/step)")
        for key in SCORE_KEYS:
            text = value_text(key, scores[key], scenario.start, scenario.stop)
            if key in undefined:
                text += f" ({undefined[key]})"
            print(f"  {key:8s} {text}")
        if args.out:
            print(f"  result   {args.out}")
    return 0


def register_run(commands):
    run = commands.add_parser("run", help="run one scenario with one controller and score it")
    run.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    run.add_argument("--controller", choices=variants.NAMES, default=variants.PROPOSED)
    run.add_argument("--step", type=cli_args.positive_float,
                     help="communication step in s (default: the scenario's); with --algorithm me the output interval")
    run.add_argument("--stop", type=cli_args.positive_float, help="stop time in s (default: the scenario's)")
    run.add_argument("--hardware", metavar="FILE", type=cli_args.existing_file,
                     help="a TOML file with a [hardware] table: a sensor and an actuator inserted between the plant "
                          "and the controller (docs/master.md, Hardware in the loop)")
    run.add_argument("--algorithm", choices=ALGORITHMS, default="feedthrough",
                     help="feedthrough: no delay along direct-feedthrough chains (default); "
                          "jacobi: every connection delayed one step; me: Model Exchange, no communication step "
                          "(the native edition's FMUs integrated by CVODE; docs/model_exchange.md)")
    run.add_argument("--rtol", type=cli_args.positive_float,
                     help=f"--algorithm me: CVODE's relative tolerance (default {DEFAULT_RTOL:g})")
    run.add_argument("--atol", type=cli_args.positive_float,
                     help="--algorithm me: absolute tolerance, times each state's nominal (default: rtol)")
    run.add_argument("--out", help="write the result CSV here")
    run.add_argument("--output-interval", type=cli_args.positive_float,
                     help="thin the CSV to this interval, a multiple of the step (scores use every step)")
    run.add_argument("--json", action="store_true", help="print one JSON object with the scores")
    run.set_defaults(handler=run_command)


#: every subcommand, in the order of ``--help``: each lives in its own module with a ``register(commands)``
SUBCOMMAND_REGISTRATIONS = (register_run, tables.register, step_study.register, me_accuracy.register,
                            work_precision.register, sweep.register, robustness.register, hardware_cures.register,
                            regression.register, ssp.register, engines.register, bench.register, mutation.register, matrix.register, tune.register,
                            compat.register)


def build_parser() -> argparse.ArgumentParser:
    parser = cli_args.OneLineParser(prog="python -m harness",
                                    description="Co-simulation of the adaptive fuzzy controller FMUs")
    commands = parser.add_subparsers(dest="command", required=True)
    for register in SUBCOMMAND_REGISTRATIONS:
        register(commands)
    for name, command in commands.choices.items():
        add_edition_argument(command, fmi3=name not in SSP_ENGINE_COMMANDS)
    return parser


# commands that hand the FMUs to SSP engines (Ecos, fmpy.ssp, libcosim), which load FMI 2.0 only
SSP_ENGINE_COMMANDS = ("export-ssp", "compare-engines", "hosts")


def add_edition_argument(parser: argparse.ArgumentParser, fmi3: bool = True) -> None:
    """``--edition``: which FMUs the command runs (one option, shared by every command);
    ``fmi3=False`` leaves out native3 (the SSP engines take FMI 2.0 FMUs)."""
    parser.add_argument("--edition", choices=fmu_catalog.EDITIONS if fmi3 else ("python", "native"),
                        default=None,
                        help="python: the pythonfmu FMUs (reference edition); native: the C FMUs, FMI 2.0"
                             + ("; native3: the C FMUs, FMI 3.0 (our master only; docs/native.md)" if fmi3 else
                                " (the SSP engines take FMI 2.0 FMUs: no native3 here)")
                             + "; default: $AFC_EDITION, else python")


def apply_edition(args):
    """Select the edition for this command and the worker processes it starts; returns an undo."""
    name = fmu_catalog.EDITION_VARIABLE
    before = os.environ.get(name)
    if getattr(args, "edition", None):
        os.environ[name] = args.edition

    def undo():
        if before is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = before
    return undo


def main(argv=None) -> int:
    """Run one subcommand; any error becomes one line on stderr (exit 2: usage, 1: the run failed, 130: Ctrl-C,
    143: SIGTERM)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # a usage error (one line already printed) or --help
        return done.code if isinstance(done.code, int) else cli_args.USAGE_EXIT
    undo = apply_edition(args)
    # the command line's own process counts its first progress line from its start; a call from Python from now
    progress.command_began(progress.process_started() if argv is None else None)
    try:
        if args.command in SSP_ENGINE_COMMANDS and os.environ.get(fmu_catalog.EDITION_VARIABLE) == "native3":
            print(f"error: {fmu_catalog.EDITION_VARIABLE}=native3: {args.command} hands the FMUs to SSP engines, "
                  "which take FMI 2.0 FMUs; use --edition native", file=sys.stderr)
            return cli_args.USAGE_EXIT
        with termination.sigterm_as_interrupt():  # SIGTERM stops a command as Ctrl-C does, workers and all
            return args.handler(args)
    except KeyboardInterrupt as interrupt:  # Ctrl-C, or SIGTERM (termination.Terminated)
        print("error: terminated (SIGTERM)" if isinstance(interrupt, termination.Terminated) else "error: interrupted",
              file=sys.stderr)
        return termination.exit_status(interrupt)
    except Exception as error:  # noqa: BLE001 - the last resort: no traceback reaches a user
        status = cli_args.report(error)
        return cli_args.USAGE_EXIT if isinstance(error, NativeBuildError) else status
    finally:
        progress.command_ended()
        undo()
