"""The chatter monitor on u (fmu_src/chatter_monitor.py), pure: no FMU."""
import math

import pytest

from fmu_src import chatter_monitor as chatter


def feed(values, h):
    state = chatter.new_state()
    alarms = [k for k, u in enumerate(values) if chatter.update(state, u, h)]
    return state, alarms


@pytest.mark.parametrize("frequency", [0.5, 2.0, 8.0])
def test_statistic_is_the_frequency_of_a_sine(frequency):
    h = 1e-4
    values = [3.0 * math.sin(2 * math.pi * frequency * k * h) for k in range(int(6 / h))]
    state, alarms = feed(values, h)
    assert chatter.frequency(state) == pytest.approx(frequency, rel=0.05)
    assert alarms == []


def test_zigzag_warns_once_after_the_warmup():
    h = 4e-4
    values = [5.0 + 0.5 * (-1) ** k for k in range(int(3 / h))]
    state, alarms = feed(values, h)
    assert len(alarms) == 1
    assert alarms[0] * h == pytest.approx(chatter.WARMUP, abs=2 * h)
    assert chatter.frequency(state) == pytest.approx(2 * 0.5 / h / 5.0 / (2 * math.pi), rel=1e-3)


def test_no_verdict_during_warmup():
    h = 1e-4
    values = [(-1.0) ** k for k in range(int(0.9 * chatter.WARMUP / h))]
    assert feed(values, h)[1] == []


def test_averages_follow_time_not_steps():
    # the same u(t) sampled at two steps gives the same statistic
    slow, fast = (feed([2.0 + math.sin(3 * k * h) for k in range(int(4 / h))], h)[0] for h in (1e-3, 1e-4))
    assert chatter.frequency(slow) == pytest.approx(chatter.frequency(fast), rel=0.02)


def test_zero_steps_and_constant_u_are_quiet():
    state = chatter.new_state()
    assert not chatter.update(state, 1.0, 0.0) and state == chatter.new_state()
    state, alarms = feed([0.0] * 30000, 1e-4)
    assert alarms == [] and chatter.frequency(state) == 0.0


def test_warning_names_step_validated_steps_and_remedy():
    text = chatter.warning(feed([(-1.0) ** k for k in range(5000)], 4e-4)[0], 4e-4)
    assert "communication step 0.0004 s" in text
    for step in chatter.JACOBI_VALIDATED_STEP.values():
        assert f"{step:g} s" in text
    assert "smaller step" in text and "direct feedthrough" in text


def test_warning_says_what_to_try_with_exact_and_with_measured_inputs():
    """Chatter from a too-large step and chatter from sensor noise need different cures: the message names
    both cases, each with its own remedies (a smaller step does not cure measured noise)."""
    text = chatter.warning(feed([(-1.0) ** k for k in range(5000)], 1e-3)[0], 1e-3)
    exact, _, measured = text.partition("If e, de are measured")
    assert "If e, de are exact" in exact and "smaller step" in exact and "direct feedthrough" in exact
    assert "sensor noise" in measured and "a smaller step does not help" in measured
    for cure in ("alpha_min", "dead_zone", "sigma", "filter_time_constant", "variant 2 or 3"):
        assert cure in measured, cure
