"""An arm driven by a DC motor with armature inductance: a third-order plant of our own.

Not from the paper: the plant that shows the controller at order n = 3
(docs/general_order.md).  A rigid arm (its mass centre at distance lc from
the joint, under gravity) on the shaft of a permanent-magnet DC motor whose
armature has resistance R and inductance L; the input is the armature
voltage u (V), the output the arm angle y = x1 (rad, 0 = hanging down).

State x1 = angle (rad), x2 = rate (rad/s), x3 = armature current (A):

    dx1 = x2
    dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J                       (motion)
    dx3 = (u - R x3 - Ke x2) / L                                    (armature)

J is the inertia at the shaft (motor and arm), b the viscous friction, Kt
the torque constant and Ke the back-emf constant.  The output's third
derivative has the form (1) of the paper with n = 3:

    y''' = f(x) + g u,  g = Kt / (J L) > 0,
    f(x) = (-Kt (R x3 + Ke x2) / L - b dx2 - m gv lc cos(x1) x2) / J
    (:func:`motor_arm_f_g`), smooth in x: a well-posed tracking problem for
    the controller with inputs e, de, d2e (d2y = dx2).

Standard library only: this module travels inside the DcMotorArm FMU.  The
derivative takes its constants as one flat tuple built by
:func:`motor_arm_params`: ``(inv_J, b, m_gv_lc, Kt, inv_L, R, Ke)``.
"""
from __future__ import annotations

import math

_sin = math.sin
_cos = math.cos


def motor_arm_params(inertia: float, friction: float, mass: float, lc: float, gv: float,
                     kt: float, ke: float, resistance: float, inductance: float) -> tuple:
    """The constants tuple of :func:`motor_arm_derivative`."""
    return (1.0 / inertia, float(friction), mass * gv * lc, float(kt), 1.0 / inductance,
            float(resistance), float(ke))


def motor_arm_acceleration(x1: float, x2: float, x3: float, params: tuple) -> float:
    """d2y = dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J in rad/s2."""
    inv_j, b, m_gv_lc, kt = params[0], params[1], params[2], params[3]
    return (kt * x3 - b * x2 - m_gv_lc * _sin(x1)) * inv_j


def motor_arm_derivative(t: float, x: tuple, u: float, params: tuple) -> tuple:
    """(dx1, dx2, dx3) of the motor-driven arm; signature of ``plant_integration.rk4_advance_states``."""
    x1, x2, x3 = x
    inv_j, b, m_gv_lc, kt, inv_l, resistance, ke = params
    return (x2,
            (kt * x3 - b * x2 - m_gv_lc * _sin(x1)) * inv_j,
            (u - resistance * x3 - ke * x2) * inv_l)


def motor_arm_f_g(x1: float, x2: float, x3: float, params: tuple) -> tuple:
    """(f(x), g) with y''' = f(x) + g u: g = Kt / (J L) and

    f = (Kt (-R x3 - Ke x2) / L - b dx2 - m gv lc cos(x1) x2) / J.
    """
    inv_j, b, m_gv_lc, kt, inv_l, resistance, ke = params
    dx2 = motor_arm_acceleration(x1, x2, x3, params)
    f = (kt * (-resistance * x3 - ke * x2) * inv_l - b * dx2 - m_gv_lc * _cos(x1) * x2) * inv_j
    return f, kt * inv_l * inv_j
