"""The master's fixed-step loop compiled (harness/master_loop.c): same calls, no Python per step.

The Python loop of :class:`harness.master.Master` makes its ctypes calls and the bookkeeping
between them from Python at every communication step.  :class:`CompiledLoop` runs the very same
plan (the Python plan's value-reference and value arrays, its FMI function pointers, its
divergence bounds) in C for a block of rows and reports what stopped it; the master then raises
exactly what its Python loop raises, from the same state, with the same rows kept.

The library is built and loaded by harness/compiled_loop.py (on first use, with zig's C compiler;
``AFC_MASTER_LOOP`` chooses); its structs are harness/loop_interface.h, mirrored in
harness/loop_interface.py.  tests/test_master_loop.py holds the two loops bit-identical, failures
included.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

from .compiled_loop import CompiledLibrary
from .loop_interface import Action, Outcome, Stepper, plan_actions

SOURCE = Path(__file__).with_name("master_loop.c")

_double_p = ctypes.POINTER(ctypes.c_double)


def _declare(library):
    function = library.master_loop_run
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.POINTER(Action), ctypes.c_size_t, ctypes.POINTER(Stepper), ctypes.c_size_t,
                         ctypes.c_double, ctypes.c_double, ctypes.c_int64, ctypes.c_int64, ctypes.c_int64, _double_p,
                         ctypes.c_size_t, _double_p, ctypes.c_int64, ctypes.POINTER(Outcome)]
    finish = library.master_loop_finish
    finish.restype = ctypes.c_int
    finish.argtypes = [ctypes.POINTER(Action), ctypes.c_size_t, ctypes.c_int64, _double_p, ctypes.c_size_t, _double_p,
                       ctypes.c_int64, ctypes.POINTER(Outcome)]


LIBRARY = CompiledLibrary("master_loop", SOURCE, "the master", _declare)


def library(loop: str = "auto"):
    """The compiled loop's library (its ``master_loop_run``), or None for the Python loop
    (harness/compiled_loop.py: "auto" falls back and says why once, "c" raises)."""
    return LIBRARY.get(loop)


class CompiledLoop:
    """A plan of harness.master (its _Read and _Write actions) and steppers, ready for master_loop_run."""

    def __init__(self, library, plan: list, components: list, record, column_bounds, check_every: int):
        self.function, self.finishing = library.master_loop_run, library.master_loop_finish
        self.plan = plan
        self.components = components
        self.record = record
        actions, self._keep = plan_actions(plan)  # _keep: ctypes objects the C side points into
        steppers = (Stepper * len(components))()
        for component, entry in zip(components, steppers):
            entry.fmi_version = 3 if component.fmi3 else 2
            entry.instance = component.instance_address
            entry.do_step = component.do_step_address
        if not (record.flags.c_contiguous and record.dtype == "float64"):
            raise ValueError("the record must be a C-contiguous float64 array")
        self.column_bounds = (ctypes.c_double * len(column_bounds))(*column_bounds)
        self._record, self._bounds = record.ctypes.data_as(_double_p), ctypes.cast(self.column_bounds, _double_p)
        self.actions, self.steppers = actions, steppers
        self.columns = record.shape[1]
        self.check_every = check_every
        self.outcome = Outcome()

    def run(self, start: float, step: float, first_row: int, last_row: int, steps: int = -1) -> Outcome:
        """Rows first_row .. last_row - 1, and the last communication point too when last_row is ``steps``; the
        Outcome says whether all ran or what stopped them."""
        self.function(self.actions, len(self.actions), self.steppers, len(self.steppers), start, step,
                      first_row, last_row, steps, self._record, self.columns, self._bounds, self.check_every,
                      ctypes.byref(self.outcome))
        return self.outcome

    def finish(self, steps: int) -> Outcome:
        """Row ``steps`` (the last communication point, no doStep) and the check of the rows after the last
        block check."""
        self.finishing(self.actions, len(self.actions), steps, self._record, self.columns, self._bounds,
                       self.check_every, ctypes.byref(self.outcome))
        return self.outcome


__all__ = ["CompiledLoop", "library", "LIBRARY", "SOURCE"]
