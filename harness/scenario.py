"""Scenario files: one TOML file per closed loop, in harness/scenarios/.

A scenario names its FMU instances, their parameters, the connections
(``instance.variable`` to ``instance.variable``), the experiment (start,
stop, communication step) and the signals to record.  See
``scenarios/pendulum_case1.toml`` for the format.  The controller variant
(``vud``, ``fixed``, ``fae``) is chosen at run time and set on the
instance named by ``controller_instance``.

Every table and key a file may hold is declared once, in :data:`SCHEMA`: :func:`parse` checks a
file against it (an unknown table or key with its close match, a missing key, a value of the wrong
type or out of range: one line naming the file, the table and the key), and the table of scenario
keys in docs/master.md is generated from it (:func:`keys_markdown`, ``python build_fmu.py --docs``).
Names that only the FMUs know (parameters, variables) are checked against their model
descriptions by harness/master.py.  harness/scenario_toml.py writes a scenario back as such a file.

A ``[hardware]`` table (or ``--hardware FILE`` of ``python -m harness run``) inserts a sensor
between the plant and the rest of the loop and an actuator between the controller and the plant,
and rewires the connections (:func:`with_hardware`; docs/master.md, "Hardware in the loop").
"""
from __future__ import annotations

import copy
import difflib
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from .variants import CONTROLLER_VARIANTS

SCENARIO_DIR = Path(__file__).resolve().parent / "scenarios"


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
    hardware: dict = field(default_factory=dict)  # the [hardware] table inserted (with_hardware), as given

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
        check_record_memory(count, len(self.record), self.start, self.step)
        return count


RECORD_MEMORY_SHARE = 0.5  # a run's record may take at most this share of the machine's memory


def physical_memory() -> int | None:
    """Bytes of physical memory (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def _bytes_text(count: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if count < 1024 or unit == "PiB":
            return f"{count:.3g} {unit}"
        count /= 1024
    return f"{count:.3g} PiB"


def check_record_memory(steps: int, recorded: int, start: float, step: float, memory: int | None = None):
    """The master keeps every communication step of every recorded signal (and the time) in memory,
    8 bytes each: refuse a run whose record needs more than RECORD_MEMORY_SHARE of the machine's
    memory, naming the limit in steps and in stop time."""
    memory = physical_memory() if memory is None else memory
    if not memory:
        return
    per_row = 8 * (recorded + 1)
    limit = int(RECORD_MEMORY_SHARE * memory // per_row) - 1
    if steps <= limit:
        return
    raise ScenarioError(f"stop = {start + steps * step:g} s at step {step:g} s is {steps:.3g} steps: the master "
                        f"keeps every step of the {recorded} recorded signals and the time in memory "
                        f"({_bytes_text(float(steps + 1) * per_row)}), more than {RECORD_MEMORY_SHARE:.0%} of "
                        f"this machine's {_bytes_text(memory)}; give a stop of at most "
                        f"{start + limit * step:.4g} s at this step (a longer step or fewer [record] variables "
                        "allow a longer run)")


def configure(name_or_path, controller: str | None = None, step: float | None = None,
              stop: float | None = None, overrides=(), fit_stop: str = "error", hardware=None) -> Scenario:
    """A scenario with the controller variant, step, stop and ``instance.parameter`` values set.

    ``hardware``: a hardware file (:func:`load_hardware`) whose sensor and actuator are inserted first.

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
    if hardware is not None:
        scenario = with_hardware(scenario, load_hardware(hardware), str(hardware))
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
        except UnicodeDecodeError as error:  # TOML is UTF-8 text: a binary file or another encoding
            raise ScenarioError(f"{path} is not a TOML file: byte {error.start} is not UTF-8 text "
                                f"({error.reason})") from None
    return parse(data, path)


# ----------------------------------------------------------------- the schema
# One declaration table of every table and key a scenario file may hold: parse() validates a file
# against it and docs/master.md's table of scenario keys is generated from it (keys_markdown()).

ANY_INSTANCE, ANY_PARAMETER, ANY_SIGNAL = "INSTANCE", "PARAMETER", "INSTANCE.VARIABLE"  # names the user chooses
CHOSEN_NAMES = (ANY_INSTANCE, ANY_PARAMETER, ANY_SIGNAL)
#: an instance name: it becomes part of file and folder names, of the FMU's resource URI and of SSP names, so
#: ASCII letters, digits and '_' only, not starting with a digit (as an identifier of C, Modelica or SSP)
INSTANCE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
INSTANCE_NAME_RULE = "ASCII letters, digits and '_', not starting with a digit"


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_dotted(value) -> bool:
    return isinstance(value, str) and re.fullmatch(r"[^.\s]+\.[^\s]+", value) is not None


@dataclass(frozen=True)
class Kind:
    """What a value must be: ``text`` names it in messages and in the docs' table."""

    text: str
    accepts: object  # value -> bool (for an array: the array itself; its elements: ``element``)
    table: bool = False  # a table whose keys the schema declares in turn
    element: "Kind | None" = None  # an array of values of this kind


TEXT = Kind("a string", lambda v: isinstance(v, str))
NUMBER = Kind("a finite number", lambda v: _is_number(v) and math.isfinite(v))
POSITIVE = Kind("a finite number > 0", lambda v: _is_number(v) and math.isfinite(v) and v > 0)
DOTTED = Kind('a string "INSTANCE.VARIABLE"', _is_dotted)
DOTTED_LIST = Kind('an array of strings "INSTANCE.VARIABLE"', lambda v: isinstance(v, list), element=DOTTED)
PARAMETER_VALUE = Kind("a finite number (true or false for a Boolean parameter)",
                       lambda v: isinstance(v, bool) or (_is_number(v) and math.isfinite(v)))
TABLE = Kind("a table", lambda v: isinstance(v, dict), table=True)
NON_NEGATIVE = Kind("a finite number >= 0", lambda v: _is_number(v) and math.isfinite(v) and v >= 0)
LIMIT = Kind("a number >= 0 (0 or inf: no limit)", lambda v: _is_number(v) and not math.isnan(v) and v >= 0)
SEED = Kind("an integer in 0 .. 2147483647", lambda v: _is_integer(v) and 0 <= v <= 2147483647)
DELAY = Kind("an integer in 0 .. 16", lambda v: _is_integer(v) and 0 <= v <= 16)
TABLES = Kind("an array of tables", lambda v: isinstance(v, list), element=TABLE)

REQUIRED = object()  # the default of a key that must be given


@dataclass(frozen=True)
class Described:
    """A default the docs describe in words (not a value of the file)."""

    text: str


@dataclass(frozen=True)
class Key:
    table: str  # "" (top level), "experiment", "components.INSTANCE", ...
    name: str  # the key, or ANY_* for a name the user chooses
    kind: Kind
    default: object  # REQUIRED, or the value a missing key takes
    meaning: str

    @property
    def path(self) -> str:
        return f"{self.table}.{self.name}" if self.table else self.name


#: every table and key of a scenario file (docs/master.md shows this table, generated by keys_markdown())
SCHEMA = (
    Key("", "name", TEXT, Described("the file's name"), "the scenario's name in reports and file names"),
    Key("", "description", TEXT, "", "one line: what the scenario is"),
    Key("", "controller_instance", TEXT, "controller",
        "the component whose `variant` parameter `--controller` sets; one of [components]"),
    Key("", "experiment", TABLE, REQUIRED, "the time grid of the run"),
    Key("experiment", "start", NUMBER, 0.0, "start time (s)"),
    Key("experiment", "stop", NUMBER, REQUIRED, "stop time (s), > start, a whole number of steps from it"),
    Key("experiment", "step", POSITIVE, REQUIRED, "communication step (s)"),
    Key("experiment", "divergence_bound", POSITIVE, 1e8,
        "a run stops as diverged when a connected or recorded signal without its own [bounds] entry "
        "reaches this magnitude or is not finite"),
    Key("", "components", TABLE, REQUIRED, "the FMU instances, one table each"),
    Key("components", ANY_INSTANCE, TABLE, Described("one or more"),
        f"one FMU instance; its name: {INSTANCE_NAME_RULE}"),
    Key("components.INSTANCE", "fmu", TEXT, REQUIRED,
        "a model identifier built by build_fmu.py (AdaptiveFuzzyController, InvertedPendulum, Manipulator, "
        "DcMotorArm, TrackingReference) or the path of an .fmu file, relative to the scenario file"),
    Key("components.INSTANCE", "parameters", TABLE, {}, "parameter values by name"),
    Key("components.INSTANCE.parameters", ANY_PARAMETER, PARAMETER_VALUE, Described("any number"),
        "a parameter of the FMU (name, Integer and Boolean checked against its model description, the "
        "range by the FMU when initialisation ends)"),
    Key("", "connections", TABLES, [], "one [[connections]] table per connection"),
    Key("connections", "from", DOTTED, REQUIRED, "an output"),
    Key("connections", "to", DOTTED, REQUIRED, "an input (each input connected once)"),
    Key("", "bounds", TABLE, {}, "divergence bounds of single signals"),
    Key("bounds", ANY_SIGNAL, POSITIVE, Described("any number"),
        "a connected or recorded output and its own divergence bound (instead of divergence_bound)"),
    Key("", "signals", TABLE, REQUIRED, "the recorded signals the scores read"),
    *(Key("signals", role, DOTTED, REQUIRED if role in ("e", "de", "ym", "dym", "u") else None, meaning)
      for role, meaning in (("e", "tracking error e = ym - y"), ("de", "its derivative"),
                            ("ym", "the reference"), ("dym", "its derivative"), ("u", "the control input"),
                            ("d2e", "second derivative of e (plants of order >= 3)"),
                            ("d3e", "third derivative of e (plants of order 4)"))),
    Key("", "record", TABLE, {}, "what is recorded at every communication step"),
    Key("record", "variables", DOTTED_LIST, [], "the outputs recorded (every signal of [signals] among them)"),
    Key("", "hardware", TABLE, {}, "a `Sensor` between the plant and the rest of the loop and an `Actuator` between "
        "the controller and the plant, the connections rewired (docs/master.md, Hardware in the loop); the "
        "scores then read the true error"),
    Key("hardware", "plant", TEXT, "plant", "the instance the sensor measures (its outputs y, dy, d2y, d3y that are "
        "connected) and the actuator drives (its connected input)"),
    Key("hardware", "sample_period", NON_NEGATIVE, 0.0,
        "the clock of the sensor and the actuator, Ts (s); 0: none, they follow every communication point"),
    Key("hardware", "seed", SEED, 0, "the noise's global seed (the sensor's local seed is 1)"),
    *(Key("hardware", f"noise_{channel}", NON_NEGATIVE, 0.0,
          f"standard deviation of the noise on {channel}, in its unit; needs sample_period > 0")
      for channel in ("y", "dy", "d2y", "d3y")),
    *(Key("hardware", f"quantum_{channel}", NON_NEGATIVE, 0.0, f"quantisation step of {channel}, in its unit; 0: none")
      for channel in ("y", "dy", "d2y", "d3y")),
    Key("hardware", "delay_samples", DELAY, 0, "the sensor's delay in samples; needs sample_period > 0"),
    Key("hardware", "filter_time_constant", NON_NEGATIVE, 0.0,
        "the sensor's first-order filter, time constant (s); 0: none; needs sample_period > 0"),
    Key("hardware", "u_max", LIMIT, 0.0, "the actuator's saturation, -u_max <= u <= u_max, in the unit of u"),
    Key("hardware", "rate_limit", LIMIT, 0.0, "the actuator's largest rate of u, in the unit of u per second"),
    Key("hardware", "rate_time_constant", POSITIVE, 1e-3, "the rate limiter's time constant Td (s)"),
    Key("hardware", "actuator_delay_samples", DELAY, 0, "the actuator's delay in samples; needs sample_period > 0"),
)
SIGNAL_ROLES = tuple(key.name for key in SCHEMA if key.table == "signals")


def did_you_mean(name: str, choices) -> str:
    """``" (did you mean 'stop'?)"``: the close match of a misspelt name among ``choices``, or ''."""
    close = difflib.get_close_matches(str(name), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_table(data: dict, table: str, dotted: str, shown: str, where: str):
    """Check one table of the file against SCHEMA (``table``: its schema name, e.g.
    ``components.INSTANCE``; ``dotted``: its name in the file; ``shown``: how messages name it)."""
    keys = [key for key in SCHEMA if key.table == table]
    named = {key.name: key for key in keys if key.name not in CHOSEN_NAMES}
    chosen = next((key for key in keys if key.name in CHOSEN_NAMES), None)
    prefix = f"{where}: {shown} " if shown else f"{where}: "
    for name, value in data.items():
        key = named.get(name, chosen)
        if key is None:
            place = "" if shown else " at the top level"
            raise ScenarioError(f"{prefix}unknown key {name!r}{place}{did_you_mean(name, named)}; "
                                f"valid: {', '.join(named)}")
        if key.name == ANY_INSTANCE and not INSTANCE_NAME.fullmatch(name):
            raise ScenarioError(f"{prefix}instance name {name!r} is not allowed: use {INSTANCE_NAME_RULE}")
        if key.name == ANY_SIGNAL and not _is_dotted(name):
            raise ScenarioError(f"{prefix}{name!r} is not a signal name; write \"INSTANCE.VARIABLE\" = bound")
        if not key.kind.accepts(value):
            raise ScenarioError(f"{prefix}{name} = {_shown(value)} is not {key.kind.text}")
        element = key.kind.element
        for index, item in enumerate(value if element is not None else ()):
            if not element.accepts(item):
                raise ScenarioError(f"{prefix}{name}: element {index + 1} = {_shown(item)} is not {element.text} "
                                    f"({name} is {key.kind.text})")
        child = f"{dotted}.{name}" if dotted else name
        if key.kind.table:
            _check_table(value, key.path, child, f"[{child}]", where)
        if element is not None and element.table:
            for index, item in enumerate(value):
                _check_table(item, key.path, child, f"[[{child}]] {index + 1}:", where)
    for name, key in named.items():
        if key.default is REQUIRED and name not in data:
            raise ScenarioError(f"{prefix}missing key {name!r} ({key.kind.text}: {key.meaning})")


def _value(data: dict, table: str, name: str):
    """The value of a key of the file, or its default."""
    key = next(k for k in SCHEMA if k.table == table and k.name == name)
    return data.get(name, copy.deepcopy(key.default))


def parse(data: dict, path: Path | None = None) -> Scenario:
    """A Scenario from the data of a scenario file, checked against SCHEMA: every mistake is one
    ScenarioError naming the file, the table and the key (and the close match of a misspelt name)."""
    where = str(path or "scenario")
    _check_table(data, "", "", "", where)
    experiment = data["experiment"]
    start, stop, step = (float(_value(experiment, "experiment", name)) for name in ("start", "stop", "step"))
    if not stop > start:
        raise ScenarioError(f"{where}: [experiment] stop = {_shown(experiment['stop'])} is not > start = {start:g}")
    components = {name: ComponentSpec(name, table["fmu"], dict(_value(table, "components.INSTANCE", "parameters")))
                  for name, table in data["components"].items()}
    if not components:
        raise ScenarioError(f"{where}: [components] has no instance; give one table [components.NAME] per FMU")
    controller_instance = _value(data, "", "controller_instance")
    if controller_instance not in components:
        raise ScenarioError(f"{where}: controller_instance = {controller_instance!r} is not a component"
                            f"{did_you_mean(controller_instance, components)}; valid: {', '.join(components)}")
    record = _value(data, "", "record")
    scenario = Scenario(
        name=data.get("name", path.stem if path else "scenario"),
        description=_value(data, "", "description"),
        start=start, stop=stop, step=step,
        components=components,
        connections=[Connection(table["from"], table["to"]) for table in _value(data, "", "connections")],
        record=list(_value(record, "record", "variables")),
        signals=dict(data["signals"]),
        controller_instance=controller_instance,
        divergence_bound=float(_value(experiment, "experiment", "divergence_bound")),
        bounds={name: float(value) for name, value in _value(data, "", "bounds").items()},
        path=path,
    )
    if "hardware" in data:
        scenario = with_hardware(scenario, data["hardware"], where)
    try:
        _ = scenario.steps  # at least one step, and a record that fits in memory
    except ScenarioError as error:
        raise ScenarioError(f"{where}: [experiment] {error}") from None
    return scenario


# ------------------------------------------------------------- hardware in the loop
#: what [hardware] inserts: the FMUs (plants/sensor/, plants/actuator/), their instances' names, and the
#: variables it connects (the sensor's channels: an input and its measured output each)
SENSOR_FMU, ACTUATOR_FMU = "Sensor", "Actuator"
SENSOR, ACTUATOR, TRUTH = "sensor", "actuator", "truth"
SENSOR_CHANNELS = ("y", "dy", "d2y", "d3y")
ACTUATOR_INPUT, ACTUATOR_OUTPUT = "u", "u_applied"
ERROR_ROLES = ("e", "de", "d2e", "d3e")  # the roles the scores read from the true error after insertion
SENSOR_LOCAL_SEED = 1


def _measured(channel: str) -> str:
    return f"{channel}_measured"


def _limit(value) -> float:
    """A limit of [hardware] as the FMU's parameter: inf (no limit) is the FMU's 0."""
    return 0.0 if math.isinf(value) else float(value)


def hardware_parameters(table: dict) -> tuple:
    """(sensor parameters, actuator parameters) of a checked [hardware] table (every key, defaults filled)."""
    value = {key.name: table.get(key.name, key.default) for key in SCHEMA if key.table == "hardware"}
    sensor = {"sample_period": float(value["sample_period"]), "delay_samples": value["delay_samples"],
              "filter_time_constant": float(value["filter_time_constant"]), "seed": value["seed"],
              "local_seed": SENSOR_LOCAL_SEED,
              **{f"{kind}_{c}": float(value[f"{kind}_{c}"]) for kind in ("noise", "quantum") for c in SENSOR_CHANNELS}}
    actuator = {"sample_period": float(value["sample_period"]), "delay_samples": value["actuator_delay_samples"],
                "u_max": _limit(value["u_max"]), "rate_limit": _limit(value["rate_limit"]),
                "rate_time_constant": float(value["rate_time_constant"])}
    return sensor, actuator


def with_hardware(scenario: Scenario, table: dict, where: str = "scenario") -> Scenario:
    """A copy of ``scenario`` with a sensor and an actuator inserted (the [hardware] table ``table``).

    * ``sensor`` (FMU Sensor): every connection that leaves the plant's y, dy, d2y or d3y leaves the
      sensor's measured channel instead, and the plant's channel feeds the sensor;
    * ``actuator`` (FMU Actuator): the connection into the plant's input comes from the actuator's
      ``u_applied``, and its source feeds the actuator's ``u``;
    * ``truth``: a copy of the instance the scores read the tracking error from (the reference), fed as
      it was before (the true plant outputs): the scores read the true error (signals e, de, ...), not
      the measured one; the record adds it and the new instances' outputs.

    Every mistake is one ScenarioError naming ``where`` and the table.
    """
    prefix = f"{where}: [hardware]"
    if scenario.hardware:
        raise ScenarioError(f"{prefix} the scenario {scenario.name!r} already has hardware inserted; give one "
                            "[hardware] table (the scenario's or --hardware's), not both")
    _check_table(table, "hardware", "hardware", "[hardware]", where)
    if not table.get("sample_period", 0.0):
        clocked = [name for name in (*(f"noise_{c}" for c in SENSOR_CHANNELS), "delay_samples", "filter_time_constant",
                                     "actuator_delay_samples") if table.get(name, 0)]
        if clocked:
            raise ScenarioError(f"{prefix} {clocked[0]} = {_shown(table[clocked[0]])} needs the clock of the sensor and "
                                "the actuator (noise is drawn, delays counted and the filter run once per sample); "
                                f"give sample_period > 0, or {clocked[0]} = 0")
    result = copy.deepcopy(scenario)
    plant = table.get("plant", "plant")
    if plant not in result.components:
        raise ScenarioError(f"{prefix} plant = {plant!r} is not a component{did_you_mean(plant, result.components)}; "
                            f"valid: {', '.join(result.components)}")
    taken = [name for name in (SENSOR, ACTUATOR, TRUTH) if name in result.components]
    if taken:
        raise ScenarioError(f"{prefix} inserts the instances {SENSOR}, {ACTUATOR} and {TRUTH}; the scenario already "
                            f"has {', '.join(repr(name) for name in taken)}: rename it")
    measured = [c for c in result.connections if c.source_instance == plant and c.source_variable in SENSOR_CHANNELS]
    driven = [c for c in result.connections if c.target_instance == plant]
    if not measured:
        raise ScenarioError(f"{prefix} no connection leaves {', '.join(f'{plant}.{c}' for c in SENSOR_CHANNELS)}: "
                            "the sensor would measure nothing")
    if len(driven) != 1:
        raise ScenarioError(f"{prefix} the actuator drives one input of {plant}; {len(driven)} connections go into "
                            f"it ({', '.join(c.target for c in driven) or 'none'})")
    roles = {role: result.signals[role] for role in ERROR_ROLES if result.signals.get(role)}
    observers = {dotted.split(".", 1)[0] for dotted in roles.values()}
    if len(observers) != 1 or next(iter(observers)) not in result.components:
        raise ScenarioError(f"{prefix} the signals {', '.join(roles)} must come from one component (the reference "
                            f"the true error is copied from); they come from {', '.join(sorted(observers))}")
    observer = next(iter(observers))
    sensor, actuator = hardware_parameters(table)
    result.components[SENSOR] = ComponentSpec(SENSOR, SENSOR_FMU, sensor)
    result.components[ACTUATOR] = ComponentSpec(ACTUATOR, ACTUATOR_FMU, actuator)
    result.components[TRUTH] = ComponentSpec(TRUTH, result.components[observer].fmu,
                                             dict(result.components[observer].parameters))
    truth = [Connection(c.source, f"{TRUTH}.{c.target_variable}") for c in result.connections
             if c.target_instance == observer]
    connections = []
    for connection in result.connections:
        if connection in measured:
            connection = Connection(f"{SENSOR}.{_measured(connection.source_variable)}", connection.target)
        elif connection in driven:
            connections.append(Connection(connection.source, f"{ACTUATOR}.{ACTUATOR_INPUT}"))
            connection = Connection(f"{ACTUATOR}.{ACTUATOR_OUTPUT}", connection.target)
        connections.append(connection)
    channels = list(dict.fromkeys(c.source_variable for c in measured))
    connections += [Connection(f"{plant}.{channel}", f"{SENSOR}.{channel}") for channel in channels] + truth
    result.connections = connections
    for role, dotted in roles.items():
        result.signals[role] = f"{TRUTH}.{dotted.split('.', 1)[1]}"
    added = ([f"{SENSOR}.{_measured(channel)}" for channel in channels] + [f"{ACTUATOR}.{ACTUATOR_OUTPUT}"]
             + list(dict.fromkeys(result.signals[role] for role in roles)))
    result.record = list(dict.fromkeys(result.record + added))
    result.hardware = dict(table)
    return result


def load_hardware(path) -> dict:
    """The [hardware] table of a hardware file (a TOML file holding that one table), checked against SCHEMA."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"no such file: {path}")
    with open(path, "rb") as stream:
        try:
            data = tomllib.load(stream)
        except tomllib.TOMLDecodeError as error:
            raise ScenarioError(f"{path} is not valid TOML: {error}") from None
    others = [name for name in data if name != "hardware"]
    if others or "hardware" not in data:
        raise ScenarioError(f"{path}: a hardware file holds one [hardware] table"
                            + (f"; unknown key {others[0]!r}{did_you_mean(others[0], ['hardware'])}" if others else ""))
    if not isinstance(data["hardware"], dict):
        raise ScenarioError(f"{path}: hardware = {_shown(data['hardware'])} is not a table")
    _check_table(data["hardware"], "hardware", "hardware", "[hardware]", str(path))
    return data["hardware"]


def _default_text(default) -> str:
    if default is REQUIRED:
        return "**required**"
    if default is None:
        return "optional"
    if default in ({}, []):
        return "empty"
    if isinstance(default, Described):
        return default.text
    if isinstance(default, float):
        return f"`{default:g}`"
    if _is_integer(default):
        return f"`{default}`"
    return f'`"{default}"`'


def keys_markdown() -> str:
    """The table of scenario keys of docs/master.md, from SCHEMA."""
    lines = ["| table | key | value | default | meaning |", "|---|---|---|---|---|"]
    for key in SCHEMA:
        table = "`[[connections]]`" if key.table == "connections" else f"`[{key.table}]`" if key.table else "(top)"
        value = key.kind.text.replace("|", "\\|")
        lines.append(f"| {table} | `{key.name}` | {value} | {_default_text(key.default)} | {key.meaning} |")
    return "\n".join(lines)
