"""The summary of one study, as plain data (written to ``<study>.json``): counts, the best and the
starting trials, the best-so-far curve, the points of the Pareto fronts, the parameter importances,
and the tuned controller against the starting one on held-out scenarios."""
from __future__ import annotations

import math

from ... import cli_args
from ... import scenario as scenarios
from ...cases import parallel_map
from .candidate import evaluate
from .config import Prepared, url_without_password
from .storage import best_trial, is_feasible, outcome_of


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
        "study": prepared.study_name, "storage": prepared.storage_shown,
        "dashboard": url_without_password(prepared.storage_url), "scenario": prepared.scenario.name,
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
