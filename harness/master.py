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

import time as clock
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import atomic_files, compiled_loop, master_loop, progress as progress_display
from .fmi import BoundArrayCall, Component, FmiError, ModelInfo
from .loop_interface import FAILED_FUNCTIONS, LoopOutcome
from .scenario import Scenario, ScenarioError
from .scenario_checks import model_info, resolve_fmu, validate

ALGORITHMS = ("feedthrough", "jacobi")
FMI_WARNING = 1
DIVERGENCE_CHECK_EVERY = 64  # rows; a non-finite value set on an FMU is caught at once
#: the compiled loop with a progress callback and no progress_every: its first block (rows), short of one
#: tick of the progress display's clock even on the slowest FMUs (pythonfmu's, a few tens of us a row) and
#: a whole short run on the native ones; then blocks that last about one tick (the count it shows is never older)
FIRST_PROGRESS_BLOCK = 4096
PROGRESS_BLOCK_S = progress_display.CLOCK_TICK_S


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
    loop_cpu_s: float = float("nan")  # the same, in CPU time of the thread that ran it (what load cannot add to)
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

    @property
    def cpu_us_per_step(self) -> float:
        """Microseconds of the loop thread's CPU time per communication step (NaN if the run stopped early)."""
        return 1e6 * self.loop_cpu_s / max(self.rows - 1, 1)

    def write_csv(self, path, output_interval: float | None = None) -> Path:
        """FMI cross-check style: time first, quoted ``instance.variable`` header; written whole or not at all
        (harness/atomic_files.py)."""
        path = Path(path)
        every = 1
        if output_interval:
            every = max(1, round(output_interval / self.scenario.step))
        table = np.column_stack([self.time, self.values])[::every]
        header = ",".join(f'"{name}"' for name in ["time", *self.columns])
        with atomic_files.replacing(path, "w", newline="") as stream:
            np.savetxt(stream, table, delimiter=",", header=header, comments="", fmt="%.17g")
        return path


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
    """Instantiate, initialise and step the FMUs of one scenario.

    :meth:`run` is the life cycle every master shares; a master of another kind (harness/me_master.py)
    specialises its steps (``_model_info``, ``_progress_units``, ``_begin_run``, ``_instantiate``,
    ``_initialise``, ``_before_loop``, ``_loop``, ``_end_run``) and the class attributes below.
    """

    ALGORITHMS = ALGORITHMS
    #: what stops a run with the rows computed so far (SimulationFailed)
    RUN_ERRORS = (FmiError, Divergence, ScenarioError)
    #: the compiled loop (harness/compiled_loop.py) of this kind of master
    LIBRARY = master_loop.LIBRARY

    def __init__(self, scenario: Scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None,
                 logging_on: bool = True, loop: str = "auto", prepared: dict | None = None):
        """``prepared``: {FMU path: (ModelInfo, folder it is extracted to)} kept by the caller for FMUs
        it runs many times (harness/studies/tune/); other FMUs are read and extracted per run."""
        if algorithm not in self.ALGORITHMS:
            raise ScenarioError(f"unknown algorithm {algorithm!r}; valid: {', '.join(self.ALGORITHMS)}")
        self.scenario, self.algorithm = scenario, algorithm
        self.infos, self.extracted = {}, {}
        for name, spec in scenario.components.items():
            path = resolve_fmu(spec.fmu, scenario, fmu_paths) if prepared else None
            if prepared and path in prepared:
                self.infos[name], self.extracted[name] = prepared[path]
            else:
                self.infos[name] = self._model_info(name, fmu_paths)  # names a bad FMU file in one line
        validate(scenario, self.infos)
        self.logging_on = logging_on
        self.loop = compiled_loop.choice(loop)  # "auto": the compiled loop if it can be built
        self._compiled_loop = self.LIBRARY.get(self.loop)  # resolved before any FMU is instantiated
        self.components: dict = {}  # instance name -> its Component, while a run lasts

    def _model_info(self, name: str, fmu_paths: dict | None) -> ModelInfo:
        """The model description of component ``name`` (its co-simulation interface)."""
        return model_info(self.scenario, name, fmu_paths)

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
        """Run the scenario; on failure raise SimulationFailed holding the partial result.

        Every FMU is instantiated, set up and given its parameters, and the initial values are
        propagated through the connections in dependency order (consistent start values, for every
        algorithm); then the master's own steps run (``_initialise``, ``_before_loop`` and ``_loop``:
        the fixed-step loop here), the last rows are checked against their bounds, and every FMU is
        freed whatever happened.
        """
        unit, count = self._progress_units()
        if isinstance(progress_every, bool) or not isinstance(progress_every, int) or progress_every < 0:
            raise ValueError(f"progress_every = {progress_every!r}: a whole number of {unit} >= 0 "
                             f"(0: {self._default_progress_text(unit)})")
        scenario = self.scenario
        steps, start = scenario.steps, scenario.start
        stop = start + steps * scenario.step
        wall_start = clock.perf_counter()
        record = None
        self.rows_done = 0
        self._begin_run()
        try:
            for name in scenario.components:
                self.components[name] = self._instantiate(name)
            for name, spec in scenario.components.items():
                component = self.components[name]
                component.setup(start, stop)
                component.set_parameters(spec.parameters)
            plan = self._prepare_plan("feedthrough")
            self._propagate(plan, start)
            plan = self._initialise(plan)
            record = np.empty((steps + 1, len(self.plan_columns)))
            self._before_loop(plan, record)
            loop_start, loop_cpu_start = clock.perf_counter(), clock.thread_time()
            if not self._loop(plan, record, progress, progress_every):  # the last rows, unless the loop checked them
                self._check_bound(record, max(0, self.rows_done - DIVERGENCE_CHECK_EVERY - 1), self.rows_done,
                                  self.column_bounds)
            self.loop_s = clock.perf_counter() - loop_start
            self.loop_cpu_s = clock.thread_time() - loop_cpu_start
            if progress is not None:
                progress(steps, steps)
        except self.RUN_ERRORS as error:
            result = self._result(record, self.rows_done, clock.perf_counter() - wall_start, complete=False)
            if isinstance(error, ScenarioError) and record is None:
                raise
            raise SimulationFailed(str(error), result, error) from error
        finally:
            self.logs = {name: component.log for name, component in self.components.items()}  # the FMUs' messages
            self._release_components(completed=record is not None and self.rows_done == steps + 1)
            self.components = {}
            self._end_run()
        return self._result(record, self.rows_done, clock.perf_counter() - wall_start, complete=True)

    # ------------------------------------------------ the steps a master specialises
    def _progress_units(self) -> tuple:
        """(what progress counts, how many of them a run has)."""
        return "steps", self.scenario.steps

    @staticmethod
    def _default_progress_text(unit: str) -> str:
        """What ``progress_every = 0`` means, for the message of a bad value."""
        return f"about every {PROGRESS_BLOCK_S:g} s with the compiled loop, every {unit} // 200 with the Python loop"

    def _begin_run(self):
        """Per-run state set before anything is instantiated."""

    def _instantiate(self, name: str) -> Component:
        return Component(name, self.infos[name]).instantiate(logging_on=self.logging_on,
                                                              extracted=self.extracted.get(name))

    def _initialise(self, plan: list) -> list:
        """After the initial values: every FMU out of initialisation mode; returns the loop's plan (the
        algorithm's order of reads and writes)."""
        if self.algorithm != "feedthrough":
            plan = self._prepare_plan()
        for component in self.components.values():
            component.exit_initialization()
        return plan

    def _before_loop(self, plan: list, record):
        """What the loop needs made before it is timed: the record's memory touched (its pages are the
        system's to map before the first row is written, not during the loop) and the compiled loop's plan
        (harness/master_loop.py)."""
        record.fill(0.0)
        self._compiled = None
        if self._compiled_loop is not None:
            self._compiled = master_loop.CompiledLoop(self._compiled_loop, plan, list(self.components.values()),
                                                      record, self.column_bounds, DIVERGENCE_CHECK_EVERY)

    def _loop(self, plan: list, record, progress, every: int) -> bool:
        """Rows 0 .. steps: the fixed-step loop (compiled or Python), then the last communication point.
        ``every``: rows between progress calls (0: the loop's own choice).  True when the loop checked the
        last rows against their bounds itself (the compiled loop does)."""
        scenario = self.scenario
        steps = scenario.steps
        if self._compiled is not None:  # the last block's call ends with the last communication point
            self._loop_compiled(self._compiled, plan, record, progress, every)
            self.rows_done = steps + 1
            return True
        self._loop_python(plan, record, progress, every)
        self._propagate(plan, scenario.start + steps * scenario.step)
        row = record[steps]
        for action in plan:
            if action.copies is None and action.recorded:
                row[action.first_column:action.first_column + action.recorded] = action.view[:action.recorded]
        self.rows_done = steps + 1
        return False

    def _release_components(self, completed: bool):
        """After a run, whether it ``completed`` or not: every FMU freed (a master that reuses its
        instances from run to run keeps them here)."""
        for component in self.components.values():
            component.free()

    def _end_run(self):
        """After every FMU is freed, whether the run completed or not."""

    # ------------------------------------------------------- the fixed-step loop
    def _loop_python(self, plan: list, record, progress, every: int):
        """Rows 0 .. steps - 1: propagate, record, check, step every FMU (the reference loop)."""
        scenario = self.scenario
        steps, step, start = scenario.steps, scenario.step, scenario.start
        reads = [(a.first_column, a.first_column + a.recorded, a.view[:a.recorded])
                 for a in plan if a.copies is None and a.recorded]
        steppers = [(component, component.stepper()) for component in self.components.values()]
        bound = self.column_bounds
        every = every or max(1, steps // 200)
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

    def _loop_compiled(self, loop, plan: list, record, progress, every: int):
        """The same rows by harness/master_loop.c, which checks every bound itself: all of them in one
        call when no one follows the progress; else in blocks of ``every`` rows (the caller's progress
        interval), with a progress call after each, or, with ``every`` 0, in blocks of about
        PROGRESS_BLOCK_S of wall time each (sized from the rows per second of the blocks before), with a
        progress call between two of them, none after the first (it sizes the next) nor after the last
        (run() reports the end).  Whatever stops it is raised here as _loop_python raises it."""
        scenario = self.scenario
        steps, step, start = scenario.steps, scenario.step, scenario.start
        components = list(self.components.values())
        n, block = 0, FIRST_PROGRESS_BLOCK
        while n < steps:
            if progress is None:
                last = steps
            elif every:
                last = min(steps, (n // every + 1) * every)
            else:
                last = min(steps, n + block)
            began = clock.perf_counter()
            outcome = loop.run(start, step, n, last, steps)
            if outcome.outcome != LoopOutcome.DONE:
                self._raise_stop(outcome, plan, components, record)
            sizing = n == 0  # the first block of a time-sized run only measures the rows per second
            if progress is not None and not every:
                rows_per_s = (last - n) / max(clock.perf_counter() - began, 1e-9)
                block = max(1, int(rows_per_s * PROGRESS_BLOCK_S))
            self.rows_done = n = last
            if progress is None:
                continue
            if every:
                if n % every == 0:
                    progress(n, steps)
            elif not sizing and n < steps:  # a line is due (the run's end is reported by run())
                progress(n, steps)

    def _raise_stop(self, outcome, plan: list, components: list, record):
        """Raise, for what stopped the compiled loop at row ``outcome.row``, what the Python loop raises."""
        row = outcome.row
        t = self.scenario.start + row * self.scenario.step
        kind = outcome.outcome
        self.rows_done = row  # the row's reads and writes are not complete
        if kind == LoopOutcome.OUT_OF_MEMORY:
            raise MemoryError(f"the compiled master loop could not allocate its working memory at row {row}")
        if kind == LoopOutcome.WRITE_DIVERGED:
            self._diverged_on_write(plan[outcome.index], outcome.copy, outcome.value, t)
        if kind in (LoopOutcome.READ_FAILED, LoopOutcome.WRITE_FAILED):
            plan[outcome.index].component.fail(FAILED_FUNCTIONS[kind], outcome.status, t)
        self.rows_done = row + 1  # the row is recorded
        if kind == LoopOutcome.RECORD_DIVERGED:
            self._check_bound(record, max(0, self.rows_done - DIVERGENCE_CHECK_EVERY), self.rows_done,
                              self.column_bounds)
        if kind == LoopOutcome.STEP_FAILED:
            components[outcome.index].fail(FAILED_FUNCTIONS[kind], outcome.status, t)
        raise RuntimeError(f"the compiled master loop stopped at row {row} for no reason the Python loop "
                           f"knows (outcome {kind}); rerun with {compiled_loop.ENVIRONMENT_SWITCH}=python")

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
                         getattr(self, "loop_s", float("nan")) if complete else float("nan"),
                         getattr(self, "loop_cpu_s", float("nan")) if complete else float("nan"))


def simulate(scenario: Scenario, algorithm: str = "feedthrough", fmu_paths: dict | None = None,
             progress=None) -> RunResult:
    """Run one scenario (with its controller variant already set)."""
    return Master(scenario, algorithm, fmu_paths).run(progress=progress)
