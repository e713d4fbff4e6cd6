"""The master's fixed-step loop compiled (harness/master_loop.c): same calls, no Python per step.

The Python loop of :class:`harness.master.Master` costs about 4 us per communication step
of the pendulum loop on top of what the FMUs themselves cost: nine ctypes calls and the
bookkeeping between them.  With the native edition's FMUs that is four fifths of a step.
:class:`CompiledLoop` runs the very same plan (the Python plan's value-reference and value
arrays, its FMI function pointers, its divergence bounds) in C for a block of rows and
reports what stopped it; the master then raises exactly what its Python loop raises, from
the same state, with the same rows kept.

The library is compiled on first use with zig's C compiler (the ``native`` and ``test``
extras) for the machine running the harness and cached in build/native/obj; with no
compiler, or with ``AFC_MASTER_LOOP=python``, the master keeps its Python loop.
tests/test_master_loop.py holds the two loops bit-identical, failures included.
"""
from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

import c_toolchain

SOURCE = Path(__file__).with_name("master_loop.c")
ENVIRONMENT_SWITCH = "AFC_MASTER_LOOP"  # "python": always the Python loop; "c": the compiled one or an error
CHOICES = ("auto", "python", "c")

LOOP_DONE, LOOP_READ_FAILED, LOOP_WRITE_DIVERGED, LOOP_WRITE_FAILED, LOOP_RECORD_DIVERGED, LOOP_STEP_FAILED = range(6)
ACTION_READ, ACTION_WRITE = 0, 1

_double_p = ctypes.POINTER(ctypes.c_double)


class Action(ctypes.Structure):
    _fields_ = [("kind", ctypes.c_int32), ("fmi_version", ctypes.c_int32), ("instance", ctypes.c_void_p),
                ("call", ctypes.c_void_p), ("references", ctypes.c_void_p), ("count", ctypes.c_size_t),
                ("values", ctypes.c_void_p), ("first_column", ctypes.c_size_t), ("recorded", ctypes.c_size_t),
                ("sources", ctypes.c_void_p), ("source_index", ctypes.c_void_p), ("bounds", ctypes.c_void_p)]


class Stepper(ctypes.Structure):
    _fields_ = [("fmi_version", ctypes.c_int32), ("instance", ctypes.c_void_p), ("do_step", ctypes.c_void_p)]


class Outcome(ctypes.Structure):
    _fields_ = [("outcome", ctypes.c_int32), ("status", ctypes.c_int32), ("row", ctypes.c_int64),
                ("action", ctypes.c_int64), ("copy", ctypes.c_int64), ("value", ctypes.c_double)]


class LoopUnavailable(RuntimeError):
    """The compiled loop cannot be built or loaded here (an error only when it was required)."""


_library = None
_unavailable = None  # why the compiled loop could not be built or loaded here (said once)


def choice(loop: str = "auto") -> str:
    """``loop`` unless it is "auto", else $AFC_MASTER_LOOP, else "auto"."""
    if loop not in CHOICES:
        raise ValueError(f"loop {loop!r} is not valid; valid: {', '.join(CHOICES)}")
    if loop != "auto":
        return loop
    value = os.environ.get(ENVIRONMENT_SWITCH, "auto") or "auto"
    if value not in CHOICES:
        raise LoopUnavailable(f"{ENVIRONMENT_SWITCH}={value!r} is not valid; valid: {', '.join(CHOICES)}")
    return value


def library(loop: str = "auto"):
    """The compiled loop's ``master_loop_run``, or None for the Python loop.

    None when ``loop`` (or $AFC_MASTER_LOOP) is "python", or when it is "auto" and the library
    cannot be had here (zig not installed, the build or the load failed: said once on stderr).
    "c" raises LoopUnavailable instead of falling back.
    """
    global _library, _unavailable
    wanted = choice(loop)
    if wanted == "python":
        return None
    if _library is None and _unavailable is None:
        try:
            _library = _load()
        except LoopUnavailable as error:
            _unavailable = str(error)
            if wanted == "auto" and "zig's C compiler is not installed" not in _unavailable:
                print(f"warning: the master runs its Python loop: {_unavailable}", file=sys.stderr)
    if _library is None and wanted == "c":
        raise LoopUnavailable(f"{ENVIRONMENT_SWITCH}=c: {_unavailable}")
    return _library


def _load():
    """Build (or find in the cache) and load the library; LoopUnavailable says why it cannot be."""
    if not c_toolchain.compiler_available():
        raise LoopUnavailable("zig's C compiler is not installed (pip install -e '.[native]')")
    try:
        function = ctypes.CDLL(str(c_toolchain.host_library("master_loop", (SOURCE,)))).master_loop_run
    except (c_toolchain.NativeBuildError, OSError) as error:
        raise LoopUnavailable(f"the compiled loop {SOURCE.name} cannot be built or loaded: "
                              f"{str(error).strip().splitlines()[0]}") from error
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.POINTER(Action), ctypes.c_size_t, ctypes.POINTER(Stepper), ctypes.c_size_t,
                         ctypes.c_double, ctypes.c_double, ctypes.c_int64, ctypes.c_int64, _double_p,
                         ctypes.c_size_t, _double_p, ctypes.c_int64, ctypes.POINTER(Outcome)]
    return function


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


class CompiledLoop:
    """A plan of harness.master (its _Read and _Write actions) and steppers, ready for master_loop_run."""

    def __init__(self, function, plan: list, components: list, record, column_bounds, check_every: int):
        self.function = function
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
        self.actions, self.steppers = actions, steppers
        self.columns = record.shape[1]
        self.check_every = check_every
        self.outcome = Outcome()

    def run(self, start: float, step: float, first_row: int, last_row: int) -> Outcome:
        """Rows first_row .. last_row - 1; the Outcome says whether all ran or what stopped them."""
        self.function(self.actions, len(self.actions), self.steppers, len(self.steppers), start, step,
                      first_row, last_row, self.record.ctypes.data_as(_double_p), self.columns,
                      ctypes.cast(self.column_bounds, _double_p), self.check_every, ctypes.byref(self.outcome))
        return self.outcome


__all__ = ["CompiledLoop", "plan_actions", "Action", "LoopUnavailable", "library", "choice", "ENVIRONMENT_SWITCH"]
