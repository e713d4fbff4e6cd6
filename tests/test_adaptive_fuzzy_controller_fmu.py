"""The controller FMU: validation, fmpy CLI, feedthrough, state, bad input."""
import math
import subprocess
import sys

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from fmu_src import afc_math
from harness.fmu_build import builder as build_fmu
from harness import variants
from tests.fmu_helpers import Driven

PARAMETERS = {v.name: v.start for v in build_fmu.model_class("AdaptiveFuzzyController").VARIABLES if v.causality == "parameter"}


@pytest.fixture(scope="module")
def controller_fmu(fmu_paths):
    return fmu_paths["AdaptiveFuzzyController"]


def test_fmpy_validate_finds_no_problem(controller_fmu):
    assert validate_fmu(str(controller_fmu)) == []
    result = subprocess.run([sys.executable, "-m", "fmpy.cli", "validate", str(controller_fmu)],
                            capture_output=True, text=True)
    assert "No problems found" in result.stdout, result.stdout + result.stderr


def test_model_structure_declares_true_dependencies(controller_fmu):
    from fmpy import read_model_description
    md = read_model_description(str(controller_fmu))
    deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}
    assert deps["u"] == ["d2e", "d2ym", "d3e", "d3ym", "de", "dym", "e", "ym"]
    assert deps["E"] == ["de", "e"]
    assert deps["theta1"] == [] and deps["w_hat"] == []
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


def replay(inputs, grid, variant, parameters):
    """The pure math in fmpy simulate's sequence: inputs applied at t_n, doStep, sample at t_n+1."""
    p = afc_math.controller_parameters(dict(parameters, variant=variant), inputs[0][:2], 0.0)
    theta, w_hat = [parameters["theta0"]] * 4, 0.0
    out = [afc_math.controller_output(inputs[0][:2], inputs[0][2:], 0.0, theta, w_hat, p)[0]]
    for n in range(len(grid) - 1):
        h = grid[n + 1] - grid[n]
        _, modified, _, xi = afc_math.controller_output(inputs[n][:2], inputs[n][2:], grid[n], theta, w_hat, p)
        tau = afc_math.adaptation_signal(modified, p["p_b"])
        for j in range(4):
            theta[j] += h * afc_math.projected_rate(theta[j], tau, xi[j], p["gamma"], p["m_theta"], p["delta"])
        if variant == 3:
            w_hat += h * p["gamma_w"] * tau
        out.append(afc_math.controller_output(inputs[n][:2], inputs[n][2:], grid[n + 1], theta, w_hat, p)[0])
    return np.array(out)


@pytest.mark.parametrize("variant", [1, 2, 3])
def test_fmpy_command_line_matches_the_pure_math(controller_fmu, tmp_path, variant):
    grid = np.arange(201) * 0.01  # fmpy: t_n = start + n * interval
    e = 0.3 * np.cos(1.7 * grid) + 0.1 * np.sin(5 * grid)
    de = -0.51 * np.sin(1.7 * grid) + 0.5 * np.cos(5 * grid)
    ym, dym = math.pi / 6 * np.sin(grid), math.pi / 6 * np.cos(grid)
    table = np.column_stack([grid, e, de, ym, dym])
    np.savetxt(tmp_path / "in.csv", table, delimiter=",", header="time,e,de,ym,dym", comments="", fmt="%.17g")
    out = tmp_path / "out.csv"
    subprocess.run([sys.executable, "-m", "fmpy.cli", "simulate", str(controller_fmu),
                    "--input-file", str(tmp_path / "in.csv"), "--output-interval", "0.01",
                    "--stop-time", "2", "--start-values", "variant", str(variant),
                    "--output-variables", "u", "--output-file", str(out)], check=True, capture_output=True)
    result = np.genfromtxt(out, delimiter=",", names=True)
    assert np.array_equal(result["time"], grid)
    expected = replay([tuple(row[1:]) for row in table], grid, variant, PARAMETERS)
    assert np.max(np.abs(expected)) > 1.0  # the controller did learn something
    assert np.allclose(result["u"], expected, rtol=0, atol=1e-12)


def test_u_is_direct_feedthrough(controller_fmu):
    c = Driven(controller_fmu).initialize(e=0.2, de=0.1)
    c.slave.doStep(0.0, 0.01)
    u_before = c.get("u")
    c.set(e=0.25, de=-0.3)  # no doStep: u must follow the inputs at once
    u_after, error = c.get("u", "E")
    assert u_after != u_before
    assert error == pytest.approx(afc_math.modified_error((0.25, -0.3), 0.01, (0.2, 0.1), 0.0, 5.0)[0], abs=1e-15)
    # reading u has no side effect: reading twice gives the same and the next step is unchanged
    assert c.get("u") == u_after
    c.free()


def test_e0_is_latched_at_end_of_initialisation(controller_fmu):
    c = Driven(controller_fmu).initialize(e=0.4, de=-0.2)
    assert c.get("E", "dE") == [0.0, pytest.approx(0.0, abs=1e-15)]
    c.set(e=0.0, de=0.0)  # a later input does not move the latch
    assert c.get("E") == pytest.approx(-0.4, abs=1e-15)
    c.free()


def run_steps(c, start, count, h=1e-3):
    us = []
    for n in range(count):
        t = start + n * h
        c.set(e=0.3 * math.cos(t), de=-0.3 * math.sin(t), ym=math.sin(t), dym=math.cos(t))
        us.append(c.get("u"))
        c.slave.doStep(t, h)
    return us + [c.get("theta1", "theta2", "theta3", "theta4", "w_hat", "u")]


@pytest.mark.parametrize("variant", [1, 3])
def test_state_round_trip_is_bit_exact(controller_fmu, variant):
    c = Driven(controller_fmu).initialize(variant=variant, e=0.3, de=0.0)
    run_steps(c, 0.0, 300)
    state = c.slave.getFMUstate()
    first = run_steps(c, 0.3, 300)
    c.slave.setFMUstate(state)
    again = run_steps(c, 0.3, 300)
    assert first == again
    serialized = c.slave.serializeFMUstate(state)
    c.slave.freeFMUstate(state)
    fresh = Driven(controller_fmu, "fresh", unzip_dir=c.unzip_dir).initialize(variant=variant)
    fresh.slave.setFMUstate(fresh.slave.deSerializeFMUstate(serialized))
    assert run_steps(fresh, 0.3, 300) == first
    fresh.free()
    c.free()


def test_reset_then_rerun_gives_the_same_result(controller_fmu):
    c = Driven(controller_fmu).initialize(e=0.3)
    first = run_steps(c, 0.0, 200)
    c.slave.reset()
    c.initialize(e=0.3)
    assert run_steps(c, 0.0, 200) == first
    c.free()


NO_VARIANT = max(variants.CONTROLLER_VARIANTS.values()) + 1  # one past the registry's last row: out of range
BAD_PARAMETERS = [
    ("lambda_ce", 0.0), ("lambda_ce", 1.0), ("lambda_ce", 1.5), ("lambda_ce", float("nan")),
    ("kappa1", 0.0), ("kappa2", -1.0), ("gamma", 0.0), ("gamma_w", -3.0), ("delta", 0.0),
    ("m_theta", -1.0), ("mf_slope", 0.0), ("E1", 0.0), ("E2", -1.0), ("q1", 0.0), ("q2", -2.0),
    ("k1", 0.0), ("k2", -1.0), ("lambda_e", -1.0), ("gamma", float("inf")), ("theta0", float("nan")),
    ("variant", 0), ("variant", NO_VARIANT), ("fls_input", 0), ("fls_input", 3),
]


@pytest.mark.parametrize("name,value", BAD_PARAMETERS)
def test_bad_parameter_fails_initialisation_naming_it(controller_fmu, name, value):
    c = Driven(controller_fmu, f"bad_{name}")
    c.slave.setupExperiment(startTime=0.0)
    c.slave.enterInitializationMode()
    with pytest.raises(FMICallException) as raised:
        c.set(**{name: value})  # a non-finite value is refused here already
        c.slave.exitInitializationMode()
    assert raised.value.status >= 3  # fmi2Error or worse (pythonfmu 0.7 reports fmi2Fatal)
    errors = [m for s, m in c.messages if s >= 3]
    assert any(f"parameter {name} = " in m and "valid range" in m for m in errors), errors
    c.slave.freeInstance()  # must not crash the host (pythonfmu 0.7 double release, see afc_slave_base)
    # the host survives and can instantiate again
    Driven(controller_fmu, "after").initialize().free()


@pytest.mark.parametrize("name", ["e", "de", "ym", "dym"])
@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_non_finite_input_is_an_error_never_a_nan_u(controller_fmu, name, value):
    c = Driven(controller_fmu).initialize(e=0.1)
    c.slave.doStep(0.0, 0.01)
    with pytest.raises(FMICallException) as raised:
        c.set(**{name: value})
    assert raised.value.status >= 3
    assert any(f"input {name} = " in m and "not finite" in m for s, m in c.messages if s >= 3)
    c.slave.freeInstance()


def test_two_instances_are_independent(controller_fmu):
    a = Driven(controller_fmu, "a").initialize(e=0.3)
    b = Driven(controller_fmu, "b", unzip_dir=a.unzip_dir).initialize(e=-0.1, variant=2)
    run_steps(a, 0.0, 100)
    alone = Driven(controller_fmu, "alone", unzip_dir=a.unzip_dir).initialize(e=-0.1, variant=2)
    assert run_steps(b, 0.0, 100) == run_steps(alone, 0.0, 100)
    for c in (a, b, alone):
        c.free()
