"""The controller math against the paper (docs/model.md sections 1-6 (the controller))."""
import math
import random

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

from fmu_src import afc_math


def test_lyapunov_p_matches_paper():
    # k = (2, 1), Q = diag(10, 10) -> P = [[15, 5], [5, 5]]  (paper, below (30))
    assert afc_math.lyapunov_p((2.0, 1.0), (10.0, 10.0)) == ((15.0, 5.0), (5.0, 5.0))


@pytest.mark.parametrize("k1,k2,q1,q2", [(2, 1, 10, 10), (3.5, 0.7, 2, 9), (1, 4, 1, 1)])
def test_lyapunov_p_solves_the_lyapunov_equation(k1, k2, q1, q2):
    a = np.array([[0.0, 1.0], [-k2, -k1]])
    q = np.diag([q1, q2])
    expected = solve_continuous_lyapunov(a.T, -q)
    assert np.allclose(afc_math.lyapunov_p((k1, k2), (q1, q2)), expected, rtol=1e-12)


def test_contraction_factor_at_zero_and_far():
    assert afc_math.contraction_factor(0.0, 0.99, 10.0) == pytest.approx(0.01, abs=1e-15)
    assert afc_math.contraction_factor(0.0, 0.995, 10.0) == pytest.approx(0.005, abs=1e-15)
    assert afc_math.contraction_factor(1e3, 0.99, 10.0) == 1.0


@pytest.mark.parametrize("z", [-1e6, -50.0, -1.0, -1e-9, 0.0, 0.3, 2.0, 1e6])
@pytest.mark.parametrize("slope", [1.5, 7.0])
def test_membership_functions_sum_to_one_and_stay_finite(z, slope):
    low, high = afc_math.membership_low(z, slope), afc_math.membership_high(z, slope)
    assert math.isfinite(low) and math.isfinite(high)
    assert 0.0 <= low <= 1.0 and 0.0 <= high <= 1.0
    assert low + high == pytest.approx(1.0, abs=1e-15)


def test_membership_is_a_sigmoid_crossing_at_one_half():
    assert afc_math.membership_high(0.0, 7.0) == 0.5
    assert afc_math.membership_high(0.1, 7.0) == pytest.approx(1 / (1 + math.exp(-0.7)), rel=1e-15)


def test_fuzzy_basis_sums_to_one_and_orders_rules_l1_slowest():
    pair = ((0.0,), (0.0,))  # m = 2: one boundary at 0 per input
    xi = afc_math.fuzzy_basis((5.0, -5.0), 7.0, pair)  # z1 high, z2 low -> rule (2,1) = j 3
    assert sum(xi) == pytest.approx(1.0, abs=1e-14)
    assert max(range(4), key=lambda j: xi[j]) == 2
    rng = random.Random(1)
    for _ in range(200):
        xi = afc_math.fuzzy_basis((rng.uniform(-3, 3), rng.uniform(-3, 3)), rng.choice([1.5, 7.0]), pair)
        assert sum(xi) == pytest.approx(1.0, abs=1e-14)


def test_normalized_input_saturates_to_the_universe():
    e1 = math.pi / 3
    assert afc_math.normalized_input(1.0, 0.01, e1) == e1
    assert afc_math.normalized_input(-1.0, 0.01, e1) == -e1
    assert afc_math.normalized_input(0.001, 0.01, e1) == pytest.approx(0.1)


@pytest.mark.parametrize("e0,de0", [(0.3, -0.2), (-math.pi / 12, 0.0), (0.0, 1.0)])
def test_modified_error_starts_at_zero(e0, de0):
    error, error_rate = afc_math.modified_error((e0, de0), 0.0, (e0, de0), 0.0, 5.0)
    assert error == 0.0 and error_rate == pytest.approx(0.0, abs=1e-15)


def test_modified_error_derivative_is_consistent():
    e0, de0, lam = 0.4, -0.3, 5.0
    def offset(t):
        e, _ = afc_math.modified_error((0.0, 0.0), t, (e0, de0), 0.0, lam)
        return -e
    for t in (0.0, 0.1, 0.7, 2.0):
        _, rate = afc_math.modified_error((0.0, 0.0), t, (e0, de0), 0.0, lam)
        h = 1e-6
        assert -rate == pytest.approx((offset(t + h) - offset(t - h)) / (2 * h), abs=1e-7)


def test_modified_error_off_when_lambda_e_is_zero():
    assert afc_math.modified_error((0.3, 0.2), 1.0, (0.5, 0.1), 0.0, 0.0) == (0.3, 0.2)


def test_projection_keeps_theta_below_bound_under_adversarial_tau():
    gamma, m_theta, delta, step = 300.0, 200.0, 5.0, 1e-4
    rng = random.Random(7)
    theta = [0.0, 150.0, -150.0, 199.0]
    largest = 0.0
    for n in range(400_000):
        # long pushes outward, then random bursts: tau as large as the loop can make it
        tau = 50.0 if (n // 50_000) % 2 == 0 else rng.uniform(-80.0, 80.0)
        for j in range(4):
            xi = 1.0 if j == n % 4 else rng.random()
            theta[j] += step * afc_math.projected_rate(theta[j], tau, xi, gamma, m_theta, delta)
            largest = max(largest, abs(theta[j]))
    assert largest > m_theta  # the push did reach the boundary layer
    assert largest < m_theta + delta


def test_projection_is_the_plain_law_inside_the_bound():
    assert afc_math.projected_rate(10.0, 2.0, 0.5, 300.0, 200.0, 5.0) == 300.0
    # outside and pushing out: scaled down, zero at the outer edge of the layer
    assert afc_math.projected_rate(205.0, 2.0, 0.5, 300.0, 200.0, 5.0) == 0.0
    # outside but pulling back in: plain law
    assert afc_math.projected_rate(205.0, -2.0, 0.5, 300.0, 200.0, 5.0) == -300.0


def test_variants_differ_as_specified():
    values = dict(order=2, sets=2, lambda_e=5.0, fls_input=1, lambda_ce=0.99, kappa1=10.0, kappa2=10.0,
                  E1=math.pi / 3, E2=math.pi / 3, mf_slope=7.0, k1=2.0, k2=1.0, q1=10.0, q2=10.0)
    theta = (1.0, -2.0, 3.0, 4.0)
    outputs = {variant: afc_math.controller_output((0.1, 0.05), (0.0, 0.0), 0.3, theta, 0.7,
                                                   afc_math.controller_parameters(dict(values, variant=variant),
                                                                                  (0.2, 0.0), 0.0))
               for variant in (1, 2, 3)}
    vud, fixed, fae = outputs[1], outputs[2], outputs[3]
    assert vud[2][0] < 1.0 and fixed[2][0] == 1.0 and fae[2][0] == 1.0
    assert fae[0] == pytest.approx(fixed[0] + 0.7, abs=1e-15)
    assert vud[0] != fixed[0]
