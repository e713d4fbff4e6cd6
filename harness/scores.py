"""Scores of one run (docs/model.md section 9 (scores)), on the recorded communication grid.

Trapezoidal integration; ||e|| = sqrt(e^2 + de^2 + ...), the norm of the whole
error vector (e, de, d2e, ... up to the plant's order; sqrt(e^2 + de^2) for the paper's plants).  Pure functions of numpy
arrays so they can be tested on signals with known answers.

A score that a run cannot give is None, never a number that looks like one: es1 and es2 on a
horizon shorter than the reference period they are taken over, ts of a run that has not settled by
its stop time.  :func:`undefined_reason` is the one place that decides it for a run's horizon, and
:func:`why_none` says why a score is None; the run command (text and JSON ``null``), the tables, the
claims and the report's header all ask them.
"""
from __future__ import annotations

import math

import numpy as np

SCORE_KEYS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec", "umax", "tv_u")
REFERENCE_PERIOD = 2 * math.pi  # of ym = A sin t, every scenario's reference: the window of es1, es2
PERIOD_SCORES = ("es1_pct", "es2_pct")  # taken over the last reference period [T - 2 pi, T]
SETTLING_BAND = 0.05  # ts: |e| within 5 % of max|ym| (docs/model.md section 10, choice 13 (settling time))
#: ts: |e| must stay inside the band for at least this long before the stop time, one period of the
#: reference ym = A sin t, so that every phase of the motion is tracked inside the band (choice 13)
SETTLING_DWELL = REFERENCE_PERIOD
NOT_SETTLED = "not settled"


def dwell_text(dwell: float | None = None) -> str:
    """The settling dwell for people: "one reference period (2 pi s)" or its length in seconds."""
    dwell = SETTLING_DWELL if dwell is None else dwell
    return "one reference period (2 pi s)" if math.isclose(dwell, REFERENCE_PERIOD) else f"{dwell:.6g} s"


def settling_text() -> str:
    """How ts is read (the constants SETTLING_BAND and SETTLING_DWELL, choice 13), for reports."""
    return (f"ts is the earliest time after which |e| <= {100 * SETTLING_BAND:g} % of max|ym| until the stop time T, "
            f"provided that leaves at least {dwell_text()} inside the band; else the run is *not settled within "
            "the horizon*")
#: what each score is, for reports (docs/model.md section 9 (scores)); units: harness/units.py score_units
DEFINITIONS = {
    "ts": f"settling time: the earliest time after which |e| <= {100 * SETTLING_BAND:g} % of max|ym| until the stop "
          f"time T, provided that leaves at least {dwell_text()} inside the band (not settled: no such time)",
    "es1_pct": "steady-state error of e: 100 max|e| / max|ym| over the last reference period [T - 2 pi, T]",
    "es2_pct": "steady-state error of de: 100 max|de| / max|dym| over the same window",
    "ITAE": "integral of t ||e|| dt over [0, T], ||e|| = sqrt(e^2 + de^2 (+ d2e^2 for order 3)), its terms "
            "taken as numbers in the unit of e",
    "IAE": "integral of ||e|| dt over [0, T]",
    "Ec": "control energy: integral of u^2 dt over [0, T]",
    "umax": "largest |u|",
    "tv_u": "total variation of u per second, sum |u(k+1) - u(k)| / T (chattering)",
}


def undefined_reason(metric: str, start: float, stop: float, period: float = REFERENCE_PERIOD) -> str | None:
    """Why score ``metric`` is not defined for a run over [start, stop] s; None when it is.

    es1 and es2 are taken over the last reference period [T - 2 pi, T]: a shorter horizon has none.
    Every other score is defined on any horizon (ts may still be "not settled": :func:`why_none`).
    """
    if metric in PERIOD_SCORES and stop - start < period - 1e-9:
        length = "2 pi s" if period == REFERENCE_PERIOD else f"{period:.6g} s"
        return (f"the horizon {stop - start:.6g} s is shorter than the reference period, {length}, "
                "over which es1 and es2 are taken")
    return None


def why_none(metric: str, start: float, stop: float) -> str:
    """Why a run over [start, stop] s has no value (None) for ``metric``."""
    reason = undefined_reason(metric, start, stop)
    if reason is not None:
        return reason
    if metric == "ts":
        return (f"|e| does not stay inside the {100 * SETTLING_BAND:g} % band of max|ym| for {dwell_text()} "
                f"before the stop time {stop:g} s")
    return "the run gave no value"


def value_text(metric: str, value, start: float, stop: float, digits: str = ".6g") -> str:
    """A score for people: the number, ``not settled`` (ts) or ``n/a`` (not defined on the horizon)."""
    if value is not None:
        return format(value, digits)
    return NOT_SETTLED if metric == "ts" and undefined_reason(metric, start, stop) is None else "n/a"


def trapezoid(values: np.ndarray, time: np.ndarray) -> float:
    return float(np.trapezoid(values, time)) if hasattr(np, "trapezoid") else float(np.trapz(values, time))


def error_norm(e: np.ndarray, de: np.ndarray, *higher: np.ndarray) -> np.ndarray:
    """||e|| = sqrt(e^2 + de^2 + d2e^2 + ...): the whole error vector (``higher`` = d2e, ...)."""
    norm = np.hypot(e, de)
    for derivative in higher:
        norm = np.hypot(norm, derivative)
    return norm


def itae(time, e, de, *higher) -> float:
    """ITAE = int_0^T t ||e|| dt."""
    return trapezoid(time * error_norm(e, de, *higher), time)


def iae(time, e, de, *higher) -> float:
    """IAE = int_0^T ||e|| dt."""
    return trapezoid(error_norm(e, de, *higher), time)


def control_energy(time, u) -> float:
    """Ec = int_0^T u^2 dt."""
    return trapezoid(u * u, time)


def settling_time(time, e, ym, fraction: float = SETTLING_BAND, dwell: float = SETTLING_DWELL) -> float | None:
    """ts: the earliest time after which |e| <= fraction * max|ym| until T, when |e| then stays inside
    the band for at least ``dwell`` (docs/model.md section 10, choice 13 (settling time)).

    The start time if |e| stays inside the band from the start (and the horizon is at least ``dwell``);
    None (not settled within the horizon) if the error enters the band for the last time less than
    ``dwell`` before T, or at the last sample only: the run shows no time after which the error stays
    small for a whole reference period.
    """
    band = fraction * float(np.max(np.abs(ym)))
    outside = np.flatnonzero(np.abs(e) > band)
    settled = 0 if outside.size == 0 else outside[-1] + 1
    if settled + 1 >= len(time):  # outside at the last sample, or inside at the last sample only
        return None
    if time[-1] - time[settled] < dwell * (1 - 1e-12):  # inside the band for less than the dwell
        return None
    return float(time[settled])


def steady_state_errors(time, e, de, ym, dym, period: float = REFERENCE_PERIOD) -> tuple:
    """(es1_pct, es2_pct): 100 max|e|, 100 max|de| over [T - period, T], over max|ym|, max|dym|;
    (None, None) when the run is shorter than ``period`` (:func:`undefined_reason`)."""
    if undefined_reason("es1_pct", float(time[0]), float(time[-1]), period) is not None:
        return None, None
    window = time >= time[-1] - period - 1e-12
    es1 = 100.0 * float(np.max(np.abs(e[window]))) / float(np.max(np.abs(ym)))
    es2 = 100.0 * float(np.max(np.abs(de[window]))) / float(np.max(np.abs(dym)))
    return es1, es2


def total_variation_rate(time, u) -> float:
    """Total variation of u per second: sum |u_k+1 - u_k| / T (chattering)."""
    duration = float(time[-1] - time[0])
    return float(np.sum(np.abs(np.diff(u)))) / duration if duration > 0 else 0.0


def score(time, e, de, ym, dym, u, higher=()) -> dict:
    """Every score of docs/model.md section 9 (scores) for one run; ``higher`` = (d2e, ...) for plants of
    order > 2.  A score the run cannot give is None (:func:`why_none` says why)."""
    es1, es2 = steady_state_errors(time, e, de, ym, dym)
    norm = error_norm(e, de, *higher)  # once for ITAE and IAE: the values itae() and iae() give, bit for bit
    return {
        "ts": settling_time(time, e, ym),
        "es1_pct": es1,
        "es2_pct": es2,
        "ITAE": trapezoid(time * norm, time),
        "IAE": trapezoid(norm, time),
        "Ec": control_energy(time, u),
        "umax": float(np.max(np.abs(u))),
        "tv_u": total_variation_rate(time, u),
    }


def score_run(result) -> dict:
    """Scores of a master RunResult (full communication grid)."""
    higher = tuple(result.role(role) for role in ("d2e", "d3e") if role in result.scenario.signals)
    return score(result.time, result.role("e"), result.role("de"), result.role("ym"),
                 result.role("dym"), result.role("u"), higher)
