"""The figure of a failing signal: reference, tube and new result, a zoom, the excursion outside the tube.

One PNG per failing signal that has a reference, beside the reports (report.md and report.html link
them by the name :func:`plot_name` gives); matplotlib is imported only when one is drawn.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ... import atomic_files
from ... import scenario as scenarios
from ...units import variable_unit, with_unit


def slug(text: str) -> str:
    """A file and anchor name from a case label and a signal (letters, digits, '.', '_', '-')."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_")


def plot_name(comparison, signal) -> str:
    return f"{slug(comparison.case.label)}_{slug(signal.signal)}.png"


def plot_signal(path: Path, case, comparison, reference, run):
    """Reference, tube and new result over the whole horizon, a zoom around the worst point, and the
    excursion outside the tube; the largest excursion is marked on all three."""
    import matplotlib  # here, not at module level: a heavy import, paid only when a failing signal is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    name = comparison.signal
    unit = variable_unit(scenarios.load(case.scenario), name)
    funnel = comparison.funnel or {}
    figure, (whole, zoom, excursion) = plt.subplots(3, 1, figsize=(9, 8), gridspec_kw={"height_ratios": [3, 3, 1.3]})
    worst = comparison.t_max_error
    for axis in (whole, zoom):
        if "lowerBound" in funnel:
            lower, upper = funnel["lowerBound"], funnel["upperBound"]
            grid = np.union1d(lower[:, 0], upper[:, 0])
            axis.fill_between(grid, np.interp(grid, lower[:, 0], lower[:, 1]), np.interp(grid, upper[:, 0], upper[:, 1]),
                              color="tab:gray", alpha=0.35, lw=0, label="tube")
        axis.plot(reference.time, reference.signals[name], color="k", lw=0.9, label="reference")
        axis.plot(run.time, run.signals[name], color="tab:red", lw=0.9, label="new result")
        if worst is not None and np.isfinite(worst):
            value = float(np.interp(worst, run.time, run.signals[name]))
            if np.isfinite(value):
                axis.plot([worst], [value], "o", ms=9, mfc="none", mec="tab:blue", mew=1.5,
                          label=f"largest excursion (t = {worst:.4g} s)")
        axis.set_ylabel(with_unit(name, unit))
    centre = worst if worst is not None else float(reference.time[-1]) / 2
    half = 0.02 * float(reference.time[-1] - reference.time[0]) + 1e-9
    inside = (reference.time >= centre - half) & (reference.time <= centre + half)
    if inside.any():
        values = np.concatenate([reference.signals[name][inside], run.signals[name][inside]])
        values = values[np.isfinite(values)]
        if values.size:
            margin = 0.2 * (values.max() - values.min()) + 1e-12
            zoom.set_ylim(values.min() - margin, values.max() + margin)
    zoom.set_xlim(centre - half, centre + half)
    zoom.set_title(f"zoom around t = {centre:.4g} s", fontsize=8)
    whole.set_title(f"{case.label}: {name} ({comparison.message or 'inside the tube'})", fontsize=9)
    whole.legend(fontsize=8, loc="best")
    if "errors" in funnel:
        excursion.plot(funnel["errors"][:, 0], funnel["errors"][:, 1], color="tab:red", lw=0.8)
        if worst is not None:
            excursion.axvline(worst, color="tab:blue", lw=0.8, ls="--")
    excursion.set_ylabel(with_unit("outside tube", unit))
    excursion.set_xlabel("time (s)")
    figure.tight_layout()
    atomic_files.save_figure(figure, path, dpi=110)
    plt.close(figure)


def draw_failing_signals(comparisons, runs, references, directory: Path):
    """A PNG for every failing signal that has a reference, each replacing its old one whole; sets
    ``signal.plot``.  The PNGs of an earlier report that this one has not drawn are removed afterwards."""
    drawn = set()
    for comparison, run, reference in zip(comparisons, runs, references):
        for signal in comparison.signals:
            if not signal.passed and reference is not None and signal.signal in reference.signals:
                path = directory / plot_name(comparison, signal)
                plot_signal(path, comparison.case, signal, reference, run)
                signal.plot = path
                drawn.add(path.name)
    for old in directory.glob("*.png"):
        if old.name not in drawn:
            old.unlink()
