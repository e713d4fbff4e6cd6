"""The Model Exchange master (``--algorithm me``): the coupled FMUs integrated with no communication step.

Every FMU of the scenario is instantiated for Model Exchange (the native edition, FMI 2.0 or 3.0;
FMI calls in harness/fmi.py).  The continuous states of all of them form one vector that one
variable-step, error-controlled integrator advances: SUNDIALS CVODE, BDF with a dense
difference-quotient Jacobian (harness/cvode.py; why: docs/model_exchange.md).  Each derivative
evaluation at (t, x) is

1. SetTime(t) on every FMU and SetContinuousStates on every FMU that has states;
2. the master's plan of reads and writes (harness/master.py: outputs read after the inputs they
   depend on directly were set, from each modelDescription's ModelStructure), which sets every
   input in dependency order;
3. GetDerivatives on every FMU that has states.

The root function does the same with GetEventIndicators instead of 3.  A root (a state event), a
time event an FMU announced, or an FMU's request at CompletedIntegratorStep stops the integrator at
the event; the master then runs the event iteration (EnterEventMode, NewDiscreteStates /
UpdateDiscreteStates on every FMU, the inputs propagated after each pass, until no FMU asks for
another pass and no input changed), returns to continuous-time mode, reads the states back (an
event may reset them) and restarts CVODE there.

Results are recorded on the output grid, the scenario's step (``start + k * step``): CVODE's
interpolant gives the state at each grid time inside the last step, the plan evaluates every
output there, and every connected and recorded value is checked against its divergence bound,
as in co-simulation.  The scores (harness/scores.py) read the same grid as a co-simulation run.

The per-evaluation path is lean: prepared value-reference and value arrays, raw C functions
bound once, one shared state, derivative and indicator array.  When zig's C compiler is there
(the ``native`` and ``test`` extras) the whole integration loop runs compiled
(harness/me_loop.c, driven by harness/me_loop.py): the same calls in the same order, CVODE
calling C functions; events are handled here in both cases.  Both give bit-identical records
(tests/test_me_master.py).

Failures stop the run with the rows recorded so far (:class:`~harness.master.SimulationFailed`):
an FMU status >= error, a value beyond its divergence bound at a grid point, and CVODE's own
failures with its flag and message (for instance a step size that collapses on a stiff or
discontinuous right-hand side).
"""
from __future__ import annotations

import ctypes
import math

import numpy as np

from . import compiled_loop, cvode, me_loop
from .fmi import MODEL_EXCHANGE, ModelExchangeComponent, ModelInfo
from .loop_interface import FAILED_FUNCTIONS, LoopOutcome
from .master import DIVERGENCE_CHECK_EVERY, FMI_WARNING, Divergence, Master, RunResult
from .scenario import Scenario, ScenarioError
from .scenario_checks import resolve_fmu

ALGORITHM = "me"
INTEGRATOR = "CVODE BDF (SUNDIALS, dense difference-quotient Jacobian)"
#: the loosest tolerance of the ladder at which every case's ITAE, IAE and Ec agree with the converged
#: co-simulation (docs/model_exchange_accuracy.md says how closely, and what a tighter one costs)
DEFAULT_RTOL = 1e-10
MAX_EVENT_PASSES = 100  # event iteration: passes before the master gives up (a model that never settles)
_DOUBLE = ctypes.sizeof(ctypes.c_double)


class IntegrationFailed(RuntimeError):
    """CVODE stopped with an error flag (the solver's reason in the message)."""


def check_tolerances(rtol: float, atol: float | None) -> tuple:
    """(rtol, atol) with atol defaulting to rtol (times each state's nominal); ValueError names the range."""
    if isinstance(rtol, bool) or not isinstance(rtol, (int, float)) or not (0 < rtol < 1):
        raise ScenarioError(f"rtol = {rtol!r} is invalid; valid: 0 < rtol < 1 (e.g. 1e-8)")
    atol = rtol if atol is None else atol
    if isinstance(atol, bool) or not isinstance(atol, (int, float)) or not (0 < atol < math.inf):
        raise ScenarioError(f"atol = {atol!r} is invalid; valid: a finite number > 0 (default: rtol)")
    return float(rtol), float(atol)


def model_exchange_info(name: str, path) -> ModelInfo:
    """The Model Exchange description of instance ``name``'s FMU, or one error naming it and why not."""
    try:
        return ModelInfo.read(path, MODEL_EXCHANGE)
    except ValueError:
        pass
    tool = ModelInfo.read(path).generation_tool
    why = ("the pythonfmu edition is co-simulation only (pythonfmu cannot export Model Exchange); "
           "use --edition native or native3" if tool.startswith("PythonFMU")
           else "its modelDescription declares co-simulation only")
    raise ScenarioError(f"--algorithm me: instance {name!r} ({path.name}) has no Model Exchange interface: {why} "
                        "(docs/model_exchange.md)")


class ModelExchangeMaster(Master):
    """Instantiate, initialise and integrate the FMUs of one scenario in Model Exchange: the life cycle
    of :meth:`Master.run`, with CVODE's integration and the events as its loop."""

    ALGORITHMS = (ALGORITHM,)
    RUN_ERRORS = (*Master.RUN_ERRORS, IntegrationFailed, cvode.CvodeError)
    LIBRARY = me_loop.LIBRARY

    def __init__(self, scenario: Scenario, fmu_paths: dict | None = None, rtol: float = DEFAULT_RTOL,
                 atol: float | None = None, logging_on: bool = True, loop: str = "auto"):
        self.rtol, self.atol = check_tolerances(rtol, atol)
        super().__init__(scenario, ALGORITHM, fmu_paths, logging_on, loop)
        self.statistics: dict = {}

    def _model_info(self, name: str, fmu_paths: dict | None) -> ModelInfo:
        return model_exchange_info(name, resolve_fmu(self.scenario.components[name].fmu, self.scenario, fmu_paths))

    # ------------------------------------------------------------ messages
    def _divergence_text(self, time: float, what: str) -> str:
        return f"diverged at t = {time:.6g} (model exchange, rtol {self.rtol:g}): {what}"

    # --------------------------------------------------------------- events
    def _event_iteration(self, plan: list, time: float) -> tuple:
        """Discrete states updated until no FMU asks for another pass and no input changed; the inputs
        propagated in dependency order after each pass.  Returns (states changed, next event time)."""
        writes = [action for action in plan if action.copies is not None]
        before = [list(action.values) for action in writes]
        changed, next_time = False, None
        for _ in range(MAX_EVENT_PASSES):
            again = False
            next_time = None
            for component in self.components.values():
                more, terminate, values_changed, timed = component.update_discrete_states()
                if terminate:
                    raise IntegrationFailed(f"{component.name} asked to terminate the simulation at t = {time:.6g}")
                again = again or more
                changed = changed or values_changed
                if timed is not None:
                    next_time = timed if next_time is None else min(next_time, timed)
            self._propagate(plan, time)
            after = [list(action.values) for action in writes]
            if not again and after == before:
                return changed, next_time
            before = after
        raise IntegrationFailed(f"the event iteration at t = {time:.6g} did not settle in {MAX_EVENT_PASSES} passes")

    def _event(self, plan: list, time: float, x) -> tuple:
        """An event at ``time`` with the states ``x`` (ctypes array): event mode, the iteration, back to
        continuous-time mode; the states after the event (an update may reset them) are read back into
        ``self.x``, where the integrator restarts from.  Returns (states changed, next event time)."""
        self._set_point(plan, time, x)
        for component in self.components.values():
            component.enter_event_mode()
        changed, next_time = self._event_iteration(plan, time)
        for component in self.components.values():
            component.enter_continuous_time_mode()
        self._read_states(self.x)
        return changed, next_time

    # ------------------------------------------------------------ the state
    def _layout(self):
        """The blocks of states and indicators and the shared arrays they are bound to."""
        states = sum(c.info.states for c in self.components.values())
        indicators = sum(c.info.event_indicators for c in self.components.values())
        self.x = (ctypes.c_double * max(states, 1))()
        self.dx = (ctypes.c_double * max(states, 1))()
        self.z = (ctypes.c_double * max(indicators, 1))()
        self.blocks, offset, z_offset = [], 0, 0
        for component in self.components.values():
            if component.info.states or component.info.event_indicators:
                self.blocks.append(component.continuous_block(offset, self.x, self.dx, z_offset, self.z))
            offset += component.info.states
            z_offset += component.info.event_indicators
        self.states, self.indicators = states, indicators
        self._bytes = _DOUBLE * max(states, 1)  # one dummy state (derivative 0) when no FMU has any
        view = np.ctypeslib.as_array(self.dx)
        self._dx_view_finite = lambda: bool(np.isfinite(view).all())
        self.timers = [(c, c.time_setter()) for c in self.components.values()]

    def _read_states(self, x):
        for block in self.blocks:
            if block.states:
                pointer = (ctypes.c_double * block.states).from_address(ctypes.addressof(x) + _DOUBLE * block.offset)
                block.component.get_states(pointer)

    def _nominals(self) -> list:
        nominal = (ctypes.c_double * max(self.states, 1))()
        for block in self.blocks:
            if block.states:
                pointer = (ctypes.c_double * block.states).from_address(
                    ctypes.addressof(nominal) + _DOUBLE * block.offset)
                block.component.get_nominals(pointer)
        return [abs(v) if v else 1.0 for v in nominal[:self.states]]

    def _set_point(self, plan: list, time: float, x):
        """Time and states set on every FMU and the plan run (checked): the outputs at (time, x)."""
        if x is not self.x:
            ctypes.memmove(self.x, x, self._bytes)
        for component, set_time in self.timers:
            status = set_time(time)
            if status > FMI_WARNING:
                component.fail("fmi2SetTime", status, time)
        for block in self.blocks:
            if block.states:
                status = block.set_states()
                if status > FMI_WARNING:
                    block.component.fail("fmi2SetContinuousStates", status, time)
        self._propagate(plan, time)

    # ------------------------------------------------------------ the run (Master.run's steps)
    def _progress_units(self) -> tuple:
        return "rows", self.scenario.steps + 1

    def _begin_run(self):
        self.events = {"state": 0, "time": 0, "step": 0}
        self.statistics = {}
        self.solver = None

    def _instantiate(self, name: str) -> ModelExchangeComponent:
        return ModelExchangeComponent(name, self.infos[name]).instantiate(logging_on=self.logging_on)

    def _initialise(self, plan: list) -> list:
        """Out of initialisation mode, the initial event iteration (FMI: event mode after initialisation),
        then continuous-time mode, the state layout and the initial states."""
        for component in self.components.values():
            component.exit_initialization()
        _, self._next_time = self._event_iteration(plan, self.scenario.start)
        for component in self.components.values():
            component.enter_continuous_time_mode()
        self._layout()
        self._read_states(self.x)
        return plan

    def _before_loop(self, plan: list, record):
        """The integrator over every FMU's states, with the compiled loop's functions when there is one."""
        scenario = self.scenario
        start, step = scenario.start, scenario.step
        absolute = [self.atol * n for n in self._nominals()] if self.states else [self.atol]
        compiled = None
        if self._compiled_loop is not None:
            compiled = me_loop.CompiledIntegration(self._compiled_loop, plan, self.timers, self.blocks, self.x,
                                                   self.dx, self.z, self.states, self.indicators, record,
                                                   self.column_bounds, DIVERGENCE_CHECK_EVERY, start, step)
        self.solver = cvode.Cvode(
            max(self.states, 1), start, self.x, self.rtol, absolute,
            rhs=self._python_rhs if compiled is None else compiled.rhs,
            roots=self._python_roots if compiled is None else compiled.roots, indicators=self.indicators,
            user_data=None if compiled is None else compiled.user_data, stop=start + scenario.steps * step)
        if compiled is not None:
            compiled.attach(self.solver)
        self._compiled = compiled

    @staticmethod
    def _default_progress_text(unit: str) -> str:
        return f"{unit} // 200"

    def _loop(self, plan: list, record, progress, every: int):
        """Row 0 at the start, then rows 1 .. rows - 1 by the integration (a progress call every ``every``
        rows; 0: rows // 200)."""
        scenario = self.scenario
        every = every or max(1, self._progress_units()[1] // 200)
        self._record_row(plan, record, 0, scenario.start, self.x)
        self.rows_done = 1
        self._integrate(plan, self._compiled, record, self._next_time, scenario.start + scenario.steps * scenario.step,
                        progress, every)

    def _end_run(self):
        self._finish_statistics()
        if self.solver is not None:
            self.solver.close()

    def _finish_statistics(self):
        if self.solver is None or self.statistics:
            return
        self.statistics = {"integrator": INTEGRATOR, "rtol": self.rtol, "atol": self.atol,
                           **self.solver.statistics(), "state_events": self.events["state"],
                           "time_events": self.events["time"], "step_events": self.events["step"],
                           "loop": "python" if self._compiled_loop is None else "compiled"}

    def _result(self, record, rows: int, wall_s: float, complete: bool) -> RunResult:
        self._finish_statistics()  # a failed run's too, before the solver is closed
        result = super()._result(record, rows, wall_s, complete)
        result.solver = dict(self.statistics) or None
        return result

    # ------------------------------------------------------- the integration
    def _integrate(self, plan: list, compiled, record, next_time, stop: float, progress, every: int):
        """Rows 1 .. rows - 1: CVODE's steps, the grid rows inside each, the events between them."""
        self._plan = plan
        rows = len(record)
        step_events = any(c.info.needs_completed_integrator_step for c in self.components.values())
        next_time = math.inf if next_time is None else next_time
        target = self._target(next_time, stop)
        row = 1
        while row < rows:
            if compiled is None:
                flag, reached, row = self._steps_python(plan, record, target, next_time, step_events, row,
                                                        min(rows, (row // every + 1) * every))
            else:
                outcome = compiled.run(target, next_time, step_events, row, min(rows, (row // every + 1) * every))
                self.rows_done = row = outcome.row
                flag, reached = self._compiled_outcome(outcome, compiled, plan, record)
            if progress is not None and (row % every == 0 or row == rows):
                progress(row - 1, rows - 1)
            if flag is None:  # a block of rows done, no event
                continue
            event = self._after_step(plan, flag, reached, next_time, step_events)
            if event is not None:
                next_time = event
                target = self._target(next_time, stop)

    def _target(self, next_time: float, stop: float) -> float:
        """The time CVODE steps towards: the next time event, else the stop (set as CVODE's stop time)."""
        target = min(next_time, stop)
        cvode.CVodeSetStopTime(self.solver.memory, target)
        return target

    def _steps_python(self, plan: list, record, target: float, next_time: float, step_events: bool, row: int,
                      last_row: int) -> tuple:
        """harness/me_loop.c's me_loop_run in Python: (CVode's flag or None, time reached, next row)."""
        solver, rows = self.solver, len(record)
        if getattr(self, "_taylor", None) is None or self._taylor.shape[1] != max(self.states, 1):
            self._taylor = np.zeros((cvode.MAX_ORDER + 1, max(self.states, 1)))
        step, start = self.scenario.step, self.scenario.start
        while row < rows:
            self._evaluation_error = None
            flag = solver.step(target)
            reached = solver.t.value
            if flag < 0:
                self._stop_failed(flag)
            tn, order = 0.0, 0
            if row < rows and start + row * step <= reached:  # the interpolant as a Taylor polynomial about tn
                status, tn, order = solver.taylor(self._taylor)
                if status < 0:
                    self._stop_failed(status)
            while row < rows:
                t = start + row * step
                if not t <= reached:
                    break
                dt = t - tn  # Horner, as harness/me_loop.c: x = ((c_q dt + c_q-1) dt + ...) dt + c_0
                x = self._taylor[order].copy()
                for k in range(order - 1, -1, -1):
                    np.multiply(x, dt, out=x)
                    np.add(x, self._taylor[k], out=x)
                ctypes.memmove(self.x, x.ctypes.data, self._bytes)
                self._record_row(plan, record, row, t, self.x)
                row += 1
                self.rows_done = row
                if row % DIVERGENCE_CHECK_EVERY == 0:
                    self._check_bound(record, row - DIVERGENCE_CHECK_EVERY, row, self.column_bounds)
            if flag == cvode.CV_ROOT_RETURN or reached >= next_time or step_events:
                return flag, reached, row
            if row >= last_row:
                break
        return None, None, row

    def _compiled_outcome(self, outcome, compiled, plan: list, record) -> tuple:
        """(flag or None, time reached) of a compiled block; what stopped it raised as the Python loop raises."""
        kind = outcome.outcome
        if kind == LoopOutcome.DONE:
            return None, None
        if kind == LoopOutcome.EVENT:
            return outcome.status, outcome.time
        if kind == LoopOutcome.SOLVER_FAILED:
            failure = compiled.loop.failure  # the evaluation that made CVODE fail, if one did
            self._raise_failure(failure.outcome, failure, plan)
            self._evaluation_error = None
            self._stop_failed(outcome.status)
        if kind == LoopOutcome.RECORD_DIVERGED:
            self._check_bound(record, self.rows_done - DIVERGENCE_CHECK_EVERY, self.rows_done, self.column_bounds)
        self._raise_failure(kind, outcome, plan)
        raise RuntimeError(f"the compiled Model Exchange loop stopped at row {outcome.row} for no reason the "
                           f"Python loop knows (outcome {kind}); rerun with {compiled_loop.ENVIRONMENT_SWITCH}=python")

    def _raise_failure(self, kind: int, where, plan: list):
        """Raise the FmiError or Divergence of a failure ``kind`` at ``where`` (an Outcome)."""
        if kind == LoopOutcome.WRITE_DIVERGED:
            self._diverged_on_write(plan[where.index], where.copy, where.value, where.time)  # raises Divergence
        function = FAILED_FUNCTIONS.get(kind)
        if function is None:
            return
        if kind in (LoopOutcome.READ_FAILED, LoopOutcome.WRITE_FAILED):
            component = plan[where.index].component
        elif kind == LoopOutcome.SET_TIME_FAILED:
            component = self.timers[where.index][0]
        else:
            component = self.blocks[where.index].component
        component.fail(function, where.status, where.time)

    def _after_step(self, plan: list, flag: int, reached: float, next_time: float, step_events: bool):
        """After a step that may end at an event: the event at ``reached`` if there is one (a root, a time
        event, or one an FMU asked for at CompletedIntegratorStep); returns the next time event (math.inf:
        none) when an event was handled, else None."""
        solver = self.solver
        kind = None
        if flag == cvode.CV_ROOT_RETURN:
            kind = "state"
        elif reached >= next_time:
            kind = "time"
        elif step_events:
            self._set_point(plan, reached, solver.y_data)
            for component in self.components.values():
                if component.info.needs_completed_integrator_step:
                    enter, terminate = component.completed_integrator_step()
                    if terminate:
                        raise IntegrationFailed(f"{component.name} asked to terminate the simulation at "
                                                f"t = {reached:.6g}")
                    kind = kind or ("step" if enter else None)
        if kind is None:
            return None
        self.events[kind] += 1
        _, timed = self._event(plan, reached, solver.y_data)
        solver.reinit(reached, self.x)
        return math.inf if timed is None else timed

    # ------------------------------------------------- the Python evaluations
    def _record_row(self, plan: list, record, row: int, time: float, x):
        """Row ``row`` at ``time`` from the states ``x``: the plan evaluated (checked), the reads recorded."""
        self._set_point(plan, time, x)
        values = record[row]
        for action in plan:
            if action.copies is None and action.recorded:
                values[action.first_column:action.first_column + action.recorded] = action.view[:action.recorded]

    def _python_rhs(self, t, y, ydot, user_data):
        return self._python_evaluate(t, y, ydot, True)

    def _python_roots(self, t, y, gout, user_data):
        return self._python_evaluate(t, y, gout, False)

    def _python_evaluate(self, t, y, out, derivatives: bool) -> int:
        """One derivative (or indicator) evaluation for CVODE (harness/me_loop.c's me_rhs, me_roots): 0; 1,
        recoverable (a value beyond its bound, a derivative not finite: CVODE retries a smaller step);
        -1, an FMU failed (CVODE stops, the master raises the failure)."""
        try:
            ctypes.memmove(self.x, cvode.N_VGetArrayPointer(y), self._bytes)
            self._set_point(self._plan, t, self.x)
            if derivatives:
                for block in self.blocks:
                    if block.states:
                        status = block.get_derivatives()
                        if status > FMI_WARNING:
                            block.component.fail("fmi2GetDerivatives", status, t)
                ctypes.memmove(cvode.N_VGetArrayPointer(out), self.dx, self._bytes)
                return 0 if self._dx_view_finite() else 1
            for block in self.blocks:
                if block.indicators:
                    status = block.get_indicators()
                    if status > FMI_WARNING:
                        block.component.fail("fmi2GetEventIndicators", status, t)
            ctypes.memmove(out, self.z, _DOUBLE * self.indicators)
            return 0
        except Divergence as error:
            self._evaluation_error = error
            return 1
        except Exception as error:  # noqa: BLE001 - raised again after CVode returns: no exception crosses C
            self._evaluation_error = error
            return -1

    def _stop_failed(self, flag: int):
        """CVODE returned ``flag`` < 0: the evaluation's own failure if one caused it, else CVODE's reason."""
        error = self._evaluation_error
        if error is not None:
            raise error
        raise IntegrationFailed(f"the integration stopped at t = {self.solver.t.value:.6g}: CVODE "
                                f"{self.solver.reason(flag)} (rtol {self.rtol:g}, atol {self.atol:g})")

def simulate(scenario: Scenario, fmu_paths: dict | None = None, rtol: float = DEFAULT_RTOL,
             atol: float | None = None, progress=None) -> RunResult:
    """Run one scenario (with its controller variant set) in Model Exchange."""
    return ModelExchangeMaster(scenario, fmu_paths, rtol, atol).run(progress=progress)


__all__ = ["ModelExchangeMaster", "IntegrationFailed", "simulate", "check_tolerances", "ALGORITHM", "DEFAULT_RTOL"]
