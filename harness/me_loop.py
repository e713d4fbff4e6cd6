"""The Model Exchange master's integration loop compiled (harness/me_loop.c): CVODE calling C.

With the Python loop of :class:`harness.me_master.ModelExchangeMaster`, CVODE calls back into
Python for every derivative and indicator evaluation and the master records every output row
from Python.  :class:`CompiledIntegration` hands CVODE the C functions ``me_rhs`` and ``me_roots``
of harness/me_loop.c instead, over the very plan of the Python loop (its value-reference and value
arrays, FMI function pointers and bounds), and records the rows in C; events, failures and the
FMUs' life cycle stay in the Python master, which raises what its Python loop raises.

Built, loaded and chosen as the co-simulation loop is (harness/compiled_loop.py:
``AFC_MASTER_LOOP=python`` keeps the Python loop, ``c`` requires the compiled one); its structs are
harness/loop_interface.h, mirrored in harness/loop_interface.py.  tests/test_me_master.py holds the
two loops bit-identical, events and failures included.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from . import cvode
from .compiled_loop import CompiledLibrary, function_address
from .loop_interface import Block, MeLoop, Outcome, Timer, plan_actions

SOURCE = Path(__file__).with_name("me_loop.c")


def _declare(library):
    run = library.me_loop_run
    run.restype = ctypes.c_int
    run.argtypes = [ctypes.POINTER(MeLoop), ctypes.c_double, ctypes.c_double, ctypes.c_int32, ctypes.c_int64,
                    ctypes.c_int64, ctypes.POINTER(Outcome)]


LIBRARY = CompiledLibrary("me_loop", SOURCE, "the Model Exchange master", _declare)


def library(loop: str = "auto"):
    """The compiled library (me_loop_run, me_rhs, me_roots), or None for the Python loop
    (harness/compiled_loop.py: "auto" falls back and says why once, "c" raises)."""
    return LIBRARY.get(loop)


class CompiledIntegration:
    """The Python master's plan, timers, state blocks and CVODE memory, ready for me_loop_run."""

    def __init__(self, loaded, plan: list, timers: list, blocks: list, x, dx, z, states: int, indicators: int,
                 record, column_bounds, check_every: int, start: float, step: float):
        self.loaded = loaded
        actions, self._keep = plan_actions(plan)
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


__all__ = ["CompiledIntegration", "library", "LIBRARY", "SOURCE"]
