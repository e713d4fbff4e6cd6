"""The points of a sweep: grid axes (``--grid NAME=START:STOP:N``), their keys, the validated plan.

Grid values must be bit-identical wherever a point runs: the parent computes them,
hands them over as Python floats and the CSV writes them with ``repr``; on resume
a point matches when its values agree to KEY_DIGITS significant digits.
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ... import scenario as scenarios
from ...master import ALGORITHMS, Master
from ...scenario import Scenario, ScenarioError
from ...scenario_checks import resolve_fmu
from ...scores import SCORE_KEYS
from ...variants import CONTROLLER_VARIANTS

SCENARIO_SETTINGS = ("step", "stop")  # sweepable scenario settings besides instance parameters
KEY_DIGITS = 12  # grid values match on resume when equal to 12 significant digits


# ------------------------------------------------------------------ grids
@dataclass(frozen=True)
class Grid:
    name: str  # "instance.parameter", "step" or "stop"
    values: tuple

    def __len__(self):
        return len(self.values)


def parse_grid(text: str) -> Grid:
    """``NAME=START:STOP:N`` (linspace), ``NAME=START:STOP:N:log`` (geomspace) or ``NAME=V1,V2,...``."""
    name, equals, spec = text.partition("=")
    name, spec = name.strip(), spec.strip()
    usage = (f"--grid {text!r}: write NAME=START:STOP:N (N evenly spaced values), NAME=START:STOP:N:log "
             "(geometric) or NAME=V1,V2,... with NAME instance.parameter, step or stop")
    if not equals or not name or not spec:
        raise ScenarioError(usage)
    try:
        if ":" in spec:
            fields = spec.split(":")
            if len(fields) not in (3, 4) or (len(fields) == 4 and fields[3] != "log"):
                raise ValueError
            start, stop, count = float(fields[0]), float(fields[1]), int(fields[2])
            if count < 1:
                raise ValueError
            if len(fields) == 4:
                if start <= 0 or stop <= 0:
                    raise ScenarioError(f"--grid {text!r}: a log grid needs START > 0 and STOP > 0")
                values = np.geomspace(start, stop, count)
            else:
                values = np.linspace(start, stop, count)
        else:
            values = [float(v) for v in spec.split(",") if v.strip()]
    except ValueError:
        raise ScenarioError(usage) from None
    values = tuple(dict.fromkeys(float(v) for v in values))  # unique, in order
    if not values or not all(math.isfinite(v) for v in values):
        raise ScenarioError(f"--grid {text!r}: need at least one finite value")
    return Grid(name, values)


def value_key(value: float) -> float:
    """Grid values compare equal on resume when they agree to KEY_DIGITS significant digits."""
    return float(f"{float(value):.{KEY_DIGITS}g}")


def point_key(controller: str, values) -> tuple:
    return (controller, *(value_key(v) for v in values))


# ---------------------------------------------------------------- settings
@dataclass
class SweepPlan:
    scenario: Scenario  # with --stop/--step applied, before the grid values
    controllers: tuple
    grids: tuple
    metric: str
    algorithm: str = "feedthrough"
    fmu_files: dict = field(default_factory=dict)  # instance -> absolute Path of its FMU

    @property
    def names(self) -> list:
        return [g.name for g in self.grids]

    def points(self) -> list:
        """(controller, values) for every point: grid-major, controllers innermost."""
        return [(controller, values) for values in itertools.product(*(g.values for g in self.grids))
                for controller in self.controllers]

    def settings(self) -> dict:
        scenario = self.scenario
        parameters = {name: {k: v for k, v in spec.parameters.items()
                             if not (name == scenario.controller_instance and k == "variant")}
                      for name, spec in scenario.components.items()}
        settings = {"scenario": scenario.name, "start": scenario.start, "stop": scenario.stop, "step": scenario.step,
                    "algorithm": self.algorithm, "grid": self.names, "parameters": parameters}
        for name in SCENARIO_SETTINGS:
            if name in self.names:  # a grid axis: the scenario's own value plays no part
                del settings[name]
        return settings


def _scenario_point(scenario: Scenario, controller: str, names, values) -> Scenario:
    point = scenario.with_controller(controller)
    for name, value in zip(names, values):
        point = point.with_parameter(name, value)
    return point


def plan_sweep(scenario_name, controllers, grids, metric="ITAE", stop=None, step=None,
               algorithm="feedthrough", fmu_paths=None) -> SweepPlan:
    """Validate everything against the scenario and the FMUs before any point runs."""
    scenario = scenarios.configure(scenario_name, step=step, stop=stop)
    controllers = tuple(dict.fromkeys(controllers))
    for controller in controllers:
        if controller not in CONTROLLER_VARIANTS:
            raise ScenarioError(f"unknown controller {controller!r}; valid: {', '.join(CONTROLLER_VARIANTS)}, all")
    if metric not in SCORE_KEYS:
        raise ScenarioError(f"unknown metric {metric!r}; valid: {', '.join(SCORE_KEYS)}")
    if algorithm not in ALGORITHMS:
        raise ScenarioError(f"unknown algorithm {algorithm!r}; valid: {', '.join(ALGORITHMS)}")
    if not grids:
        raise ScenarioError("give at least one --grid NAME=START:STOP:N")
    names = [g.name for g in grids]
    if len(set(names)) != len(names):
        raise ScenarioError(f"a parameter appears in two --grid options: {', '.join(names)}")
    overridden = {"stop": stop, "step": step}
    for grid in grids:
        if grid.name in overridden and overridden[grid.name] is not None:
            raise ScenarioError(f"--grid {grid.name} and --{grid.name} both set the {grid.name}: drop one")
        if grid.name == f"{scenario.controller_instance}.variant":
            raise ScenarioError(f"{grid.name} is chosen with --controller (vud, fixed, fae, all), not --grid")
        if "." not in grid.name and grid.name not in SCENARIO_SETTINGS:
            raise ScenarioError(f"unknown grid name {grid.name!r}: write instance.parameter with instance one of "
                                f"{', '.join(scenario.components)}, or one of {', '.join(SCENARIO_SETTINGS)}")
        if grid.name in SCENARIO_SETTINGS and min(grid.values) <= 0:
            raise ScenarioError(f"--grid {grid.name}: values must be > 0")
    # the master validates every name against the model descriptions on construction
    first = _scenario_point(scenario, controllers[0], names, [g.values[0] for g in grids])
    try:
        master = Master(first, algorithm, fmu_paths)
    except ScenarioError as error:
        raise ScenarioError(f"--grid {', '.join(names)}: {error}") from None
    for grid in grids:
        instance, _, parameter = grid.name.partition(".")
        if not parameter:  # step or stop: at least one step, and a given stop a whole number of steps
            for value in grid.values:
                point = _scenario_point(scenario, controllers[0], [grid.name], [value])
                try:
                    scenarios.whole_steps(point, stop_given=grid.name == "stop" or stop is not None)
                except ScenarioError as error:
                    raise ScenarioError(f"--grid {grid.name}={value:g}: {error}") from None
            continue
        kind = master.infos[instance].variables[parameter].type
        if kind in ("Integer", "Boolean", "Enumeration") and any(v != int(v) for v in grid.values):
            raise ScenarioError(f"--grid {grid.name}: {instance}.{parameter} is an {kind}; "
                                f"give whole numbers (got {', '.join(map(repr, grid.values))})")
    fmu_files = {name: resolve_fmu(spec.fmu, scenario, fmu_paths).resolve()
                 for name, spec in scenario.components.items()}
    return SweepPlan(scenario, controllers, tuple(grids), metric, algorithm, fmu_files)
