"""Inverted pendulum on a cart, eq. (37) of Pan, Er, Huang, Wang (IEEE TFS 2011).

docs/model.md section 7 (the plants).  State x1 = pole angle (rad), x2 = its rate (rad/s),
input u = force on the cart (N), output y = x1:

    dx1 = x2                                                            (37)
    den = lp (4/3 - mp cos^2 x1 / (mc + mp))
    dx2 = (gv sin x1 - mp lp x2^2 cos x1 sin x1 / (mc + mp)) / den
          + (cos x1 / (mc + mp)) / den * u + d(t)                       (37)

with the disturbance (docs/model.md section 10, choice 10 (disturbance): it enters dx2 additively)

    d(t) = dist_gain * (3 cos 2t + 2 sin((0.09 t + 1) t))

dist_gain = 0 is case 1, dist_gain = 1 cases 2 and 3 (case 3: mp = 1).
For mc, mp > 0 the denominator is at least lp / 3 > 0: no singularity.

Standard library only: this module travels inside the InvertedPendulum FMU
and is imported by the in-process oracle of the co-simulation master.

Parameters representation
-------------------------
The derivative takes its constants as one flat tuple, built once by
:func:`pendulum_params` (tuple unpacking is the cheapest way to pass
constants to a Python function called 4 times per RK4 step).  Its layout,
``(gv, lp, mp_lp_over_mt, mp_over_mt, inv_mt, dist_gain)`` with
``mt = mc + mp``, holds precomputed products and is an implementation
detail: always build it with :func:`pendulum_params`.
"""
from __future__ import annotations

import math

_cos = math.cos
_sin = math.sin
FOUR_THIRDS = 4.0 / 3.0


def pendulum_params(gv: float, mc: float, mp: float, lp: float, dist_gain: float = 0.0) -> tuple:
    """The constants tuple of :func:`pendulum_derivative`.

    gv gravity (m/s2), mc cart mass (kg), mp pole mass (kg), lp pole
    half-length (m), dist_gain gain of the disturbance d(t) (1 = cases 2, 3 of docs/model.md
    section 8 (scenarios)).
    """
    mt = mc + mp
    return (float(gv), float(lp), mp * lp / mt, mp / mt, 1.0 / mt, float(dist_gain))


def pendulum_disturbance(t: float, dist_gain: float) -> float:
    """d(t) = dist_gain * (3 cos 2t + 2 sin((0.09 t + 1) t)) in rad/s2 (case 2 of docs/model.md
    section 8 (scenarios))."""
    if dist_gain == 0.0:
        return 0.0
    return dist_gain * (3.0 * _cos(2.0 * t) + 2.0 * _sin((0.09 * t + 1.0) * t))


def pendulum_derivative(t: float, x1: float, x2: float, u: float, params: tuple) -> tuple:
    """(dx1, dx2) of eq. (37) plus the disturbance d(t) in dx2.

    ``params`` comes from :func:`pendulum_params`.  Signature as required by
    ``plant_integration.rk4_advance``.
    """
    gv, lp, mp_lp_over_mt, mp_over_mt, inv_mt, dist_gain = params
    c = _cos(x1)
    s = _sin(x1)
    den = lp * (FOUR_THIRDS - mp_over_mt * c * c)  # (37)
    dx2 = (gv * s - mp_lp_over_mt * x2 * x2 * c * s + c * inv_mt * u) / den  # (37)
    if dist_gain != 0.0:  # d(t), docs/model.md section 10, choice 10 (disturbance): additive in dx2
        dx2 += dist_gain * (3.0 * _cos(2.0 * t) + 2.0 * _sin((0.09 * t + 1.0) * t))
    return x2, dx2


def oracle(p: dict) -> tuple:
    """(derivative, params, extra) of the oracle (harness/studies/oracle.py) for the FMU's parameters
    ``p``: extra(t, x1, x2) gives the outputs beyond y, dy."""
    params = pendulum_params(p["gv"], p["mc"], p["mp"], p["lp"], p["dist_gain"])

    def extra(t, x1, x2):
        return {"plant.d": pendulum_disturbance(t, p["dist_gain"])}

    return pendulum_derivative, params, extra
