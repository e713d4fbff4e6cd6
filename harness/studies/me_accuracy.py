"""Model Exchange against the converged co-simulation: ``python -m harness me-accuracy [--apply]``.

Accuracy without a step (docs/model_exchange.md): every case of Table I/II (4 scenarios x vud,
fixed, fae) and the third-order plant (motor_arm, vud) runs in Model Exchange
(harness/me_master.py, native edition) at the relative tolerances ``--rtols`` (default 1e-6,
1e-8, 1e-10) and is compared with the converged co-simulation:

* ITAE, IAE and Ec against the step study's converged values (Richardson extrapolation of our
  feedthrough master, harness/studies/step_study.py, committed in
  harness/scenarios/convergence.json); motor_arm is not in the step study, so its converged values
  are computed here by the same rule (halving from the scenario's step until the change is below
  0.1 %, or 0.5 % in the first-order regime, then 2 f(h/2) - f(h));
* every score (ts, es1, es2, ITAE, IAE, Ec, umax, tv_u) at the tolerance ``--compare-rtol``
  (1e-8) against a co-simulation ladder from the scenario's step down to an eighth of it: the
  Richardson value of its two finest runs (marked unsettled when the ladder has not converged for
  that score), the finest run for ts (read off the grid: its resolution is the step);
* for the manipulator, where the link sticks: the intervals in which Model Exchange holds it at
  rest (its stuck friction mode) and what co-simulation does there (dy chattering around 0, u
  zig-zagging with it): the evidence of which result is the model's.

The output grid of every Model Exchange run is the scenario's step (the scores read the same
grid as the co-simulation).  The study goes to results/me_accuracy/; ``--apply`` also writes
docs/model_exchange_accuracy.md.
"""
from __future__ import annotations

import json
import math
import sys
import time as clock
from pathlib import Path

import numpy as np

from harness.fmu_build import builder as build_fmu

from .. import atomic_files, cli_args, me_master, variants
from .. import scenario as scenarios
from ..cases import Case, default_jobs, run_cases
from ..master import simulate
from ..me_master import ALGORITHM as MODEL_EXCHANGE
from ..scores import SCORE_KEYS
from .step_study import halving_converged, load_convergence, richardson

ROOT = Path(__file__).resolve().parents[2]
DOCS_PAGE = ROOT / "docs" / "model_exchange_accuracy.md"
DEFAULT_OUT = Path("results") / "me_accuracy"
PAPER_SCENARIOS = ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator")
BEYOND = (("motor_arm", variants.PROPOSED),)  # the third-order plant: not in the step study
RTOLS = (1e-6, 1e-8, 1e-10)
COMPARE_RTOL = 1e-8
TARGET = 5e-4  # every score within 0.05 % of the converged co-simulation at COMPARE_RTOL
METRICS = ("ITAE", "IAE", "Ec")
FRICTION_SCENARIOS = ("manipulator",)  # where the stuck mode's evidence is gathered
GRID_READ = ("ts",)  # read off the output grid: compared with the finest co-simulation, within its step
LEVELS = 4  # the co-simulation ladder of the other scores: the scenario's step down to step / 8


def study_cases(names=PAPER_SCENARIOS, controllers=variants.NAMES, beyond=BEYOND) -> list:
    """(scenario, controller) of every case: Table I/II and the cases beyond the paper."""
    return [(n, c) for n in names for c in controllers] + [tuple(b) for b in beyond]


def co_simulation_ladder(cases: list, stop, jobs: int, levels: int = LEVELS) -> dict:
    """{(scenario, controller): [outcome at h, h/2, ..., h / 2^(levels - 1)]} from the scenario's step h."""
    ladders = {(n, c): [Case(n, c, step=scenarios.load(n).step / 2 ** k, stop=stop) for k in range(levels)]
               for n, c in cases}
    flat = sorted((case for ladder in ladders.values() for case in ladder), key=lambda case: case.step)
    outcomes = dict(zip(flat, run_cases(flat, jobs=jobs, description="co-simulation ladders")))
    return {key: [outcomes[case] for case in ladder] for key, ladder in ladders.items()}


def converged_values(key: tuple, ladder: list, convergence: dict, stop) -> dict:
    """The reference of each score: {score: (value, how, converged)}: ITAE, IAE, Ec from the step study (motor_arm:
    this ladder by the step study's rule); the other scores the Richardson value of this ladder's two finest runs,
    converged when their last change is below the target or shrank like the step (the first-order regime); ts
    the finest run (read off the grid)."""
    fine, coarse = ladder[-1], ladder[-2]
    if fine["status"] != "ok" or coarse["status"] != "ok":
        return {}
    values = {}
    for k in SCORE_KEYS:
        if any(run[k] is None for run in ladder):  # not defined on this horizon (harness/scores.py says why)
            continue
        if k in GRID_READ:
            values[k] = (fine[k], f"co-simulation at {fine['step']:g} s (read off its grid)", True)
            continue
        changes = [abs(b[k] - a[k]) / abs(b[k]) if b[k] else math.inf for a, b in zip(ladder, ladder[1:])]
        first_order = len(changes) >= 2 and changes[-1] > 0 and 1.6 <= changes[-2] / changes[-1] <= 2.5
        settled = changes[-1] < TARGET or first_order
        values[k] = (2.0 * fine[k] - coarse[k], f"Richardson from {coarse['step']:g} s (last change "
                     f"{100 * changes[-1]:.2g} %)", settled)
    study = convergence.get("scenarios", {}).get(key[0], {}).get("controllers", {}).get(key[1], {}).get("converged")
    if study and stop is None:
        values.update({m: (study[m], f"step study: {study['method']}", True) for m in METRICS})
    elif stop is None:  # not in the step study (motor_arm): its rule on this ladder
        used = next((i for i in range(2, len(ladder) + 1) if halving_converged(ladder[:i])), len(ladder))
        levels = ladder[:used]
        extrapolated = richardson(levels[-1], levels[-2])
        values.update({m: (extrapolated[m], f"step study's rule here: Richardson from {levels[-2]['step']:g} s",
                           True) for m in METRICS})
    return values


def relative(value: float, reference: float) -> float:
    return (value - reference) / abs(reference) if reference else math.inf


def accuracy_study(cases: list, rtols=RTOLS, compare_rtol: float = COMPARE_RTOL, stop=None,
                   jobs: int | None = None) -> dict:
    """Every case in Model Exchange at every tolerance, against the converged co-simulation."""
    jobs = jobs or default_jobs()
    began = clock.perf_counter()
    convergence = load_convergence()
    tolerances = sorted(set(rtols) | {compare_rtol}, reverse=True)
    me_cases = [Case(n, c, stop=stop, algorithm=MODEL_EXCHANGE, rtol=r) for n, c in cases for r in tolerances]
    me_outcomes = dict(zip(me_cases, run_cases(me_cases, jobs=jobs, description="Model Exchange runs")))
    ladders = co_simulation_ladder(cases, stop, jobs)
    rows = []
    for name, controller in cases:
        ladder = ladders[(name, controller)]
        reference = converged_values((name, controller), ladder, convergence, stop)
        runs = []
        for rtol in tolerances:
            outcome = me_outcomes[Case(name, controller, stop=stop, algorithm=MODEL_EXCHANGE, rtol=rtol)]
            entry = {k: outcome.get(k) for k in ("rtol", "status", "reason", "steps", "derivative_evaluations",
                                                 "state_events", "wall_s", "step", *SCORE_KEYS)}
            entry["rtol"] = rtol
            if outcome["status"] == "ok" and reference:
                defined = [k for k in SCORE_KEYS if k in reference and outcome[k] is not None]
                entry["error"] = {k: relative(outcome[k], reference[k][0]) for k in defined if k not in GRID_READ}
                entry["error"].update({k: outcome[k] - reference[k][0] for k in defined if k in GRID_READ})
            runs.append(entry)
        rows.append({"scenario": name, "controller": controller, "step": scenarios.load(name).step,
                     "reference": {k: {"value": v, "how": how, "converged": ok} for k, (v, how, ok) in reference.items()},
                     "co_simulation": [{k: o.get(k) for k in ("step", "status", "reason", *SCORE_KEYS)} for o in ladder],
                     "runs": runs})
    fmu_paths = build_fmu.ensure_built()
    stick = [stick_evidence(n, c, min(tolerances), stop, fmu_paths) for n, c in cases if n in FRICTION_SCENARIOS]
    return {"rtols": tolerances, "compare_rtol": compare_rtol, "target": TARGET, "stop": stop, "rows": rows,
            "stick": stick, "wall_s": clock.perf_counter() - began, "jobs": jobs}


def run_at(row: dict, rtol: float) -> dict:
    return next(r for r in row["runs"] if math.isclose(r["rtol"], rtol))


def score_within(row: dict, rtol: float, key: str) -> bool:
    run = run_at(row, rtol)
    error = (run.get("error") or {}).get(key)
    if run["status"] != "ok" or error is None:
        return False
    if key in GRID_READ:  # read off the grid: the co-simulation's own ts moves by a step per halving
        return abs(error) <= 2 * row["step"] * (1 + 1e-9)
    return abs(error) <= TARGET


def within_target(row: dict, rtol: float, keys=SCORE_KEYS) -> bool:
    """Every score (``keys``) within the target at ``rtol`` (ts: within two output steps)."""
    return all(score_within(row, rtol, k) for k in keys)


def stick_evidence(name: str, controller: str, rtol: float, stop, fmu_paths: dict | None = None) -> dict:
    """Where the link sticks: the intervals in which the Model Exchange run rests (dy exactly 0, the stuck
    friction mode), and there the total variation of u and the sign changes of dy in co-simulation (fixed-step
    RK4 of sgn(x2): no stuck mode) at the scenario's step and a quarter of it, against Model Exchange."""
    scenario = scenarios.configure(name, controller, None, stop)
    me = me_master.simulate(scenario, fmu_paths, rtol)
    resting = me.signal("plant.dy") == 0.0
    intervals, first = [], None
    for k, rest in enumerate(resting):
        if rest and first is None:
            first = k
        if (not rest or k == len(resting) - 1) and first is not None:
            last = k if rest else k - 1
            if last > first:
                intervals.append((float(me.time[first]), float(me.time[last])))
            first = None

    def inside(time):
        mask = np.zeros(len(time), dtype=bool)
        for a, b in intervals:
            mask |= (time >= a) & (time <= b)
        return mask

    def variation(result):
        mask = inside(result.time)
        both = mask[1:] & mask[:-1]
        du = np.abs(np.diff(result.signal("controller.u")))
        return float(du[both].sum()), float(du[~both].sum())

    evidence = {"scenario": name, "controller": controller, "intervals": intervals,
                "me": dict(zip(("tv_inside", "tv_outside"), variation(me))), "co_simulation": []}
    for factor in (1, 4):
        cs = simulate(scenarios.configure(name, controller, scenario.step / factor, stop), fmu_paths=fmu_paths)
        mask = inside(cs.time)
        dy = cs.signal("plant.dy")[mask]
        tv_inside, tv_outside = variation(cs)
        evidence["co_simulation"].append({"step": cs.scenario.step, "tv_inside": tv_inside, "tv_outside": tv_outside,
                                          "sign_changes": int(np.sum(np.diff(np.sign(dy)) != 0)),
                                          "max_dy": float(np.max(np.abs(dy))) if dy.size else 0.0})
    return evidence


def every_score_table(study: dict, rtol: float) -> list:
    lines = ["", f"## Every score at rtol {rtol:g}", "",
             "Relative difference from the converged co-simulation (ts: in seconds; within two output steps "
             "counts, the co-simulation's own ts moves by a step per halving). A difference in **bold** is beyond "
             f"{100 * TARGET:g} %; *unsettled* marks a score whose co-simulation ladder had not settled (last change "
             f"above {100 * TARGET:g} % and not shrinking like the step), so its reference is not converged.", "",
             "| case | " + " | ".join(SCORE_KEYS) + " |", "|---|" + "---|" * len(SCORE_KEYS)]
    for row in study["rows"]:
        error = run_at(row, rtol).get("error") or {}
        cells = []
        for k in SCORE_KEYS:
            if k not in error:
                cells.append("n/a")
                continue
            text = f"{error[k]:+.2g} s" if k in GRID_READ else _pct(error[k])
            if not score_within(row, rtol, k):
                text = f"**{text}**"
            if not row["reference"][k].get("converged", True):
                text += " *unsettled*"
            cells.append(text)
        lines.append(f"| {row['scenario']} / {row['controller']} | " + " | ".join(cells) + " |")
    return lines


def _pct(value) -> str:
    return "n/a" if value is None or not math.isfinite(value) else f"{100 * value:+.2g} %"


def markdown(study: dict) -> str:
    rtols, compare = study["rtols"], study["compare_rtol"]
    horizon = f"{study['stop']:g} s (short horizon)" if study.get("stop") else "the scenarios' 20 s"
    integral = {r: sum(within_target(row, r, METRICS) for row in study["rows"]) for r in rtols}
    lines = ["# Model Exchange against the converged co-simulation", "",
             f"Generated by `python -m harness me-accuracy --apply` ({study['wall_s']:.0f} s wall on {study['jobs']} "
             f"processes shared with other jobs; horizon {horizon}; native edition, FMI 2.0). Each case runs in "
             "Model Exchange (harness/me_master.py: CVODE BDF over the states of all FMUs, no communication step; "
             "the scenario's step is the output grid the scores read) at each relative tolerance, and is compared "
             "with the converged co-simulation: ITAE, IAE and Ec with the step study's Richardson values "
             "(docs/convergence.md; motor_arm, which the step study does not cover, by the same rule on this "
             f"study's ladder), the other scores with the Richardson value of a co-simulation ladder from the "
             f"scenario's step down to an eighth of it, ts with its finest run. How: "
             "harness/studies/me_accuracy.py; what Model Exchange is: docs/model_exchange.md.", "",
             f"**ITAE, IAE and Ec within {100 * TARGET:g} % of the converged values: "
             + ", ".join(f"{integral[r]} of {len(study['rows'])} cases at rtol {r:g}" for r in rtols) + ".**", "",
             "## ITAE, IAE, Ec: error against the converged values at each tolerance", "",
             "| case | " + " | ".join(f"rtol {r:g} (ITAE / IAE / Ec)" for r in rtols) + " | steps, derivative "
             f"evaluations, state events at {compare:g} |",
             "|---|" + "---|" * len(rtols) + "---|"]
    for row in study["rows"]:
        cells = []
        for rtol in rtols:
            run = run_at(row, rtol)
            error = run.get("error")
            mark = "" if within_target(row, rtol, METRICS) else " **(beyond)**"
            cells.append(" / ".join(_pct(error[m]) for m in METRICS) + mark if error else
                         f"{run['status']}: {run.get('reason', '')}")
        run = run_at(row, compare)
        cells.append(f"{run.get('steps')}, {run.get('derivative_evaluations')}, {run.get('state_events')}")
        lines.append(f"| {row['scenario']} / {row['controller']} | " + " | ".join(cells) + " |")
    for rtol in dict.fromkeys((compare, min(rtols))):
        lines += every_score_table(study, rtol)
    if study.get("stick"):
        lines += ["", "## Where the link sticks: Model Exchange and co-simulation differ, and which is right", "",
                  "In the manipulator's stuck mode (docs/model_exchange.md) static friction holds the link: dy is "
                  "exactly 0 in Model Exchange. Co-simulation integrates sgn(x2) of (39) by fixed-step RK4, which has "
                  "no stuck mode: in the same intervals dy chatters around 0 (its sign changes every few steps, with "
                  "an amplitude that shrinks like the step), and u, which feeds back de = dym - dy, zig-zags with "
                  "it. The number of zig-zags grows as the step shrinks while their size shrinks, so their total "
                  "variation does not vanish: tv_u of the co-simulation converges to a value above the Model "
                  "Exchange one, by what it gathers inside these intervals. The continuous-time model (38, 39) with "
                  "its Coulomb term has the stuck solution there (Filippov: the vector fields on both sides of "
                  "dy = 0 point towards it while |F| < cr), so the Model Exchange value is the model's, and the "
                  "co-simulation's tv_u (and the scores near the stops: es2, the largest |de| of the last period) "
                  "carry an artefact of its fixed step.", "",
                  f"Model Exchange at rtol {min(rtols):g} (when the link breaks away depends on the tolerance: the "
                  "stop ends where the applied torque reaches cr, a function of the whole state).", "",
                  "| case | stuck intervals (Model Exchange) | total stuck | TV(u) inside: ME | TV(u) inside: "
                  "co-simulation (step) | sign changes of dy inside (co-simulation) | largest |dy| inside "
                  "(co-simulation) | TV(u) outside: ME / co-simulation |", "|---|---|---|---|---|---|---|---|"]
        for ev in study["stick"]:
            cs = ev["co_simulation"]
            spans = ", ".join(f"{a:.4g}-{b:.4g}" for a, b in ev["intervals"])
            lines.append(f"| {ev['scenario']} / {ev['controller']} | {len(ev['intervals'])}: {spans} s | "
                         f"{sum(b - a for a, b in ev['intervals']):.3f} s | {ev['me']['tv_inside']:.2f} | "
                         + ", ".join(f"{c['tv_inside']:.2f} ({c['step']:g} s)" for c in cs) + " | "
                         + ", ".join(f"{c['sign_changes']} ({c['step']:g} s)" for c in cs) + " | "
                         + ", ".join(f"{c['max_dy']:.2g} rad/s ({c['step']:g} s)" for c in cs) + " | "
                         f"{ev['me']['tv_outside']:.1f} / " + ", ".join(f"{c['tv_outside']:.1f}" for c in cs) + " |")
    lines += ["", "## The converged values and the Model Exchange values", "",
              "| case | score | converged co-simulation | how | " + " | ".join(f"ME rtol {r:g}" for r in rtols) + " |",
              "|---|---|---|---|" + "---|" * len(rtols)]
    for row in study["rows"]:
        for key in SCORE_KEYS:
            reference = row["reference"].get(key)
            if reference is None:
                continue
            values = [run_at(row, r).get(key) for r in rtols]
            lines.append(f"| {row['scenario']} / {row['controller']} | {key} | {reference['value']:.8g} | "
                         f"{reference['how']} | " + " | ".join("n/a" if v is None else f"{v:.8g}" for v in values)
                         + " |")
    return "\n".join(lines) + "\n"


def me_accuracy_command(args) -> int:
    out = Path(args.out)
    cli_args.refuse_tracked([out / "me_accuracy.json", out / "me_accuracy.md"])
    if args.from_json:
        study = json.loads(Path(args.from_json).read_text())
    else:
        cases = study_cases(args.scenarios or PAPER_SCENARIOS, args.controller or variants.NAMES,
                            () if args.scenarios else BEYOND)
        study = accuracy_study(cases, tuple(args.rtols), args.compare_rtol, args.stop, args.jobs)
    out.mkdir(parents=True, exist_ok=True)
    atomic_files.write_text(out / "me_accuracy.json", json.dumps(study, indent=1))
    text = markdown(study)
    atomic_files.write_text(out / "me_accuracy.md", text)
    written = [out / "me_accuracy.json", out / "me_accuracy.md"]
    for row in study["rows"]:
        run = run_at(row, study["compare_rtol"])
        error = run.get("error") or {}
        print(f"{row['scenario']:15s} {row['controller']:5s} rtol {study['compare_rtol']:g}: "
              + " ".join(f"{m} {_pct(error.get(m))}" for m in METRICS)
              + f"  ITAE, IAE, Ec {'within' if within_target(row, study['compare_rtol'], METRICS) else 'NOT within'} "
                f"{100 * TARGET:g} %; every score: {'yes' if within_target(row, study['compare_rtol']) else 'no'}")
    if args.apply:
        if study.get("stop") is not None:
            print("error: --apply needs the full horizon (no --stop)", file=sys.stderr)
            return 1
        atomic_files.write_text(DOCS_PAGE, text)
        written.append(DOCS_PAGE)
    print(f"study wall time {study['wall_s']:.1f} s; written: " + ", ".join(str(p) for p in written))
    return 0


def register(commands):
    command = commands.add_parser("me-accuracy", help="Model Exchange at a tolerance ladder against the converged "
                                                      "co-simulation (every score, Table I/II and motor_arm)")
    command.add_argument("scenarios", nargs="*", type=cli_args.scenario,
                         help=f"default: {', '.join(PAPER_SCENARIOS)} and motor_arm/vud")
    command.add_argument("--controller", nargs="+", choices=variants.NAMES, help="default: all three")
    command.add_argument("--rtols", nargs="+", type=cli_args.positive_float, default=list(RTOLS),
                         help=f"relative tolerances (default {' '.join(f'{r:g}' for r in RTOLS)})")
    command.add_argument("--compare-rtol", type=cli_args.positive_float, default=COMPARE_RTOL,
                         help=f"the tolerance every score is compared at (default {COMPARE_RTOL:g})")
    command.add_argument("--stop", type=cli_args.positive_float, help="shorter horizon (tests); default 20 s")
    command.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    command.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/)")
    command.add_argument("--from-json", type=cli_args.existing_file,
                         help="do not run: rewrite the outputs from this study's me_accuracy.json")
    command.add_argument("--apply", action="store_true", help=f"also write {DOCS_PAGE.relative_to(ROOT)}")
    command.set_defaults(handler=me_accuracy_command)


__all__ = ["accuracy_study", "study_cases", "markdown", "within_target"]
