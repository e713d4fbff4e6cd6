"""The figure of a Monte Carlo study: the empirical CDF of the objective per controller (left), and
the objective over the most influential parameter (right), one colour per controller; runs that
diverged are counted in the legend (they have no objective)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...units import score_units, variable_unit, with_unit
from .statistics import finite_scores


def plot_study(plan, rows: list, influence: dict, path) -> Path:
    import matplotlib  # here, not at module level: a heavy import, paid only when the figure is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objective = plan.objective
    label = with_unit(objective, score_units(plan.scenario)[objective])
    top = influence.get("ranking", [{}])[0].get("name") if influence else None
    top = top or (plan.names[0] if plan.names else None)
    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    positive = True
    for controller in plan.controllers:
        mine = [row for row in rows if row["controller"] == controller]
        values = np.sort(finite_scores(mine, objective))
        diverged = sum(row["status"] == "diverged" for row in mine)
        if len(values):
            positive &= bool(values[0] > 0)
            share = np.arange(1, len(values) + 1) / max(len(mine), 1)  # diverged runs keep the curve below 1
            left.step(values, share, where="post", label=f"{controller} ({len(values)} ok, {diverged} diverged)")
        if top is not None:
            column = plan.names.index(top)
            points = [(row["values"][column], row["scores"][objective]) for row in mine if row["status"] == "ok"
                      and math.isfinite(row["scores"].get(objective, math.nan))]
            if points:
                x, y = np.array(points).T
                right.scatter(x, y, s=6, alpha=0.5, label=controller)
    left.set_xlabel(label)
    left.set_ylabel("share of the samples (ECDF)")
    left.set_ylim(0, 1.02)
    left.legend(fontsize=8, loc="lower right")
    if positive:
        left.set_xscale("log")
        right.set_yscale("log")
    if top is not None:
        right.set_xlabel(with_unit(top, variable_unit(plan.scenario, top)))
        right.set_ylabel(label)
        right.legend(fontsize=8, markerscale=2)
        s1 = next((e["S1"] for e in influence.get("ranking", []) if e["name"] == top), None) if influence else None
        right.set_title(f"{objective} over {top}" + (f" (most influential, S1 = {s1:.2f})" if s1 is not None else ""),
                        fontsize=10)
    figure.suptitle(f"{plan.scenario.name}: {len({row['sample'] for row in rows})} samples, "
                    f"{plan.sampler} design, seed {plan.seed}", fontsize=10)
    path = Path(path)
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


__all__ = ["plot_study"]
