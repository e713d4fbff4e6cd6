"""The loop: ask a trial, run its candidate, tell its outcome, until the study holds its budget.

``--jobs 1``: ask, run, tell, one trial after the other in this process (sequential sampling).
``--jobs N``: N trials in flight on a local pool; ``--scheduler ADDRESS``: as many as the Dask
cluster has worker threads.  A finished trial is told and the next one asked while the others run;
only this process talks to the study's database, the workers run candidates (harness/executors/:
the FMUs travel once per worker).  The sampler is seeded per trial from ``--seed`` and the number of
trials already in the study.  A trial whose worker is lost is run again by the executor; one that
kills its worker again, alone, is told PRUNED with the reason.
"""
from __future__ import annotations

import math
import os
import socket
import time as clock

from ... import master_loop
from ...executors import WorkerLost, open_executor
from ...scenario_checks import resolve_fmu
from .candidate import evaluate_here
from .config import Prepared
from .space import paper_conditions, parameter_values, sample_of
from .storage import HEARTBEAT_S, Heartbeat, best_trial, recover_dead_trials


def sampler_for(kind: str, seed: int, count: int, x0: dict | None = None):
    """A sampler seeded for the trial asked when the study holds ``count`` trials (the package text,
    harness/studies/tune/__init__.py, says what that gives)."""
    import optuna

    trial_seed = (seed * 1_000_003 + count) % (2 ** 32)
    if kind == "cmaes":
        return optuna.samplers.CmaEsSampler(seed=trial_seed, x0=x0, warn_independent_sampling=False)
    return optuna.samplers.TPESampler(seed=trial_seed)


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
    # the heartbeat before the claim: a trial whose owner is written has a heartbeat, so one of a process
    # killed on another host goes stale (fail_stale_trials); Optuna never fails a trial without one
    heartbeat.add(trial._trial_id)
    try:
        trial.set_user_attr("owner", owner)  # claimed: recover_dead_trials knows whose it is
    except optuna.exceptions.UpdateFinishedTrialError:
        # another process found it unclaimed for ORPHAN_S (a machine under heavy load), counted it lost
        # and queued its parameters again: it is not ours to run
        pending.remove(trial)
        heartbeat.remove(trial._trial_id)
        return None
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


def candidate_files(prepared: Prepared) -> dict:
    """{instance: FMU file} of the tuned scenario: the files every candidate reads (a Dask worker
    receives them once)."""
    scenario = prepared.scenario
    return {instance: str(resolve_fmu(spec.fmu, scenario, prepared.fmu_paths))
            for instance, spec in scenario.components.items()}


def _lost_outcome(error: BaseException) -> dict:
    """The outcome of a candidate whose run never came back: its worker died again while running it
    alone (a crash in an FMU), or the candidate raised."""
    status = "failed"
    what = "its run killed the worker process" if isinstance(error, WorkerLost) else "its run raised"
    return {"status": status, "reason": f"{what}: {type(error).__name__}: {error}", "scores": None, "wall_s": 0.0}


def run_study(prepared: Prepared, study, log=None, executor=None) -> dict:
    """Run trials until the study holds ``trials`` finished ones; returns counts and timings of this call.

    ``--jobs 1``: ask, run, tell, one trial after the other (sequential sampling: with the same seed
    on an empty study, the same trials).  ``--jobs N`` or ``--scheduler``: as many trials in flight as
    the executor runs at once; a finished one is told and the next one asked while the others run
    (asynchronous: the trials depend on the order in which runs finish).  ``executor``: one opened by
    the caller (it is closed here), else the one of ``--jobs`` / ``--scheduler``.
    """
    import optuna
    from optuna.trial import TrialState

    config = prepared.config
    log = log or (lambda line: None)
    finished_states = (TrialState.COMPLETE, TrialState.PRUNED)
    master_loop.library()  # the compiled loop, once, before the workers start
    executor = executor or open_executor(config.jobs, config.scheduler, files=candidate_files(prepared),
                                         inline_single=True)
    where = executor.describe()
    heartbeat = Heartbeat(study._storage)
    recovered, _ = recover_dead_trials(study)
    if recovered:
        log(f"note: trials {', '.join(map(str, recovered))} of a killed run are run again (same parameters)")
    owner = {"host": socket.gethostname(), "pid": os.getpid()}
    x0 = sample_of(prepared.dimensions, prepared.fixed) if config.sampler == "cmaes" else None
    pending, in_flight = [], {}
    ran, began, simulated, stale_checked = 0, clock.perf_counter(), 0.0, -math.inf
    interrupted = False
    try:
        while True:
            while len(in_flight) < executor.slots:
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
                    elif waiting or running:
                        # a trial nobody has claimed yet (its process may have died right after asking), or
                        # one another process runs: wait until it finishes or its heartbeat goes silent
                        # (fail_stale_trials above, then it is queued again), so the study reaches its budget
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
                        "objective": config.objective, "verify_below": best[0] if best is not None else math.inf,
                        "tolerance": config.tolerance}
                executor.submit(evaluate_here, task, key=trial.number)
                in_flight[trial.number] = (trial, values)
            if not in_flight:
                break
            for done in sorted(executor.next_done(), key=lambda d: d.key):
                trial, values = in_flight.pop(done.key)
                outcome = done.value if done.ok else _lost_outcome(done.error)
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
        interrupted = True
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
        executor.close(cancel=interrupted)  # an interrupt or an error stops the workers where they are
    return {"ran": ran, "wall_s": clock.perf_counter() - began, "simulated_s": simulated, "executor": where}
