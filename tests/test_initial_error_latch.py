"""The initial-error latch rule (fmu_src/initial_error_latch.py), pure: no FMU."""
import math

import pytest

from fmu_src import initial_error_latch as latch

H = 1e-4


def signal(t, n=2, omega=1.3, amplitude=-0.26, phase=0.4):
    """x = [e, de, d2e, d3e][:n] of e = amplitude cos(omega t + phase)."""
    return [amplitude * omega ** k * math.cos(omega * t + phase + k * math.pi / 2) for k in range(n)]


def fresh(n=2, time=0.0, sample=None):
    state = [0.0] * latch.size(n)
    latch.start(state, time, sample if sample is not None else signal(time, n))
    return state


@pytest.mark.parametrize("n", [2, 3, 4])
@pytest.mark.parametrize("h", [1e-5, 1e-4, 4e-4, 1e-2])
def test_samples_of_a_smooth_signal_are_consistent(n, h):
    for k in range(50):
        assert latch.consistent(signal(k * h, n), signal((k + 1) * h, n), h)


@pytest.mark.parametrize("n,placeholder_index", [(n, i) for n in (2, 3, 4) for i in range(n)])
def test_one_placeholder_component_is_inconsistent(n, placeholder_index):
    earlier = signal(0.0, n)
    earlier[placeholder_index] = 0.0  # start value of that input
    assert not latch.consistent(earlier, signal(H, n), H)


def test_consistent_host_keeps_the_start_inputs_and_decides_at_the_first_pair():
    state = fresh()
    assert latch.observe(state, 0.0, signal(0.0)) == 0  # first doStep: same time, same inputs
    assert latch.observe(state, H, signal(H)) == latch.DECIDED
    assert state[latch.OPEN] == 0 and state[latch.ORIGIN] == 0.0
    assert latch.latched(state) == signal(0.0)
    assert latch.warning(state, ("e", "de")) is None


def test_jacobi_without_propagation_relatches_once_at_the_first_true_sample():
    # exitInitializationMode: start values (0, 0); first doStep: the reference's outputs from
    # its own placeholder inputs (e = ym(0) - 0 = 0, de right); then true (delayed) samples.
    state = fresh(sample=[0.0, 0.0])
    assert latch.observe(state, 0.0, [0.0, 0.52]) == latch.RELATCHED
    assert latch.observe(state, H, signal(H)) == latch.RELATCHED
    assert latch.observe(state, 2 * H, signal(2 * H)) == latch.DECIDED
    assert latch.latched(state) == signal(H) and state[latch.ORIGIN] == H
    message = latch.warning(state, ("e", "de"))
    assert "rejected e = 0, de = 0 at t = 0 " in message
    assert f"kept e = {signal(H)[0]:.9g}, de = {signal(H)[1]:.9g} at t = 0.0001" in message
    assert "moved 2 times" in message and "initial_error = 2" in message


def test_inputs_that_change_at_the_start_time_show_placeholders():
    state = fresh(sample=[0.0, 0.0])
    assert latch.observe(state, 0.0, signal(0.0)) == latch.RELATCHED
    assert state[latch.ORIGIN] == 0.0 and latch.latched(state) == signal(0.0)
    assert latch.observe(state, H, signal(H)) == latch.DECIDED
    assert "rejected e = 0, de = 0 at t = 0 " in latch.warning(state, ("e", "de"))


def test_once_decided_a_jump_never_relatches():
    state = fresh()
    latch.observe(state, 0.0, signal(0.0))
    latch.observe(state, H, signal(H))
    before = list(state)
    assert latch.observe(state, 2 * H, [5.0, -3.0]) == 0  # a reference step at t > 0
    assert state == before


def test_identical_samples_neither_decide_nor_relatch():
    state = fresh(sample=[0.3, 0.0])
    for k in range(3):
        assert latch.observe(state, k * H, [0.3, 0.0]) == 0
    assert state[latch.OPEN] == latch.CHECK_STEPS - 3


def test_window_ends_without_a_consistent_pair():
    state = fresh(sample=[0.0, 0.0])
    events = [latch.observe(state, k * H, [(-1.0) ** k, 0.0]) for k in range(1, latch.CHECK_STEPS + 1)]
    assert all(e & latch.RELATCHED for e in events)
    assert events[-1] & latch.DECIDED and not any(e & latch.DECIDED for e in events[:-1])
    assert latch.observe(state, 99.0, [7.0, 7.0]) == 0
    message = latch.warning(state, ("e", "de"))
    assert f"moved {latch.CHECK_STEPS} times" in message and "no later pair" in message


def test_first_order_error_uses_only_the_same_time_rule():
    state = fresh(n=1, sample=[0.0])
    assert latch.observe(state, 0.0, [0.5]) == latch.RELATCHED
    assert latch.observe(state, H, [0.1]) == 0  # no derivative: nothing to compare
    assert latch.latched(state) == [0.5]


def test_pinned_latch_is_decided():
    state = [0.0] * latch.size(2)
    latch.pin(state, 1.5, [0.1, -0.2, 9.0, 9.0])
    assert state[latch.OPEN] == 0 and state[latch.ORIGIN] == 1.5 and latch.latched(state) == [0.1, -0.2]
    assert latch.observe(state, 1.5, [3.0, 3.0]) == 0 and latch.warning(state, ("e", "de")) is None


def test_absolute_floor_accepts_round_off_of_a_zero_error():
    state = fresh(sample=[0.0, 0.0])
    assert latch.observe(state, 0.0, [0.0, 0.0]) == 0
    assert latch.observe(state, H, [1e-12, 0.0]) == latch.DECIDED


def test_placeholders_after_good_start_inputs_keep_the_start_inputs():
    # fmpy's SSP simulator: consistent start values at initialisation, then its connectors
    # hand 0 for two steps, then the true (one-step delayed) samples
    state = fresh()
    assert latch.observe(state, 0.0, [0.0, 0.0]) == latch.RELATCHED
    assert latch.observe(state, H, [0.0, 0.0]) == 0
    assert latch.observe(state, 2 * H, signal(2 * H)) == latch.RELATCHED | latch.DECIDED
    assert latch.latched(state) == signal(0.0) and state[latch.ORIGIN] == 0.0
    assert latch.warning(state, ("e", "de")) is None
