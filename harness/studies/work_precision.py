"""Work-precision in one run: ``python -m harness work-precision [--apply]``.

For the pendulum (case 1) and the manipulator, controller vud, native edition: the error of ITAE
against the converged value (the step study's Richardson extrapolation, docs/convergence.md)
and the CPU time of the whole run (instantiation, initialisation, the loop, clean-up: the
process's CPU time around one ``simulate``, the best of ``--repeat`` runs; runs over 2 s once),
for

* our co-simulation master, feedthrough-aware (a ladder of communication steps);
* our co-simulation master, Jacobi (every connection delayed one step; a ladder of steps);
* Model Exchange (harness/me_master.py: CVODE, a ladder of relative tolerances) with the
  scenario's step as output grid, as every other run of the project records it;
* Model Exchange with a 1 ms output grid (the grid only decides where the outputs are evaluated
  and how finely the trapezoidal rule integrates the scores; the trajectory is the same).

ITAE is taken on the true error ym - y of the plant's and the reference's outputs at the same
time (as the step study does: under Jacobi the reference's own e pairs ym(t) with an older y).
The runs are sequential, in this process, so their CPU times compare; on a machine shared with
other jobs they still vary by some 10-30 %.  The figure and the table go to results/work_precision/;
``--apply`` also writes docs/work_precision.md and docs/work_precision.png.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time as clock
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from .. import atomic_files, cli_args, variants
from .. import scenario as scenarios
from ..cases import simulate_any
from ..master import SimulationFailed
from ..me_master import ALGORITHM as MODEL_EXCHANGE
from ..scores import itae
from .step_study import load_convergence, true_error_signals

ROOT = Path(__file__).resolve().parents[2]
DOCS_PAGE = ROOT / "docs" / "work_precision.md"
DOCS_FIGURE = ROOT / "docs" / "work_precision.png"
DEFAULT_OUT = Path("results") / "work_precision"
TARGET = 1e-4  # 0.01 % of ITAE
CONTROLLER = variants.PROPOSED
ME_GRID = 1e-3  # the coarser output grid of the second Model Exchange series
RTOLS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
#: per scenario: the step ladders of the two co-simulation schemes
LADDERS = {
    "pendulum_case1": {"feedthrough": (6.4e-4, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5),
                       "jacobi": (1.6e-4, 1e-4, 5e-5, 2.5e-5, 1.25e-5)},
    "manipulator": {"feedthrough": (1e-4, 5e-5, 2.5e-5, 1.25e-5),
                    "jacobi": (4e-5, 2e-5, 1e-5, 5e-6)},
}
SERIES = ("feedthrough", "jacobi", "me", "me-1ms")
LABELS = {"feedthrough": "co-simulation, our feedthrough master (step ladder)",
          "jacobi": "co-simulation, Jacobi (step ladder)",
          "me": "Model Exchange, CVODE (rtol ladder), output grid = the scenario's step",
          "me-1ms": f"Model Exchange, CVODE (rtol ladder), output grid {ME_GRID * 1e3:g} ms"}
LONG_RUN_S = 2.0  # CPU seconds beyond which a run is timed once


def measure(name: str, series: str, setting: float, stop, repeat: int, fmu_paths: dict) -> dict:
    """One point: the run's ITAE (true error) and its CPU time (best of ``repeat``)."""
    me = series.startswith("me")
    step = ME_GRID if series == "me-1ms" else (None if me else setting)
    scenario = scenarios.configure(name, CONTROLLER, step, stop, fit_stop="move")
    point = {"scenario": name, "series": series, "step": scenario.step, "rtol": setting if me else None}
    best = math.inf
    for attempt in range(max(1, repeat)):
        began = clock.process_time()
        try:
            result = simulate_any(scenario, MODEL_EXCHANGE if me else series, fmu_paths,
                                  rtol=setting if me else None)
        except SimulationFailed as failure:
            return dict(point, status="failed", reason=str(failure).splitlines()[0])
        best = min(best, clock.process_time() - began)
        if best > LONG_RUN_S:
            break
    y, dy = (result.signal(n) for n in true_error_signals(scenario))
    ym, dym = result.role("ym"), result.role("dym")
    point.update(status="ok", ITAE=itae(result.time, ym - y, dym - dy), cpu_s=best, rows=result.rows)
    if result.solver:
        point.update(steps=result.solver["steps"], derivative_evaluations=result.solver["derivative_evaluations"])
    return point


def work_precision(names=tuple(LADDERS), stop=None, repeat: int = 3) -> dict:
    fmu_paths = build_fmu.ensure_built()
    convergence = load_convergence()
    began = clock.perf_counter()
    points, converged = [], {}
    for name in names:
        entry = convergence["scenarios"][name]["controllers"][CONTROLLER]["converged"]
        converged[name] = entry["ITAE"] if stop is None else None
        settings = {**LADDERS[name], "me": RTOLS, "me-1ms": RTOLS}
        for series in SERIES:
            for setting in settings[series]:
                point = measure(name, series, setting, stop, repeat, fmu_paths)
                reference = converged[name]
                if point["status"] == "ok" and reference:
                    point["error"] = point["ITAE"] / reference - 1
                points.append(point)
                print(f"  {name} {series:11s} {setting:<9g} " + (
                    f"ITAE error {100 * point.get('error', math.nan):+.4f} %  CPU {point['cpu_s']:.3f} s"
                    if point["status"] == "ok" else point["reason"]), file=sys.stderr)
    return {"points": points, "converged": converged, "controller": CONTROLLER, "target": TARGET,
            "repeat": repeat, "stop": stop, "wall_s": clock.perf_counter() - began}


def cheapest_within(points: list, name: str, series: str, target: float = TARGET):
    """The cheapest point of a series within the target, or None."""
    within = [p for p in points if p["scenario"] == name and p["series"] == series and p["status"] == "ok"
              and abs(p.get("error", math.inf)) <= target]
    return min(within, key=lambda p: p["cpu_s"]) if within else None


def verdicts(study: dict) -> dict:
    """Per scenario: the cheapest point within the target of each series, and whether Model Exchange (on the
    scenario's grid, and on the 1 ms grid) costs no more CPU than the cheapest co-simulation scheme there."""
    result = {}
    for name in dict.fromkeys(p["scenario"] for p in study["points"]):
        best = {series: cheapest_within(study["points"], name, series, study["target"]) for series in SERIES}
        co_simulation = [best[s] for s in ("feedthrough", "jacobi") if best[s]]
        cheapest_cs = min((p["cpu_s"] for p in co_simulation), default=math.inf)
        result[name] = {"best": best, "cheapest_co_simulation_s": cheapest_cs,
                        "met": {s: bool(best[s]) and best[s]["cpu_s"] <= cheapest_cs for s in ("me", "me-1ms")}}
    return result


def figure(study: dict, path: Path) -> Path:
    import matplotlib  # here, not at module level: a heavy import, paid only when the figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(p["scenario"] for p in study["points"]))
    fig, axes = plt.subplots(1, len(names), figsize=(6 * len(names), 4.8), squeeze=False)
    styles = {"feedthrough": ("tab:blue", "o-"), "jacobi": ("tab:orange", "s-"), "me": ("tab:green", "^-"),
              "me-1ms": ("tab:olive", "v--")}
    for axis, name in zip(axes[0], names):
        for series in SERIES:
            points = [p for p in study["points"] if p["scenario"] == name and p["series"] == series
                      and p["status"] == "ok" and "error" in p]
            if not points:
                continue
            colour, style = styles[series]
            axis.loglog([p["cpu_s"] for p in points], [max(abs(p["error"]), 1e-9) * 100 for p in points], style,
                        color=colour, label=LABELS[series], ms=5, lw=1)
            for p in points:
                label = f"{p['rtol']:.0e}" if p["rtol"] else f"{p['step'] * 1e6:g} us"
                axis.annotate(label, (p["cpu_s"], max(abs(p["error"]), 1e-9) * 100), fontsize=6,
                              textcoords="offset points", xytext=(3, 3), color=colour)
        axis.axhline(100 * study["target"], color="k", lw=0.8, ls=":", label=f"{100 * study['target']:g} %")
        axis.set_xlabel("CPU time of the run (s)")
        axis.set_ylabel("|ITAE error| against the converged value (%)")
        axis.set_title(f"{name} / {study['controller']}", fontsize=10)
        axis.grid(alpha=0.3, which="both")
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    atomic_files.save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def _cpu(point) -> str:
    return f"{point['cpu_s']:.3f} s ({_setting(point)})" if point else "not reached in the ladder"


def _setting(point) -> str:
    return f"rtol {point['rtol']:g}, grid {point['step']:g} s" if point["rtol"] else f"step {point['step']:g} s"


def markdown(study: dict, figure_name: str) -> str:
    judged = verdicts(study)
    lines = ["# Work-precision: co-simulation against Model Exchange", "",
             f"Generated by `python -m harness work-precision --apply` ({study['wall_s']:.0f} s wall; native "
             f"edition, FMI 2.0, controller {study['controller']}; CPU time of each whole run, best of "
             f"{study['repeat']} (runs over {LONG_RUN_S:g} s once), measured one run at a time on a 2-core machine "
             "shared with other jobs, so single figures vary by 10-30 %). The error is that of ITAE on the true "
             "error ym - y against the step study's converged value (docs/convergence.md). How: "
             "harness/studies/work_precision.py.", "",
             f"![work-precision]({figure_name})", "",
             f"## At {100 * study['target']:g} % accuracy", "",
             "| scenario | cheapest feedthrough | cheapest Jacobi | cheapest Model Exchange (scenario grid) | "
             "cheapest Model Exchange (1 ms grid) | ME no dearer than the cheapest co-simulation |",
             "|---|---|---|---|---|---|"]
    for name, verdict in judged.items():
        best, met = verdict["best"], verdict["met"]
        lines.append(f"| {name} | {_cpu(best['feedthrough'])} | {_cpu(best['jacobi'])} | {_cpu(best['me'])} | "
                     f"{_cpu(best['me-1ms'])} | scenario grid: {'yes' if met['me'] else '**no**'}; 1 ms grid: "
                     f"{'yes' if met['me-1ms'] else '**no**'} |")
    lines += ["", "## Every point", "",
              "| scenario | series | step or rtol | output grid (s) | ITAE error | CPU (s) | steps | derivative "
              "evaluations |", "|---|---|---|---|---|---|---|---|"]
    for p in study["points"]:
        if p["status"] != "ok":
            lines.append(f"| {p['scenario']} | {p['series']} | {p['rtol'] or p['step']:g} | | {p['status']}: "
                         f"{p.get('reason', '')} |||| ")
            continue
        error = f"{100 * p['error']:+.3g} %" if "error" in p else "n/a"
        lines.append(f"| {p['scenario']} | {p['series']} | {p['rtol'] or p['step']:g} | {p['step']:g} | {error} | "
                     f"{p['cpu_s']:.3f} | {p.get('steps', p['rows'] - 1)} | {p.get('derivative_evaluations', '')} |")
    return "\n".join(lines) + "\n"


def work_precision_command(args) -> int:
    out = Path(args.out)
    cli_args.refuse_tracked([out / "work_precision.json", out / "work_precision.md", out / "work_precision.png"])
    if args.from_json:
        study = json.loads(Path(args.from_json).read_text())
    else:
        study = work_precision(tuple(args.scenarios or LADDERS), args.stop, args.repeat)
    out.mkdir(parents=True, exist_ok=True)
    atomic_files.write_text(out / "work_precision.json", json.dumps(study, indent=1))
    figure(study, out / "work_precision.png")
    text = markdown(study, "work_precision.png")
    atomic_files.write_text(out / "work_precision.md", text)
    written = [out / "work_precision.json", out / "work_precision.md", out / "work_precision.png"]
    for name, verdict in verdicts(study).items():
        print(f"{name}: at {100 * study['target']:g} %: " + "; ".join(
            f"{series} {_cpu(point)}" for series, point in verdict["best"].items()))
    if args.apply:
        if study.get("stop") is not None:
            print("error: --apply needs the full horizon (no --stop)", file=sys.stderr)
            return 1
        atomic_files.write_text(DOCS_PAGE, text)
        figure(study, DOCS_FIGURE)
        written += [DOCS_PAGE, DOCS_FIGURE]
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def _ladder_scenario(text: str) -> str:
    if text not in LADDERS:
        raise argparse.ArgumentTypeError(f"no step ladders for {text!r}; valid: {', '.join(LADDERS)}")
    return text


def register(commands):
    command = commands.add_parser("work-precision", help="ITAE error against CPU time: co-simulation (feedthrough, "
                                                         "Jacobi) step ladders and Model Exchange tolerance ladders")
    command.add_argument("scenarios", nargs="*", type=_ladder_scenario, metavar="SCENARIO",
                         help=f"default: {', '.join(LADDERS)}")
    command.add_argument("--repeat", type=cli_args.positive_int, default=3,
                         help="runs per point, the fastest counts (default 3; runs over 2 s once)")
    command.add_argument("--stop", type=cli_args.positive_float,
                         help="shorter horizon (tests: no converged value, so no error); default 20 s")
    command.add_argument("--out", default=str(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT}/)")
    command.add_argument("--from-json", type=cli_args.existing_file,
                         help="do not run: redraw from this study's work_precision.json")
    command.add_argument("--apply", action="store_true", help="also write docs/work_precision.md and its figure")
    command.set_defaults(handler=work_precision_command)


__all__ = ["work_precision", "verdicts", "cheapest_within", "markdown"]
