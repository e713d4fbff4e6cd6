"""Table I / Table II report and the step-size study.

``python -m harness tables [--out DIR] [--jobs N]`` runs the 12 co-simulations
(4 scenarios x vud, fixed, fae) in parallel processes and writes table1.csv,
table2.csv, report.md and figures like the paper's Figs. 4-8 to DIR.  It also
runs each case at half its step (and, with ``--refine``, the cases an open claim
needs finer still): harness/claims.py decides the paper's claims on those ladders.
Beyond the paper, it runs the third-order plant (motor_arm x vud, fixed, fae x
m = 2, 3 fuzzy sets) into table3_beyond_paper.csv and a section of report.md.

``python -m harness convergence [SCENARIO...]`` is the step-size study: per
scenario and controller the scores on a ladder of halving steps until
halving changes ITAE, IAE and Ec by less than 0.5 %, plus half and a
quarter of the chosen step, and the largest stable communication step for
both master algorithms.  It writes harness/scenarios/convergence.json and
docs/convergence.md (the report includes them; ``tables`` stays fast) and,
with ``--apply``, the chosen step into each scenario file.
"""
from __future__ import annotations

import csv
import json
import math
import re
import sys
import time as clock
from pathlib import Path

from . import claims as claims_module
from . import scenario as scenarios
from .cases import Case, default_jobs, parallel_map, run_cases

ROOT = Path(__file__).resolve().parents[1]
CONVERGENCE_JSON = scenarios.SCENARIO_DIR / "convergence.json"
CONVERGENCE_MD = ROOT / "docs" / "convergence.md"
CONTROLLERS = tuple(scenarios.CONTROLLER_VARIANTS)  # vud, fixed, fae
PENDULUM = ("pendulum_case1", "pendulum_case2", "pendulum_case3")
ALL_SCENARIOS = (*PENDULUM, "manipulator")
TABLE_COLUMNS = ("scenario", "controller", "ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec",
                 "umax", "tv_u", "step", "largest_stable_step", "status")
PAPER_METRICS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec")
CONVERGENCE_TOLERANCE = 0.005  # halving the step changes ITAE, IAE and Ec by less than 0.5 %
BEYOND_PAPER = "motor_arm"  # a third-order plant of our own (docs/general_order.md)
BEYOND_PAPER_SETS = (2, 3)  # fuzzy sets per input: M = 8 and 27 rules at order 3
CONTROLLER_NAMES = {"vud": "proposed AFC (variable universes)", "fixed": "stand-in for [46] (fixed universes)",
                    "fae": "stand-in for [28] (fixed universes + error estimator)"}


# ------------------------------------------------------------------ tables
def load_convergence() -> dict:
    if CONVERGENCE_JSON.exists():
        return json.loads(CONVERGENCE_JSON.read_text())
    return {}


def largest_stable_step(convergence: dict, scenario: str, controller: str, algorithm="feedthrough"):
    return convergence.get("scenarios", {}).get(scenario, {}).get("largest_stable_step", {}) \
        .get(algorithm, {}).get(controller)


def write_table(path: Path, rows: list, columns=TABLE_COLUMNS):
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _csv_value(row.get(key)) for key in columns})


def _csv_value(value):
    if isinstance(value, float):
        return repr(value)
    return "" if value is None else value


def _fmt(value, digits=4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def paper_table(rows: list, scenario: str) -> str:
    lines = ["| controller | ts (s) | es1 (%) | es2 (%) | ITAE | IAE | Ec | umax | TV(u)/s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        if row["scenario"] != scenario:
            continue
        if row["status"] != "ok":
            lines.append(f"| {row['controller']} | {row['status']}: {row['reason']} |||||||| ")
            continue
        lines.append("| " + " | ".join([row["controller"], *(_fmt(row[k]) for k in PAPER_METRICS),
                                         _fmt(row["umax"]), _fmt(row["tv_u"])]) + " |")
    return "\n".join(lines)


def beyond_paper_cases(stop=None) -> list:
    """The extra runs: the third-order plant with every controller at m = 2 and 3 sets per input."""
    return [Case(BEYOND_PAPER, controller, stop=stop, overrides=(("controller.sets", sets),))
            for sets in BEYOND_PAPER_SETS for controller in CONTROLLERS]


def beyond_paper_table(rows: list) -> str:
    """The third-order plant's scores (||e|| over e, de, d2e) per controller and number of sets."""
    lines = ["| controller | sets m (rules) | ts (s) | es1 (%) | es2 (%) | ITAE | IAE | Ec | umax | TV(u)/s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        shape = f"{row['sets']} ({row['sets'] ** 3})"
        if row["status"] != "ok":
            lines.append(f"| {row['controller']} | {shape} | {row['status']}: {row['reason']} |||||||| ")
            continue
        lines.append("| " + " | ".join([row["controller"], shape, *(_fmt(row[k]) for k in PAPER_METRICS),
                                         _fmt(row["umax"]), _fmt(row["tv_u"])]) + " |")
    return "\n".join(lines)


def figures(rows: list, out: Path) -> list:
    """Figs. 4-8 like the paper's: x1 vs ym, x2 vs dym, e, de, ||e||, u of the three controllers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    paths = []
    colours = {"vud": "tab:red", "fixed": "tab:blue", "fae": "tab:green"}
    for name in ALL_SCENARIOS:
        order = {"fixed": 0, "fae": 1, "vud": 2}  # the proposed controller drawn on top
        runs = sorted((r for r in rows if r["scenario"] == name and "signals" in r),
                      key=lambda r: order[r["controller"]])
        if not runs:
            continue
        fig, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True)
        panels = [("x1 and ym (rad)", "plant.y"), ("x2 and dym (rad/s)", "plant.dy"), ("e (rad)", "reference.e"),
                  ("de (rad/s)", "reference.de"), ("||e||", None), ("u", "controller.u")]
        for axis, (title, signal) in zip(axes.flat, panels):
            for run in runs:
                s = run["signals"]
                values = np.hypot(s["reference.e"], s["reference.de"]) if signal is None else s[signal]
                axis.plot(s["time"], values, color=colours[run["controller"]], lw=0.9, label=run["controller"])
            if signal == "plant.y":
                axis.plot(runs[0]["signals"]["time"], runs[0]["signals"]["reference.ym"], "k--", lw=0.8, label="ym")
            if signal == "plant.dy":
                axis.plot(runs[0]["signals"]["time"], runs[0]["signals"]["reference.dym"], "k--", lw=0.8,
                          label="dym")
            axis.set_title(title, fontsize=10)
            axis.grid(alpha=0.3)
        axes[0, 0].legend(fontsize=8)
        for axis in axes[-1]:
            axis.set_xlabel("t (s)")
        fig.suptitle(f"{name}: {scenarios.load(name).description}", fontsize=11)
        fig.tight_layout()
        path = out / f"{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def choices_text() -> str:
    return """The numbers depend on these choices of SPEC.md (the paper is ambiguous there):
- Normalised FLS inputs saturated to the universe [-E_i, E_i]; sigmoid membership functions (slope 7 pendulum, 1.5 manipulator).
- Modified tracking error E = e - (a0 + a1 t) exp(-5 t) (Remark 3) used by all three controllers, e(0), de(0) latched at the end of initialisation.
- Comparison controllers are documented stand-ins with the same learning rate (gamma = 300): `fixed` (alpha = 1) for [46], `fae` (alpha = 1 plus w_hat, gamma_w = gamma) for [28]; the equations of [46] and [28] are not public here.
- Pendulum disturbance d(t) enters additively in dx2; horizon 0-20 s; ts is the earliest time after which |e| <= 5 % max|ym| until T; es1, es2 are 100 max|e|, 100 max|de| over the last reference period [T - 2 pi, T] over max|ym|, max|dym|.
- Sampled-data controller: u held over each communication step, theta += h * dtheta; plants integrated with RK4 at internal steps <= 0.1 ms; scores by the trapezoidal rule on the communication grid."""


def peak_memory_mib() -> float:
    """Peak resident memory of this process and of its largest finished worker (Linux: KiB)."""
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, children) / 1024.0


CLAIMS_METHOD = (
    "Each claim is decided on step ladders: every case also runs at half the scenario's step, and a "
    "case that an open claim needs at a further half (`--refine`). A score is its value at the finest "
    "step run, ± its numerical error: the change of that score over the last halving (the loop is "
    "first order in the step). A comparison is decided only when the gap exceeds the sum of both "
    "errors; otherwise it is *not decided at this accuracy*. The tables above are at the scenario's step.")


def report_markdown(rows: list, claims: list, convergence: dict, figure_paths: list, wall_s: float, jobs: int,
                    peak_mib: float = float("nan"), beyond_rows=()) -> str:
    parts = ["# Table I / Table II: co-simulation report", "",
             f"Generated by `python -m harness tables` in {wall_s:.1f} s wall (with the claims' step ladders) "
             f"on {jobs} processes "
             f"(peak memory of the largest process {peak_mib:.0f} MiB). "
             "Each row is one FMI co-simulation (controller, plant and reference FMUs coupled by the "
             "feedthrough-aware master) from 0 to 20 s at the scenario's communication step.", ""]
    parts += ["## Table I: inverted pendulum", ""]
    for name in PENDULUM:
        parts += [f"### {name}: {scenarios.load(name).description}", "", paper_table(rows, name), ""]
    parts += ["## Table II: single-link manipulator with friction", "", paper_table(rows, "manipulator"), ""]
    if beyond_rows:
        beyond = scenarios.load(BEYOND_PAPER)
        parts += ["## Beyond the paper: a third-order plant", "",
                  f"{beyond.description}; the controller at order n = 3 (inputs e, de, d2e; ||e|| over all "
                  f"three) with m = 2 and 3 fuzzy sets per input, step {beyond.step:g} s "
                  "(converged by halving, docs/general_order.md).", "", beyond_paper_table(beyond_rows), ""]
    parts += ["## Claims of the paper, checked", "", CLAIMS_METHOD, ""]
    parts += claims_module.claims_markdown(claims)
    parts += ["", "## Choices the numbers depend on", "", choices_text(), ""]
    parts += ["## Communication step and stability", ""]
    if convergence:
        parts += [convergence_summary(convergence), "",
                  "The full evidence (every step of the ladder) is in `docs/convergence.md`.", ""]
    else:
        parts += ["No step-size study found: run `python -m harness convergence`.", ""]
    if figure_paths:
        parts += ["## Figures (like the paper's Figs. 4-8)", ""]
        parts += [f"![{p.stem}]({p.name})" for p in figure_paths]
    return "\n".join(parts) + "\n"


def half_step_case(case: Case) -> Case:
    """The same case at half its step (no figure signals): the error estimate of the claims."""
    return Case(case.scenario, case.controller, step=case.build().step / 2, stop=case.stop)


def case_cost(case: Case) -> int:
    return case.build().steps


def refine_open_claims(ladders: dict, stop: float | None, jobs: int, levels: int) -> tuple[list, list]:
    """(claims, refined cases): up to ``levels`` further halvings of the step for the cases a
    claim still open needs (``ladders`` gains their runs)."""
    claims = claims_module.claims_check(ladders)
    refined = []
    for _ in range(levels):
        open_cases = claims_module.undecided_cases(claims)
        if not open_cases:
            break
        finer = [Case(name, controller, step=min(o["step"] for o in ladders[(name, controller)]) / 2, stop=stop)
                 for name, controller in sorted(open_cases)]
        for outcome in run_cases(sorted(finer, key=case_cost, reverse=True), jobs=jobs,
                                 description="claims: finer steps"):
            ladders[(outcome["scenario"], outcome["controller"])].append(outcome)
            refined.append((outcome["scenario"], outcome["controller"], outcome["step"]))
        claims = claims_module.claims_check(ladders)
    return claims, refined


def tables_command(args) -> int:
    if args.refine < 0:
        print(f"error: --refine {args.refine} is invalid; give 0 (decide on h and h/2 only) or more levels",
              file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = args.jobs or default_jobs()
    cases = [Case(name, controller, stop=args.stop, figure_interval=0.01)
             for name in ALL_SCENARIOS for controller in CONTROLLERS]
    # every case at h (the tables) and at h/2 (the claims' error estimates) in one pool,
    # the longest runs first, so both cores finish together
    extra = beyond_paper_cases(args.stop)  # the third-order plant, beyond the paper (no claims)
    runs = sorted([*cases, *map(half_step_case, cases)], key=case_cost, reverse=True)
    started = clock.perf_counter()
    everything = sorted([*runs, *extra], key=case_cost, reverse=True)
    outcomes = dict(zip(everything, run_cases(everything, jobs=jobs,
                                              description="Table I/II co-simulations and half steps")))
    rows = [outcomes[case] for case in cases]
    beyond_rows = [dict(outcomes[case], sets=dict(case.overrides)["controller.sets"]) for case in extra]
    ladders = claims_module.ladders_from_rows([outcomes[case] for case in runs])
    ladder_s = clock.perf_counter() - started
    claims, refined = refine_open_claims(ladders, args.stop, jobs, args.refine)
    wall_s = clock.perf_counter() - started
    peak_mib = peak_memory_mib()
    convergence = load_convergence()
    for row in rows:
        row["largest_stable_step"] = largest_stable_step(convergence, row["scenario"], row["controller"])
    write_table(out / "table1.csv", [r for r in rows if r["scenario"] in PENDULUM])
    write_table(out / "table2.csv", [r for r in rows if r["scenario"] == "manipulator"])
    write_table(out / "table3_beyond_paper.csv", beyond_rows,
                ("scenario", "controller", "sets", *TABLE_COLUMNS[2:-2], "status"))
    figure_paths = figures(rows, out)
    (out / "report.md").write_text(report_markdown(rows, claims, convergence, figure_paths, wall_s, jobs, peak_mib,
                                                   beyond_rows))
    print(f"{len(rows)} co-simulations and the same at half the step in {ladder_s:.1f} s, {len(refined)} finer "
          f"for open claims in {wall_s - ladder_s:.1f} s: {wall_s:.1f} s wall on {jobs} processes; peak memory "
          f"{peak_mib:.0f} MiB (largest process)")
    for name in ALL_SCENARIOS:
        print(f"\n{name}\n{paper_table(rows, name)}")
    print(f"\n{BEYOND_PAPER} (beyond the paper)\n{beyond_paper_table(beyond_rows)}")
    print("\nclaims (decided on the step ladders, see the report):")
    for claim in claims:
        print(f"  {claim.verdict:29s} {claim.label}")
    if refined:
        print("refined for open claims: " + ", ".join(f"{s}/{c} at {h:g} s" for s, c, h in refined))
    print(f"\nwritten: {out / 'table1.csv'}, {out / 'table2.csv'}, {out / 'table3_beyond_paper.csv'}, "
          f"{out / 'report.md'}, "
          f"{len(figure_paths)} figures")
    failed = [r for r in rows + beyond_rows if r["status"] != "ok"]
    for row in failed:
        print(f"error: {row['scenario']}/{row['controller']}: {row['reason']}", file=sys.stderr)
    return 1 if failed else 0


# ------------------------------------------------------------ convergence
def is_stable(outcome: dict, stop: float) -> bool:
    """Stable: the run completes within bounds and |e| settles into the 5 % band before the end."""
    return outcome["status"] == "ok" and outcome["ts"] < stop - 1e-9


def relative_change(fine: dict, coarse: dict, metric: str) -> float:
    if fine["status"] != "ok" or coarse["status"] != "ok":
        return math.inf
    return abs(coarse[metric] - fine[metric]) / abs(fine[metric])


def converged(fine: dict, coarse: dict) -> bool:
    return all(relative_change(fine, coarse, m) < CONVERGENCE_TOLERANCE for m in ("ITAE", "IAE", "Ec"))


def study_scenario(name: str, start_step: float, finest_step: float, jobs: int, stop: float | None,
                   stability_limit: float) -> dict:
    """The step ladder and the largest stable steps of one scenario."""
    ladder = {c: [] for c in CONTROLLERS}

    def run_level(step):
        outcomes = run_cases([Case(name, c, step=step, stop=stop) for c in CONTROLLERS], jobs=jobs,
                             description=f"{name} h={step:g}")
        for controller, outcome in zip(CONTROLLERS, outcomes):
            ladder[controller].append(outcome)

    step = start_step
    run_level(step)
    chosen = None
    while step / 2 >= finest_step * (1 - 1e-9):
        run_level(step / 2)
        if all(converged(ladder[c][-1], ladder[c][-2]) for c in CONTROLLERS):
            chosen = step
            break
        step /= 2
    if chosen is None:
        chosen = step
    # half and a quarter of the chosen step: the evidence the issue asks for
    have = {round(o["step"], 15) for o in ladder["vud"]}
    for fraction in (2, 4):
        if round(chosen / fraction, 15) not in have:
            run_level(chosen / fraction)
    scenario_stop = stop or scenarios.load(name).stop
    searches = [(algorithm, c) for algorithm in ("feedthrough", "jacobi") for c in CONTROLLERS]
    found = parallel_map(_stable_step_search, [(name, c, algorithm, chosen, stop, scenario_stop, stability_limit)
                                               for algorithm, c in searches], jobs)
    largest = {"feedthrough": {}, "jacobi": {}}
    for (algorithm, controller), step in zip(searches, found):
        largest[algorithm][controller] = step
    return {"chosen_step": chosen, "ladder": ladder, "largest_stable_step": largest}


def _stable_step_search(arguments: tuple):
    return stable_step_search(*arguments)


def stable_step_search(name, controller, algorithm, start, stop, scenario_stop, limit, precision=0.05):
    """Largest stable step by doubling from ``start`` then bisection (to 5 %); stability need not be monotone."""
    def stable(step):
        outcome = run_cases([Case(name, controller, step=step, stop=stop, algorithm=algorithm)], jobs=1,
                            progress=False)[0]
        return is_stable(outcome, scenario_stop)

    low = start
    while not stable(low):
        low /= 2
        if low < start / 4:  # unstable even at a quarter of the chosen step: report none
            return None
    high = low * 2
    while high <= limit and stable(high):
        low, high = high, high * 2
    if high > limit:
        return low
    while high / low > 1 + precision:
        middle = math.sqrt(low * high)
        if stable(middle):
            low = middle
        else:
            high = middle
    return low


def convergence_summary(convergence: dict) -> str:
    lines = ["| scenario | chosen step (s) | largest stable step, ours (vud / fixed / fae) | "
             "largest stable step, jacobi (vud / fixed / fae) | ratio ours / jacobi (vud / fixed / fae) |",
             "|---|---|---|---|---|"]
    for name, study in convergence.get("scenarios", {}).items():
        ours = study["largest_stable_step"]["feedthrough"]
        jacobi = study["largest_stable_step"]["jacobi"]
        ratios = [ours[c] / jacobi[c] if ours.get(c) and jacobi.get(c) else None for c in CONTROLLERS]
        lines.append(f"| {name} | {study['chosen_step']:g} | "
                     + " / ".join(_fmt(ours.get(c), 3) for c in CONTROLLERS) + " | "
                     + " / ".join(_fmt(jacobi.get(c), 3) for c in CONTROLLERS) + " | "
                     + " / ".join(_fmt(r, 3) for r in ratios) + " |")
    criterion = convergence.get("criterion", "")
    return (lines and "\n".join(lines)) + (f"\n\nStep criterion: {criterion}" if criterion else "")


def convergence_markdown(convergence: dict) -> str:
    parts = ["# Step-size study", "",
             "Generated by `python -m harness convergence`. For each scenario the communication step is "
             "halved until halving changes ITAE, IAE and Ec of all three controllers by less than "
             f"{100 * CONVERGENCE_TOLERANCE:g} %; that step goes into the scenario file. The largest stable "
             "step (run completes within bounds and |e| settles into the 5 % band before 20 s) is found by "
             "doubling and bisection to 5 %, for our feedthrough-aware master and for the Jacobi scheme "
             "(every connection delayed one step, as most co-simulation engines do).", "",
             convergence_summary(convergence), ""]
    for name, study in convergence.get("scenarios", {}).items():
        parts += [f"## {name}", "", "| controller | step (s) | status | ITAE | IAE | Ec | change vs half step "
                  "(ITAE / IAE / Ec) |", "|---|---|---|---|---|---|---|"]
        for controller in CONTROLLERS:
            levels = sorted(study["ladder"][controller], key=lambda o: -o["step"])
            for index, outcome in enumerate(levels):
                finer = levels[index + 1] if index + 1 < len(levels) else None
                change = " / ".join(f"{100 * relative_change(finer, outcome, m):.3g} %"
                                    for m in ("ITAE", "IAE", "Ec")) if finer else ""
                parts.append(f"| {controller} | {outcome['step']:g} | {outcome['status']} | "
                             f"{_fmt(outcome.get('ITAE'))} | {_fmt(outcome.get('IAE'))} | "
                             f"{_fmt(outcome.get('Ec'))} | {change} |")
        parts.append("")
    return "\n".join(parts)


def apply_step(name: str, step: float):
    path = scenarios.SCENARIO_DIR / f"{name}.toml"
    text = path.read_text()
    text, count = re.subn(r"(?m)^step = [^#\n]*", f"step = {step:g}  ", text, count=1)
    if count != 1:
        raise RuntimeError(f"no 'step = ' line in {path}")
    path.write_text(text)


def convergence_command(args) -> int:
    names = args.scenarios or list(ALL_SCENARIOS)
    jobs = args.jobs or default_jobs()
    convergence = load_convergence() or {"scenarios": {}}
    convergence["criterion"] = (f"halving the step changes ITAE, IAE and Ec by less than "
                                f"{100 * CONVERGENCE_TOLERANCE:g} % for vud, fixed and fae")
    started = clock.perf_counter()
    for name in names:
        scenarios.load(name)  # clear error for an unknown name
        study = study_scenario(name, args.start_step, args.finest_step, jobs, args.stop, args.stability_limit)
        for outcomes in study["ladder"].values():
            for outcome in outcomes:
                outcome.pop("signals", None)
        convergence["scenarios"][name] = study
        print(f"{name}: chosen step {study['chosen_step']:g} s; largest stable step "
              f"{study['largest_stable_step']}")
        if args.apply:
            apply_step(name, study["chosen_step"])
    convergence["wall_s"] = clock.perf_counter() - started
    if args.stop is not None:
        convergence["stop"] = args.stop
    out_json = Path(args.json_out) if args.json_out else CONVERGENCE_JSON
    out_md = Path(args.markdown_out) if args.markdown_out else CONVERGENCE_MD
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(convergence, indent=1))
    out_md.write_text(convergence_markdown(convergence))
    print(f"written: {out_json}, {out_md}")
    return 0


def register(commands):
    tables = commands.add_parser("tables", help="run Table I/II (12 co-simulations) and the third-order "
                                                "plant beyond the paper (6) and write the report")
    tables.add_argument("--out", default="results", help="output folder (default results/)")
    tables.add_argument("--jobs", type=int, help="parallel processes (default: every core)")
    tables.add_argument("--stop", type=float, help="shorter horizon (tests); default the scenarios' 20 s")
    tables.add_argument("--refine", type=int, default=1, metavar="LEVELS",
                        help="further halvings of the step for the cases an open claim needs (default 1; 0: "
                             "decide on h and h/2 only)")
    tables.set_defaults(handler=tables_command)
    study = commands.add_parser("convergence", help="step-size study and largest stable steps")
    study.add_argument("scenarios", nargs="*", help=f"default: {', '.join(ALL_SCENARIOS)}")
    study.add_argument("--jobs", type=int, help="parallel processes (default: every core)")
    study.add_argument("--start-step", type=float, default=1.6e-3, help="coarsest step of the ladder")
    study.add_argument("--finest-step", type=float, default=2.5e-5, help="finest step of the ladder")
    study.add_argument("--stability-limit", type=float, default=0.1, help="largest step tried for stability")
    study.add_argument("--stop", type=float, help="shorter horizon (tests)")
    study.add_argument("--apply", action="store_true", help="write the chosen step into each scenario file")
    study.add_argument("--json-out", help=f"default {CONVERGENCE_JSON.relative_to(ROOT)}")
    study.add_argument("--markdown-out", help=f"default {CONVERGENCE_MD.relative_to(ROOT)}")
    study.set_defaults(handler=convergence_command)
