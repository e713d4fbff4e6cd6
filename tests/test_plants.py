"""The plant FMUs InvertedPendulum, Manipulator and the TrackingReference.

Driven through fmpy's low-level API (FMU2Slave): accuracy against scipy's
solve_ivp, the friction and payload outputs, the reference's feedthrough,
FMU state get/set/serialize, parameter validation, fmpy validate.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu
from scipy.integrate import solve_ivp

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from harness.fmu_build import builder as build_fmu  # noqa: E402
from harness.fmu_build import catalog as fmu_catalog  # noqa: E402
from tests.fmu_helpers import Driven  # noqa: E402
from plants import plant_integration  # noqa: E402
from plants.inverted_pendulum import model as inverted_pendulum_model  # noqa: E402
from plants.manipulator import model as manipulator_model  # noqa: E402
from plants import registry as plant_registry  # noqa: E402

#: every FMU of the plant registry: a new model folder is tested here as soon as it is added (its
#: dependencies, state round trip and bad parameters come from its fmu.py)
PLANTS = tuple(row.model_identifier for row in plant_registry.PLANT_FMUS)
RTOL, ATOL = 1e-10, 1e-12  # solve_ivp reference tolerances


# ----------------------------------------------------------------- helpers
@pytest.fixture(scope="session")
def plant_fmus(tmp_path_factory):
    """{model identifier: (path, unzip directory)}; built once, only if stale; extracted into pytest's tmp."""
    paths = build_fmu.ensure_built()
    return {name: (paths[name], extract(str(paths[name]), str(tmp_path_factory.mktemp(name)))) for name in PLANTS}


class Instance(Driven):
    """One plant FMU instance (a fresh instance name each time) on the session's extracted FMU."""

    count = 0

    def __init__(self, fmus, name):
        path, unzip_dir = fmus[name]
        Instance.count += 1
        super().__init__(path, f"{name}_{Instance.count}", unzip_dir=unzip_dir)


def pendulum_rhs(t, x, u, gv, mc, mp, lp, dist_gain):
    """Eq. (37) plus d(t) (docs/model.md section 7 (the plants)), written out independently of plants/."""
    x1, x2 = x
    mt = mc + mp
    den = lp * (4.0 / 3.0 - mp * math.cos(x1) ** 2 / mt)
    d = dist_gain * (3 * math.cos(2 * t) + 2 * math.sin((0.09 * t + 1) * t))
    dx2 = ((gv * math.sin(x1) - mp * lp * x2 ** 2 * math.cos(x1) * math.sin(x1) / mt) / den
           + (math.cos(x1) / mt) / den * u + d)
    return [x2, dx2]


def manipulator_rhs(t, x, u, gv, lr, dr, cr, vr, mr0, mr1):
    """Eqs. (38, 39) (docs/model.md section 7 (the plants)), written out independently of plants/."""
    x1, x2 = x
    mr = mr0 + mr1 * math.sin(t)
    J = 1.33 * mr * lr ** 2
    d = -(np.sign(x2) * cr + vr * x2) / J
    return [x2, -(dr * x2 + mr * gv * lr * math.cos(x1)) / J + u / J + d]


def reference_solution(rhs, x0, inputs, h, args):
    """solve_ivp over each communication interval with u held: states at every t_k = k h."""
    states = [np.array(x0, dtype=float)]
    for k, u in enumerate(inputs):
        sol = solve_ivp(rhs, (k * h, (k + 1) * h), states[-1], method="DOP853",
                        rtol=RTOL, atol=ATOL, args=(u, *args))
        assert sol.success
        states.append(sol.y[:, -1])
    return np.array(states)


def fmu_trajectory(instance, inputs, h):
    """(y, dy) at t_0 .. t_N with u_k set before doStep(t_k, h)."""
    out = [instance.get("y", "dy")]
    vr_u = [instance.vr["u"]]
    for k, u in enumerate(inputs):
        instance.slave.setReal(vr_u, [u])
        instance.slave.doStep(k * h, h)
        out.append(instance.get("y", "dy"))
    return np.array(out)


PENDULUM_DEFAULTS = dict(gv=9.8, mc=1.0, mp=0.1, lp=0.5)
MANIPULATOR_DEFAULTS = dict(gv=9.8, lr=0.25, dr=2.0, cr=1.5, vr=0.3, mr0=5.0, mr1=4.0)


# -------------------------------------------------------- pure functions
def test_internal_step_count_splits_into_steps_no_larger_than_the_bound():
    count = plant_integration.internal_step_count
    assert count(1e-3, 1e-4) == 10  # 1e-3 / 1e-4 = 10.000000000000002 in floating point
    assert count(1e-4, 1e-4) == 1
    assert count(1e-5, 1e-4) == 1
    assert count(1.05e-4, 1e-4) == 2
    assert count(0.3, 0.1) == 3
    assert count(0.0, 1e-4) == 0
    assert plant_integration.rk4_advance(None, 0.0, 1.0, 2.0, 0.0, 0.0, 1e-4, ()) == (1.0, 2.0)


def test_rk4_is_fourth_order_on_a_harmonic_oscillator():
    def oscillator(t, x1, x2, u, params):
        return x2, -x1 + u

    errors = []
    for internal in (0.1, 0.05, 0.025):
        x1, x2 = 1.0, 0.0
        for k in range(100):
            x1, x2 = plant_integration.rk4_advance(oscillator, k * 0.1, x1, x2, 0.0, 0.1, internal, None)
        errors.append(abs(x1 - math.cos(10.0)) + abs(x2 + math.sin(10.0)))
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(3.8 < p < 4.2 for p in orders), orders


def test_model_functions_match_the_spec_formulas():
    rng = np.random.default_rng(3)
    pend = inverted_pendulum_model.pendulum_params(9.8, 1.0, 0.7, 0.5, 1.3)
    manip = manipulator_model.manipulator_params(9.8, 0.25, 2.0, 1.5, 0.3, 5.0, 4.0)
    for t, x1, x2, u in rng.uniform(-3, 3, size=(50, 4)):
        got = inverted_pendulum_model.pendulum_derivative(t, x1, x2, u, pend)
        assert np.allclose(got, pendulum_rhs(t, (x1, x2), u, 9.8, 1.0, 0.7, 0.5, 1.3), rtol=1e-13, atol=1e-13)
        got = manipulator_model.manipulator_derivative(t, x1, x2, u, manip)
        assert np.allclose(got, manipulator_rhs(t, (x1, x2), u, 9.8, 0.25, 2.0, 1.5, 0.3, 5.0, 4.0),
                           rtol=1e-13, atol=1e-13)
    assert inverted_pendulum_model.pendulum_disturbance(2.0, 0.0) == 0.0
    assert math.isclose(inverted_pendulum_model.pendulum_disturbance(2.0, 2.0),
                        2 * (3 * math.cos(4.0) + 2 * math.sin(1.18 * 2.0)), rel_tol=1e-15)
    assert manipulator_model.sgn(0.0) == 0.0 and manipulator_model.manipulator_friction(0.0, 1.0, 1.5, 0.3) == 0.0
    assert manipulator_model.manipulator_derivative(0.0, 0.0, 0.0, 0.0, manip)[1] == pytest.approx(
        -5.0 * 9.8 * 0.25 / (1.33 * 5.0 * 0.25 ** 2))  # sgn(0) = 0: no Coulomb term at rest


# ----------------------------------------------------- open-loop accuracy
OPEN_LOOP_STEP = 1e-2  # communication step; the FMU integrates with max_internal_step = 1e-4 inside
OPEN_LOOP_STEPS = 500  # 5 s


@pytest.mark.parametrize("case, overrides", [
    ("pendulum_case1", dict(dist_gain=0.0)),
    ("pendulum_case2", dict(dist_gain=1.0)),
    ("pendulum_case3", dict(dist_gain=1.0, mp=1.0)),
])
def test_pendulum_open_loop_matches_solve_ivp(plant_fmus, case, overrides):
    """u_k = 3 sin(2 t_k) + 1 held over each 10 ms step; 5 s; the pole swings through large angles."""
    parameters = {**PENDULUM_DEFAULTS, "dist_gain": 0.0, **overrides}
    grid = np.arange(OPEN_LOOP_STEPS) * OPEN_LOOP_STEP
    inputs = 3.0 * np.sin(2.0 * grid) + 1.0
    x0 = (math.pi / 12, 0.0)
    args = tuple(parameters[n] for n in ("gv", "mc", "mp", "lp", "dist_gain"))
    expected = reference_solution(pendulum_rhs, x0, inputs, OPEN_LOOP_STEP, args)
    plant = Instance(plant_fmus, "InvertedPendulum").initialize(**overrides)
    try:
        got = fmu_trajectory(plant, inputs, OPEN_LOOP_STEP)
    finally:
        plant.free()
    assert np.ptp(expected[:, 0]) > 1.0  # a real excursion, not a trivial trajectory
    assert np.max(np.abs(got - expected)) < 1e-6, np.max(np.abs(got - expected), axis=0)


def test_manipulator_open_loop_matches_solve_ivp(plant_fmus):
    """x2 kept away from 0 (no event needed): x2(0) = 2 rad/s and u_k = 40 + 10 sin(3 t_k) N.m
    exceeds gravity (<= 22.05 N.m) plus Coulomb friction (1.5 N.m), so the arm keeps turning
    forwards (x2 > 0.5 rad/s is asserted) and the sign term never switches."""
    grid = np.arange(OPEN_LOOP_STEPS) * OPEN_LOOP_STEP
    inputs = 40.0 + 10.0 * np.sin(3.0 * grid)
    x0 = (math.pi / 6, 2.0)
    args = tuple(MANIPULATOR_DEFAULTS[n] for n in ("gv", "lr", "dr", "cr", "vr", "mr0", "mr1"))
    expected = reference_solution(manipulator_rhs, x0, inputs, OPEN_LOOP_STEP, args)
    plant = Instance(plant_fmus, "Manipulator").initialize(x2_start=2.0)
    try:
        got = fmu_trajectory(plant, inputs, OPEN_LOOP_STEP)
    finally:
        plant.free()
    assert expected[:, 1].min() > 0.5 and got[:, 1].min() > 0.5
    assert np.max(np.abs(got - expected)) < 1e-6, np.max(np.abs(got - expected), axis=0)


def test_fmus_equal_the_pure_functions_bit_for_bit(plant_fmus):
    """The master's in-process oracle (rk4_advance + the model modules) reproduces the FMUs exactly."""
    h, steps = 1e-3, 300
    cases = [
        ("InvertedPendulum", dict(dist_gain=1.0, mp=1.0, max_internal_step=3e-4),
         inverted_pendulum_model.pendulum_derivative,
         inverted_pendulum_model.pendulum_params(9.8, 1.0, 1.0, 0.5, 1.0), (math.pi / 12, 0.0)),
        ("Manipulator", dict(max_internal_step=3e-4), manipulator_model.manipulator_derivative,
         manipulator_model.manipulator_params(**MANIPULATOR_DEFAULTS), (math.pi / 6, 0.0)),
    ]
    for name, overrides, derivative, params, (x1, x2) in cases:
        plant = Instance(plant_fmus, name).initialize(**overrides)
        try:
            for k in range(steps):
                u = 5.0 * math.sin(7.0 * k * h)
                x1, x2 = plant_integration.rk4_advance(derivative, k * h, x1, x2, u, h, 3e-4, params)
                plant.set(u=u)
                plant.slave.doStep(k * h, h)
                assert plant.get("y", "dy") == [x1, x2], (name, k)
        finally:
            plant.free()


def manipulator_rhs_fixed_sign(t, x, u, sign, gv, lr, dr, cr, vr, mr0, mr1):
    """(38, 39) with sgn(x2) replaced by a constant: smooth on one side of x2 = 0."""
    x1, x2 = x
    mr = mr0 + mr1 * math.sin(t)
    J = 1.33 * mr * lr ** 2
    return [x2, (u - dr * x2 - mr * gv * lr * math.cos(x1) - sign * cr - vr * x2) / J]


def test_manipulator_converges_across_friction_switches(plant_fmus):
    """Through a zero crossing of x2 (no event handling in the FMU) the error shrinks with the
    internal step, but only at first order.  The reference gives solve_ivp an event at x2 = 0:
    it integrates each side with the sign term fixed and restarts at the crossing.  u = -20 N.m is
    held, so x2 crosses 0 transversally (|u - gravity torque| > cr: no sticking) once, from x2 > 0."""
    args = tuple(MANIPULATOR_DEFAULTS[n] for n in ("gv", "lr", "dr", "cr", "vr", "mr0", "mr1"))
    h, steps, u = 1e-2, 100, -20.0
    t_end = steps * h

    def crossing(t, x, *a):
        return x[1]
    crossing.terminal = True

    t, x, sign, crossings = 0.0, np.array([math.pi / 6, 1.0]), 1.0, 0
    while t < t_end:
        crossing.direction = -sign  # leave the side x2 * sign > 0
        sol = solve_ivp(manipulator_rhs_fixed_sign, (t, t_end), x, method="DOP853", rtol=RTOL,
                        atol=ATOL, args=(u, sign, *args), events=crossing)
        assert sol.success
        t, x = sol.t[-1], sol.y[:, -1]
        if sol.status == 1:
            crossings += 1
            t_cross = t
            x = np.array([x[0], 0.0])
            sides = [manipulator_rhs_fixed_sign(t, x, u, s, *args)[1] for s in (1.0, -1.0)]
            assert np.sign(sides[0]) == np.sign(sides[1]) == -sign, "transversal crossing expected"
            sign = -sign
    assert crossings == 1
    errors = []
    for internal in (1e-3, 5e-4, 2.5e-4, 1.25e-4):
        plant = Instance(plant_fmus, "Manipulator").initialize(x2_start=1.0, max_internal_step=internal)
        try:
            got = fmu_trajectory(plant, [u] * steps, h)[-1]
        finally:
            plant.free()
        errors.append(float(np.max(np.abs(got - x))))
    # First order: the one internal step that straddles the switch is off by at most about
    # (jump of dx2 = 2 cr / J) * (internal step); where the switch falls inside that step varies,
    # so the error is not monotone in the step, only bounded by C * step.  A smooth right-hand
    # side would give ~1e-12 here (fourth order).
    jump = 2 * MANIPULATOR_DEFAULTS["cr"] / (1.33 * (5.0 + 4.0 * math.sin(t_cross)) * 0.25 ** 2)
    for internal, error in zip((1e-3, 5e-4, 2.5e-4, 1.25e-4), errors):
        assert 1e-8 < error < jump * internal, errors


# ------------------------------------------------- friction, payload, init
def test_friction_opposes_motion_and_payload_follows_mr0_plus_mr1_sin_t(plant_fmus):
    p = dict(MANIPULATOR_DEFAULTS, mr0=6.0, mr1=2.5, cr=1.2, vr=0.4)
    plant = Instance(plant_fmus, "Manipulator").initialize(mr0=p["mr0"], mr1=p["mr1"], cr=p["cr"], vr=p["vr"])
    h = 1e-3
    signs = set()
    try:
        for k in range(3000):
            t = k * h
            y, dy, d, mr = plant.get("y", "dy", "d", "mr")
            assert mr == pytest.approx(p["mr0"] + p["mr1"] * math.sin(t), rel=1e-14, abs=1e-14)
            J = 1.33 * mr * p["lr"] ** 2
            assert d == pytest.approx(-(np.sign(dy) * p["cr"] + p["vr"] * dy) / J, rel=1e-13, abs=1e-15)
            if dy != 0.0:
                assert np.sign(d) == -np.sign(dy)
                signs.add(np.sign(dy))
            plant.set(u=25.0 * math.sin(3.0 * t))
            plant.slave.doStep(t, h)
    finally:
        plant.free()
    assert signs == {1.0, -1.0}  # the arm moved both ways


def test_plant_outputs_equal_the_start_values(plant_fmus):
    plant = Instance(plant_fmus, "InvertedPendulum").enter(x1_start=0.4, x2_start=-0.3, dist_gain=1.0)
    try:
        # initialization mode: the outputs already follow the start values (InitialUnknowns)
        assert plant.get("y", "dy") == [0.4, -0.3]
        plant.slave.exitInitializationMode()
        assert plant.get("y", "dy", "d") == [0.4, -0.3, 3.0]  # d(0) = 3 cos 0 + 2 sin 0
    finally:
        plant.free()
    plant = Instance(plant_fmus, "Manipulator").enter(x1_start=-0.2, x2_start=0.5)
    try:
        assert plant.get("y", "dy", "mr") == [-0.2, 0.5, 5.0]
        plant.slave.exitInitializationMode()
        y, dy, d, mr = plant.get("y", "dy", "d", "mr")
        assert (y, dy, mr) == (-0.2, 0.5, 5.0)
        assert d == pytest.approx(-(1.5 + 0.3 * 0.5) / (1.33 * 5.0 * 0.25 ** 2))
    finally:
        plant.free()
    for name, start in (("InvertedPendulum", math.pi / 12), ("Manipulator", math.pi / 6)):
        plant = Instance(plant_fmus, name).initialize()
        try:
            assert plant.get("y", "dy") == [start, 0.0]
        finally:
            plant.free()


def test_diverging_state_fails_with_a_clear_message(plant_fmus):
    plant = Instance(plant_fmus, "InvertedPendulum").initialize()
    try:
        plant.set(u=1e306)
        with pytest.raises(FMICallException):
            for k in range(10):
                plant.slave.doStep(k * 0.1, 0.1)
        assert any("diverged" in m for _, m in plant.messages), plant.messages
    finally:
        plant.free()


# ------------------------------------------------------------- reference
def test_reference_e_and_de_are_direct_feedthrough(plant_fmus):
    ref = Instance(plant_fmus, "TrackingReference").enter(amplitude=1.0, omega=1.0)
    try:
        ref.set(y=0.1, dy=-0.2)  # initialization mode: e(0), de(0) available for the controller
        assert ref.get("ym", "dym", "e", "de") == [0.0, 1.0, -0.1, 1.2]
        ref.slave.exitInitializationMode()
        ref.set(y=0.3, dy=-0.25)
        ym, dym, e, de = ref.get("ym", "dym", "e", "de")  # no doStep in between
        assert e == ym - 0.3 and de == dym - (-0.25)
        h = 1e-2
        for k in range(157):
            ref.slave.doStep(k * h, h)
        t = 157 * h
        ref.set(y=0.5, dy=0.125)
        ym, dym, ddym, e, de = ref.get("ym", "dym", "ddym", "e", "de")
        assert ym == pytest.approx(math.sin(t), abs=1e-14)
        assert dym == pytest.approx(math.cos(t), abs=1e-14)
        assert ddym == pytest.approx(-math.sin(t), abs=1e-14)
        assert e == ym - 0.5 and de == dym - 0.125
    finally:
        ref.free()
    ref = Instance(plant_fmus, "TrackingReference").initialize()  # defaults: pi/6 sin(t)
    try:
        ref.slave.doStep(0.0, 0.5)
        assert ref.get("ym", "dym", "ddym") == pytest.approx(
            [math.pi / 6 * math.sin(0.5), math.pi / 6 * math.cos(0.5), -math.pi / 6 * math.sin(0.5)], abs=1e-15)
    finally:
        ref.free()


def test_model_structure_declares_the_true_dependencies(plant_fmus):
    """Each output's dependencies in the description are the inputs its table row names (direct
    feedthrough), none else."""
    for name, (path, _) in plant_fmus.items():
        expected = {v.name: sorted(v.depends_on) for v in fmu_catalog.model_class(name).VARIABLES
                    if v.causality == "output"}
        md = read_model_description(str(path))
        deps = {u.variable.name: sorted(d.name for d in u.dependencies) for u in md.outputs}
        assert deps == expected, name
        assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate


# ------------------------------------------------------------------ state
def outputs_of(name) -> tuple:
    return tuple(v.name for v in fmu_catalog.model_class(name).VARIABLES if v.causality == "output")


def drive(instance, name, first, count, outputs):
    """count communication steps of the FMU's test drive from step index first; the outputs after each."""
    test_drive = fmu_catalog.declaration(name).test_drive()
    h = test_drive.step
    record = []
    for k in range(first, first + count):
        t = k * h
        instance.set(**test_drive.inputs(t))
        instance.slave.doStep(t, h)
        record.append(instance.get(*outputs))
    return record


@pytest.mark.parametrize("name", PLANTS)
def test_state_restore_and_serialization_give_bit_identical_continuations(plant_fmus, name):
    """Along the FMU's test drive (its parameters, its inputs u(t), its step; fmu.py's test_drive())."""
    outputs = outputs_of(name)
    fmu = Instance(plant_fmus, name).initialize(**fmu_catalog.declaration(name).test_drive().parameters)
    other = None
    try:
        drive(fmu, name, 0, 200, outputs)
        state = fmu.slave.getFMUstate()
        first = drive(fmu, name, 200, 200, outputs)
        fmu.slave.setFMUstate(state)
        assert drive(fmu, name, 200, 200, outputs) == first
        serialized = fmu.slave.serializeFMUstate(state)
        fmu.slave.freeFMUstate(state)
        other = Instance(plant_fmus, name).initialize()  # default parameters: the state brings them
        restored = other.slave.deSerializeFMUstate(serialized)
        other.slave.setFMUstate(restored)
        assert drive(other, name, 200, 200, outputs) == first
        other.slave.freeFMUstate(restored)
    finally:
        fmu.free()
        if other is not None:
            other.free()


# ------------------------------------------------------------- validation
def out_of_range(variable) -> list:
    """Values the declared valid range of a Real parameter rejects: NaN and inf always; the bound
    itself when it is excluded, and a value beyond each bound."""
    values = [math.nan, math.inf]
    for bound, excluded, beyond in ((variable.minimum, variable.exclusive_minimum, -1.0),
                                    (variable.maximum, variable.exclusive_maximum, 1.0)):
        if bound is not None:
            values += ([bound] if excluded else []) + [bound + beyond * max(1.0, abs(variable.start))]
    return values


def bad_parameters(name) -> list:
    """(parameter, value, other parameters) of every value the FMU must reject: out of each parameter's
    declared range, and the cross-parameter violations its test drive names."""
    cases = [(v.name, value, {}) for v in fmu_catalog.model_class(name).VARIABLES
             if v.causality == "parameter" and v.kind == "Real" for value in out_of_range(v)]
    return cases + list(fmu_catalog.declaration(name).test_drive().cross_parameter_violations)


BAD_PARAMETERS = [(name, *case) for name in PLANTS for case in bad_parameters(name)]


@pytest.mark.parametrize("name, parameter, value, others", BAD_PARAMETERS)
def test_bad_parameter_fails_with_a_message_naming_it_and_its_range(plant_fmus, name, parameter, value, others):
    """Finite bad values fail at exitInitializationMode; NaN/inf already at setReal (the base rejects
    non-finite values as they are set).  pythonfmu 0.7 reports fmi2Fatal for any Python exception."""
    fmu = Instance(plant_fmus, name)
    try:
        fmu.slave.setupExperiment(startTime=0.0)
        fmu.slave.enterInitializationMode()
        fmu.set(**others)
        with pytest.raises(FMICallException) as failure:
            fmu.set(**{parameter: value})
            assert math.isfinite(value), "a non-finite value must be rejected by setReal"
            fmu.slave.exitInitializationMode()
        assert failure.value.status >= 3  # error or fatal (pythonfmu 0.7: fatal)
        errors = [m for status, m in fmu.messages if status >= 3 and parameter in m]
        assert errors, fmu.messages
        assert any(f"parameter {parameter} = " in m and "valid range" in m for m in errors), errors
    finally:
        fmu.free()
    # the process survives and the FMU instantiates and runs again
    again = Instance(plant_fmus, name).initialize()
    try:
        again.slave.doStep(0.0, 1e-3)
    finally:
        again.free()


def test_mr1_message_states_the_payload_constraint(plant_fmus):
    fmu = Instance(plant_fmus, "Manipulator").enter(mr0=3.0, mr1=3.0)
    try:
        with pytest.raises(FMICallException):
            fmu.slave.exitInitializationMode()
        assert any("mr1 = 3.0" in m and "mr1 < mr0 = 3.0" in m for _, m in fmu.messages), fmu.messages
    finally:
        fmu.free()


@pytest.mark.parametrize("name", PLANTS)
def test_fmpy_validate_finds_no_problem(plant_fmus, name):
    assert validate_fmu(str(plant_fmus[name][0])) == []
