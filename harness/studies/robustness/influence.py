"""Which uncertain parameter matters most: SALib's RBD-FAST first-order indices S1 of the objective
(``SALib.analyze.rbd_fast``), with their bootstrap confidence, per controller.

RBD-FAST (random balance designs, Fourier amplitude sensitivity test) estimates S1_i, the share of
the objective's variance explained by parameter i alone, from any sample of the parameters (it
reorders the given runs along each parameter; no design of its own such as Saltelli's), so it reads
the study's Sobol' or Latin hypercube draws as they are.  Only completed runs enter (a diverged run
has no objective), and the noise seed is not a parameter: what it explains stays in the residual.
"""
from __future__ import annotations

import math

import numpy as np

MIN_RUNS = 64  # fewer completed runs than this: no ranking (RBD-FAST's spectrum needs samples)
HARMONICS = 10  # M, the harmonics RBD-FAST sums (SALib's default)


def rank_parameters(rows: list, names, bounds, objective: str, seed: int) -> dict:
    """{"method", "runs", "ranking": [{"name", "S1", "S1_conf"}, ...] most influential first} or
    {"runs", "reason"} when it cannot be estimated."""
    used = [row for row in rows if row["status"] == "ok" and row["scores"].get(objective) is not None
            and math.isfinite(row["scores"][objective])]
    if len(used) < max(MIN_RUNS, 2 * HARMONICS + 1):
        return {"runs": len(used), "reason": f"{len(used)} completed runs: RBD-FAST needs at least {MIN_RUNS}"}
    if not names:
        return {"runs": len(used), "reason": "no uncertain parameter"}
    from SALib.analyze import rbd_fast  # the robustness extra

    x = np.array([row["values"][:len(names)] for row in used], dtype=float)
    y = np.array([row["scores"][objective] for row in used], dtype=float)
    if np.ptp(y) == 0:
        return {"runs": len(used), "reason": f"{objective} is the same in every completed run"}
    problem = {"num_vars": len(names), "names": list(names), "bounds": [list(b) for b in bounds]}
    result = rbd_fast.analyze(problem, x, y, M=HARMONICS, seed=seed)
    ranking = [{"name": name, "S1": float(s1), "S1_conf": float(conf)}
               for name, s1, conf in zip(names, result["S1"], result["S1_conf"])]
    ranking.sort(key=lambda entry: -entry["S1"] if math.isfinite(entry["S1"]) else math.inf)
    return {"method": "RBD-FAST first-order index S1 (SALib)", "runs": len(used), "ranking": ranking}


__all__ = ["rank_parameters", "MIN_RUNS"]
