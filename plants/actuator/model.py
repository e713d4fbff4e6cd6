"""The actuator's limits: saturation and a rate limit (docs/model.md section 13).

The command c (the controller's u, sampled and delayed by plants/sampled_chain.py) is saturated,

    v = min(max(c, -u_max), u_max)          (u_max = 0: no saturation)               (A1)

and the applied input r follows v at a bounded rate, the law of Modelica's
``Modelica.Blocks.Nonlinear.SlewRateLimiter`` (Rising = R, Falling = -R, derivative time
constant Td):

    dr/dt = min(max((v - r) / Td, -R), R)   (R = 0: no rate limit, r = v)            (A2)

With v held over an interval, (A2) has a closed-form solution, which co-simulation uses
(:func:`slew`): r moves at the rate R towards v until |v - r| = R Td, then approaches v
exponentially with time constant Td.  Model Exchange integrates (A2) itself (:func:`slew_rate`).

Standard library only: this module travels inside the Actuator FMU.
"""
from __future__ import annotations

import math

_exp = math.exp


def saturate(command: float, limit: float) -> float:
    """v of (A1); ``limit`` = 0: ``command`` itself."""
    if limit == 0.0:
        return command
    if command > limit:
        return limit
    if command < -limit:
        return -limit
    return command


def slew_rate(applied: float, target: float, rate: float, time_constant: float) -> float:
    """dr/dt of (A2)."""
    speed = (target - applied) / time_constant
    if speed > rate:
        return rate
    if speed < -rate:
        return -rate
    return speed


def slew(applied: float, target: float, duration: float, rate: float, time_constant: float) -> float:
    """r after ``duration`` of (A2) with the target v held: the exact solution."""
    gap = target - applied
    band = rate * time_constant  # |v - r| within it: dr/dt = (v - r) / Td
    if -band <= gap <= band:
        return target - gap * _exp(-duration / time_constant)
    ramp = ((gap if gap > 0.0 else -gap) - band) / rate  # time at the limit rate to reach the band
    sign = 1.0 if gap > 0.0 else -1.0
    if duration <= ramp:
        return applied + sign * rate * duration
    return target - sign * band * _exp(-(duration - ramp) / time_constant)
