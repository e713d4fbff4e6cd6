"""Single-link manipulator with friction and a varying payload, eqs. (38, 39)
of Pan, Er, Huang, Wang (IEEE TFS 2011); docs/model.md section 7 (the plants).

State x1 = link angle (rad), x2 = its rate (rad/s), input u = joint torque
(N.m), output y = x1:

    dx1 = x2                                                        (38)
    dx2 = -(dr x2 + mr gv lr cos x1) / J + u / J + d                (38)
    J   = 1.33 mr lr^2                                              (39)
    d   = -(sgn(x2) cr + vr x2) / J      (friction, sgn(0) = 0)      (39)
    mr(t) = mr0 + mr1 sin t              (payload; paper 5 + 4 sin t) (39)

The payload must stay positive: mr1 < mr0 (with mr1 >= 0).

Coulomb friction and fixed-step RK4
-----------------------------------
``sgn(x2)`` makes dx2 jump by ``2 cr / J`` where x2 changes sign.  The
plant FMU integrates with fixed-step RK4 and no event handling (no zero
crossing of x2 is located), so:

* where x2 crosses zero transversally, the one internal step that contains
  the crossing is integrated with a right-hand side that is discontinuous
  inside it: that step has a local error O(h) instead of O(h^5), and the
  global error from a finite number of crossings is O(h) per crossing.
* where the arm sticks (|u - mr gv lr cos x1| < cr, so static friction would
  hold it), the exact (Filippov) solution has x2 = 0, but sgn(0) = 0 is never
  held: x2 chatters around 0 within O(h cr / J) at the internal-step scale h,
  the sign of the Coulomb term flipping between RK4 stages or steps, and x1
  creeps at a rate of the same order instead of standing still (e.g. x1 =
  pi/2, u = 0.5 N.m held: |x2| <= 1.8 h rad/s, x1 drifts by about 0.8 h rad
  in 2 s, for h = 1e-3 ... 1e-5 s).
* in both situations the fixed-step result converges only to first order in
  the internal step (not fourth order); keep ``max_internal_step`` small
  (default 1e-4 s) and compare against a reference that handles the event
  (or keep x2 away from 0) when checking accuracy.

Standard library only: this module travels inside the Manipulator FMU and is
imported by the in-process oracle of the co-simulation master.

Parameters representation
-------------------------
:func:`manipulator_derivative` takes its constants as one flat tuple built by
:func:`manipulator_params`; its layout ``(gv_lr, inertia_factor, dr_plus_vr,
cr, mr0, mr1)`` with ``gv_lr = gv lr`` and ``inertia_factor = 1.33 lr^2``
is an implementation detail: always build it with :func:`manipulator_params`.
"""
from __future__ import annotations

import math

_cos = math.cos
_sin = math.sin
INERTIA_COEFFICIENT = 1.33  # J = 1.33 mr lr^2  (39)


def manipulator_params(gv: float, lr: float, dr: float, cr: float, vr: float,
                       mr0: float, mr1: float) -> tuple:
    """The constants tuple of :func:`manipulator_derivative`.

    gv gravity (m/s2), lr link length (m), dr damping (N.m.s/rad), cr Coulomb
    friction torque (N.m), vr viscous friction (N.m.s/rad), payload
    mr(t) = mr0 + mr1 sin t (kg).
    """
    return (gv * lr, INERTIA_COEFFICIENT * lr * lr, float(dr + vr), float(cr),
            float(mr0), float(mr1))


def manipulator_payload(t: float, mr0: float, mr1: float) -> float:
    """mr(t) = mr0 + mr1 sin t in kg  (39); the paper: 5 + 4 sin t."""
    return mr0 + mr1 * _sin(t)


def manipulator_inertia(mr: float, lr: float) -> float:
    """J = 1.33 mr lr^2 in kg.m2  (39)."""
    return INERTIA_COEFFICIENT * mr * lr * lr


def sgn(x: float) -> float:
    """Sign function with sgn(0) = 0 (and sgn(NaN) = 0)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


def manipulator_friction(x2: float, inertia: float, cr: float, vr: float) -> float:
    """d = -(sgn(x2) cr + vr x2) / J in rad/s2  (39): Coulomb plus viscous friction.

    Always opposes the motion: sign(d) = -sign(x2), d = 0 at x2 = 0.
    """
    return -(sgn(x2) * cr + vr * x2) / inertia


def manipulator_derivative(t: float, x1: float, x2: float, u: float, params: tuple) -> tuple:
    """(dx1, dx2) of eq. (38) with J, d, mr of (39).

    ``params`` comes from :func:`manipulator_params`.  Signature as required
    by ``plant_integration.rk4_advance``.  Algebraically
    dx2 = (u - (dr + vr) x2 - mr gv lr cos x1 - sgn(x2) cr) / J.
    """
    gv_lr, inertia_factor, dr_plus_vr, cr, mr0, mr1 = params
    mr = mr0 + mr1 * _sin(t)  # (39)
    torque = u - dr_plus_vr * x2 - mr * gv_lr * _cos(x1)  # (38), viscous part of d (39)
    if x2 > 0.0:  # Coulomb part of d (39), sgn(0) = 0
        torque -= cr
    elif x2 < 0.0:
        torque += cr
    return x2, torque / (inertia_factor * mr)  # J = 1.33 mr lr^2 (39)
