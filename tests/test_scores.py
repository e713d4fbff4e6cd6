"""Score functions on signals with known answers (docs/model.md section 9 (scores))."""
import math

import numpy as np
import pytest

from harness import scores

T = 10.0
TIME = np.linspace(0.0, T, 100_001)


def test_iae_and_itae_of_a_decaying_exponential():
    e = np.exp(-TIME)
    zero = np.zeros_like(TIME)
    assert scores.iae(TIME, e, zero) == pytest.approx(1 - math.exp(-T), rel=1e-8)
    assert scores.itae(TIME, e, zero) == pytest.approx(1 - (T + 1) * math.exp(-T), rel=1e-8)


def test_error_norm_combines_e_and_de():
    e, de = 0.6 * np.ones_like(TIME), 0.8 * np.ones_like(TIME)
    assert scores.iae(TIME, e, de) == pytest.approx(T, rel=1e-12)
    assert scores.itae(TIME, e, de) == pytest.approx(T * T / 2, rel=1e-12)


def test_settling_time_of_a_decaying_exponential():
    e = np.exp(-TIME)
    ym = np.sin(TIME)  # max |ym| = 1: band 0.05
    assert scores.settling_time(TIME, e, ym) == pytest.approx(math.log(20.0), abs=2 * (TIME[1] - TIME[0]))


def test_settling_time_edge_cases():
    ym = np.sin(TIME)
    assert scores.settling_time(TIME, np.zeros_like(TIME), ym) == 0.0  # inside the band from the start
    assert scores.settling_time(TIME, np.ones_like(TIME), ym) == T  # never settles
    late = np.where(TIME > 9.0, 1.0, 0.0)  # leaves the band again: the last exit counts
    assert scores.settling_time(TIME, late, ym) == T


def test_control_energy_and_total_variation_of_a_sine():
    time = np.linspace(0.0, 2 * math.pi, 200_001)
    u = 3.0 * np.sin(time)
    assert scores.control_energy(time, u) == pytest.approx(9.0 * math.pi, rel=1e-9)
    assert scores.total_variation_rate(time, u) == pytest.approx(12.0 / (2 * math.pi), rel=1e-9)


def test_steady_state_errors_use_the_last_reference_period():
    time = np.linspace(0.0, 20.0, 200_001)
    ym, dym = 2.0 * np.sin(time), 2.0 * np.cos(time)
    e = np.where(time < 20 - 2 * math.pi - 0.01, 5.0, 0.1 * np.sin(time))  # large early, small at the end
    de = np.where(time < 20 - 2 * math.pi - 0.01, 5.0, 0.05)
    es1, es2 = scores.steady_state_errors(time, e, de, ym, dym)
    assert es1 == pytest.approx(100 * 0.1 / 2.0, rel=1e-6)
    assert es2 == pytest.approx(100 * 0.05 / 2.0, rel=1e-9)


def test_score_has_every_key():
    e = np.exp(-TIME)
    result = scores.score(TIME, e, -e, np.sin(TIME), np.cos(TIME), np.cos(TIME))
    assert tuple(result) == scores.SCORE_KEYS
    assert all(math.isfinite(v) for v in result.values())
