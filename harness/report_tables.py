"""Table I / Table II report.

``python -m harness tables [--out DIR] [--jobs N]`` runs the 12 co-simulations
(4 scenarios x vud, fixed, fae) in parallel processes and writes table1.csv,
table2.csv, report.md and figures like the paper's Figs. 4-8 to DIR.  The
step-size study behind each scenario's step is harness/step_study.py.
"""
from __future__ import annotations

import csv
import math
import sys
import time as clock
from pathlib import Path

from . import scenario as scenarios
from .cases import Case, default_jobs, run_cases
from .step_study import convergence_summary, load_convergence, validated_step

CONTROLLERS = tuple(scenarios.CONTROLLER_VARIANTS)  # vud, fixed, fae
PENDULUM = ("pendulum_case1", "pendulum_case2", "pendulum_case3")
ALL_SCENARIOS = (*PENDULUM, "manipulator")
TABLE_COLUMNS = ("scenario", "controller", "ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec",
                 "umax", "tv_u", "step", "validated_step", "status")
PAPER_METRICS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec")
DISTURBANCE_TOLERANCE = 0.10  # "barely changes": ITAE and IAE within 10 % of case 1
SMOOTHNESS_TOLERANCE = 1.10  # "smooth": tv_u at most 10 % above the smoothest comparison controller
CONTROLLER_NAMES = {"vud": "proposed AFC (variable universes)", "fixed": "stand-in for [46] (fixed universes)",
                    "fae": "stand-in for [28] (fixed universes + error estimator)"}


# ------------------------------------------------------------------ tables
def write_table(path: Path, rows: list):
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=TABLE_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _csv_value(row.get(key)) for key in TABLE_COLUMNS})


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


def claims_check(rows: list) -> list:
    """Each claim of the paper (SPEC section 7) with its verdict and the numbers that decide it."""
    by = {(r["scenario"], r["controller"]): r for r in rows}
    ok = all(r["status"] == "ok" for r in rows)
    claims = []

    def best(metric, scenario_list, label):
        details, verdict = [], ok
        for name in scenario_list:
            values = {c: by[(name, c)].get(metric) for c in CONTROLLERS}
            if any(v is None for v in values.values()):
                verdict = False
                continue
            others = min(values["fixed"], values["fae"])
            wins = values["vud"] < others
            verdict = verdict and wins
            details.append(f"{name}: vud {_fmt(values['vud'])} vs fixed {_fmt(values['fixed'])}, "
                           f"fae {_fmt(values['fae'])} ({'best' if wins else 'not best'})")
        claims.append((label, verdict, details))

    best("ts", ALL_SCENARIOS, "The proposed AFC has the shortest settling time ts in all four scenarios")
    best("es1_pct", ALL_SCENARIOS, "The proposed AFC has the smallest steady-state error es1 in all four scenarios")
    best("es2_pct", ALL_SCENARIOS, "The proposed AFC has the smallest steady-state error es2 in all four scenarios")
    best("ITAE", ALL_SCENARIOS, "The proposed AFC has the smallest ITAE in all four scenarios")
    best("IAE", ALL_SCENARIOS, "The proposed AFC has the smallest IAE in all four scenarios")
    best("Ec", PENDULUM, "The proposed AFC needs the least control energy Ec for the pendulum (cases 1-3)")
    details, verdict = [], ok
    for controller in CONTROLLERS:
        one, two = by[("pendulum_case1", controller)], by[("pendulum_case2", controller)]
        changes = []
        for metric in ("ITAE", "IAE"):
            if one.get(metric) and two.get(metric) is not None:
                change = two[metric] / one[metric] - 1.0
                changes.append(f"{metric} {100 * change:+.1f} %")
                if controller == "vud":
                    verdict = verdict and abs(change) < DISTURBANCE_TOLERANCE
        details.append(f"{controller}: case 2 vs case 1: {', '.join(changes)}")
    claims.append((f"The disturbance barely changes the proposed AFC's tracking (case 2 vs case 1: "
                   f"ITAE and IAE within {100 * DISTURBANCE_TOLERANCE:.0f} %)", verdict, details))
    details, verdict = [], ok
    for name in ALL_SCENARIOS:
        values = {c: by[(name, c)].get("tv_u") for c in CONTROLLERS}
        if any(v is None for v in values.values()):
            verdict = False
            continue
        smooth = values["vud"] <= SMOOTHNESS_TOLERANCE * min(values["fixed"], values["fae"])
        verdict = verdict and smooth
        details.append(f"{name}: TV(u)/s vud {_fmt(values['vud'])} vs fixed {_fmt(values['fixed'])}, "
                       f"fae {_fmt(values['fae'])} ({'smooth' if smooth else 'rougher'})")
    claims.append((f"The proposed AFC's control input is smooth (total variation of u per second at most "
                   f"{100 * (SMOOTHNESS_TOLERANCE - 1):.0f} % above the smoother comparison controller)",
                   verdict, details))
    return claims


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


def report_markdown(rows: list, convergence: dict, figure_paths: list, wall_s: float, jobs: int,
                    peak_mib: float = float("nan")) -> str:
    parts = ["# Table I / Table II: co-simulation report", "",
             f"Generated by `python -m harness tables` in {wall_s:.1f} s wall on {jobs} processes "
             f"(peak memory of the largest process {peak_mib:.0f} MiB). "
             "Each row is one FMI co-simulation (controller, plant and reference FMUs coupled by the "
             "feedthrough-aware master) from 0 to 20 s at the scenario's communication step.", ""]
    parts += ["## Table I: inverted pendulum", ""]
    for name in PENDULUM:
        parts += [f"### {name}: {scenarios.load(name).description}", "", paper_table(rows, name), ""]
    parts += ["## Table II: single-link manipulator with friction", "", paper_table(rows, "manipulator"), ""]
    parts += ["## Claims of the paper, checked", ""]
    for label, verdict, details in claims_check(rows):
        parts.append(f"- **{'reproduced' if verdict else 'not reproduced'}**: {label}.")
        parts += [f"  - {d}" for d in details]
    parts += ["", "## Choices the numbers depend on", "", choices_text(), ""]
    parts += ["## Communication step (validated step, 1 %)", ""]
    if convergence:
        parts += [convergence_summary(convergence), "",
                  "The full evidence (every step of the ladder) is in `docs/convergence.md`.", ""]
    else:
        parts += ["No step-size study found: run `python -m harness convergence`.", ""]
    if figure_paths:
        parts += ["## Figures (like the paper's Figs. 4-8)", ""]
        parts += [f"![{p.stem}]({p.name})" for p in figure_paths]
    return "\n".join(parts) + "\n"


def tables_command(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    jobs = args.jobs or default_jobs()
    # the longest runs first (the manipulator's step is 8x finer), so both cores finish together
    longest_first = sorted(ALL_SCENARIOS, key=lambda name: scenarios.load(name).steps, reverse=True)
    cases = [Case(name, controller, stop=args.stop, figure_interval=0.01)
             for name in longest_first for controller in CONTROLLERS]
    started = clock.perf_counter()
    rows = run_cases(cases, jobs=jobs, description="Table I/II co-simulations")
    wall_s = clock.perf_counter() - started
    peak_mib = peak_memory_mib()
    convergence = load_convergence()
    for row in rows:
        row["validated_step"] = validated_step(convergence, row["scenario"], row["controller"])
    write_table(out / "table1.csv", [r for r in rows if r["scenario"] in PENDULUM])
    write_table(out / "table2.csv", [r for r in rows if r["scenario"] == "manipulator"])
    figure_paths = figures(rows, out)
    (out / "report.md").write_text(report_markdown(rows, convergence, figure_paths, wall_s, jobs, peak_mib))
    print(f"12 co-simulations in {wall_s:.1f} s wall on {jobs} processes; peak memory {peak_mib:.0f} MiB "
          "(largest process)")
    for name in ALL_SCENARIOS:
        print(f"\n{name}\n{paper_table(rows, name)}")
    print("\nclaims:")
    for label, verdict, _ in claims_check(rows):
        print(f"  {'reproduced    ' if verdict else 'NOT reproduced'}  {label}")
    print(f"\nwritten: {out / 'table1.csv'}, {out / 'table2.csv'}, {out / 'report.md'}, "
          f"{len(figure_paths)} figures")
    failed = [r for r in rows if r["status"] != "ok"]
    for row in failed:
        print(f"error: {row['scenario']}/{row['controller']}: {row['reason']}", file=sys.stderr)
    return 1 if failed else 0


def register(commands):
    tables = commands.add_parser("tables", help="run Table I/II (12 co-simulations) and write the report")
    tables.add_argument("--out", default="results", help="output folder (default results/)")
    tables.add_argument("--jobs", type=int, help="parallel processes (default: every core)")
    tables.add_argument("--stop", type=float, help="shorter horizon (tests); default the scenarios' 20 s")
    tables.set_defaults(handler=tables_command)
