"""Heat maps of a sweep: one metric over the first two grid axes, one panel per controller."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ...units import score_units, variable_unit, with_unit
from .grid import SCENARIO_SETTINGS, SweepPlan, value_key


def heatmap_arrays(plan: SweepPlan, rows: list, controller: str):
    """(metric, status) arrays over the first two grid axes (axis 0 along x); worst over the other axes.

    status: 0 missing, 1 ok, 2 diverged, 3 failed.  A cell is diverged or
    failed (and its metric NaN) if any point folded into it is; otherwise
    its metric is the largest (all the scores are "lower is better").
    """
    grids = plan.grids
    nx = len(grids[0])
    ny = len(grids[1]) if len(grids) > 1 else 1
    metric = np.full((ny, nx), np.nan)
    status = np.zeros((ny, nx), dtype=int)
    index_x = {value_key(v): i for i, v in enumerate(grids[0].values)}
    index_y = {value_key(v): i for i, v in enumerate(grids[1].values)} if len(grids) > 1 else None
    code = {"ok": 1, "diverged": 2, "failed": 3}
    for row in rows:
        if row["controller"] != controller:
            continue
        i = index_x[value_key(row["values"][0])]
        j = index_y[value_key(row["values"][1])] if index_y else 0
        status[j, i] = max(status[j, i], code[row["status"]])
        value = row["scores"].get(plan.metric, math.nan)
        if row["status"] == "ok" and math.isfinite(value):
            metric[j, i] = value if math.isnan(metric[j, i]) else max(metric[j, i], value)
    metric[status > 1] = np.nan
    return metric, status


def plot_heatmap(plan: SweepPlan, rows: list, path) -> Path:
    import matplotlib  # here, not at module level: a heavy import, paid only when a heat map is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm, Normalize

    def axis_label(name: str) -> str:  # step and stop in s, a parameter in its FMU's unit
        return with_unit(name, "s" if name in SCENARIO_SETTINGS else variable_unit(plan.scenario, name))

    panels = [(c, *heatmap_arrays(plan, rows, c)) for c in plan.controllers]
    finite = np.concatenate([m[np.isfinite(m)] for _, m, _ in panels])
    positive = finite[finite > 0]
    if positive.size and positive.max() / positive.min() > 20:
        norm, scale = LogNorm(positive.min(), positive.max()), "log"
    elif finite.size:
        low, high = float(finite.min()), float(finite.max())
        norm, scale = Normalize(low, high if high > low else low + 1), "linear"
    else:
        norm, scale = Normalize(0, 1), "linear"
    gx = plan.grids[0]
    gy = plan.grids[1] if len(plan.grids) > 1 else None
    ny, nx = panels[0][1].shape
    cell = max(0.3, min(0.6, 4.0 / max(nx, ny)))  # inches per cell
    width = max(len(panels) * (nx * cell + 0.7) + 1.6, 6.0)  # room for the title over one small panel
    height = ny * cell + 1.7
    figure, axes = plt.subplots(1, len(panels), figsize=(width, height), squeeze=False, constrained_layout=True)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="white")
    image = None
    annotate = nx * ny <= 100
    for axis, (controller, metric, status) in zip(axes[0], panels):
        shown = np.ma.masked_invalid(np.where(metric > 0, metric, np.nan) if scale == "log" else metric)
        image = axis.imshow(shown, origin="lower", cmap=cmap, norm=norm, aspect="auto")
        for j in range(ny):
            for i in range(nx):
                if status[j, i] in (2, 3):
                    axis.add_patch(plt.Rectangle((i - 0.5, j - 0.5), 1, 1, facecolor="#d9d9d9" if status[j, i] == 2
                                                 else "#f4a6a6", edgecolor="white", hatch="xx", linewidth=0.5))
                    axis.text(i, j, "div" if status[j, i] == 2 else "fail", ha="center", va="center",
                              fontsize=7, color="black")
                elif status[j, i] == 0:
                    axis.text(i, j, "-", ha="center", va="center", fontsize=7, color="grey")
                elif annotate and np.isfinite(metric[j, i]):
                    rgba = cmap(norm(metric[j, i])) if metric[j, i] > 0 or scale == "linear" else (1, 1, 1, 1)
                    light = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] > 0.5
                    axis.text(i, j, f"{metric[j, i]:.3g}", ha="center", va="center", fontsize=6.5,
                              color="black" if light else "white")
        ok = int(np.sum(status == 1))
        axis.set_title(f"{controller}: {ok}/{nx * ny} ok", fontsize=10)
        axis.set_xticks(range(nx), [f"{v:.3g}" for v in gx.values], fontsize=7,
                        rotation=45 if nx > 8 else 0)
        axis.set_xlabel(axis_label(gx.name))
        if gy is not None:
            axis.set_yticks(range(ny), [f"{v:.3g}" for v in gy.values], fontsize=7)
            if axis is axes[0][0]:
                axis.set_ylabel(axis_label(gy.name))
        else:
            axis.set_yticks([])
    rest = [g.name for g in plan.grids[2:]]
    horizon = ", ".join(f"{name} {getattr(plan.scenario, name):g} s" for name in SCENARIO_SETTINGS
                        if name not in plan.names)
    title = f"{plan.scenario.name}: {plan.metric} ({scale} colour scale)" + (f", {horizon}" if horizon else "")
    if rest:
        title += f"\nworst case over {', '.join(rest)}"
    figure.suptitle(title, fontsize=10)
    if image is not None:
        figure.colorbar(image, ax=axes[0].tolist(), shrink=0.9,
                        label=with_unit(plan.metric, score_units(plan.scenario)[plan.metric]))
    path = Path(path)
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path
