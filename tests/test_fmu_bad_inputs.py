"""Bad parameters and inputs of every FMU (generated from each FMU's declaration table): every
invalid parameter value fails initialisation naming it, its value and its valid range; a non-finite
input at any moment is an error, never a non-finite output; huge finite inputs give finite outputs
or an error.

Extends, without repeating, tests/test_adaptive_fuzzy_controller_fmu.py (hand-picked bad controller
parameters, non-finite controller inputs after one step) and tests/test_plants.py (hand-picked bad
plant parameters).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from tests.fmu_variables import FMI_ERROR, FMU_IDS, VARIABLES, driven, errors, inputs_of, outputs_of


# ------------------------------------------------------ every invalid parameter
def invalid_values(variable) -> list:
    """Values outside a parameter's valid range, derived from its table row alone:
    non-finite values (Real only), each bound itself when it is exclusive, the nearest
    value beyond each bound, and a plainly wrong value (bound -/+ 1)."""
    values = []
    integer = variable.kind == "Integer"
    if not integer:
        values += [math.nan, math.inf, -math.inf]
    low, high = variable.minimum, variable.maximum
    if low is not None:
        if variable.exclusive_minimum:
            values.append(low)  # zero for a positive parameter
        values += [int(low) - 1] if integer else [math.nextafter(low, -math.inf), low - 1.0]
    if high is not None:
        if variable.exclusive_maximum:
            values.append(high)
        values += [int(high) + 1] if integer else [math.nextafter(high, math.inf), high + 1.0]
    unique = []
    for value in values:
        if not any(value == seen or (value != value and seen != seen) for seen in unique):
            unique.append(value)
    return unique


PARAMETER_CASES = [(fmu_id, name, value) for fmu_id in FMU_IDS
                   for name, v in VARIABLES[fmu_id].items() if v.causality == "parameter"
                   for value in invalid_values(v)]


def test_the_generated_cases_cover_every_parameter_of_every_fmu():
    covered = {(fmu_id, name) for fmu_id, name, _ in PARAMETER_CASES}
    every = {(fmu_id, n) for fmu_id in FMU_IDS for n, v in VARIABLES[fmu_id].items() if v.causality == "parameter"}
    assert covered == every
    for fmu_id, name, value in PARAMETER_CASES:
        assert VARIABLES[fmu_id][name].check(value) is not None, (fmu_id, name, value)
    # the cases include zero and negative values wherever the range excludes them
    assert ("AdaptiveFuzzyController", "gamma", 0.0) in PARAMETER_CASES
    assert ("Manipulator", "cr", -1.0) in PARAMETER_CASES
    assert ("AdaptiveFuzzyController", "lambda_ce", 1.0) in PARAMETER_CASES


@pytest.mark.parametrize("fmu_id,name,value", PARAMETER_CASES,
                         ids=[f"{f}-{n}={v!r}" for f, n, v in PARAMETER_CASES])
def test_every_invalid_parameter_fails_initialisation_naming_it_its_value_and_range(
        fmu_paths, unzipped, fmu_id, name, value):
    variable = VARIABLES[fmu_id][name]
    fmu = driven(fmu_paths, unzipped, fmu_id, f"bad_{name}")
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    with pytest.raises(FMICallException) as failure:
        fmu.set(**{name: value})  # non-finite values are refused here already
        fmu.slave.exitInitializationMode()
    assert failure.value.status >= FMI_ERROR
    expected = f"parameter {name} = {value!r} is invalid; valid range: {variable.valid_range()}"
    assert any(expected in m for m in errors(fmu)), (expected, fmu.messages)
    fmu.slave.freeInstance()  # the host survives freeing the failed instance...
    again = driven(fmu_paths, unzipped, fmu_id, "after").initialize()  # ...and instantiates again
    again.slave.doStep(0.0, 1e-3)
    assert np.all(np.isfinite(again.get(*outputs_of(fmu_id))))
    again.free()


# ---------------------------------------------------------- bad inputs, any step
MOMENTS = ("initialisation", "first point", "mid-run")
INPUT_CASES = [(fmu_id, name) for fmu_id in FMU_IDS for name in inputs_of(fmu_id)]
GOOD_INPUTS = {"e": 0.2, "de": -0.1, "ym": 0.3, "dym": 0.5, "u": 1.5, "y": 0.1, "dy": -0.2,
               "d2e": 0.3, "d3e": -0.2, "d2ym": -0.3, "d3ym": -0.5, "d2y": 0.4, "d3y": -0.6}  # order 3, 4


def start_at(fmu_paths, unzipped, fmu_id, moment, steps=50, h=1e-3):
    """An instance at the given moment of a run, with finite inputs set."""
    fmu = driven(fmu_paths, unzipped, fmu_id, f"{fmu_id}_{moment.replace(' ', '_')}")
    inputs = {n: GOOD_INPUTS[n] for n in inputs_of(fmu_id)}
    fmu.slave.setupExperiment(startTime=0.0)
    fmu.slave.enterInitializationMode()
    fmu.set(**inputs)
    if moment == "initialisation":
        return fmu
    fmu.slave.exitInitializationMode()
    if moment == "mid-run":
        for n in range(steps):
            fmu.set(**inputs)
            fmu.slave.doStep(n * h, h)
    return fmu


@pytest.mark.parametrize("moment", MOMENTS)
@pytest.mark.parametrize("fmu_id,name", INPUT_CASES, ids=[f"{f}.{n}" for f, n in INPUT_CASES])
def test_non_finite_input_at_any_moment_is_an_error_never_a_non_finite_output(
        fmu_paths, unzipped, fmu_id, name, moment):
    for value in (math.nan, math.inf, -math.inf):
        fmu = start_at(fmu_paths, unzipped, fmu_id, moment)
        before = fmu.get(*outputs_of(fmu_id))
        with pytest.raises(FMICallException) as failure:
            fmu.set(**{name: value})
        assert failure.value.status >= FMI_ERROR
        assert any(f"input {name} = {value!r} is not finite" in m for m in errors(fmu)), fmu.messages
        # beyond FMI (the instance reported fatal): it still holds the last good input
        assert fmu.get(*outputs_of(fmu_id)) == before
        fmu.slave.freeInstance()


HUGE = (1e308, -1e308, 1e200, 1e155)


@pytest.mark.parametrize("fmu_id,name", INPUT_CASES, ids=[f"{f}.{n}" for f, n in INPUT_CASES])
def test_huge_finite_inputs_give_finite_outputs_or_an_error_never_nan(fmu_paths, unzipped, fmu_id, name):
    """Finite but extreme inputs may overflow inside a model: each call either succeeds
    with finite outputs or fails with an error status and a message, for three steps."""
    outcomes = []
    for value in HUGE:
        fmu = start_at(fmu_paths, unzipped, fmu_id, "mid-run", steps=5)
        try:
            for n in range(5, 8):
                fmu.set(**{name: value})
                assert np.all(np.isfinite(fmu.get(*outputs_of(fmu_id)))), (value, n)
                fmu.slave.doStep(n * 1e-3, 1e-3)
            assert np.all(np.isfinite(fmu.get(*outputs_of(fmu_id))))
            outcomes.append("finite")
        except FMICallException as failure:
            assert failure.status >= FMI_ERROR
            assert errors(fmu), fmu.messages
            outcomes.append(errors(fmu)[0])
        fmu.slave.freeInstance()
    if fmu_id == "AdaptiveFuzzyController" and name in ("e", "de"):
        assert any("diverged" in outcome or "out of range" in outcome for outcome in outcomes), outcomes


