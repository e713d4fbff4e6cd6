"""Scenario files: one TOML file per closed loop, in harness/scenarios/.

A scenario names its FMU instances, their parameters, the connections
(``instance.variable`` to ``instance.variable``), the experiment (start,
stop, communication step) and the signals to record.  See
``scenarios/pendulum_case1.toml`` for the format.  The controller variant
(``vud``, ``fixed``, ``fae``) is chosen at run time and set on the
instance named by ``controller_instance``.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .variants import CONTROLLER_VARIANTS

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"
SIGNAL_ROLES = ("e", "de", "ym", "dym", "u", "d2e", "d3e")  # d2e, d3e: plants of order 3, 4


class ScenarioError(ValueError):
    """A mistake in a scenario file; the message lists the valid names."""


@dataclass
class Connection:
    source: str  # "instance.variable"
    target: str

    @property
    def source_instance(self):
        return self.source.split(".", 1)[0]

    @property
    def source_variable(self):
        return self.source.split(".", 1)[1]

    @property
    def target_instance(self):
        return self.target.split(".", 1)[0]

    @property
    def target_variable(self):
        return self.target.split(".", 1)[1]


@dataclass
class ComponentSpec:
    name: str
    fmu: str  # a model identifier built by build_fmu.py, or a path to an .fmu file
    parameters: dict = field(default_factory=dict)


@dataclass
class Scenario:
    name: str
    description: str
    start: float
    stop: float
    step: float
    components: dict  # name -> ComponentSpec
    connections: list
    record: list
    signals: dict  # role -> "instance.variable"
    controller_instance: str = "controller"
    divergence_bound: float = 1e8
    bounds: dict = field(default_factory=dict)  # "instance.variable" -> its own divergence bound
    path: Path | None = None
    notes: list = field(default_factory=list)  # what configure() changed that the user did not ask for

    def bound(self, dotted: str) -> float:
        """The divergence bound of one signal: its own, else the scenario's."""
        return self.bounds.get(dotted, self.divergence_bound)

    def with_controller(self, controller: str) -> "Scenario":
        """A copy with the controller variant set (vud, fixed or fae)."""
        if controller not in CONTROLLER_VARIANTS:
            raise ScenarioError(f"unknown controller {controller!r}; valid: {', '.join(CONTROLLER_VARIANTS)}")
        if self.controller_instance not in self.components:
            raise ScenarioError(f"controller_instance {self.controller_instance!r} is not a component; "
                                f"valid: {', '.join(self.components)}")
        result = copy.deepcopy(self)
        result.components[self.controller_instance].parameters["variant"] = CONTROLLER_VARIANTS[controller]
        return result

    def with_parameter(self, dotted: str, value) -> "Scenario":
        """A copy with ``instance.parameter`` (or ``step``/``stop``) set."""
        result = copy.deepcopy(self)
        if dotted in ("step", "stop", "start"):
            setattr(result, dotted, float(value))
            return result
        instance, _, name = dotted.partition(".")
        if instance not in result.components or not name:
            raise ScenarioError(f"unknown parameter {dotted!r}; write instance.parameter with instance one of "
                                f"{', '.join(result.components)} (or step, stop)")
        result.components[instance].parameters[name] = value
        return result

    @property
    def steps(self) -> int:
        for name in ("start", "stop", "step"):
            if not math.isfinite(getattr(self, name)):
                raise ScenarioError(f"{name} = {getattr(self, name)} is not a finite number")
        if not self.step > 0:
            raise ScenarioError(f"step = {self.step} is invalid; the communication step must be > 0")
        count = round((self.stop - self.start) / self.step)
        if count < 1:
            raise ScenarioError(f"stop - start = {self.stop - self.start} is shorter than one step {self.step}")
        return count


def configure(name_or_path, controller: str | None = None, step: float | None = None,
              stop: float | None = None, overrides=(), fit_stop: str = "error") -> Scenario:
    """A scenario with the controller variant, step, stop and ``instance.parameter`` values set.

    The run covers a whole number of steps.  A stop that was given (``stop`` or an
    override) and is not a whole number of steps from the start is an error naming
    both and the nearest valid stop, unless ``fit_stop="move"`` (studies that try
    many steps on one horizon: the step study, sweeps over the step); the scenario's
    own stop, when only the step was changed, is moved.  A moved stop is said in
    ``notes`` (the run command prints it; a case's outcome carries it).
    """
    if fit_stop not in ("error", "move"):
        raise ValueError(f"fit_stop={fit_stop!r}; valid: error, move")
    scenario = load(name_or_path)
    if controller is not None:
        scenario = scenario.with_controller(controller)
    if step is not None:
        scenario = scenario.with_parameter("step", step)
    if stop is not None:
        scenario = scenario.with_parameter("stop", stop)
    for dotted, value in overrides:
        scenario = scenario.with_parameter(dotted, value)
    given = {name for name, value in (("step", step), ("stop", stop)) if value is not None}
    given |= {dotted for dotted, _ in overrides if dotted in ("step", "stop", "start")}
    if given:
        whole_steps(scenario, stop_given=fit_stop == "error" and bool(given & {"stop", "start"}))
    return scenario


def whole_steps(scenario: Scenario, stop_given: bool) -> Scenario:
    """Make sure the run covers a whole number of steps (see :func:`configure`); returns ``scenario``."""
    count = scenario.steps  # also: finite numbers, step > 0, at least one step
    nearest = scenario.start + count * scenario.step
    if abs(nearest - scenario.stop) <= 1e-9 * max(abs(scenario.stop), scenario.step):
        return scenario
    if stop_given:
        raise ScenarioError(f"stop = {scenario.stop:g} s is not a whole number of steps of {scenario.step:g} s "
                            f"from start = {scenario.start:g} s ({(scenario.stop - scenario.start) / scenario.step:.6g}"
                            f" steps); nearest valid stop: {nearest:.12g} s")
    scenario.notes.append(f"stop moved from {scenario.stop:g} s to {nearest:.12g} s, a whole number of steps "
                          f"({count}) of {scenario.step:g} s")
    scenario.stop = nearest
    return scenario


def scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def load(name_or_path) -> Scenario:
    """Load a scenario by name (harness/scenarios/NAME.toml) or by file path (a Scenario: a copy of it)."""
    if isinstance(name_or_path, Scenario):
        return copy.deepcopy(name_or_path)
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = SCENARIO_DIR / f"{name_or_path}.toml"
    if not path.exists():
        if Path(name_or_path).suffix == ".toml":
            raise ScenarioError(f"no such file: {name_or_path}")
        raise ScenarioError(f"unknown scenario {str(name_or_path)!r}; valid: {', '.join(scenario_names())} "
                            "or a .toml path")
    with open(path, "rb") as stream:
        try:
            data = tomllib.load(stream)
        except tomllib.TOMLDecodeError as error:
            raise ScenarioError(f"{path} is not valid TOML: {error}") from None
    return parse(data, path)


def _require(table: dict, key: str, where: str):
    if key not in table:
        raise ScenarioError(f"{where}: missing key {key!r}")
    return table[key]


def parse(data: dict, path: Path | None = None) -> Scenario:
    where = str(path or "scenario")
    experiment = _require(data, "experiment", where)
    components = {}
    for name, table in _require(data, "components", where).items():
        if "." in name:
            raise ScenarioError(f"{where}: instance name {name!r} must not contain '.'")
        components[name] = ComponentSpec(name, str(_require(table, "fmu", f"{where}: components.{name}")),
                                         dict(table.get("parameters", {})))
    connections = []
    for index, table in enumerate(data.get("connections", [])):
        connection = Connection(str(_require(table, "from", f"{where}: connection {index + 1}")),
                                str(_require(table, "to", f"{where}: connection {index + 1}")))
        connections.append(connection)
    record = list(data.get("record", {}).get("variables", []))
    signals = dict(data.get("signals", {}))
    scenario = Scenario(
        name=str(data.get("name", path.stem if path else "scenario")),
        description=str(data.get("description", "")),
        start=float(experiment.get("start", 0.0)),
        stop=float(_require(experiment, "stop", f"{where}: experiment")),
        step=float(_require(experiment, "step", f"{where}: experiment")),
        components=components, connections=connections, record=record, signals=signals,
        controller_instance=str(data.get("controller_instance", "controller")),
        divergence_bound=float(experiment.get("divergence_bound", 1e8)),
        bounds={str(name): float(value) for name, value in data.get("bounds", {}).items()},
        path=path,
    )
    for name, value in scenario.bounds.items():
        if not value > 0:
            raise ScenarioError(f"{where}: bounds.{name} = {value!r} must be > 0")
    for role in signals:
        if role not in SIGNAL_ROLES:
            raise ScenarioError(f"{where}: unknown signal role {role!r}; valid: {', '.join(SIGNAL_ROLES)}")
    if not scenario.step > 0 or not scenario.stop > scenario.start:
        raise ScenarioError(f"{where}: need step > 0 and stop > start (step = {scenario.step}, "
                            f"start = {scenario.start}, stop = {scenario.stop})")
    return scenario
