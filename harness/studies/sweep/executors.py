"""One point of a sweep as a task of the executor layer (harness/executors/): what a worker needs
(:func:`point_task`) and what it does with it (:func:`run_point`), on a local pool or a Dask cluster.

Each point is one :class:`~harness.cases.Case` run by the shared runner
(:func:`~harness.cases.run_case`) and turned into a CSV row.  The FMUs are the executor's files: a
Dask worker receives their bytes once and caches them by content hash, so a point gives the same
scores on any host.
"""
from __future__ import annotations

import dataclasses

from ...cases import Case, run_case
from ...scores import SCORE_KEYS
from .grid import SweepPlan


def run_point(task: dict, files: dict) -> dict:
    """Run one point; never raises for a failing simulation (the row says why).

    ``task``: the point's case (grid values and controller set) and its grid values; ``files``:
    {instance: path of its FMU on this host}.
    """
    case = dataclasses.replace(task["case"], fmu_files=tuple((instance, str(path)) for instance, path in files.items()))
    outcome = run_case(case)
    scores = {key: outcome[key] for key in SCORE_KEYS} if outcome["status"] == "ok" else {}
    return {"controller": case.controller, "values": list(task["values"]), "scores": scores,
            "wall_s": outcome["wall_s"], "status": outcome["status"],
            "reason": outcome["reason"] or "; ".join(outcome["notes"])}  # e.g. a stop moved to whole steps


def point_task(plan: SweepPlan, controller: str, values) -> dict:
    """What a worker needs to run one point (the FMUs travel as the executor's files)."""
    case = Case(plan.scenario, controller, algorithm=plan.algorithm, overrides=tuple(zip(plan.names, values)))
    return {"case": case, "controller": controller, "values": tuple(values)}


def point_files(plan: SweepPlan) -> dict:
    """{instance: path of its FMU}: the files every point reads."""
    return {instance: str(path) for instance, path in plan.fmu_files.items()}
