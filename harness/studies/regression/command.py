"""``python -m harness regress``: run the cases, compare them with their references, write the reports.

* the cases: the built-in scenarios x the three controllers, or a user's scenario files (their plant
  FMU, our controller: ``regress my_loop.toml``), run in a process pool (:mod:`.runs`);
* each compared with its reference inside the tube (:mod:`.comparison`); a missing reference fails
  (``--update`` creates it); references are written only by ``--update`` (:mod:`.references`);
* the reports go to ``--report DIR`` (default results/regression/), JUnit XML to ``--junit FILE``
  (:mod:`.report`); the exit code is 1 if anything failed, 2 for a usage error.
"""
from __future__ import annotations

import os
import shlex
import sys
import time as clock
from dataclasses import dataclass
from pathlib import Path

from ... import cli_args, variants
from ... import scenario as scenarios
from .comparison import compare_case
from .references import (DEFAULT_TOLERANCES, read_reference, reference_directory, reference_tolerances, relative,
                         write_reference)
from .report import SUMMARY_HEADER, markdown_table, slowness, summary_rows, write_junit, write_report
from .runs import all_cases, case_signals, run_cases

DEFAULT_REPORT_DIR = Path("results") / "regression"  # in the working directory, like tables' results/


@dataclass
class Outcome:
    comparisons: list
    runs: list
    report: Path | None  # report.md (report.html beside it)
    written: list  # reference files written by --update
    junit: Path | None = None

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.comparisons)

    @property
    def html(self) -> Path | None:
        return self.report.with_name("report.html") if self.report else None


def regress(cases, update: bool = False, report_dir=DEFAULT_REPORT_DIR, tolerances: dict | None = None,
            workers: int | None = None, reference_dir: Path | None = None, fmu_paths: dict | None = None,
            runs: list | None = None, junit: Path | None = None) -> Outcome:
    """Run (or reuse ``runs``), compare with the references, write the reports; ``update`` rewrites them.

    ``tolerances``: those given on the command line (they override the references' own and the defaults).
    ``reference_dir`` None: the references of the cases' algorithm (:func:`reference_directory`).
    """
    if reference_dir is None:
        algorithms = {case.algorithm for case in (cases if runs is None else [run.case for run in runs])}
        reference_dir = reference_directory(algorithms.pop() if len(algorithms) == 1 else "feedthrough")
    reference_dir = Path(reference_dir)
    given = dict(tolerances or {})
    if update and any(case.overrides for case in cases):
        raise ValueError("--update with parameter overrides: a mutated run never becomes a reference")
    cases = [run.case for run in runs] if runs is not None else list(cases)
    references = [read_reference(case, reference_dir) for case in cases]
    for case, reference in zip(cases, references):  # a mistake in a reference's metadata: one line before any run
        if reference is not None:
            reference_tolerances(reference, case_signals(case))
    if runs is None:
        runs = run_cases(cases, workers=workers, fmu_paths=fmu_paths)
    comparisons = [compare_case(run, reference, given, reference_dir) for run, reference in zip(runs, references)]
    written = []
    if update:
        for run, reference in zip(runs, references):
            written += write_reference(run, reference_dir, given, reference.meta if reference else None)
    report = write_report(comparisons, runs, references, report_dir, given, reference_dir) if report_dir else None
    junit_path = write_junit(comparisons, junit, report.with_name("report.html") if report else None) \
        if junit else None
    return Outcome(comparisons, runs, report, written, junit_path)


def regress_command(args) -> int:
    names = args.scenarios or scenarios.scenario_names()
    overrides = tuple(args.set or ())
    if args.update and overrides:
        raise cli_args.UsageError("--update with --set: a mutated run never becomes a reference; drop one")
    if args.update and args.junit:
        raise cli_args.UsageError("--junit with --update: an update writes references and tests nothing; drop one")
    reference_dir = Path(args.references) if args.references else reference_directory(args.algorithm)
    if reference_dir.exists() and not reference_dir.is_dir():
        raise cli_args.UsageError(f"--references {args.references}: not a folder")
    for name in names:
        cli_args.check_assignments(scenarios.load(name), overrides)
    tolerances = {key: getattr(args, key) for key in DEFAULT_TOLERANCES if getattr(args, key) is not None}
    cases = all_cases(names, args.controller, overrides, args.algorithm)
    print(f"running {len(cases)} case(s) on {min(len(cases), args.workers or os.cpu_count() or 1)} process(es)...",
          file=sys.stderr)
    wall = clock.perf_counter()
    outcome = regress(cases, update=args.update, report_dir=Path(args.report), tolerances=tolerances,
                      workers=args.workers, reference_dir=reference_dir,
                      junit=Path(args.junit) if args.junit else None)
    wall = clock.perf_counter() - wall
    if args.update:
        for comparison in outcome.comparisons:
            state = ("new" if "no reference" in comparison.message else
                     "unchanged (inside the old tube)" if comparison.passed else "CHANGED")
            print(f"reference {comparison.case.name}: {state}")
        size = sum(p.stat().st_size for p in outcome.written)
        print(f"wrote {len(outcome.written)} reference files ({size / 1e6:.2f} MB) to "
              f"{relative(reference_dir)}/ in {wall:.0f} s; report {outcome.html}")
        return 0
    for line in markdown_table(summary_rows(outcome.comparisons), SUMMARY_HEADER, escape=False):
        print(line)
    for comparison in outcome.comparisons:
        if slowness(comparison):
            print(f"slow: {comparison.case.label} ran {comparison.wall_s:.2f} s, "
                  f"{slowness(comparison)} ({comparison.reference_wall_s:.2f} s)")
    passed = sum(c.passed for c in outcome.comparisons)
    print(f"{passed}/{len(outcome.comparisons)} cases pass in {wall:.0f} s; report {outcome.html} (and report.md)")
    if outcome.junit:
        print(f"JUnit XML: {outcome.junit}")
    if any("no reference" in c.message for c in outcome.comparisons):
        words = ["python", "-m", "harness", "regress", *map(str, args.scenarios or []),
                 *(["--algorithm", "me", "--edition", "native"] if args.algorithm == "me" else []), "--update",
                 *(["--references", str(args.references)] if args.references else [])]
        print(f"missing references: create them with `{shlex.join(words)}`", file=sys.stderr)
    return 0 if outcome.passed else 1


def register(commands):
    regress_parser = commands.add_parser(
        "regress", help="compare every case with its reference result inside a tolerance tube (pyfunnel)")
    regress_parser.add_argument("scenarios", nargs="*", metavar="SCENARIO", type=cli_args.scenario,
                                help=f"scenario names or .toml files of your own (default: all built-in: "
                                     f"{', '.join(scenarios.scenario_names())})")
    regress_parser.add_argument("--controller", nargs="+", choices=variants.NAMES,
                                help="controllers (default: all)")
    regress_parser.add_argument("--update", action="store_true",
                                help="rewrite the reference results from this run (the only way they change); "
                                     "the tolerances in the old metadata are kept")
    regress_parser.add_argument("--references", metavar="DIR",
                                help="folder of the reference results (default harness/references; created by "
                                     "the first --update)")
    regress_parser.add_argument("--report", default=str(DEFAULT_REPORT_DIR),
                                help="folder for report.html, report.md and the PNGs of failing signals "
                                     "(default results/regression)")
    regress_parser.add_argument("--junit", metavar="FILE",
                                help="also write JUnit XML here (one test case per scenario x controller)")
    regress_parser.add_argument("--workers", type=cli_args.positive_int, help="processes (default: every core)")
    regress_parser.add_argument("--algorithm", choices=("feedthrough", "me"), default="feedthrough",
                                help="feedthrough: our co-simulation master (default); me: Model Exchange (the native "
                                     "FMUs, CVODE), held to its own references in harness/references/model_exchange/ "
                                     "(docs/model_exchange.md)")
    regress_parser.add_argument("--set", action="append", metavar="INSTANCE.PARAMETER=VALUE", type=cli_args.assignment,
                                help="run with a parameter changed (e.g. controller.gamma=290: a mutation that "
                                     "must fail); never allowed with --update")
    for key, value in DEFAULT_TOLERANCES.items():
        regress_parser.add_argument(f"--{key}", type=cli_args.non_negative_float,
                                    help=f"pyfunnel tolerance {key} for every signal, over the references' own "
                                         f"(default {value:g})")
    regress_parser.set_defaults(handler=regress_command)
