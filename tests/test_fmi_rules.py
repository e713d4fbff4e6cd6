"""FMI's rules of the calling sequence, on every FMU.

Each rule is driven through fmpy's low-level API as a host would: a write to a fixed
parameter after initialisation, doStep before initialisation or after fmi2Terminate,
and doStep at a communication point other than the FMU's own time.  Each must give an
error status and a log message naming the call, the variable or time and the rule.

Statuses under pythonfmu 0.7 (see fmu_src/afc_slave_base.py): a refused write is
fmi2Fatal (pythonfmu turns every Python exception into fmi2Fatal); a refused doStep is
fmi2Discard (do_step returned False) with the FMU's state and time unchanged.
"""
import math

import pytest
from fmpy import extract
from fmpy.fmi1 import FMICallException

from harness.fmu_build import builder as build_fmu
from tests.fmu_helpers import Driven

DISCARD, FATAL = 2, 4
H = 1e-3
FMUS = ("AdaptiveFuzzyController", "InvertedPendulum", "Manipulator", "TrackingReference")
#: outputs that show the state of each FMU (compared before and after a refused call)
STATE_OUTPUTS = {"AdaptiveFuzzyController": ("u", "theta1", "theta4", "alpha1"), "InvertedPendulum": ("y", "dy"),
                 "Manipulator": ("y", "dy", "mr"), "TrackingReference": ("ym", "dym")}
#: inputs set before the steps, so that the state moves (a refused step that changed it would show)
INPUTS = {"AdaptiveFuzzyController": {"e": 0.2, "de": -0.1, "ym": 0.3, "dym": 0.1}, "InvertedPendulum": {"u": 1.5},
          "Manipulator": {"u": -2.0}, "TrackingReference": {"y": 0.1, "dy": 0.2}}


def parameters(name):
    """(parameter name, kind, start, a valid value other than the start) of one FMU."""
    rows = []
    for v in build_fmu.model_class(name).VARIABLES:
        if v.causality != "parameter":
            continue
        if v.kind == "Integer":
            other = v.minimum if v.start != v.minimum else v.maximum
        elif v.maximum is not None:  # (0, 1) etc.: halfway to the bound
            other = (v.start + v.maximum) / 2
        else:  # 10 % more (mr1 stays below mr0), or 1 for a start of 0
            other = v.start * 1.1 if v.start > 0 else v.start + 1
        rows.append((v.name, v.kind, v.start, other))
    return rows


ALL_PARAMETERS = [(fmu, *row) for fmu in FMUS for row in parameters(fmu)]


@pytest.fixture(scope="module")
def fmus(fmu_paths, tmp_path_factory):
    """{model identifier: (path, unzip directory)}: each FMU extracted once, into pytest's tmp folder."""
    folder = tmp_path_factory.mktemp("fmi_rules")
    return {name: (fmu_paths[name], extract(str(fmu_paths[name]), str(folder / name))) for name in FMUS}


def instance(fmus, name, label="rules"):
    path, unzip_dir = fmus[name]
    return Driven(path, f"{name}_{label}", unzip_dir=unzip_dir)


def errors(driven):
    return [message for status, message in driven.messages if status >= 3]


def read(driven, names):
    values = driven.get(*names)
    return list(values) if len(names) > 1 else [values]


def stepped(fmus, name, steps=3, label="rules"):
    """An initialised instance with its inputs set, after ``steps`` accepted steps of H."""
    driven = instance(fmus, name, label).initialize(**INPUTS[name])
    for n in range(steps):
        driven.slave.doStep(n * H, H)
    return driven


# ------------------------------------------------------- fixed parameters
@pytest.mark.parametrize("name,parameter,kind,start,other", ALL_PARAMETERS,
                         ids=[f"{row[0]}.{row[1]}" for row in ALL_PARAMETERS])
def test_a_fixed_parameter_written_after_initialisation_is_refused_and_keeps_its_value(
        fmus, name, parameter, kind, start, other):
    driven = stepped(fmus, name, steps=2)
    before = read(driven, STATE_OUTPUTS[name])
    call = "fmi2SetInteger" if kind == "Integer" else "fmi2SetReal"
    with pytest.raises(FMICallException) as raised:
        driven.set(**{parameter: other})
    assert raised.value.status == FATAL  # pythonfmu 0.7: every refusal by exception is fmi2Fatal
    message = " ".join(errors(driven))
    assert f"{call}: {parameter} = " in message and "variability fixed" in message, message
    assert "only before fmi2ExitInitializationMode" in message and "t = 0.002" in message, message
    kept = driven.slave.getInteger([driven.vr[parameter]])[0] if kind == "Integer" else driven.get(parameter)
    assert kept == start  # reads back unchanged
    assert read(driven, STATE_OUTPUTS[name]) == before  # and nothing derived from it moved
    driven.slave.freeInstance()  # the host survives the fatal status (afc_slave_base._outlive_pythonfmu_cleanup)


@pytest.mark.parametrize("name,parameter,kind,start,other", ALL_PARAMETERS,
                         ids=[f"{row[0]}.{row[1]}" for row in ALL_PARAMETERS])
def test_a_fixed_parameter_is_accepted_after_instantiation_and_in_initialisation_mode(
        fmus, name, parameter, kind, start, other):
    driven = instance(fmus, name)
    driven.set(**{parameter: other})  # after instantiation
    driven.enter(**{parameter: other})  # in initialisation mode
    driven.slave.exitInitializationMode()
    kept = driven.slave.getInteger([driven.vr[parameter]])[0] if kind == "Integer" else driven.get(parameter)
    assert kept == other and not errors(driven)
    driven.free()


def test_the_issue_s_three_writes_no_longer_change_the_controller_or_the_plant(fmus):
    """lambda_ce = 5 gave alpha = -4; k1 = 100 was accepted without a new P; mp read back changed."""
    controller = stepped(fmus, "AdaptiveFuzzyController", label="issue")
    alpha, u = controller.get("alpha1", "u")
    for parameter, value in (("lambda_ce", 5.0), ("k1", 100.0)):
        copy = stepped(fmus, "AdaptiveFuzzyController", label=f"issue_{parameter}")
        with pytest.raises(FMICallException):
            copy.set(**{parameter: value})
        assert list(copy.get("alpha1", "u")) == [alpha, u] and 0 < alpha <= 1
        copy.slave.freeInstance()
    controller.free()
    plant = stepped(fmus, "InvertedPendulum", label="issue")
    with pytest.raises(FMICallException):
        plant.set(mp=1.0)
    assert plant.get("mp") == 0.1
    plant.slave.freeInstance()


# ------------------------------------------------- doStep outside step mode
@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("when", ["after instantiation", "in initialisation mode"])
def test_do_step_before_initialisation_is_discarded_and_changes_nothing(fmus, name, when):
    driven = instance(fmus, name)
    if when == "in initialisation mode":
        driven.enter(**INPUTS[name])
    with pytest.raises(FMICallException) as raised:
        driven.slave.doStep(0.0, H)
    assert raised.value.status == DISCARD
    message = " ".join(errors(driven))
    assert "fmi2DoStep(currentCommunicationPoint = 0.0" in message and "not initialised" in message, message
    assert "fmi2ExitInitializationMode" in message
    # nothing happened: initialisation goes on and the first step is the one at the start time
    if when == "after instantiation":
        driven.enter(**INPUTS[name])
    driven.slave.exitInitializationMode()
    driven.slave.doStep(0.0, H)
    reference = stepped(fmus, name, steps=1, label="reference")
    assert read(driven, STATE_OUTPUTS[name]) == read(reference, STATE_OUTPUTS[name])
    driven.free()
    reference.free()


@pytest.mark.parametrize("name", FMUS)
def test_do_step_and_writes_after_terminate_are_refused(fmus, name):
    driven = stepped(fmus, name, steps=2)
    driven.slave.terminate()
    with pytest.raises(FMICallException) as raised:
        driven.slave.doStep(2 * H, H)
    assert raised.value.status == DISCARD
    assert any("fmi2DoStep(currentCommunicationPoint = 0.002" in m and "terminated" in m for m in errors(driven))
    first_input = next(iter(INPUTS[name]))
    with pytest.raises(FMICallException) as raised:
        driven.set(**{first_input: 0.5})
    assert raised.value.status == FATAL
    assert any(f"fmi2SetReal: {first_input} = 0.5 refused" in m and "fmi2Terminate" in m for m in errors(driven))
    driven.slave.freeInstance()


# ------------------------------------------------- the communication point
@pytest.mark.parametrize("name", FMUS)
@pytest.mark.parametrize("wrong", [0.0, 2 * H, 5 * H, -H], ids=["repeat", "skip one", "jump", "before start"])
def test_do_step_at_another_time_than_the_fmu_s_is_discarded_and_changes_nothing(fmus, name, wrong):
    driven = stepped(fmus, name, steps=1)  # the FMU's time is H
    before = read(driven, STATE_OUTPUTS[name])
    with pytest.raises(FMICallException) as raised:
        driven.slave.doStep(wrong, H)
    assert raised.value.status == DISCARD
    message = " ".join(errors(driven))
    assert f"fmi2DoStep(currentCommunicationPoint = {wrong!r}" in message, message
    assert f"expected currentCommunicationPoint = {H!r}" in message, message
    assert read(driven, STATE_OUTPUTS[name]) == before
    # the right point still works, as if the wrong call had never happened
    driven.slave.doStep(H, H)
    reference = stepped(fmus, name, steps=2, label="reference")
    assert read(driven, STATE_OUTPUTS[name]) == read(reference, STATE_OUTPUTS[name])
    driven.free()
    reference.free()


@pytest.mark.parametrize("name", FMUS)
def test_rounding_of_the_communication_point_is_tolerated(fmus, name):
    """t_n = n h computed by the host differs from the FMU's t_(n-1) + h in the last bits."""
    driven = instance(fmus, name).initialize(**INPUTS[name])
    step = 0.1  # 0.1 + 0.1 + 0.1 != 0.3 in binary floating point
    for n in range(5):
        driven.slave.doStep(n * step, step)
    driven.slave.doStep(math.nextafter(0.5, 1.0), step)  # one ulp late
    assert not errors(driven)
    driven.free()


@pytest.mark.parametrize("name", FMUS)
def test_after_a_state_restore_the_step_starts_at_the_restored_time(fmus, name):
    driven = stepped(fmus, name, steps=1)
    state = driven.slave.getFMUstate()
    driven.slave.doStep(H, H)
    driven.slave.doStep(2 * H, H)
    driven.slave.setFMUstate(state)
    with pytest.raises(FMICallException) as raised:
        driven.slave.doStep(3 * H, H)  # the time before the restore
    assert raised.value.status == DISCARD
    driven.slave.doStep(H, H)  # the restored time
    driven.slave.freeFMUstate(state)
    driven.free()


@pytest.mark.parametrize("name", FMUS)
def test_a_negative_or_nan_step_is_discarded(fmus, name):
    driven = stepped(fmus, name, steps=1)
    for size in (-H, float("nan")):
        with pytest.raises(FMICallException) as raised:
            driven.slave.doStep(H, size)
        assert raised.value.status == DISCARD
    assert sum("communication step must be >= 0" in m for m in errors(driven)) == 2
    driven.slave.doStep(H, H)
    driven.free()


@pytest.mark.parametrize("name", FMUS)
def test_a_state_restored_into_a_fresh_instance_is_in_step_mode_at_its_time(fmus, name):
    """A serialized step-mode state restored right after instantiation: doStep at its time, no parameter writes."""
    source = stepped(fmus, name, steps=2, label="source")
    state = source.slave.getFMUstate()
    serialized = source.slave.serializeFMUstate(state)
    source.slave.freeFMUstate(state)
    source.slave.doStep(2 * H, H)
    expected = read(source, STATE_OUTPUTS[name])
    fresh = instance(fmus, name, "fresh")
    restored = fresh.slave.deSerializeFMUstate(serialized)
    fresh.slave.setFMUstate(restored)
    fresh.slave.freeFMUstate(restored)
    fresh.slave.doStep(2 * H, H)
    assert read(fresh, STATE_OUTPUTS[name]) == expected and not errors(fresh)
    parameter = parameters(name)[0]
    with pytest.raises(FMICallException):
        fresh.set(**{parameter[0]: parameter[3]})
    fresh.slave.freeInstance()
    source.free()
