"""The adaptive law (31), tau = [E, dE] P B with P of (30), and the fae estimator, through the
controller FMU, against formulas written here from the paper (not the project's afc_math).

Asymmetric gains (k1 != k2, q1 != q2, so p12 != p22; gamma_w != gamma; theta0 != 0), and a
projection bound small enough that theta crosses it on both sides.
"""
import math

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

from tests.fmu_helpers import Driven

GAINS = dict(k1=3.0, k2=0.5, q1=4.0, q2=9.0)
SLOPE, UNIVERSE = 7.0, 1.0


def p12_p22(k1, k2, q1, q2):
    """A^T P + P A = -Q (30) for A = [[0, 1], [-k2, -k1]], Q = diag(q1, q2)."""
    p = solve_continuous_lyapunov(np.array([[0.0, 1.0], [-k2, -k1]]).T, -np.diag([q1, q2]))
    return p[0, 1], p[1, 1]


def basis(x1, x2, alpha1=1.0, alpha2=1.0):
    """xi of (8) from (7) (saturated to [-E, E]) and the sigmoids; rule j = 2 (l1 - 1) + l2."""
    z1 = min(max(x1 / alpha1, -UNIVERSE), UNIVERSE)
    z2 = min(max(x2 / alpha2, -UNIVERSE), UNIVERSE)
    low = lambda z: 1.0 / (1.0 + math.exp(SLOPE * z))  # noqa: E731
    high = lambda z: 1.0 / (1.0 + math.exp(-SLOPE * z))  # noqa: E731
    return np.array([low(z1) * low(z2), low(z1) * high(z2), high(z1) * low(z2), high(z1) * high(z2)])


def controller(fmu_paths, name, **parameters):
    settings = dict(GAINS, lambda_e=0.0, mf_slope=SLOPE, E1=UNIVERSE, E2=UNIVERSE, **parameters)
    return Driven(fmu_paths["AdaptiveFuzzyController"], name).initialize(**settings)


THETAS = ("theta1", "theta2", "theta3", "theta4")


@pytest.mark.parametrize("variant", [1, 2, 3])
def test_one_step_of_the_adaptive_law_uses_p12_for_E_p22_for_dE_gamma_and_gamma_w(fmu_paths, variant):
    theta0, gamma, gamma_w, h, lambda_ce, kappa1, kappa2 = 0.7, 250.0, 40.0, 0.01, 0.9, 10.0, 4.0
    c = controller(fmu_paths, f"one_step_{variant}", variant=variant, theta0=theta0, gamma=gamma, gamma_w=gamma_w,
                   lambda_ce=lambda_ce, kappa1=kappa1, kappa2=kappa2)
    e, de = 0.2, -0.45  # E = e, dE = de (lambda_e = 0)
    c.set(e=e, de=de, ym=0.1, dym=0.3)
    if variant == 1:  # (23)
        alphas = (1 - lambda_ce * math.exp(-kappa1 * e * e), 1 - lambda_ce * math.exp(-kappa2 * de * de))
    else:
        alphas = (1.0, 1.0)
    xi = basis(e, de, *alphas)
    assert c.get("alpha1", "alpha2") == pytest.approx(alphas, abs=1e-15)
    assert c.get("u") == pytest.approx(theta0 * xi.sum(), abs=1e-14)  # (9), w_hat(0) = 0
    c.slave.doStep(0.0, h)
    p12, p22 = p12_p22(**GAINS)
    assert abs(p12 - p22) > 1.0  # a swap of p12 and p22 changes tau
    tau = e * p12 + de * p22  # [E, dE] P B
    expected_theta = theta0 + h * gamma * tau * xi  # (31) inside the bound
    np.testing.assert_allclose(c.get(*THETAS), expected_theta, rtol=0, atol=1e-13)
    expected_w = h * gamma_w * tau if variant == 3 else 0.0
    assert c.get("w_hat") == pytest.approx(expected_w, abs=1e-13)
    # the next communication point: u = theta^T xi (+ w_hat) with the stepped theta
    e, de = -0.1, 0.35
    c.set(e=e, de=de)
    if variant == 1:
        alphas = (1 - lambda_ce * math.exp(-kappa1 * e * e), 1 - lambda_ce * math.exp(-kappa2 * de * de))
    assert c.get("u") == pytest.approx(float(expected_theta @ basis(e, de, *alphas)) + expected_w, abs=1e-13)
    c.free()


def projected(theta, tau, xi, gamma, m_theta, delta):
    """dtheta of (31), written from the paper for a vector of rules."""
    rate = gamma * tau * xi
    factor = np.ones_like(theta)
    upper = (theta > m_theta) & (tau > 0)
    lower = (theta < -m_theta) & (tau < 0)
    factor[upper] = 1.0 + (m_theta - theta[upper]) / delta
    factor[lower] = 1.0 + (m_theta + theta[lower]) / delta
    return factor * rate


def test_the_projection_holds_theta_within_m_theta_plus_delta_from_both_sides(fmu_paths):
    """tau > 0 for 1 s drives the dominant theta_j above m_theta into the boundary layer,
    then tau < 0 for 1.5 s drives another below -m_theta: each step equals (31) computed here,
    theta passes m_theta + 0.9 delta and -(m_theta + 0.9 delta) and never leaves
    [-(m_theta + delta), m_theta + delta] (h gamma tau / delta < 1: Euler does not overshoot)."""
    m_theta, delta, gamma, h, theta0 = 0.5, 0.2, 1.0, 0.01, 0.05
    c = controller(fmu_paths, "projection", variant=2, m_theta=m_theta, delta=delta, gamma=gamma, theta0=theta0)
    p12, p22 = p12_p22(**GAINS)
    theta = np.full(4, theta0)
    history = [theta.copy()]
    phases = [((0.5, 0.3), 100), ((-0.5, -0.3), 150), ((0.5, -0.3), 100)]  # tau > 0, < 0, > 0
    n = 0
    for (e, de), count in phases:
        tau = e * p12 + de * p22
        assert h * gamma * abs(tau) / delta < 1.0
        for _ in range(count):
            c.set(e=e, de=de)
            c.slave.doStep(n * h, h)
            theta = theta + h * projected(theta, tau, basis(e, de), gamma, m_theta, delta)
            got = np.array(c.get(*THETAS))
            np.testing.assert_allclose(got, theta, rtol=0, atol=1e-13, err_msg=f"step {n}")
            history.append(got)
            n += 1
    history = np.array(history)
    bound = m_theta + delta
    assert history.max() > m_theta + 0.9 * delta  # the upper boundary layer was entered...
    assert history.min() < -(m_theta + 0.9 * delta)  # ...and the lower one
    assert np.all(np.abs(history) <= bound)  # and the bound holds from both sides
    # above m_theta with tau < 0 the plain law applies: theta4 falls back at the full rate
    assert history[100, 3] > m_theta and history[250, 3] < history[100, 3] - 0.01
    c.free()


@pytest.mark.parametrize("variant", [1, 2])
def test_the_state_input_ablation_feeds_the_state_to_the_fls_and_the_error_to_tau(fmu_paths, variant):
    """fls_input = 2 (Remark 4's ablation): xi from x = [ym - e, dym - de]; tau still from [E, dE]."""
    theta0, gamma, h, lambda_ce, kappa1, kappa2 = -0.4, 120.0, 0.01, 0.9, 10.0, 4.0
    c = controller(fmu_paths, f"state_input_{variant}", variant=variant, fls_input=2, theta0=theta0, gamma=gamma,
                   lambda_ce=lambda_ce, kappa1=kappa1, kappa2=kappa2)
    e, de, ym, dym = 0.15, -0.3, 0.4, -0.25
    x1, x2 = ym - e, dym - de  # 0.25, 0.05: the state, not the error
    c.set(e=e, de=de, ym=ym, dym=dym)
    if variant == 1:
        alphas = (1 - lambda_ce * math.exp(-kappa1 * x1 * x1), 1 - lambda_ce * math.exp(-kappa2 * x2 * x2))
    else:
        alphas = (1.0, 1.0)
    assert c.get("alpha1", "alpha2") == pytest.approx(alphas, abs=1e-15)
    c.slave.doStep(0.0, h)
    p12, p22 = p12_p22(**GAINS)
    expected = theta0 + h * gamma * (e * p12 + de * p22) * basis(x1, x2, *alphas)
    np.testing.assert_allclose(c.get(*THETAS), expected, rtol=0, atol=1e-13)
    c.free()
