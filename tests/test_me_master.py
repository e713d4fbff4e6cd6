"""The Model Exchange master (harness/me_master.py, harness/me_loop.c, harness/cvode.py).

1. Its Python loop and its compiled loop give bit-identical records and statistics, events included,
   and the same failure (text and rows kept) when a value leaves its bound.
2. The manipulator's friction events: the stuck mode holds the link at exactly dy = 0 (the state reset
   of the event update reaches the integrator), and it breaks away again; events are counted.
3. Accuracy: on a short horizon the Model Exchange run agrees with the co-simulation extrapolated to a
   zero step (Richardson of our feedthrough master), far inside what the step leaves.
4. Bad input: the pythonfmu edition (co-simulation only) and bad tolerances are one line, exit 2; an
   integration CVODE cannot carry out stops with the rows so far and CVODE's own reason.
"""
from __future__ import annotations

import numpy as np
import pytest

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness import cli, cvode
from harness import scenario as scenarios
from harness.cases import Case, run_case
from harness.master import SimulationFailed
from harness.me_master import ModelExchangeMaster, check_tolerances
from harness.scenario import ScenarioError

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")


@pytest.fixture(scope="module")
def native():
    return build_fmu.ensure_built(edition="native")


@pytest.fixture(scope="module")
def native3():
    return build_fmu.ensure_built(edition="native3")


def run(name, native, stop, loop="auto", rtol=1e-8, controller="vud", edit=None, **kwargs):
    scenario = scenarios.configure(name, controller, None, stop)
    if edit:
        edit(scenario)
    return ModelExchangeMaster(scenario, native, rtol=rtol, loop=loop, **kwargs).run()


# ------------------------------------------------------------- the two loops
@pytest.mark.parametrize("name, stop", [("pendulum_case2", 1.0), ("manipulator", 3.0)])
def test_python_and_compiled_loops_are_bit_identical(native, name, stop):
    python = run(name, native, stop, loop="python")
    compiled = run(name, native, stop, loop="c")
    assert python.rows == compiled.rows == scenarios.configure(name, "vud", None, stop).steps + 1
    assert np.array_equal(python.values, compiled.values)
    assert {k: v for k, v in python.solver.items() if k != "loop"} == \
        {k: v for k, v in compiled.solver.items() if k != "loop"}
    assert (python.solver["loop"], compiled.solver["loop"]) == ("python", "compiled")
    if name == "manipulator":
        assert compiled.solver["state_events"] >= 2


def test_fmi3_gives_the_fmi2_trajectory(native, native3):
    """The same C model functions behind both versions: the same run to the last bit."""
    two, three = run("manipulator", native, 2.0), run("manipulator", native3, 2.0)
    assert np.array_equal(two.values, three.values)
    assert two.solver == three.solver


@pytest.mark.parametrize("loop", ["python", "c"])
def test_a_value_beyond_its_bound_stops_both_loops_alike(native, loop):
    def tight(scenario):
        scenario.bounds["controller.u"] = 2.0  # u passes 2 N.m within the first second

    with pytest.raises(SimulationFailed) as failure:
        run("pendulum_case1", native, 1.0, loop=loop, edit=tight)
    assert "diverged at t = " in str(failure.value) and "controller.u" in str(failure.value)
    assert 0 < failure.value.result.rows < 2001
    assert np.all(np.abs(failure.value.result.signal("controller.u")) < 2.0)
    if loop == "c":
        with pytest.raises(SimulationFailed) as python:
            run("pendulum_case1", native, 1.0, loop="python", edit=tight)
        assert str(python.value) == str(failure.value)
        assert python.value.result.rows == failure.value.result.rows
        assert np.array_equal(python.value.result.values, failure.value.result.values)


@pytest.mark.parametrize("loop", ["python", "c"])
def test_the_model_exchange_master_runs_the_masters_life_cycle(native, loop):
    """ModelExchangeMaster has no run of its own: Master.run with its steps specialised, its progress in
    rows; and it is built by Master.__init__ (an unknown parameter is the scenario check's error)."""
    assert "run" not in vars(ModelExchangeMaster) and "__init__" in vars(ModelExchangeMaster)
    scenario = scenarios.configure("pendulum_case1", "vud", None, 0.05)
    with pytest.raises(ValueError, match=r"progress_every = -1: a whole number of rows >= 0 \(0: rows // 200\)"):
        ModelExchangeMaster(scenario, native, loop=loop).run(progress_every=-1)
    calls = []
    result = ModelExchangeMaster(scenario, native, rtol=1e-8, loop=loop).run(
        progress=lambda done, total: calls.append((done, total)), progress_every=40)
    assert calls[-1] == (100, 100) and {total for _, total in calls} == {100}  # the steps, in rows - 1
    assert result.rows == 101 and result.complete
    with pytest.raises(ScenarioError, match=r"has no parameter 'gama' \(did you mean 'gamma'\?\)"):
        ModelExchangeMaster(scenario.with_parameter("controller.gama", 1.0), native, loop=loop)


# ------------------------------------------------------------------ events
def test_the_stuck_link_rests_at_exactly_zero_and_breaks_away(native):
    """At rtol 1e-10 the paper's manipulator (vud) sticks near t = 1.573 s and slips again ~48 ms later
    (docs/model_exchange_accuracy.md); while stuck dy is exactly 0 and so is the friction output d."""
    result = run("manipulator", native, 2.0, rtol=1e-10)
    dy, d, t = result.signal("plant.dy"), result.signal("plant.d"), result.time
    resting = (t > 1.574) & (t < 1.62)
    assert np.all(dy[resting] == 0.0)
    assert np.all(d[resting] == 0.0)
    assert np.all(dy[(t > 1.63) & (t < 2.0)] != 0.0)  # slipping again
    assert result.solver["state_events"] >= 3


# ---------------------------------------------------------------- accuracy
@pytest.mark.parametrize("name, stop", [("pendulum_case1", 2.0), ("manipulator", 2.0)])
def test_agrees_with_the_co_simulation_extrapolated_to_a_zero_step(native, name, stop):
    step = scenarios.load(name).step
    coarse, fine = (run_case(Case(name, "vud", step=h, stop=stop), native) for h in (step / 2, step / 4))
    me = run_case(Case(name, "vud", stop=stop, algorithm="me", rtol=1e-10), native)
    assert me["status"] == "ok" and me["steps"] > 0 and me["derivative_evaluations"] > me["steps"]
    for metric in ("ITAE", "IAE", "Ec"):
        extrapolated = 2 * fine[metric] - coarse[metric]
        step_error = abs(fine[metric] - coarse[metric])
        # closer to the zero-step limit than half of what the finest co-simulation run still misses
        assert abs(me[metric] - extrapolated) < max(0.5 * step_error, 2e-6 * abs(extrapolated)), metric


# -------------------------------------------------------------- bad input
def test_the_pythonfmu_edition_is_one_line_naming_the_fmu(capsys):
    status = cli.main(["run", "pendulum_case1", "--algorithm", "me", "--edition", "python", "--stop", "0.1"])
    error = capsys.readouterr().err.strip()
    assert status == 2 and len(error.splitlines()) == 1
    assert "instance 'plant' (InvertedPendulum.fmu) has no Model Exchange interface" in error
    assert "pythonfmu" in error and "--edition native" in error


@pytest.mark.parametrize("arguments, expected", [
    (["--rtol", "1"], "rtol = 1.0 is invalid; valid: 0 < rtol < 1"),
    (["--rtol=-1e-8"], "argument --rtol: -1e-8 is invalid; give a finite number > 0"),
    (["--atol", "nan"], "argument --atol: 'nan' is not finite"),
])
def test_bad_tolerances_are_one_line(capsys, arguments, expected):
    status = cli.main(["run", "pendulum_case1", "--algorithm", "me", "--edition", "native", "--stop", "0.1",
                       *arguments])
    error = capsys.readouterr().err.strip()
    assert status == 2 and len(error.splitlines()) == 1 and expected in error


def test_tolerances_belong_to_model_exchange(capsys):
    assert cli.main(["run", "pendulum_case1", "--rtol", "1e-8", "--stop", "0.1"]) == 2
    assert "--rtol and --atol are tolerances of --algorithm me" in capsys.readouterr().err
    with pytest.raises(ScenarioError):
        check_tolerances(1e-8, 0.0)


def test_an_integration_cvode_cannot_carry_out_stops_with_its_rows_and_reason(native):
    """A tolerance below what double precision can meet: CVODE refuses the step (CV_TOO_MUCH_ACC)."""
    with pytest.raises(SimulationFailed) as failure:
        run("pendulum_case1", native, 1.0, rtol=1e-300, atol=1e-300)
    text = str(failure.value)
    assert "the integration stopped at t = " in text and "CVODE CV_TOO_MUCH_ACC" in text
    assert failure.value.result.rows >= 1 and failure.value.result.solver["rtol"] == 1e-300


def test_run_reports_the_integrators_work(capsys):
    assert cli.main(["run", "manipulator", "--algorithm", "me", "--edition", "native", "--stop", "2"]) == 0
    out = capsys.readouterr().out
    assert "Model Exchange, CVODE BDF" in out and "steps" in out and "derivative evaluations" in out
    assert "state events" in out and "rows every 5e-05 s" in out


def test_the_flag_names_come_from_cvode():
    assert cvode.flag_name(-2) == "CV_TOO_MUCH_ACC" and cvode.flag_name(2) == "CV_ROOT_RETURN"
