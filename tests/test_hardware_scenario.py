"""A scenario's [hardware] table and ``run --hardware FILE`` (harness/scenario.py; docs/master.md, Hardware in
the loop): the sensor, the actuator and the true-error reference inserted and wired; every mistake one line;
neutral hardware gives today's records bit for bit (every plant, both editions); a Jacobi host gets the
hardware's warning."""
from __future__ import annotations

import math

import numpy as np
import pytest

from harness import master
from harness import scenario as scenarios
from harness.cli import main as cli_main
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build import native as build_native

HARDWARE_KEYS = [key for key in scenarios.SCHEMA if key.table == "hardware"]


def _one_line(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line.strip()]
    assert len(lines) == 1, lines
    return lines[0]


# ------------------------------------------------------------------ the expansion
def test_the_hardware_table_inserts_a_sensor_an_actuator_and_the_true_error():
    plain = scenarios.load("pendulum_case2")
    rig = scenarios.load("pendulum_case2_hardware")
    assert set(rig.components) == set(plain.components) | {"sensor", "actuator", "truth"}
    wires = {(c.source, c.target) for c in rig.connections}
    assert {("plant.y", "sensor.y"), ("plant.dy", "sensor.dy"), ("sensor.y_measured", "reference.y"),
            ("sensor.dy_measured", "reference.dy"), ("controller.u", "actuator.u"),
            ("actuator.u_applied", "plant.u"), ("plant.y", "truth.y"), ("plant.dy", "truth.dy")} <= wires
    assert ("plant.y", "reference.y") not in wires and ("controller.u", "plant.u") not in wires
    assert rig.signals == {**plain.signals, "e": "truth.e", "de": "truth.de"}  # scored on the true error
    assert rig.components["truth"].parameters == plain.components["reference"].parameters
    assert rig.record[:len(plain.record)] == plain.record
    assert {"sensor.y_measured", "actuator.u_applied", "truth.e"} <= set(rig.record)
    sensor, actuator = rig.components["sensor"].parameters, rig.components["actuator"].parameters
    assert sensor["quantum_y"] == 2 * math.pi / 4096 and sensor["delay_samples"] == 1 and sensor["seed"] == 1
    assert actuator["u_max"] == 15.0 and actuator["sample_period"] == sensor["sample_period"] == 1e-3
    # a plant of order 3: its d2y is measured too
    arm = scenarios.with_hardware(scenarios.load("motor_arm"), {})
    assert ("plant.d2y", "sensor.d2y") in {(c.source, c.target) for c in arm.connections}
    assert arm.signals["d2e"] == "truth.d2e"


def test_the_inserted_variables_and_parameters_are_the_fmus_own():
    """The names the expansion wires and sets are in the FMUs' tables; a neutral table sets their defaults."""
    tables = {name: {v.name: v for v in fmu_catalog.model_class(name).VARIABLES} for name in ("Sensor", "Actuator")}
    for channel in scenarios.SENSOR_CHANNELS:
        assert tables["Sensor"][channel].causality == "input"
        assert tables["Sensor"][f"{channel}_measured"].causality == "output"
    assert tables["Actuator"][scenarios.ACTUATOR_INPUT].causality == "input"
    assert tables["Actuator"][scenarios.ACTUATOR_OUTPUT].causality == "output"
    for model, parameters in zip(("Sensor", "Actuator"), scenarios.hardware_parameters({})):
        for name, value in parameters.items():
            assert tables[model][name].causality == "parameter", (model, name)
            if name != "local_seed":
                assert value == tables[model][name].start, (model, name)  # neutral: the FMU's defaults
    assert scenarios.hardware_parameters({"u_max": math.inf, "rate_limit": math.inf})[1]["u_max"] == 0.0


def _misspelt(name: str) -> str:
    return name[:-1] + name[-1] * 2 if len(name) > 2 else name + "x"


@pytest.mark.parametrize("key", HARDWARE_KEYS, ids=lambda key: key.name)
def test_a_misspelt_hardware_key_is_one_error_naming_it_and_the_valid_keys(key):
    with pytest.raises(scenarios.ScenarioError) as error:
        scenarios.with_hardware(scenarios.load("pendulum_case1"), {_misspelt(key.name): 1.0}, "rig.toml")
    text = str(error.value)
    assert text.startswith("rig.toml: [hardware] unknown key ") and f"(did you mean {key.name!r}?)" in text
    assert "; valid: plant, sample_period, seed, noise_y" in text and "\n" not in text


BAD_VALUES = [("sample_period", -1e-3, "a finite number >= 0"), ("sample_period", math.nan, "a finite number >= 0"),
              ("noise_dy", math.inf, "a finite number >= 0"), ("quantum_y", "fine", "a finite number >= 0"),
              ("delay_samples", 17, "an integer in 0 .. 16"), ("delay_samples", 1.0, "an integer in 0 .. 16"),
              ("actuator_delay_samples", -1, "an integer in 0 .. 16"), ("seed", -3, "an integer in 0 .. 2147483647"),
              ("seed", 2 ** 31, "an integer in 0 .. 2147483647"), ("u_max", -5.0, "a number >= 0 (0 or inf: no limit)"),
              ("rate_limit", math.nan, "a number >= 0 (0 or inf: no limit)"), ("rate_time_constant", 0.0, "> 0"),
              ("plant", 3, "a string")]


@pytest.mark.parametrize("name, value, valid", BAD_VALUES, ids=lambda item: str(item))
def test_a_bad_hardware_value_is_one_error_with_its_valid_range(name, value, valid):
    with pytest.raises(scenarios.ScenarioError) as error:
        scenarios.with_hardware(scenarios.load("pendulum_case1"), {"sample_period": 1e-3, name: value}, "rig.toml")
    text = str(error.value)
    assert text.startswith(f"rig.toml: [hardware] {name} = ") and valid in text and "\n" not in text


@pytest.mark.parametrize("table, message", [
    ({"plant": "plnt"}, "[hardware] plant = 'plnt' is not a component (did you mean 'plant'?); valid: plant, "
                        "reference, controller"),
    ({"noise_y": 1e-3}, "[hardware] noise_y = 0.001 needs the clock of the sensor and the actuator"),
    ({"delay_samples": 1}, "[hardware] delay_samples = 1 needs the clock"),
    ({"actuator_delay_samples": 2, "sample_period": 0.0}, "[hardware] actuator_delay_samples = 2 needs the clock"),
    ({"plant": "reference"}, "[hardware] no connection leaves reference.y, reference.dy, reference.d2y, "
                             "reference.d3y: the sensor would measure nothing"),
])
def test_a_hardware_table_that_cannot_be_inserted_is_one_error(table, message):
    with pytest.raises(scenarios.ScenarioError) as error:
        scenarios.with_hardware(scenarios.load("pendulum_case1"), table, "rig.toml")
    assert message in str(error.value) and "\n" not in str(error.value)


def test_names_already_taken_and_a_second_table_are_refused():
    scenario = scenarios.load("pendulum_case1")
    scenario.components["sensor"] = scenario.components["reference"]
    with pytest.raises(scenarios.ScenarioError, match="inserts the instances sensor, actuator and truth; the "
                                                      "scenario already has 'sensor': rename it"):
        scenarios.with_hardware(scenario, {})
    with pytest.raises(scenarios.ScenarioError, match="already has hardware inserted"):
        scenarios.with_hardware(scenarios.load("pendulum_case2_hardware"), {})


def test_run_takes_a_hardware_file_and_refuses_a_bad_one_in_one_line(tmp_path, capsys):
    good = tmp_path / "rig.toml"
    good.write_text("[hardware]\nsample_period = 0.001\nnoise_y = 0.001\nu_max = 10.0\n")
    scenario = scenarios.configure("pendulum_case1", "vud", hardware=good)
    assert scenario.components["sensor"].parameters["noise_y"] == 0.001 and scenario.hardware["u_max"] == 10.0
    for text, words in (("[hardware]\nnoise_yy = 1\n", "unknown key 'noise_yy' (did you mean 'noise_y'?)"),
                        ("[hardwre]\n", "a hardware file holds one [hardware] table; unknown key 'hardwre'"),
                        ("[hardware]\nu_max = -1\n", "u_max = -1 is not a number >= 0"),
                        ("hardware = 3\n", "hardware = 3 is not a table"),
                        ("[hardware\n", "is not valid TOML")):
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        assert cli_main(["run", "pendulum_case1", "--hardware", str(bad), "--stop", "0.01"]) == 2
        line = _one_line(capsys.readouterr().err)
        assert line.startswith("error: ") and words in line and "Traceback" not in line, line
    assert cli_main(["run", "pendulum_case1", "--hardware", str(tmp_path / "none.toml")]) == 2
    assert "no such file" in _one_line(capsys.readouterr().err)
    assert cli_main(["run", "pendulum_case2_hardware", "--hardware", str(good), "--stop", "0.01"]) == 2
    assert "already has hardware inserted" in _one_line(capsys.readouterr().err)


# ------------------------------------------------------------------ runs
IDENTITY = [("pendulum_case1", 0.5), ("manipulator", 0.2), ("motor_arm", 0.4)]


@pytest.fixture(scope="module")
def edition_paths(fmu_paths):
    """{edition: {model identifier: FMU path}} of the editions built here."""
    paths = {"python": fmu_paths}
    if build_native.compiler_available():
        native = build_native.ensure_built()
        paths["native"] = {name: versions[2] for name, versions in native.items()}
        paths["native3"] = {name: versions[3] for name, versions in native.items()}
    return paths


@pytest.mark.parametrize("name, stop", IDENTITY, ids=[name for name, _ in IDENTITY])
def test_neutral_hardware_gives_todays_records_bit_for_bit(edition_paths, name, stop):
    """Every plant, every edition built, every controller: the loop with a neutral sensor and actuator
    inserted records every signal of the loop without them, bit for bit (and its true error is the
    reference's)."""
    for edition, paths in edition_paths.items():
        for controller in ("vud", "fixed", "fae"):
            plain = scenarios.configure(name, controller, stop=stop)
            rig = scenarios.with_hardware(plain, {})
            without, with_hardware = master.simulate(plain, fmu_paths=paths), master.simulate(rig, fmu_paths=paths)
            assert with_hardware.rows == without.rows == round(stop / plain.step) + 1
            for column in without.columns:
                assert np.array_equal(with_hardware.signal(column), without.signal(column)), (edition, controller,
                                                                                              column)
            assert np.array_equal(with_hardware.role("e"), without.role("e"))
            assert np.array_equal(with_hardware.signal("actuator.u_applied"), without.signal("controller.u"))


def test_a_jacobi_host_gets_the_hardwares_warning_and_a_feedthrough_master_none(edition_paths):
    rig = scenarios.with_hardware(scenarios.configure("pendulum_case1", "fixed", stop=0.05), {})
    for edition, paths in edition_paths.items():
        for algorithm, expected in (("feedthrough", {}), ("jacobi", {"sensor", "actuator"})):
            run = master.Master(rig, algorithm, fmu_paths=paths)
            run.run()
            warned = {name for name, lines in run.logs.items() if any("before it set" in line for line in lines)}
            assert warned == set(expected), (edition, algorithm, run.logs)
