"""The Model Exchange model functions (docs/model_exchange.md) against the co-simulation ones, in Python.

* the adaptive law's rates (afc_math.adaptation_rates) are the rates the sampled-data step
  (afc_math.adapted_weights) multiplies by the step, bit for bit, projection included;
* the manipulator's mode derivative is (38, 39) wherever the mode is sgn(x2); its friction modes
  follow the physics: stuck while |F| < cr, slipping in the direction of F otherwise, the slip
  indicator starts positive and the event update settles in one pass.
"""
import math
import random

import pytest

from fmu_src import afc_math
from plants.manipulator import model

PARAMS = model.manipulator_params(9.8, 0.25, 2.0, 1.5, 0.3, 5.0, 4.0)


def test_the_rates_are_what_the_sampled_data_step_multiplies_by_the_step():
    rng = random.Random(7)
    projected = 0
    for _ in range(2000):
        rules = rng.choice([2, 4, 9, 27])
        theta = [rng.uniform(-260.0, 260.0) for _ in range(rules)]
        xi = [rng.random() for _ in range(rules)]
        tau, h = rng.uniform(-3.0, 3.0), rng.choice([1e-4, 1e-3, 0.013])
        rates = afc_math.adaptation_rates(theta, tau, xi, 300.0, 200.0, 5.0)
        assert afc_math.adapted_weights(theta, tau, xi, 300.0, 200.0, 5.0, h) == [t + h * r for t, r in zip(theta, rates)]
        projected += sum(abs(t) > 200.0 and r != 300.0 * tau * b for t, r, b in zip(theta, rates, xi))
    assert projected > 100


def test_the_projection_is_continuous_where_it_switches():
    """(31) needs no event: the rate is continuous at |theta_j| = M_theta and at tau = 0."""
    for theta in (200.0, -200.0):
        for tau in (0.7, -0.7):
            inside = afc_math.adaptation_rates([theta], tau, [0.4], 300.0, 200.0, 5.0)[0]
            outside = afc_math.adaptation_rates([math.copysign(200.0 + 1e-9, theta)], tau, [0.4], 300.0, 200.0, 5.0)[0]
            assert outside == pytest.approx(inside, rel=1e-9)
    assert afc_math.adaptation_rates([203.0], 0.0, [0.4], 300.0, 200.0, 5.0) == [0.0]


def test_the_mode_derivative_is_the_model_wherever_the_mode_is_the_sign_of_x2():
    rng = random.Random(3)
    for _ in range(2000):
        t, x1, u = rng.uniform(0, 20), rng.uniform(-4, 4), rng.uniform(-30, 30)
        x2 = rng.choice([-1, 1]) * rng.uniform(1e-12, 10.0)
        mode = model.SLIP_FORWARD if x2 > 0 else model.SLIP_BACKWARD
        assert model.manipulator_mode_derivative(t, x1, x2, u, PARAMS, mode) == model.manipulator_derivative(
            t, x1, x2, u, PARAMS)
    assert model.manipulator_mode_derivative(1.0, 0.3, 0.0, 5.0, PARAMS, model.STICK) == (0.0, 0.0)


@pytest.mark.parametrize("u,expected", [(0.0, model.STICK), (1.4, model.STICK), (-1.4, model.STICK),
                                        (1.6, model.SLIP_FORWARD), (-1.6, model.SLIP_BACKWARD)])
def test_at_rest_the_link_sticks_while_static_friction_holds_it(u, expected):
    x1 = math.pi / 2  # gravity has no moment: F = u
    assert model.manipulator_applied_torque(0.0, x1, u, PARAMS) == pytest.approx(u, abs=1e-14)
    assert model.manipulator_friction_mode(0.0, x1, 0.0, u, PARAMS, model.STICK) == expected
    z_slip, z_stick = model.manipulator_event_indicators(0.0, x1, 0.0, u, PARAMS, expected)
    assert z_slip > 0.0 and z_stick > 0.0  # both strictly positive when the mode starts


def test_a_slipping_link_that_crossed_zero_is_set_at_rest_and_the_update_settles_in_one_pass():
    for x2, u in ((-1e-6, 0.7), (-1e-6, 3.0), (-1e-6, -3.0), (-0.6e-10, 0.7)):
        mode, x2_after = model.manipulator_event_update(0.0, math.pi / 2, x2, u, PARAMS, model.SLIP_FORWARD)
        assert x2_after == 0.0 and mode == model.manipulator_rest_mode(u, 1.5)
        assert model.manipulator_event_update(0.0, math.pi / 2, x2_after, u, PARAMS, mode) == (mode, x2_after)
    # still slipping: nothing changes (an event of the host's, e.g. an input jump)
    assert model.manipulator_event_update(0.0, 0.3, 0.2, -9.0, PARAMS, model.SLIP_FORWARD) == (model.SLIP_FORWARD, 0.2)
    # a root finder that stops a hair before the crossing (z_slip = +1e-15) still gets the change
    x2 = -model.ZERO_VELOCITY + 1e-15
    assert model.manipulator_event_update(0.0, math.pi / 2, x2, 0.7, PARAMS, model.SLIP_FORWARD) == (model.STICK, 0.0)
