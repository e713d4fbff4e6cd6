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
    assert scores.settling_time(TIME, np.ones_like(TIME), ym) is None  # never settles: not the stop time
    late = np.where(TIME > 9.0, 1.0, 0.0)  # leaves the band again: the last exit counts
    assert scores.settling_time(TIME, late, ym) is None
    last_only = np.where(TIME < T, 1.0, 0.0)  # inside at the last sample only: no time it stays inside
    assert scores.settling_time(TIME, last_only, ym) is None
    two_last = np.where(TIME < TIME[-2], 1.0, 0.0)  # inside over the last step only: shorter than the dwell
    assert scores.settling_time(TIME, two_last, ym) is None
    assert scores.settling_time(TIME, two_last, ym, dwell=0.0) == TIME[-2]  # no dwell: settled over that step


@pytest.mark.parametrize("dwell", [2 * math.pi, 1.5, 4.0])
def test_settling_needs_the_error_to_stay_in_the_band_for_the_dwell(dwell):
    """ts counts only when |e| stays inside the band for at least the dwell (one reference period by default)
    before the stop time: entering it just before T is not settling."""
    ym = np.sin(TIME)
    for enters in (T - dwell - 0.01, T - dwell + 0.01):
        e = np.where(TIME < enters, 1.0, 0.0)
        found = scores.settling_time(TIME, e, ym, dwell=dwell)
        if enters <= T - dwell:
            assert found == pytest.approx(enters, abs=2 * (TIME[1] - TIME[0])), (dwell, enters)
        else:
            assert found is None, (dwell, enters, found)
    assert scores.SETTLING_DWELL == scores.REFERENCE_PERIOD
    e = np.where(TIME < T - 0.57, 1.0, 0.0)  # enters 0.57 s before the end: not settled with the default dwell
    assert scores.settling_time(TIME, e, ym) is None and scores.score(
        TIME, e, np.zeros_like(TIME), ym, np.cos(TIME), TIME)["ts"] is None


def test_whether_a_score_is_defined_is_decided_in_one_place():
    """es1, es2 need one reference period; ts may be 'not settled'; never a number instead."""
    assert scores.undefined_reason("es1_pct", 0.0, 2 * math.pi) is None
    assert scores.undefined_reason("es2_pct", 0.0, 6.0) == (
        "the horizon 6 s is shorter than the reference period, 2 pi s, over which es1 and es2 are taken")
    assert all(scores.undefined_reason(m, 0.0, 0.3) is None for m in scores.SCORE_KEYS if m not in scores.PERIOD_SCORES)
    short = np.linspace(0.0, 0.3, 301)
    result = scores.score(short, np.ones_like(short), np.ones_like(short), np.sin(short), np.cos(short), short)
    assert result["es1_pct"] is None and result["es2_pct"] is None and result["ts"] is None
    assert all(isinstance(result[m], float) for m in ("ITAE", "IAE", "Ec", "umax", "tv_u"))
    assert scores.why_none("ts", 0.0, 0.3) == ("|e| does not stay inside the 5 % band of max|ym| for one reference "
                                               "period (2 pi s) before the stop time 0.3 s")
    assert [scores.value_text(m, result[m], 0.0, 0.3) for m in ("ts", "es1_pct", "Ec")] == [
        "not settled", "n/a", format(result["Ec"], ".6g")]


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
    time = np.linspace(0.0, 20.0, 20_001)
    e = np.exp(-time)
    result = scores.score(time, e, -e, np.sin(time), np.cos(time), np.cos(time))
    assert tuple(result) == scores.SCORE_KEYS
    assert all(math.isfinite(v) for v in result.values())
