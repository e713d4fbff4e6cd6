"""The native FMUs' Model Exchange interface, FMI 2.0 and 3.0 (docs/model_exchange.md).

* the derivatives are the pure Python model functions' (plants/*/model.py, fmu_src/afc_math.py),
  bit for bit, in every friction mode of the manipulator and every controller variant;
* ``fmpy simulate --interface-type ModelExchange`` runs each FMU alone (inputs from a CSV of
  piecewise-constant signals) and agrees with solve_ivp of the Python model, the manipulator's
  friction events and stick phases included;
* the friction event, the stick mode and the break-away are located where the equations put them;
* FMU state get/set/serialize round trips exactly in Model Exchange (the friction mode included);
* the initial error of Remark 3 is latched from the inputs the host set for the initial state;
  no chatter warning (a co-simulation artefact) in Model Exchange;
* every call of the wrong interface gets one clear error; the pythonfmu edition stays co-simulation;
* the FMU Compliance Checker in ME mode is clean on every FMI 2.0 FMU (skipped without ../shared).

The native FMUs are built for $AFC_NATIVE_PLATFORMS (default: all); only linux64 is run here.
"""
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy.fmi1 import FMICallException

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.native_stages import model_exchange as native_model_exchange
from fmu_src import afc_math
from plants import registry as plant_registry
from plants.dc_motor_arm import model as dc_motor_arm_model
from plants.inverted_pendulum import model as inverted_pendulum_model
from plants.manipulator import model as manipulator_model
from tests import me_helpers as me
from tests.fmu_helpers import Driven
from tests.message_meaning import meaning

ROOT = Path(__file__).resolve().parents[1]
MODELS = [m.model_identifier for m in build_native.models()]
VERSIONS = [2, 3]
FMUCHECK = ROOT.parent / "shared" / "tools" / "fmucheck" / "fmucheck.sh"

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e '.[native]')")


@pytest.fixture(scope="module")
def native():
    """{model identifier: {2: FMI 2.0 path, 3: FMI 3.0 path}}"""
    return build_native.ensure_built()


def table(model: str):
    return build_fmu.model_class(model)


def instance(native, model, version, **kwargs) -> me.MeInstance:
    return me.MeInstance(native[model][version], version, **kwargs)


# ------------------------------------------------------------------ derivatives
PENDULUM_STATES = [(0.3, -0.7, 2.5, 0.0), (-1.2, 3.0, -8.0, 1.7), (math.pi / 12, 0.0, 0.0, 12.25)]


@pytest.mark.parametrize("version", VERSIONS)
def test_the_pendulum_derivatives_are_the_python_model_function_s(native, version):
    values = me.table_values(table("InvertedPendulum"), dist_gain=1.0, mp=0.7)
    params = me.pendulum_params(values)
    fmu = instance(native, "InvertedPendulum", version)
    try:
        fmu.initialize(dist_gain=1.0, mp=0.7)
        for x1, x2, u, t in PENDULUM_STATES:
            fmu.set_time(t)
            fmu.set_states([x1, x2])
            fmu.set(u=u)
            expected = inverted_pendulum_model.pendulum_derivative(t, x1, x2, u, params)
            assert fmu.derivatives().tolist() == list(expected)
            assert fmu.get("der(y)", "der(dy)") == list(expected)  # the derivative variables too
            assert fmu.get("y", "dy", "d") == [x1, x2, inverted_pendulum_model.pendulum_disturbance(t, 1.0)]
    finally:
        fmu.free()


@pytest.mark.parametrize("version", VERSIONS)
def test_the_motor_arm_derivatives_are_the_python_model_function_s(native, version):
    values = me.table_values(table("DcMotorArm"), L=0.05, b=0.35)
    params = me.motor_arm_params(values)
    fmu = instance(native, "DcMotorArm", version)
    try:
        fmu.initialize(L=0.05, b=0.35)
        for x, u, t in [((0.3, -0.7, 1.2), 4.0, 0.5), ((-2.0, 5.0, -3.0), -12.0, 3.25)]:
            fmu.set_time(t)
            fmu.set_states(x)
            fmu.set(u=u)
            expected = dc_motor_arm_model.motor_arm_derivative(t, x, u, params)
            assert fmu.derivatives().tolist() == list(expected)
            assert fmu.get("d2y") == dc_motor_arm_model.motor_arm_acceleration(*x, params)
    finally:
        fmu.free()


@pytest.mark.parametrize("version", VERSIONS)
def test_the_manipulator_derivatives_are_the_python_model_function_s_in_every_friction_mode(native, version):
    model = manipulator_model
    values = me.table_values(table("Manipulator"))
    params = me.manipulator_params(values)
    fmu = instance(native, "Manipulator", version)
    seen = set()
    try:
        fmu.initialize(x1_start=0.4, x2_start=1.3)
        assert fmu.get("friction_mode") == 1.0 and fmu.derivatives().tolist() == list(
            model.manipulator_derivative(0.0, 0.4, 1.3, 0.0, params))
        # (x1, x2, u, t), each after the previous: x2 crossed zero and the torque drives the link
        # backwards; x2 crossed zero again with |F| < cr: stuck; held; pushed off forwards (break-away);
        # slipping forwards at x2 = 0; crossed zero (backwards); slipping backwards
        for x1, x2, u, t in [(0.4, -1e-6, 2.0, 0.3), (math.pi / 2, 1e-6, 0.7, 0.5), (math.pi / 2, 0.0, -0.7, 2.0),
                             (0.2, 0.0, 40.0, 0.8), (0.2, 0.0, -40.0, 0.8), (0.2, -1e-3, -40.0, 0.8),
                             (-0.8, -2.1, -5.0, 1.1)]:
            fmu.set_time(t)
            fmu.set_states([x1, x2])
            fmu.set(u=u)
            mode = fmu.get("friction_mode")
            changed = fmu.event()  # the mode follows the state at an event
            expected_mode, expected_x2 = model.manipulator_event_update(t, x1, x2, u, params, int(mode))
            assert fmu.get("friction_mode") == expected_mode
            assert changed == (expected_x2 != x2)
            assert fmu.states().tolist() == [x1, expected_x2]
            expected = model.manipulator_mode_derivative(t, x1, expected_x2, u, params, expected_mode)
            assert fmu.derivatives().tolist() == list(expected)
            if expected_x2 != 0.0:  # slipping: the co-simulation right-hand side, bit for bit
                assert list(expected) == list(model.manipulator_derivative(t, x1, expected_x2, u, params))
            assert fmu.indicators().tolist() == list(
                model.manipulator_event_indicators(t, x1, expected_x2, u, params, expected_mode))
            assert fmu.get("z_slip", "z_stick") == fmu.indicators().tolist()
            seen.add(expected_mode)
    finally:
        fmu.free()
    assert seen == {-1, 0, 1}


CONTROLLER_CASES = [
    dict(variant=1, fls_input=1),
    dict(variant=2, fls_input=2, k1=3.0, k2=2.0, q1=7.0, q2=4.0),
    dict(variant=3, fls_input=1, gamma_w=50.0, theta0=1.5),
    dict(variant=1, fls_input=1, order=3, sets=3, k3=0.5),
    dict(variant=1, fls_input=2, m_theta=2.0, delta=0.5, theta0=1.0),  # theta beyond M_theta: the projection
]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("case", range(len(CONTROLLER_CASES)))
def test_the_controller_derivatives_are_the_adaptive_law_of_afc_math(native, version, case):
    parameters = CONTROLLER_CASES[case]
    values = me.table_values(table("AdaptiveFuzzyController"), **parameters)
    n = values["order"]
    start = {"e": 0.3, "de": -0.1, "d2e": 0.05, "ym": 0.2, "dym": 0.05, "d2ym": -0.02}
    names_e, names_r = ("e", "de", "d2e")[:n], ("ym", "dym", "d2ym")[:n]
    p = afc_math.controller_parameters(values, [start[k] for k in names_e], 0.0)
    rules = p["rules"]
    rng = np.random.default_rng(case)
    fmu = instance(native, "AdaptiveFuzzyController", version)
    try:
        fmu.initialize(**parameters, **{k: start[k] for k in (*names_e, *names_r)})
        x0 = fmu.states()
        assert len(x0) == 126 and x0.tolist() == [values["theta0"]] * rules + [0.0] * (126 - rules)
        projected = 0
        for t in (0.0, 0.013, 0.4, 2.5):
            theta = (values["theta0"] + rng.normal(0.0, 3.0, rules)).tolist()
            w_hat = float(rng.normal()) if values["variant"] == 3 else 0.0
            error = rng.normal(0.0, 0.5, n).tolist()
            reference = rng.normal(0.0, 0.5, n).tolist()
            fmu.set_time(t)
            fmu.set_states(theta + [0.0] * (125 - rules) + [w_hat])
            fmu.set(**dict(zip(names_e, error)), **dict(zip(names_r, reference)))
            u, modified, alpha, xi = afc_math.controller_output(error, reference, t, theta, w_hat, p)
            tau = afc_math.adaptation_signal(modified, p["p_b"])
            rates = afc_math.adaptation_rates(theta, tau, xi, values["gamma"], values["m_theta"], values["delta"])
            w_rate = afc_math.estimate_rate(tau, values["gamma_w"]) if values["variant"] == 3 else 0.0
            derivatives = fmu.derivatives().tolist()
            assert derivatives == rates + [0.0] * (125 - rules) + [w_rate]
            assert fmu.get("u") == u
            assert fmu.get(*("E", "dE", "d2E")[:n]) == (list(modified) if n > 1 else modified[0])
            projected += sum(r != values["gamma"] * tau * b for r, b in zip(rates, xi))
    finally:
        fmu.free()
    if values["m_theta"] < 10:  # the smooth projection (31) acted on some weights
        assert projected > 0


@pytest.mark.parametrize("version", VERSIONS)
def test_the_reference_has_no_states_and_its_outputs_follow_the_host_s_time(native, version):
    fmu = instance(native, "TrackingReference", version)
    try:
        fmu.initialize(amplitude=0.5, omega=2.0, y=0.1, dy=-0.2)
        assert fmu.nx == 0 and fmu.nz == 0 and fmu.states().size == 0 and fmu.derivatives().size == 0
        fmu.set_time(0.7)
        fmu.set(y=0.3, dy=0.4)
        assert fmu.get("ym", "dym", "e", "de") == [0.5 * math.sin(1.4), 0.5 * 2.0 * math.cos(1.4),
                                                   0.5 * math.sin(1.4) - 0.3, 0.5 * 2.0 * math.cos(1.4) - 0.4]
    finally:
        fmu.free()


# ---------------------------------------------------- fmpy simulate, each FMU alone
def fmpy_simulate(path: Path, folder: Path, stop: float, outputs, inputs=None, start_values=None,
                  rtol: float = 1e-10, interval: float = 0.01) -> np.ndarray:
    """`fmpy simulate --interface-type ModelExchange` (CVode) of one FMU; the recorded rows.

    ``inputs`` = (names, jump times, rows): a CSV of piecewise-constant signals."""
    folder.mkdir(parents=True, exist_ok=True)
    result = folder / "out.csv"
    command = [sys.executable, "-m", "fmpy", "simulate", str(path), "--interface-type", "ModelExchange",
               "--stop-time", repr(stop), "--relative-tolerance", repr(rtol), "--output-interval", repr(interval),
               "--output-file", str(result), "--timeout", "120", "--output-variables", *outputs]
    if inputs is not None:
        names, times, rows = inputs
        command += ["--input-file", str(me.input_csv(folder / "in.csv", names, times, rows, stop))]
    if start_values:
        command += ["--start-values", *[str(item) for pair in start_values.items() for item in pair]]
    completed = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    return np.genfromtxt(result, delimiter=",", names=True)


def regular_rows(rows: np.ndarray, jumps=()) -> np.ndarray:
    """The rows away from events: fmpy records two rows at each event time (before and after)."""
    times = rows["time"]
    events = set(times[1:][np.diff(times) == 0.0]) | set(jumps)
    keep = [i for i, t in enumerate(times) if all(abs(t - e) > 1e-9 for e in events)]
    return rows[keep]


def event_times(rows: np.ndarray) -> list:
    times = rows["time"]
    return sorted(set(times[1:][np.diff(times) == 0.0]))


def largest_difference(rows, solutions, columns, scale=None) -> float:
    """max over rows and columns of |fmpy - reference| (relative to each column's largest |value|
    when ``scale``)."""
    fmu = np.column_stack([rows[c] for c in columns])
    reference = np.array([me.evaluate(solutions, t)[:len(columns)] for t in rows["time"]])
    difference = np.abs(fmu - reference).max(axis=0)
    if scale:
        difference = difference / np.maximum(np.abs(reference).max(axis=0), 1e-300)
    return float(difference.max())


# fmpy's CVode at rtol 1e-10 against DOP853 at 1e-12 on the Python model: the largest difference of
# a state over the run, relative to that state's largest |value| (measured: docs/model_exchange.md;
# it follows CVode's tolerance: the pendulum 7e-7, 3e-8, 1e-10 at rtol 1e-8, 1e-10, 1e-12)
AGREEMENT = {"InvertedPendulum": 1e-7, "DcMotorArm": 1e-7, "AdaptiveFuzzyController": 1e-6}
U_JUMPS = (0.0, 1.0, 2.0)


@pytest.mark.parametrize("version", VERSIONS)
def test_fmpy_simulates_the_pendulum_as_solve_ivp_integrates_the_python_model(native, tmp_path, version):
    values = me.table_values(table("InvertedPendulum"), dist_gain=1.0)
    params = me.pendulum_params(values)
    forces = (0.5, -2.0, 1.0)
    rows = fmpy_simulate(native["InvertedPendulum"][version], tmp_path, 2.5, ["y", "dy"],
                         (["u"], U_JUMPS, [(f,) for f in forces]), {"dist_gain": 1.0})
    solutions = me.smooth_reference(lambda t, x, u: inverted_pendulum_model.pendulum_derivative(t, *x, u, params),
                                    (values["x1_start"], values["x2_start"]), me.pieces(U_JUMPS, forces, 2.5))
    difference = largest_difference(regular_rows(rows, U_JUMPS), solutions, ("y", "dy"), scale=True)
    print(f"pendulum FMI {version}: fmpy ME vs solve_ivp, largest difference {difference:.3g} of the range")
    assert difference < AGREEMENT["InvertedPendulum"]


@pytest.mark.parametrize("version", VERSIONS)
def test_fmpy_simulates_the_motor_arm_as_solve_ivp_integrates_the_python_model(native, tmp_path, version):
    values = me.table_values(table("DcMotorArm"))
    params = me.motor_arm_params(values)
    voltages = (5.0, -3.0, 0.0)
    rows = fmpy_simulate(native["DcMotorArm"][version], tmp_path, 2.5, ["y", "dy", "i"],
                         (["u"], U_JUMPS, [(v,) for v in voltages]))
    solutions = me.smooth_reference(lambda t, x, u: dc_motor_arm_model.motor_arm_derivative(t, x, u, params),
                                    (values["x1_start"], values["x2_start"], values["x3_start"]),
                                    me.pieces(U_JUMPS, voltages, 2.5))
    difference = largest_difference(regular_rows(rows, U_JUMPS), solutions, ("y", "dy", "i"), scale=True)
    print(f"motor arm FMI {version}: fmpy ME vs solve_ivp, largest difference {difference:.3g} of the range")
    assert difference < AGREEMENT["DcMotorArm"]


MANIPULATOR_JUMPS = (0.0, 1.0, 2.0)
MANIPULATOR_TORQUES = (0.0, 14.0, -14.0)  # falls back, is pushed forwards, backwards; sticks near t = 2.74


@pytest.mark.parametrize("version", VERSIONS)
def test_fmpy_simulates_the_manipulator_through_its_friction_events_as_the_python_model(native, tmp_path, version):
    values = me.table_values(table("Manipulator"))
    params = me.manipulator_params(values)
    stop = 3.0
    # at rtol 1e-12: the event times follow the states' accuracy (measured, the last event, after a
    # 10 ms slip: 8.5e-7, 9.9e-9, 1.2e-10 s from the reference's at rtol 1e-8, 1e-10, 1e-12)
    rows = fmpy_simulate(native["Manipulator"][version], tmp_path, stop, ["y", "dy", "friction_mode"],
                         (["u"], MANIPULATOR_JUMPS, [(u,) for u in MANIPULATOR_TORQUES]), rtol=1e-12)
    solutions, events = me.manipulator_reference(params, (values["x1_start"], values["x2_start"]),
                                                 me.pieces(MANIPULATOR_JUMPS, MANIPULATOR_TORQUES, stop))
    state_events = [e for e in events if e[5] == "state"]
    difference = largest_difference(regular_rows(rows, MANIPULATOR_JUMPS), solutions, ("y", "dy"), scale=True)
    located = event_times(rows)
    expected = sorted({e[0] for e in events} - {0.0})
    assert len(located) == len(expected)
    timing = max(abs(a - b) for a, b in zip(located, expected))
    print(f"manipulator FMI {version}: fmpy ME vs solve_ivp, largest difference {difference:.3g} of the range; "
          f"events at {[round(float(t), 6) for t in located]}, {timing:.2g} s from the reference's")
    assert len(state_events) >= 3 and any(e[2] == manipulator_model.STICK for e in state_events)
    assert timing < 1e-9
    assert difference < 1e-9
    stuck = rows[(rows["time"] > expected[-1] + 1e-6)]
    assert stuck.size and np.all(stuck["friction_mode"] == 0.0) and np.all(stuck["dy"] == 0.0)
    assert np.ptp(stuck["y"]) == 0.0  # at rest, exactly


CONTROLLER_INPUTS = [(0.3, -0.1, 0.2, 0.05), (-0.2, 0.4, 0.5, -0.3), (0.05, 0.0, -0.1, 0.2)]


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("variant", [1, 3])
def test_fmpy_simulates_the_controller_as_solve_ivp_integrates_the_adaptive_law(native, tmp_path, version, variant):
    parameters = {"variant": variant, "gamma": 30.0, "gamma_w": 20.0}
    values = me.table_values(table("AdaptiveFuzzyController"), **parameters)
    jumps, stop = (0.0, 0.4, 0.8), 1.2
    thetas = ["theta1", "theta2", "theta3", "theta4"]
    rows = fmpy_simulate(native["AdaptiveFuzzyController"][version], tmp_path, stop, [*thetas, "w_hat", "u"],
                         (["e", "de", "ym", "dym"], jumps, CONTROLLER_INPUTS), parameters)
    (solutions, p) = me.controller_reference(values, CONTROLLER_INPUTS[0][:2],
                                             me.pieces(jumps, CONTROLLER_INPUTS, stop))
    difference = largest_difference(regular_rows(rows, jumps), solutions, (*thetas, "w_hat"), scale=True)
    print(f"controller variant {variant} FMI {version}: fmpy ME vs solve_ivp, largest difference "
          f"{difference:.3g} of the range (theta up to {np.abs(np.column_stack([rows[c] for c in thetas])).max():.3g})")
    assert difference < AGREEMENT["AdaptiveFuzzyController"]
    assert np.abs(rows["theta1"]).max() > 0.1 and (variant != 3 or np.abs(rows["w_hat"]).max() > 0.01)


@pytest.mark.parametrize("version", VERSIONS)
def test_fmpy_simulates_the_reference_alone(native, tmp_path, version):
    jumps, stop = (0.0, 0.5), 1.0
    rows = fmpy_simulate(native["TrackingReference"][version], tmp_path, stop, ["ym", "e", "de"],
                         (["y", "dy"], jumps, [(0.1, -0.2), (0.3, 0.4)]), {"amplitude": 1.0})
    rows = regular_rows(rows, jumps)
    y = np.where(rows["time"] < 0.5, 0.1, 0.3)
    dy = np.where(rows["time"] < 0.5, -0.2, 0.4)
    assert np.array_equal(rows["ym"], np.sin(rows["time"]))
    assert np.array_equal(rows["e"], np.sin(rows["time"]) - y)
    assert np.array_equal(rows["de"], np.cos(rows["time"]) - dy)


# ------------------------------------------------------------ friction events
@pytest.mark.parametrize("version", VERSIONS)
def test_the_arm_sticks_until_the_torque_overcomes_coulomb_friction_and_breaks_away_on_time(native, tmp_path, version):
    """x1 = 0 at rest with u = 12.25 N.m = mr0 gv lr: F(t) = u - mr(t) gv lr = -9.8 sin t stays inside
    (-cr, cr) until sin t = cr / 9.8; the arm must rest exactly until then and break away backwards."""
    from scipy.optimize import brentq

    values = me.table_values(table("Manipulator"), x1_start=0.0, x2_start=0.0)
    params = me.manipulator_params(values)
    u = 12.25
    margin = lambda t: params[3] - abs(manipulator_model.manipulator_applied_torque(t, 0.0, u, params))  # noqa: E731
    breakaway = brentq(margin, 0.0, 0.5, xtol=1e-15)
    assert breakaway == pytest.approx(math.asin(1.5 / 9.8), rel=1e-12)
    rows = fmpy_simulate(native["Manipulator"][version], tmp_path, 0.5, ["y", "dy", "friction_mode", "z_stick"],
                         start_values={"x1_start": 0.0, "x2_start": 0.0, "u": u}, interval=0.005)
    events = event_times(rows)
    print(f"Manipulator FMI {version}: break-away at t = {events[0]!r}, expected {breakaway!r} "
          f"(sin t = cr / (mr1 gv lr)), {abs(events[0] - breakaway):.2g} s apart")
    assert abs(events[0] - breakaway) < 1e-9
    before, after = rows[rows["time"] < events[0]], rows[rows["time"] > events[0]]
    assert np.all(before["y"] == 0.0) and np.all(before["dy"] == 0.0) and np.all(before["friction_mode"] == 0.0)
    assert np.all(np.diff(before["z_stick"]) < 0.0)  # |F| grows towards cr
    assert np.all(after["friction_mode"] == -1.0) and np.all(after["dy"] < 0.0) and after["y"][-1] < -1e-3


@pytest.mark.parametrize("version", VERSIONS)
def test_a_slipping_arm_stops_where_x2_crosses_zero_and_sticks_or_reverses(native, version):
    """Our own explicit stepping of the ME interface (no solver of fmpy's): the event is where z_slip
    changes sign, x2 is then 0 and the mode follows the torque."""
    fmu = instance(native, "Manipulator", version)
    model = manipulator_model
    light = dict(mr0=0.2, mr1=0.0)  # a light payload: gravity's moment stays below 0.49 N.m
    params = me.manipulator_params(me.table_values(table("Manipulator"), **light))
    try:
        # near x1 = pi/2, F = u - mr gv lr cos x1 stays within 0.7 +- 0.49 N.m < cr: the arm slides
        # forwards, is braked by friction and sticks
        fmu.initialize(x1_start=math.pi / 2, x2_start=0.5, u=0.7, **light)
        assert fmu.get("friction_mode") == 1.0
        t, h, crossings = 0.0, 1e-4, 0
        previous = fmu.indicators()
        while t < 0.2:
            x = fmu.states()
            dx = fmu.derivatives()
            t += h
            fmu.set_time(t)
            fmu.set_states(x + h * dx)
            z = fmu.indicators()
            if z[0] <= 0.0 < previous[0]:
                crossings += 1
                assert fmu.event()  # x2 set to 0
                assert fmu.states()[1] == 0.0 and fmu.get("friction_mode") == model.STICK  # |F| = 0.7 < cr
                assert fmu.derivatives().tolist() == [0.0, 0.0]
                stuck_at = fmu.states()[0]
            previous = z
        assert crossings == 1 and fmu.states().tolist() == [stuck_at, 0.0]
        assert fmu.indicators()[1] == params[3] - abs(model.manipulator_applied_torque(t, stuck_at, 0.7, params))
        fmu.set(u=-2.0)  # now |F| > cr: the host's event (an input jump) breaks it away backwards
        assert not fmu.event()
        assert fmu.get("friction_mode") == -1.0 and fmu.derivatives()[1] < 0.0
    finally:
        fmu.free()


# --------------------------------------------------------------- FMU state
def run_of(model: str) -> tuple:
    """(parameters, inputs at t, step) of the model's test drive (its script's test_drive()): the
    manipulator slides, sticks at t ~ 2 ms (the state is taken at 5 ms, stuck) and breaks away
    when u jumps at 7 ms."""
    drive = fmu_catalog.declaration(model).test_drive()
    return drive.parameters, drive.inputs, drive.step


RUNS = {model: run_of(model) for model in MODELS}


def _run(fmu: me.MeInstance, model: str, first: int, last: int, outputs) -> list:
    """Explicit Euler steps first..last-1 through the ME interface, an event where an indicator
    reaches zero, an input jumps or a time event the FMU announced falls (inside a step: the step is
    split there); each step's time, states, derivatives, indicators and outputs."""
    _, inputs, h = RUNS[model]
    trace = []
    previous_z = fmu.indicators()
    for i in range(first, last):
        t = i * h
        x, dx = fmu.states(), fmu.derivatives()
        trace.append((t, x.tolist(), dx.tolist(), previous_z.tolist(), fmu.get(*outputs)))
        end = (i + 1) * h
        due = fmu.next_event_time
        if due is not None and t < due < end - 1e-9 * h:  # a time event inside the step
            fmu.set_time(due)
            fmu.set_states(x + (due - t) * dx)
            fmu.event()
            x, dx = fmu.states(), fmu.derivatives()
            fmu.set_time(end)
            fmu.set_states(x + (end - due) * dx)
        else:
            fmu.set_time(end)
            fmu.set_states(x + h * dx)
        given = inputs(end)
        jumped = any(v != inputs(t)[k] and abs(v - inputs(t)[k]) > 0.5 for k, v in given.items())
        fmu.set(**given)
        z = fmu.indicators()
        timed = fmu.next_event_time is not None and abs(fmu.next_event_time - end) <= 1e-9 * h
        if jumped or timed or np.any((previous_z > 0.0) & (z <= 0.0)):
            fmu.event()
            z = fmu.indicators()
        previous_z = z
    return trace


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
def test_fmu_state_get_set_and_serialize_round_trip_in_model_exchange(native, model, version):
    parameters, inputs, _ = RUNS[model]
    outputs = [v.name for v in table(model).VARIABLES if v.causality == "output"]
    first = instance(native, model, version)
    try:
        first.initialize(**parameters, **inputs(0.0))
        head = _run(first, model, 0, 50, outputs)
        state = first.get_state()
        blob = first.serialize(state)
        tail = _run(first, model, 50, 100, outputs)
    finally:
        first.free()
    assert head[-1] != tail[-1]  # it moved
    if model == "Manipulator":  # the state was taken stuck; it broke away after
        assert head[-1][1][1] == 0.0 and tail[-1][1][1] < 0.0
    # another instance, initialised otherwise and already running, continues from the state
    other = instance(native, model, version, instance_name="other")
    try:
        other.initialize(**inputs(0.0))
        _run(other, model, 0, 7, outputs)
        other.set_state(other.deserialize(blob))
        if native_model_exchange.model_exchange(model).time_events:
            # a host keeps its schedule of time events with the state; this one learns it from an event
            # update at the restored time (a sampled FMU takes that instant's sample again, from the same inputs)
            other.event()
        assert _run(other, model, 50, 100, outputs) == tail
        with pytest.raises(FMICallException):
            other.deserialize(blob[:-1])
    finally:
        other.free()
    # a fresh instance (only instantiated): the state brings it to event mode at its time
    fresh = instance(native, model, version, instance_name="fresh")
    try:
        fresh.set_state(fresh.deserialize(blob))
        assert fresh.update() == (False, False)  # the restored state is consistent: nothing to update
        fresh.fmu.enterContinuousTimeMode()
        assert _run(fresh, model, 50, 100, outputs) == tail
    finally:
        fresh.free()


# ------------------------------------------------------ Remark 3, chatter monitor
def _modified(error, t, error0, t0, values):
    return list(afc_math.modified_error(error, t, error0, t0, values["lambda_e"]))


@pytest.mark.parametrize("version", VERSIONS)
def test_the_initial_error_is_latched_from_the_inputs_the_host_set_for_the_initial_state(native, version):
    values = me.table_values(table("AdaptiveFuzzyController"))
    fmu = instance(native, "AdaptiveFuzzyController", version)
    try:
        at_start = _modified((0.3, -0.1), 2.0, (0.3, -0.1), 2.0, values)  # E(t0) = 0 up to rounding
        assert max(map(abs, at_start)) < 1e-15
        fmu.enter(start_time=2.0, e=0.3, de=-0.1)
        assert fmu.get("E", "dE") == at_start  # initialization mode: latched from the inputs set so far
        fmu.exit()
        assert fmu.get("E", "dE") == at_start
        fmu.fmu.enterContinuousTimeMode()
        fmu.set_time(2.1)
        fmu.set(e=0.25, de=-0.2)
        assert fmu.get("E", "dE") == _modified((0.25, -0.2), 2.1, (0.3, -0.1), 2.0, values)  # t0 = start time
        fmu.set(e=-0.4)
        assert fmu.event() is False  # a later event does not move the latch
        assert fmu.get("E", "dE") == _modified((-0.4, -0.2), 2.1, (0.3, -0.1), 2.0, values)
    finally:
        fmu.free()
    # a host that sets the inputs only in the initial event iteration (event mode at the start time)
    late = instance(native, "AdaptiveFuzzyController", version)
    try:
        late.enter(start_time=0.0)
        late.fmu.exitInitializationMode()
        late.update()
        late.set(e=0.3, de=-0.1)
        late.update()  # the event iteration again, with the inputs of the initial state
        late.fmu.enterContinuousTimeMode()
        assert late.get("E", "dE") == _modified((0.3, -0.1), 0.0, (0.3, -0.1), 0.0, values)
        late.set_time(0.1)
        assert late.get("E", "dE") == _modified((0.3, -0.1), 0.1, (0.3, -0.1), 0.0, values)
    finally:
        late.free()
    # pinned by parameters: the inputs do not move it
    pinned = instance(native, "AdaptiveFuzzyController", version)
    try:
        pinned.initialize(initial_error=2, e0=0.5, de0=0.2, e=0.3, de=-0.1)
        assert pinned.get("E", "dE") == _modified((0.3, -0.1), 0.0, (0.5, 0.2), 0.0, values)
    finally:
        pinned.free()


@pytest.mark.parametrize("version", VERSIONS)
def test_no_chatter_warning_in_model_exchange(native, fmu_paths, version):
    """The chattering host of tests/test_native.py (e alternating every 10 ms) warns in co-simulation;
    in Model Exchange there is no communication step to blame: no monitor, no warning."""
    fmu = instance(native, "AdaptiveFuzzyController", version)
    try:
        fmu.initialize(e=0.1, de=0.0, ym=0.0, dym=0.0)
        h = 1e-3
        for i in range(1500):
            x, dx = fmu.states(), fmu.derivatives()
            fmu.set_time((i + 1) * h)
            fmu.set_states(x + h * dx)
            if (i + 1) % 10 == 0:
                fmu.set(e=0.1 if ((i + 1) // 10) % 2 else -0.1)
                fmu.event()
        assert [m for s, m in fmu.messages if s != 0] == []
    finally:
        fmu.free()
    driven = Driven(native["AdaptiveFuzzyController"][2])  # the same host in co-simulation does warn
    try:
        driven.initialize(e=0.1, de=0.0, ym=0.0, dym=0.0)
        for i in range(150):
            driven.set(e=0.1 if i % 2 else -0.1)
            driven.slave.doStep(i * 0.01, 0.01)
        assert any("chatters" in m for s, m in driven.messages if s == 1)
    finally:
        driven.free()


# ------------------------------------------------------------- interface rules
def _raw_call(fmu, name, argument_types, *arguments) -> int:
    """Call an FMI function of the loaded binary directly (fmpy's classes bind only their interface's)."""
    import ctypes
    function = getattr(fmu.dll, name)
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.c_void_p, *argument_types]
    return function(fmu.component, *arguments)


def test_each_interface_refuses_the_other_s_calls_in_one_line(native):
    import ctypes
    driven = Driven(native["InvertedPendulum"][2])  # co-simulation
    try:
        driven.initialize()
        buffer = (ctypes.c_double * 2)()
        assert _raw_call(driven.slave, "fmi2GetDerivatives", [ctypes.POINTER(ctypes.c_double), ctypes.c_size_t],
                         buffer, 2) == 3  # fmi2Error
        assert driven.messages[-1][1] == ("instance: fmi2GetDerivatives is a model exchange function; this instance "
                                          "was instantiated for co-simulation")
        assert driven.get("der(dy)") == inverted_pendulum_model.pendulum_derivative(
            0.0, math.pi / 12, 0.0, 0.0, me.pendulum_params(me.table_values(table("InvertedPendulum"))))[1]
    finally:
        driven.free()
    fmu = instance(native, "InvertedPendulum", 2)
    try:
        fmu.initialize()
        assert _raw_call(fmu.fmu, "fmi2DoStep", [ctypes.c_double, ctypes.c_double, ctypes.c_int], 0.0, 1e-3, 1) == 3
        assert fmu.messages[-1][1] == ("me: fmi2DoStep is a co-simulation function; this instance was instantiated "
                                       "for model exchange")
        with pytest.raises(FMICallException):
            fmu.fmu.getDerivatives(me._pointer(np.zeros(3)), 3)
        assert fmu.messages[-1][1] == "me: fmi2GetDerivatives: 3 derivatives requested; this FMU has 2"
        with pytest.raises(FMICallException):
            fmu.set(mp=1.0)
        assert meaning(fmu.messages[-1][1]) == meaning(
            "me: fmi2SetReal: mp = 1.0 refused at t = 0.0: mp is a parameter of variability fixed, which can be set "
            "only before fmi2ExitInitializationMode (it keeps 0.1); in event and continuous-time mode only inputs "
            "can be set")
        with pytest.raises(FMICallException):
            fmu.set(**{"der(y)": 1.0})
        assert fmu.messages[-1][1] == "me: fmi2SetReal: der(y) is calculated by the FMU and cannot be set"
        fmu.fmu.enterEventMode()
        with pytest.raises(FMICallException):
            fmu.set_states([0.1, 0.2])
        assert fmu.messages[-1][1] == "me: fmi2SetContinuousStates is not allowed in state Event Mode"
    finally:
        fmu.free()


@pytest.mark.parametrize("model", MODELS)
def test_the_pythonfmu_edition_stays_co_simulation(fmu_paths, model):
    from fmpy import read_model_description

    md = read_model_description(str(fmu_paths[model]))
    assert md.modelExchange is None and md.coSimulation is not None and not md.derivatives


# ------------------------------------------------------------- ModelStructure
def _names(unknown):
    return sorted(v.name for v in (unknown.dependencies or []))


def _expected_initial(model: str, name: str) -> list:
    from fmu_src.afc_slave_base import initial_dependencies
    rows = {v.name: v for v in table(model).VARIABLES}
    if name in rows:
        return sorted(initial_dependencies(table(model).VARIABLES, rows[name]))
    declaration = native_model_exchange.model_exchange(model)
    derivative = next(d for d in declaration.derivatives if f"der({d.state})" == name)
    knowns = set(derivative.parameters)
    for known, _ in derivative.depends_on:
        knowns |= (set(initial_dependencies(table(model).VARIABLES, rows[known])) if known in declaration.states
                   else {known})
    return sorted(knowns)


@pytest.mark.parametrize("edition", ["python", "native2", "native3"])
@pytest.mark.parametrize("model", MODELS)
def test_the_model_structure_declares_the_table_s_dependencies(native, fmu_paths, model, edition):
    from fmpy import read_model_description

    path = fmu_paths[model] if edition == "python" else native[model][int(edition[-1])]
    md = read_model_description(str(path))
    rows = {v.name: v for v in table(model).VARIABLES}
    declaration = native_model_exchange.model_exchange(model)
    output_states = dict(declaration.output_states)
    # Outputs: the inputs of the table's depends_on; in the native edition also the states
    assert sorted(u.variable.name for u in md.outputs) == sorted(n for n, v in rows.items() if v.causality == "output")
    for unknown in md.outputs:
        name = unknown.variable.name
        expected = set(rows[name].depends_on)
        if edition != "python":
            expected |= {state for state, _ in output_states.get(name, ())}
        assert _names(unknown) == sorted(expected), name
    # InitialUnknowns: every output (and in the native edition every derivative), with explicit dependencies
    expected_unknowns = [n for n, v in rows.items() if v.causality == "output"]
    if edition != "python":
        expected_unknowns += [f"der({state})" for state in declaration.states]
    assert sorted(u.variable.name for u in md.initialUnknowns) == sorted(expected_unknowns)
    for unknown in md.initialUnknowns:
        assert unknown.dependencies is not None, unknown.variable.name
        assert _names(unknown) == _expected_initial(model, unknown.variable.name), unknown.variable.name
    if "u" in rows and rows["u"].causality == "input":  # a plant: y(0), dy(0) do not depend on its input
        for unknown in md.initialUnknowns:
            if unknown.variable.name in ("y", "dy"):
                assert "u" not in _names(unknown) and _names(unknown) == [f"x{('y', 'dy').index(unknown.variable.name) + 1}_start"]
    # Derivatives (native): of the declared states, with the declared dependencies and kinds
    if edition == "python":
        assert not md.derivatives and md.numberOfEventIndicators in (0, None)
        return
    assert [u.variable.derivative.name for u in md.derivatives] == list(declaration.states)
    assert md.numberOfContinuousStates == len(declaration.states)
    assert md.numberOfEventIndicators == len(declaration.event_indicators)
    for unknown, derivative in zip(md.derivatives, declaration.derivatives):
        assert unknown.variable.name == f"der({derivative.state})"
        declared = sorted(derivative.depends_on)
        assert sorted(zip((d.name for d in unknown.dependencies), unknown.dependenciesKind)) == declared
    if edition == "native3":  # FMI 3.0 declares the event indicators and their dependencies
        assert [u.variable.name for u in md.eventIndicators] == [e.name for e in declaration.event_indicators]
        for unknown, indicator in zip(md.eventIndicators, declaration.event_indicators):
            assert sorted(zip((d.name for d in unknown.dependencies), unknown.dependenciesKind or [])) == sorted(
                indicator.depends_on)


def _perturbed(value, variable):
    if variable.type in ("Integer", "Int32"):
        high = int(variable.max) if variable.max is not None else int(value) + 1
        return int(value) + 1 if int(value) + 1 <= high else int(value) - 1
    return float(value) * (1.0 + 1e-3) + 1e-3


def _moves(fmu, declared, x, inputs) -> dict:
    """Perturb each state (from x) and each input: {unknown: the knowns it moved with}."""
    unknowns = sorted(declared)
    fmu.set_states(x)
    fmu.set(**inputs)
    base = dict(zip(unknowns, fmu.get(*unknowns))) if len(unknowns) > 1 else {unknowns[0]: fmu.get(unknowns[0])}
    moved = {}
    for k, state in enumerate(fmu.md_states):
        fmu.set_states(x + np.eye(fmu.nx)[k] * (1e-3 + 1e-3 * abs(x[k])))
        for name, value in zip(unknowns, fmu.get(*unknowns)):
            if value != base[name]:
                moved.setdefault(name, set()).add(state)
    fmu.set_states(x)
    for known, value in inputs.items():
        fmu.set(**{known: value * 1.001 + 1e-3})
        for name, now in zip(unknowns, fmu.get(*unknowns)):
            if now != base[name]:
                moved.setdefault(name, set()).add(known)
        fmu.set(**{known: value})
    return moved


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS)
def test_every_numerical_dependency_is_declared_in_continuous_time(native, model, version):
    """Perturb each state and input of a model exchange instance: every output, derivative or (FMI 3.0)
    event indicator that moves must declare that known (the declarations may be wider, never narrower);
    the manipulator slipping and stuck."""
    parameters, inputs, _ = RUNS[model]
    fmu = instance(native, model, version)
    try:
        fmu.initialize(**parameters, **inputs(0.3))
        fmu.set_time(0.3)
        fmu.md_states = [d.state for d in native_model_exchange.model_exchange(model).derivatives]
        declared = {u.variable.name: set(_names(u))
                    for u in (*fmu.md.outputs, *fmu.md.derivatives, *fmu.md.eventIndicators)}  # (FMI 3.0's)
        x = fmu.states() + np.linspace(0.1, 0.3, fmu.nx)  # away from the start values (thetas unequal)
        situations = [_moves(fmu, declared, x, inputs(0.3))]
        if model == "Manipulator":  # x2 crossed zero with |F| < cr: stuck
            fmu.set(u=0.7)
            fmu.set_states([x[0], -1e-3])
            fmu.event()
            assert fmu.get("friction_mode") == 0.0
            situations.append(_moves(fmu, declared, fmu.states(), {"u": 0.7}))
            if version == 3:
                assert situations[-1]["z_stick"] == {"y", "u"}  # cr - |F|: what FMI 3.0 declares
        sampled = native_model_exchange.model_exchange(model).time_events and not fmu.nx
        for moved in situations:
            assert moved or sampled  # a sampled sensor holds its samples in continuous time: nothing moves
            for name, knowns in moved.items():
                assert knowns - {name} <= declared[name], f"{name} moves with {sorted(knowns - declared[name])}"
    finally:
        fmu.free()


def _initial_unknowns(get, names):
    return dict(zip(names, get(*names))) if len(names) > 1 else {names[0]: get(names[0])}


@pytest.mark.parametrize("edition", ["python", "native2", "native3"])
@pytest.mark.parametrize("model", MODELS)
def test_every_numerical_initial_dependency_is_declared(native, fmu_paths, model, edition):
    """In initialization mode, perturb each parameter and input: every InitialUnknown that moves must
    declare it (a plant's y(0) moves with x1_start, never with u)."""
    if edition == "python":
        fmu = Driven(fmu_paths[model])
        variables = {v.name: v for v in fmu.md.modelVariables}

        def restart(**values):
            fmu.slave.reset()
            fmu.enter(**values)
        get = fmu.get
    else:
        fmu = instance(native, model, int(edition[-1]))
        variables = {v.name: v for v in fmu.md.modelVariables}

        def restart(**values):
            fmu.fmu.reset()
            fmu.enter(**values)
        get = fmu.get
    try:
        declared = {u.variable.name: set(_names(u)) for u in fmu.md.initialUnknowns}
        names = sorted(declared)
        base_values = {n: v.start for n, v in variables.items() if v.causality in ("parameter", "input")}
        base_values = {n: (int(v) if variables[n].type in ("Integer", "Int32") else float(v))
                       for n, v in base_values.items()}
        base_values.update(RUNS[model][0])
        base_values.update({k: v + 0.1 for k, v in RUNS[model][1](0.2).items()})
        restart(**base_values)
        base = _initial_unknowns(get, names)
        moved = {}
        for known in sorted(base_values):
            restart(**{**base_values, known: _perturbed(base_values[known], variables[known])})
            now = _initial_unknowns(get, names)
            for name in names:
                if now[name] != base[name]:
                    moved.setdefault(name, set()).add(known)
                    assert known in declared[name], f"{name} (initialization mode) moves with {known}"
        row = plant_registry.BY_IDENTIFIER.get(model)
        if row is not None and row.integrated:  # a plant: y(0) follows x1_start only
            assert moved["y"] == {"x1_start"}
            if edition != "python":  # its state derivatives do
                assert any("u" in known for name, known in moved.items() if name.startswith("der("))
    finally:
        fmu.free()


# --------------------------------------------------------- validators and checker
@pytest.mark.parametrize("edition", ["python", "native2", "native3"])
@pytest.mark.parametrize("model", MODELS)
def test_fmpy_validate_is_clean(native, fmu_paths, model, edition):
    from fmpy.validation import validate_fmu

    path = fmu_paths[model] if edition == "python" else native[model][int(edition[-1])]
    assert validate_fmu(str(path)) == []


@pytest.mark.parametrize("model", MODELS)
def test_the_compliance_checker_in_model_exchange_mode_is_clean(native, model, tmp_path):
    """fmuCheck -k me (forward Euler, its own event handling) strictly clean on each FMI 2.0 FMU; the
    manipulator over 3 s (it falls, reverses and sticks: friction events)."""
    if not FMUCHECK.exists():
        pytest.skip(f"{FMUCHECK} is absent (the shared tools are not beside this clone)")
    platforms = os.environ.get("AFC_NATIVE_PLATFORMS", "")
    if platforms and "linux64" not in platforms.split(","):
        pytest.skip("linux64 not built")
    checker = tmp_path / "fmuCheck-no-python"  # the native FMUs need no libpython (see tests/test_native.py)
    checker.write_text("#!/bin/sh\nunset LD_PRELOAD PYTHONHOME PYTHONPATH\n"
                       f"exec '{FMUCHECK.parent / 'fmuCheck.linux64'}' \"$@\"\n")
    checker.chmod(0o755)
    environment = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME")}
    environment["FMUCHECK_BIN"] = str(checker)
    stop = "3" if model == "Manipulator" else "1"
    completed = subprocess.run(["bash", str(FMUCHECK), "--strict", "--verbose", str(native[model][2]), "-k", "me",
                                "-s", stop], capture_output=True, text=True, env=environment, timeout=300)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    assert "PASS" in completed.stdout and "Version returned from ME FMU" in completed.stdout
