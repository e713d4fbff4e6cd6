"""Regression against reference results kept in the repository: ``python -m harness regress``.

In the style of BuildingsPy's ReferenceResults and the Modelica Standard
Library's reference results, checked with the tube (funnel) comparison that
BuildingsPy uses (``pyfunnel``):

* a *case* is one scenario with one controller (4 x 3 = 12 cases);
* its reference is ``references/<scenario>_<controller>_ref.csv`` (FMI
  cross-check style: time first, quoted ``"instance.variable"`` header) with
  the comparison signals resampled to ``POINTS`` points over the scenario's
  whole horizon, plus ``<...>_ref.json`` (start, stop, step, points, signals,
  tolerances, tool versions, date, git commit);
* every signal of a new run is resampled the same way and must lie inside
  the tube around its reference: per signal pass/fail, the largest excursion
  outside the tube and where, and the largest deviation from the reference;
* a missing reference fails (run ``--update`` to create it); references are
  written only by ``--update``, never by a plain run;
* the report (Markdown, plus a PNG of reference, tube and new result for
  every failing signal) goes to ``--report DIR`` (default
  results/regression/); the exit code is 1 if anything failed.

The cases run in a process pool (``spawn``: every core, a fresh interpreter
per worker, no state shared with a parent that may hold loaded FMUs).
"""
from __future__ import annotations

import contextlib
import dataclasses
import datetime
import importlib.metadata
import io
import json
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

from .. import cases as shared
from .. import cli_args, variants
from .. import scenario as scenarios
from ..cases import Case
from ..me_master import DEFAULT_RTOL
from ..units import variable_unit, with_unit

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


def all_cases(names=None, controllers=None, overrides=(), algorithm: str = "feedthrough") -> list[Case]:
    """``algorithm="me"``: the same cases in Model Exchange, held to the same (co-simulation) references."""
    names = list(names or scenarios.scenario_names())
    controllers = list(controllers or variants.NAMES)
    return [Case(n, c, overrides=tuple(overrides), algorithm=algorithm) for n in names for c in controllers]


def reference_directory(algorithm: str) -> Path:
    """Where the references of an algorithm's runs are: our feedthrough master's, or Model Exchange's."""
    return MODEL_EXCHANGE_REFERENCE_DIR if algorithm == "me" else REFERENCE_DIR


def reference_paths(case: Case, directory: Path = REFERENCE_DIR) -> tuple[Path, Path]:
    return directory / f"{case.name}_ref.csv", directory / f"{case.name}_ref.json"


# ------------------------------------------------------------------ running
@dataclass
class CaseRun:
    case: Case
    start: float
    stop: float
    step: float
    time: np.ndarray  # the resampled grid
    signals: dict  # name -> resampled values
    wall_s: float
    error: str | None = None  # the run failed (message); signals then hold what was computed


def run_cases(cases, workers: int | None = None, fmu_paths: dict | None = None, points: int = POINTS) -> list:
    """Run the cases with the shared runner (a process pool, every core by default), resampled for comparison.

    Results in the order of ``cases``; a failed run keeps what it computed (NaN after it stopped).
    """
    wanted = [dataclasses.replace(case, points=points, signals=SIGNALS, figure_interval=None) for case in cases]
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


def write_reference(run: CaseRun, directory: Path = REFERENCE_DIR, tolerances: dict | None = None) -> tuple:
    if run.error:
        raise RuntimeError(f"{run.case.label}: the run failed, no reference written: {run.error}")
    if run.case.overrides:
        raise RuntimeError(f"{run.case.label}: a run with parameter overrides never becomes a reference")
    csv_path, json_path = reference_paths(run.case, directory)
    directory.mkdir(parents=True, exist_ok=True)
    header = ",".join(f'"{name}"' for name in ["time", *SIGNALS])
    table = np.column_stack([run.time, *[run.signals[name] for name in SIGNALS]])
    np.savetxt(csv_path, table, delimiter=",", header=header, comments="", fmt=VALUE_FORMAT)
    meta = {
        "case": run.case.name, "scenario": run.case.scenario, "controller": run.case.controller,
        "start": run.start, "stop": run.stop, "step": run.step, "points": len(run.time),
        "signals": list(SIGNALS), "algorithm": run.case.algorithm,
        **({"rtol": run.case.rtol or DEFAULT_RTOL, "edition": "native"} if run.case.algorithm == "me" else {}),
        "tolerances": dict(tolerances or DEFAULT_TOLERANCES),
        "tools": tool_versions(), "platform": f"{platform.system()} {platform.machine()}",
        "date": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
        "git_commit": git_commit(), "wall_s": round(run.wall_s, 2),
    }
    json_path.write_text(json.dumps(meta, indent=2) + "\n")
    return csv_path, json_path


@dataclass
class Reference:
    time: np.ndarray
    signals: dict
    meta: dict


def read_reference(case: Case, directory: Path = REFERENCE_DIR) -> Reference | None:
    csv_path, json_path = reference_paths(case, directory)
    if not csv_path.exists() or not json_path.exists():
        return None
    with open(csv_path) as stream:
        names = [name.strip().strip('"') for name in stream.readline().strip().split(",")]
    table = np.loadtxt(csv_path, delimiter=",", skiprows=1, ndmin=2)
    return Reference(table[:, 0], {name: table[:, k] for k, name in enumerate(names) if k},
                     json.loads(json_path.read_text()))


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


def compare_signal(name, x_ref, y_ref, x_test, y_test, tolerances: dict | None = None,
                   keep_funnel: bool = False) -> SignalComparison:
    """Tube comparison of one signal with pyfunnel (reference and test must span the same x range)."""
    import pyfunnel  # here, not at module level: 0.2 s of import, paid only when signals are compared

    x_ref, y_ref = np.asarray(x_ref, float), np.asarray(y_ref, float)
    x_test, y_test = np.asarray(x_test, float), np.asarray(y_test, float)
    deviation = np.abs(np.interp(x_ref, x_test, y_test) - y_ref) if len(x_test) else np.array([np.inf])
    worst = int(np.nanargmax(deviation)) if np.isfinite(deviation).any() else 0
    max_deviation = float(deviation[worst]) if np.isfinite(deviation).any() else float("inf")
    if not (np.all(np.isfinite(y_test)) and np.all(np.isfinite(y_ref))):
        bad = np.flatnonzero(~np.isfinite(y_test))
        where = float(x_test[bad[0]]) if bad.size else None
        return SignalComparison(name, False, float("inf"), where, float("inf"), where,
                                "non-finite values (the run stopped or diverged)")
    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    directory = tempfile.mkdtemp(prefix="afc_funnel_")
    try:
        log = io.StringIO()
        with contextlib.redirect_stdout(log):
            status = pyfunnel.compareAndReport(x_ref, y_ref, x_test, y_test, outputDirectory=directory, **tolerances)
        if status != 0:
            message = " ".join(log.getvalue().replace("*** Warning:", "").split())
            return SignalComparison(name, False, float("inf"), None, max_deviation, float(x_ref[worst]),
                                    f"pyfunnel failed: {message}")
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
    message = "" if passed else f"outside the tube by up to {max_error:.3e} at t = {t_error:.6g}"
    return SignalComparison(name, passed, max_error, t_error if not passed else None, max_deviation,
                            float(x_ref[worst]), message, funnel=funnel)


@dataclass
class CaseComparison:
    case: Case
    signals: list
    message: str = ""  # a failure that is not one signal's (missing reference, failed run, experiment changed)
    wall_s: float = 0.0

    @property
    def passed(self) -> bool:
        return not self.message and all(s.passed for s in self.signals)


def compare_case(run: CaseRun, reference: Reference | None, tolerances: dict | None = None,
                 reference_dir: Path | None = None) -> CaseComparison:
    case = run.case
    if reference is None:
        missing = reference_paths(case, REFERENCE_DIR if reference_dir is None else Path(reference_dir))[0]
        me = " --algorithm me --edition native" if case.algorithm == "me" else ""
        return CaseComparison(case, [], f"no reference {_relative(missing)}: "
                                        f"run `python -m harness regress {case.scenario} --controller "
                                        f"{case.controller}{me} --update` to create it", run.wall_s)
    messages = []
    meta = reference.meta
    for key, value in (("start", run.start), ("stop", run.stop), ("step", run.step)):
        if key in meta and not np.isclose(meta[key], value, rtol=1e-12, atol=0):
            messages.append(f"experiment changed: reference {key} = {meta[key]:g}, now {value:g} "
                            "(run --update if intended)")
    if run.error:
        messages.append(f"the run failed: {run.error.splitlines()[0]}")
    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    signals = []
    for name in SIGNALS:
        if name not in reference.signals:
            signals.append(SignalComparison(name, False, float("inf"), None, float("inf"), None,
                                            "missing from the reference (run --update)"))
            continue
        signals.append(compare_signal(name, reference.time, reference.signals[name], run.time, run.signals[name],
                                      tolerances))
    return CaseComparison(case, signals, "; ".join(messages), run.wall_s)


# ------------------------------------------------------------------ report
def plot_signal(path: Path, case: Case, comparison: SignalComparison, reference: Reference, run: CaseRun):
    """Reference, tube and new result: the whole horizon, a zoom around the worst point, the excursion."""
    import matplotlib  # here, not at module level: 1-3 s of import, paid only when a failing signal is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = comparison.signal
    unit = variable_unit(scenarios.load(case.scenario), name)
    funnel = comparison.funnel or {}
    figure, (whole, zoom, excursion) = plt.subplots(3, 1, figsize=(9, 8), gridspec_kw={"height_ratios": [3, 3, 1.3]})
    for axis in (whole, zoom):
        if "lowerBound" in funnel:
            lower, upper = funnel["lowerBound"], funnel["upperBound"]
            grid = np.union1d(lower[:, 0], upper[:, 0])
            axis.fill_between(grid, np.interp(grid, lower[:, 0], lower[:, 1]), np.interp(grid, upper[:, 0], upper[:, 1]),
                              color="tab:gray", alpha=0.35, lw=0, label="tube")
        axis.plot(reference.time, reference.signals[name], color="k", lw=0.9, label="reference")
        axis.plot(run.time, run.signals[name], color="tab:red", lw=0.9, label="new result")
        axis.set_ylabel(with_unit(name, unit))
    centre = comparison.t_max_error if comparison.t_max_error is not None else float(reference.time[-1]) / 2
    half = 0.02 * float(reference.time[-1] - reference.time[0]) + 1e-9
    inside = (reference.time >= centre - half) & (reference.time <= centre + half)
    if inside.any():
        values = np.concatenate([reference.signals[name][inside], run.signals[name][inside]])
        values = values[np.isfinite(values)]
        if values.size:
            margin = 0.2 * (values.max() - values.min()) + 1e-12
            zoom.set_ylim(values.min() - margin, values.max() + margin)
    zoom.set_xlim(centre - half, centre + half)
    zoom.set_title(f"zoom around t = {centre:.4g} s", fontsize=8)
    whole.set_title(f"{case.label}: {name} ({comparison.message or 'inside the tube'})", fontsize=9)
    whole.legend(fontsize=8, loc="best")
    if "errors" in funnel:
        excursion.plot(funnel["errors"][:, 0], funnel["errors"][:, 1], color="tab:red", lw=0.8)
    excursion.set_ylabel(with_unit("outside tube", unit))
    excursion.set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _table(rows, header) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return lines


def summary_rows(comparisons) -> list:
    rows = []
    for comparison in comparisons:
        failed = [s for s in comparison.signals if not s.passed]
        worst = max(comparison.signals, key=lambda s: (s.max_error, s.max_deviation), default=None)
        rows.append([comparison.case.label, "pass" if comparison.passed else "**FAIL**",
                     f"{len(comparison.signals) - len(failed)}/{len(SIGNALS)}",
                     worst.signal if worst else "-",
                     f"{worst.max_error:.3g}" if worst else "-",
                     f"{worst.t_max_error:.4g}" if worst and worst.t_max_error is not None else "-",
                     f"{worst.max_deviation:.3g}" if worst else "-",
                     f"{comparison.wall_s:.1f}",
                     comparison.message or ", ".join(s.signal for s in failed) or ""])
    return rows


SUMMARY_HEADER = ["case", "result", "signals in tube", "worst signal", "max outside tube", "at t [s]",
                  "max abs deviation", "run [s]", "notes"]


def write_report(comparisons, runs, references, directory: Path, tolerances: dict) -> Path:
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    for old in directory.glob("*.png"):
        old.unlink()
    for comparison, run, reference in zip(comparisons, runs, references):
        for signal in comparison.signals:
            if not signal.passed and reference is not None and signal.signal in reference.signals:
                path = directory / f"{comparison.case.name}_{signal.signal}.png"
                plot_signal(path, comparison.case, signal, reference, run)
                signal.plot = path
    passed = sum(c.passed for c in comparisons)
    lines = [f"# Regression report ({passed}/{len(comparisons)} cases pass)", "",
             f"Generated {datetime.datetime.now().replace(microsecond=0).isoformat()} by "
             "`python -m harness regress`; references in `harness/references/`.",
             "", "Tolerances (pyfunnel): " + ", ".join(f"{k} = {v:g}" for k, v in tolerances.items())
             + f"; signals resampled to {POINTS} points over each scenario's horizon.", "", "## Summary", ""]
    lines += _table(summary_rows(comparisons), SUMMARY_HEADER)
    lines += ["", "## Signals", ""]
    rows = []
    for comparison in comparisons:
        for s in comparison.signals:
            plot = f"![]({s.plot.name})" if s.plot else ""
            rows.append([comparison.case.label, s.signal, "pass" if s.passed else "**FAIL**", f"{s.max_error:.3g}",
                         f"{s.t_max_error:.4g}" if s.t_max_error is not None else "-", f"{s.max_deviation:.3g}",
                         f"{s.t_max_deviation:.4g}" if s.t_max_deviation is not None else "-",
                         s.message, plot])
    lines += _table(rows, ["case", "signal", "result", "max outside tube", "at t [s]", "max abs deviation",
                           "at t [s]", "message", "plot"])
    path = directory / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


# --------------------------------------------------------------- top level
@dataclass
class Outcome:
    comparisons: list
    runs: list
    report: Path | None
    written: list  # reference files written by --update

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.comparisons)


def regress(cases, update: bool = False, report_dir=DEFAULT_REPORT_DIR, tolerances: dict | None = None,
            workers: int | None = None, reference_dir: Path | None = None, fmu_paths: dict | None = None,
            runs: list | None = None) -> Outcome:
    """Run (or reuse ``runs``), compare with the references, write the report; ``update`` rewrites them."""
    if reference_dir is None:
        algorithms = {case.algorithm for case in cases}
        reference_dir = reference_directory(algorithms.pop() if len(algorithms) == 1 else "feedthrough")
    reference_dir = Path(reference_dir)
    tolerances = {**DEFAULT_TOLERANCES, **(tolerances or {})}
    if update and any(case.overrides for case in cases):
        raise ValueError("--update with parameter overrides: a mutated run never becomes a reference")
    if runs is None:
        runs = run_cases(cases, workers=workers, fmu_paths=fmu_paths)
    references = [read_reference(run.case, reference_dir) for run in runs]
    comparisons = [compare_case(run, reference, tolerances, reference_dir) for run, reference in zip(runs, references)]
    written = []
    if update:
        for run in runs:
            written += write_reference(run, reference_dir, tolerances)
    report = write_report(comparisons, runs, references, report_dir, tolerances) if report_dir else None
    return Outcome(comparisons, runs, report, written)


def regress_command(args) -> int:
    names = args.scenarios or scenarios.scenario_names()
    overrides = tuple(args.set or ())
    if args.update and overrides:
        raise cli_args.UsageError("--update with --set: a mutated run never becomes a reference; drop one")
    for name in names:
        cli_args.check_assignments(scenarios.load(name), overrides)
    tolerances = {key: getattr(args, key) for key in DEFAULT_TOLERANCES if getattr(args, key) is not None}
    cases = all_cases(names, args.controller, overrides, args.algorithm)
    print(f"running {len(cases)} case(s) on {min(len(cases), args.workers or os.cpu_count() or 1)} process(es)...",
          file=sys.stderr)
    wall = clock.perf_counter()
    outcome = regress(cases, update=args.update, report_dir=Path(args.report), tolerances=tolerances,
                      workers=args.workers)
    wall = clock.perf_counter() - wall
    if not args.update:
        for line in _table(summary_rows(outcome.comparisons), SUMMARY_HEADER):
            print(line)
    else:
        for comparison in outcome.comparisons:
            state = ("new" if "no reference" in comparison.message else
                     "unchanged (inside the old tube)" if comparison.passed else "CHANGED")
            print(f"reference {comparison.case.name}: {state}")
        size = sum(p.stat().st_size for p in outcome.written)
        print(f"wrote {len(outcome.written)} reference files ({size / 1e6:.2f} MB) to "
              f"{_relative(reference_directory(args.algorithm))}/ in {wall:.0f} s; report {outcome.report}")
        return 0
    passed = sum(c.passed for c in outcome.comparisons)
    print(f"{passed}/{len(outcome.comparisons)} cases pass in {wall:.0f} s; report {outcome.report}")
    if any("no reference" in c.message for c in outcome.comparisons):
        print("missing references: create them with `python -m harness regress --update`", file=sys.stderr)
    return 0 if outcome.passed else 1


def register(commands):
    regress_parser = commands.add_parser(
        "regress", help="compare every case with its reference result inside a tolerance tube (pyfunnel)")
    regress_parser.add_argument("scenarios", nargs="*", metavar="SCENARIO", type=cli_args.scenario,
                                help=f"scenario names (default: all: {', '.join(scenarios.scenario_names())})")
    regress_parser.add_argument("--controller", nargs="+", choices=variants.NAMES,
                                help="controllers (default: all)")
    regress_parser.add_argument("--update", action="store_true",
                                help="rewrite the reference results from this run (the only way they change)")
    regress_parser.add_argument("--report", default=str(DEFAULT_REPORT_DIR),
                                help="directory for report.md and the PNGs of failing signals (default results/regression)")
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
                                    help=f"pyfunnel tolerance {key} (default {value:g})")
    regress_parser.set_defaults(handler=regress_command)
