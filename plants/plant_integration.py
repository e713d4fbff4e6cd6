"""Fixed-step classical Runge-Kutta (RK4) integration of a 2-state plant.

Standard library only: this module travels inside the plant FMUs
(InvertedPendulum, Manipulator) and is also imported by the in-process
oracle of the co-simulation master, so that both integrate the plant with
exactly the same arithmetic.

It runs once per communication step (about 10^5 times per simulation), so
it is written lean: plain floats and tuples, no numpy, no allocation beyond
the tuples returned by the derivative.
"""
from __future__ import annotations

import math

#: relative slack when splitting a communication step into internal steps:
#: a step that is an exact multiple of ``max_internal_step`` up to rounding
#: (1e-3 / 1e-4 = 10.000000000000002) is not split into one extra step.
SPLIT_TOLERANCE = 1e-12


def internal_step_count(step_size: float, max_internal_step: float) -> int:
    """Number n of equal RK4 steps over a communication step.

    ``n = ceil(step_size / max_internal_step - 1e-12)``, at least 1 for a
    positive ``step_size`` (0 for ``step_size == 0``), so that each internal
    step ``step_size / n`` is no larger than ``max_internal_step`` (up to a
    relative 1e-12).
    """
    if step_size <= 0.0:
        return 0
    n = math.ceil(step_size / max_internal_step - SPLIT_TOLERANCE)
    return n if n > 1 else 1


def rk4_advance(derivative, t, x1, x2, u, step_size, max_internal_step, params):
    """Advance ``(x1, x2)`` from time ``t`` to ``t + step_size`` with classical RK4.

    Parameters
    ----------
    derivative : callable ``(t, x1, x2, u, params) -> (dx1, dx2)``
        Right-hand side of the plant, e.g.
        ``pendulum_derivative`` of plants/inverted_pendulum/model.py or
        ``manipulator_derivative`` of plants/manipulator/model.py.
    t : float
        Time at the start of the communication step.
    x1, x2 : float
        State at ``t``.
    u : float
        Input, held constant over the whole communication step (zero-order
        hold, as in co-simulation).
    step_size : float
        Communication step size, >= 0 (0 returns the state unchanged).
    max_internal_step : float
        Upper bound (> 0) of the internal RK4 step: the communication step is
        split into ``n = ceil(step_size / max_internal_step - 1e-12)`` equal
        steps ``h = step_size / n``.
    params : tuple
        Passed through to ``derivative`` unchanged.

    Returns
    -------
    (x1, x2) : tuple of float
        State at ``t + step_size``.

    The internal step i starts at ``t + i * h`` (not at an accumulated sum),
    so the time grid has no drift.  No event handling: a right-hand side with
    a discontinuity (Coulomb friction) is integrated across it as it is.
    """
    n = internal_step_count(step_size, max_internal_step)
    if n == 0:
        return x1, x2
    h = step_size / n
    half = 0.5 * h
    sixth = h / 6.0
    for i in range(n):
        ti = t + i * h
        tm = ti + half
        a1, b1 = derivative(ti, x1, x2, u, params)
        a2, b2 = derivative(tm, x1 + half * a1, x2 + half * b1, u, params)
        a3, b3 = derivative(tm, x1 + half * a2, x2 + half * b2, u, params)
        a4, b4 = derivative(ti + h, x1 + h * a3, x2 + h * b3, u, params)
        x1 = x1 + sixth * (a1 + 2.0 * (a2 + a3) + a4)
        x2 = x2 + sixth * (b1 + 2.0 * (b2 + b3) + b4)
    return x1, x2


def rk4_advance_states(derivative, t, x, u, step_size, max_internal_step, params):
    """Advance the state tuple ``x`` (any number of states) like :func:`rk4_advance`.

    ``derivative(t, x, u, params) -> dx`` takes and returns tuples.  The same
    scheme and step split as :func:`rk4_advance` (which stays the lean
    2-state path of the pendulum and the manipulator); with a 2-state
    derivative both give the same numbers bit for bit.
    """
    n = internal_step_count(step_size, max_internal_step)
    if n == 0:
        return tuple(x)
    h = step_size / n
    half = 0.5 * h
    sixth = h / 6.0
    for i in range(n):
        ti = t + i * h
        tm = ti + half
        k1 = derivative(ti, x, u, params)
        k2 = derivative(tm, tuple([a + half * b for a, b in zip(x, k1)]), u, params)
        k3 = derivative(tm, tuple([a + half * b for a, b in zip(x, k2)]), u, params)
        k4 = derivative(ti + h, tuple([a + h * b for a, b in zip(x, k3)]), u, params)
        x = tuple([a + sixth * (b1 + 2.0 * (b2 + b3) + b4) for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)])
    return x
