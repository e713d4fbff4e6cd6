"""The closed loop written again from the paper's equations, in this file alone, against the master.

Nothing here imports fmu_src, plants or harness/studies/oracle.py: the controller (Remark 3, (23),
(7), sigmoid memberships, (8), (9), (30) for n = 2, (31), the fae estimator of docs/model.md
section 6 (the three controllers)), the pendulum (37), the manipulator (38, 39), the reference and
RK4 are written from the paper as docs/model.md sections 1-8 (the problem to the scenarios) restate
it, vectorised over a batch of cases (one row per case).  The
sampled-data semantics are those of an embedded target and of our master: at each
communication point t_n the reference and the controller read the plant outputs at t_n
(direct feedthrough, no delay), u(t_n) is held over [t_n, t_n + h] while the plant is
integrated by RK4 in ceil(h / max_internal_step) equal steps, and theta, w_hat advance by
one explicit Euler step from E, dE, xi at t_n.  e(0), de(0) of Remark 3 are the errors at
the start time.

The parameters are deliberately asymmetric (k1 != k2, q1 != q2 so p12 != p22,
gamma_w != gamma, a projection bound the loop reaches), so swapped or mistyped terms show.
The FMUs get every parameter explicitly, so their defaults do not enter either.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import solve_continuous_lyapunov

from harness import scenario as scenarios
from harness.master import simulate

VARIANTS = {"vud": 1, "fixed": 2, "fae": 3}
HORIZON = 1.5  # s

# --- the cases: (scenario file, controller, plant parameters, controller parameters, step, max internal step)
ASYMMETRIC = dict(k1=3.0, k2=1.5, q1=8.0, q2=20.0, gamma=250.0, gamma_w=90.0, lambda_e=4.0, theta0=0.3)
PENDULUM_CONTROLLER = dict(ASYMMETRIC, E1=math.pi / 3, E2=1.2, mf_slope=7.0, lambda_ce=0.99, kappa1=10.0,
                           kappa2=6.0, m_theta=200.0, delta=5.0)
MANIPULATOR_CONTROLLER = dict(ASYMMETRIC, E1=math.pi, E2=2.5, mf_slope=1.5, lambda_ce=0.995, kappa1=10.0,
                              kappa2=8.0, m_theta=15.0, delta=3.0)  # a bound the loop reaches within 1.5 s
PENDULUM_PLANT = dict(gv=9.8, mc=1.0, lp=0.5, x1_start=math.pi / 12, x2_start=0.05)
MANIPULATOR_PLANT = dict(gv=9.8, lr=0.25, dr=2.0, cr=1.5, vr=0.3, mr0=5.0, mr1=4.0, x1_start=math.pi / 6,
                         x2_start=0.0)
CASES = {
    "pendulum": [("pendulum_case2", "vud", dict(PENDULUM_PLANT, mp=0.1, dist_gain=1.0)),
                 ("pendulum_case3", "fixed", dict(PENDULUM_PLANT, mp=1.0, dist_gain=1.0)),
                 ("pendulum_case2", "fae", dict(PENDULUM_PLANT, mp=0.3, dist_gain=0.7))],
    "manipulator": [("manipulator", "vud", MANIPULATOR_PLANT), ("manipulator", "fixed", MANIPULATOR_PLANT),
                    ("manipulator", "fae", dict(MANIPULATOR_PLANT, mr1=2.0))],
}
STEPS = {"pendulum": (4e-4, 2e-4), "manipulator": (2e-4, 1e-4)}  # (communication step, max internal step)
REFERENCE = {"pendulum": dict(amplitude=math.pi / 6, omega=1.0), "manipulator": dict(amplitude=1.0, omega=1.3)}


# ------------------------------------------------------------------ the paper, vectorised
def lyapunov_p12_p22(k1, k2, q1, q2):
    """P of A^T P + P A = -Q (30), A = [[0, 1], [-k2, -k1]] (n = 2): (p12, p22) per case."""
    p12, p22 = [], []
    for a1, a2, b1, b2 in zip(k1, k2, q1, q2):
        a = np.array([[0.0, 1.0], [-a2, -a1]])
        p = solve_continuous_lyapunov(a.T, -np.diag([b1, b2]))
        p12.append(p[0, 1])
        p22.append(p[1, 1])
    return np.array(p12), np.array(p22)


def controller_output(c, e, de, t, theta, w_hat, e0, de0):
    """u (9) with Remark 3, (23), (7), sigmoids, (8); also E, dE and xi (cases x 4)."""
    lam = c["lambda_e"]
    decay = np.exp(-lam * t)
    a0, a1 = e0, de0 + lam * e0
    big_e = e - (a0 + a1 * t) * decay  # Remark 3
    big_de = de - (a1 - lam * (a0 + a1 * t)) * decay
    vud = c["variant"] == 1
    alpha1 = np.where(vud, 1.0 - c["lambda_ce"] * np.exp(-c["kappa1"] * big_e ** 2), 1.0)  # (23)
    alpha2 = np.where(vud, 1.0 - c["lambda_ce"] * np.exp(-c["kappa2"] * big_de ** 2), 1.0)
    z1 = np.clip(big_e / alpha1, -c["E1"], c["E1"])  # (7), saturated to the universe
    z2 = np.clip(big_de / alpha2, -c["E2"], c["E2"])
    s = c["mf_slope"]
    low1, high1 = 1.0 / (1.0 + np.exp(s * z1)), 1.0 / (1.0 + np.exp(-s * z1))
    low2, high2 = 1.0 / (1.0 + np.exp(s * z2)), 1.0 / (1.0 + np.exp(-s * z2))
    xi = np.stack([low1 * low2, low1 * high2, high1 * low2, high1 * high2], axis=1)  # (8), l1 slowest
    u = np.sum(theta * xi, axis=1) + np.where(c["variant"] == 3, w_hat, 0.0)  # (9) (+ w_hat for fae)
    return u, big_e, big_de, xi


def adaptive_rate(c, theta, big_e, big_de, xi, p12, p22):
    """dtheta of (31) with its projection, and dw_hat = gamma_w tau for fae."""
    tau = (big_e * p12 + big_de * p22)[:, None]  # [E, dE] P B, B = [0, 1]^T
    m, delta = c["m_theta"][:, None], c["delta"][:, None]
    plain = c["gamma"][:, None] * tau * xi
    upper = (theta > m) & (tau > 0)
    lower = (theta < -m) & (tau < 0)
    rate = np.where(upper, (1.0 + (m - theta) / delta) * plain,
                    np.where(lower, (1.0 + (m + theta) / delta) * plain, plain))
    w_rate = np.where(c["variant"] == 3, c["gamma_w"] * tau[:, 0], 0.0)
    return rate, w_rate


def pendulum_rhs(p, t, x1, x2, u):
    """(37) with d(t) added to dx2."""
    mt = p["mc"] + p["mp"]
    c, s = np.cos(x1), np.sin(x1)
    den = p["lp"] * (4.0 / 3.0 - p["mp"] * c ** 2 / mt)
    d = p["dist_gain"] * (3.0 * np.cos(2.0 * t) + 2.0 * np.sin((0.09 * t + 1.0) * t))
    dx2 = (p["gv"] * s - p["mp"] * p["lp"] * x2 ** 2 * c * s / mt) / den + (c / mt) / den * u + d
    return x2, dx2


def manipulator_rhs(p, t, x1, x2, u):
    """(38) with J, d, mr(t) of (39); sgn(0) = 0."""
    mr = p["mr0"] + p["mr1"] * np.sin(t)
    inertia = 1.33 * mr * p["lr"] ** 2
    d = -(np.sign(x2) * p["cr"] + p["vr"] * x2) / inertia
    dx2 = -(p["dr"] * x2 + mr * p["gv"] * p["lr"] * np.cos(x1)) / inertia + u / inertia + d
    return x2, dx2


def rk4(rhs, p, t, x1, x2, u, h, max_internal):
    n = math.ceil(h / max_internal - 1e-12)
    k = h / n
    for i in range(n):
        ti = t + i * k
        a1, b1 = rhs(p, ti, x1, x2, u)
        a2, b2 = rhs(p, ti + k / 2, x1 + k / 2 * a1, x2 + k / 2 * b1, u)
        a3, b3 = rhs(p, ti + k / 2, x1 + k / 2 * a2, x2 + k / 2 * b2, u)
        a4, b4 = rhs(p, ti + k, x1 + k * a3, x2 + k * b3, u)
        x1 = x1 + k / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        x2 = x2 + k / 6 * (b1 + 2 * b2 + 2 * b3 + b4)
    return x1, x2


def independent_loop(plant_kind, cases, horizon):
    """{signal: (steps + 1) x cases} of the sampled-data closed loop."""
    h, max_internal = STEPS[plant_kind]
    rhs = pendulum_rhs if plant_kind == "pendulum" else manipulator_rhs
    controller_parameters = PENDULUM_CONTROLLER if plant_kind == "pendulum" else MANIPULATOR_CONTROLLER
    plant = {k: np.array([case[2][k] for case in cases], dtype=float) for k in cases[0][2]}
    c = {k: np.full(len(cases), v, dtype=float) for k, v in controller_parameters.items()}
    c["variant"] = np.array([VARIANTS[case[1]] for case in cases])
    p12, p22 = lyapunov_p12_p22(c["k1"], c["k2"], c["q1"], c["q2"])
    amplitude, omega = REFERENCE[plant_kind]["amplitude"], REFERENCE[plant_kind]["omega"]
    steps = round(horizon / h)
    x1, x2 = plant["x1_start"].copy(), plant["x2_start"].copy()
    theta = np.repeat(c["theta0"][:, None], 4, axis=1)
    w_hat = np.zeros(len(cases))
    e0, de0 = amplitude * math.sin(0.0) - x1, amplitude * omega * math.cos(0.0) - x2  # latched at t = 0
    out = {name: np.empty((steps + 1, len(cases))) for name in ("y", "dy", "e", "de", "u", "E", "dE", "w_hat")}
    out.update({f"theta{j}": np.empty((steps + 1, len(cases))) for j in range(1, 5)})
    for n in range(steps + 1):
        t = n * h
        e = amplitude * math.sin(omega * t) - x1
        de = amplitude * omega * math.cos(omega * t) - x2
        u, big_e, big_de, xi = controller_output(c, e, de, t, theta, w_hat, e0, de0)
        for name, value in (("y", x1), ("dy", x2), ("e", e), ("de", de), ("u", u), ("E", big_e), ("dE", big_de),
                            ("w_hat", w_hat)):
            out[name][n] = value
        for j in range(4):
            out[f"theta{j + 1}"][n] = theta[:, j]
        if n == steps:
            break
        rate, w_rate = adaptive_rate(c, theta, big_e, big_de, xi, p12, p22)
        theta = theta + h * rate  # explicit Euler over the communication step
        w_hat = w_hat + h * w_rate
        x1, x2 = rk4(rhs, plant, t, x1, x2, u, h, max_internal)  # u held
    return out


# ------------------------------------------------------------------ the master, same parameters
def master_run(plant_kind, case, fmu_paths, horizon):
    name, controller, plant = case
    h, max_internal = STEPS[plant_kind]
    controller_parameters = PENDULUM_CONTROLLER if plant_kind == "pendulum" else MANIPULATOR_CONTROLLER
    scenario = scenarios.configure(name, controller, h, horizon)
    for key, value in dict(plant, max_internal_step=max_internal).items():
        scenario = scenario.with_parameter(f"plant.{key}", value)
    for key, value in controller_parameters.items():
        scenario = scenario.with_parameter(f"controller.{key}", value)
    for key, value in REFERENCE[plant_kind].items():
        scenario = scenario.with_parameter(f"reference.{key}", value)
    return simulate(scenario, fmu_paths=fmu_paths)


SIGNALS = {"y": "plant.y", "dy": "plant.dy", "e": "reference.e", "de": "reference.de", "u": "controller.u",
           "E": "controller.E", "dE": "controller.dE", "w_hat": "controller.w_hat",
           **{f"theta{j}": f"controller.theta{j}" for j in range(1, 5)}}
# absolute; measured (printed with -s): states and errors within 2e-15, u, theta, w_hat within 1e-12
TOLERANCE = {"y": 1e-13, "dy": 1e-13, "e": 1e-13, "de": 1e-13, "E": 1e-13, "dE": 1e-13, "u": 1e-10, "w_hat": 1e-10,
             **{f"theta{j}": 1e-10 for j in range(1, 5)}}


@pytest.fixture(scope="module")
def independent():
    return {kind: independent_loop(kind, cases, HORIZON) for kind, cases in CASES.items()}


@pytest.mark.parametrize("plant_kind,index", [(kind, i) for kind, cases in CASES.items() for i in range(len(cases))],
                         ids=[f"{case[0]}-{case[1]}" for cases in CASES.values() for case in cases])
def test_the_master_runs_the_papers_closed_loop(fmu_paths, independent, plant_kind, index):
    case = CASES[plant_kind][index]
    result = master_run(plant_kind, case, fmu_paths, HORIZON)
    ours = independent[plant_kind]
    worst = {}
    for name, dotted in SIGNALS.items():
        expected = ours[name][:, index]
        got = result.signal(dotted)
        assert got.shape == expected.shape, name
        worst[name] = float(np.max(np.abs(got - expected)))
    print(f"{case[0]}/{case[1]}: largest differences " + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    for name, difference in worst.items():
        assert difference <= TOLERANCE[name], (name, difference, worst)
    # the case exercises what it is meant to: a real transient, asymmetric gains
    assert np.max(np.abs(ours["u"][:, index])) > 1.0
    if case[1] == "fae":
        assert np.max(np.abs(ours["w_hat"][:, index])) > 0.05


def test_the_manipulator_cases_reach_the_projection_bound(independent):
    """m_theta = 15 in the manipulator cases: theta enters the boundary layer (31) and stays
    within m_theta + delta, so the projection branches are part of the comparison above."""
    theta = np.stack([independent["manipulator"][f"theta{j}"] for j in range(1, 5)])
    bound = MANIPULATOR_CONTROLLER["m_theta"]
    assert np.max(np.abs(theta)) > bound
    assert np.max(np.abs(theta)) <= bound + MANIPULATOR_CONTROLLER["delta"] + 1e-9


def test_the_lyapunov_solution_has_p12_different_from_p22():
    p12, p22 = lyapunov_p12_p22(*(np.array([ASYMMETRIC[k]]) for k in ("k1", "k2", "q1", "q2")))
    assert abs(p12[0] - p22[0]) > 0.5
