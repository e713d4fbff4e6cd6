"""The Sensor and Actuator FMUs (plants/sensor/, plants/actuator/; docs/model.md section 13 (the sensor and
the actuator)).

* the pure functions: SplitMix64 against the reference generator's outputs, the noise a standard normal
  that does not depend on which samples were drawn before, the quantiser, the filter, the chain's clock
  and delay, the rate limiter's closed form against solve_ivp;
* both editions (pythonfmu, native FMI 2.0 and 3.0) give the pure functions' samples bit for bit, and
  the samples at the sample instants do not depend on the host's step (H and H/3) nor on the host
  (fmpy's FMU2Slave, fmpy.simulate_fmu, our master);
* a sample inside a host step comes from the input held over it; the delay line starts full, the filter
  at rest, the rate limiter at rest from the command of the first doStep, also in a host that does not
  propagate initial values; a host that reads before it sets gets one warning;
* Model Exchange (native): the samples are time events, announced and taken from the event's inputs; a
  host that ignores them gets the samples and one warning; a clockless quantiser is refused there; the
  rate limiter's derivative is the slew law.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import simulate_fmu
from scipy import stats
from scipy.integrate import solve_ivp

from harness import master
from harness import scenario as scenarios
from harness.fmu_build import native as build_native
from plants import sampled_chain as chain
from plants.actuator import model as actuator_model
from plants.sensor import model as sensor_model
from tests import me_helpers as me
from tests.fmu_helpers import Driven

CHANNELS = ("y", "dy", "d2y", "d3y")
MEASURED = tuple(f"{c}_measured" for c in CHANNELS)
needs_native = pytest.mark.skipif(not build_native.compiler_available(),
                                  reason="zig's C compiler is not installed (pip install -e '.[native]')")


# ------------------------------------------------------------------ pure functions
def test_splitmix64_gives_the_reference_generators_outputs():
    """Vigna's splitmix64.c: seed 0 and seed 1234567 (the values of its published test runs)."""
    assert [sensor_model.splitmix64(0, i) for i in (1, 2, 3, 4)] == [
        0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4, 0x06C45D188009454F, 0xF88BB8A8724C81EC]
    assert [sensor_model.splitmix64(1234567, i) for i in (1, 2, 3)] == [
        0x599ED017FB08FC85, 0x2C73F08458540FA5, 0x883EBCE5A3F27C77]


def test_the_noise_is_standard_normal_independent_and_counter_based():
    key = sensor_model.stream_key(3, 1, 0)
    draws = np.array([sensor_model.gaussian(key, k) for k in range(20000)])
    assert stats.kstest(draws, "norm").pvalue > 1e-3
    assert abs(draws.mean()) < 4 / math.sqrt(draws.size) and abs(draws.std() - 1.0) < 0.02
    others = [sensor_model.stream_key(3, 1, 1), sensor_model.stream_key(3, 2, 0), sensor_model.stream_key(4, 1, 0)]
    for other in others:  # another channel, local seed or global seed: an independent stream
        assert other != key
        series = np.array([sensor_model.gaussian(other, k) for k in range(draws.size)])
        assert abs(np.corrcoef(draws, series)[0, 1]) < 4 / math.sqrt(draws.size)
    lagged = np.corrcoef(draws[:-1], draws[1:])[0, 1]
    assert abs(lagged) < 4 / math.sqrt(draws.size)
    # a sample is a function of its index alone: drawn alone, late, it is the same number
    assert sensor_model.gaussian(key, 12345) == draws[12345]


def test_quantiser_filter_and_measurement():
    q = sensor_model.quantise
    assert q(0.14, 0.1) == pytest.approx(0.1) and q(0.16, 0.1) == pytest.approx(0.2)
    assert q(-0.25, 0.5) == 0.0 and q(0.25, 0.5) == 0.5  # halves rounded up (mid-tread)
    assert q(0.123456789, 0.0) == 0.123456789
    assert sensor_model.filter_coefficient(1e-3, 0.0) == 1.0
    assert sensor_model.filter_coefficient(1e-3, 4e-3) == pytest.approx(1 - math.exp(-0.25), rel=1e-15)
    key = sensor_model.stream_key(1, 1, 0)
    assert sensor_model.measure(key, 7, 0.123456789, 5.0, 0.0, 0.0, 1.0, False) == 0.123456789  # all off
    # a unit step through the filter from rest: 1 - (1 - a)^k after k samples
    a = sensor_model.filter_coefficient(1e-3, 5e-3)
    value = sensor_model.measure(key, 0, 0.0, 0.0, 0.0, 0.0, a, True)
    for k in range(1, 30):
        value = sensor_model.measure(key, k, 1.0, value, 0.0, 0.0, a, True)
    assert value == pytest.approx(1 - (1 - a) ** 29, rel=1e-12)
    noisy = sensor_model.measure(key, 3, 0.5, 0.0, 0.01, 0.0, 1.0, False)
    assert noisy == 0.5 + 0.01 * sensor_model.gaussian(key, 3)


def test_the_chain_counts_its_samples_and_delays_them():
    state = chain.new_state(2)
    assert chain.samples_before(state, 0.0, 0.0, 1e-3) == 0  # the sample at the step's end is not its
    assert chain.samples_before(state, 2.5e-3, 0.0, 1e-3) == 3  # 0, 1, 2 ms
    assert chain.samples_before(state, 3e-3 * (1 + 1e-12), 0.0, 1e-3) == 3  # rounding of a host's sum
    assert chain.at_instant(0.1 + 0.2, 0.0, 0.1, 3) and not chain.at_instant(0.305, 0.0, 0.1, 3)
    for k in range(5):
        chain.commit(state, 2, [float(k), -float(k)])
    assert chain.committed(state) == 5
    assert [chain.delayed_index(k, 2) for k in range(5)] == [0, 0, 0, 1, 2]  # the first sample fills the line
    assert state[chain.slot(2, 4, 1)] == -4.0
    assert chain.held_index(state, 5e-3, 0.0, 1e-3) == (5, True)  # sample 5 due now: pending
    assert chain.held_index(state, 5.5e-3, 0.0, 1e-3) == (4, False)


@pytest.mark.parametrize("applied, target, duration", [(0.0, 10.0, 0.02), (0.0, 10.0, 3e-3), (4.0, -3.0, 0.05),
                                                       (0.0, 0.05, 0.01), (2.0, 1.99, 1e-3)])
def test_the_slew_is_the_exact_solution_of_the_rate_limiter(applied, target, duration):
    """(A2) with R = 500, Td = 2 ms: the closed form against solve_ivp."""
    rate, time_constant = 500.0, 2e-3
    solution = solve_ivp(lambda t, r: [actuator_model.slew_rate(r[0], target, rate, time_constant)],
                         (0.0, duration), [applied], method="LSODA", rtol=1e-12, atol=1e-12, max_step=duration / 50)
    exact = actuator_model.slew(applied, target, duration, rate, time_constant)
    assert exact == pytest.approx(solution.y[0, -1], abs=1e-8)
    assert actuator_model.saturate(20.0, 15.0) == 15.0 and actuator_model.saturate(-20.0, 15.0) == -15.0
    assert actuator_model.saturate(-20.0, 0.0) == -20.0 and actuator_model.saturate(3.0, 15.0) == 3.0


# ------------------------------------------------------------------ FMUs, both editions
@pytest.fixture(scope="module")
def native():
    return build_native.ensure_built() if build_native.compiler_available() else {}


@pytest.fixture(scope="module")
def editions(fmu_paths, native):
    """{edition: {model: FMI 2.0 co-simulation FMU path}}."""
    found = {"python": {m: fmu_paths[m] for m in ("Sensor", "Actuator")}}
    if native:
        found["native"] = {m: native[m][2] for m in ("Sensor", "Actuator")}
    return found


def drive(path, parameters, inputs, step, steps, name="hw", read_first=False, propagate=True):
    """A co-simulation run driven through fmpy's FMU2Slave: the outputs at each communication point
    (after its inputs are set; ``read_first``: read before they are set, as a Jacobi host does) and the
    log.  ``propagate`` False: the inputs stay at their start values until the first doStep."""
    fmu = Driven(path, name)
    outputs = [v.name for v in fmu.md.modelVariables if v.causality == "output"]
    try:
        fmu.enter(**parameters, **(inputs(0.0) if propagate else {}))
        fmu.slave.exitInitializationMode()
        rows = []
        for n in range(steps + 1):
            t = n * step
            if read_first:
                rows.append(fmu.get(*outputs))
            fmu.set(**inputs(t))
            if not read_first:
                rows.append(fmu.get(*outputs))
            if n < steps:
                fmu.slave.doStep(t, step)
        return np.array(rows), fmu.messages
    finally:
        fmu.free()


SIGMAS = {"noise_y": 1e-3, "noise_dy": 2e-2, "noise_d2y": 0.5, "noise_d3y": 3.0}
CONSTANT = {"y": 0.25, "dy": -0.5, "d2y": 1.0, "d3y": 2.0}


def expected_noise(parameters, count):
    """The samples of a sensor with constant inputs CONSTANT: x + sigma n(seed, local_seed, c, k)."""
    keys = [sensor_model.stream_key(parameters["seed"], parameters["local_seed"], c) for c in range(4)]
    return np.array([[CONSTANT[name] + parameters[f"noise_{name}"] * sensor_model.gaussian(keys[c], k)
                      for c, name in enumerate(CHANNELS)] for k in range(count)])


def test_both_editions_draw_the_pure_functions_noise_bit_for_bit(editions):
    parameters = dict(sample_period=1e-3, seed=11, local_seed=4, **SIGMAS)
    expected = expected_noise(parameters, 301)
    for edition, paths in editions.items():
        rows, messages = drive(paths["Sensor"], parameters, lambda t: CONSTANT, 1e-3, 300)
        assert np.array_equal(rows, expected), edition
        assert not messages


def master_samples(edition_paths, parameters, step, stop):
    """Our master running a sensor alone (its inputs at their start values, 0) at ``step``."""
    recorded = ", ".join(f'"sensor.{name}"' for name in MEASURED)
    text = f"""name = "sensor_alone"
controller_instance = "sensor"
[experiment]
stop = {stop!r}
step = {step!r}
[components.sensor]
fmu = "Sensor"
parameters = {{ {", ".join(f"{k} = {v!r}" for k, v in parameters.items())} }}
[signals]
e = "sensor.y_measured"
de = "sensor.dy_measured"
ym = "sensor.d2y_measured"
dym = "sensor.d3y_measured"
u = "sensor.y_measured"
[record]
variables = [{recorded}]
"""
    scenario = scenarios.parse(scenarios.tomllib.loads(text))
    result = master.simulate(scenario, fmu_paths=edition_paths)
    return result.time, np.column_stack([result.signal(f"sensor.{name}") for name in MEASURED])


def at_instants(time, rows, period, count):
    """The rows at the sample instants k * period, k < count (found by rounding the grid's times)."""
    index = {round(t / period * 1e6): i for i, t in enumerate(time)}
    return np.array([rows[index[k * 1_000_000]] for k in range(count)])


def test_the_samples_depend_neither_on_the_hosts_step_nor_on_the_host(editions, native, tmp_path):
    """Every stage on (noise, quantiser, filter, a delay of 2), Ts = 3 ms; hosts at H = 1 ms and H/3:
    fmpy's FMU2Slave with an input that changes at the sample instants, fmpy.simulate_fmu (FMI 2.0 and
    3.0) and our master with constant inputs: the samples at the instants are the same numbers."""
    period, count = 3e-3, 40
    parameters = dict(sample_period=period, delay_samples=2, filter_time_constant=5e-3, seed=2, local_seed=9,
                      quantum_y=1e-3, quantum_dy=1e-2, **SIGMAS)

    def staircase(t):  # a value per sample interval: the same at each instant whatever the grid
        k = math.floor(t / period + 1e-6)
        return {"y": 0.01 * k, "dy": -0.02 * k, "d2y": 0.5, "d3y": 0.0}

    runs = {}
    for edition, paths in editions.items():
        for divisor in (1, 3):
            step = 1e-3 / divisor
            steps = round(count * period / step)
            rows, _ = drive(paths["Sensor"], parameters, staircase, step, steps)
            runs[(edition, "FMU2Slave", divisor)] = at_instants(np.arange(steps + 1) * step, rows, period, count)
    first = runs[("python", "FMU2Slave", 1)]
    assert np.ptp(first[:, 0]) > 0.1  # the staircase came through
    for key, samples in runs.items():
        assert np.array_equal(samples, first), key
    # constant inputs (their start values): fmpy.simulate_fmu and our master
    constant = {}
    files = {("python", 2): editions["python"]["Sensor"]}
    if native:
        files.update({("native", 2): native["Sensor"][2], ("native", 3): native["Sensor"][3]})
    for (edition, version), path in files.items():
        for divisor in (1, 3):
            step = 1e-3 / divisor
            result = simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=count * period, step_size=step,
                                  output_interval=step, start_values={**parameters, **CONSTANT},
                                  output=list(MEASURED))
            rows = np.column_stack([result[name] for name in MEASURED])
            constant[(edition, f"fmpy FMI {version}.0", divisor)] = at_instants(result["time"], rows, period, count)
    zero = dict(parameters)
    for edition, paths in editions.items():
        for divisor in (1, 3):
            time, rows = master_samples(paths, zero, 1e-3 / divisor, count * period)
            constant[(edition, "our master", divisor)] = at_instants(time, rows, period, count)
    reference = constant[("python", "fmpy FMI 2.0", 1)]
    for key, samples in constant.items():
        if key[1] == "our master":  # inputs 0: the same noise, quantised and filtered from 0
            assert np.array_equal(samples, constant[("python", "our master", 1)]), key
        else:
            assert np.array_equal(samples, reference), key
    assert not np.array_equal(constant[("python", "our master", 1)], reference)  # the inputs count


def test_a_sample_inside_a_step_comes_from_the_input_held_over_it_and_the_delay_line_starts_full(editions):
    """Ts = 2.5 ms over 1 ms host steps: sample k is the input of the last communication point at or
    before t_k; with a delay of 2 the first two samples read sample 0."""
    parameters = dict(sample_period=2.5e-3, delay_samples=2)
    ramp = lambda t: {"y": round(t * 1000) * 0.1}  # noqa: E731 - 0.1 per millisecond
    expected_samples = [round(math.floor(k * 2.5 + 1e-9)) * 0.1 for k in range(12)]
    for edition, paths in editions.items():
        rows, _ = drive(paths["Sensor"], parameters, ramp, 1e-3, 25)
        for n in range(26):
            k = math.floor(n / 2.5 + 1e-9)  # the sample that holds at t = n ms
            assert rows[n][0] == pytest.approx(expected_samples[max(k - 2, 0)], abs=1e-12), (edition, n)


def test_the_actuator_saturates_delays_and_slews_as_the_exact_solution(editions):
    """u_max = 8, R = 400 /s, Td = 2 ms, a 2 ms clock with one sample of delay, commands that jump;
    the rate limiter starts at rest from the first command."""
    parameters = dict(sample_period=2e-3, delay_samples=1, u_max=8.0, rate_limit=400.0, rate_time_constant=2e-3)
    commands = lambda t: {"u": 12.0 if t < 0.02 else (-3.0 if t < 0.05 else 5.0)}  # noqa: E731
    step, steps = 1e-3, 80
    r, held, reference = None, [], []
    for n in range(steps + 1):  # the chain: one sample every 2 steps, applied one sample late
        t = n * step
        k = n // 2
        held.append(actuator_model.saturate(commands(max(k - 1, 0) * 2e-3)["u"], 8.0))
    r = held[0]
    reference.append(r)
    for n in range(steps):
        r = actuator_model.slew(r, held[n], step, 400.0, 2e-3)
        reference.append(r)
    for edition, paths in editions.items():
        rows, messages = drive(paths["Actuator"], parameters, commands, step, steps)
        assert rows[:, 0].tolist() == pytest.approx(reference, abs=1e-12), edition
        assert np.array_equal(rows[:, 0], rows[:, 1])  # u_applied is the rate limiter's state
        assert max(abs(rows[:, 0])) <= 8.0 and not messages
    neutral = {}
    for edition, paths in editions.items():  # every limit off: the command itself
        rows, _ = drive(paths["Actuator"], {}, lambda t: {"u": math.sin(40 * t) * 1e3}, step, 50)
        assert rows[:, 0].tolist() == [math.sin(40 * (n * step)) * 1e3 for n in range(51)]


def test_without_initial_values_both_start_from_the_inputs_of_the_first_step(editions):
    """A host that leaves the inputs at their start values until the first doStep: the same outputs."""
    cases = (("Sensor", dict(sample_period=2e-3, delay_samples=1, filter_time_constant=3e-3, noise_y=1e-3,
                             seed=5), lambda t: {"y": 0.3 + t, "dy": 1.0}),
             ("Actuator", dict(sample_period=2e-3, delay_samples=1, rate_limit=100.0, u_max=2.0),
              lambda t: {"u": 1.5 + 10 * t}))
    for model, parameters, inputs in cases:
        for edition, paths in editions.items():
            propagated, _ = drive(paths[model], parameters, inputs, 1e-3, 20)
            late, _ = drive(paths[model], parameters, inputs, 1e-3, 20, propagate=False)
            assert np.array_equal(late, propagated), (model, edition)


def test_a_host_that_reads_before_it_sets_gets_one_warning_naming_the_time(editions):
    cases = (("Sensor", dict(sample_period=1e-3), lambda t: {"y": t}, "y_measured"),
             ("Actuator", dict(u_max=5.0), lambda t: {"u": t}, "u_applied"))
    for model, parameters, inputs, output in cases:
        for edition, paths in editions.items():
            _, messages = drive(paths[model], parameters, inputs, 1e-3, 10, read_first=True)
            warnings = [m for _, m in messages if "before it set" in m]
            assert len(warnings) == 1 and "at t = 0.001 " in warnings[0] and output in warnings[0], (model, edition)
            assert "Jacobi" in warnings[0]
            _, messages = drive(paths[model], parameters, inputs, 1e-3, 10)  # set, then read: nothing to say
            assert not messages, (model, edition)
    for edition, paths in editions.items():  # a delay of one sample: the output does not depend on the input
        _, messages = drive(paths["Sensor"], dict(sample_period=1e-3, delay_samples=1), lambda t: {"y": t}, 1e-3, 10,
                            read_first=True)
        assert not messages, edition


# ------------------------------------------------------------------ Model Exchange (native)
def _update(fmu: me.MeInstance) -> tuple:
    """One event update: (next event time defined, next event time)."""
    if fmu.version == 2:
        info = fmu.fmu.newDiscreteStates()
        return bool(info[4]), info[5]
    result = fmu.fmu.updateDiscreteStates()
    return bool(result[4]), result[5]


@needs_native
@pytest.mark.parametrize("version", [2, 3])
def test_model_exchange_takes_the_samples_at_announced_time_events(native, version):
    fmu = me.MeInstance(native["Sensor"][version], version, "sensor")
    try:
        fmu.enter(0.0, sample_period=2e-3, noise_y=1e-3, seed=3, y=0.5)
        fmu.fmu.exitInitializationMode()
        assert _update(fmu) == (True, 2e-3)  # sample 0 taken at the initial event, the next announced
        fmu.fmu.enterContinuousTimeMode()
        key = sensor_model.stream_key(3, 1, 0)
        first = 0.5 + 1e-3 * sensor_model.gaussian(key, 0)
        assert fmu.get("y_measured") == first
        for t in (1e-3, 2e-3):  # in continuous time the sample holds, up to the event's time included
            fmu.set_time(t)
            fmu.set(y=0.7)
            assert fmu.get("y_measured") == first
        fmu.fmu.enterEventMode()
        assert _update(fmu) == (True, 4e-3)
        assert fmu.get("y_measured") == 0.7 + 1e-3 * sensor_model.gaussian(key, 1)
        fmu.set(y=0.9)  # another FMU's event changed this input: a later pass takes the sample again
        assert _update(fmu) == (True, 4e-3)
        assert fmu.get("y_measured") == 0.9 + 1e-3 * sensor_model.gaussian(key, 1)
        fmu.fmu.enterContinuousTimeMode()
        assert not [m for _, m in fmu.messages]
        fmu.set_time(7e-3)  # a host that ignores the event at 4 ms and 6 ms: taken now, one warning
        fmu.set(y=1.1)
        assert fmu.get("y_measured") == 1.1 + 1e-3 * sensor_model.gaussian(key, 3)
        warnings = [m for _, m in fmu.messages if "without an event" in m]
        assert len(warnings) == 1 and "passed the sample instant t = 0.004" in warnings[0]
    finally:
        fmu.free()


@needs_native
@pytest.mark.parametrize("version", [2, 3])
def test_fmpy_in_model_exchange_gets_the_co_simulation_samples(native, version):
    parameters = dict(sample_period=2e-3, seed=6, delay_samples=1, filter_time_constant=4e-3, **SIGMAS)
    result = simulate_fmu(str(native["Sensor"][version]), fmi_type="ModelExchange", stop_time=0.04,
                          output_interval=1e-3, start_values={**parameters, **CONSTANT}, output=list(MEASURED))
    rows = np.column_stack([result[name] for name in MEASURED])
    after = {}  # fmpy records each event twice (before, after): keep the last row of each time
    for t, row in zip(result["time"], rows):
        after[round(t * 1e6)] = row
    cosimulation, _ = drive(native["Sensor"][2], parameters, lambda t: CONSTANT, 1e-3, 40)
    for n in range(41):
        assert np.array_equal(after[n * 1000], cosimulation[n]), n


@needs_native
@pytest.mark.parametrize("version", [2, 3])
def test_the_actuator_in_model_exchange_integrates_the_slew_law(native, version):
    fmu = me.MeInstance(native["Actuator"][version], version, "actuator")
    try:
        fmu.initialize(0.0, u_max=8.0, rate_limit=400.0, rate_time_constant=2e-3, u=3.0)
        assert fmu.states().tolist() == [3.0]  # at rest at the first command
        for r, u in ((3.0, 12.0), (7.9, 12.0), (2.0, -1.0)):
            fmu.set_states([r])
            fmu.set(u=u)
            assert fmu.derivatives().tolist() == [actuator_model.slew_rate(r, min(u, 8.0), 400.0, 2e-3)]
            assert fmu.get("u_applied") == r
    finally:
        fmu.free()
    result = simulate_fmu(str(native["Actuator"][version]), fmi_type="ModelExchange", stop_time=0.05,
                          output_interval=1e-3, start_values=dict(u_max=8.0, rate_limit=400.0, u=12.0),
                          output=["u_applied"], relative_tolerance=1e-10)
    # from rest at u(0) = 12 saturated to 8: it stays there
    assert np.allclose(result["u_applied"], 8.0, atol=1e-9)


@needs_native
def test_a_clockless_quantiser_is_refused_in_model_exchange_and_kept_in_co_simulation(native):
    fmu = me.MeInstance(native["Sensor"][2], 2, "sensor")
    try:
        fmu.enter(0.0, quantum_y=1e-3)
        with pytest.raises(Exception):
            fmu.fmu.exitInitializationMode()
        assert any("parameter quantum_y = 0.001 is invalid with sample_period = 0 in Model Exchange" in m
                   for _, m in fmu.messages), fmu.messages
    finally:
        fmu.free()
    rows, messages = drive(native["Sensor"][2], dict(quantum_y=1e-3), lambda t: {"y": 0.01234}, 1e-3, 3)
    assert rows[:, 0].tolist() == [pytest.approx(0.012)] * 4 and not messages
