"""The manipulator's closed loop in continuous time, solved here by scipy apart from the master, against
Model Exchange (harness/me_master.py) and the stuck intervals docs/model_exchange_accuracy.md lists.

The model of docs/model.md sections 1-7: the controller without a hold (u of (9) with Remark 3, (23),
(7), the sigmoid memberships, (8), theta of (31) with its projection, P of (30) from scipy's Lyapunov
solver), the manipulator (38, 39) with its Coulomb friction as a Filippov system: slipping forwards or
backwards the Coulomb sign is the mode's; at rest (x2 = 0) the link sticks while the applied torque
F = u - mr gv lr cos x1 has |F| < cr (static friction holds it: dx1 = dx2 = 0) and breaks away in the
direction of F when |F| reaches cr. scipy's Radau locates every mode change (the rest event x2 = 0
while slipping, the break-away event |F| = cr while stuck) and its dense output gives the solution on
the scenario's output grid, where TV(u)/s is summed as harness/scores.py does. Nothing here imports
fmu_src, plants or the master: the parameters come from the scenario file and docs/model.md's defaults
(gv = 9.8 m/s2, theta0 = 0).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import solve_continuous_lyapunov

from harness.fmu_build import native as build_native
from harness.me_master import DEFAULT_RTOL
from harness.studies import claims

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from tests.conftest import ROOT

SCENARIO = tomllib.loads((ROOT / "harness" / "scenarios" / "manipulator.toml").read_text())
PLANT = {"gv": 9.8, **SCENARIO["components"]["plant"]["parameters"]}
CONTROLLER = {"theta0": 0.0, **SCENARIO["components"]["controller"]["parameters"]}
REFERENCE = SCENARIO["components"]["reference"]["parameters"]
STEP, STOP = SCENARIO["experiment"]["step"], SCENARIO["experiment"]["stop"]
RTOL = 1e-8  # Radau; 1e-10 gives the same TV(u)/s within 1e-7 and the same mode changes within 1e-6 s
#: our Model Exchange run against this solution: TV(u)/s within this (its rtol 1e-10 against Radau's 1e-8)
TV_AGREEMENT = 1e-5
#: s: a mode change of Model Exchange against this solution's (where the applied torque reaches cr depends on the
#: whole state, so on both tolerances)
EVENT_AGREEMENT = 1e-5


def lyapunov_p(k1, k2, q1, q2):
    """P of A^T P + P A = -Q (30), A = [[0, 1], [-k2, -k1]] (n = 2)."""
    return solve_continuous_lyapunov(np.array([[0.0, 1.0], [-k2, -k1]]).T, -np.diag([q1, q2]))


class ClosedLoop:
    """The continuous-time loop of one controller (``vud`` or ``fixed``) as functions of (t, x), x = (x1, x2,
    theta1..4); numpy's functions so that the same code runs on one point and on the whole grid."""

    def __init__(self, controller: str):
        c, p = CONTROLLER, PLANT
        self.c, self.p, self.vud = c, p, controller == "vud"
        amplitude, omega = REFERENCE["amplitude"], REFERENCE["omega"]
        self.reference = lambda t: (amplitude * np.sin(omega * t), amplitude * omega * np.cos(omega * t))
        ym0, dym0 = self.reference(0.0)
        self.e0, self.de0 = ym0 - p["x1_start"], dym0 - p["x2_start"]  # Remark 3: the errors at the start
        big_p = lyapunov_p(c["k1"], c["k2"], c["q1"], c["q2"])
        self.p12, self.p22 = big_p[0, 1], big_p[1, 1]

    def control(self, t, x1, x2, theta):
        """(u, E, dE, xi) of (9) with Remark 3, (23), (7), the sigmoids and (8); ``theta`` of shape (4, ...)."""
        c = self.c
        ym, dym = self.reference(t)
        e, de = ym - x1, dym - x2
        lam = c["lambda_e"]
        a0, a1 = self.e0, self.de0 + lam * self.e0
        decay = np.exp(-lam * t)
        big_e = e - (a0 + a1 * t) * decay  # Remark 3
        big_de = de - (a1 - lam * (a0 + a1 * t)) * decay
        alpha1 = 1.0 - c["lambda_ce"] * np.exp(-c["kappa1"] * big_e ** 2) if self.vud else 1.0  # (23)
        alpha2 = 1.0 - c["lambda_ce"] * np.exp(-c["kappa2"] * big_de ** 2) if self.vud else 1.0
        z1 = np.clip(big_e / alpha1, -c["E1"], c["E1"])  # (7), saturated to the universe
        z2 = np.clip(big_de / alpha2, -c["E2"], c["E2"])
        s = c["mf_slope"]
        low1, high1 = 1.0 / (1.0 + np.exp(s * z1)), 1.0 / (1.0 + np.exp(-s * z1))
        low2, high2 = 1.0 / (1.0 + np.exp(s * z2)), 1.0 / (1.0 + np.exp(-s * z2))
        xi = (low1 * low2, low1 * high2, high1 * low2, high1 * high2)  # (8), e's set slowest
        u = sum(theta[j] * xi[j] for j in range(4))  # (9)
        return u, big_e, big_de, xi

    def theta_rate(self, theta, big_e, big_de, xi):
        """dtheta of (31) with its projection: tau = [E, dE] P B, B = [0, 1]^T."""
        c = self.c
        tau = big_e * self.p12 + big_de * self.p22
        m, delta = c["m_theta"], c["delta"]
        rates = []
        for j in range(4):
            plain = c["gamma"] * tau * xi[j]
            if theta[j] > m and tau > 0:
                plain *= 1.0 + (m - theta[j]) / delta
            elif theta[j] < -m and tau < 0:
                plain *= 1.0 + (m + theta[j]) / delta
            rates.append(plain)
        return rates

    def applied_torque(self, t, x1, u):
        """(F, mr): the torque on the link besides friction, F = u - mr gv lr cos x1 (38, 39)."""
        p = self.p
        mr = p["mr0"] + p["mr1"] * np.sin(t)
        return u - mr * p["gv"] * p["lr"] * np.cos(x1), mr

    def derivative(self, mode: int):
        """f(t, x) of one Filippov mode: slipping (+1, -1, the Coulomb sign the mode's) or stuck (0)."""
        p = self.p

        def f(t, x):
            u, big_e, big_de, xi = self.control(t, x[0], x[1], x[2:])
            rates = self.theta_rate(x[2:], big_e, big_de, xi)
            if mode == 0:
                return [0.0, 0.0, *rates]
            force, mr = self.applied_torque(t, x[0], u)
            inertia = 1.33 * mr * p["lr"] ** 2  # (39)
            return [x[1], (force - (p["dr"] + p["vr"]) * x[1] - mode * p["cr"]) / inertia, *rates]
        return f

    def force_at(self, t, x):
        return self.applied_torque(t, x[0], self.control(t, x[0], x[1], x[2:])[0])[0]

    def events(self, mode: int):
        if mode == 0:
            def breaks_away(t, x):
                return self.p["cr"] - abs(self.force_at(t, x))
            breaks_away.terminal, breaks_away.direction = True, -1
            return [breaks_away]

        def comes_to_rest(t, x):
            return x[1]
        comes_to_rest.terminal, comes_to_rest.direction = True, -mode
        return [comes_to_rest]

    def rest_mode(self, t, x) -> int:
        """At x2 = 0: stuck while |F| < cr, else slipping in the direction of F."""
        force = self.force_at(t, x)
        return 0 if abs(force) < self.p["cr"] else (1 if force > 0 else -1)


def filippov_solution(controller: str, stop: float = STOP, rtol: float = RTOL) -> dict:
    """{"tv_u": TV(u)/s on the output grid, "stuck": [(start, end)], "events": mode changes} of one controller."""
    loop = ClosedLoop(controller)
    x = np.array([PLANT["x1_start"], PLANT["x2_start"], *[CONTROLLER["theta0"]] * 4], dtype=float)
    t = 0.0
    mode = loop.rest_mode(t, x) if x[1] == 0.0 else (1 if x[1] > 0 else -1)
    segments, events = [], 0
    while t < stop:
        solution = solve_ivp(loop.derivative(mode), (t, stop), x, method="Radau", rtol=rtol, atol=rtol * 1e-2,
                             dense_output=True, events=loop.events(mode))
        assert solution.success, solution.message
        segments.append((t, solution.t[-1], mode, solution.sol))
        t, x = solution.t[-1], solution.y[:, -1].copy()
        if solution.status == 1:  # a mode change located
            events += 1
            assert events < 100, "Zeno: the mode changes do not stop"
            if mode != 0:  # came to rest
                x[1] = 0.0
                mode = loop.rest_mode(t, x)
            else:  # |F| reached cr: the link slips in the direction of F
                mode = 1 if loop.force_at(t, x) > 0 else -1
    grid = np.arange(round(stop / STEP) + 1) * STEP
    states = np.empty((6, grid.size))
    for start, end, segment_mode, dense in segments:
        inside = (grid >= start) & (grid <= end)
        states[:, inside] = dense(grid[inside])
        if segment_mode == 0:
            states[1, inside] = 0.0
    u = loop.control(grid, states[0], states[1], states[2:])[0]
    return {"tv_u": float(np.sum(np.abs(np.diff(u)))) / (grid[-1] - grid[0]), "events": events,
            "stuck": [(start, end) for start, end, segment_mode, _ in segments if segment_mode == 0]}


@pytest.fixture(scope="module")
def reference():
    return {controller: filippov_solution(controller) for controller in ("vud", "fixed")}


@pytest.fixture(scope="module")
def model_exchange(fmu_paths, monkeypatch_module):
    """The Model Exchange runs of both controllers (native edition, the default rtol) and their stuck intervals
    as harness/studies/me_accuracy.py finds them."""
    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e .)")
    monkeypatch_module.setenv("AFC_EDITION", "native")
    from harness.cases import Case, run_case
    from harness.fmu_build import builder
    from harness.studies import me_accuracy

    paths = builder.ensure_built()
    return {controller: (run_case(Case("manipulator", controller, algorithm="me"), paths),
                         me_accuracy.stick_evidence("manipulator", controller, me_accuracy.RTOLS[-1], None, paths,
                                                    co_simulation_steps=()),
                         run_case(Case("manipulator", controller, algorithm="me",
                                       rtol=DEFAULT_RTOL * claims.TOLERANCE_FACTOR), paths))
            for controller in ("vud", "fixed")}


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


@pytest.mark.parametrize("controller", ["vud", "fixed"])
def test_model_exchange_gives_the_continuous_time_total_variation_of_u(reference, model_exchange, controller):
    """TV(u)/s of our Model Exchange run is the Filippov solution's: the values the smooth-u claim is decided
    on in the continuous-time model (vud below 1.1 x fixed)."""
    outcome, _, _ = model_exchange[controller]
    assert outcome["status"] == "ok", outcome["reason"]
    print(f"{controller}: TV(u)/s Filippov {reference[controller]['tv_u']:.7f}, Model Exchange "
          f"{outcome['tv_u']:.7f}, {reference[controller]['events']} mode changes")
    assert outcome["tv_u"] == pytest.approx(reference[controller]["tv_u"], abs=TV_AGREEMENT)


@pytest.mark.parametrize("controller", ["vud", "fixed"])
def test_the_model_exchange_claims_error_bounds_the_distance_to_this_solution(reference, model_exchange, controller):
    """`tables --algorithm me` decides on tolerance ladders (harness/studies/claims.py): its +- of TV(u)/s covers
    the distance to the Filippov solution."""
    tight, _, loose = model_exchange[controller]
    found = claims.estimate([tight, loose], "tv_u")
    assert abs(found.value - reference[controller]["tv_u"]) <= found.error + 10 * RTOL, (found, reference[controller])


def test_the_continuous_time_loop_decides_the_smooth_u_claim_on_the_manipulator(reference):
    assert reference["vud"]["tv_u"] <= 1.1 * reference["fixed"]["tv_u"] - 0.5  # by a wide margin
    assert reference["vud"]["tv_u"] > reference["fixed"]["tv_u"]  # and still above fixed's own


@pytest.mark.parametrize("controller", ["vud", "fixed"])
def test_the_stuck_intervals_are_those_an_event_location_finds(reference, model_exchange, controller):
    """docs/model_exchange_accuracy.md's stuck intervals (harness/studies/me_accuracy.py) on the output grid:
    each within one output step of an event-located stuck phase, none missed, none split."""
    _, evidence, _ = model_exchange[controller]
    located = reference[controller]["stuck"]
    found = evidence["intervals"]
    assert len(found) == len(located), (found, located)
    for (start, end), (first, last) in zip(located, found):  # the first and last output times inside
        print(f"{controller}: stuck {start:.6f}-{end:.6f} s, on the output grid {first:.6f}-{last:.6f} s")
        assert start - EVENT_AGREEMENT <= first <= start + STEP + EVENT_AGREEMENT, (start, first)
        assert end - STEP - EVENT_AGREEMENT <= last <= end + EVENT_AGREEMENT, (end, last)
    total = sum(b - a for a, b in located)
    assert sum(b - a for a, b in found) == pytest.approx(total, abs=2 * STEP * len(located))
