"""The master's compiled loop (harness/master_loop.c) against its Python loop.

1. The C loop alone, on fake FMUs made of ctypes callbacks: the order of the calls, their
   arguments (time, step, the copied values), the record, and each way a block stops
   (getReal / setReal / doStep status >= error, a value beyond its bound on its way to an
   input, a recorded value beyond its bound at the end of a check block), for FMI 2.0 and
   FMI 3.0 signatures.
2. The whole master with either loop on the real FMUs: every recorded value bit-identical,
   the same FMU messages, and on failure the same exception text and the same rows kept.
"""
from __future__ import annotations

import ctypes
import dataclasses
import math

import numpy as np
import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build import toolchain as c_toolchain
from harness import compiled_loop, master_loop
from harness import master as master_module
from harness import scenario as scenarios
from harness.loop_interface import ACTION_READ, ACTION_WRITE, Action, LoopOutcome, Outcome, Stepper
from harness.master import Master, SimulationFailed

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

GET2 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                        ctypes.POINTER(ctypes.c_double))
GET3 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint), ctypes.c_size_t,
                        ctypes.POINTER(ctypes.c_double), ctypes.c_size_t)
STEP2 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)
_bool_p = ctypes.POINTER(ctypes.c_bool)
STEP3 = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool, _bool_p,
                         _bool_p, _bool_p, ctypes.POINTER(ctypes.c_double))


class FakeSystem:
    """Two fake FMUs: A (outputs a0, a1; a0 recorded in column 1) and B (inputs <- A.a1, A.a0; output
    b0 recorded in column 0).

    Plan per row: get A, set B <- (A.a1, A.a0), get B; then doStep A, doStep B.  A's outputs are
    (row + 0.25, 2 row + 0.5) at its k-th getReal (k = row); B's output is its last first input
    times 3.  ``fail`` = (call, row, status) makes that call return ``status`` at that row.
    ``bound``, ``bound2``: the divergence bounds of B's two inputs.
    """

    def __init__(self, fmi_version: int, rows: int, fail=None, a1_override=None, bound=1e6, record_bounds=(1e6, 1e6),
                 a0_override=None, bound2=1e6):
        self.fmi_version, self.fail, self.a1_override, self.a0_override = fmi_version, fail, a1_override, a0_override
        self.trace = []
        self.row = {"getA": 0, "setB": 0, "getB": 0, "stepA": 0, "stepB": 0}
        self.b_input = 0.0
        get_type, step_type = (GET3, STEP3) if fmi_version == 3 else (GET2, STEP2)
        self._callbacks = [get_type(self._get), get_type(self._set), step_type(self._step)]
        self.a_refs, self.a_values = (ctypes.c_uint * 2)(7, 8), (ctypes.c_double * 2)()
        self.b_in_refs, self.b_in_values = (ctypes.c_uint * 2)(3, 5), (ctypes.c_double * 2)()
        self.b_refs, self.b_values = (ctypes.c_uint * 1)(4), (ctypes.c_double * 1)()
        self.sources = (ctypes.c_void_p * 2)(ctypes.addressof(self.a_values), ctypes.addressof(self.a_values))
        self.source_index = (ctypes.c_size_t * 2)(1, 0)
        self.bounds = (ctypes.c_double * 2)(bound, bound2)
        get_address, set_address, step_address = (ctypes.cast(c, ctypes.c_void_p).value for c in self._callbacks)
        actions = (Action * 3)()
        for entry, (kind, instance, call, refs, values, first, recorded) in zip(actions, [
                (ACTION_READ, 1, get_address, self.a_refs, self.a_values, 1, 1),
                (ACTION_WRITE, 2, set_address, self.b_in_refs, self.b_in_values, 0, 0),
                (ACTION_READ, 2, get_address, self.b_refs, self.b_values, 0, 1)]):
            entry.kind, entry.fmi_version, entry.instance, entry.call = kind, fmi_version, instance, call
            entry.references, entry.count, entry.values = ctypes.addressof(refs), len(values), ctypes.addressof(values)
            entry.first_column, entry.recorded = first, recorded
        actions[1].sources = ctypes.addressof(self.sources)
        actions[1].source_index = ctypes.addressof(self.source_index)
        actions[1].bounds = ctypes.addressof(self.bounds)
        steppers = (Stepper * 2)()
        for entry, instance in zip(steppers, (1, 2)):
            entry.fmi_version, entry.instance, entry.do_step = fmi_version, instance, step_address
        self.actions, self.steppers = actions, steppers
        self.record = np.full((rows + 1, 2), -1.0)  # one row more than run: a write past a row shows
        self.column_bounds = (ctypes.c_double * 2)(*record_bounds)

    def _status(self, call: str) -> int:
        row = self.row[call]
        self.row[call] += 1
        if self.fail and self.fail[0] == call and self.fail[1] == row:
            return self.fail[2]
        return 0

    def _get(self, instance, references, count, values, *value_count):
        if self.fmi_version == 3:
            assert value_count == (count,)
        name = "A" if instance == 1 else "B"
        row = self.row[f"get{name}"]
        self.trace.append((f"get{name}", [references[i] for i in range(count)]))
        if name == "A":
            values[0], values[1] = row + 0.25, 2 * row + 0.5
            if self.a1_override and self.a1_override[0] == row:
                values[1] = self.a1_override[1]
            if self.a0_override and self.a0_override[0] == row:
                values[0] = self.a0_override[1]
        else:
            values[0] = 3 * self.b_input
        return self._status(f"get{name}")

    def _set(self, instance, references, count, values, *value_count):
        assert instance == 2 and count == 2 and (references[0], references[1]) == (3, 5)
        self.b_input = values[0]
        self.trace.append(("setB", values[0], values[1]))
        return self._status("setB")

    def _step(self, instance, time, step, no_prior_state, *outputs):
        assert no_prior_state
        name = "A" if instance == 1 else "B"
        self.trace.append((f"step{name}", time, step))
        return self._status(f"step{name}")

    def run(self, first_row: int, last_row: int, start=0.1, step=0.0005, check_every=4, steps=-1) -> Outcome:
        function = master_loop.library("c").master_loop_run
        outcome = Outcome()
        function(self.actions, 3, self.steppers, 2, start, step, first_row, last_row, steps,
                 self.record.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), 2,
                 ctypes.cast(self.column_bounds, ctypes.POINTER(ctypes.c_double)), check_every, ctypes.byref(outcome))
        return outcome

    def finish(self, steps: int, check_every=4) -> Outcome:
        function = master_loop.library("c").master_loop_finish
        outcome = Outcome()
        function(self.actions, 3, steps, self.record.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), 2,
                 ctypes.cast(self.column_bounds, ctypes.POINTER(ctypes.c_double)), check_every, ctypes.byref(outcome))
        return outcome


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_the_last_communication_point_is_the_plans_pass_and_the_check_of_the_rows_left(fmi_version):
    """master_loop_finish: row `steps` is read, handed along and recorded with no doStep; then the rows after
    the last block check are checked (here rows 8 .. 10 of 11, check_every 4)."""
    system = FakeSystem(fmi_version, rows=11)
    assert system.run(0, 10).outcome == LoopOutcome.DONE
    del system.trace[:]
    outcome = system.finish(10)
    assert outcome.outcome == LoopOutcome.DONE and outcome.row == 10
    assert [entry[0] for entry in system.trace] == ["getA", "setB", "getB"]  # no doStep
    assert list(system.record[10]) == [3 * (2 * 10 + 0.5), 10.25]
    tail = FakeSystem(fmi_version, rows=11, record_bounds=(1e6, 9.0), a0_override=(10, 0.0))  # row 9 alone is beyond
    assert tail.run(0, 8).outcome == LoopOutcome.DONE  # rows 0 .. 7, checked at 4 and 8
    tail.row = {key: 10 for key in tail.row}
    tail.record[8:10] = [[0.0, 8.25], [0.0, 9.25]]  # rows 8, 9 as a run would leave them
    stopped = tail.finish(10)
    assert (stopped.outcome, stopped.row) == (LoopOutcome.RECORD_DIVERGED, 10)
    failing = FakeSystem(fmi_version, rows=11, fail=("getA", 0, 3))
    failed = failing.finish(10)
    assert (failed.outcome, failed.row, failed.index, failed.status) == (LoopOutcome.READ_FAILED, 10, 0, 3)


def test_a_call_that_reaches_the_last_row_ends_with_the_last_communication_point():
    """master_loop_run with last_row = steps: the rows, then master_loop_finish's pass, in one call."""
    whole, parts = FakeSystem(2, rows=11), FakeSystem(2, rows=11)
    assert whole.run(0, 10, steps=10).outcome == LoopOutcome.DONE
    assert parts.run(0, 10).outcome == LoopOutcome.DONE and parts.finish(10).outcome == LoopOutcome.DONE
    assert whole.trace == parts.trace and whole.trace[-1][0] == "getB"  # no doStep after the last row
    assert np.array_equal(whole.record, parts.record)
    assert FakeSystem(2, rows=11).run(0, 6, steps=10).outcome == LoopOutcome.DONE  # a block before the end: rows only
    failing = FakeSystem(2, rows=11, fail=("getA", 10, 3)).run(0, 10, steps=10)
    assert (failing.outcome, failing.row, failing.index) == (LoopOutcome.READ_FAILED, 10, 0)


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_the_c_loop_makes_the_calls_of_the_python_loop_in_its_order(fmi_version):
    rows = 100  # start + n * step, not fma(n, step, start): 30 of these 100 times differ in the last bit
    system = FakeSystem(fmi_version, rows=rows)
    outcome = system.run(0, rows, start=0.1, step=0.0005)
    assert outcome.outcome == LoopOutcome.DONE
    expected = []
    for n in range(rows):
        t = 0.1 + n * 0.0005  # the time exactly as Python computes it
        expected += [("getA", [7, 8]), ("setB", 2 * n + 0.5, n + 0.25), ("getB", [4]), ("stepA", t, 0.0005),
                     ("stepB", t, 0.0005)]
    assert system.trace == expected
    assert system.record[:rows].tolist() == [[3 * (2 * n + 0.5), n + 0.25] for n in range(rows)]
    assert system.record[rows].tolist() == [-1.0, -1.0]  # nothing written beyond the block


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("status", [2, 3, 4])  # discard, error, fatal
@pytest.mark.parametrize("call, outcome_kind, action, rows_recorded", [
    ("getA", LoopOutcome.READ_FAILED, 0, 2),
    ("setB", LoopOutcome.WRITE_FAILED, 1, 2),
    ("getB", LoopOutcome.READ_FAILED, 2, 2),
    ("stepA", LoopOutcome.STEP_FAILED, 0, 3),
    ("stepB", LoopOutcome.STEP_FAILED, 1, 3),
])
def test_an_fmi_error_stops_the_block_where_the_python_loop_stops(fmi_version, status, call, outcome_kind, action,
                                                                   rows_recorded):
    system = FakeSystem(fmi_version, rows=6, fail=(call, 2, status))
    outcome = system.run(0, 6)
    assert (outcome.outcome, outcome.row, outcome.index, outcome.status) == (outcome_kind, 2, action, status)
    assert system.trace[-1][0] == call  # nothing is called after the failing call
    # the rows kept are recorded; nothing is written past the failing row (a read that fills its record columns
    # itself may have written into the failing row, which the master does not keep)
    assert (system.record[:rows_recorded] != -1).all() and (system.record[3:] == -1).all()
    if call != "getB":
        assert (system.record[rows_recorded:] == -1).all()


@pytest.mark.parametrize("call", ["getA", "setB", "getB", "stepA", "stepB"])
def test_a_warning_does_not_stop_the_loop(call):
    system = FakeSystem(2, rows=4, fail=(call, 1, 1))
    assert system.run(0, 4).outcome == LoopOutcome.DONE
    assert len(system.trace) == 4 * 5


@pytest.mark.parametrize("value", [float("nan"), float("inf"), 10.0, -10.0])
def test_a_value_beyond_its_bound_never_reaches_the_input(value):
    system = FakeSystem(2, rows=6, a1_override=(3, value), bound=10.0)
    outcome = system.run(0, 6)
    assert (outcome.outcome, outcome.row, outcome.index, outcome.copy) == (LoopOutcome.WRITE_DIVERGED, 3, 1, 0)
    assert outcome.value == value or (math.isnan(value) and math.isnan(outcome.value))
    assert system.trace[-1] == ("getA", [7, 8])  # setB was not called with it
    assert all(entry[1] == entry[1] and abs(entry[1]) < 10 for entry in system.trace if entry[0] == "setB")


def test_every_input_of_a_write_is_checked_against_its_own_bound():
    # B's second input (A.a0 = row + 0.25) has bound 3.5: row 4 (4.25) stops; the first input's bound is 1e6
    system = FakeSystem(2, rows=8, bound2=3.5)
    outcome = system.run(0, 8)
    assert (outcome.outcome, outcome.row, outcome.index, outcome.copy, outcome.value) == (
        LoopOutcome.WRITE_DIVERGED, 3 + 1, 1, 1, 4.25)


def test_a_recorded_value_beyond_its_bound_stops_at_the_end_of_its_check_block():
    # a0 = row + 0.25 passes 5 at row 5; with blocks of 4 rows the check at the end of rows 4..7 finds it
    system = FakeSystem(2, rows=10, record_bounds=(1e6, 5.0))
    outcome = system.run(0, 10, check_every=4)
    assert (outcome.outcome, outcome.row) == (LoopOutcome.RECORD_DIVERGED, 7)
    assert [entry[0] for entry in system.trace[-3:]] == ["getA", "setB", "getB"]  # row 7 not stepped


@pytest.mark.parametrize("row, stop_row", [(3, 3), (4, 7), (7, 7), (8, None)])
def test_every_row_of_a_check_block_is_checked(row, stop_row):
    system = FakeSystem(2, rows=9, record_bounds=(1e6, 50.0), a0_override=(row, 1e300), bound2=float("inf"))
    outcome = system.run(0, 9, check_every=4)
    if stop_row is None:  # row 8 starts a block that has not ended
        assert outcome.outcome == LoopOutcome.DONE
    else:
        assert (outcome.outcome, outcome.row) == (LoopOutcome.RECORD_DIVERGED, stop_row)


@pytest.mark.parametrize("split", [1, 2, 3])
def test_a_block_begun_by_an_earlier_call_is_checked_whole(split):
    """Row 1 is beyond its bound; the block 0 .. 3 ends in the second call, which stops at its end."""
    system = FakeSystem(2, rows=9, record_bounds=(1e6, 50.0), a0_override=(1, 1e300), bound2=float("inf"))
    assert system.run(0, split, check_every=4).outcome == LoopOutcome.DONE
    outcome = system.run(split, 9, check_every=4)
    assert (outcome.outcome, outcome.row) == (LoopOutcome.RECORD_DIVERGED, 3)


def test_blocks_continue_where_the_last_one_ended():
    whole, parts = FakeSystem(2, rows=7), FakeSystem(2, rows=7)
    assert whole.run(0, 7).outcome == LoopOutcome.DONE
    for first, last in ((0, 3), (3, 4), (4, 7)):
        assert parts.run(first, last).outcome == LoopOutcome.DONE
    assert parts.trace == whole.trace
    assert np.array_equal(parts.record, whole.record)


# ------------------------------------------------------- the whole master, either loop
@pytest.fixture(scope="module")
def native_fmus():
    return {name: paths[2] for name, paths in build_native.ensure_built().items()}


@pytest.fixture(scope="module")
def native3_fmus():
    return {name: paths[3] for name, paths in build_native.ensure_built().items()}


def _both_loops(scenario, algorithm, fmu_paths):
    outcomes = {}
    for loop in ("python", "c"):
        master = Master(scenario, algorithm, fmu_paths, loop=loop)
        try:
            outcomes[loop] = ("ok", master.run(), None)
        except SimulationFailed as failure:
            outcomes[loop] = ("failed", failure.result, str(failure))
        outcomes[loop] += (master.logs,)
    return outcomes["python"], outcomes["c"]


def _assert_same(python, compiled):
    assert python[0] == compiled[0]
    assert python[2] == compiled[2]  # the same error text
    assert python[1].rows == compiled[1].rows
    assert np.array_equal(python[1].values, compiled[1].values, equal_nan=True)
    assert python[3] == compiled[3]  # the same FMU messages


@pytest.mark.parametrize("algorithm", ["feedthrough", "jacobi"])
@pytest.mark.parametrize("name", ["pendulum_case1", "pendulum_case3", "manipulator", "motor_arm"])
def test_native_fmus_give_bit_identical_runs_with_either_loop(native_fmus, name, algorithm):
    scenario = scenarios.configure(name, "fae" if name == "pendulum_case3" else "vud", None, 0.3)
    python, compiled = _both_loops(scenario, algorithm, native_fmus)
    assert python[0] == "ok"
    _assert_same(python, compiled)


def test_fmi3_fmus_give_bit_identical_runs_with_either_loop(native3_fmus):
    python, compiled = _both_loops(scenarios.configure("pendulum_case2", "vud", None, 0.3), "feedthrough",
                                   native3_fmus)
    assert python[0] == "ok"
    _assert_same(python, compiled)


def test_pythonfmu_fmus_give_bit_identical_runs_with_either_loop(fmu_paths):
    python, compiled = _both_loops(scenarios.configure("pendulum_case1", "fixed", None, 0.1), "jacobi", fmu_paths)
    assert python[0] == "ok"
    _assert_same(python, compiled)


def _failing(kind: str):
    base = scenarios.configure("pendulum_case1", "vud", None, 1.0)
    if kind == "write":  # u beyond its bound on its way to the plant
        return dataclasses.replace(base, bounds={**base.bounds, "controller.u": 3.0})
    if kind == "record":  # theta1 (recorded, not connected) beyond its bound
        return dataclasses.replace(base, bounds={**base.bounds, "controller.theta1": 0.05})
    if kind == "third input":  # ym, the third of the controller's four inputs, beyond its own bound
        return dataclasses.replace(base, bounds={**base.bounds, "reference.ym": 0.2})
    # the plant's doStep fails: a learning rate that throws the loop out at once, no bounds to stop it first
    inf = float("inf")
    return dataclasses.replace(base.with_parameter("controller.gamma", 1e300), divergence_bound=inf,
                               bounds={"plant.y": inf, "controller.u": inf})


@pytest.mark.parametrize("kind, message, rows", [
    ("write", "controller.u = -3.0857 beyond its bound 3 (on its way to plant.u)", 74),
    ("record", "controller.theta1 = -0.0554221 beyond its bound 0.05;", 64),
    ("third input", "reference.ym = 0.200034 beyond its bound 0.2 (on its way to controller.ym)", 784),
    ("step", "plant: fmi2DoStep returned error at t = 0.001", 3)])
def test_a_failing_run_fails_alike_with_either_loop(native_fmus, kind, message, rows):
    python, compiled = _both_loops(_failing(kind), "feedthrough", native_fmus)
    assert python[0] == "failed" and python[1].rows == rows and message in python[2], python[2]
    _assert_same(python, compiled)


def test_an_fmi3_failure_names_the_fmi3_function(native3_fmus):
    python, compiled = _both_loops(_failing("step"), "feedthrough", native3_fmus)
    assert python[0] == "failed" and "plant: fmi3DoStep returned error at t = 0.001" in python[2], python[2]
    _assert_same(python, compiled)


class _FailingComponent:
    """Stands for a Component in _raise_stop: records how it is failed."""

    def __init__(self, name):
        self.name, self.failed = name, None

    def fail(self, function, status, time):
        self.failed = (function, status, time)
        raise RuntimeError(f"{self.name}: {function}")


@pytest.mark.parametrize("kind, function, rows_kept", [
    (LoopOutcome.READ_FAILED, "fmi2GetReal", 5), (LoopOutcome.WRITE_FAILED, "fmi2SetReal", 5),
    (LoopOutcome.STEP_FAILED, "fmi2DoStep", 6)])
def test_what_stops_the_compiled_loop_is_raised_as_the_python_loop_raises_it(kind, function, rows_kept):
    scenario = scenarios.configure("pendulum_case1", "vud", None, 0.01)
    master = Master(scenario, loop="python")
    plan = [dataclasses.make_dataclass("Action", ["component"])(_FailingComponent(f"action{i}")) for i in range(3)]
    components = [_FailingComponent(f"stepper{i}") for i in range(3)]
    outcome = Outcome(outcome=kind, status=2, row=5, index=1)
    with pytest.raises(RuntimeError):
        master._raise_stop(outcome, plan, components, record=None)
    failed = components[1] if kind == LoopOutcome.STEP_FAILED else plan[1].component
    assert failed.failed == (function, 2, scenario.start + 5 * scenario.step)
    assert master.rows_done == rows_kept  # a failed read or write: row 5 is not recorded; a failed step: it is


@pytest.mark.parametrize("every", [-1, 1.5, True])
def test_a_bad_progress_interval_is_refused_before_anything_runs(every):
    with pytest.raises(ValueError, match="progress_every = .*: a whole number of steps >= 0"):
        Master(scenarios.configure("pendulum_case1", "vud", None, 0.01), loop="c").run(progress_every=every)


def test_auto_falls_back_to_the_python_loop_when_the_library_cannot_be_built(monkeypatch, capsys):
    def broken(*args, **kwargs):
        raise c_toolchain.NativeBuildError("compiling master_loop failed:\nerror: no space left")

    monkeypatch.setattr(master_loop.LIBRARY, "loaded", None)
    monkeypatch.setattr(master_loop.LIBRARY, "unavailable", None)
    monkeypatch.setattr(c_toolchain, "host_library", broken)
    monkeypatch.delenv(compiled_loop.ENVIRONMENT_SWITCH, raising=False)
    assert master_loop.library() is None
    assert capsys.readouterr().err == ("warning: the master runs its Python loop: the compiled loop master_loop.c "
                                       "cannot be built or loaded: compiling master_loop failed:\n")
    assert master_loop.library() is None and capsys.readouterr().err == ""  # said once
    with pytest.raises(compiled_loop.LoopUnavailable, match="AFC_MASTER_LOOP=c: the compiled loop master_loop.c"):
        master_loop.library("c")


def test_the_loop_can_be_chosen(monkeypatch):
    scenario = scenarios.configure("pendulum_case1", "vud", None, 0.01)
    monkeypatch.setenv(compiled_loop.ENVIRONMENT_SWITCH, "python")
    assert master_loop.library() is None
    assert Master(scenario, loop="c").loop == "c"  # the argument wins over the environment
    monkeypatch.setenv(compiled_loop.ENVIRONMENT_SWITCH, "fast")
    with pytest.raises(compiled_loop.LoopUnavailable, match="AFC_MASTER_LOOP='fast' is not valid; valid: auto, python, c"):
        master_loop.library()
    with pytest.raises(ValueError, match="valid: auto, python, c"):
        Master(scenario, loop="cython")


def test_progress_is_reported_at_the_same_rows_with_either_loop(native_fmus):
    scenario = scenarios.configure("pendulum_case1", "vud", None, 0.1)  # 200 steps
    calls = {}
    for loop in ("python", "c"):
        calls[loop] = []
        Master(scenario, "feedthrough", native_fmus, loop=loop).run(
            progress=lambda done, total, seen=calls[loop]: seen.append((done, total)), progress_every=30)
    assert calls["python"] == calls["c"]
    assert calls["c"][:2] == [(30, 200), (60, 200)] and calls["c"][-1] == (200, 200)


def _counted_blocks(monkeypatch) -> list:
    """The (first_row, last_row) of every call of the compiled loop from now on."""
    blocks = []
    run = master_loop.CompiledLoop.run

    def counted(self, start, step, first_row, last_row, steps=-1):
        blocks.append((first_row, last_row))
        return run(self, start, step, first_row, last_row, steps)

    monkeypatch.setattr(master_loop.CompiledLoop, "run", counted)
    return blocks


def test_a_run_no_one_follows_is_one_call_of_the_compiled_loop(native_fmus, monkeypatch):
    """No Python between blocks: without a progress callback the C loop runs every row (and checks every
    bound) in one call."""
    blocks = _counted_blocks(monkeypatch)
    scenario = scenarios.configure("pendulum_case1", "vud", None, 1.0)  # 2000 steps
    result = Master(scenario, "feedthrough", native_fmus, loop="c").run()
    assert blocks == [(0, 2000)] and result.complete and result.rows == 2001


def test_a_short_followed_run_is_one_block_with_its_progress_at_the_end(native_fmus, monkeypatch):
    """A run the progress display follows but that is shorter than the first block (a cold `run --stop 2` on
    the native FMUs: 4000 rows) makes one call of the C loop, and the only progress call is Master.run's at
    the end: no Python inside the timed loop."""
    blocks = _counted_blocks(monkeypatch)
    calls = []
    scenario = scenarios.configure("pendulum_case1", "vud", None, 2.0)  # 4000 steps
    assert scenario.steps <= master_module.FIRST_PROGRESS_BLOCK
    Master(scenario, "feedthrough", native_fmus, loop="c").run(progress=lambda done, total: calls.append(done))
    assert blocks == [(0, 4000)] and calls == [4000]


def test_followed_progress_comes_in_blocks_of_wall_time(native_fmus, monkeypatch):
    """With a callback and no progress_every, the first block has FIRST_PROGRESS_BLOCK rows and the next ones
    last about PROGRESS_BLOCK_S each, sized from the rate so far; a progress call between two blocks but after
    the first (which sizes the next), and Master.run's own at the end."""
    blocks = _counted_blocks(monkeypatch)
    monkeypatch.setattr(master_module, "FIRST_PROGRESS_BLOCK", 100)
    monkeypatch.setattr(master_module, "PROGRESS_BLOCK_S", 0.004)  # a few ms: several blocks in a short run
    calls = []
    scenario = scenarios.configure("pendulum_case1", "vud", None, 5.0)  # 10000 steps
    Master(scenario, "feedthrough", native_fmus, loop="c").run(progress=lambda done, total: calls.append(done))
    assert blocks[0] == (0, 100) and blocks[-1][1] == 10000 and 3 <= len(blocks) < 200
    assert all(first == previous_last for (first, _), (_, previous_last) in zip(blocks[1:], blocks))
    assert max(last - first for first, last in blocks[1:-1]) > 100  # sized from the rate, not by a fixed count
    assert calls == [last for _, last in blocks[1:-1]] + [10000]  # and Master.run's own final call
