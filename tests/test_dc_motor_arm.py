"""The third-order plant DcMotorArm and its closed loop with the order-3 controller.

The closed-loop check below is written from the equations (docs/general_order.md) with numpy and
scipy only: it shares no code with fmu_src/ or plants/.
"""
import math

import numpy as np
import pytest
from numpy.polynomial import polynomial as poly
from scipy.linalg import solve_continuous_lyapunov

from harness import scenario as scenarios
from harness.master import simulate
from plants import plant_integration
from plants.dc_motor_arm import model as dc_motor_arm_model
from plants.inverted_pendulum import model as inverted_pendulum_model


def test_n_state_rk4_gives_the_two_state_results_bit_for_bit():
    params = inverted_pendulum_model.pendulum_params(9.8, 1.0, 1.0, 0.5, 1.0)

    def as_vector(t, x, u, p):
        return inverted_pendulum_model.pendulum_derivative(t, x[0], x[1], u, p)

    x1, x2, x = 0.26, -0.1, (0.26, -0.1)
    for n in range(300):
        t, u = n * 4e-4, 3.0 * math.sin(n * 4e-4)
        x1, x2 = plant_integration.rk4_advance(inverted_pendulum_model.pendulum_derivative, t, x1, x2, u,
                                               4e-4, 1e-4, params)
        x = plant_integration.rk4_advance_states(as_vector, t, x, u, 4e-4, 1e-4, params)
        assert x == (x1, x2)


def test_the_plant_has_the_form_y3_equals_f_plus_g_u():
    params = dc_motor_arm_model.motor_arm_params(0.5, 0.2, 2.0, 0.25, 9.8, 0.5, 0.5, 1.0, 0.1)
    x, u, h = (0.4, -0.7, 1.3), 2.5, 1e-6
    f, g = dc_motor_arm_model.motor_arm_f_g(*x, params)
    assert g == pytest.approx(0.5 / (0.5 * 0.1))

    def acceleration_after(dt):  # d2y along the trajectory with u held
        dx = dc_motor_arm_model.motor_arm_derivative(0.0, x, u, params)
        moved = tuple(a + dt * b for a, b in zip(x, dx))
        return dc_motor_arm_model.motor_arm_acceleration(*moved, params)

    jerk = (acceleration_after(h) - acceleration_after(-h)) / (2 * h)
    assert jerk == pytest.approx(f + g * u, rel=1e-6)


# ------------------------------------------------ the closed loop, from the equations
def independent_closed_loop(scenario):
    """plant -> reference -> controller on the master's grid, written here from the equations."""
    plant = scenario.components["plant"].parameters
    J, b, m, lc, Kt, Ke, R, L = (plant[k] for k in ("J", "b", "m", "lc", "Kt", "Ke", "R", "L"))
    mgl = m * 9.8 * lc
    reference = scenario.components["reference"].parameters
    A, w = reference["amplitude"], reference["omega"]
    c = scenario.components["controller"].parameters
    n, sets, variant = c["order"], c["sets"], c["variant"]
    k = [c[f"k{i}"] for i in range(1, n + 1)]
    Q = np.diag([c[f"q{i}"] for i in range(1, n + 1)])
    kappa = np.array([c[f"kappa{i}"] for i in range(1, n + 1)])
    universe = np.array([c[f"E{i}"] for i in range(1, n + 1)])
    lam, lam_ce, s = c["lambda_e"], c["lambda_ce"], c["mf_slope"]
    gamma, gamma_w, m_theta, delta = c["gamma"], c["gamma_w"], c["m_theta"], c["delta"]

    companion = np.zeros((n, n))
    companion[:-1, 1:] = np.eye(n - 1)
    companion[-1, :] = -np.array(k[::-1])
    P = solve_continuous_lyapunov(companion.T, -Q)  # A^T P + P A = -Q  (30)
    PB = P[:, -1]

    def derivative(x, u):
        return np.array([x[1], (Kt * x[2] - b * x[1] - mgl * math.sin(x[0])) / J, (u - R * x[2] - Ke * x[1]) / L])

    def errors(t, x):
        ym = np.array([A * math.sin(w * t), A * w * math.cos(w * t), -A * w * w * math.sin(w * t)])
        y = np.array([x[0], x[1], derivative(x, 0.0)[1]])
        return ym - y

    def memberships(z, universe_i):
        c_l = -universe_i + 2 * universe_i * np.arange(1, sets) / sets
        rising = 1.0 / (1.0 + np.exp(-s * (z - c_l)))
        return np.concatenate([[1.0 - rising[0]], rising[:-1] - rising[1:], [rising[-1]]])

    x = np.array([plant["x1_start"], plant["x2_start"], plant["x3_start"]])
    e0 = errors(0.0, x)
    # Remark 3 (36): offset(t) = p(t) exp(-lam t) with offset^(i)(0) = e0_i: solve for p's coefficients
    derivative_rows = []
    for i in range(n):  # offset^(i)(0) = sum_j coefficient a_j * [d^i/dt^i t^j exp(-lam t)](0)
        derivative_rows.append([math.comb(i, j) * math.factorial(j) * (-lam) ** (i - j) if j <= i else 0.0
                                for j in range(n)])
    a = np.linalg.solve(np.array(derivative_rows), e0)
    offsets = [a]
    for _ in range(1, n):
        previous = offsets[-1]
        offsets.append(poly.polysub(poly.polyder(previous), lam * previous))

    theta, w_hat = np.full(sets ** n, c.get("theta0", 0.0)), 0.0
    h, steps = scenario.step, scenario.steps
    internal = math.ceil(h / 1e-4 - 1e-12)
    rows = []
    for step_index in range(steps + 1):
        t = step_index * h
        e = errors(t, x)
        E = e - np.array([poly.polyval(t, r) for r in offsets]) * math.exp(-lam * t)
        alpha = 1.0 - lam_ce * np.exp(-kappa * E * E) if variant == 1 else np.ones(n)
        z = np.clip(E / alpha, -universe, universe)
        xi = np.array([1.0])
        for i in range(n):
            xi = np.kron(xi, memberships(z[i], universe[i]))
        u = theta @ xi + (w_hat if variant == 3 else 0.0)
        rows.append((x[0], u, theta[0], E[2]))
        tau = E @ PB
        rate = gamma * tau * xi
        outward = ((theta > m_theta) & (tau > 0)) | ((theta < -m_theta) & (tau < 0))
        scale = np.where(theta > 0, 1.0 + (m_theta - theta) / delta, 1.0 + (m_theta + theta) / delta)
        theta = theta + h * np.where(outward, scale * rate, rate)
        if variant == 3:
            w_hat += h * gamma_w * tau
        hi = h / internal
        for j in range(internal):
            k1 = derivative(x, u)
            k2 = derivative(x + hi / 2 * k1, u)
            k3 = derivative(x + hi / 2 * k2, u)
            k4 = derivative(x + hi * k3, u)
            x = x + hi / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return np.array(rows)


@pytest.mark.parametrize("controller,sets", [("vud", 3), ("fae", 2)])
def test_master_run_matches_the_closed_loop_written_from_the_equations(fmu_paths, controller, sets):
    scenario = (scenarios.load("motor_arm").with_controller(controller).with_parameter("stop", 0.6)
                .with_parameter("controller.sets", sets))
    result = simulate(scenario, fmu_paths=fmu_paths)
    expected = independent_closed_loop(scenario)
    ours = np.column_stack([result.signal(name) for name in
                            ("plant.y", "controller.u", "controller.theta1", "controller.d2E")])
    assert ours.shape == expected.shape
    assert np.max(np.abs(expected[:, 1])) > 1.0 and np.max(np.abs(expected[:, 2])) > 1e-6  # it acts and learns
    for column, name in enumerate(("y", "u", "theta1", "d2E")):
        scale = np.max(np.abs(expected[:, column]))
        np.testing.assert_allclose(ours[:, column], expected[:, column], rtol=0, atol=1e-8 * scale, err_msg=name)
