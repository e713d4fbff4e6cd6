"""Tuning the controller for a plant: ``python -m harness tune SCENARIO`` (docs/tuning.md).

The paper picks lambda_ce and kappa "by trial and error" and the rest by hand; this study searches
the controller's design parameters with an optimiser instead, on any scenario that wires our
controller (``AdaptiveFuzzyController``) to a plant.

Search space
    From the FMU's own variable table (``fmu_src/adaptive_fuzzy_controller_fmu.py``, the single
    source): every parameter that declares a :class:`Tuning` range and acts in the chosen variant
    at the controller's order.  ``log`` ranges are searched in log(value), ``log1m`` (lambda_ce)
    in log(1 - value), ``hurwitz`` (k3, k4) as a fraction of the Routh bound given the lower gains.
    The paper's conditions hold by construction or are checked before any run
    (:func:`paper_conditions`): every value inside its valid range (0 < lambda_ce < 1, gamma > 0,
    ...), k Hurwitz so that P of (30) is positive definite (the FMU's own test), |theta0| <= M_theta.

Optimiser and database
    Optuna (TPE by default, CMA-ES with ``--sampler cmaes``) with its RDB storage: SQLite by
    default (``sqlite:///results/tune/<scenario>.db``, write-ahead log), any SQLAlchemy URL with
    ``--storage``.  ``--jobs N`` keeps N trials in flight on a process pool: a finished one is told
    and the next one asked while the others run.  Several ``tune`` processes may drive one study
    (same ``--storage`` and study name); ``--trials N`` is the number of finished trials the study
    should hold, so a repeated or resumed command adds only the missing ones.  A killed run leaves
    its running trials RUNNING: the next run on the same host fails them and enqueues them again
    with the same parameters (a dead process on another host: after the heartbeat's grace period).
    The sampler is seeded per trial from ``--seed`` and the number of trials already in the study,
    so the same seed gives the same trials under sequential sampling: ``--jobs 1``, one process,
    the study run from empty without interruption.  In parallel the trials depend on the order in
    which runs finish; a resumed run retries the killed trials as new ones, so its later trials
    differ from an uninterrupted run's.

Pruned, not lost
    A candidate whose run diverges (the master's divergence stop, or an FMU that reports its
    state or adaptation diverged), fails, or makes u chatter (the controller FMU's own monitor,
    a warning in its log) is told as PRUNED with the reason; so is one that beats the best so far
    and whose objective moves by more than ``--verify-tolerance`` (1 %) when the run is repeated
    at half the step (a numerical artefact, not the controller).  The best trial is therefore
    always one re-run at half the step: its Richardson estimate 2 f(h/2) - f(h) and the error
    estimate |f(h) - (2 f(h/2) - f(h))| of every score are reported.

Outputs (``--out``, default results/tune/)
    ``<study>.toml``: the scenario with the best parameters, which ``run`` and ``regress`` take
    unchanged; ``<study>.json`` and ``<study>_*.png``; ``report.md``: every study of the folder
    (best-so-far curve, Pareto fronts ITAE vs Ec and vs TV(u), parameter importances, the tuned
    controller against the starting one on held-out scenarios) and the equal-effort comparison
    of the three controllers (``--compare``).
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import re
import signal
import socket
import sys
import tempfile
import threading
import time as clock
import warnings
from dataclasses import dataclass
from pathlib import Path

import build_fmu
import c_toolchain
import fmu_catalog
from fmu_src import afc_math
from fmu_src.afc_slave_base import Tuning

from .. import cli_args, master_loop, variants
from .. import scenario as scenarios
from ..cases import default_jobs, parallel_map, status_of
from ..fmi import ModelInfo
from ..master import Master, SimulationFailed, resolve_fmu
from ..scores import REFERENCE_PERIOD, SCORE_KEYS, score_run, undefined_reason, value_text, why_none
from . import step_study

CONTROLLER_MODEL = "AdaptiveFuzzyController"
DEFAULT_OUT = Path("results") / "tune"  # under the working directory, like the other studies
DEFAULT_TRIALS = 200
VERIFY_TOLERANCE = 0.01  # a best candidate whose objective moves more at half the step is an artefact
CHATTER_MARK = "u chatters"  # the controller FMU's chatter warning (fmu_src/chatter_monitor.py: warning)
HEARTBEAT_S = 10  # a running trial's heartbeat (Optuna's RDB heartbeat)
GRACE_S = 120  # a trial without heartbeat for this long belongs to a dead process: failed and retried
ORPHAN_S = 15  # a RUNNING trial still without owner this long after it started: its process died
SAMPLERS = ("tpe", "cmaes")
STATUSES = ("ok", "diverged", "failed", "chatter", "step-dependent", "infeasible", "undefined")
# held-out scenarios for the tuned-vs-start comparison: the other pendulum cases (disturbance, heavy pole)
HELD_OUT = {"pendulum_case1": ("pendulum_case2", "pendulum_case3")}
# --robust without --vary: the plant variations of each plant FMU (numbers, or xF: F times the scenario's value)
ROBUST_GRIDS = {
    "InvertedPendulum": (("mp", ("0.1", "1.0")), ("dist_gain", ("0", "1"))),  # the pendulum's cases 1-3 and 4th
    "Manipulator": (("mr0", ("x1", "x1.5")), ("cr", ("x1", "x2"))),
    "DcMotorArm": (("m", ("x1", "x2")), ("L", ("x1", "x2"))),
}
SCORE_ALIASES = {re.sub(r"[_\s]|pct$", "", key.lower()): key for key in SCORE_KEYS}  # tvu -> tv_u, es1 -> es1_pct


class TuneError(cli_args.UsageError):
    """A mistake in the tune command's input (exit 2, nothing written)."""


# ------------------------------------------------------------------ search space
@dataclass(frozen=True)
class Dimension:
    """One searched parameter: the FMU parameter, its range and how it is searched (Tuning.scale)."""

    parameter: str
    low: float
    high: float
    scale: str  # linear, log, log1m, hurwitz

    @property
    def name(self) -> str:
        """The optimiser's name for it (what the importances and the dashboard show)."""
        return {"log1m": f"1-{self.parameter}", "hurwitz": f"{self.parameter}_fraction"}.get(self.scale,
                                                                                             self.parameter)

    def bounds(self) -> tuple:
        """(low, high, log) of the optimiser's variable."""
        if self.scale == "log1m":
            return 1.0 - self.high, 1.0 - self.low, True
        return self.low, self.high, self.scale in ("log", "hurwitz")

    def describe(self) -> str:
        return {"linear": f"[{self.low:g}, {self.high:g}]", "log": f"[{self.low:g}, {self.high:g}] log",
                "log1m": f"[{self.low:g}, {self.high:g}], log(1 - value)",
                "hurwitz": f"fraction [{self.low:g}, {self.high:g}] (log) of the Routh bound"}[self.scale]


def declared_parameters() -> dict:
    """{name: Variable} of the controller FMU's parameters, from its declaration table."""

    return {v.name: v for v in build_fmu.model_class(CONTROLLER_MODEL).VARIABLES if v.causality == "parameter"}


def _acts(variable, variant: int, order: int) -> bool:
    tuning = variable.tuning
    return (not tuning.variants or variant in tuning.variants) and order >= tuning.order


def _inactive_reason(variable, variant: int, order: int) -> str:
    tuning = variable.tuning
    if tuning.variants and variant not in tuning.variants:
        names = {number: name for name, number in variants.CONTROLLER_VARIANTS.items()}
        return (f"it has no effect with controller {names.get(variant, variant)} (it acts in "
                f"{', '.join(names.get(v, str(v)) for v in tuning.variants)} only)")
    return f"it has no effect at order {order} (it acts from order {tuning.order})"


def search_space(variant: int, order: int, table: dict | None = None, only=None, ranges=None) -> list:
    """The searched dimensions, in table order.

    ``only``: names to search (default: every tunable parameter that acts in ``variant`` at
    ``order``); ``ranges``: {name: (low, high)} replacing declared ranges (the scale stays).
    A name the table does not know, one without a search range, one that does not act here, an
    empty or inverted range, or one leaving the valid range is a TuneError naming it.
    """

    table = declared_parameters() if table is None else table
    tunable = [name for name, v in table.items() if v.tuning is not None and _acts(v, variant, order)]
    ranges = dict(ranges or {})

    def check_name(name: str, option: str) -> None:
        if name not in table:
            raise TuneError(f"{option}: {CONTROLLER_MODEL} has no parameter {name!r}; tunable: {', '.join(tunable)}")
        variable = table[name]
        if variable.tuning is None:
            raise TuneError(f"{option}: parameter {name} is not tunable (the FMU's table gives it no search "
                            f"range); tunable: {', '.join(tunable)}")
        if not _acts(variable, variant, order):
            raise TuneError(f"{option}: parameter {name}: {_inactive_reason(variable, variant, order)}; "
                            f"tunable here: {', '.join(tunable)}")

    chosen = list(only) if only else list(tunable)
    for name in chosen:
        check_name(name, f"--params {name}")
    for name in ranges:
        check_name(name, f"--range {name}")
        if name not in chosen:
            chosen.append(name)
    dimensions = []
    for name in table:  # table order: k1, k2 before k3 (the Hurwitz fraction needs them)
        if name not in chosen:
            continue
        variable = table[name]
        low, high = ranges.get(name, (variable.tuning.low, variable.tuning.high))
        tuning = Tuning(low, high, variable.tuning.scale)
        problem = tuning.problem()
        if name in ranges:
            where = f"--range {name}={low:g}:{high:g}"
            if low < high and variable.tuning.scale != "hurwitz":
                for end in (low, high):
                    if variable.check(end) is not None:
                        raise TuneError(f"{where}: {end:g} is outside the valid range {variable.valid_range()} "
                                        f"of {name}")
            if problem:
                raise TuneError(f"{where}: {problem}")
        elif problem:
            raise TuneError(f"the FMU's table: {name}: {problem}")
        dimensions.append(Dimension(name, float(low), float(high), variable.tuning.scale))
    return dimensions


def search_space_markdown(table: dict | None = None) -> str:
    """The table of docs/tuning.md: every declared search range (tests/test_tune.py keeps the page current)."""
    table = declared_parameters() if table is None else table
    names = {number: name for name, number in variants.CONTROLLER_VARIANTS.items()}
    lines = ["| parameter | default | valid range | searched | acts in | from order |", "|---|---|---|---|---|---|"]
    for name, variable in table.items():
        tuning = variable.tuning
        if tuning is None:
            continue
        dimension = Dimension(name, tuning.low, tuning.high, tuning.scale)
        acts = ", ".join(names[v] for v in tuning.variants) if tuning.variants else "every controller"
        lines.append(f"| `{name}` | {variable.start:.6g} | {variable.valid_range()} | {dimension.describe()} | "
                     f"{acts} | {tuning.order} |")
    return "\n".join(lines)


def hurwitz_bound(i: int, k) -> float:
    """The supremum of k_i that keeps s^n + k1 s^(n-1) + ... + kn Hurwitz, given k1..k(i-1) > 0.

    Routh's array: n = 1, 2: every k > 0; k3 < k1 k2 (n >= 3); k4 < k3 (k1 k2 - k3) / k1^2
    (n = 4, with k3 < k1 k2).  The controller's orders go up to 4 (afc_math.ORDER_MAX).
    """
    if i <= 2:
        return math.inf
    if i == 3:
        return k[0] * k[1]
    if i == 4:
        return k[2] * (k[0] * k[1] - k[2]) / (k[0] * k[0])
    raise ValueError(f"no Hurwitz bound for k{i}: orders up to 4")


def _gain_index(name: str) -> int:
    return int(name[1:])


def parameter_values(dimensions, sample: dict, fixed: dict) -> dict:
    """The FMU values of the searched parameters from the optimiser's ``sample`` ({Dimension.name: x});
    ``fixed``: the other parameters' values (the lower gains a Hurwitz fraction refers to)."""
    values = {}
    for dimension in dimensions:
        x = sample[dimension.name]
        if dimension.scale == "log1m":
            values[dimension.parameter] = 1.0 - x
        elif dimension.scale == "hurwitz":
            i = _gain_index(dimension.parameter)
            k = [values.get(f"k{j}", fixed.get(f"k{j}")) for j in range(1, i)]
            values[dimension.parameter] = x * hurwitz_bound(i, k)
        else:
            values[dimension.parameter] = x
    return values


def sample_of(dimensions, values: dict) -> dict:
    """The optimiser's sample for FMU ``values`` (inverse of :func:`parameter_values`)."""
    sample = {}
    for dimension in dimensions:
        value = values[dimension.parameter]
        if dimension.scale == "log1m":
            sample[dimension.name] = 1.0 - value
        elif dimension.scale == "hurwitz":
            i = _gain_index(dimension.parameter)
            sample[dimension.name] = value / hurwitz_bound(i, [values[f"k{j}"] for j in range(1, i)])
        else:
            sample[dimension.name] = value
    return sample


def paper_conditions(values: dict, table: dict) -> str | None:
    """None if the controller's parameter ``values`` (all of them) meet the paper's conditions, else why not.

    Every value inside its valid range (0 < lambda_ce < 1, gamma, kappa_i, ... > 0); k1..kn Hurwitz so
    that P of (30) is positive definite (the FMU's own test: afc_math.lyapunov_p, is_positive_definite);
    the initial weights inside the projection bound, |theta0| <= M_theta (31).
    """

    for name, value in values.items():
        variable = table.get(name)
        if variable is not None:
            problem = variable.check(value)
            if problem:
                return problem
    n = int(values["order"])
    k = tuple(float(values[f"k{i}"]) for i in range(1, n + 1))
    q = tuple(float(values[f"q{i}"]) for i in range(1, n + 1))
    try:
        positive_definite = afc_math.is_positive_definite(afc_math.lyapunov_p(k, q))
    except ValueError:
        positive_definite = False
    if not positive_definite:
        return f"k = {k!r} is not Hurwitz (no positive definite P in (30))"
    if abs(values["theta0"]) > values["m_theta"]:
        return f"|theta0| = {abs(values['theta0']):g} > M_theta = {values['m_theta']:g} (31)"
    return None


# ---------------------------------------------------------- objective, constraints, grid
def score_name(text: str) -> str:
    """A score key of SCORE_KEYS from ``text`` (case and underscores free: itae, tvu, es1)."""
    key = re.sub(r"[_\s]|pct$", "", str(text).strip().lower())
    if key not in SCORE_ALIASES:
        raise TuneError(f"unknown score {text!r}; valid: {', '.join(SCORE_KEYS)}")
    return SCORE_ALIASES[key]


@dataclass(frozen=True)
class Constraint:
    score: str
    operator: str  # "<=" or ">="
    limit: float

    @property
    def text(self) -> str:
        return f"{self.score}{self.operator}{self.limit:g}"

    def violation(self, scores: dict) -> float:
        """<= 0: met (Optuna's convention); > 0: by how much it is missed."""
        value = scores[self.score]
        if value is None:  # ts of a run that never settles misses any bound on ts
            return math.inf
        return value - self.limit if self.operator == "<=" else self.limit - value


def parse_constraint(text: str) -> Constraint:
    match = re.fullmatch(r"\s*([A-Za-z_0-9 ]+?)\s*(<=|>=)\s*(\S+)\s*", str(text))
    if not match:
        raise TuneError(f"--constraint {text!r}: write SCORE<=LIMIT or SCORE>=LIMIT, e.g. \"umax<=20\"; "
                        f"scores: {', '.join(SCORE_KEYS)}")
    score = score_name(match.group(1))
    try:
        limit = float(match.group(3))
    except ValueError:
        raise TuneError(f"--constraint {text!r}: {match.group(3)!r} is not a number") from None
    if not math.isfinite(limit):
        raise TuneError(f"--constraint {text!r}: the limit must be finite")
    return Constraint(score, match.group(2), limit)


def parse_range(text: str) -> tuple:
    """``NAME=LOW:HIGH`` -> (name, low, high) (numbers only; the range itself is checked later)."""
    name, equals, span = str(text).partition("=")
    low, colon, high = span.partition(":")
    if not equals or not colon or not name.strip():
        raise TuneError(f"--range {text!r}: write NAME=LOW:HIGH, e.g. gamma=100:3000")
    try:
        numbers = float(low), float(high)
    except ValueError:
        raise TuneError(f"--range {text!r}: LOW and HIGH must be numbers") from None
    return name.strip(), *numbers


def parse_vary(text: str) -> tuple:
    """``INSTANCE.PARAMETER=V1,V2,...`` (numbers, or xF = F times the scenario's value) -> (dotted, values)."""
    dotted, equals, listed = str(text).partition("=")
    dotted = dotted.strip()
    items = [item.strip() for item in listed.split(",") if item.strip()]
    if not equals or "." not in dotted or not items:
        raise TuneError(f"--vary {text!r}: write INSTANCE.PARAMETER=V1,V2,... (numbers, or xF for F times the "
                        "scenario's value), e.g. plant.mp=0.1,1 or plant.m=x1,x2")
    for item in items:
        try:
            float(item[1:] if item.lower().startswith("x") else item)
        except ValueError:
            raise TuneError(f"--vary {text!r}: {item!r} is neither a number nor xF") from None
    return dotted, tuple(items)


def plant_instance(scenario) -> str:
    """The instance the controller's u drives."""
    source = scenario.signals.get("u", f"{scenario.controller_instance}.u")
    return next((c.target_instance for c in scenario.connections if c.source == source), "plant")


def robust_grid(scenario, varies, infos: dict) -> list:
    """The plant variations: [((dotted, value), ...), ...], the scenario itself first when it is on the grid.

    ``varies``: [(dotted, (item, ...))] from --vary, or empty for the default grid of the plant FMU.
    """
    import itertools

    if not varies:
        plant = plant_instance(scenario)
        identifier = infos[plant].model_identifier
        if identifier not in ROBUST_GRIDS:
            raise TuneError(f"--robust: no default grid for the plant {identifier}; give the variations with "
                            f"--vary INSTANCE.PARAMETER=V1,V2 (default grids: {', '.join(ROBUST_GRIDS)})")
        varies = [(f"{plant}.{name}", items) for name, items in ROBUST_GRIDS[identifier]]
    axes = []
    for dotted, items in varies:
        instance, _, name = dotted.partition(".")
        if instance not in scenario.components:
            raise TuneError(f"--vary {dotted}: unknown instance {instance!r}; valid: {', '.join(scenario.components)}")
        variable = infos[instance].variables.get(name)
        if variable is None or variable.causality != "parameter":
            valid = [n for n, v in infos[instance].variables.items() if v.causality == "parameter"]
            raise TuneError(f"--vary {dotted}: {instance} has no parameter {name!r}; valid: {', '.join(valid)}")
        base = scenario.components[instance].parameters.get(name, variable.start)
        values = []
        for item in items:
            value = float(base) * float(item[1:]) if item.lower().startswith("x") else float(item)
            if variable.type == "Integer":
                value = int(round(value))
            values.append(value)
        axes.append([(dotted, value) for value in dict.fromkeys(values)])
    return [tuple(point) for point in itertools.product(*axes)]


# ------------------------------------------------------------------ running a candidate
def with_values(scenario, controller_values: dict, variation=()) -> "scenarios.Scenario":
    """A copy of ``scenario`` with the controller's values and a plant variation set."""
    result = copy.deepcopy(scenario)
    result.components[scenario.controller_instance].parameters.update(controller_values)
    for dotted, value in variation:
        instance, _, name = dotted.partition(".")
        result.components[instance].parameters[name] = value
    return result


def half_step(scenario) -> "scenarios.Scenario":
    """The same run at half the communication step (twice the steps over the same horizon)."""
    result = copy.deepcopy(scenario)
    result.step = scenario.step / 2.0
    return result


EXTRACTION_PREFIX = "afc_tune_"  # afc_tune_<pid>_<model>_...: removed when the process ends (or by the next run)
_EXTRACTED = {}  # FMU path -> (ModelInfo, extracted folder, (mtime, size)): this process's, removed at exit


def prepared_fmus(scenario, fmu_paths: dict) -> dict:
    """{FMU path: (ModelInfo, folder)} of the scenario's FMUs, read and extracted once per process
    (a run of 40000 steps takes 0.06 s; extracting and reading three FMUs took as long again)."""
    import atexit

    from fmpy import extract


    if not _EXTRACTED:
        atexit.register(release_fmus)
        _remove_dead_extractions()
    for spec in scenario.components.values():
        path = resolve_fmu(spec.fmu, scenario, fmu_paths)
        stat = path.stat()
        stamp = (stat.st_mtime_ns, stat.st_size)
        if path in _EXTRACTED and _EXTRACTED[path][2] == stamp:
            continue
        if path in _EXTRACTED:  # rebuilt meanwhile: extract the new one
            import shutil

            shutil.rmtree(_EXTRACTED.pop(path)[1], ignore_errors=True)
        folder = tempfile.mkdtemp(prefix=f"{EXTRACTION_PREFIX}{os.getpid()}_{path.stem}_")
        extract(str(path), folder)
        _EXTRACTED[path] = (ModelInfo.read(path), folder, stamp)
    return {path: (info, folder) for path, (info, folder, _) in _EXTRACTED.items()}


def _remove_dead_extractions() -> None:
    """The extracted FMUs a killed ``tune`` process of this host left in the temporary folder."""
    import shutil

    for folder in Path(tempfile.gettempdir()).glob(f"{EXTRACTION_PREFIX}*"):
        pid = folder.name[len(EXTRACTION_PREFIX):].split("_", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _pid_alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)


def release_fmus() -> None:
    """Remove this process's extracted FMUs."""
    import shutil

    while _EXTRACTED:
        _, (_, folder, _) = _EXTRACTED.popitem()
        shutil.rmtree(folder, ignore_errors=True)


def run_point(scenario, fmu_paths: dict) -> dict:
    """One run: {"status", "reason", "scores", "wall_s"}; never raises for a failing run.

    ``chatter``: the run completed, but the controller FMU warned that u chatters (its own monitor,
    read from the FMU log the master keeps: ``Master.logs``).
    """

    began = clock.perf_counter()
    try:
        master = Master(scenario, fmu_paths=fmu_paths, prepared=prepared_fmus(scenario, fmu_paths))
        result = master.run()
    except SimulationFailed as failure:
        return {"status": status_of(failure), "reason": cli_args.one_line(failure), "scores": None,
                "wall_s": clock.perf_counter() - began}
    except Exception as error:  # noqa: BLE001 - a candidate that cannot run is an outcome
        return {"status": "failed", "reason": cli_args.one_line(error), "scores": None,
                "wall_s": clock.perf_counter() - began}
    scores = score_run(result)
    outcome = {"status": "ok", "reason": "", "scores": scores, "wall_s": clock.perf_counter() - began}
    chatter = next((line for line in master.logs.get(scenario.controller_instance, ()) if CHATTER_MARK in line),
                   None)
    if chatter is not None:
        outcome.update(status="chatter", reason=re.sub(r"^\[\w+\]\s*", "", chatter).split(": over the")[0])
    elif not all(value is None or math.isfinite(value) for value in scores.values()):  # None: scores.why_none
        outcome.update(status="failed", reason=f"a score is not finite: {scores}")
    return outcome


def worst_case(points: list) -> dict:
    """Every score's worst (largest) value over the grid points (every score: smaller is better)."""
    return {key: None if any(point["scores"][key] is None for point in points)  # not settled somewhere
            else max(point["scores"][key] for point in points) for key in SCORE_KEYS}


def relative_change(fine: float, coarse: float) -> float:
    return abs(fine - coarse) / abs(coarse) if coarse else (0.0 if fine == coarse else math.inf)


def richardson(fine: dict, coarse: dict) -> dict:
    """2 f(h/2) - f(h) for every score (the step study's extrapolation)."""
    return step_study.richardson(fine, coarse, metrics=defined_in_both(fine, coarse))


def error_estimates(fine: dict, coarse: dict) -> dict:
    """|f(h) - (2 f(h/2) - f(h))| = 2 |f(h) - f(h/2)|: the estimated error of the score at step h."""
    return {key: 2.0 * abs(coarse[key] - fine[key]) for key in defined_in_both(fine, coarse)}


def defined_in_both(fine: dict, coarse: dict) -> tuple:
    """The scores both runs define (ts is None where a run does not settle: scores.why_none)."""
    return tuple(key for key in coarse if coarse[key] is not None and fine.get(key) is not None)


def evaluate(task: dict) -> dict:
    """One candidate on every grid point (worker side; never raises for a failing run).

    ``task``: scenario (configured), values (controller parameters), grid, fmu_paths, objective,
    verify_below (re-run at half the step if the objective is below it), tolerance.
    """
    began = clock.perf_counter()
    scenario, grid = task["scenario"], task["grid"]
    points = []
    for variation in grid:
        point = run_point(with_values(scenario, task["values"], variation), task["fmu_paths"])
        point["variation"] = [list(item) for item in variation]
        points.append(point)
        if point["status"] != "ok":
            break
    outcome = {"status": "ok", "reason": "", "scores": None, "half_step": None, "points": points}
    bad = next((point for point in points if point["status"] != "ok"), None)
    if bad is not None:
        where = f" (at {', '.join(f'{d}={v:g}' for d, v in bad['variation'])})" if len(grid) > 1 else ""
        outcome.update(status=bad["status"], reason=bad["reason"] + where, scores=bad["scores"])
    else:
        outcome["scores"] = worst_case(points)
        objective = task["objective"]
        if outcome["scores"][objective] is None:  # ts of a run that never settles: no value to rank
            outcome.update(status="undefined", reason=f"{objective}: {why_none(objective, scenario.start, scenario.stop)}")
        elif outcome["scores"][objective] < task["verify_below"]:
            halves = [run_point(half_step(with_values(scenario, task["values"], variation)), task["fmu_paths"])
                      for variation in grid]
            failed = next((half for half in halves if half["status"] != "ok"), None)
            if failed is not None:
                outcome.update(status="step-dependent", reason=f"at half the step: {failed['status']}: "
                                                               f"{failed['reason']}")
            else:
                fine = worst_case(halves)
                change = (math.inf if fine[objective] is None
                          else relative_change(fine[objective], outcome["scores"][objective]))
                outcome["half_step"] = {"step": scenario.step / 2.0, "scores": fine, "change": change,
                                        "richardson": richardson(fine, outcome["scores"]),
                                        "error": error_estimates(fine, outcome["scores"])}
                if change > task["tolerance"]:
                    coarse = outcome["scores"][objective]
                    outcome.update(status="step-dependent",
                                   reason=f"{objective} {coarse:.6g} at step {scenario.step:g} s, "
                                          f"{value_text(objective, fine[objective], scenario.start, scenario.stop)} at half the step ({100 * change:.3g} % > "
                                          f"{100 * task['tolerance']:g} %)")
    outcome["wall_s"] = clock.perf_counter() - began
    return outcome


def _ignore_interrupts():  # pool workers: Ctrl-C is the parent's to handle (it lets the round finish)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


# ------------------------------------------------------------------ the configuration
@dataclass
class TuneConfig:
    scenario: object  # name or .toml path
    controller: str = "vud"
    objective: str = "ITAE"
    constraints: tuple = ()
    trials: int = DEFAULT_TRIALS
    seed: int = 0
    storage: str | None = None  # None: sqlite:///<out>/<scenario>.db
    study: str | None = None  # None: <scenario>-<controller>-<objective>[-robust]
    sampler: str = "tpe"
    jobs: int = 1
    stop: float | None = None
    edition: str = "python"
    robust: bool = False
    vary: tuple = ()
    params: tuple = ()
    ranges: tuple = ()  # ((name, low, high), ...)
    out: Path = DEFAULT_OUT
    tolerance: float = VERIFY_TOLERANCE
    held_out: tuple | None = None  # None: HELD_OUT of the scenario
    quiet: bool = False
    fmu_paths: dict | None = None


@dataclass
class Prepared:
    """Everything checked before the database is opened."""

    config: TuneConfig
    scenario: object  # the configured Scenario (controller variant, stop)
    table: dict
    dimensions: list
    fixed: dict  # every controller parameter's value before tuning (table start values, then the scenario's)
    grid: list
    constraints: tuple
    fmu_paths: dict
    study_name: str
    storage_url: str
    signature: dict
    held_out: tuple


def _digest(scenario) -> str:
    data = {"start": scenario.start,  # stop and step are signature entries of their own
            "components": {n: [c.fmu, sorted(c.parameters.items())] for n, c in scenario.components.items()},
            "connections": [[c.source, c.target] for c in scenario.connections],
            "signals": sorted(scenario.signals.items()), "bounds": sorted(scenario.bounds.items()),
            "divergence_bound": scenario.divergence_bound}
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:16]


def prepare(config: TuneConfig) -> Prepared:
    """Check every input (TuneError names the culprit); nothing is written and no database is opened."""

    if config.controller not in variants.NAMES:
        raise TuneError(f"unknown controller {config.controller!r}; valid: {', '.join(variants.NAMES)}")
    if config.sampler not in SAMPLERS:
        raise TuneError(f"unknown sampler {config.sampler!r}; valid: {', '.join(SAMPLERS)}")
    objective = score_name(config.objective)
    constraints = tuple(parse_constraint(c) if isinstance(c, str) else c for c in config.constraints)
    if config.trials < 1:
        raise TuneError(f"--trials {config.trials}: give a whole number >= 1")
    if not 0 < config.tolerance:
        raise TuneError(f"--verify-tolerance: give a number > 0 (percent), not {100 * config.tolerance:g}")
    scenario = scenarios.configure(config.scenario, config.controller, stop=config.stop)
    for score in dict.fromkeys((objective, *(c.score for c in constraints))):
        reason = undefined_reason(score, scenario.start, scenario.stop)
        if reason is not None:
            raise TuneError(f"{score} is not defined on this run: {reason}; give --stop of at least "
                            f"{scenario.start + REFERENCE_PERIOD:.4g} s or another score")
    fmu_paths = config.fmu_paths
    if fmu_paths is None:

        fmu_paths = build_fmu.ensure_built(edition=config.edition)
    infos = {name: ModelInfo.read(resolve_fmu(spec.fmu, scenario, fmu_paths))
             for name, spec in scenario.components.items()}
    controller = scenario.controller_instance
    if infos[controller].model_identifier != CONTROLLER_MODEL:
        raise TuneError(f"tune searches the parameters of {CONTROLLER_MODEL}; the scenario's controller_instance "
                        f"{controller!r} is {infos[controller].model_identifier}")
    table = declared_parameters()
    fixed = {name: v.start for name, v in table.items()}
    fixed.update(scenario.components[controller].parameters)
    variant, order = int(fixed["variant"]), int(fixed["order"])
    ranges = {}
    for name, low, high in config.ranges:
        ranges[name] = (low, high)
    dimensions = search_space(variant, order, table, only=config.params, ranges=ranges)
    if not dimensions:
        raise TuneError("nothing to search: no tunable parameter acts here")
    problem = paper_conditions(fixed, table)
    if problem:
        raise TuneError(f"the scenario's controller parameters: {problem}")
    grid = [()]
    if config.robust or config.vary:
        grid = robust_grid(scenario, [parse_vary(v) if isinstance(v, str) else v for v in config.vary], infos)
        for point in grid:  # values the FMUs reject (a mass < 0, ...) are usage errors, before anything runs
            cli_args.check_assignments(scenario, list(point), fmu_paths, option="--vary")
    held_out = tuple(config.held_out) if config.held_out is not None else HELD_OUT.get(scenario.name, ())
    for name in held_out:
        scenarios.load(name)
    study_name = config.study or "-".join(
        [scenario.name, config.controller, objective]
        + [f"{c.score}{'le' if c.operator == '<=' else 'ge'}{c.limit:g}" for c in constraints]
        + (["robust"] if len(grid) > 1 else []))
    storage_url = config.storage or f"sqlite:///{Path(config.out) / scenario.name}.db"
    signature = {"scenario": scenario.name, "scenario_digest": _digest(scenario), "controller": config.controller,
                 "objective": objective, "constraints": sorted(c.text for c in constraints),
                 "grid": [[list(item) for item in point] for point in grid], "step": scenario.step,
                 "stop": scenario.stop, "edition": config.edition, "sampler": config.sampler,
                 "space": [[d.parameter, d.low, d.high, d.scale] for d in dimensions],
                 "tolerance": config.tolerance}
    config.objective = objective
    return Prepared(config, scenario, table, dimensions, fixed, grid, constraints, fmu_paths, study_name,
                    storage_url, signature, held_out)


# ------------------------------------------------------------------ database and study
def _quiet_optuna():
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    warnings.filterwarnings("ignore", module=r"optuna(\..*)?")
    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)


def _sqlite_pragmas(storage) -> None:
    """Write-ahead log, fsync at checkpoints: 10x fewer milliseconds per trial than SQLite's default
    rollback journal, and a committed trial survives a killed process (not a power cut)."""
    from sqlalchemy import event

    @event.listens_for(storage.engine, "connect")
    def _on_connect(connection, _record):
        cursor = connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.close()

    storage.engine.dispose()  # connections opened from here on get the pragmas


def open_storage(url: str):
    """Optuna's RDB storage at ``url`` with heartbeats; a database that cannot be opened is a TuneError."""
    import optuna

    _quiet_optuna()
    sqlite = url.startswith("sqlite")
    for attempt in range(10):
        try:
            storage = optuna.storages.RDBStorage(
                url, engine_kwargs={"connect_args": {"timeout": 120}} if sqlite else None,
                heartbeat_interval=HEARTBEAT_S, grace_period=GRACE_S,
                heartbeat_stale_trial_callback=optuna.storages.RetryHeartbeatStaleTrialCallback())
            if sqlite:
                _sqlite_pragmas(storage)
            storage.get_all_studies()
            return storage
        except Exception as error:  # noqa: BLE001 - any driver's error: one line, exit 2
            text = cli_args.one_line(error)
            racing = ("already exists", "alembic_version", "database is locked")  # another process creates it now
            if any(word in text for word in racing) and attempt < 9:
                clock.sleep(0.2 * (attempt + 1))
                continue
            raise TuneError(f"--storage {url}: cannot open the database: {text}") from None


def _signature_difference(stored: dict, wanted: dict) -> list:
    names = {"scenario_digest": "the scenario's components, connections or bounds (digest)"}
    return [f"{names.get(key, key)} = {json.dumps(stored.get(key))} (now {json.dumps(wanted.get(key))})"
            for key in wanted if stored.get(key) != wanted.get(key)]


def open_study(prepared: Prepared, storage):
    """Create the study (with the starting parameters as its first trial) or load it; a study of the
    same name made with other settings is a TuneError (nothing written)."""
    import optuna

    name = prepared.study_name
    try:
        storage.get_study_id_from_name(name)
        exists = True
    except KeyError:
        exists = False
    if not exists:
        try:
            study = optuna.create_study(storage=storage, study_name=name, direction="minimize")
        except optuna.exceptions.DuplicatedStudyError:  # another process created it meanwhile
            exists = True
        else:
            study.set_user_attr("signature", prepared.signature)
            start = sample_of(prepared.dimensions, prepared.fixed)
            study.enqueue_trial(start, user_attrs={"start": True}, skip_if_exists=False)
            return study
    study = optuna.load_study(study_name=name, storage=storage)
    check_signature(study, prepared)
    return study


def check_signature(study, prepared: Prepared) -> None:
    """A TuneError unless the existing ``study`` was made with ``prepared``'s settings (reads only)."""
    name = prepared.study_name
    for _ in range(100):  # a study another process is creating gets its signature within moments
        stored = study.user_attrs.get("signature")
        if stored is not None:
            break
        clock.sleep(0.1)
    else:
        raise TuneError(f"study {name!r} in {prepared.storage_url} was not made by tune (no signature); "
                        "name another study with --study NAME")
    differences = _signature_difference(stored, prepared.signature)
    if differences:
        raise TuneError(f"study {name!r} in {prepared.storage_url} was made with other settings: "
                        f"{'; '.join(differences)}; resume it with its settings or name another study with "
                        "--study NAME")


def check_existing(prepared: Prepared) -> None:
    """Before a run of several studies: an existing study of the same name must have the same settings
    (an SQLite file that is not there yet is not created here)."""
    import optuna

    url = prepared.storage_url
    if url.startswith("sqlite:///"):
        path = url[len("sqlite:///"):]
        if path != ":memory:" and not Path(path).exists():
            return
    storage = open_storage(url)
    try:
        storage.get_study_id_from_name(prepared.study_name)
    except KeyError:
        return
    check_signature(optuna.load_study(study_name=prepared.study_name, storage=storage), prepared)


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, TypeError, ValueError, OverflowError):
        return True
    return True


def _age_s(trial) -> float:
    """Seconds since the trial started (Optuna stores local naive times)."""
    import datetime

    started = trial.datetime_start
    return (datetime.datetime.now() - started).total_seconds() if started else math.inf


def recover_dead_trials(study, mine=()) -> tuple:
    """RUNNING trials of a dead ``tune`` process: failed, and enqueued again with the same parameters
    (Optuna's retry: system attribute failed_trial).  Returns (their numbers, how many trials have no
    owner yet but are younger than ORPHAN_S: a process claims its trial right after asking it).

    A trial's owner (host, pid) is written right after it is asked; one of this host whose process is
    gone is recovered at once, one without an owner once it is ORPHAN_S old (its process died between
    the two writes), one of another host by the heartbeat's grace period (fail_stale_trials).
    """
    import optuna
    from optuna.trial import TrialState

    host, me = socket.gethostname(), os.getpid()
    retry = optuna.storages.RetryHeartbeatStaleTrialCallback()
    recovered, waiting = [], 0
    for trial in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        if trial.number in mine:
            continue
        owner = trial.user_attrs.get("owner")
        if owner is None:
            if _age_s(trial) < ORPHAN_S:
                waiting += 1
                continue
            reason = "its process ended between asking for the trial and claiming it"
        else:
            if owner.get("host") != host or (owner.get("pid") != me and _pid_alive(owner.get("pid"))):
                continue
            reason = f"its process (pid {owner.get('pid')}) ended before the trial did"
        try:
            study._storage.set_trial_user_attr(trial._trial_id, "outcome", {
                "status": "lost", "reason": f"{reason}; run again as a new trial"})
            if not study._storage.set_trial_state_values(trial._trial_id, state=TrialState.FAIL):
                continue
        except optuna.exceptions.UpdateFinishedTrialError:
            continue
        retry(study, study._storage.get_trial(trial._trial_id))
        recovered.append(trial.number)
    return recovered, waiting


class _Heartbeat:
    """Records Optuna heartbeats for this process's running trials (ask-and-tell has no thread of its own)."""

    def __init__(self, storage):
        from optuna.storages._heartbeat import is_heartbeat_enabled

        self.storage, self.ids, self.lock = storage, set(), threading.Lock()
        self.enabled = is_heartbeat_enabled(storage)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True, name="tune-heartbeat")
        if self.enabled:
            self.thread.start()

    def add(self, trial_id: int):
        if self.enabled:
            self.storage.record_heartbeat(trial_id)
            with self.lock:
                self.ids.add(trial_id)

    def remove(self, trial_id: int):
        with self.lock:
            self.ids.discard(trial_id)

    def _run(self):
        while not self.stop.wait(self.storage.get_heartbeat_interval()):
            with self.lock:
                ids = list(self.ids)
            for trial_id in ids:
                try:
                    self.storage.record_heartbeat(trial_id)
                except Exception:  # noqa: BLE001 - a missed beat is retried at the next interval
                    pass

    def close(self):
        self.stop.set()
        if self.enabled:
            self.thread.join(timeout=5)


def sampler_for(kind: str, seed: int, count: int, x0: dict | None = None):
    """A sampler seeded for the trial asked when the study holds ``count`` trials (see the module text)."""
    import optuna

    trial_seed = (seed * 1_000_003 + count) % (2 ** 32)
    if kind == "cmaes":
        return optuna.samplers.CmaEsSampler(seed=trial_seed, x0=x0, warn_independent_sampling=False)
    return optuna.samplers.TPESampler(seed=trial_seed)


def outcome_of(trial) -> dict:
    return trial.user_attrs.get("outcome") or {}


def is_feasible(trial) -> bool:
    """Every constraint met (Optuna: every constraint value <= 0)."""
    constraints = trial.constraints or {}
    return all(value <= 0.0 for value in (constraints.values() if isinstance(constraints, dict) else constraints))


def best_trial(trials):
    """The best COMPLETE, feasible trial that was re-run at half the step; None if there is none."""
    from optuna.trial import TrialState

    candidates = [t for t in trials if t.state == TrialState.COMPLETE and is_feasible(t)
                  and outcome_of(t).get("half_step")]
    return min(candidates, key=lambda t: (t.value, t.number)) if candidates else None


# ------------------------------------------------------------------ the loop
def _progress_line(trial, state: str, outcome: dict, objective: str, best, total: int) -> str:
    value = (outcome.get("scores") or {}).get(objective)
    text = f"trial {trial.number:4d}/{total} {state:8s}"
    text += f" {objective} {value:.6g}" if value is not None else ""
    if outcome.get("status") not in ("ok", None):
        text += f"  [{outcome['status']}] {outcome.get('reason', '')[:110]}"
    if best is not None:
        text += f"  best {best[0]:.6g} (#{best[1]})"
    return text + f"  {outcome.get('wall_s', 0.0):.2f} s"


def _tell(study, trial, values: dict, outcome: dict, prepared: Prepared):
    """Store the outcome and tell the trial: COMPLETE with the objective, else PRUNED; returns the state."""
    from optuna.trial import TrialState

    objective = prepared.config.objective
    record = {key: outcome.get(key) for key in ("status", "reason", "scores", "half_step", "wall_s")}
    record["parameters"] = values
    if len(prepared.grid) > 1:
        record["points"] = [{"variation": p.get("variation"), "status": p["status"], "scores": p["scores"]}
                            for p in outcome.get("points", ())]
    state = TrialState.COMPLETE if outcome["status"] == "ok" else TrialState.PRUNED
    violations = {}
    if state == TrialState.COMPLETE and prepared.constraints:
        violations = {c.text: c.violation(outcome["scores"]) for c in prepared.constraints}
        record["constraints"] = outcome["constraints"] = violations
        if prepared.config.sampler == "cmaes" and any(v > 0 for v in violations.values()):
            state = TrialState.PRUNED  # CMA-ES reads no constraints: it learns from complete trials only
            record.update(status="infeasible", reason="; ".join(f"{k} missed by {v:.4g}" for k, v in
                                                                   violations.items() if v > 0))
    trial.set_user_attr("outcome", record)
    if state == TrialState.COMPLETE:
        for text, violation in violations.items():
            trial.set_constraint(text, violation)
        study.tell(trial, outcome["scores"][objective])
    else:
        study.tell(trial, state=TrialState.PRUNED)
    return state


class _Inline:
    """The executor of ``--jobs 1``: the candidate runs in this process when submitted (sequential sampling)."""

    def submit(self, function, argument):
        from concurrent.futures import Future

        future = Future()
        future.set_result(function(argument))
        return future

    def shutdown(self, wait=True, cancel_futures=False):
        pass


def _best_of(trials) -> tuple | None:
    best = best_trial(trials)
    return None if best is None else (best.value, best.number)


def _ask(study, prepared: Prepared, heartbeat, owner: dict, x0, pending: list, log, best, count: int):
    """Ask one trial (the study holding ``count`` trials) and sample it; returns (trial, values) to run,
    or None when it needs no run (surplus of a shared budget, or told PRUNED as infeasible at once)."""
    import optuna
    from optuna.trial import TrialState

    config = prepared.config
    study.sampler = sampler_for(config.sampler, config.seed, count, x0)
    trial = study.ask()
    pending.append(trial)
    try:
        trial.set_user_attr("owner", owner)  # claimed: recover_dead_trials knows whose it is
    except optuna.exceptions.UpdateFinishedTrialError:
        # another process found it unclaimed for ORPHAN_S (a machine under heavy load), counted it lost
        # and queued its parameters again: it is not ours to run
        pending.remove(trial)
        return None
    heartbeat.add(trial._trial_id)
    alive = sorted(t.number for t in study.get_trials(deepcopy=False) if t.state != TrialState.FAIL)
    if alive.index(trial.number) >= config.trials:  # other processes filled the budget meanwhile
        trial.set_user_attr("outcome", {"status": "surplus", "reason": "the study's budget was reached by other "
                                                                       "processes; not run"})
        study.tell(trial, state=TrialState.FAIL)
        pending.remove(trial)
        heartbeat.remove(trial._trial_id)
        return None
    sample = {}
    for dimension in prepared.dimensions:
        low, high, log_scale = dimension.bounds()
        sample[dimension.name] = trial.suggest_float(dimension.name, low, high, log=log_scale)
    values = parameter_values(prepared.dimensions, sample, prepared.fixed)
    problem = paper_conditions({**prepared.fixed, **values}, prepared.table)
    if problem:  # a k3 kept fixed (--params) beyond the Routh bound of searched k1, k2; a fraction at its edge
        outcome = {"status": "infeasible", "reason": problem, "wall_s": 0.0}
        _tell(study, trial, values, outcome, prepared)
        pending.remove(trial)
        heartbeat.remove(trial._trial_id)
        log(_progress_line(trial, "pruned", outcome, config.objective, best, config.trials))
        return None
    return trial, values


def run_study(prepared: Prepared, study, log=None) -> dict:
    """Run trials until the study holds ``trials`` finished ones; returns counts and timings of this call.

    ``--jobs 1``: ask, run, tell, one trial after the other (sequential sampling: with the same seed
    on an empty study, the same trials).  ``--jobs N``: N trials in flight on a process pool; a
    finished one is told and the next one asked while the others run (asynchronous: the trials
    depend on the order in which runs finish).
    """
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    import optuna
    from optuna.trial import TrialState

    config = prepared.config
    log = log or (lambda line: None)
    finished_states = (TrialState.COMPLETE, TrialState.PRUNED)
    heartbeat = _Heartbeat(study._storage)
    recovered, _ = recover_dead_trials(study)
    if recovered:
        log(f"note: trials {', '.join(map(str, recovered))} of a killed run are run again (same parameters)")
    owner = {"host": socket.gethostname(), "pid": os.getpid()}
    x0 = sample_of(prepared.dimensions, prepared.fixed) if config.sampler == "cmaes" else None
    if config.jobs > 1:

        master_loop.library()  # the compiled loop, once, before the workers start
        executor = ProcessPoolExecutor(max_workers=config.jobs, mp_context=multiprocessing.get_context("spawn"),
                                       initializer=_ignore_interrupts)
    else:
        executor = _Inline()
    pending, in_flight = [], {}
    ran, began, simulated, stale_checked = 0, clock.perf_counter(), 0.0, -math.inf
    try:
        while True:
            while len(in_flight) < config.jobs:
                if clock.monotonic() - stale_checked > HEARTBEAT_S:  # trials of dead processes elsewhere
                    optuna.storages.fail_stale_trials(study)
                    stale_checked = clock.monotonic()
                trials = study.get_trials(deepcopy=False)
                finished = sum(t.state in finished_states for t in trials)
                running = sum(t.state == TrialState.RUNNING for t in trials)
                if finished + running >= config.trials:
                    if in_flight:
                        break
                    mine = {trial.number for trial in pending}
                    recovered, waiting = recover_dead_trials(study, mine)
                    if recovered:
                        log(f"note: trials {', '.join(map(str, recovered))} of a killed run are run again")
                    elif waiting:  # a trial nobody has claimed yet: its process may have died right after asking
                        clock.sleep(1.0)
                    else:
                        break
                    continue
                best = _best_of(trials)  # every process's: the verification threshold
                asked = _ask(study, prepared, heartbeat, owner, x0, pending, log, best, len(trials))
                if asked is None:
                    continue
                trial, values = asked
                task = {"scenario": prepared.scenario, "values": values, "grid": prepared.grid,
                        "fmu_paths": prepared.fmu_paths, "objective": config.objective,
                        "verify_below": best[0] if best is not None else math.inf,
                        "tolerance": config.tolerance}
                in_flight[executor.submit(evaluate, task)] = (trial, values)
            if not in_flight:
                break
            done, _ = wait(list(in_flight), return_when=FIRST_COMPLETED)
            for future in sorted(done, key=lambda f: in_flight[f][0].number):
                trial, values = in_flight.pop(future)
                outcome = future.result()
                pending.remove(trial)
                heartbeat.remove(trial._trial_id)
                try:
                    state = _tell(study, trial, values, outcome, prepared)
                except optuna.exceptions.UpdateFinishedTrialError:  # failed as lost by another process,
                    log(f"note: trial {trial.number} was counted lost by another process, which runs its "
                        "parameters again; this run of it is not recorded")
                    continue
                ran += 1
                simulated += outcome.get("wall_s", 0.0)
                value = outcome["scores"][config.objective] if state == TrialState.COMPLETE else None
                if (value is not None and outcome.get("half_step") and not any(
                        v > 0 for v in outcome.get("constraints", {}).values())
                        and (best is None or (value, trial.number) < best)):
                    best = (value, trial.number)
                log(_progress_line(trial, "complete" if state == TrialState.COMPLETE else "pruned", outcome,
                                   config.objective, best, config.trials))
    except BaseException:
        for trial in pending:  # interrupted: these run again next time, with the same parameters
            try:
                study._storage.set_trial_user_attr(trial._trial_id, "outcome", {
                    "status": "lost", "reason": "interrupted; run again as a new trial"})
                frozen = study._storage.get_trial(trial._trial_id)
                study.tell(trial, state=TrialState.FAIL)
                optuna.storages.RetryHeartbeatStaleTrialCallback()(study, frozen)
            except Exception:  # noqa: BLE001 - what cannot be told is recovered by the next run
                pass
        raise
    finally:
        heartbeat.close()
        executor.shutdown(wait=True, cancel_futures=True)
    return {"ran": ran, "wall_s": clock.perf_counter() - began, "simulated_s": simulated}


# ------------------------------------------------------------------ results: the scenario file
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key)


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)  # the shortest text that reads back as the same double
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {value!r}")


def scenario_toml(scenario, comments=()) -> str:
    """The text of a scenario file (the format of harness/scenarios/*.toml) for ``scenario``;
    an FMU file relative to the original scenario is written as an absolute path."""
    lines = [f"# {line}" if line else "#" for line in comments]
    lines += [f"name = {_toml_value(scenario.name)}", f"description = {_toml_value(scenario.description)}",
              f"controller_instance = {_toml_value(scenario.controller_instance)}", "", "[experiment]",
              f"start = {_toml_value(float(scenario.start))}", f"stop = {_toml_value(float(scenario.stop))}",
              f"step = {_toml_value(float(scenario.step))}",
              f"divergence_bound = {_toml_value(float(scenario.divergence_bound))}"]
    for name, spec in scenario.components.items():
        fmu = spec.fmu
        if fmu.endswith(".fmu") and not Path(fmu).is_absolute() and scenario.path is not None:
            fmu = str((scenario.path.parent / fmu).resolve())
        lines += ["", f"[components.{_toml_key(name)}]", f"fmu = {_toml_value(fmu)}",
                  f"parameters = {_toml_value(dict(spec.parameters))}"]
    for connection in scenario.connections:
        lines += ["", "[[connections]]", f"from = {_toml_value(connection.source)}",
                  f"to = {_toml_value(connection.target)}"]
    if scenario.bounds:
        lines += ["", "[bounds]"] + [f"{_toml_key(k)} = {_toml_value(float(v))}" for k, v in scenario.bounds.items()]
    lines += ["", "[signals]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in scenario.signals.items()]
    lines += ["", "[record]", f"variables = {_toml_value(list(scenario.record))}", ""]
    return "\n".join(lines)


def tuned_scenario(prepared: Prepared, values: dict):
    """The configured scenario with the tuned values (and its variant) set, named after the study (the
    file's stem, which regress names its reference files after)."""
    tuned = with_values(prepared.scenario, values)
    tuned.name = _safe(prepared.study_name)
    tuned.description = (f"{prepared.scenario.description} -- controller {prepared.config.controller} tuned by "
                         f"`python -m harness tune` ({prepared.config.objective})")
    return tuned


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def write_tuned_toml(prepared: Prepared, trial, path: Path) -> Path:
    outcome = outcome_of(trial)
    objective = prepared.config.objective
    scores = outcome["scores"]
    tuned = tuned_scenario(prepared, outcome["parameters"])
    edition = prepared.config.edition
    comments = [f"Tuned by `python -m harness tune` (docs/tuning.md): study {prepared.study_name!r} in "
                f"{prepared.storage_url}, trial #{trial.number}.",
                f"{objective} = {scores[objective]!r} at step {prepared.scenario.step:g} s with the {edition} "
                f"edition" + (" (worst case over the --robust grid; this file is its base point)"
                              if len(prepared.grid) > 1 else "") + ".",
                f"Reproduce: python -m harness run {path} --controller {prepared.config.controller} --edition "
                f"{edition}",
                f"Regression: python -m harness regress {path} --controller {prepared.config.controller} "
                "[--update]", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    text = scenario_toml(tuned, comments)
    scenarios.parse(scenarios.tomllib.loads(text), path)  # it reads back as a scenario
    path.write_text(text)
    return path


# ------------------------------------------------------------------ results: summary, figures, report
def pareto_front(points) -> list:
    """Indices of the points (x, y) no other point beats in both (both minimised), by increasing x."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best_y = [], math.inf
    for i in order:
        if points[i][1] < best_y:
            front.append(i)
            best_y = points[i][1]
    return front


def best_so_far(trials) -> list:
    """[(trial number, best feasible objective until then)] over the COMPLETE trials, by number."""
    from optuna.trial import TrialState

    curve, best = [], math.inf
    for trial in sorted(trials, key=lambda t: t.number):
        if trial.state == TrialState.COMPLETE and is_feasible(trial) and trial.value < best:
            best = trial.value
        if trial.state in (TrialState.COMPLETE, TrialState.PRUNED):
            curve.append((trial.number, best))
    return curve


def importances(study) -> tuple:
    """(Optuna's parameter importances {name: share} over the COMPLETE trials, evaluator or why there are none)."""
    import optuna
    from optuna.trial import TrialState

    complete = [t for t in study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    if len(complete) < 4:
        return {}, f"too few complete trials ({len(complete)})"
    try:
        evaluator = optuna.importance.PedAnovaImportanceEvaluator()
        return dict(optuna.importance.get_param_importances(study, evaluator=evaluator)), "PED-ANOVA (Optuna)"
    except Exception as error:  # noqa: BLE001 - the report says why
        return {}, cli_args.one_line(error)


def _figure_progress(summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(7, 4), layout="constrained")
    values = summary["trial_values"]
    if values:
        axes.scatter([v[0] for v in values], [v[1] for v in values], s=8, color="0.6", label="complete trials")
    curve = [(n, b) for n, b in summary["best_so_far"] if math.isfinite(b)]
    if curve:
        axes.step([c[0] for c in curve], [c[1] for c in curve], where="post", color="C0", label="best so far")
    if summary.get("start"):
        axes.axhline(summary["start"]["scores"][summary["objective"]], color="C3", linestyle="--",
                     label="starting parameters")
    axes.set_yscale("log")
    axes.set_xlabel("trial")
    axes.set_ylabel(summary["objective"])
    axes.set_title(f"{summary['study']}: best so far")
    axes.legend(loc="upper right", fontsize=8)
    figure.savefig(path, dpi=110)
    plt.close(figure)


def _figure_pareto(summary: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, panels = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    points = summary["pareto_points"]
    for panel, (key, label) in zip(panels, (("Ec", "Ec = int u^2 dt"), ("tv_u", "TV(u) per second"))):
        xy = [(p["ITAE"], p[key]) for p in points]
        if xy:
            panel.scatter([p[0] for p in xy], [p[1] for p in xy], s=8, color="0.65", label="complete trials")
            front = [xy[i] for i in pareto_front(xy)]
            panel.plot([p[0] for p in front], [p[1] for p in front], "o-", color="C0", markersize=4,
                       label="Pareto front")
        for which, marker, color in (("start", "s", "C3"), ("best", "*", "C2")):
            if summary.get(which):
                scores = summary[which]["scores"]
                panel.scatter([scores["ITAE"]], [scores[key]], marker=marker, s=80, color=color, zorder=5,
                              label=f"{which} (#{summary[which]['number']})")
        panel.set_xscale("log")
        panel.set_yscale("log")
        panel.set_xlabel("ITAE")
        panel.set_ylabel(label)
        panel.legend(fontsize=8)
    figure.suptitle(f"{summary['study']}: ITAE against control effort and smoothness")
    figure.savefig(path, dpi=110)
    plt.close(figure)


def held_out_runs(prepared: Prepared, values: dict, pool_jobs: int) -> list:
    """The starting and the tuned controller on each held-out scenario (same stop as the tuning)."""

    tasks, labels = [], []
    for name in prepared.held_out:
        scenario = scenarios.configure(name, prepared.config.controller, stop=prepared.config.stop)
        for label, controller_values in (("start", {}), ("tuned", values)):
            tasks.append({"scenario": scenario, "values": controller_values, "grid": [()],
                          "fmu_paths": prepared.fmu_paths, "objective": prepared.config.objective,
                          "verify_below": -math.inf, "tolerance": prepared.config.tolerance})
            labels.append((name, label))
    outcomes = parallel_map(evaluate, tasks, pool_jobs) if tasks else []
    rows = {}
    for (name, label), outcome in zip(labels, outcomes):
        rows.setdefault(name, {"scenario": name})[label] = {"status": outcome["status"], "reason": outcome["reason"],
                                                            "scores": outcome["scores"]}
    return list(rows.values())


def summarize(prepared: Prepared, study, run_info: dict | None = None) -> dict:
    """Everything the report shows of one study, as plain data (written to <study>.json)."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)
    objective = prepared.config.objective
    counts = {}
    for trial in trials:
        status = outcome_of(trial).get("status", trial.state.name.lower())
        if trial.state == TrialState.COMPLETE and not is_feasible(trial):
            status = "infeasible"  # complete, a constraint missed: kept for the sampler, never best
        counts[status] = counts.get(status, 0) + 1
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    best = best_trial(trials)
    start = next((t for t in sorted(trials, key=lambda t: t.number) if t.user_attrs.get("start")
                  and outcome_of(t).get("scores")), None)

    def entry(trial):
        if trial is None:
            return None
        outcome = outcome_of(trial)
        return {"number": trial.number, "state": trial.state.name, "status": outcome.get("status"),
                "reason": outcome.get("reason"), "value": outcome["scores"][objective], "scores": outcome["scores"],
                "half_step": outcome.get("half_step"), "parameters": outcome.get("parameters"),
                "points": outcome.get("points")}

    first_trial_began = min((t.datetime_start for t in trials if t.datetime_start), default=None)
    last_complete = max((t.datetime_complete for t in trials if t.datetime_complete), default=None)
    span = (last_complete - first_trial_began).total_seconds() if first_trial_began and last_complete else None
    finished = sum(t.state in (TrialState.COMPLETE, TrialState.PRUNED) for t in trials)
    first_better = None
    if start is not None:
        reference = outcome_of(start)["scores"][objective]
        first_better = next((n for n, b in best_so_far(trials) if b < reference), None)
    importance, evaluator = importances(study)
    summary = {
        "study": prepared.study_name, "storage": prepared.storage_url, "scenario": prepared.scenario.name,
        "controller": prepared.config.controller, "objective": objective,
        "constraints": [c.text for c in prepared.constraints], "sampler": prepared.config.sampler,
        "edition": prepared.config.edition, "step": prepared.scenario.step, "stop": prepared.scenario.stop,
        "grid": [[list(item) for item in point] for point in prepared.grid], "seed": prepared.config.seed,
        "tolerance": prepared.config.tolerance,
        "space": [{"parameter": d.parameter, "name": d.name, "range": d.describe(),
                   "start": prepared.fixed[d.parameter]} for d in prepared.dimensions],
        "trials": len(trials), "finished": finished, "counts": counts, "span_s": span,
        "states": {state: sum(t.state.name == state for t in trials) for state in ("COMPLETE", "PRUNED", "FAIL")},
        "run": run_info, "best": entry(best), "start": entry(start), "first_better": first_better,
        "best_so_far": best_so_far(trials),
        "trial_values": [(t.number, t.value) for t in complete],
        "pareto_points": [{"number": t.number, **{k: outcome_of(t)["scores"][k] for k in ("ITAE", "Ec", "tv_u")}}
                          for t in complete],
        "importances": importance, "importance_evaluator": evaluator,
    }
    return summary


def _g(value, digits: int = 6) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "n/a"
    return f"{value:.{digits}g}"


def study_markdown(summary: dict, folder: Path) -> str:
    """The report section of one study."""
    objective = summary["objective"]
    name = summary["study"]
    lines = [f"## Study `{name}`", ""]
    horizon = f"{summary['stop']:g} s"
    grid = summary["grid"]
    lines.append(f"Scenario `{summary['scenario']}`, controller `{summary['controller']}`, objective {objective}"
                 + (f" (worst case over {len(grid)} plant variations)" if len(grid) > 1 else "")
                 + (f", constraints {', '.join(summary['constraints'])}" if summary["constraints"] else "")
                 + f"; horizon {horizon}, step {summary['step']:g} s, {summary['edition']} edition, sampler "
                 f"{summary['sampler']}, seed {summary['seed']}; database `{summary['storage']}` "
                 f"(`optuna-dashboard {summary['storage']}` shows it live).")
    counts = ", ".join(f"{count} {status}" for status, count in sorted(summary["counts"].items()))
    lines += ["", f"**Trials**: {summary['finished']} finished of {summary['trials']} ({counts})."]
    run = summary.get("run")
    if run and run.get("ran"):
        lines.append(f"This run: {run['ran']} trials in {run['wall_s']:.1f} s wall on {run.get('jobs', 1)} "
                     f"process(es) ({run['ran'] / run['wall_s']:.2f} trials/s; {run['simulated_s']:.1f} s in the "
                     "co-simulations).")
    if len(grid) > 1:
        lines.append("Plant variations: " + "; ".join(", ".join(f"{d}={v:g}" for d, v in point) for point in grid)
                     + ".")
    start, best = summary.get("start"), summary.get("best")
    lines += ["", "### Best parameters", ""]
    if best is None:
        lines.append("No trial finished complete, feasible and verified at half the step: nothing to report "
                     "as best.")
    else:
        improvement = ""
        if start is not None:
            improvement = (f" against {_g(start['value'])} for the starting parameters (trial #{start['number']}); "
                           f"first better than the start at trial #{summary['first_better']}")
        half = best["half_step"]
        lines.append(f"Trial #{best['number']}: {objective} = {_g(best['value'])}{improvement}. Re-run at half "
                     f"the step ({half['step']:g} s): {objective} {_g(half['scores'][objective])} "
                     f"({100 * half['change']:.3g} % change; limit {100 * summary['tolerance']:g} %). Scenario "
                     f"file: `{summary['study_file']}`.")
        lines += ["", "| parameter | searched | start | tuned |", "|---|---|---|---|"]
        for dimension in summary["space"]:
            tuned = best["parameters"].get(dimension["parameter"])
            lines.append(f"| `{dimension['parameter']}` | {dimension['range']} | {_g(dimension['start'])} | "
                         f"{_g(tuned)} |")
        lines += ["", "| score | start | tuned at h | tuned at h/2 | Richardson 2 f(h/2) - f(h) | "
                  "error estimate of tuned at h |", "|---|---|---|---|---|---|"]
        for key in SCORE_KEYS:
            lines.append(f"| {key} | {_g(start['scores'][key]) if start else 'n/a'} | {_g(best['scores'][key])} | "
                         f"{_g(half['scores'][key])} | {_g(half['richardson'].get(key))} | {_g(half['error'].get(key), 3)} |")
    lines += ["", f"![best so far]({name}_progress.png)", "",
              f"![Pareto fronts]({name}_pareto.png)", ""]
    lines += ["### Parameter importances", ""]
    if summary["importances"]:
        lines.append(f"{summary['importance_evaluator']}, over the complete trials:")
        lines += ["", "| parameter | importance |", "|---|---|"]
        lines += [f"| `{k}` | {v:.3f} |" for k, v in sorted(summary["importances"].items(), key=lambda kv: -kv[1])]
    else:
        lines.append(f"None: {summary['importance_evaluator']}.")
    held = summary.get("held_out") or []
    if held:
        lines += ["", "### Tuned against starting parameters on held-out scenarios", "",
                  f"Tuned on `{summary['scenario']}` only; the same controller parameters on scenarios the search "
                  "never saw:", "", "| scenario | controller | " + " | ".join(SCORE_KEYS) + " |",
                  "|---|---|" + "---|" * len(SCORE_KEYS)]
        for row in held:
            for label in ("start", "tuned"):
                result = row.get(label, {})
                if result.get("scores") and result.get("status") == "ok":
                    cells = " | ".join(_g(result["scores"][k], 4) for k in SCORE_KEYS)
                else:
                    cells = f"{result.get('status')}: {result.get('reason', '')}" + " |" * (len(SCORE_KEYS) - 1)
                lines.append(f"| {row['scenario']} | {label} | {cells} |")
    return "\n".join(lines) + "\n"


def write_study_outputs(prepared: Prepared, study, run_info: dict | None, held_out: bool = True,
                        jobs: int = 1) -> dict:
    """<study>.toml (when there is a best), <study>.json, the two figures; returns the summary."""
    out = Path(prepared.config.out)
    out.mkdir(parents=True, exist_ok=True)
    base = _safe(prepared.study_name)
    summary = summarize(prepared, study, run_info)
    summary["study_file"] = None
    best = best_trial(study.get_trials(deepcopy=False))
    if best is not None:
        path = write_tuned_toml(prepared, best, out / f"{base}.toml")
        summary["study_file"] = str(path)
        if held_out and prepared.held_out:
            summary["held_out"] = held_out_runs(prepared, outcome_of(best)["parameters"], jobs)
    _figure_progress(summary, out / f"{base}_progress.png")
    _figure_pareto(summary, out / f"{base}_pareto.png")
    (out / f"{base}.json").write_text(json.dumps(summary, indent=1, default=str))
    return summary


# ------------------------------------------------------------------ the equal-effort comparison
def compare_rows(summaries: list) -> list:
    """One row per study of the comparison: start and tuned objective with their error estimates."""
    rows = []
    for summary in summaries:
        objective = summary["objective"]
        row = {"scenario": summary["scenario"], "controller": summary["controller"], "study": summary["study"],
               "objective": objective, "finished": summary["finished"], "counts": summary["counts"],
               "states": summary.get("states", {})}
        for which in ("start", "best"):
            entry = summary.get(which)
            half = (entry or {}).get("half_step")
            row[which] = None if entry is None else {
                "number": entry["number"], "value": entry["value"], "scores": entry["scores"],
                "error": half["error"] if half else None, "parameters": entry.get("parameters")}
        rows.append(row)
    return rows


def smallest(rows: list, which: str, key: str) -> dict:
    """Which controller has the smallest ``key`` (start or best), and is it apart beyond the numerical errors?"""
    present = [r for r in rows if r.get(which)]
    if not present:
        return {"controller": None, "separated": False, "text": "no result"}
    ranked = sorted(present, key=lambda r: r[which]["scores"][key])
    winner = ranked[0]

    def error(row):
        errors = row[which].get("error")
        return errors[key] if errors else math.nan

    high = winner[which]["scores"][key] + (error(winner) if math.isfinite(error(winner)) else 0.0)
    separated = all(high < r[which]["scores"][key] - (error(r) if math.isfinite(error(r)) else 0.0)
                    for r in ranked[1:]) and all(math.isfinite(error(r)) for r in ranked)
    return {"controller": winner["controller"], "separated": separated,
            "values": {r["controller"]: (r[which]["scores"][key], error(r)) for r in ranked}}


def beats(rows: list, which: str, key: str, first: str, second: str) -> dict:
    """Does ``first`` have a smaller ``key`` than ``second`` beyond their numerical errors?"""
    by = {r["controller"]: r for r in rows if r.get(which)}
    if first not in by or second not in by:
        return {"answer": "no result"}
    a, b = by[first][which], by[second][which]
    ea = (a.get("error") or {}).get(key, math.nan)
    eb = (b.get("error") or {}).get(key, math.nan)
    va, vb = a["scores"][key], b["scores"][key]
    if not (math.isfinite(ea) and math.isfinite(eb)):
        answer = "yes" if va < vb else "no"
        answer += " (no error estimate)"
    elif va + ea < vb - eb:
        answer = "yes"
    elif vb + eb < va - ea:
        answer = "no"
    else:
        answer = "undecided: the difference is within the numerical errors"
    return {"answer": answer, first: (va, ea), second: (vb, eb)}


def comparison_markdown(comparison: dict) -> str:
    seeds = comparison["seeds"]
    key = comparison["objective"]
    lines = ["## The paper's comparison under equal tuning effort", "",
             f"Every controller tuned with the same budget ({comparison['trials']} trials per study, sampler "
             f"{comparison['sampler']}, objective {key}"
             + (f", constraints {', '.join(comparison['constraints'])}" if comparison.get("constraints") else "")
             + ") over the same search space where they share parameters "
             "(lambda_ce and kappa_i act in vud only, gamma_w in fae only: the FMU's table), "
             f"{len(seeds)} time(s) with seeds {', '.join(map(str, seeds))}: an optimiser's result varies with "
             "its seed, and that spread is part of the answer. Trial 0 of every study is the scenario's own "
             "parameters (the paper's values). Each value is at the scenario's step h, +- the estimated "
             "numerical error |f(h) - (2 f(h/2) - f(h))| from the re-run at half the step (Richardson, as in the "
             "step study).", ""]

    def cell(entry, score):
        if not entry:
            return "n/a"
        error = (entry.get("error") or {}).get(score)
        return _g(entry["scores"][score], 5) + (f" +- {error:.2g}" if error is not None else "")

    for scenario, block in comparison["scenarios"].items():
        lines += [f"### {scenario}", "", f"| controller | seed | {key}, paper's parameters | {key}, tuned | "
                  "Ec, tuned | TV(u)/s, tuned | umax, tuned | best trial | finished trials (pruned) |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for repeat in block["repeats"]:
            for row in repeat["rows"]:
                start, best = row.get("start"), row.get("best")
                pruned = row.get("states", {}).get("PRUNED", 0)
                lines.append(f"| {row['controller']} | {repeat['seed']} | {cell(start, key)} | {cell(best, key)} | "
                             f"{cell(best, 'Ec')} | {cell(best, 'tv_u')} | {cell(best, 'umax')} | "
                             f"{'#' + str(best['number']) if best else 'n/a'} | {row['finished']} ({pruned}) |")
        lines.append("")
        for repeat in block["repeats"]:
            for verdict in repeat["verdicts"]:
                lines.append(f"- seed {repeat['seed']}: **{verdict['question']}** {verdict['answer']}")
        for verdict in block.get("overall", ()):
            lines.append(f"- **{verdict['question']}** {verdict['answer']}")
        lines.append("")
    return "\n".join(lines)


def overall_verdicts(scenario_name: str, order: int, repeats: list, key: str) -> list:
    """The claims over every seed: in how many repetitions does each answer come out?"""
    found = []
    count = len(repeats)
    if scenario_name.startswith("pendulum"):
        winners = [smallest(r["rows"], "best", key) for r in repeats]
        vud = sum(w["controller"] == "vud" for w in winners)
        apart = sum(w["controller"] == "vud" and w["separated"] for w in winners)
        others = ", ".join(f"{w['controller']} (seed {r['seed']})" for w, r in zip(winners, repeats)
                           if w["controller"] != "vud")
        found.append({"question": f"Over all seeds: does vud give the smallest {key} on the pendulum when every "
                                  "controller is tuned?",
                      "answer": f"in {vud} of {count} repetition(s) ({apart} apart beyond the numerical errors)"
                                + (f"; otherwise {others}" if others else "") + "."})
    if order >= 3:
        answers = [beats(r["rows"], "best", key, "fae", "vud")["answer"] for r in repeats]
        yes = sum(a == "yes" for a in answers)
        no = sum(a == "no" for a in answers)
        found.append({"question": "Over all seeds: does fae beat vud on the third-order plant when both are tuned?",
                      "answer": f"yes in {yes}, no in {no}, undecided in {count - yes - no} of {count} "
                                "repetition(s)."})
    return found


def verdicts_for(scenario_name: str, order: int, rows: list, key: str) -> list:
    """The paper's claims re-checked on one scenario: the smallest score before and after tuning;
    on the pendulum: is vud still the smallest; on a plant of order 3 or more: does fae still beat vud?"""
    found = []

    def describe(result):
        if result["controller"] is None:
            return "no result"
        values = ", ".join(f"{c} {_g(v, 5)}" + (f" +- {e:.2g}" if math.isfinite(e) else "")
                           for c, (v, e) in result["values"].items())
        apart = "apart beyond the numerical errors" if result["separated"] else \
            "not apart beyond the numerical errors"
        return f"{result['controller']} ({values}; {apart})"

    before, after = smallest(rows, "start", key), smallest(rows, "best", key)
    if scenario_name.startswith("pendulum"):
        answer = ("yes" if after["controller"] == "vud" and after["separated"] else
                  "yes, but within the numerical errors" if after["controller"] == "vud" else
                  f"no: {after['controller']} has it")
        found.append({"question": f"Does vud still give the smallest {key} on the pendulum when every controller "
                                  "is tuned?", "answer": f"{answer}. Tuned: {describe(after)}. With the paper's "
                                                          f"parameters: {describe(before)}."})
    if order >= 3:
        for which, label in (("start", "with the pendulum's (paper's) parameters"), ("best", "all tuned")):
            result = beats(rows, which, key, "fae", "vud")
            if result["answer"] == "no result":
                continue
            va, ea = result["fae"]
            vb, eb = result["vud"]
            found.append({"question": f"Does fae beat vud on the third-order plant ({label})?",
                          "answer": f"{result['answer']} (fae {_g(va, 5)} +- {ea:.2g}, vud {_g(vb, 5)} +- "
                                    f"{eb:.2g})."})
    if not found:
        found.append({"question": f"Smallest {key} when every controller is tuned:", "answer": describe(after)})
    return found


# ------------------------------------------------------------------ report.md
def write_report(out: Path) -> Path:
    """report.md of the folder: the comparison (if run) and every study whose <study>.json is there."""
    out = Path(out)
    summaries = []
    for path in sorted(out.glob("*.json")):
        if path.name == "comparison.json":
            continue
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(data, dict) and "study" in data and "best_so_far" in data:
            summaries.append(data)
    parts = ["# Tuning report", "",
             "Generated by `python -m harness tune` (docs/tuning.md) from the studies in this folder. Every "
             "best value was re-run at half the communication step; candidates that diverged, failed, made u "
             "chatter (the controller FMU's warning) or moved by more than the tolerance at half the step are "
             "pruned and counted, never reported as best.", ""]
    order = list(variants.NAMES)
    summaries.sort(key=lambda m: (m["scenario"], m["seed"], order.index(m["controller"])
                                  if m["controller"] in order else 9, m["study"]))
    if summaries:
        parts += ["| study | seed | trials (pruned) | best | start | scenario file |", "|---|---|---|---|---|---|"]
        for m in summaries:
            best, start = m.get("best"), m.get("start")
            pruned = m.get("states", {}).get("PRUNED", 0)
            link = f"[`{m['study']}`](#study-{m['study'].lower()})"
            parts.append(f"| {link} | {m['seed']} | {m['finished']} ({pruned}) | "
                         f"{m['objective']} {_g(best['value'], 5) if best else 'n/a'} | "
                         f"{_g(start['value'], 5) if start else 'n/a'} | "
                         f"{'`' + Path(m['study_file']).name + '`' if m.get('study_file') else 'none'} |")
        parts.append("")
    comparison_path = out / "comparison.json"
    if comparison_path.exists():
        try:
            parts.append(comparison_markdown(json.loads(comparison_path.read_text())))
        except (KeyError, TypeError, ValueError) as error:  # written by another version of this module
            parts.append(f"(comparison.json not shown: {cli_args.one_line(error)}; run `tune --compare` again)\n")
    for summary in summaries:
        parts.append(study_markdown(summary, out))
    path = out / "report.md"
    path.write_text("\n".join(parts))
    return path


# ------------------------------------------------------------------ command line
def tune(config: TuneConfig, log=None, outputs: bool = True) -> dict:
    """Prepare, open the study, run it, write the outputs; returns the study's summary (plain data)."""
    prepared = prepare(config)
    out = Path(config.out)
    if config.storage is None:
        out.mkdir(parents=True, exist_ok=True)
    storage = open_storage(prepared.storage_url)
    study = open_study(prepared, storage)
    log = log or (lambda line: None)
    log(f"study {prepared.study_name!r} in {prepared.storage_url}: {len(prepared.dimensions)} parameters "
        f"({', '.join(d.name for d in prepared.dimensions)}), {config.edition} edition, {config.jobs} process(es)")
    try:
        run_info = run_study(prepared, study, log)
        run_info["jobs"] = config.jobs
        if not outputs:
            summary = summarize(prepared, study, run_info)
            summary["study_file"] = None
            return summary
        summary = write_study_outputs(prepared, study, run_info, jobs=config.jobs)
    finally:
        release_fmus()  # those of --jobs 1 (the workers remove theirs when they exit)
    write_report(out)
    return summary


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
                      jobs=args.jobs or default_jobs(), stop=args.stop, edition=args.edition or default_edition(),
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
          f"{_g(best['value']) if best else 'n/a'} (#{best['number'] if best else '-'}); "
          f"target 200 trials within 60 s: {target}")
    return 0


def compare_command(args, out: Path, log) -> int:
    """``--compare``: vud, fixed and fae tuned with the same budget on each scenario, ``--repeats`` seeds."""
    controllers = variants.NAMES
    objective = score_name(args.objective)
    seeds = [args.seed + r for r in range(args.repeats)]
    plan = []
    for name in args.scenarios:
        scenario_name = scenarios.load(name).name
        for seed in seeds:
            for controller in controllers:
                config = _config_from(args, name, controller, out)
                config.seed = seed
                if seed != seeds[0]:  # the first repetition is the study a plain `tune` makes
                    config.study = f"{prepare(copy.copy(config)).study_name}-seed{seed}"
                plan.append((scenario_name, seed, config))
    for _, _, config in plan:  # every usage error (and a study of the same name made otherwise) before any trial
        check_existing(prepare(copy.copy(config)))
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
    try:
        import optuna  # noqa: F401
    except ImportError:
        raise TuneError("tune needs Optuna: pip install -e '.[tune]' (optuna, optuna-dashboard, cmaes)") from None
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
    print(f"  report {out / 'report.md'}; dashboard: optuna-dashboard {summary['storage']}")
    return 0


def _without_option(error) -> str:
    """The message without its leading "--option 'text': " (argparse names the option itself)."""
    return re.sub(r"^--[\w-]+ '[^']*': ", "", str(error))


def _range_argument(text: str) -> tuple:
    try:
        return parse_range(text)
    except TuneError as error:
        import argparse

        raise argparse.ArgumentTypeError(_without_option(error)) from None


def _score_argument(text: str) -> str:
    try:
        return score_name(text)
    except TuneError as error:
        import argparse

        raise argparse.ArgumentTypeError(str(error)) from None


def _constraint_argument(text: str) -> Constraint:
    try:
        return parse_constraint(text)
    except TuneError as error:
        import argparse

        raise argparse.ArgumentTypeError(_without_option(error)) from None


def _vary_argument(text: str) -> tuple:
    try:
        return parse_vary(text)
    except TuneError as error:
        import argparse

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
    command.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
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


__all__ = ["TuneConfig", "tune", "search_space", "hurwitz_bound", "parameter_values", "sample_of",
           "paper_conditions", "evaluate", "pareto_front", "scenario_toml", "register"]
