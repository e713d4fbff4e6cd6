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


# ------------------------------------------------ Model Exchange: friction modes
# docs/model_exchange.md.  In Model Exchange the host's solver integrates (38, 39) and the
# Coulomb term switches only at located events: the link is in one of three modes,
# slipping forwards (+1), slipping backwards (-1) or stuck (0).  While slipping, the Coulomb
# sign is the mode's (not sgn(x2)), so the right-hand side is smooth between events; while
# stuck, static friction balances the applied torque and the link rests (dx1 = dx2 = 0).

SLIP_BACKWARD = -1
STICK = 0
SLIP_FORWARD = 1
#: rad/s: the slip indicator is z_slip = mode x2 + ZERO_VELOCITY, so that it starts strictly
#: positive when slipping begins at x2 = 0 (every host sees its later sign change) and the
#: event fires once x2 has crossed zero by this much (the wrong Coulomb sign acts for
#: ZERO_VELOCITY / |dx2|, some 1e-11 s at the paper's parameters).  The event update counts
#: the link as come to rest once z_slip < ZERO_VELOCITY / 2: a host whose root finder stops a
#: hair before the crossing (z_slip = +1e-15) still gets the mode change, not the same event again.
ZERO_VELOCITY = 1e-10
#: N.m: the link breaks away once |F| is within this of cr (z_stick <= TORQUE_TOLERANCE), and
#: sticks only where |F| < cr - TORQUE_TOLERANCE (so z_stick starts > 0): the same margin for
#: the break-away event located a hair early.
TORQUE_TOLERANCE = 1e-9


def manipulator_applied_torque(t: float, x1: float, u: float, params: tuple) -> float:
    """F = u - mr(t) gv lr cos x1: the torque on the link at rest besides friction (38, 39).

    The same arithmetic as the torque of :func:`manipulator_derivative` at x2 = 0.
    """
    gv_lr, mr0, mr1 = params[0], params[4], params[5]
    mr = mr0 + mr1 * _sin(t)  # (39)
    return u - mr * gv_lr * _cos(x1)


def manipulator_rest_mode(force: float, cr: float) -> int:
    """The mode of the link at rest (x2 = 0) under the applied torque F (39): stuck while static
    friction can hold it, |F| < cr; else slipping in the direction of F (forwards at F = 0,
    which only cr = 0 lets through: then the Coulomb term is 0 and the sign does not matter).

    With the margin TORQUE_TOLERANCE, so that z_stick = cr - |F| is > 0 when the link sticks and
    its crossing of zero (break-away) is a sign change every host sees."""
    if abs(force) < cr - TORQUE_TOLERANCE:
        return STICK
    return SLIP_FORWARD if force >= 0.0 else SLIP_BACKWARD


def manipulator_still_slipping(x2: float, mode: int) -> bool:
    """A slipping link has not come to rest: z_slip = mode x2 + ZERO_VELOCITY > ZERO_VELOCITY / 2."""
    return mode * x2 + ZERO_VELOCITY > 0.5 * ZERO_VELOCITY


def manipulator_friction_mode(t: float, x1: float, x2: float, u: float, params: tuple, mode: int) -> int:
    """The friction mode after an event (or at the initial state, from ``mode`` = STICK).

    A slipping link keeps slipping while its slip indicator is positive (x2 has not crossed
    zero); when it has, the link is at rest and :func:`manipulator_rest_mode` decides (the FMU
    then sets x2 = 0).  A stuck link (or the initial state) with x2 != 0 slips in the direction
    of x2; with x2 = 0 the rest mode decides (break-away when |F| reaches cr).
    """
    if mode != STICK:
        if manipulator_still_slipping(x2, mode):
            return mode
    elif x2 != 0.0:
        return SLIP_FORWARD if x2 > 0.0 else SLIP_BACKWARD
    return manipulator_rest_mode(manipulator_applied_torque(t, x1, u, params), params[3])


def manipulator_event_update(t: float, x1: float, x2: float, u: float, params: tuple, mode: int) -> tuple:
    """(mode, x2) after an event: the new friction mode (:func:`manipulator_friction_mode`) and
    the rate, set to 0 where a slipping link came to rest (its slip indicator reached zero)."""
    new_mode = manipulator_friction_mode(t, x1, x2, u, params, mode)
    if mode != STICK and not manipulator_still_slipping(x2, mode):
        x2 = 0.0
    return new_mode, x2


def manipulator_mode_derivative(t: float, x1: float, x2: float, u: float, params: tuple, mode: int) -> tuple:
    """(dx1, dx2) of (38, 39) in a friction mode: slipping, the Coulomb sign is the mode's
    (the same numbers as :func:`manipulator_derivative` wherever sgn(x2) = mode); stuck, the
    link rests: (x2, 0) with x2 = 0."""
    if mode == STICK:
        return x2, 0.0
    gv_lr, inertia_factor, dr_plus_vr, cr, mr0, mr1 = params
    mr = mr0 + mr1 * _sin(t)  # (39)
    torque = u - dr_plus_vr * x2 - mr * gv_lr * _cos(x1)  # (38), viscous part of d (39)
    if mode > 0:  # Coulomb part of d (39) with the mode's sign
        torque -= cr
    else:
        torque += cr
    return x2, torque / (inertia_factor * mr)  # J = 1.33 mr lr^2 (39)


def manipulator_event_indicators(t: float, x1: float, x2: float, u: float, params: tuple, mode: int) -> tuple:
    """(z_slip, z_stick), both > 0 between events.

    z_slip = mode x2 + ZERO_VELOCITY: crosses zero when a slipping link comes to rest (ZERO_VELOCITY
    while stuck); z_stick = cr - |F| while stuck: crosses zero at break-away (cr while slipping).
    """
    cr = params[3]
    if mode == STICK:
        return ZERO_VELOCITY, cr - abs(manipulator_applied_torque(t, x1, u, params))
    return mode * x2 + ZERO_VELOCITY, cr


def oracle(p: dict) -> tuple:
    """(derivative, params, extra) of the oracle (harness/studies/oracle.py) for the FMU's parameters
    ``p``: extra(t, x1, x2) gives the outputs beyond y, dy."""
    params = manipulator_params(p["gv"], p["lr"], p["dr"], p["cr"], p["vr"], p["mr0"], p["mr1"])

    def extra(t, x1, x2):
        mr = manipulator_payload(t, p["mr0"], p["mr1"])
        inertia = manipulator_inertia(mr, p["lr"])
        return {"plant.d": manipulator_friction(x2, inertia, p["cr"], p["vr"]), "plant.mr": mr}

    return manipulator_derivative, params, extra
