"""Regression against reference results: ``python -m harness regress``.

In the style of BuildingsPy's ReferenceResults and the Modelica Standard
Library's reference results, checked with the tube (funnel) comparison that
BuildingsPy uses (``pyfunnel``):

* a *case* is one scenario with one controller: the built-in scenarios (5 x 3 cases) or any
  scenario file of a user's (their plant FMU, our controller: ``regress my_loop.toml``);
* its reference is ``<references>/<scenario>_<controller>_ref.csv`` (FMI cross-check style: time
  first, quoted ``"instance.variable"`` header) with the compared signals resampled to ``POINTS``
  points over the scenario's whole horizon, plus ``<...>_ref.json``: start, stop, step, points,
  signals, tolerances (per case, and per signal in ``signal_tolerances``), the scenario's hash and
  settings, tool versions, date, git commit and the wall time of the run;
  ``<references>`` is harness/references/ or ``--references DIR``;
* the compared signals: the nine of ``SIGNALS`` for the built-in scenarios, the scenario's
  ``[record] variables`` for a user's;
* every signal of a new run is resampled the same way and must lie inside the tube around its
  reference: per signal pass/fail, the largest excursion outside the tube and where, and the
  largest deviation from the reference; a changed experiment (start, stop, step) or a changed
  scenario file (its hash; the changed settings are named) fails the case;
* a missing reference fails (run ``--update`` to create it); references are written only by
  ``--update``, never by a plain run, and an update keeps the tolerances set in the old metadata;
* the reports (report.md, report.html with a PNG of reference, tube and new result for every
  failing signal; harness/studies/regression_report.py) go to ``--report DIR`` (default
  results/regression/), JUnit XML to ``--junit FILE``; the exit code is 1 if anything failed.

The cases run in a process pool (``spawn``: every core, a fresh interpreter
per worker, no state shared with a parent that may hold loaded FMUs).
"""
from __future__ import annotations

import contextlib
import dataclasses
import datetime
import hashlib
import importlib.metadata
import io
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .. import cases as shared
from .. import cli_args, variants
from .. import scenario as scenarios
from ..cases import Case
from ..me_master import DEFAULT_RTOL
from . import regression_report as reports
from .regression_report import SLOW_FACTOR, SUMMARY_HEADER, summary_rows

ROOT = Path(__file__).resolve().parents[2]
REFERENCE_DIR = ROOT / "harness" / "references"
#: Model Exchange (--algorithm me) has references of its own: the co-simulation's carry its O(step) error, which in the
#: controller's transient exceeds the tube (theta1 of pendulum_case1/fae at 0.55 s: -3.08 at the scenario's step,
#: -2.90, -2.81, -2.77 at 1/2, 1/4, 1/8 of it, -2.73 in Model Exchange)
MODEL_EXCHANGE_REFERENCE_DIR = REFERENCE_DIR / "model_exchange"
DEFAULT_REPORT_DIR = Path("results") / "regression"  # in the working directory, like tables' results/
SIGNALS = ("plant.y", "plant.dy", "controller.u", "controller.theta1", "controller.theta2", "controller.theta3",
           "controller.theta4", "reference.e", "reference.de")
POINTS = 2001
VALUE_FORMAT = "%.10g"  # 10 significant digits: 1e-10 relative, far inside the tube, and small files
#: pyfunnel tolerances.  BuildingsPy's default ``tol = 1e-3`` means atolx = atoly = ltoly = 1e-3; here the
#: absolute y tolerance is relative to each signal's range (rtoly) because the signals span 1e-3 rad (e)
#: to 1e2 (theta): a fixed 1e-3 would be as wide as e itself at steady state.
DEFAULT_TOLERANCES = {"atolx": 1e-3, "atoly": 0.0, "ltolx": 0.0, "ltoly": 1e-3, "rtolx": 0.0, "rtoly": 1e-3}

__all__ = ["Case", "CaseRun", "CaseComparison", "SignalComparison", "Reference", "Outcome", "SIGNALS", "POINTS",
           "DEFAULT_TOLERANCES", "REFERENCE_DIR", "SLOW_FACTOR", "SUMMARY_HEADER", "all_cases", "case_signals",
           "reference_paths", "run_cases", "write_reference", "read_reference", "compare_signal", "compare_case",
           "summary_rows", "write_report", "regress", "scenario_fingerprint", "register"]


def all_cases(names=None, controllers=None, overrides=(), algorithm: str = "feedthrough") -> list[Case]:
    """``algorithm="me"``: the same cases in Model Exchange, held to the same (co-simulation) references."""
    names = list(names or scenarios.scenario_names())
    controllers = list(controllers or variants.NAMES)
    return [Case(n, c, overrides=tuple(overrides), algorithm=algorithm) for n in names for c in controllers]


def reference_directory(algorithm: str) -> Path:
    """Where the references of an algorithm's runs are: our feedthrough master's, or Model Exchange's."""
    return MODEL_EXCHANGE_REFERENCE_DIR if algorithm == "me" else REFERENCE_DIR


def reference_paths(case: Case, directory: Path = REFERENCE_DIR) -> tuple[Path, Path]:
    directory = Path(directory)
    return directory / f"{case.name}_ref.csv", directory / f"{case.name}_ref.json"


def is_builtin(case: Case) -> bool:
    """A scenario of harness/scenarios/ (its references are the committed ones)."""
    path = scenarios.load(case.scenario).path
    return path is not None and path.resolve().parent == scenarios.SCENARIO_DIR.resolve()


def case_signals(case: Case) -> tuple:
    """The compared signals: the nine of SIGNALS for a built-in scenario, the recorded ones for a user's."""
    return SIGNALS if is_builtin(case) else tuple(scenarios.load(case.scenario).record)


# ------------------------------------------------------ scenario fingerprint
def _flatten(data, prefix: str = "") -> dict:
    """{"components.plant.parameters.T": 0.5, "connections": [...], ...}: tables flattened to dotted keys."""
    flat = {}
    for key, value in data.items():
        dotted = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, dotted + "."))
        else:
            flat[dotted] = value
    return flat


def scenario_fingerprint(case: Case) -> tuple[str, dict]:
    """(sha256, settings) of the case's scenario file as TOML data: comments, spacing and key order do
    not count; every value does (parameters, connections, experiment, record, ...). The controller and
    ``--set`` overrides are not part of it (the case's name and label carry them)."""
    path = scenarios.load(case.scenario).path
    with open(path, "rb") as stream:
        settings = _flatten(tomllib.load(stream))
    canonical = json.dumps(settings, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(canonical.encode()).hexdigest(), json.loads(canonical)


def scenario_changes(old: dict, new: dict, limit: int = 4) -> str:
    """The settings that differ, ``key: old -> new`` (at most ``limit``, then how many more)."""
    def shown(value):
        text = "(absent)" if value is _ABSENT else json.dumps(value)
        return text if len(text) <= 60 else text[:57] + "..."

    changed = [f"{key}: {shown(old.get(key, _ABSENT))} -> {shown(new.get(key, _ABSENT))}"
               for key in sorted(set(old) | set(new)) if old.get(key, _ABSENT) != new.get(key, _ABSENT)]
    more = f"; {len(changed) - limit} more" if len(changed) > limit else ""
    return "; ".join(changed[:limit]) + more


_ABSENT = object()


# ------------------------------------------------------------------ running
@dataclass
class CaseRun:
    case: Case
    start: float
    stop: float
    step: float
    time: np.ndarray  # the resampled grid
    signals: dict  # name -> resampled values (the compared signals, in order)
    wall_s: float
    error: str | None = None  # the run failed (message); signals then hold what was computed


def run_cases(cases, workers: int | None = None, fmu_paths: dict | None = None, points: int = POINTS) -> list:
    """Run the cases with the shared runner (a process pool, every core by default), resampled for comparison.

    Results in the order of ``cases``; a failed run keeps what it computed (NaN after it stopped).
    """
    wanted = [dataclasses.replace(case, points=points, signals=case_signals(case), figure_interval=None)
              for case in cases]
    outcomes = shared.run_cases(wanted, jobs=workers, fmu_paths=fmu_paths, progress=False)
    return [CaseRun(case, outcome["start"], outcome["stop"], outcome["step"], outcome["time"], outcome["signals"],
                    outcome["wall_s"], outcome["reason"] if outcome["status"] != "ok" else None)
            for case, outcome in zip(cases, outcomes)]


# --------------------------------------------------------------- references
def _relative(path: Path) -> str:
    try:
        return str(Path(path).resolve().relative_to(ROOT))
    except ValueError:
        return str(path)


def tool_versions() -> dict:
    def version(package):
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return None

    return {"python": platform.python_version(), "fmpy": version("fmpy"), "pythonfmu": version("pythonfmu"),
            "numpy": np.__version__, "pyfunnel": version("pyfunnel")}


def git_commit() -> str | None:
    try:
        completed = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return completed.stdout.strip() or None if completed.returncode == 0 else None


def write_reference(run: CaseRun, directory: Path = REFERENCE_DIR, tolerances: dict | None = None,
                    previous: dict | None = None) -> tuple:
    """Write the reference of ``run``; ``tolerances`` given on the command line, ``previous`` the old
    metadata, whose tolerances (per case and per signal) are kept."""
    if run.error:
        raise RuntimeError(f"{run.case.label}: the run failed, no reference written: {run.error}")
    if run.case.overrides:
        raise RuntimeError(f"{run.case.label}: a run with parameter overrides never becomes a reference")
    directory = Path(directory)
    csv_path, json_path = reference_paths(run.case, directory)
    directory.mkdir(parents=True, exist_ok=True)
    names = list(run.signals)
    header = ",".join(f'"{name}"' for name in ["time", *names])
    table = np.column_stack([run.time, *[run.signals[name] for name in names]])
    np.savetxt(csv_path, table, delimiter=",", header=header, comments="", fmt=VALUE_FORMAT)
    previous = previous or {}
    digest, settings = scenario_fingerprint(run.case)
    scenario_path = scenarios.load(run.case.scenario).path
    meta = {
        "case": run.case.name, "scenario": run.case.scenario_name, "controller": run.case.controller,
        "scenario_file": _relative(scenario_path) if is_builtin(run.case) else str(run.case.scenario),
        "scenario_hash": digest,
        "start": run.start, "stop": run.stop, "step": run.step, "points": len(run.time),
        "signals": names, "algorithm": run.case.algorithm,
        **({"rtol": run.case.rtol or DEFAULT_RTOL, "edition": "native"} if run.case.algorithm == "me" else {}),
        "tolerances": {**DEFAULT_TOLERANCES, **previous.get("tolerances", {}), **(tolerances or {})},
        "signal_tolerances": {name: dict(values) for name, values in previous.get("signal_tolerances", {}).items()
                              if name in names},
        "tools": tool_versions(), "platform": f"{platform.system()} {platform.machine()}",
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "git_commit": git_commit(), "wall_s": round(run.wall_s, 3),
        "scenario_settings": settings,
    }
    json_path.write_text(json.dumps(meta, indent=2) + "\n")
    return csv_path, json_path


@dataclass
class Reference:
    time: np.ndarray
    signals: dict
    meta: dict
    path: Path | None = None  # the _ref.json


def read_reference(case: Case, directory: Path = REFERENCE_DIR) -> Reference | None:
    csv_path, json_path = reference_paths(case, directory)
    if not csv_path.exists() or not json_path.exists():
        return None
    with open(csv_path) as stream:
        names = [name.strip().strip('"') for name in stream.readline().strip().split(",")]
    table = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    try:
        meta = json.loads(json_path.read_text())
    except json.JSONDecodeError as error:
        raise cli_args.UsageError(f"{json_path} is not valid JSON: {error}") from None
    return Reference(table[:, 0], {name: table[:, k] for k, name in enumerate(names) if k}, meta, json_path)


def _checked_tolerances(values, where: str) -> dict:
    if not isinstance(values, dict):
        raise cli_args.UsageError(f"{where} must be a table of tolerances; valid keys: {', '.join(DEFAULT_TOLERANCES)}")
    for key, value in values.items():
        if key not in DEFAULT_TOLERANCES:
            raise cli_args.UsageError(f"{where}: unknown tolerance {key!r}; valid: {', '.join(DEFAULT_TOLERANCES)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise cli_args.UsageError(f"{where}: {key} = {value!r} is invalid; give a finite number >= 0")
    return {key: float(value) for key, value in values.items()}


def reference_tolerances(reference: Reference, signals) -> tuple[dict, dict]:
    """(per case, {signal: per signal}) tolerances of a reference's metadata, checked: a mistake is one
    line naming the file, the key and the valid ones (exit 2)."""
    where = str(reference.path or "reference metadata")
    case_level = _checked_tolerances(reference.meta.get("tolerances", {}), f"{where}: tolerances")
    per_signal = reference.meta.get("signal_tolerances", {})
    if not isinstance(per_signal, dict):
        raise cli_args.UsageError(f"{where}: signal_tolerances must map a signal to its tolerances")
    checked = {}
    for name, values in per_signal.items():
        if name not in signals:
            raise cli_args.UsageError(f"{where}: signal_tolerances names {name!r}, which is not compared; "
                                      f"valid: {', '.join(signals)}")
        checked[name] = _checked_tolerances(values, f"{where}: signal_tolerances.{name}")
    return case_level, checked


# --------------------------------------------------------------- comparison
@dataclass
class SignalComparison:
    signal: str
    passed: bool
    max_error: float  # largest excursion outside the tube (0 inside)
    t_max_error: float | None
    max_deviation: float  # largest |new - reference| on the grid
    t_max_deviation: float | None
    message: str = ""
    plot: Path | None = None
    funnel: dict | None = field(default=None, repr=False)  # lower/upper bound arrays, when kept
    tolerances: dict = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))  # the ones it was compared with


def compare_signal(name, x_ref, y_ref, x_test, y_test, tolerances: dict | None = None,
                   keep_funnel: bool = False) -> SignalComparison:
    """Tube comparison of one signal with pyfunnel (reference and test must span the same x range)."""
    import pyfunnel  # here, not at module level: its import is paid only when signals are compared

    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    x_ref, y_ref = np.asarray(x_ref, float), np.asarray(y_ref, float)
    x_test, y_test = np.asarray(x_test, float), np.asarray(y_test, float)
    deviation = np.abs(np.interp(x_ref, x_test, y_test) - y_ref) if len(x_test) else np.array([np.inf])
    worst = int(np.nanargmax(deviation)) if np.isfinite(deviation).any() else 0
    max_deviation = float(deviation[worst]) if np.isfinite(deviation).any() else float("inf")
    if not (np.all(np.isfinite(y_test)) and np.all(np.isfinite(y_ref))):
        bad = np.flatnonzero(~np.isfinite(y_test))
        where = float(x_test[bad[0]]) if bad.size else None
        return SignalComparison(name, False, float("inf"), where, float("inf"), where,
                                "non-finite values (the run stopped or diverged)", tolerances=tolerances)
    directory = tempfile.mkdtemp(prefix="afc_funnel_")
    try:
        log = io.StringIO()
        with contextlib.redirect_stdout(log):
            status = pyfunnel.compareAndReport(x_ref, y_ref, x_test, y_test, outputDirectory=directory, **tolerances)
        if status != 0:
            message = " ".join(log.getvalue().replace("*** Warning:", "").split())
            return SignalComparison(name, False, float("inf"), None, max_deviation, float(x_ref[worst]),
                                    f"pyfunnel failed: {message}", tolerances=tolerances)
        errors = np.loadtxt(os.path.join(directory, "errors.csv"), delimiter=",", skiprows=1, ndmin=2)
        k = int(np.argmax(errors[:, 1]))
        max_error, t_error = float(errors[k, 1]), float(errors[k, 0])
        funnel = None
        if keep_funnel or max_error > 0:
            funnel = {part: np.loadtxt(os.path.join(directory, f"{part}.csv"), delimiter=",", skiprows=1, ndmin=2)
                      for part in ("lowerBound", "upperBound")}
            funnel["errors"] = errors
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    passed = max_error == 0
    message = "" if passed else f"outside the tube by up to {max_error:.3e} at t = {t_error:.6g} s"
    return SignalComparison(name, passed, max_error, t_error if not passed else None, max_deviation,
                            float(x_ref[worst]), message, funnel=funnel, tolerances=tolerances)


@dataclass
class CaseComparison:
    case: Case
    signals: list
    message: str = ""  # a failure that is not one signal's (missing reference, failed run, changed scenario)
    wall_s: float = 0.0
    reference_wall_s: float | None = None  # the wall time of the reference's run
    notes: list = field(default_factory=list)  # what the report says that is no failure
    run_tolerances: dict = field(default_factory=lambda: dict(DEFAULT_TOLERANCES))  # the report's (no metadata)

    @property
    def passed(self) -> bool:
        return not self.message and all(s.passed for s in self.signals)

    @property
    def slowdown(self) -> float | None:
        """The run's wall time over its reference's (None without a recorded reference time)."""
        return self.wall_s / self.reference_wall_s if self.reference_wall_s else None


def update_command(case: Case, reference_dir: Path) -> str:
    me = " --algorithm me --edition native" if case.algorithm == "me" else ""
    command = f"python -m harness regress {case.scenario} --controller {case.controller}{me} --update"
    if Path(reference_dir).resolve() != reference_directory(case.algorithm).resolve():
        command += f" --references {reference_dir}"
    return command


def compare_case(run: CaseRun, reference: Reference | None, tolerances: dict | None = None,
                 reference_dir: Path | None = None) -> CaseComparison:
    """Compare one run with its reference; ``tolerances``: those given on the command line, which override
    the reference's own (per case and per signal) and the defaults."""
    case = run.case
    reference_dir = REFERENCE_DIR if reference_dir is None else Path(reference_dir)
    given = dict(tolerances or {})
    run_tolerances = {**DEFAULT_TOLERANCES, **given}
    if reference is None:
        missing = reference_paths(case, reference_dir)[0]
        return CaseComparison(case, [], f"no reference {_relative(missing)}: run `{update_command(case, reference_dir)}` "
                                        "to create it", run.wall_s, run_tolerances=run_tolerances)
    messages, notes = [], []
    meta = reference.meta
    for key, value in (("start", run.start), ("stop", run.stop), ("step", run.step)):
        if key in meta and not np.isclose(meta[key], value, rtol=1e-12, atol=0):
            messages.append(f"experiment changed: reference {key} = {meta[key]:g}, now {value:g} "
                            "(run --update if intended)")
    digest, settings = scenario_fingerprint(case)
    if "scenario_hash" not in meta:
        notes.append("the reference records no scenario hash (run --update to add it)")
    elif meta["scenario_hash"] != digest:
        changes = scenario_changes(meta.get("scenario_settings", {}), settings)
        messages.append(f"scenario changed since the reference ({changes or 'hash differs'}); "
                        "run --update if intended")
    if run.error:
        messages.append(f"the run failed: {run.error.splitlines()[0]}")
    case_level, per_signal = reference_tolerances(reference, list(run.signals))
    signals = []
    for name in run.signals:
        own = {**DEFAULT_TOLERANCES, **case_level, **per_signal.get(name, {}), **given}
        if name not in reference.signals:
            signals.append(SignalComparison(name, False, float("inf"), None, float("inf"), None,
                                            "missing from the reference (run --update)", tolerances=own))
            continue
        signals.append(compare_signal(name, reference.time, reference.signals[name], run.time, run.signals[name],
                                      own))
    wall = meta.get("wall_s")
    reference_wall = float(wall) if isinstance(wall, (int, float)) and wall > 0 else None
    return CaseComparison(case, signals, "; ".join(messages), run.wall_s, reference_wall, notes, run_tolerances)


# ------------------------------------------------------------------ report
def write_report(comparisons, runs, references, directory: Path, tolerances: dict,
                 reference_dir: Path = REFERENCE_DIR) -> Path:
    """report.md and report.html (with a PNG of every failing signal) in ``directory``; returns report.md."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    reports.draw_failing_signals(comparisons, runs, references, directory)
    shown = _relative(reference_dir) + "/"
    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    reports.write_html(comparisons, directory / "report.html", shown, tolerances, POINTS)
    return reports.write_markdown(comparisons, directory / "report.md", shown, tolerances, POINTS)


# --------------------------------------------------------------- top level
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
    junit_path = reports.write_junit(comparisons, junit, report.with_name("report.html") if report else None) \
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
              f"{_relative(reference_dir)}/ in {wall:.0f} s; report {outcome.html}")
        return 0
    for line in reports._table(summary_rows(outcome.comparisons), SUMMARY_HEADER):
        print(line)
    for comparison in outcome.comparisons:
        if reports.slowness(comparison):
            print(f"slow: {comparison.case.label} ran {comparison.wall_s:.2f} s, "
                  f"{reports.slowness(comparison)} ({comparison.reference_wall_s:.2f} s)")
    passed = sum(c.passed for c in outcome.comparisons)
    print(f"{passed}/{len(outcome.comparisons)} cases pass in {wall:.0f} s; report {outcome.html} (and report.md)")
    if outcome.junit:
        print(f"JUnit XML: {outcome.junit}")
    if any("no reference" in c.message for c in outcome.comparisons):
        where = f" --references {args.references}" if args.references else ""
        me = "--algorithm me --edition native " if args.algorithm == "me" else ""
        print(f"missing references: create them with `python -m harness regress {' '.join(args.scenarios or [])}"
              f"{' ' if args.scenarios else ''}{me}--update{where}`", file=sys.stderr)
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
