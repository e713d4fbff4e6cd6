"""Scores of one run (docs/model.md section 9 (scores)), on the recorded communication grid.

Trapezoidal integration; ||e|| = sqrt(e^2 + de^2 + ...), the norm of the whole
error vector (e, de, d2e, ... up to the plant's order; sqrt(e^2 + de^2) for the paper's plants).  Pure functions of numpy
arrays so they can be tested on signals with known answers.
"""
from __future__ import annotations

import math

import numpy as np

SCORE_KEYS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec", "umax", "tv_u")


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


def settling_time(time, e, ym, fraction: float = 0.05) -> float:
    """ts: the earliest time after which |e| <= fraction * max|ym| until T
    (docs/model.md section 10, choice 13 (settling time)).

    0 if |e| stays inside the band from the start; T (the last time) if the
    last sample is outside it, i.e. the run never settles.
    """
    band = fraction * float(np.max(np.abs(ym)))
    outside = np.flatnonzero(np.abs(e) > band)
    if outside.size == 0:
        return float(time[0])
    last = outside[-1]
    if last + 1 >= len(time):
        return float(time[-1])
    return float(time[last + 1])


def steady_state_errors(time, e, de, ym, dym, period: float = 2 * math.pi) -> tuple[float, float]:
    """(es1_pct, es2_pct): 100 max|e|, 100 max|de| over [T - period, T], over max|ym|, max|dym|."""
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
    order > 2."""
    es1, es2 = steady_state_errors(time, e, de, ym, dym)
    return {
        "ts": settling_time(time, e, ym),
        "es1_pct": es1,
        "es2_pct": es2,
        "ITAE": itae(time, e, de, *higher),
        "IAE": iae(time, e, de, *higher),
        "Ec": control_energy(time, u),
        "umax": float(np.max(np.abs(u))),
        "tv_u": total_variation_rate(time, u),
    }


def score_run(result) -> dict:
    """Scores of a master RunResult (full communication grid)."""
    higher = tuple(result.role(role) for role in ("d2e", "d3e") if role in result.scenario.signals)
    return score(result.time, result.role("e"), result.role("de"), result.role("ym"),
                 result.role("dym"), result.role("u"), higher)
