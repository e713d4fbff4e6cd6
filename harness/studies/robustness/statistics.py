"""The summary of a Monte Carlo study from its rows, every figure with its own uncertainty:

* per controller, the share of runs that diverged, that chattered (the controller's chatter monitor
  warned) and that met the user's ``--spec``, each with its 95 % Wilson score interval
  (``scipy.stats.binomtest(...).proportion_ci(method="wilson")``);
* per controller and score, the 5 %, 50 % and 95 % quantiles of the completed runs, each with a 95 %
  bootstrap percentile interval (``scipy.stats.bootstrap``, RESAMPLES resamples, seeded);
* per pair of controllers, the paired difference of the objective on the samples both completed
  (the same draws: common random numbers): its mean and median with bootstrap intervals, and the
  share of samples where the first is lower with its Wilson interval.  A difference whose median's
  interval holds 0, or of fewer than MIN_DECIDED paired samples, is "not decided".
"""
from __future__ import annotations

import itertools
import math

import numpy as np

CONFIDENCE = 0.95
RESAMPLES = 1000  # bootstrap resamples of each interval
BATCH = 100  # resamples computed at once (memory: BATCH x runs values)
QUANTILES = (0.05, 0.5, 0.95)
QUANTILE_NAMES = ("q05", "median", "q95")
MIN_DECIDED = 20  # fewer paired samples: "not decided" whatever the interval (a percentile bootstrap of a few is too narrow)


def wilson(count: int, total: int) -> dict | None:
    """{count, total, share, low, high}: ``count`` of ``total`` with its 95 % Wilson interval."""
    if total == 0:
        return None
    from scipy.stats import binomtest  # the robustness extra

    interval = binomtest(count, total).proportion_ci(confidence_level=CONFIDENCE, method="wilson")
    return {"count": count, "total": total, "share": count / total, "low": float(interval.low),
            "high": float(interval.high)}


def _quantiles(sample, axis=-1):
    return np.quantile(sample, QUANTILES, axis=axis)


def _mean_median(sample, axis=-1):
    return np.stack([np.mean(sample, axis=axis), np.median(sample, axis=axis)])


def bootstrap_intervals(values, statistic, seed: int):
    """(estimates, lows, highs) of a vector-valued ``statistic`` of ``values``; intervals None for
    fewer than 2 values."""
    values = np.asarray(values, dtype=float)
    estimate = statistic(values)
    if len(values) < 2:
        return estimate, None, None
    from scipy.stats import bootstrap  # the robustness extra

    result = bootstrap((values,), statistic, n_resamples=RESAMPLES, batch=BATCH, vectorized=True,
                       confidence_level=CONFIDENCE, method="percentile", rng=seed)
    return estimate, result.confidence_interval.low, result.confidence_interval.high


def _estimates(names, estimate, low, high) -> dict:
    return {name: {"value": float(estimate[k]), "low": None if low is None else float(low[k]),
                   "high": None if high is None else float(high[k])} for k, name in enumerate(names)}


def finite_scores(rows, score: str) -> np.ndarray:
    """The values of ``score`` over the completed rows where it is finite (None and NaN left out)."""
    return np.array([row["scores"][score] for row in rows if row["status"] == "ok"
                     and row["scores"].get(score) is not None and math.isfinite(row["scores"][score])])


def controller_summary(rows: list, scores, spec, seed: int) -> dict:
    """The summary of one controller's rows (see the module's doc)."""
    total = len(rows)
    summary = {"runs": total, "ok": sum(r["status"] == "ok" for r in rows),
               "failed": sum(r["status"] == "failed" for r in rows),
               "diverged": wilson(sum(r["status"] == "diverged" for r in rows), total),
               "chattered": wilson(sum(int(r["chatter"]) for r in rows), total),
               "spec": wilson(sum(spec.met(r) for r in rows), total) if spec is not None else None,
               "scores": {}}
    for score in scores:
        values = finite_scores(rows, score)
        if len(values) == 0:
            summary["scores"][score] = {"n": 0}
            continue
        summary["scores"][score] = {"n": int(len(values)),
                                    **_estimates(QUANTILE_NAMES, *bootstrap_intervals(values, _quantiles, seed))}
    return summary


def paired_differences(rows: list, controllers, objective: str, seed: int) -> list:
    """For each pair (a, b): objective(a) - objective(b) on the samples where both completed."""
    by_key = {(r["sample"], r["controller"]): r for r in rows}
    samples = sorted({r["sample"] for r in rows})
    pairs = []
    for a, b in itertools.combinations(controllers, 2):
        differences, alone = [], {a: 0, b: 0}
        for sample in samples:
            ra, rb = by_key.get((sample, a)), by_key.get((sample, b))
            if ra is None or rb is None:
                continue
            va, vb = ra["scores"].get(objective), rb["scores"].get(objective)
            good_a = ra["status"] == "ok" and va is not None and math.isfinite(va)
            good_b = rb["status"] == "ok" and vb is not None and math.isfinite(vb)
            if good_a and good_b:
                differences.append(va - vb)
            elif good_a or good_b:
                alone[a if good_a else b] += 1
        entry = {"a": a, "b": b, "objective": objective, "paired": len(differences),
                 "completed_alone": alone, "verdict": "not decided"}
        if differences:
            values = np.array(differences)
            entry.update(_estimates(("mean", "median"), *bootstrap_intervals(values, _mean_median, seed)))
            entry["a_lower"] = wilson(int(np.sum(values < 0)), len(values))
            low, high = entry["median"]["low"], entry["median"]["high"]
            if len(values) < MIN_DECIDED:
                entry["verdict"] = f"not decided ({len(values)} paired samples, fewer than {MIN_DECIDED})"
            elif low is not None and high < 0:
                entry["verdict"] = f"{a} lower"
            elif low is not None and low > 0:
                entry["verdict"] = f"{b} lower"
        pairs.append(entry)
    return pairs


__all__ = ["wilson", "bootstrap_intervals", "controller_summary", "paired_differences", "finite_scores",
           "CONFIDENCE", "RESAMPLES", "QUANTILES", "QUANTILE_NAMES"]
