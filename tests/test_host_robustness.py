"""The controller FMU in hosts other than our master (docs/host_robustness.md).

A plain fmpy host (harness/hosts/plain_fmpy.py, the host matrix's fmpy-jacobi and fmpy-gs-*: no
initial-value propagation, Jacobi or Gauss-Seidel in any order) must give the scores of our
master's converged run within 1 %, with one Warning naming the re-latch; our master (which
propagates initial values) must give no warning; u chatter at a step too large for Jacobi must
give one Warning, converged runs none.  Horizons are short (2 s or less, the transient the
initial error shapes) to keep CI fast.
"""
import itertools

import pytest

from fmu_src import chatter_monitor
from harness import fmi
from harness import scenario as scenarios
from harness.hosts import plain_fmpy
from harness.master import simulate
from harness.scores import score_run
from tests.fmu_helpers import Driven

WARNING = 1  # fmi2Warning
HORIZON = 2.0  # s, pendulum plain-host runs
MANIPULATOR_HORIZON = 1.0  # s
ACCURACY = 0.01  # ITAE, IAE, Ec within 1 % of the converged run over the same horizon
SCORES = ("ITAE", "IAE", "Ec")


@pytest.fixture(scope="module")
def converged():
    """Our master, feedthrough, at the step validated for Jacobi (finer than the scenarios')."""
    runs = {}
    for name, step, stop in (("pendulum_case1", 1e-4, HORIZON), ("manipulator", 2.5e-5, MANIPULATOR_HORIZON)):
        scenario = scenarios.configure(name, "vud", step, stop)
        runs[name] = score_run(simulate(scenario))
    return runs


def warnings_of(messages, instance="controller"):
    return [text for status, text in messages[instance] if status == WARNING]


def assert_close(scores, reference):
    for key in SCORES:
        assert abs(scores[key] / reference[key] - 1) < ACCURACY, (key, scores[key], reference[key])


def plain_run(fmu_paths, name, order=None, step=1e-4, stop=HORIZON, **controller):
    """The plain fmpy host: Jacobi (``order`` None) or Gauss-Seidel in ``order``; its scores and
    {instance: [(status, message), ...]}."""
    scenario = scenarios.configure(name, "vud", step, stop)
    scenario.components["controller"].parameters.update(controller)
    trajectory, messages = plain_fmpy.run(scenario, fmu_paths, order)
    return {"scores": trajectory.scores(),
            "messages": {n: [(status, text) for i, status, text in messages if i == n] for n in scenario.components}}


def test_plain_jacobi_without_propagation_gets_the_converged_result(fmu_paths, converged):
    run = plain_run(fmu_paths, "pendulum_case1")
    assert_close(run["scores"], converged["pendulum_case1"])
    (warning,) = warnings_of(run["messages"])
    assert "re-latched" in warning and "rejected e = 0, de = 0 at t = 0 " in warning
    assert "at t = 0.0001 as e(0)" in warning  # Jacobi: the first true sample is one step late
    assert all(not warnings_of(run["messages"], other) for other in ("plant", "reference"))


@pytest.mark.parametrize("order", list(itertools.permutations(("controller", "plant", "reference"))))
def test_plain_gauss_seidel_in_every_order_gets_the_converged_result(fmu_paths, converged, order):
    run = plain_run(fmu_paths, "pendulum_case1", order)
    assert_close(run["scores"], converged["pendulum_case1"])
    (warning,) = warnings_of(run["messages"])
    assert "rejected e = 0, de = 0 at t = 0 " in warning


def test_plain_jacobi_manipulator_gets_the_converged_result(fmu_paths, converged):
    run = plain_run(fmu_paths, "manipulator", step=2.5e-5, stop=MANIPULATOR_HORIZON)
    assert_close(run["scores"], converged["manipulator"])
    assert len(warnings_of(run["messages"])) == 1


def test_pinned_initial_error_is_used_without_warning(fmu_paths, converged):
    scenario = scenarios.configure("pendulum_case1", "vud")
    x1 = scenario.components["plant"].parameters["x1_start"]
    amplitude = scenario.components["reference"].parameters["amplitude"]
    run = plain_run(fmu_paths, "pendulum_case1", initial_error=2, e0=-x1, de0=amplitude)
    assert_close(run["scores"], converged["pendulum_case1"])
    assert warnings_of(run["messages"]) == []


def test_pinned_e0_de0_set_the_modified_error(fmu_paths):
    c = Driven(fmu_paths["AdaptiveFuzzyController"]).initialize(initial_error=2, e0=0.1, de0=-0.2, e=0.5, de=0.3)
    assert c.get("E", "dE") == [pytest.approx(0.4, abs=1e-15), pytest.approx(0.5, abs=1e-15)]
    for k in range(20):  # inputs inconsistent with their derivatives: pinned, so nothing moves
        c.set(e=(-1) ** k, de=0.0)
        c.slave.doStep(k * 1e-3, 1e-3)
    assert c.messages == []
    c.free()


def smooth_inputs(t):
    return dict(e=0.3 - 0.5 * t, de=-0.5, ym=0.0, dym=0.0)


def test_reference_jump_after_the_start_does_not_relatch(fmu_paths):
    from fmu_src import afc_math

    h = 1e-3
    c = Driven(fmu_paths["AdaptiveFuzzyController"]).initialize(**smooth_inputs(0.0))
    for k in range(30):
        c.set(**smooth_inputs(k * h))
        c.slave.doStep(k * h, h)
    t = 30 * h
    c.set(e=1.2, de=4.0)  # the reference jumps at t > 0
    expected = afc_math.modified_error((1.2, 4.0), t, (0.3, -0.5), 0.0, 5.0)
    assert c.get("E", "dE") == [pytest.approx(v, abs=1e-14) for v in expected]
    for k in range(30, 60):
        c.slave.doStep(k * h, h)
        c.set(e=1.2 + 0.01 * (k % 2), de=0.0)
    c.set(e=1.2, de=4.0)
    expected = afc_math.modified_error((1.2, 4.0), 60 * h, (0.3, -0.5), 0.0, 5.0)  # still the latch of t = 0
    assert c.get("E", "dE") == [pytest.approx(v, abs=1e-14) for v in expected]
    assert c.messages == []
    c.free()


def test_relatch_restarts_adaptation_and_moves_the_time_origin(fmu_paths):
    from fmu_src import afc_math

    h, theta0 = 1e-3, 0.7
    c = Driven(fmu_paths["AdaptiveFuzzyController"]).initialize(theta0=theta0, e=0.1, de=0.0)
    for k in range(3):  # the placeholders (user guesses) stay while a deep chain fills: E moves
        c.slave.doStep(k * h, h)
    assert c.get("theta1") != theta0  # the adaptation ran on the guessed latch
    t2, true = 3 * h, dict(e=-0.26, de=0.52)
    c.set(**true)
    c.slave.doStep(t2, h)  # inconsistent with the guesses: re-latch at t2, adaptation restarted
    # E(t2) = dE(t2) = 0 at the new latch, so the step from t2 leaves theta at theta0
    assert c.get("theta1", "theta2", "theta3", "theta4") == [theta0] * 4
    t3, later = 4 * h, dict(e=-0.26 + 0.52 * h, de=0.52)
    c.set(**later)
    expected = afc_math.modified_error((later["e"], later["de"]), t3, (true["e"], true["de"]), t2, 5.0)
    assert c.get("E", "dE") == [pytest.approx(v, rel=1e-12) for v in expected]
    c.slave.doStep(t3, h)  # a consistent pair: decided, one warning naming both latches
    (warning,) = warnings_of({"c": c.messages}, "c")
    assert "rejected e = 0.1, de = 0 at t = 0 " in warning and "kept e = -0.26, de = 0.52 at t = 0.003 " in warning
    c.free()


def drive_window(c, first, count, h=1e-4):
    """Steps of a Jacobi-like start: placeholders, then a smooth error; outputs read each step."""
    record = []
    for k in range(first, first + count):
        t = k * h
        inputs = dict(e=0.0, de=0.52) if k == 0 else dict(e=-0.26 + 0.52 * t, de=0.52)
        c.set(**inputs)
        record.append(tuple(c.get("u", "E", "dE", "theta1")))
        c.slave.doStep(t, h)
    return record + [tuple(c.get("theta1", "theta2", "theta3", "theta4", "w_hat"))]


def test_state_in_the_middle_of_the_latch_window_is_exact(fmu_paths):
    c = Driven(fmu_paths["AdaptiveFuzzyController"]).initialize()  # placeholders e = de = 0
    drive_window(c, 0, 1)  # re-latched at t = 0, not decided yet
    state = c.slave.getFMUstate()
    first, messages = drive_window(c, 1, 20), list(c.messages)
    assert len(warnings_of({"c": messages}, "c")) == 1
    c.slave.setFMUstate(state)
    c.messages.clear()
    assert drive_window(c, 1, 20) == first and c.messages == messages  # decided again, warned again
    serialized = c.slave.serializeFMUstate(state)
    c.slave.freeFMUstate(state)
    fresh = Driven(fmu_paths["AdaptiveFuzzyController"], "fresh", unzip_dir=c.unzip_dir).initialize()
    fresh.slave.setFMUstate(fresh.slave.deSerializeFMUstate(serialized))
    assert drive_window(fresh, 1, 20) == first
    fresh.free()
    c.free()


def test_reading_outputs_in_the_window_changes_nothing(fmu_paths):
    reading = Driven(fmu_paths["AdaptiveFuzzyController"], "reading").initialize()
    quiet = Driven(fmu_paths["AdaptiveFuzzyController"], "quiet", unzip_dir=reading.unzip_dir).initialize()
    h = 1e-4
    for k in range(20):
        inputs = dict(e=0.0, de=0.52) if k == 0 else dict(e=-0.26 + 0.52 * k * h, de=0.52)
        reading.set(**inputs)
        for _ in range(3):
            reading.get("u", "E", "dE", "alpha1")
        reading.slave.doStep(k * h, h)
        quiet.set(**inputs)
        quiet.slave.doStep(k * h, h)
    names = ("theta1", "theta2", "theta3", "theta4", "u", "E")
    assert reading.get(*names) == quiet.get(*names)
    without_name = [[(status, text.split(": ", 1)[1]) for status, text in unit.messages] for unit in (reading, quiet)]
    assert without_name[0] == without_name[1] and len(quiet.messages) == 1
    reading.free()
    quiet.free()


def test_warnings_need_logging_on_under_pythonfmu(fmu_paths):
    """pythonfmu 0.7 forwards every message only while debug logging is on (docs/host_robustness.md)."""
    silent = Driven(fmu_paths["AdaptiveFuzzyController"], logging_on=False).initialize()
    drive_window(silent, 0, 5)
    assert silent.messages == []  # the re-latch warning was dropped by pythonfmu's C wrapper
    silent.free()
    late = Driven(fmu_paths["AdaptiveFuzzyController"], "late", logging_on=False).initialize()
    late.slave.setDebugLogging(True, [])  # fmi2SetDebugLogging(loggingOn = true, no category filter)
    drive_window(late, 0, 5)
    assert len(warnings_of({"c": late.messages}, "c")) == 1
    late.free()


@pytest.fixture
def master_logs(monkeypatch):
    """Every FMU log line of our master's runs (the master frees its components at the end)."""
    logs = []
    free = fmi.Component.free

    def keep_log_then_free(component):
        logs.extend((component.name, line) for line in component.log)
        free(component)

    monkeypatch.setattr(fmi.Component, "free", keep_log_then_free)
    return logs


CONVERGED_RUNS = [(name, controller, algorithm, step)
                  for name in ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator")
                  for controller in ("vud", "fixed", "fae")
                  for algorithm, step in (("feedthrough", None),
                                          ("jacobi", 2.5e-5 if name == "manipulator" else 1e-4))]


def test_no_warning_in_our_masters_converged_runs(fmu_paths, master_logs):
    """All 12 cases at their chosen steps (feedthrough) and at the validated Jacobi steps.

    1.5 s: past the warm-up of the chatter monitor, where the converged runs' statistic peaks
    (docs/host_robustness.md); the initial-error latch decides in the first doSteps.
    """
    for name, controller, algorithm, step in CONVERGED_RUNS:
        scenario = scenarios.configure(name, controller, step, 1.5)
        assert simulate(scenario, algorithm, fmu_paths).complete
    assert master_logs == []  # no warning (nor any other message)


@pytest.mark.parametrize("step,stop", [(4e-4, 6.0), (2e-4, 18.5)])
def test_chatter_in_jacobi_warns_once(fmu_paths, master_logs, step, stop):
    """pendulum case 1 vud in Jacobi: the horizons reach past the onset of chatter at each step
    (docs/host_robustness.md gives when it sets in)."""
    simulate(scenarios.configure("pendulum_case1", "vud", step, stop), "jacobi", fmu_paths)
    warnings = [line for name, line in master_logs if line.startswith("[WARNING]") and "chatters" in line]
    assert len(warnings) == 1
    assert f"communication step {step:g} s" in warnings[0]
    for validated in chatter_monitor.JACOBI_VALIDATED_STEP.values():
        assert f"{validated:g} s" in warnings[0]
    assert len(master_logs) == 1  # no initial-error warning: our master propagates initial values

