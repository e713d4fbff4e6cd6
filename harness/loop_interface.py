"""The Python side of harness/loop_interface.h: the ctypes layouts of the compiled loops' structs and
the codes of what stopped a loop, named once for both masters; and the master's plan as the header's
Actions, which both loops run.

Each structure mirrors the header's struct of the same name field for field;
tests/test_loop_interface.py compiles the header and holds every size, offset and code equal.
"""
from __future__ import annotations

import ctypes
import enum
from pathlib import Path

HEADER = Path(__file__).with_name("loop_interface.h")

ACTION_READ, ACTION_WRITE = 0, 1


class LoopOutcome(enum.IntEnum):
    """The header's LOOP_ codes (LOOP_DONE is DONE): what stopped a loop, or what failed in an evaluation."""

    DONE = 0
    READ_FAILED = 1
    WRITE_DIVERGED = 2
    WRITE_FAILED = 3
    RECORD_DIVERGED = 4
    STEP_FAILED = 5
    SET_TIME_FAILED = 6
    SET_STATES_FAILED = 7
    DERIVATIVES_FAILED = 8
    INDICATORS_FAILED = 9
    SOLVER_FAILED = 10
    EVENT = 11
    OUT_OF_MEMORY = 12


#: the FMI function each failure names (FMI 2.0 names; an FMI 3.0 instance reports its own)
FAILED_FUNCTIONS = {LoopOutcome.READ_FAILED: "fmi2GetReal", LoopOutcome.WRITE_FAILED: "fmi2SetReal",
                    LoopOutcome.STEP_FAILED: "fmi2DoStep", LoopOutcome.SET_TIME_FAILED: "fmi2SetTime",
                    LoopOutcome.SET_STATES_FAILED: "fmi2SetContinuousStates",
                    LoopOutcome.DERIVATIVES_FAILED: "fmi2GetDerivatives",
                    LoopOutcome.INDICATORS_FAILED: "fmi2GetEventIndicators"}

_void, _size, _int32, _int64, _double = ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int32, ctypes.c_int64, ctypes.c_double


class Action(ctypes.Structure):
    _fields_ = [("kind", _int32), ("fmi_version", _int32), ("instance", _void), ("call", _void),
                ("references", _void), ("count", _size), ("values", _void), ("first_column", _size),
                ("recorded", _size), ("sources", _void), ("source_index", _void), ("bounds", _void)]


class Stepper(ctypes.Structure):
    _fields_ = [("fmi_version", _int32), ("instance", _void), ("do_step", _void)]


class Timer(ctypes.Structure):
    _fields_ = [("instance", _void), ("set_time", _void)]


class Block(ctypes.Structure):
    _fields_ = [("instance", _void), ("set_states", _void), ("get_derivatives", _void), ("get_indicators", _void),
                ("offset", _size), ("states", _size), ("indicator_offset", _size), ("indicators", _size)]


class Outcome(ctypes.Structure):
    _fields_ = [("outcome", _int32), ("status", _int32), ("row", _int64), ("index", _int64), ("copy", _int64),
                ("value", _double), ("time", _double)]


class MeLoop(ctypes.Structure):
    _fields_ = [("plan", _void), ("actions", _size), ("timers", _void), ("timer_count", _size),
                ("blocks", _void), ("block_count", _size), ("x", _void), ("dx", _void), ("z", _void),
                ("states", _size), ("indicators", _size), ("cvode_memory", _void), ("y", _void),
                ("interpolated", _void), ("cvode", _void), ("get_dky", _void), ("get_array_pointer", _void),
                ("get_last_order", _void), ("get_current_time", _void), ("taylor", _void), ("record", _void),
                ("columns", _size), ("column_bounds", _void), ("check_every", _int64), ("rows", _int64),
                ("start", _double), ("step", _double), ("failure", Outcome), ("evaluations", _int64)]


#: every struct of the header, by its C name
STRUCTS = {structure.__name__: structure for structure in (Action, Stepper, Timer, Block, Outcome, MeLoop)}


def _address(array) -> int:
    return ctypes.addressof(array)


def plan_actions(plan: list) -> tuple:
    """(Action array, ctypes objects it points into) for a plan of harness.master (its _Read and _Write
    actions): the same value-reference and value arrays, the same FMI function pointers and bounds."""
    keep = []
    actions = (Action * len(plan))()
    for action, entry in zip(plan, actions):
        array = action.array
        component = action.component
        entry.fmi_version = 3 if component.fmi3 else 2
        entry.instance = component.instance_address
        entry.call = array.function_address
        entry.references = _address(array.references)
        entry.count = len(array.values)
        entry.values = _address(array.values)
        if action.copies is None:
            entry.kind = ACTION_READ
            entry.first_column, entry.recorded = action.first_column, action.recorded
            continue
        entry.kind = ACTION_WRITE
        if [k for k, *_ in action.copies] != list(range(entry.count)):
            raise ValueError("a write's copies must fill its value array in order")
        sources = (ctypes.c_void_p * entry.count)(*[_address(source) for _, source, _, _ in action.copies])
        source_index = (ctypes.c_size_t * entry.count)(*[j for _, _, j, _ in action.copies])
        bounds = (ctypes.c_double * entry.count)(*[bound for *_, bound in action.copies])
        keep += [sources, source_index, bounds]
        entry.sources, entry.source_index, entry.bounds = _address(sources), _address(source_index), _address(bounds)
    return actions, keep


__all__ = ["HEADER", "ACTION_READ", "ACTION_WRITE", "LoopOutcome", "FAILED_FUNCTIONS", "Action", "Stepper", "Timer",
           "Block", "Outcome", "MeLoop", "STRUCTS", "plan_actions"]
