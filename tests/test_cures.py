"""The robust cures of the controller (docs/model.md section 14 (robust cures)): alpha_min (23a), dead_zone
(31a), sigma (31b), filter_time_constant (F1).

Off by default: every shipped scenario x controller records, in both editions, the numbers of the code
before the cures existed, bit for bit (``tests/data/cures_off_fingerprints.json``: the SHA-256 of each
record, written by ``python -m tests.test_cures --write`` from a checkout of that code). Each cure acts:
the pure functions against their equations, and both FMUs driven through FMI (alpha never below the
floor; theta constant while |tau| is inside the dead zone and moving outside it; sigma pulls theta to 0
at zero error; the filter's step response), the editions equal bit for bit with the cures on; Model
Exchange refuses the filter in one line.
"""
from __future__ import annotations

import hashlib
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from fmu_src import afc_math
from harness import master, variants
from harness import scenario as scenarios
from harness.fmu_build import native as build_native
from tests.fmu_helpers import Driven

ROOT = Path(__file__).resolve().parents[1]
FINGERPRINTS = ROOT / "tests" / "data" / "cures_off_fingerprints.json"
FINGERPRINT_STOP = 1.0  # s: past the latch's check window and the chatter monitor's warm-up


# ------------------------------------------------------------------ the pure functions
def test_the_floor_keeps_every_alpha_at_or_above_alpha_min_and_leaves_larger_ones():
    alpha = (0.01, 0.35, 0.2, 0.9)
    assert afc_math.floored_contraction_factors(alpha, 0.2) == (0.2, 0.35, 0.2, 0.9)
    assert afc_math.floored_contraction_factors(alpha[:2], 0.3) == (0.3, 0.35)  # the unrolled n = 2
    values = {v.name: v.start for v in _controller_table() if v.causality == "parameter"}
    p = afc_math.controller_parameters({**values, "alpha_min": 0.25})
    plain = afc_math.controller_parameters(values)
    for e in np.linspace(-1.0, 1.0, 41):
        _, _, alpha, _ = afc_math.controller_output((e, -0.3 * e), (0.0, 0.0), 0.0, [1.0, -2.0, 3.0, -4.0], 0.0, p)
        _, _, free, _ = afc_math.controller_output((e, -0.3 * e), (0.0, 0.0), 0.0, [1.0, -2.0, 3.0, -4.0], 0.0, plain)
        assert min(alpha) >= 0.25 and alpha == tuple(max(a, 0.25) for a in free)
    assert afc_math.controller_parameters({**values, "alpha_min": 0.0})["alpha_min"] == 0.0


def test_the_dead_zone_is_zero_inside_and_shifted_continuously_outside():
    assert afc_math.dead_zone_signal(0.03, 0.05) == 0.0 == afc_math.dead_zone_signal(-0.05, 0.05)
    assert afc_math.dead_zone_signal(0.25, 0.05) == pytest.approx(0.2)
    assert afc_math.dead_zone_signal(-0.25, 0.05) == pytest.approx(-0.2)
    edge = 0.05
    assert afc_math.dead_zone_signal(math.nextafter(edge, 1.0), edge) == pytest.approx(0.0, abs=1e-15)
    assert afc_math.dead_zone_signal(7.0, 0.0) == 7.0  # width 0: the law untouched


def test_leakage_pulls_the_weights_to_zero_and_is_the_plain_law_at_sigma_zero():
    theta = [4.0, -2.0, 250.0, -210.0]  # two beyond M_theta: the projection acts
    xi, tau = (0.1, 0.2, 0.3, 0.4), 0.7
    rates = afc_math.adaptation_rates(theta, tau, xi, 300.0, 200.0, 5.0)
    assert afc_math.leaky_weights(theta, rates, 0.0, 1e-3) == afc_math.adapted_weights(theta, tau, xi, 300.0, 200.0,
                                                                                     5.0, 1e-3)
    assert afc_math.leaky_weights(theta, [0.0] * 4, 2.0, 0.01) == pytest.approx([value * (1 - 0.02) for value in theta])
    assert afc_math.leaky_rates(theta, [0.0] * 4, 2.0) == [-2.0 * value for value in theta]


def test_the_measurement_filter_is_the_first_order_step_response():
    gain = afc_math.measurement_filter_gain(1e-3, 0.01)
    assert gain == pytest.approx(1 - math.exp(-0.1))
    f = (0.0, 0.0)
    for _ in range(30):
        f = afc_math.filtered_measurements(f, (1.0, -2.0), gain)
    assert f == pytest.approx((1 - math.exp(-3.0), -2 * (1 - math.exp(-3.0))), rel=1e-12)
    assert afc_math.filtered_measurements((5.0,), (1.0,), 1.0) == (1.0,)


def _controller_table():
    from harness.fmu_build import catalog

    return catalog.model_class("AdaptiveFuzzyController").VARIABLES


# ------------------------------------------------------------------ both FMUs through FMI
@pytest.fixture(scope="module")
def editions(fmu_paths):
    """{edition: the controller FMU} of the editions built here."""
    paths = {"python": fmu_paths["AdaptiveFuzzyController"]}
    if build_native.compiler_available():
        paths["native"] = build_native.ensure_built()["AdaptiveFuzzyController"][2]
    return paths


PINNED = dict(initial_error=2, e0=0.0, de0=0.0, lambda_e=0.0)  # E = e: the inputs drive tau directly
P12 = P22 = 5.0  # P B for k1 = 2, k2 = 1, Q = diag(10, 10) (30): tau = 5 E + 5 dE


def _drive(path, inputs, steps, h=1e-3, **parameters):
    """[(u, E, dE, alpha1, alpha2, theta1..4, w_hat) at each point] of the controller fed inputs(t)."""
    names = ("u", "E", "dE", "alpha1", "alpha2", "theta1", "theta2", "theta3", "theta4", "w_hat")
    c = Driven(path, "cures")
    try:
        c.enter(**parameters, **inputs(0.0))
        c.slave.exitInitializationMode()
        rows = []
        for k in range(steps):
            c.set(**inputs(k * h))
            rows.append(c.get(*names))
            c.slave.doStep(k * h, h)
        return np.array(rows), c.messages
    finally:
        c.free()


def _wave(t):
    return dict(e=0.2 * math.sin(7 * t), de=1.4 * math.cos(7 * t), ym=0.0, dym=0.0)


def test_the_floor_holds_alpha_in_both_editions(editions):
    runs = {}
    for edition, path in editions.items():
        rows, _ = _drive(path, _wave, 1500, alpha_min=0.3, **PINNED)
        free, _ = _drive(path, _wave, 1500, **PINNED)
        alpha, unfloored = rows[:, 3:5], free[:, 3:5]
        assert alpha.min() == 0.3 and (unfloored < 0.3).any()  # the floor is reached and holds
        assert np.array_equal(alpha, np.maximum(unfloored, 0.3))  # alpha depends on E alone (23a)
        runs[edition] = rows
    if len(runs) == 2:
        assert np.array_equal(runs["python"], runs["native"])


def test_the_dead_zone_freezes_theta_while_tau_is_inside_it_in_both_editions(editions):
    width = 0.8
    runs = {}
    for edition, path in editions.items():
        rows, _ = _drive(path, _wave, 1500, dead_zone=width, variant=3, **PINNED)
        tau = P12 * rows[:, 1] + P22 * rows[:, 2]
        adapted = rows[:, 5:10]  # theta1..4 and w_hat
        moved = np.any(adapted[1:] != adapted[:-1], axis=1)
        inside = np.abs(tau[:-1]) <= width
        assert inside.any() and (~inside).any()
        assert not moved[inside].any(), f"{edition}: theta moved while |tau| <= {width}"
        assert moved[~inside].all(), f"{edition}: theta stood still while |tau| > {width}"
        runs[edition] = rows
    if len(runs) == 2:
        assert np.array_equal(runs["python"], runs["native"])


def test_sigma_pulls_theta_to_zero_at_zero_error_in_both_editions(editions):
    h, sigma = 1e-3, 2.0
    zero = lambda t: dict(e=0.0, de=0.0, ym=0.0, dym=0.0)  # noqa: E731
    runs = {}
    for edition, path in editions.items():
        rows, _ = _drive(path, zero, 500, h, sigma=sigma, theta0=5.0, variant=3, **PINNED)
        plain, _ = _drive(path, zero, 500, h, theta0=5.0, variant=3, **PINNED)
        expected = 5.0 * (1.0 - h * sigma) ** np.arange(500)
        assert np.allclose(rows[:, 5], expected, rtol=1e-12) and rows[-1, 5] < 5.0 * math.exp(-0.99)
        assert (plain[:, 5] == 5.0).all()  # without leakage nothing moves at zero error
        runs[edition] = rows
    if len(runs) == 2:
        assert np.array_equal(runs["python"], runs["native"])


def test_the_filter_gives_e_its_first_order_step_response_in_both_editions(editions):
    h, time_constant = 1e-3, 0.01
    step = lambda t: dict(e=1.0 if t > 0 else 0.0, de=0.0, ym=0.0, dym=0.0)  # noqa: E731
    runs = {}
    for edition, path in editions.items():
        rows, _ = _drive(path, step, 60, h, filter_time_constant=time_constant, **PINNED)
        plain, _ = _drive(path, step, 60, h, **PINNED)
        k = np.arange(60)
        assert np.allclose(rows[:, 1], np.where(k > 0, 1 - np.exp(-k * h / time_constant), 0.0), rtol=1e-12, atol=0)
        assert (plain[1:, 1] == 1.0).all()
        runs[edition] = rows
    if len(runs) == 2:
        assert np.array_equal(runs["python"], runs["native"])


def test_model_exchange_refuses_the_filter_in_one_line(fmu_paths):
    if not build_native.compiler_available():
        pytest.skip("the native edition needs zig's C compiler")
    paths = {name: versions[2] for name, versions in build_native.ensure_built().items()}
    scenario = scenarios.configure("pendulum_case1", "vud", stop=0.01)
    from harness import me_master

    with pytest.raises(master.SimulationFailed) as failure:
        me_master.simulate(scenario.with_parameter("controller.filter_time_constant", 0.01), fmu_paths=paths)
    text = str(failure.value)
    assert "parameter filter_time_constant = 0.01 is invalid in Model Exchange; valid there: 0" in text


def test_model_exchange_integrates_the_dead_zone_and_the_leakage():
    """The native Model Exchange derivatives (31a), (31b): a dead zone wider than any tau stops the learning,
    and then sigma alone takes theta_j from theta0 as theta0 exp(-sigma t) (CVODE's solution)."""
    if not build_native.compiler_available():
        pytest.skip("the native edition needs zig's C compiler")
    from harness import me_master

    paths = {name: versions[2] for name, versions in build_native.ensure_built().items()}
    scenario = scenarios.configure("pendulum_case1", "fae", stop=0.5)
    for name, value in dict(dead_zone=1e9, theta0=3.0).items():
        scenario = scenario.with_parameter(f"controller.{name}", value)
    frozen = me_master.simulate(scenario, fmu_paths=paths)
    assert (frozen.signal("controller.theta1") == 3.0).all() and (frozen.signal("controller.w_hat") == 0.0).all()
    leaking = me_master.simulate(scenario.with_parameter("controller.sigma", 2.0), fmu_paths=paths)
    for j in range(1, 5):
        assert np.allclose(leaking.signal(f"controller.theta{j}"), 3.0 * np.exp(-2.0 * leaking.time), rtol=1e-6)


# ------------------------------------------------------------------ off by default: bit for bit
def fingerprints(edition_paths: dict) -> dict:
    """{edition: {"scenario/controller": SHA-256 of the record}} of every shipped scenario x controller,
    FINGERPRINT_STOP seconds, defaults of every controller parameter the scenario does not set."""
    found = {}
    for edition, paths in edition_paths.items():
        for name in scenarios.scenario_names():
            for controller in variants.NAMES:
                run = master.simulate(scenarios.configure(name, controller, stop=FINGERPRINT_STOP), fmu_paths=paths)
                digest = hashlib.sha256(np.ascontiguousarray(run.time).tobytes())
                digest.update(np.ascontiguousarray(run.values).tobytes())
                digest.update("\n".join(run.columns).encode())
                found.setdefault(edition, {})[f"{name}/{controller}"] = digest.hexdigest()
    return found


def _edition_paths(python_paths: dict) -> dict:
    paths = {"python": python_paths}
    if build_native.compiler_available():
        paths["native"] = {name: versions[2] for name, versions in build_native.ensure_built().items()}
    return paths


def test_with_the_cures_off_every_shipped_scenario_records_what_it_did_before_them(fmu_paths):
    committed = json.loads(FINGERPRINTS.read_text())
    fresh = fingerprints(_edition_paths(fmu_paths))
    for edition, cases in fresh.items():
        assert set(cases) == set(committed[edition]), "a scenario was added: write the fingerprints again"
        changed = [case for case, digest in cases.items() if committed[edition][case] != digest]
        assert not changed, f"{edition}: records changed with the cures off: {changed}"


if __name__ == "__main__":  # python -m tests.test_cures --write: the fingerprints of this checkout's code
    if sys.argv[1:] != ["--write"]:
        raise SystemExit("usage: python -m tests.test_cures --write")
    from harness.fmu_build import builder

    FINGERPRINTS.parent.mkdir(parents=True, exist_ok=True)
    FINGERPRINTS.write_text(json.dumps(fingerprints(_edition_paths(builder.ensure_built())), indent=1,
                                       sort_keys=True) + "\n")
    print(f"wrote {FINGERPRINTS}")
