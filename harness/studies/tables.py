"""Table I / Table II report.

``python -m harness tables [--out DIR] [--jobs N]`` runs the 12 co-simulations
(4 scenarios x vud, fixed, fae) in parallel processes and writes table1.csv,
table2.csv, report.md and figures like the paper's Figs. 4-8 to DIR.  It also
runs each case at half its step (and, with ``--refine``, the cases an open claim
needs finer still): harness/studies/claims.py decides the paper's claims on those ladders.
Beyond the paper, it runs the third-order plant (motor_arm x vud, fixed, fae x
m = 2, 3 fuzzy sets) into table3_beyond_paper.csv and a section of report.md.
The step study behind each scenario's step is harness/studies/step_study.py.
"""
from __future__ import annotations

import csv
import math
import sys
import time as clock
from pathlib import Path

import numpy as np

from .. import atomic_files, cli_args, variants
from .. import scenario as scenarios
from ..cases import Case, default_jobs, run_cases
from ..me_master import ALGORITHM as MODEL_EXCHANGE
from ..me_master import DEFAULT_RTOL
from ..scores import DEFINITIONS, SCORE_KEYS, SETTLING_BAND, undefined_reason, value_text, why_none
from ..units import score_units, variable_unit, with_unit
from . import claims as claims_module
from .step_study import convergence_summary, load_convergence, validated_step

ROOT = Path(__file__).resolve().parents[2]
CONTROLLERS = variants.PAPER  # the paper's comparison: vud, fixed, fae
PENDULUM = ("pendulum_case1", "pendulum_case2", "pendulum_case3")
ALL_SCENARIOS = (*PENDULUM, "manipulator")
TABLE_COLUMNS = ("scenario", "controller", "ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec",
                 "umax", "tv_u", "step", "validated_step", "status")
PAPER_METRICS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec")
SHOWN_METRICS = (*PAPER_METRICS, "umax", "tv_u")  # the columns of the report's tables
HEADINGS = {"ts": "ts", "es1_pct": "es1", "es2_pct": "es2", "ITAE": "ITAE", "IAE": "IAE", "Ec": "Ec", "umax": "umax",
            "tv_u": "TV(u)/s"}
BEYOND_PAPER = "motor_arm"  # a third-order plant of our own (docs/general_order.md)
BEYOND_PAPER_SETS = (2, 3)  # fuzzy sets per input: M = 8 and 27 rules at order 3


# ------------------------------------------------------------------ tables
def write_table(path: Path, rows: list, columns=TABLE_COLUMNS):
    with atomic_files.replacing(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({key: _csv_value(row.get(key)) for key in columns})


def _csv_value(value):
    if isinstance(value, float):
        return repr(value)
    return "" if value is None else value


def _columns(scenario: str) -> list:
    """Column headings with units (the scenario's: N or N.m, rad or ...): ``ITAE (rad.s2)``."""
    units = score_units(scenarios.load(scenario))
    return [f"{HEADINGS[m]} ({units[m]})" for m in SHOWN_METRICS]


def _cells(row: dict) -> list:
    return [value_text(m, row[m], row["start"], row["stop"], ".4g") for m in SHOWN_METRICS]


def paper_table(rows: list, scenario: str) -> str:
    """The scenario's rows: every score with its unit; n/a or not settled where the run gives none."""
    columns = _columns(scenario)
    lines = ["| controller | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for row in rows:
        if row["scenario"] != scenario:
            continue
        if row["status"] != "ok":
            lines.append(f"| {row['controller']} | {row['status']}: {row['reason']} |||||||| ")
            continue
        lines.append("| " + " | ".join([row["controller"], *_cells(row)]) + " |")
    return "\n".join(lines)


def table_notes(rows: list) -> list:
    """One line per kind of missing score in ``rows`` (ok runs): what n/a and not settled mean there."""
    notes = {}
    for row in rows:
        if row["status"] != "ok":
            continue
        for metric in SHOWN_METRICS:
            if row[metric] is None:
                text = value_text(metric, None, row["start"], row["stop"])
                key = (text, why_none(metric, row["start"], row["stop"]))
                notes.setdefault(key, {}).setdefault(HEADINGS[metric], []).append(row["controller"])
    lines = []
    for (text, reason), metrics in notes.items():
        which = "; ".join(f"{metric} of {', '.join(dict.fromkeys(names))}" for metric, names in metrics.items())
        lines.append(f"{text} ({which}): {reason}.")
    return lines


def step_note(rows: list, scenario: str) -> str:
    """Where the table's values come from, beside the claims' values of the same scores."""
    own = [row for row in rows if row["scenario"] == scenario]
    steps = sorted({row["step"] for row in own})
    step = ", ".join(f"{h:g}" for h in steps)
    if any(row.get("algorithm") == MODEL_EXCHANGE for row in own):
        tolerances = ", ".join(f"{rtol:g}" for rtol in sorted({row["rtol"] for row in own if row.get("rtol")}))
        return (f"Model Exchange at rtol {tolerances}, on the output grid h = {step} s. The claims below read the "
                "same scores at the tightest rtol run with their numerical error, so their values differ from "
                "these in the digits that error covers.")
    return (f"At the scenario's step h = {step} s. The claims below read the same scores at the finest step "
            "run (h/2 or finer) with their numerical error, so their values differ from these in the digits "
            "that error covers.")


def table_block(rows: list, scenario: str) -> list:
    """The table of one scenario with its step note and the notes of its missing scores."""
    own = [row for row in rows if row["scenario"] == scenario]
    return [paper_table(rows, scenario), "", step_note(rows, scenario), *(["", *table_notes(own)]
                                                                         if table_notes(own) else []), ""]


def table_cases(stop=None, algorithm: str = "feedthrough", rtol: float | None = None) -> list:
    """The cases of Tables I and II: every scenario of the paper with every controller."""
    return [Case(name, controller, stop=stop, figure_interval=0.01, algorithm=algorithm, rtol=rtol)
            for name in ALL_SCENARIOS for controller in CONTROLLERS]


def pool_counts() -> tuple:
    """(cases of Tables I/II, runs in the first pool, of them the third-order plant's): what ``--help`` says."""
    cases, extra = table_cases(), beyond_paper_cases()
    return len(cases), 2 * len(cases) + len(extra), len(extra)


def beyond_paper_cases(stop=None, algorithm: str = "feedthrough", rtol: float | None = None) -> list:
    """The extra runs: the third-order plant with every controller at m = 2 and 3 sets per input."""
    return [Case(BEYOND_PAPER, controller, stop=stop, overrides=(("controller.sets", sets),), algorithm=algorithm,
                 rtol=rtol) for sets in BEYOND_PAPER_SETS for controller in CONTROLLERS]


def beyond_paper_table(rows: list) -> str:
    """The third-order plant's scores (||e|| over e, de, d2e) per controller and number of sets."""
    columns = _columns(BEYOND_PAPER)
    lines = ["| controller | sets m (rules) | " + " | ".join(columns) + " |", "|---" * (len(columns) + 2) + "|"]
    for row in rows:
        shape = f"{row['sets']} ({row['sets'] ** 3})"
        if row["status"] != "ok":
            lines.append(f"| {row['controller']} | {shape} | {row['status']}: {row['reason']} |||||||| ")
            continue
        lines.append("| " + " | ".join([row["controller"], shape, *_cells(row)]) + " |")
    return "\n".join(lines)


def legend_label(controller: str) -> str:
    """``vud: proposed AFC (variable universes)``: a figure's legend defines each controller."""
    return next(f"{v.name}: {v.label}" for v in variants.VARIANTS if v.name == controller)


def figures(rows: list, out: Path) -> list:
    """Figs. 4-8 like the paper's: x1 vs ym, x2 vs dym, e, de, ||e||, u of the three controllers."""
    import matplotlib  # here, not at module level: its import is paid only when figures are drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for name in ALL_SCENARIOS:
        runs = [r for r in rows if r["scenario"] == name and "signals" in r]
        if not runs:
            continue
        fig = draw_figure(name, runs, plt)
        path = out / f"{name}.png"
        atomic_files.save_figure(fig, path, dpi=90)
        plt.close(fig)
        paths.append(path)
    return paths


def draw_figure(name: str, runs: list, plt):
    """One scenario's figure: six panels, each controller in its colour with its definition in the legend,
    the reference dashed, the 5 % band of ts drawn on e."""
    order = {name: k for k, name in enumerate((*variants.COMPARISONS, variants.PROPOSED))}  # proposed on top
    runs = sorted(runs, key=lambda r: order[r["controller"]])
    fig, axes = plt.subplots(3, 2, figsize=(11, 9), sharex=True)
    configured = scenarios.load(name)
    unit = {dotted: variable_unit(configured, dotted) for dotted in
            ("plant.y", "plant.dy", "reference.e", "reference.de", "controller.u")}
    panels = [(with_unit("x1 and ym", unit["plant.y"]), "plant.y"),
              (with_unit("x2 and dym", unit["plant.dy"]), "plant.dy"),
              (with_unit("e", unit["reference.e"]), "reference.e"),
              (with_unit("de", unit["reference.de"]), "reference.de"),
              (with_unit("||e|| = sqrt(e^2 + de^2)", f"{unit['reference.e']}, {unit['reference.de']}"), None),
              (with_unit("u", unit["controller.u"]), "controller.u")]
    for axis, (title, signal) in zip(axes.flat, panels):
        if signal == "reference.e":  # the band ts is read against
            band = SETTLING_BAND * float(np.max(np.abs(runs[0]["signals"]["reference.ym"])))
            axis.axhspan(-band, band, color="0.85", lw=0, label=f"{100 * SETTLING_BAND:g} % band of max|ym| (ts)")
        for run in runs:
            s = run["signals"]
            values = np.hypot(s["reference.e"], s["reference.de"]) if signal is None else s[signal]
            axis.plot(s["time"], values, color=variants.COLOURS[run["controller"]], lw=0.9,
                      label=legend_label(run["controller"]))
        if signal == "plant.y":
            axis.plot(runs[0]["signals"]["time"], runs[0]["signals"]["reference.ym"], "k--", lw=0.8, label="ym")
        if signal == "plant.dy":
            axis.plot(runs[0]["signals"]["time"], runs[0]["signals"]["reference.dym"], "k--", lw=0.8,
                      label="dym")
        axis.set_title(title, fontsize=10)
        axis.set_ylabel(title.split(" (")[-1].rstrip(")") if " (" in title else "", fontsize=8)
        axis.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    handles, labels = axes[1, 0].get_legend_handles_labels()
    axes[1, 0].legend(handles[:1], labels[:1], fontsize=7)  # the band
    for axis in axes[-1]:
        axis.set_xlabel("t (s)")
    fig.suptitle(f"{name}: {configured.description}", fontsize=11)
    fig.tight_layout()
    return fig


def choices_text() -> str:
    return """The numbers depend on these choices (the paper is ambiguous there; all of them: docs/model.md, section 10):
- Normalised FLS inputs saturated to the universe [-E_i, E_i]; sigmoid membership functions (slope 7 pendulum, 1.5 manipulator).
- Modified tracking error E = e - (a0 + a1 t) exp(-5 t) (Remark 3) used by all three controllers, e(0), de(0) latched at the end of initialisation.
- Comparison controllers are documented stand-ins with the same learning rate (gamma = 300): `fixed` (alpha = 1) for [46], `fae` (alpha = 1 plus w_hat, gamma_w = gamma) for [28]; the equations of [46] and [28] are not public here.
- Pendulum disturbance d(t) enters additively in dx2; horizon 0-20 s; ts is the earliest time after which |e| <= 5 % max|ym| until T; es1, es2 are 100 max|e|, 100 max|de| over the last reference period [T - 2 pi, T] over max|ym|, max|dym|.
- Sampled-data controller: u held over each communication step, theta += h * dtheta; plants integrated with RK4 at internal steps <= 0.1 ms; scores by the trapezoidal rule on the communication grid."""


def peak_memory_mib() -> float:
    """Peak resident memory of this process and of its largest finished worker (Linux: KiB)."""
    import resource  # here, not at module level: a Unix-only module that only this figure needs

    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, children) / 1024.0


CLAIMS_METHOD = (
    "Each claim is decided on step ladders: every case also runs at half the scenario's step, and a "
    "case that an open claim needs at a further half (`--refine`). A score is its value at the finest "
    "step run, ± its numerical error: the change of that score over the last halving (the loop is "
    "first order in the step). A comparison is decided only when the gap exceeds the sum of both "
    "errors; otherwise it is *not decided at this accuracy*; one decided by a gap under "
    f"{100 * claims_module.CLOSE_MARGIN:g} % of the values says *close*. The tables above are at the scenario's "
    "step, so their digits differ from the values here where the numerical error reaches them.")
PAPER_VALUES = (
    "The paper's Tables I and II are not in the text of the paper we have (it holds their captions, "
    "not their numbers), so these claims are checked against the paper's statements about the tables "
    "(which controller is best in which score), not against its values.")


def horizon(rows: list) -> tuple:
    """(start, stop) of the runs (they share one horizon: the scenarios' 0-20 s or --stop)."""
    starts = {row["start"] for row in rows} or {0.0}
    stops = {row["stop"] for row in rows} or {math.nan}
    return min(starts), max(stops)


def horizon_text(rows: list, model_exchange: bool = False) -> str:
    """The header's words on the horizon and on the scores it does not define (harness/scores.py decides)."""
    start, stop = horizon(rows)
    undefined = {}
    for metric in SCORE_KEYS:
        reason = undefined_reason(metric, start, stop)
        if reason is not None:
            undefined.setdefault(reason, []).append(HEADINGS[metric])
    text = (f"from {start:g} to {stop:g} s, recorded and scored on the scenario's step as output grid."
            if model_exchange else f"from {start:g} to {stop:g} s at the scenario's communication step.")
    for reason, names in undefined.items():
        text += (f" On this horizon {' and '.join(names)} are not defined ({reason}): the tables show n/a and "
                 "the claims on them are not decided.")
    return text


def units_text(units: dict) -> str:
    """One score's unit over the scenarios {name: unit}: the unit alone when they share it, else each unit
    with its scenarios (``N2.s in pendulum_case1, pendulum_case2; V2.s in motor_arm``)."""
    by_unit = {}
    for name, unit in units.items():
        by_unit.setdefault(unit, []).append(name)
    if len(by_unit) == 1:
        return next(iter(by_unit))
    return "; ".join(f"{unit} in {', '.join(names)}" for unit, names in by_unit.items())


def reading_guide(names) -> list:
    """What the report's names mean: the controllers, the scores with their units in each of the scenarios
    ``names`` (from the units their FMUs declare), n/a, not settled."""
    lines = ["## How to read this report", "", "The controllers (the `variant` parameter of the controller FMU; "
             "docs/model.md section 6):", ""]
    lines += [f"- `{v.name}` (variant {v.code}): {v.label}" for v in variants.VARIANTS if v.name in CONTROLLERS]
    units = {name: score_units(scenarios.load(name)) for name in names}
    lines += ["", "The scores (docs/model.md section 9) [unit]:", ""]
    for metric in SHOWN_METRICS:
        unit = units_text({name: units[name][metric] for name in names})
        lines.append(f"- {HEADINGS[metric]} [{unit}]: {DEFINITIONS[metric]}")
    lines += ["", "*n/a*: the score is not defined on the run's horizon; *not settled*: |e| did not stay inside the "
              f"{100 * SETTLING_BAND:g} % band up to the stop time (ts is then no number, not the stop time).", ""]
    return lines


def figure_caption(number: int, path: Path, rows: list) -> str:
    name = path.stem
    steps = ", ".join(f"{h:g}" for h in sorted({r["step"] for r in rows if r["scenario"] == name}))
    controllers = "; ".join(legend_label(c) for c in CONTROLLERS)
    return (f"*Figure {number}: {name}, {scenarios.load(name).description}; every controller at the scenario's "
            f"step h = {steps} s, signals drawn every 0.01 s. Left column: x1 with ym (dashed), the tracking "
            "error e, the error norm ||e||; right column: x2 with dym (dashed), de, the control input u. "
            f"Controllers: {controllers}. Grey band on e: ±{100 * SETTLING_BAND:g} % of max|ym|, the band of the "
            "settling time ts.*")


def report_markdown(rows: list, claims: list, convergence: dict, figure_paths: list, wall_s: float, jobs: int,
                    peak_mib: float = float("nan"), beyond_rows=(), rtol: float | None = None) -> str:
    how = ("one FMI co-simulation (controller, plant and reference FMUs coupled by the feedthrough-aware master)"
           if rtol is None else
           f"one Model Exchange run (the native FMUs integrated together by CVODE, rtol {rtol:g}, "
           "harness/me_master.py: no communication step)")
    parts = ["# Table I / Table II: co-simulation report", "",
             f"Generated by `python -m harness tables` in {wall_s:.1f} s wall (with the claims' step ladders) "
             f"on {jobs} processes "
             f"(peak memory of the largest process {peak_mib:.0f} MiB). "
             f"Each row is {how} {horizon_text(rows, model_exchange=rtol is not None)}", ""]
    parts += reading_guide(list(dict.fromkeys(row["scenario"] for row in [*rows, *beyond_rows])))
    parts += ["## Table I: inverted pendulum", ""]
    for name in PENDULUM:
        parts += [f"### {name}: {scenarios.load(name).description}", "", *table_block(rows, name)]
    parts += ["## Table II: single-link manipulator with friction", "", *table_block(rows, "manipulator")]
    if beyond_rows:
        beyond = scenarios.load(BEYOND_PAPER)
        parts += ["## Beyond the paper: a third-order plant", "",
                  f"{beyond.description}; the controller at order n = 3 (inputs e, de, d2e; ||e|| over all "
                  f"three) with m = 2 and 3 fuzzy sets per input, step {beyond.step:g} s "
                  "(converged by halving, docs/general_order.md).", "", beyond_paper_table(beyond_rows), ""]
        notes = table_notes(list(beyond_rows))
        parts += [*notes, ""] if notes else []
    parts += ["## Claims of the paper, checked", "", PAPER_VALUES, "", CLAIMS_METHOD if rtol is None else CLAIMS_METHOD_ME,
              ""]
    parts += claims_module.claims_markdown(claims)
    parts += ["", "## Choices the numbers depend on", "", choices_text(), ""]
    parts += ["## Communication step (validated step, 1 %)", ""]
    if convergence:
        parts += [convergence_summary(convergence), "",
                  "The full evidence (every step of the ladder) is in `docs/convergence.md`.", ""]
    else:
        parts += ["No step-size study found: run `python -m harness convergence`.", ""]
    if figure_paths:
        parts += ["## Figures (like the paper's Figs. 4-8)", ""]
        for number, path in enumerate(figure_paths, 1):
            parts += [f"![{path.stem}]({path.name})", "", figure_caption(number, path, rows), ""]
    return "\n".join(parts) + "\n"


CLAIMS_METHOD_ME = (
    "Model Exchange (`--algorithm me`) has no step to halve: each claim is decided on tolerance ladders. Every "
    f"case also runs at a {claims_module.TOLERANCE_FACTOR:g} times looser rtol, and a case that an open claim "
    f"needs at a {claims_module.TOLERANCE_FACTOR:g} times tighter one (`--refine`). A score is its value at the "
    "tightest rtol run, ± the change of that score from the looser run (CVODE's error is about proportional to "
    "rtol, so the change overstates the error left). A comparison is decided only when the gap exceeds the sum of "
    "both errors; otherwise it is *not decided at this accuracy*.")


def half_step_case(case: Case) -> Case:
    """The same case at half its step (no figure signals): the error estimate of the claims; for Model Exchange
    the same case at a TOLERANCE_FACTOR looser rtol."""
    if case.algorithm == MODEL_EXCHANGE:
        return Case(case.scenario, case.controller, stop=case.stop, algorithm=MODEL_EXCHANGE,
                    rtol=case.rtol * claims_module.TOLERANCE_FACTOR)
    return Case(case.scenario, case.controller, step=case.build().step / 2, stop=case.stop)


def case_cost(case: Case) -> int:
    return case.build().steps


def finer_case(name: str, controller: str, ladder: list, stop: float | None) -> Case:
    """The next rung of a case's ladder: half its finest step, or (Model Exchange) a tighter rtol."""
    if all(o.get("rtol") for o in ladder):
        return Case(name, controller, stop=stop, algorithm=MODEL_EXCHANGE,
                    rtol=min(o["rtol"] for o in ladder) / claims_module.TOLERANCE_FACTOR)
    return Case(name, controller, step=min(o["step"] for o in ladder) / 2, stop=stop)


def refine_open_claims(ladders: dict, stop: float | None, jobs: int, levels: int) -> tuple[list, list]:
    """(claims, refined cases): up to ``levels`` further halvings of the step (tighter tolerances for
    Model Exchange) for the cases a claim still open needs (``ladders`` gains their runs)."""
    claims = claims_module.claims_check(ladders)
    refined = []
    for _ in range(levels):
        open_cases = claims_module.undecided_cases(claims)
        if not open_cases:
            break
        finer = [finer_case(name, controller, ladders[(name, controller)], stop)
                 for name, controller in sorted(open_cases)]
        for outcome in run_cases(sorted(finer, key=case_cost, reverse=True), jobs=jobs,
                                 description="claims: finer steps"):
            ladders[(outcome["scenario"], outcome["controller"])].append(outcome)
            refined.append((outcome["scenario"], outcome["controller"], outcome.get("rtol") or outcome["step"]))
        claims = claims_module.claims_check(ladders)
    return claims, refined


def ladder_words(model_exchange: bool) -> str:
    """How the claims' ladders begin: each case at h and h/2, or (Model Exchange) at rtol and a looser one."""
    return (f"at rtol and {claims_module.TOLERANCE_FACTOR:g} rtol" if model_exchange else "at h and h/2")


def communication_steps(outcomes) -> int:
    """The communication steps of co-simulation runs, from each outcome's horizon and step."""
    return sum(round((o["stop"] - o["start"]) / o["step"]) for o in outcomes)


def run_summary(paper_cases: int, pooled: int, beyond: int, refined: int, pool_s: float, wall_s: float, jobs: int,
                peak_mib: float, steps: int | None, model_exchange: bool) -> str:
    """The command's first line: every run it made, by kind, with its wall time (README.md quotes the counts)."""
    return (f"{pooled + refined} runs: {pooled} in one pool in {pool_s:.1f} s (the {paper_cases} cases of Tables I/II "
            f"{ladder_words(model_exchange)}, {beyond} of the third-order plant), {refined} finer for open claims in "
            f"{wall_s - pool_s:.1f} s; " + (f"{steps} communication steps, " if steps is not None else "")
            + f"{wall_s:.1f} s wall on {jobs} processes; peak memory {peak_mib:.0f} MiB (largest process)")


#: the figure the README shows; ``tables --apply`` copies it from the report into docs/
README_FIGURE = "pendulum_case2.png"
DOCS_DIR = ROOT / "docs"


def tables_command(args) -> int:
    out = Path(args.out)
    outputs = [out / name for name in ("table1.csv", "table2.csv", "table3_beyond_paper.csv", "report.md",
                                       *(f"{n}.png" for n in ALL_SCENARIOS))]
    cli_args.refuse_tracked(outputs)
    cli_args.check_writable(outputs)  # before the first run; it makes the folder
    jobs = args.jobs or default_jobs()
    me = args.algorithm == MODEL_EXCHANGE
    if not me and args.rtol is not None:
        raise cli_args.UsageError("--rtol is the tolerance of --algorithm me; co-simulation has a step")
    rtol = (args.rtol or DEFAULT_RTOL) if me else None
    cases = table_cases(args.stop, args.algorithm, rtol)
    # every case at h (the tables) and at h/2 (the claims' error estimates) in one pool,
    # the longest runs first, so both cores finish together
    extra = beyond_paper_cases(args.stop, args.algorithm, rtol)  # the third-order plant, beyond the paper (no claims)
    runs = sorted([*cases, *map(half_step_case, cases)], key=case_cost, reverse=True)
    started = clock.perf_counter()
    everything = sorted([*runs, *extra], key=case_cost, reverse=True)
    outcomes = dict(zip(everything, run_cases(everything, jobs=jobs,
                                              description=f"Table I/II {ladder_words(me)}, third-order plant")))
    rows = [outcomes[case] for case in cases]
    beyond_rows = [dict(outcomes[case], sets=dict(case.overrides)["controller.sets"]) for case in extra]
    ladders = claims_module.ladders_from_rows([outcomes[case] for case in runs])
    ladder_s = clock.perf_counter() - started
    claims, refined = refine_open_claims(ladders, args.stop, jobs, args.refine)
    wall_s = clock.perf_counter() - started
    peak_mib = peak_memory_mib()
    convergence = load_convergence()
    for row in rows:  # the validated step is a co-simulation's: Model Exchange has none
        row["validated_step"] = None if me else validated_step(convergence, row["scenario"], row["controller"])
    start, stop = horizon(rows)
    undefined = {}  # e.g. es1, es2 on a --stop shorter than one reference period
    for metric in SCORE_KEYS:
        reason = undefined_reason(metric, start, stop)
        if reason is not None:
            undefined.setdefault(reason, []).append(HEADINGS[metric])
    for reason, names in undefined.items():
        print(f"note: {' and '.join(names)} are n/a in every table and their claims are not decided: {reason}",
              file=sys.stderr)
    write_table(out / "table1.csv", [r for r in rows if r["scenario"] in PENDULUM])
    write_table(out / "table2.csv", [r for r in rows if r["scenario"] == "manipulator"])
    write_table(out / "table3_beyond_paper.csv", beyond_rows,
                ("scenario", "controller", "sets", *TABLE_COLUMNS[2:-2], "status"))
    figure_paths = figures(rows, out)
    atomic_files.write_text(out / "report.md", report_markdown(rows, claims, convergence, figure_paths, wall_s, jobs, peak_mib,
                                                   beyond_rows, rtol))
    print(run_summary(len(cases), len(everything), len(extra), len(refined), ladder_s, wall_s, jobs, peak_mib,
                      None if me else communication_steps([*(o for ladder in ladders.values() for o in ladder),
                                                            *(outcomes[case] for case in extra)]), me))
    for name in ALL_SCENARIOS:
        print(f"\n{name}\n{paper_table(rows, name)}")
    print(f"\n{BEYOND_PAPER} (beyond the paper)\n{beyond_paper_table(beyond_rows)}")
    print("\nclaims (decided on the step ladders, see the report):")
    for claim in claims:
        print(f"  {claim.verdict:29s} {claim.label}")
    if refined:
        print("refined for open claims: " + ", ".join(f"{s}/{c} at {h:g}" + (" (rtol)" if me else " s")
                                                       for s, c, h in refined))
    print(f"\nwritten: {out / 'table1.csv'}, {out / 'table2.csv'}, {out / 'table3_beyond_paper.csv'}, "
          f"{out / 'report.md'}, "
          f"{len(figure_paths)} figures")
    failed = [r for r in rows + beyond_rows if r["status"] != "ok"]
    for row in failed:
        print(f"error: {row['scenario']}/{row['controller']}: {row['reason']}", file=sys.stderr)
    if args.apply:
        if me:
            print("error: --apply refused: the README's figure is the co-simulation's (run without --algorithm me)",
                  file=sys.stderr)
            return 1
        if failed or args.stop is not None:
            print("error: --apply refused: the docs show complete runs over the scenarios' horizon "
                  "(no --stop, no failed run)", file=sys.stderr)
            return 1
        target = DOCS_DIR / README_FIGURE
        atomic_files.write_bytes(target, (out / README_FIGURE).read_bytes())
        print(f"applied: {target} (the README's figure) from {out / README_FIGURE}")
    return 1 if failed else 0


def register(commands):
    paper, pooled, beyond = pool_counts()
    tables = commands.add_parser("tables", help=f"run Table I/II and write the report: {pooled} co-simulations "
                                                f"in one pool (the {paper} cases at their step and at half of it, "
                                                f"{beyond} of the third-order plant beyond the paper), then finer "
                                                "ones for the claims left open (--refine)")
    tables.add_argument("--out", default="results", help="output folder (default results/, ignored by git)")
    tables.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    tables.add_argument("--stop", type=cli_args.positive_float,
                        help="shorter horizon (tests); default the scenarios' 20 s")
    tables.add_argument("--refine", type=cli_args.non_negative_int, default=1, metavar="LEVELS",
                        help="further halvings of the step for the cases an open claim needs (default 1; 0: "
                             "decide on h and h/2 only)")
    tables.add_argument("--algorithm", choices=("feedthrough", MODEL_EXCHANGE), default="feedthrough",
                        help="feedthrough: our co-simulation master (default); me: Model Exchange, the native FMUs "
                             "integrated by CVODE, no step (--edition native; docs/model_exchange.md)")
    tables.add_argument("--rtol", type=cli_args.positive_float,
                        help=f"--algorithm me: CVODE's relative tolerance (default {DEFAULT_RTOL:g})")
    tables.add_argument("--apply", action="store_true",
                        help=f"also copy the README's figure ({README_FIGURE}) into docs/ (full runs only)")
    tables.set_defaults(handler=tables_command)
