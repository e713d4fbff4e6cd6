"""One row of the host matrix: one scenario x controller x host x step, run in its host, scored, and
compared with our converged result over the same horizon (harness/studies/step_study.py); within
1 % of it in ITAE, IAE and Ec is the row's verdict **ok**."""
from __future__ import annotations

import math
import time as clock

from .. import scenario as scenarios
from ..cases import Case, run_case
from ..studies.step_study import richardson
from .host_registry import HOSTS_BY_KEY

METRICS = ("ITAE", "IAE", "Ec")
ACCURACY = 0.01


def host_row(task: tuple) -> dict:
    """One row of the matrix (in a worker process): run, score, compare with the converged values."""
    key, name, controller, step, stop, converged, fmu_paths, package, step_kind = task
    scenario = scenarios.configure(name, controller, step, stop)
    row = {"scenario": name, "controller": controller, "host": key, "step": step, "stop": scenario.stop,
           "step_kind": step_kind, "converged": converged}
    began = clock.perf_counter()
    try:
        trajectory, warnings, where = HOSTS_BY_KEY[key].run(scenario, fmu_paths, package)
        scores = trajectory.scores()
        finite = all(math.isfinite(v) for v in scores.values())
        row.update(status="ok" if finite else "diverged", **scores, warnings=warnings, warnings_from=where,
                   error={m: scores[m] / converged[m] - 1 for m in METRICS} if finite else None)
    except Exception as error:  # a host failing is a row with its reason
        first_line = str(error).splitlines()[0] if str(error) else ""
        row.update(status="failed", reason=f"{type(error).__name__}: {first_line}",
                   warnings=[], error=None)
    row["wall_s"] = clock.perf_counter() - began
    return row


def converged_values(name: str, controller: str, stop: float | None, fmu_paths, convergence: dict) -> dict:
    """Our converged ITAE, IAE, Ec: the study's for the full horizon, else Richardson over ``stop``."""
    scenario = scenarios.load(name)
    entry = convergence.get("scenarios", {}).get(name, {}).get("controllers", {}).get(controller, {})
    if (stop is None or stop >= scenario.stop) and entry.get("converged") and not convergence.get("stop"):
        return {m: entry["converged"][m] for m in METRICS}
    fine = entry.get("levels", [scenario.step])[-1] if entry else scenario.step / 4
    coarse, finer = (run_case(Case(name, controller, step=h, stop=stop), fmu_paths) for h in (fine, fine / 2))
    if coarse["status"] != "ok" or finer["status"] != "ok":
        raise RuntimeError(f"{name}/{controller}: our reference runs failed: {coarse['reason'] or finer['reason']}")
    return richardson(finer, coarse)


def within(row: dict) -> bool:
    return row.get("status") == "ok" and all(abs(row["error"][m]) <= ACCURACY for m in METRICS)
