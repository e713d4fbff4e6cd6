"""Every figure axis carries its unit, taken from the FMUs' declarations."""
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from harness import scenario as scenarios, units
from harness.studies import sweep, tables


@pytest.mark.parametrize("name,force", [("pendulum_case1", "N"), ("manipulator", "N.m")])
def test_signal_units_come_from_the_declarations_and_u_from_the_input_it_drives(fmu_paths, name, force):
    configured = scenarios.load(name)
    assert units.variable_unit(configured, "plant.y") == "rad"
    assert units.variable_unit(configured, "reference.de") == "rad/s"
    for dotted in ("controller.u", "controller.theta3", "controller.w_hat"):
        assert units.variable_unit(configured, dotted) == force  # u = theta^T xi + w_hat
    assert units.variable_unit(configured, "controller.gamma") == ""  # dimensionless
    scores = units.score_units(configured)
    assert scores["umax"] == force and scores["tv_u"] == f"{force}/s" and scores["ts"] == "s"
    assert scores["ITAE"] == "rad.s2" and scores["IAE"] == "rad.s"
    assert units.variable_unit(configured, "plant.mp" if name.startswith("pendulum") else "plant.mr0") == "kg"


@pytest.fixture
def drawn_axes(monkeypatch):
    """Title, x label and y label of every axis of every figure saved meanwhile."""
    axes = []

    def record(figure, *args, **kwargs):
        axes.extend((a.get_title(), a.get_xlabel(), a.get_ylabel()) for a in figure.axes)

    monkeypatch.setattr(Figure, "savefig", record)
    return axes


def _signals(time):
    wave = np.sin(time)
    return {"time": time, **{name: wave for name in ("plant.y", "plant.dy", "reference.e", "reference.de",
                                                     "reference.ym", "reference.dym", "controller.u")}}


def test_table_figures_label_every_panel_with_its_unit(fmu_paths, drawn_axes, tmp_path):
    rows = [{"scenario": name, "controller": controller, "signals": _signals(np.linspace(0, 1, 11))}
            for name in ("pendulum_case1", "manipulator") for controller in ("vud", "fixed", "fae")]
    tables.figures(rows, tmp_path)
    titles = [title for title, _, _ in drawn_axes]
    assert titles.count("u (N)") == 1 and titles.count("u (N.m)") == 1
    for title, xlabel, ylabel in drawn_axes:
        assert title.endswith(")") and ylabel, f"panel {title!r} without a unit"
    assert sum(xlabel == "t (s)" for _, xlabel, _ in drawn_axes) == 4  # the bottom row of two figures


def test_sweep_heat_map_axes_and_colour_bar_carry_units(fmu_paths, drawn_axes, tmp_path):
    grids = [sweep.parse_grid("step=2e-4,4e-4"), sweep.parse_grid("plant.mp=0.1,1")]
    plan = sweep.plan_sweep("pendulum_case2", ("vud",), grids, metric="ITAE", stop=0.1, fmu_paths=fmu_paths)
    rows = [{"controller": "vud", "values": [h, m], "scores": {"ITAE": h * m}, "status": "ok"}
            for h in (2e-4, 4e-4) for m in (0.1, 1.0)]
    sweep.plot_heatmap(plan, rows, Path(tmp_path) / "map.png")
    labels = [label for _, xlabel, ylabel in drawn_axes for label in (xlabel, ylabel) if label]
    assert "step (s)" in labels and "plant.mp (kg)" in labels and "ITAE (rad.s2)" in labels
