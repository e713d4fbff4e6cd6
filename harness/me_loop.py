"""The Model Exchange master's integration loop compiled (harness/me_loop.c): CVODE calling C.

With the Python loop of :class:`harness.me_master.ModelExchangeMaster`, CVODE calls back into
Python for every derivative and indicator evaluation and the master records every output row
from Python: about 15 us per evaluation and per row on top of what the FMUs cost, most of a
run.  :class:`CompiledIntegration` hands CVODE the C functions ``me_rhs`` and ``me_roots`` of
harness/me_loop.c instead, over the very plan of the Python loop (its value-reference and value
arrays, FMI function pointers and bounds), and records the rows in C; events, failures and the
FMUs' life cycle stay in the Python master, which raises what its Python loop raises.

The same switch as the co-simulation loop's (harness/master_loop.py): ``AFC_MASTER_LOOP=python``
keeps the Python loop, ``c`` requires the compiled one; built on first use with zig's C
compiler (the ``native`` and ``test`` extras) and cached in build/native/obj.
tests/test_me_master.py holds the two loops bit-identical, events and failures included.
"""
from __future__ import annotations

import ctypes
import sys
from pathlib import Path

import numpy as np

import c_toolchain

from . import cvode, master_loop

SOURCE = Path(__file__).with_name("me_loop.c")
CHOICES = master_loop.CHOICES
ENVIRONMENT_SWITCH = master_loop.ENVIRONMENT_SWITCH

(LOOP_DONE, LOOP_READ_FAILED, LOOP_WRITE_DIVERGED, LOOP_WRITE_FAILED, LOOP_RECORD_DIVERGED, LOOP_SET_TIME_FAILED,
 LOOP_SET_STATES_FAILED, LOOP_DERIVATIVES_FAILED, LOOP_INDICATORS_FAILED, LOOP_SOLVER_FAILED, LOOP_EVENT) = range(11)
#: the FMI function each failure names (FMI 2.0 names; an FMI 3.0 instance reports its own)
FAILED_FUNCTIONS = {LOOP_READ_FAILED: "fmi2GetReal", LOOP_WRITE_FAILED: "fmi2SetReal",
                    LOOP_SET_TIME_FAILED: "fmi2SetTime", LOOP_SET_STATES_FAILED: "fmi2SetContinuousStates",
                    LOOP_DERIVATIVES_FAILED: "fmi2GetDerivatives", LOOP_INDICATORS_FAILED: "fmi2GetEventIndicators"}

_void, _size = ctypes.c_void_p, ctypes.c_size_t


class Timer(ctypes.Structure):
    _fields_ = [("instance", _void), ("set_time", _void)]


class Block(ctypes.Structure):
    _fields_ = [("instance", _void), ("set_states", _void), ("get_derivatives", _void), ("get_indicators", _void),
                ("offset", _size), ("states", _size), ("indicator_offset", _size), ("indicators", _size)]


class Outcome(ctypes.Structure):
    _fields_ = [("outcome", ctypes.c_int32), ("status", ctypes.c_int32), ("row", ctypes.c_int64),
                ("index", ctypes.c_int64), ("copy", ctypes.c_int64), ("value", ctypes.c_double),
                ("time", ctypes.c_double)]


class MeLoop(ctypes.Structure):
    _fields_ = [("plan", _void), ("actions", _size), ("timers", _void), ("timer_count", _size),
                ("blocks", _void), ("block_count", _size), ("x", _void), ("dx", _void), ("z", _void),
                ("states", _size), ("indicators", _size), ("cvode_memory", _void), ("y", _void),
                ("interpolated", _void), ("cvode", _void), ("get_dky", _void), ("get_array_pointer", _void),
                ("get_last_order", _void), ("get_current_time", _void), ("taylor", _void), ("record", _void), ("columns", _size), ("column_bounds", _void), ("check_every", ctypes.c_int64),
                ("rows", ctypes.c_int64), ("start", ctypes.c_double), ("step", ctypes.c_double),
                ("failure", Outcome), ("evaluations", ctypes.c_int64)]


_library = None
_unavailable = None


def choice(loop: str = "auto") -> str:
    return master_loop.choice(loop)


def library(loop: str = "auto"):
    """The compiled library (me_loop_run, me_rhs, me_roots), or None for the Python loop (as
    harness/master_loop.py's ``library``: "auto" falls back and says why once, "c" raises)."""
    global _library, _unavailable
    wanted = choice(loop)
    if wanted == "python":
        return None
    if _library is None and _unavailable is None:
        try:
            _library = _load()
        except master_loop.LoopUnavailable as error:
            _unavailable = str(error)
            if wanted == "auto" and "zig's C compiler is not installed" not in _unavailable:
                print(f"warning: the Model Exchange master runs its Python loop: {_unavailable}", file=sys.stderr)
    if _library is None and wanted == "c":
        raise master_loop.LoopUnavailable(f"{ENVIRONMENT_SWITCH}=c: {_unavailable}")
    return _library


def _load():
    if not c_toolchain.compiler_available():
        raise master_loop.LoopUnavailable("zig's C compiler is not installed (pip install -e '.[native]')")
    try:
        loaded = ctypes.CDLL(str(c_toolchain.host_library("me_loop", (SOURCE,))))
    except (c_toolchain.NativeBuildError, OSError) as error:
        raise master_loop.LoopUnavailable(f"the compiled loop {SOURCE.name} cannot be built or loaded: "
                                          f"{str(error).strip().splitlines()[0]}") from error
    run = loaded.me_loop_run
    run.restype = ctypes.c_int
    run.argtypes = [ctypes.POINTER(MeLoop), ctypes.c_double, ctypes.c_double, ctypes.c_int32, ctypes.c_int64,
                    ctypes.c_int64, ctypes.POINTER(Outcome)]
    return loaded


def function_address(loaded, name: str) -> int:
    return ctypes.cast(getattr(loaded, name), _void).value


class CompiledIntegration:
    """The Python master's plan, timers, state blocks and CVODE memory, ready for me_loop_run."""

    def __init__(self, loaded, plan: list, timers: list, blocks: list, x, dx, z, states: int, indicators: int,
                 record, column_bounds, check_every: int, start: float, step: float):
        self.loaded = loaded
        actions, self._keep = master_loop.plan_actions(plan)
        timer_array = (Timer * max(len(timers), 1))()
        for (component, _), entry in zip(timers, timer_array):
            entry.instance, entry.set_time = component.instance_address, component.addresses["set_time"]
        block_array = (Block * max(len(blocks), 1))()
        for block, entry in zip(blocks, block_array):
            addresses = block.component.addresses
            entry.instance = block.component.instance_address
            entry.set_states, entry.get_derivatives = addresses["set_states"], addresses["get_derivatives"]
            entry.get_indicators = addresses["get_indicators"]
            entry.offset, entry.states = block.offset, block.states
            entry.indicator_offset, entry.indicators = block.indicator_offset, block.indicators
        if not (record.flags.c_contiguous and record.dtype == "float64"):
            raise ValueError("the record must be a C-contiguous float64 array")
        self.column_bounds = (ctypes.c_double * max(len(column_bounds), 1))(*column_bounds)
        self._keep += [actions, timer_array, block_array, record]
        loop = MeLoop()
        loop.plan, loop.actions = ctypes.addressof(actions), len(plan)
        loop.timers, loop.timer_count = ctypes.addressof(timer_array), len(timers)
        loop.blocks, loop.block_count = ctypes.addressof(block_array), len(blocks)
        loop.x, loop.dx, loop.z = ctypes.addressof(x), ctypes.addressof(dx), ctypes.addressof(z)
        loop.states, loop.indicators = max(states, 1), indicators
        loop.cvode = cvode.address_of("CVode")
        loop.get_dky = cvode.address_of("CVodeGetDky")
        loop.get_array_pointer = cvode.address_of("N_VGetArrayPointer")
        loop.get_last_order = cvode.address_of("CVodeGetLastOrder")
        loop.get_current_time = cvode.address_of("CVodeGetCurrentTime")
        self.taylor = np.zeros((cvode.MAX_ORDER + 1, max(states, 1)))
        loop.taylor = self.taylor.ctypes.data
        loop.record, loop.columns = record.ctypes.data, record.shape[1]
        loop.column_bounds = ctypes.addressof(self.column_bounds)
        loop.check_every, loop.rows = check_every, record.shape[0]
        loop.start, loop.step = start, step
        self.loop = loop
        self.outcome = Outcome()

    @property
    def user_data(self) -> int:
        return ctypes.addressof(self.loop)

    @property
    def rhs(self) -> int:
        return function_address(self.loaded, "me_rhs")

    @property
    def roots(self) -> int:
        return function_address(self.loaded, "me_roots")

    def attach(self, solver):
        """Point the loop at ``solver``'s CVODE memory and vectors (once the solver exists)."""
        self.loop.cvode_memory = solver.memory
        self.loop.y = solver.y
        self.loop.interpolated = solver._interpolated

    def run(self, target: float, next_event: float, every_step: bool, row: int, last_row: int) -> Outcome:
        self.loaded.me_loop_run(ctypes.byref(self.loop), target, next_event, int(every_step), row, last_row,
                                ctypes.byref(self.outcome))
        return self.outcome

    @property
    def evaluations(self) -> int:
        return self.loop.evaluations


__all__ = ["CompiledIntegration", "library", "choice", "ENVIRONMENT_SWITCH", "FAILED_FUNCTIONS"]
