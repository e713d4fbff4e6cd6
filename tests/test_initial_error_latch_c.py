"""The C latch of the initial error (fmu_src/initial_error_latch.c) against its Python twin,
rule for rule, on the sample sequences hosts produce and on random ones.

Every observation's events, the whole state after it and the warning text must be equal: a
rule the C edition lacks (it once lacked the return to the start inputs after placeholders,
which fmpy's SSP simulator needs) shows up as a different event or state at once.
"""
from __future__ import annotations

import ctypes
import math
import random

import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build.native_stages import compiler
from fmu_src import initial_error_latch as latch_py

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

MAX_ORDER = 4
NAMES = ("e", "de", "d2e", "d3e")


class Latch(ctypes.Structure):  # InitialErrorLatch of initial_error_latch.h
    _fields_ = [(name, ctypes.c_double) for name in
                ("open", "origin", "previous_time", "rejected_time", "relatches", "confirmed")] + [
        ("latched", ctypes.c_double * MAX_ORDER), ("previous", ctypes.c_double * MAX_ORDER),
        ("rejected", ctypes.c_double * MAX_ORDER), ("order", ctypes.c_double)]


@pytest.fixture(scope="module")
def library():
    return ctypes.CDLL(str(compiler.math_library()))


def _vector(values):
    return (ctypes.c_double * MAX_ORDER)(*values)


def _python_fields(state: list, n: int) -> dict:
    """The Python state list in the C struct's fields."""
    return dict(open=state[latch_py.OPEN], origin=state[latch_py.ORIGIN],
                previous_time=state[latch_py.PREVIOUS_TIME], rejected_time=state[latch_py.REJECTED_TIME],
                relatches=state[latch_py.RELATCHES], confirmed=state[latch_py.CONFIRMED],
                latched=state[latch_py.LATCHED:latch_py.LATCHED + n],
                previous=state[latch_py.LATCHED + n:latch_py.LATCHED + 2 * n],
                rejected=state[latch_py.LATCHED + 2 * n:latch_py.LATCHED + 3 * n])


def _c_fields(latch: Latch, n: int) -> dict:
    fields = {name: getattr(latch, name) for name in
              ("open", "origin", "previous_time", "rejected_time", "relatches", "confirmed")}
    fields.update({name: list(getattr(latch, name)[:n]) for name in ("latched", "previous", "rejected")})
    return fields


def _warning_c(library, latch: Latch) -> str | None:
    text = ctypes.create_string_buffer(2048)
    names = (ctypes.c_char_p * MAX_ORDER)(*[name.encode() for name in NAMES])
    return text.value.decode() if library.latch_warning(ctypes.byref(latch), names, text, len(text)) else None


def _replay(library, n: int, start_time: float, start_sample, samples) -> None:
    """Both latches through the same start and observations; equal after every call."""
    state = [0.0] * latch_py.size(n)
    latch_py.start(state, start_time, start_sample)
    latch = Latch()
    library.latch_start(ctypes.byref(latch), n, ctypes.c_double(start_time), _vector(start_sample))
    assert _c_fields(latch, n) == _python_fields(state, n)
    for time, sample in samples:
        if state[latch_py.OPEN] <= 0:  # the FMUs stop asking once decided
            break
        events_py = latch_py.observe(state, time, sample)
        events_c = library.latch_observe(ctypes.byref(latch), ctypes.c_double(time), _vector(sample))
        assert events_c == events_py, (time, sample)
        assert _c_fields(latch, n) == _python_fields(state, n), (time, sample)
    assert _warning_c(library, latch) == latch_py.warning(state, NAMES[:n])


def _true_error(t: float, n: int) -> list:
    """e = 0.26 cos 2t and its derivatives: a smooth error the trapezoid rule accepts."""
    return [0.26 * 2 ** i * math.cos(2 * t + i * math.pi / 2) for i in range(n)]


HOSTS = {  # name -> (start sample, [(time, sample)]) for n = 2, h = 1e-4
    "propagating": (_true_error(0, 2), [(k * 1e-4, _true_error(k * 1e-4, 2)) for k in range(10)]),
    "no propagation, feedthrough": ([0.0, 0.0], [(k * 1e-4, _true_error(k * 1e-4, 2)) for k in range(10)]),
    "no propagation, Jacobi": ([0.0, 0.0], [(0.0, [0.0, 0.0])] +
                               [(k * 1e-4, _true_error((k - 1) * 1e-4, 2)) for k in range(1, 10)]),
    # fmpy's SSP simulator: consistent start values, then 0 for two steps, then the true values
    "fmpy.ssp": (_true_error(0, 2), [(0.0, [0.0, 0.0]), (1e-4, [0.0, 0.0])] +
                 [(k * 1e-4, _true_error(k * 1e-4, 2)) for k in range(2, 10)]),
    "alternating sign": ([0.1, 0.0], [(k * 0.01, [0.1 if k % 2 else -0.1, 0.0]) for k in range(10)]),
    "constant": ([0.2, 0.0], [(k * 1e-4, [0.2, 0.0]) for k in range(10)]),
}


@pytest.mark.parametrize("host", HOSTS)
def test_the_c_latch_follows_the_python_latch_in_every_host(library, host):
    start_sample, samples = HOSTS[host]
    _replay(library, 2, 0.0, start_sample, samples)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_the_c_latch_follows_the_python_latch_on_random_sequences(library, n):
    generator = random.Random(16 + n)
    for _ in range(300):
        h = generator.choice([1e-4, 1e-3, 0.01])
        offset = generator.uniform(0, 3)
        choices = ("true", "zero", "start", "jump", "late")

        def sample(k: int, kind: str) -> list:
            t = offset + k * h
            if kind == "zero":
                return [0.0] * n
            if kind == "jump":
                return [generator.uniform(-1, 1) for _ in range(n)]
            if kind == "late":  # one step old, as a Jacobi host hands it
                return _true_error(t - h, n)
            return _true_error(t, n)

        start_kind = generator.choice(("true", "zero", "jump"))
        start_sample = sample(0, start_kind)
        samples = []
        for k in range(12):
            kind = generator.choice(choices)
            values = start_sample if kind == "start" else sample(k, kind)
            time = offset + (k - 1) * h if k else offset  # the first doStep at the start time
            samples.append((max(offset, time), values))
        _replay(library, n, offset, start_sample, samples)
