"""The step study by accuracy: ``python -m harness convergence [SCENARIO...]``.

For every scenario x controller x algorithm (feedthrough, jacobi) it finds the
**validated step (1 %)**: the largest communication step whose ITAE, IAE and
Ec are all within 1 % of the converged values.

Converged values
    Our feedthrough master from the scenario's step down, halving the step
    until halving changes ITAE, IAE and Ec by less than 0.1 %, or by less than
    0.5 % while each change shrank 1.6-2.5x from the previous halving (the
    first-order regime of the sampled-data loop: theta += h dtheta, u held
    over the step).  The converged value is the Richardson extrapolation
    2 f(h/2) - f(h) of the last two levels: exact to O(h^2) in the
    first-order regime, and otherwise within the last change (< 0.1 %) of
    f(h/2).  Both algorithms converge to the same continuous-time loop, so
    one converged value per scenario x controller serves both.  If the ladder
    reaches ``--finest-step`` first, the study says so (``fallback``) and
    uses the extrapolation of its last two levels.

Scores
    ITAE, IAE on the true tracking error ym - y of the reference's and the
    plant's outputs at the same time, Ec on the u the plant was given
    (``run_scored``): under Jacobi the reference's own e pairs ym(t_n) with
    y(t_{n-1}), a bias of about 1 % of ITAE at the pendulum's 0.16 ms.

Search
    Steps lie on the ladder 1, 1.25, 1.6, 2, 2.5, 3.2, 4, 5, 6.4, 8 x 10^k
    (closed under doubling; each rung up to the 0.05 s limit divides the 20 s horizon).  From the
    scenario's step the search doubles while the run stays within 1 %, or
    halves until it does, then tests the two rungs between the last step
    within 1 % and the first one outside it.  The validated step is
    therefore exact to one rung: the true limit lies below the next rung
    (at most 1.28x higher), provided the error grows with the step between
    neighbouring rungs.  A search that finds no step within 1 % down to
    ``--finest-step`` reports none and says so; one that stays within 1 % up
    to ``--limit`` reports the limit and says so.

The scenario's step (``chosen_step``) is the smallest feedthrough validated
step of its three controllers (the paper's, ``variants.PAPER``; every variant of the registry is
studied, for its own validated steps): the step of Table I/II and the regression.

Nothing the repository tracks is overwritten unless asked: the study goes to
``results/step_study/`` (``--out``); ``--apply`` also writes
harness/scenarios/convergence.json, docs/convergence.md and the chosen step
into each scenario file.
"""
from __future__ import annotations

import json
import math
import re
import shutil
import sys
import tempfile
import time as clock
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from .. import atomic_files, cli_args, variants
from .. import scenario as scenarios
from ..cases import default_jobs, parallel_map
from ..master import Divergence, SimulationFailed, simulate
from ..scores import score

ROOT = Path(__file__).resolve().parents[2]
CONVERGENCE_JSON = scenarios.SCENARIO_DIR / "convergence.json"
CONVERGENCE_MD = ROOT / "docs" / "convergence.md"
DEFAULT_OUT = Path("results") / "step_study"  # under the working directory, like tables and regress
CONTROLLERS = variants.NAMES  # vud, fixed, fae
ALGORITHMS = ("feedthrough", "jacobi")
ALL_SCENARIOS = ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator")
METRICS = ("ITAE", "IAE", "Ec")
ACCURACY = 0.01  # validated: ITAE, IAE and Ec within 1 % of the converged values
CONVERGED_CHANGE = 0.001  # halving changes every metric by less than 0.1 %
FIRST_ORDER_CHANGE = 0.005  # ... or by less than 0.5 % while shrinking like h (ratio below)
FIRST_ORDER_RATIO = (1.6, 2.5)
RUNGS = (1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.4, 8.0)  # x 10^k


def _fmt(value, digits=4) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


# ----------------------------------------------------------- reading a study
def load_convergence(path: Path | None = None) -> dict:
    """The committed study (harness/scenarios/convergence.json), or {}."""
    path = path or CONVERGENCE_JSON
    if path.exists():
        return json.loads(path.read_text())
    return {}


def validated_step(convergence: dict, scenario: str, controller: str, algorithm: str = "feedthrough"):
    """The validated step (1 %) of one scenario x controller x algorithm, or None."""
    return convergence.get("scenarios", {}).get(scenario, {}).get("controllers", {}).get(controller, {}) \
        .get("validated_step", {}).get(algorithm)


def jacobi_safe_step(convergence: dict, scenario: str):
    """The smallest Jacobi validated step of a scenario's three controllers (a host that delays every link)."""
    steps = [validated_step(convergence, scenario, c, "jacobi") for c in CONTROLLERS]
    steps = [s for s in steps if s]
    return min(steps) if steps else None


def step_warning(scenario_name: str, controller: str, algorithm: str, step: float,
                 convergence: dict | None = None) -> str | None:
    """One line if ``step`` is beyond the validated step of this scenario x controller x algorithm."""
    convergence = load_convergence() if convergence is None else convergence
    limit = validated_step(convergence, scenario_name, controller, algorithm)
    if limit is None or step <= limit * (1 + 1e-9):
        return None
    return (f"warning: step {step:g} s is beyond the validated step (1 %) {limit:g} s of {scenario_name}/"
            f"{controller} with the {algorithm} algorithm (docs/convergence.md): ITAE, IAE and Ec may be off "
            f"by more than 1 %; use --step {limit:g}")


# ----------------------------------------------------------------- the math
def ladder_between(low: float, high: float) -> list:
    """The rungs strictly between ``low`` and ``high`` (ascending)."""
    found = []
    for exponent in range(math.floor(math.log10(low)) - 1, math.ceil(math.log10(high)) + 1):
        for rung in RUNGS:
            step = float(f"{rung}e{exponent}")
            if low * (1 + 1e-9) < step < high * (1 - 1e-9):
                found.append(step)
    return sorted(found)


def relative_error(outcome: dict, reference: dict) -> float:
    """Largest relative deviation of ITAE, IAE, Ec from ``reference``; inf for a failed run."""
    if outcome.get("status") != "ok":
        return math.inf
    return max(abs(outcome[m] - reference[m]) / abs(reference[m]) for m in METRICS)


def changes(fine: dict, coarse: dict) -> dict:
    """{metric: relative change} from ``coarse`` to ``fine`` (inf if either failed)."""
    if fine.get("status") != "ok" or coarse.get("status") != "ok":
        return {m: math.inf for m in METRICS}
    return {m: abs(coarse[m] - fine[m]) / abs(fine[m]) for m in METRICS}


def halving_converged(levels: list) -> bool:
    """The last halving changed every metric by < 0.1 %, or by < 0.5 % shrinking like h."""
    if len(levels) < 2:
        return False
    last = changes(levels[-1], levels[-2])
    if all(c < CONVERGED_CHANGE for c in last.values()):
        return True
    if len(levels) < 3 or any(c >= FIRST_ORDER_CHANGE for c in last.values()):
        return False
    previous = changes(levels[-2], levels[-3])
    low, high = FIRST_ORDER_RATIO
    return all(last[m] < CONVERGED_CHANGE or low <= previous[m] / last[m] <= high for m in METRICS)


def richardson(fine: dict, coarse: dict, metrics=METRICS) -> dict:
    """2 f(h/2) - f(h) for each metric: first-order error removed."""
    return {m: 2.0 * fine[m] - coarse[m] for m in metrics}


def search_validated(within, start: float, finest: float, limit: float) -> tuple:
    """(largest step with within(step) True, note or None); see the module text for the ladder."""
    if within(start):
        low = start
        while 2 * low <= limit * (1 + 1e-9):
            if not within(2 * low):
                break
            low *= 2
        else:
            return low, f"within 1 % up to the search limit {limit:g} s (not searched further)"
        high = 2 * low
    else:
        high = start
        while True:
            low = high / 2
            if low < finest * (1 - 1e-9):
                return None, f"no step within 1 % down to the finest step {finest:g} s"
            if within(low):
                break
            high = low
    for rung in ladder_between(low, high):  # at most two rungs between a step and its double
        if not within(rung):
            break
        low = rung
    return low, None


# ------------------------------------------------------------------- a study
def true_error_signals(scenario) -> tuple:
    """("plant.y", "plant.dy"): the outputs whose difference from ym, dym is the tracking error.

    The reference FMU's own e, de are computed from the y, dy it was given: with every link delayed
    (jacobi) that is y one step old, e(t_n) = ym(t_n) - y(t_{n-1}), an O(h) bias that is several
    percent of the small steady-state error.  The study scores every run on ym - y at the same time.
    """
    reference = scenario.signals["e"].split(".", 1)[0]
    sources = {c.target: c.source for c in scenario.connections}
    return sources[f"{reference}.y"], sources[f"{reference}.dy"]


def run_scored(name: str, controller: str, step: float, stop: float | None, algorithm: str,
               fmu_paths: dict | None) -> dict:
    """One run scored on the true tracking error ym - y (see true_error_signals); failures are rows."""
    scenario = scenarios.configure(name, controller, step, stop)
    outcome = {"step": scenario.step, "algorithm": algorithm}
    try:
        result = simulate(scenario, algorithm=algorithm, fmu_paths=fmu_paths)
    except SimulationFailed as failure:
        status = "diverged" if isinstance(failure.cause, Divergence) else "failed"
        return dict(outcome, status=status, reason=str(failure).splitlines()[0], wall_s=failure.result.wall_s)
    y, dy = (result.signal(n) for n in true_error_signals(scenario))
    ym, dym = result.role("ym"), result.role("dym")
    return dict(outcome, status="ok", reason="", **score(result.time, ym - y, dym - dy, ym, dym, result.role("u")),
                wall_s=result.wall_s)


def _slim(outcome: dict) -> dict:
    keep = ("step", "algorithm", "status", "reason", "ts", "ITAE", "IAE", "Ec", "tv_u", "wall_s")
    return {k: outcome[k] for k in keep if k in outcome}


def previous_runs(study: dict, name: str, controller: str) -> dict:
    """{(algorithm, step): outcome} of a previous study's 20 s feedthrough runs (either format).

    Only feedthrough runs: there the reference's e is ym - y at the same time, so the older scores
    (on the reference's e) equal the true-error scores; Jacobi runs are always run again.
    """
    entry = study.get("scenarios", {}).get(name, {})
    if study.get("stop"):
        return {}
    outcomes = (entry.get("controllers", {}).get(controller, {}).get("runs")
                or entry.get("ladder", {}).get(controller, []))
    return {(o.get("algorithm", "feedthrough"), float(f"{o['step']:.12g}")): dict(_slim(o), reused=True)
            for o in outcomes if o.get("algorithm", "feedthrough") == "feedthrough"}


def study_controller(name: str, controller: str, start: float, finest: float, limit: float,
                     stop: float | None, fmu_paths: dict | None = None, algorithms=ALGORITHMS,
                     reuse: dict | None = None) -> dict:
    """Converged values and validated steps of one scenario x controller (sequential runs)."""
    runs = dict(reuse or {})

    touched = set()

    def run(step: float, algorithm: str) -> dict:
        key = (algorithm, float(f"{step:.12g}"))
        touched.add(key)
        if key not in runs:
            runs[key] = _slim(run_scored(name, controller, key[1], stop, algorithm, fmu_paths))
        return runs[key]

    levels = [run(start, "feedthrough")]
    step, fallback = start, None
    while not halving_converged(levels):
        if step / 2 < finest * (1 - 1e-9):
            fallback = (f"halving did not converge down to the finest step {finest:g} s; converged values "
                        f"extrapolated from the last two levels")
            break
        step /= 2
        levels.append(run(step, "feedthrough"))
    if len(levels) >= 2 and all(lv["status"] == "ok" for lv in levels[-2:]):
        converged = richardson(levels[-1], levels[-2])
        converged["method"] = (f"Richardson 2 f(h/2) - f(h) from h = {levels[-2]['step']:g} s "
                               f"(last change {100 * max(changes(levels[-1], levels[-2]).values()):.3g} %)")
    else:
        converged = None
        fallback = fallback or "no two successive finished levels"
    result = {"converged": converged, "fallback": fallback,
              "levels": [lv["step"] for lv in levels], "validated_step": {}, "search_note": {}}
    for algorithm in algorithms:
        if converged is None:
            result["validated_step"][algorithm] = None
            result["search_note"][algorithm] = "no converged values to compare with"
            continue
        found, note = search_validated(lambda h: relative_error(run(h, algorithm), converged) <= ACCURACY,
                                       start, finest, limit)
        result["validated_step"][algorithm] = found
        result["search_note"][algorithm] = note
    for outcome in runs.values():
        if converged is not None and outcome["status"] == "ok":
            outcome["error_pct"] = {m: 100 * (outcome[m] / converged[m] - 1) for m in METRICS}
    used = {id(o) for o in runs.values() if not o.get("reused")} | {id(runs[k]) for k in touched}
    result["runs"] = sorted((o for o in runs.values() if id(o) in used), key=lambda o: (o["algorithm"], -o["step"]))
    return result


def _study_task(arguments: tuple) -> tuple:
    name, controller, start, finest, limit, stop, fmu_paths, reuse = arguments
    began = clock.perf_counter()
    result = study_controller(name, controller, start, finest, limit, stop, fmu_paths, reuse=reuse)
    result["wall_s"] = clock.perf_counter() - began
    return name, controller, result


def study(names: list, jobs: int, stop: float | None = None, start_step: float | None = None,
          finest_factor: float = 16.0, limit: float = 0.05, controllers=CONTROLLERS, reuse: dict | None = None) -> dict:
    """The whole study: one task per scenario x controller, longest first, on ``jobs`` processes."""
    # a private copy of the FMUs: a rebuild during the study (minutes to an hour) must not pull them away
    snapshot = Path(tempfile.mkdtemp(prefix="afc_step_study_"))
    fmu_paths = {name: Path(shutil.copy(path, snapshot / path.name)) for name, path in build_fmu.ensure_built().items()}
    tasks = []
    for name in names:
        start = start_step or scenarios.load(name).step
        for controller in controllers:
            previous = previous_runs(reuse, name, controller) if reuse and stop is None else {}
            tasks.append((name, controller, start, start / finest_factor, limit, stop, fmu_paths, previous))
    tasks.sort(key=lambda t: t[2])  # finest start first: the longest tasks start first
    began = clock.perf_counter()
    try:
        done = parallel_map(_study_task, tasks, jobs, description="step study", progress=None)
    finally:
        shutil.rmtree(snapshot, ignore_errors=True)
    convergence = {"criterion": criterion_text(), "accuracy": ACCURACY, "stop": stop, "scenarios": {}}
    for name in names:
        convergence["scenarios"][name] = {"start_step": next(t[2] for t in tasks if t[0] == name),
                                          "controllers": {}}
    for name, controller, result in done:
        convergence["scenarios"][name]["controllers"][controller] = result
    for entry in convergence["scenarios"].values():
        entry["chosen_step"], entry["chosen_note"] = chosen_step(entry)
    convergence["wall_s"] = clock.perf_counter() - began
    return convergence


def chosen_step(entry: dict) -> tuple:
    """(the scenario's step, a note or None): the smallest feedthrough validated step of the paper's variants
    (``variants.PAPER``; a variant beyond the paper has its own validated steps but sets no scenario's step)."""
    steps = [result["validated_step"].get("feedthrough") for controller, result in entry["controllers"].items()
             if controller in variants.PAPER]
    if steps and all(steps):
        return min(steps), None
    return entry["start_step"], "fallback: a controller has no feedthrough validated step; the scenario keeps its step"


def criterion_text() -> str:
    return (f"validated step (1 %): the largest step on the ladder {', '.join(f'{r:g}' for r in RUNGS)} x 10^k "
            f"whose ITAE, IAE and Ec are all within {100 * ACCURACY:g} % of the converged values (Richardson "
            f"extrapolation of our feedthrough master, halving until changes < {100 * CONVERGED_CHANGE:g} %, or "
            f"< {100 * FIRST_ORDER_CHANGE:g} % in the first-order regime)")


# ---------------------------------------------------------------- reporting
def convergence_summary(convergence: dict) -> str:
    names = " / ".join(CONTROLLERS)  # the variant registry's, in its order (the columns' values below)
    lines = [f"| scenario | chosen step (s) | validated step (1 %), feedthrough ({names}) | "
             f"validated step (1 %), jacobi ({names}) | ratio feedthrough / jacobi ({names}) |",
             "|---|---|---|---|---|"]
    notes = []
    for name, entry in convergence.get("scenarios", {}).items():
        ours = [validated_step(convergence, name, c, "feedthrough") for c in CONTROLLERS]
        jacobi = [validated_step(convergence, name, c, "jacobi") for c in CONTROLLERS]
        ratios = [a / b if a and b else None for a, b in zip(ours, jacobi)]
        lines.append(f"| {name} | {entry['chosen_step']:g} | " + " / ".join(_fmt(s, 3) for s in ours) + " | "
                     + " / ".join(_fmt(s, 3) for s in jacobi) + " | " + " / ".join(_fmt(r, 3) for r in ratios)
                     + " |")
        if entry.get("chosen_note"):
            notes.append(f"- {name}: {entry['chosen_note']}")
        for controller, result in entry.get("controllers", {}).items():
            if result.get("fallback"):
                notes.append(f"- {name}/{controller}: {result['fallback']}")
            for algorithm, note in result.get("search_note", {}).items():
                if note:
                    notes.append(f"- {name}/{controller}/{algorithm}: {note}")
    text = "\n".join(lines)
    if notes:
        text += "\n\nFallbacks and limits of the search:\n" + "\n".join(notes)
    if convergence.get("criterion"):
        text += f"\n\nCriterion: {convergence['criterion']}."
    return text


def convergence_markdown(convergence: dict) -> str:
    horizon = f"{convergence['stop']:g} s (short horizon)" if convergence.get("stop") else "the scenario's 20 s"
    reused = sum(1 for entry in convergence.get("scenarios", {}).values()
                 for result in entry.get("controllers", {}).values() for run in result.get("runs", ())
                 if run.get("reused"))
    reuse_text = f", {reused} of the runs reused from {convergence['reused_from']}" if reused else ""
    studied = convergence.get("studied")
    last_run = (f"the last run, of {', '.join(studied)}: " if studied else "") + \
        f"{convergence.get('wall_s', float('nan')):.0f} s wall on 2 cores shared with other jobs"
    earlier = [name for name in convergence.get("scenarios", {}) if studied and name not in studied]
    earlier_text = f"; {', '.join(earlier)} from earlier runs of the study" if earlier else ""
    parts = ["# Step study by accuracy", "",
             "Generated by `python -m harness convergence --apply` "
             f"({last_run}{earlier_text}, horizon {horizon}{reuse_text}). "
             "For every scenario x controller x algorithm: the **validated step (1 %)**, the largest "
             "communication step whose ITAE, IAE and Ec are all within 1 % of the converged values. "
             "`feedthrough` is our master (no delay along direct-feedthrough chains); `jacobi` delays every "
             "connection one step, as Ecos, libcosim, fmpy.ssp and fmu-manipulation-toolbox containers do. "
             "The chosen step of each scenario (Table I/II, regression) is the smallest feedthrough validated "
             "step of its three controllers. Every run is scored on the true tracking error ym - y (the "
             "plant's and the reference's outputs at the same time; under Jacobi the reference's own e pairs "
             "ym(t) with y one step older). How the converged values are computed and how precise the "
             "search is: `harness/studies/step_study.py` (the true limit lies below the next rung of the ladder, "
             "at most 1.28x higher).", "",
             convergence_summary(convergence), ""]
    for name, entry in convergence.get("scenarios", {}).items():
        parts += [f"## {name}", ""]
        parts += ["| controller | converged ITAE | IAE | Ec | how |", "|---|---|---|---|---|"]
        for controller, result in entry["controllers"].items():
            c = result.get("converged") or {}
            parts.append(f"| {controller} | {_fmt(c.get('ITAE'), 6)} | {_fmt(c.get('IAE'), 6)} | "
                         f"{_fmt(c.get('Ec'), 6)} | {c.get('method', result.get('fallback', ''))} |")
        parts += ["", "| controller | algorithm | step (s) | status | ITAE | IAE | Ec | error vs converged "
                  "(ITAE / IAE / Ec) | TV(u)/s |", "|---|---|---|---|---|---|---|---|---|"]
        for controller, result in entry["controllers"].items():
            for outcome in result["runs"]:
                error = outcome.get("error_pct")
                text = " / ".join(f"{error[m]:+.3g} %" for m in METRICS) if error else outcome.get("reason", "")
                mark = " **validated**" if outcome["step"] == result["validated_step"].get(outcome["algorithm"]) \
                    else ""
                parts.append(f"| {controller} | {outcome['algorithm']} | {outcome['step']:g}{mark} | "
                             f"{outcome['status']} | {_fmt(outcome.get('ITAE'))} | {_fmt(outcome.get('IAE'))} | "
                             f"{_fmt(outcome.get('Ec'))} | {text} | {_fmt(outcome.get('tv_u'))} |")
        parts.append("")
    return "\n".join(parts)


def merged_study(committed: dict, study: dict) -> dict:
    """The committed study with the scenarios of ``study`` put in (replaced or added) and every other
    scenario's entry kept: ``--apply`` of a study of one scenario (a new plant's) loses no other one.
    A merged study names the scenarios of its last run (``studied``); its wall time is that run's."""
    kept = [name for name in committed.get("scenarios", {}) if name not in study["scenarios"]]
    if not kept:
        return study
    merged = dict(study, scenarios={**{name: committed["scenarios"][name] for name in kept}, **study["scenarios"]},
                  studied=list(study["scenarios"]))
    if not study.get("reused_from") and committed.get("reused_from"):  # what the kept entries' reused runs cite
        merged["reused_from"] = committed["reused_from"]
    return merged


def apply_step(name: str, step: float):
    path = scenarios.SCENARIO_DIR / f"{name}.toml"
    text = path.read_text()
    text, count = re.subn(r"(?m)^step = [^#\n]*#[^\n]*",
                          f"step = {step:g}  # validated step (1 %) of `python -m harness convergence` "
                          "(docs/convergence.md)", text, count=1)
    if count != 1:
        raise RuntimeError(f"no 'step = ... # comment' line in {path}")
    atomic_files.write_text(path, text)


def convergence_command(args) -> int:
    cli_args.refuse_tracked([Path(args.out) / "convergence.json", Path(args.out) / "convergence.md"])
    names = args.scenarios or list(ALL_SCENARIOS)
    for name in names:
        scenarios.load(name)  # clear error for an unknown name
    jobs = args.jobs or default_jobs()
    stop = args.stop if args.stop is not None else (2.0 if args.quick else None)
    controllers = (variants.PROPOSED,) if args.quick else CONTROLLERS
    if args.from_json:  # rewrite the outputs (and --apply them) from a study already run
        convergence = json.loads(Path(args.from_json).read_text())
        stop = convergence.get("stop")
        controllers = tuple(next(iter(convergence["scenarios"].values()))["controllers"])
    else:
        reuse = json.loads(Path(args.reuse).read_text()) if args.reuse else None
        convergence = study(names, jobs, stop=stop, start_step=args.start_step, finest_factor=args.finest_factor,
                            limit=args.limit, controllers=controllers, reuse=reuse)
        if args.reuse:
            convergence["reused_from"] = args.reuse
    for name, entry in convergence["scenarios"].items():
        print(f"{name}: chosen step {entry['chosen_step']:g} s" + (f" ({entry['chosen_note']})"
                                                                    if entry["chosen_note"] else ""))
        for controller, result in entry["controllers"].items():
            steps = ", ".join(f"{a} {_fmt(s, 3)}" for a, s in result["validated_step"].items())
            print(f"  {controller}: validated step (1 %) {steps}  [{result['wall_s']:.0f} s]")
            for note in [result.get("fallback"), *result["search_note"].values()]:
                if note:
                    print(f"    note: {note}")
    print(f"study wall time {convergence['wall_s']:.1f} s on {jobs} processes")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_files.write_text(out / "convergence.json", json.dumps(convergence, indent=1))
    atomic_files.write_text(out / "convergence.md", convergence_markdown(convergence))
    written = [out / "convergence.json", out / "convergence.md"]
    if args.apply:
        if stop is not None or set(controllers) != set(CONTROLLERS):
            print("error: --apply needs the full study (no --stop, no --quick)", file=sys.stderr)
            return 2
        committed = merged_study(load_convergence(), convergence)
        atomic_files.write_text(CONVERGENCE_JSON, json.dumps(committed, indent=1))
        atomic_files.write_text(CONVERGENCE_MD, convergence_markdown(committed))
        written += [CONVERGENCE_JSON, CONVERGENCE_MD]
        for name, entry in convergence["scenarios"].items():
            changed = scenarios.load(name).step != entry["chosen_step"]
            apply_step(name, entry["chosen_step"])
            written.append(scenarios.SCENARIO_DIR / f"{name}.toml")
            if changed:
                print(f"{name}: step changed to {entry['chosen_step']:g} s: run `python -m harness regress "
                      "--update`, review and commit the references", file=sys.stderr)
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def register(commands):
    command = commands.add_parser("convergence", help="step study by accuracy: validated step (1 %%) per scenario x "
                                                      "controller x algorithm")
    command.add_argument("scenarios", nargs="*", type=cli_args.scenario, help=f"default: {', '.join(ALL_SCENARIOS)}")
    command.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    command.add_argument("--start-step", type=cli_args.positive_float,
                         help="first step of the ladder (default: the scenario's step)")
    command.add_argument("--finest-factor", type=cli_args.positive_float, default=16.0,
                         help="finest step tried = start step / this (default 16)")
    command.add_argument("--limit", type=cli_args.positive_float, default=0.05,
                         help="largest step tried (default 0.05 s)")
    command.add_argument("--stop", type=cli_args.positive_float,
                         help="shorter horizon (tests); default the scenarios' 20 s")
    command.add_argument("--quick", action="store_true", help="vud only, 2 s horizon (a smoke test of the study)")
    command.add_argument("--out", default=str(DEFAULT_OUT),
                         help=f"output folder (default {DEFAULT_OUT}/ under the working directory)")
    command.add_argument("--from-json", type=cli_args.existing_file,
                         help="do not run: rewrite the outputs from this study's convergence.json")
    command.add_argument("--reuse", type=cli_args.existing_file,
                         help="take the 20 s runs a previous study's convergence.json holds instead of running them "
                              "again (runs are deterministic; marked 'reused')")
    command.add_argument("--apply", action="store_true",
                         help="also write harness/scenarios/convergence.json, docs/convergence.md and the chosen "
                              "step into each scenario file (tracked files)")
    command.set_defaults(handler=convergence_command)


__all__ = ["study", "validated_step", "jacobi_safe_step", "step_warning", "search_validated"]
