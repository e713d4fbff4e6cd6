"""A co-simulation master on fmpy's FMU2Slave, generic over FMI 2.0 co-simulation FMUs.

At every communication point the master propagates values along the
connections in dependency order before anyone steps: a component's outputs
are read after the inputs they depend on directly were set (dependencies
from each modelDescription's ModelStructure; no dependency list means
"depends on every input").  A pure chain plant -> reference -> controller
-> plant therefore has no artificial one-step delay.  A cycle through
direct feedthrough is an algebraic loop and a clear error.

``algorithm="jacobi"`` is the classic scheme of most co-simulation engines
(fmpy's SSP simulator among them): read every output, then set every
input, so every connection is delayed by one communication step.

The per-step path uses value-reference and value arrays prepared once, one
getReal and one setReal per FMU per step, and records into a preallocated
numpy array; nothing is looked up by name, allocated or logged per step.
"""
from __future__ import annotations

import math
import numbers
import time as clock
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import build_fmu

from . import master_loop
from .fmi import BoundArrayCall, Component, FmiError, FmuFileError, ModelInfo
from .scenario import Scenario, ScenarioError, did_you_mean

ALGORITHMS = ("feedthrough", "jacobi")
FMI_WARNING = 1
DIVERGENCE_CHECK_EVERY = 64  # rows; a non-finite value set on an FMU is caught at once


class Divergence(RuntimeError):
    """The closed loop left the bound or produced a non-finite value."""


class SimulationFailed(RuntimeError):
    """A run stopped early; ``result`` holds every row computed until then."""

    def __init__(self, message: str, result: "RunResult", cause: Exception):
        super().__init__(message)
        self.result = result
        self.cause = cause


@dataclass
class RunResult:
    scenario: Scenario
    algorithm: str
    time: np.ndarray
    columns: list  # "instance.variable", in the scenario's record order
    values: np.ndarray  # rows x columns
    wall_s: float
    complete: bool
    loop_s: float = float("nan")  # the fixed-step loop alone (no instantiation, initialisation, clean-up)
    solver: dict | None = None  # --algorithm me: the integrator's statistics (harness/me_master.py)

    @property
    def rows(self) -> int:
        return len(self.time)

    def signal(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"{name!r} was not recorded; recorded: {', '.join(self.columns)}") from None

    def role(self, role: str) -> np.ndarray:
        """The signal that plays ``role`` (e, de, ym, dym, u) in the scores."""
        return self.signal(self.scenario.signals[role])

    @property
    def us_per_step(self) -> float:
        """Microseconds per communication step of the loop (whole run if it stopped early)."""
        seconds = self.loop_s if self.loop_s == self.loop_s else self.wall_s
        return 1e6 * seconds / max(self.rows - 1, 1)

    def write_csv(self, path, output_interval: float | None = None) -> Path:
        """FMI cross-check style: time first, quoted ``instance.variable`` header."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        every = 1
        if output_interval:
            every = max(1, round(output_interval / self.scenario.step))
        table = np.column_stack([self.time, self.values])[::every]
        header = ",".join(f'"{name}"' for name in ["time", *self.columns])
        np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.17g")
        return path


def resolve_fmu(spec_fmu: str, scenario: Scenario, built: dict | None) -> Path:
    if spec_fmu.endswith(".fmu"):
        path = Path(spec_fmu)
        if not path.is_absolute() and scenario.path is not None:
            path = scenario.path.parent / path
        if not path.exists():
            raise ScenarioError(f"FMU file not found: {path}")
        return path
    if built is None:
        built = build_fmu.ensure_built()
    if spec_fmu not in built:
        raise ScenarioError(f"unknown FMU {spec_fmu!r}; valid: {', '.join(sorted(built))} or a path to an .fmu file")
    return built[spec_fmu]


def _names(info: ModelInfo, causality: str) -> list:
    return [v.name for v in info.variables.values() if v.causality == causality]


def _article(word: str) -> str:
    return "an" if word[:1] in "aeiou" else "a"


def _where(scenario: Scenario) -> str:
    """How messages name the scenario: its file, else its name."""
    return str(scenario.path) if scenario.path is not None else scenario.name


def model_info(scenario: Scenario, instance: str, fmu_paths: dict | None) -> ModelInfo:
    """The model description of one component; a missing or broken FMU file is a ScenarioError
    naming the file, the component and its ``fmu`` key."""
    spec = scenario.components[instance]
    try:
        return ModelInfo.read(resolve_fmu(spec.fmu, scenario, fmu_paths))
    except (ScenarioError, FmuFileError, FileNotFoundError) as error:
        raise ScenarioError(f"{_where(scenario)}: [components.{instance}] fmu = {spec.fmu!r}: {error}") from None


def _check_variable(dotted: str, infos: dict, causality: str, role: str):
    instance, _, variable = dotted.partition(".")
    if instance not in infos:
        raise ScenarioError(f"{role} {dotted!r}: unknown instance {instance!r}{did_you_mean(instance, infos)}; "
                            f"valid: {', '.join(infos)}")
    info = infos[instance]
    found = info.variables.get(variable)
    wanted = _names(info, causality)
    if found is None:
        raise ScenarioError(f"{role} {dotted!r}: {instance} has no variable {variable!r}"
                            f"{did_you_mean(variable, wanted)}; valid {causality}s: {', '.join(wanted)}")
    if found.causality != causality:
        raise ScenarioError(f"{role} {dotted!r} is {_article(found.causality)} {found.causality}, "
                            f"not {_article(causality)} {causality}; "
                            f"valid {causality}s of {instance}: {', '.join(wanted)}")
    if found.type != "Real":
        raise ScenarioError(f"{role} {dotted!r} is of type {found.type}; connections and records are Real")


def _check_parameter_value(instance: str, parameter: str, value, kind: str):
    """A scenario value must be a number (not text, not a Boolean), integral for an Integer.

    Range checks stay with the FMU, which names the valid range; this only stops values
    that float()/int() would silently convert ("0.99") or truncate (1.5 -> 1).
    """
    where = f"[components.{instance}.parameters] {parameter} = {value!r}"
    if kind == "Boolean":
        if not isinstance(value, bool):
            raise ScenarioError(f"{where} is not a Boolean (true or false)")
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy numbers too
        raise ScenarioError(f"{where} is not a number")
    if kind == "Integer" and not (math.isfinite(value) and value == int(value)):
        raise ScenarioError(f"{where} is not an integer")


def validate(scenario: Scenario, infos: dict):
    """Check every name of the scenario against the model descriptions; a mistake is one
    ScenarioError naming the file, the table and the key (and the close match of a misspelt name)."""
    try:
        _validate(scenario, infos)
    except ScenarioError as error:
        raise ScenarioError(f"{_where(scenario)}: {error}") from None


def _validate(scenario: Scenario, infos: dict):
    for name, spec in scenario.components.items():
        info = infos[name]
        for parameter in spec.parameters:
            found = info.variables.get(parameter)
            if found is None or found.causality != "parameter":
                valid = _names(info, "parameter")
                raise ScenarioError(f"[components.{name}.parameters] {info.model_identifier} has no parameter "
                                    f"{parameter!r}"
                                    f"{did_you_mean(parameter, valid)}; valid: {', '.join(valid)}")
            _check_parameter_value(name, parameter, spec.parameters[parameter], found.type)
    targets = set()
    for index, connection in enumerate(scenario.connections):
        _check_variable(connection.source, infos, "output", f"[[connections]] {index + 1}: from =")
        _check_variable(connection.target, infos, "input", f"[[connections]] {index + 1}: to =")
        if connection.target in targets:
            raise ScenarioError(f"[[connections]] {index + 1}: input {connection.target!r} is connected twice")
        targets.add(connection.target)
    for dotted in scenario.record:
        _check_variable(dotted, infos, "output", "[record] variables:")
    connected = {c.source for c in scenario.connections}
    for dotted in scenario.bounds:
        _check_variable(dotted, infos, "output", "[bounds]")
        if dotted not in connected and dotted not in scenario.record:
            raise ScenarioError(f"[bounds] {dotted!r} is neither connected nor recorded, so it is never read")
    for role, dotted in scenario.signals.items():
        if dotted not in scenario.record:
            raise ScenarioError(f"[signals] {role} = {dotted!r} is not in [record] variables"
                                f"{did_you_mean(dotted, scenario.record)}; add it there")


@dataclass
class _Read:
    component: Component
    values: object  # ctypes array the call fills
    call: object  # () -> status: one fmi2GetReal
    view: np.ndarray  # numpy view of values
    first_column: int  # recorded outputs come first in the buffer
    recorded: int
    array: BoundArrayCall  # the same call and arrays, for harness/master_loop.c
    copies = None  # marks a read in the per-step loop


@dataclass
class _Write:
    component: Component
    values: object  # ctypes array the call sends
    call: object  # () -> status: one fmi2SetReal
    copies: tuple  # (index in values, source values array, index in source, divergence bound)
    sources: tuple = ()  # "instance.variable" of each value, for messages
    targets: tuple = ()
    array: BoundArrayCall | None = None  # the same call and arrays, for harness/master_loop.c


def _order(scenario: Scenario, infos: dict, reads: dict, algorithm: str) -> list:
    """The sequence of ("get"|"set", instance) actions for one communication point."""
    getters = [name for name in scenario.components if reads[name]]
    setters = list(dict.fromkeys(c.target_instance for c in scenario.connections))
    if algorithm == "jacobi":
        return [("get", n) for n in getters] + [("set", n) for n in setters]
    edges = {("get", n): set() for n in getters}
    edges.update({("set", n): set() for n in setters})
    for connection in scenario.connections:
        edges[("set", connection.target_instance)].add(("get", connection.source_instance))
    for name in setters:
        if name not in reads or not reads[name]:
            continue
        connected_inputs = {c.target_variable for c in scenario.connections if c.target_instance == name}
        dependencies = infos[name].direct_dependencies
        if any(set(dependencies.get(output, ())) & connected_inputs for output in reads[name]):
            edges[("get", name)].add(("set", name))
    order, done = [], set()
    pending = list(edges)
    while pending:
        ready = [node for node in pending if edges[node] <= done]
        if not ready:
            loop = [f"{kind} {name}" for kind, name in pending]
            raise ScenarioError("algebraic loop: these reads and writes wait on each other through direct "
                                f"feedthrough: {', '.join(loop)}; break it with a component whose output does "
                                "not depend directly on its input, or run --algorithm jacobi")
        for node in ready:
            order.append(node)
            done.add(node)
            pending.remove(node)
    return order


class Master:
    """Instantiate, initialise and step the FMUs of one scenario."""

    def __init__(self, scenario: Scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None,
                 logging_on: bool = True, loop: str = "auto", prepared: dict | None = None):
        """``prepared``: {FMU path: (ModelInfo, folder it is extracted to)} kept by the caller for FMUs
        it runs many times (harness/studies/tune/); other FMUs are read and extracted per run."""
        if algorithm not in ALGORITHMS:
            raise ScenarioError(f"unknown algorithm {algorithm!r}; valid: {', '.join(ALGORITHMS)}")
        self.scenario, self.algorithm = scenario, algorithm
        self.infos, self.extracted = {}, {}
        for name, spec in scenario.components.items():
            path = resolve_fmu(spec.fmu, scenario, fmu_paths) if prepared else None
            if prepared and path in prepared:
                self.infos[name], self.extracted[name] = prepared[path]
            else:
                self.infos[name] = model_info(scenario, name, fmu_paths)  # names a bad FMU file in one line
        validate(scenario, self.infos)
        self.logging_on = logging_on
        self.loop = master_loop.choice(loop)  # "auto": the compiled loop if it can be built (master_loop.py)
        self._compiled_loop = master_loop.library(self.loop)  # resolved before any FMU is instantiated
        self.components: dict[str, Component] = {}

    def _prepare_plan(self, algorithm: str | None = None) -> list:
        """The read/write actions of one communication point; sets the record columns."""
        scenario = self.scenario
        reads = {}
        for name in scenario.components:
            recorded = [d.split(".", 1)[1] for d in scenario.record if d.split(".", 1)[0] == name]
            connected = [c.source_variable for c in scenario.connections if c.source_instance == name]
            reads[name] = list(dict.fromkeys(recorded + connected))
        order = _order(scenario, self.infos, reads, algorithm or self.algorithm)
        read_buffers, columns = {}, []
        for kind, name in order:
            if kind != "get":
                continue
            component = self.components[name]
            array = component.real_reader(reads[name])
            recorded = [v for v in reads[name] if f"{name}.{v}" in scenario.record]
            read_buffers[name] = _Read(component, array.values, array.call, np.ctypeslib.as_array(array.values),
                                       len(columns), len(recorded), array)
            columns += [f"{name}.{v}" for v in recorded]
        plan = []
        for kind, name in order:
            if kind == "get":
                plan.append(read_buffers[name])
                continue
            component = self.components[name]
            incoming = [c for c in scenario.connections if c.target_instance == name]
            array = component.real_writer([c.target_variable for c in incoming])
            copies = tuple((k, read_buffers[c.source_instance].values,
                            reads[c.source_instance].index(c.source_variable), scenario.bound(c.source))
                           for k, c in enumerate(incoming))
            plan.append(_Write(component, array.values, array.call, copies, tuple(c.source for c in incoming),
                               tuple(c.target for c in incoming), array))
        self.plan_columns = columns
        self.column_bounds = np.array([scenario.bound(name) for name in columns])
        # CSV columns in the scenario's record order
        self.column_order = [columns.index(d) for d in scenario.record]
        return plan

    def _propagate(self, plan: list, time: float):
        """One pass of reads and writes at a communication point (the per-step path).

        Every value handed along a connection is checked against the divergence
        bound here (a chained comparison, also False for NaN), so no FMU is ever
        handed a non-finite or runaway input; recorded-only outputs are checked
        in blocks of rows.
        """
        for action in plan:
            copies = action.copies
            if copies is None:  # a read
                status = action.call()
                if status > FMI_WARNING:
                    action.component.fail("fmi2GetReal", status, time)
            else:
                values = action.values
                for k, source, j, bound in copies:
                    value = source[j]
                    if not -bound < value < bound:  # also False for NaN
                        self._diverged_on_write(action, k, value, time)
                    values[k] = value
                status = action.call()
                if status > FMI_WARNING:
                    action.component.fail("fmi2SetReal", status, time)

    def _diverged_on_write(self, action: _Write, index: int, value: float, time: float):
        target = action.targets[index]
        raise Divergence(self._divergence_text(
            time, f"{action.sources[index]} = {value:.6g} beyond its bound {self.scenario.bound(action.sources[index]):g} "
                  f"(on its way to {target})"))

    def _divergence_text(self, time: float, what: str) -> str:
        return (f"diverged at t = {time:.6g} with step {self.scenario.step:g}: {what}; "
                "try a smaller step")

    def run(self, progress=None, progress_every: int = 0) -> RunResult:
        """Run the scenario; on failure raise SimulationFailed holding the partial result."""
        if isinstance(progress_every, bool) or not isinstance(progress_every, int) or progress_every < 0:
            raise ValueError(f"progress_every = {progress_every!r}: a whole number of steps >= 0 (0: steps // 200)")
        scenario = self.scenario
        steps, step, start = scenario.steps, scenario.step, scenario.start
        stop = start + steps * step
        wall_start = clock.perf_counter()
        record = None
        self.rows_done = 0
        try:
            for name, spec in scenario.components.items():
                component = Component(name, self.infos[name]).instantiate(logging_on=self.logging_on,
                                                                          extracted=self.extracted.get(name))
                self.components[name] = component
            for name, spec in scenario.components.items():
                component = self.components[name]
                component.setup(start, stop)
                component.set_parameters(spec.parameters)
            # initial values propagated through the connections in dependency order, for
            # both algorithms (consistent start values); then the plan of the loop
            plan = self._prepare_plan("feedthrough")
            self._propagate(plan, start)
            if self.algorithm != "feedthrough":
                plan = self._prepare_plan()
            record = np.empty((steps + 1, len(self.plan_columns)))
            for component in self.components.values():
                component.exit_initialization()
            every = progress_every or max(1, steps // 200)
            compiled = self._compiled_loop
            loop_start = clock.perf_counter()
            if compiled is None:
                self._loop_python(plan, record, progress, every)
            else:
                self._loop_compiled(compiled, plan, record, progress, every)
            self._propagate(plan, stop)
            row = record[steps]
            for action in plan:
                if action.copies is None and action.recorded:
                    row[action.first_column:action.first_column + action.recorded] = action.view[:action.recorded]
            self.rows_done = steps + 1
            self._check_bound(record, max(0, self.rows_done - DIVERGENCE_CHECK_EVERY - 1), self.rows_done,
                              self.column_bounds)
            self.loop_s = clock.perf_counter() - loop_start
            if progress is not None:
                progress(steps, steps)
        except (FmiError, Divergence, ScenarioError) as error:
            result = self._result(record, self.rows_done, clock.perf_counter() - wall_start, complete=False)
            if isinstance(error, ScenarioError) and record is None:
                raise
            raise SimulationFailed(str(error), result, error) from error
        finally:
            self.logs = {name: component.log for name, component in self.components.items()}  # the FMUs' messages
            for component in self.components.values():
                component.free()
            self.components = {}
        return self._result(record, self.rows_done, clock.perf_counter() - wall_start, complete=True)

    def _loop_python(self, plan: list, record, progress, every: int):
        """Rows 0 .. steps - 1: propagate, record, check, step every FMU (the reference loop)."""
        scenario = self.scenario
        steps, step, start = scenario.steps, scenario.step, scenario.start
        reads = [(a.first_column, a.first_column + a.recorded, a.view[:a.recorded])
                 for a in plan if a.copies is None and a.recorded]
        steppers = [(component, component.stepper()) for component in self.components.values()]
        bound = self.column_bounds
        rows_done = 0
        try:
            for n in range(steps):
                t = start + n * step
                self._propagate(plan, t)
                row = record[n]
                for first, last, view in reads:
                    row[first:last] = view
                rows_done = n + 1
                if rows_done % DIVERGENCE_CHECK_EVERY == 0:
                    self._check_bound(record, rows_done - DIVERGENCE_CHECK_EVERY, rows_done, bound)
                for component, do_step in steppers:
                    status = do_step(t, step, 1)
                    if status > FMI_WARNING:
                        component.fail("fmi2DoStep", status, t)
                if progress is not None and rows_done % every == 0:
                    progress(rows_done, steps)
        finally:
            self.rows_done = rows_done  # for the partial result, if something stopped the loop

    def _loop_compiled(self, function, plan: list, record, progress, every: int):
        """The same rows by harness/master_loop.c, in blocks of ``every`` rows (the progress
        interval); whatever stops it is raised here as _loop_python raises it."""
        scenario = self.scenario
        steps, step, start = scenario.steps, scenario.step, scenario.start
        components = list(self.components.values())
        loop = master_loop.CompiledLoop(function, plan, components, record, self.column_bounds,
                                        DIVERGENCE_CHECK_EVERY)
        n = 0
        while n < steps:
            last = min(steps, (n // every + 1) * every)
            outcome = loop.run(start, step, n, last)
            if outcome.outcome != master_loop.LOOP_DONE:
                self._raise_stop(outcome, plan, components, record)
            self.rows_done = n = last
            if progress is not None and n % every == 0:
                progress(n, steps)

    def _raise_stop(self, outcome, plan: list, components: list, record):
        """Raise, for what stopped the compiled loop at row ``outcome.row``, what the Python loop raises."""
        row = outcome.row
        t = self.scenario.start + row * self.scenario.step
        kind = outcome.outcome
        self.rows_done = row  # the row's reads and writes are not complete
        if kind == master_loop.LOOP_READ_FAILED:
            plan[outcome.action].component.fail("fmi2GetReal", outcome.status, t)
        if kind == master_loop.LOOP_WRITE_DIVERGED:
            self._diverged_on_write(plan[outcome.action], outcome.copy, outcome.value, t)
        if kind == master_loop.LOOP_WRITE_FAILED:
            plan[outcome.action].component.fail("fmi2SetReal", outcome.status, t)
        self.rows_done = row + 1  # the row is recorded
        if kind == master_loop.LOOP_RECORD_DIVERGED:
            self._check_bound(record, self.rows_done - DIVERGENCE_CHECK_EVERY, self.rows_done, self.column_bounds)
        if kind == master_loop.LOOP_STEP_FAILED:
            components[outcome.action].fail("fmi2DoStep", outcome.status, t)
        raise RuntimeError(f"the compiled master loop stopped at row {row} for no reason the Python loop "
                           f"knows (outcome {kind}); rerun with {master_loop.ENVIRONMENT_SWITCH}=python")

    def _check_bound(self, record, first: int, last: int, bound: np.ndarray):
        block = record[first:last]
        with np.errstate(invalid="ignore"):
            bad = ~(np.abs(block) < bound)
        if bad.any():
            row, column = np.argwhere(bad)[0]
            time = self.scenario.start + (first + row) * self.scenario.step
            name = self.plan_columns[column]
            raise Divergence(self._divergence_text(time, f"{name} = {block[row, column]:.6g} "
                                                   f"beyond its bound {bound[column]:g}"))

    def _result(self, record, rows: int, wall_s: float, complete: bool) -> RunResult:
        scenario = self.scenario
        if record is None:
            values = np.empty((0, len(scenario.record)))
        else:
            order = self.column_order  # the record's columns in the scenario's record order: a view if they are
            values = record[:rows] if order == list(range(len(order))) else record[:rows][:, np.asarray(order)]
        time = scenario.start + np.arange(rows) * scenario.step
        return RunResult(scenario, self.algorithm, time, list(scenario.record), values, wall_s, complete,
                         getattr(self, "loop_s", float("nan")) if complete else float("nan"))


def simulate(scenario: Scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None,
             progress=None) -> RunResult:
    """Run one scenario (with its controller variant already set)."""
    return Master(scenario, algorithm, fmu_paths).run(progress=progress)
