"""harness/scenario.py: the scenario schema (one declaration table), parsing, the record's memory limit.

A misspelt key or table in a scenario file used to be ignored (a run on the plant's
defaults, exit 0); every mistake is now one line naming the file, the table and the key, exit 2.
Every key misspelt and every value of the wrong type, through the command line: tests/test_cli.py.
"""
from __future__ import annotations

import re

import pytest

from harness import scenario as scenarios
from harness.cli import main as cli_main
from harness.scenario import ScenarioError


def edited(tmp_path, name: str, old: str, new: str):
    text = (scenarios.SCENARIO_DIR / f"{name}.toml").read_text()
    assert old in text
    path = tmp_path / "copy.toml"
    path.write_text(text.replace(old, new, 1))
    return path


ISSUE_CASES = [  # (what, scenario, old, new, the error line)
    ("a misspelt table key runs on the plant's defaults", "pendulum_case3", "\nparameters = { mp = 1.0",
     "\nparamters = { mp = 1.0",
     "copy.toml: [components.plant] unknown key 'paramters' (did you mean 'parameters'?); valid: fmu, parameters"),
    ("a misspelt optional key", "pendulum_case3", "divergence_bound = 1e8", "divergence_bnd = 1e8",
     "copy.toml: [experiment] unknown key 'divergence_bnd' (did you mean 'divergence_bound'?); "
     "valid: start, stop, step, divergence_bound"),
    ("a misspelt table", "pendulum_case3", "[record]", "[recrod]",
     "copy.toml: unknown key 'recrod' at the top level (did you mean 'record'?); valid: name, description, "
     "controller_instance, experiment, components, connections, bounds, signals, record"),
    ("a value of the wrong type", "pendulum_case1", "stop = 20.0", 'stop = "20"',
     "copy.toml: [experiment] stop = '20' is not a finite number"),
    ("a value out of range", "manipulator", "step = 5e-05", "step = -5e-05",
     "copy.toml: [experiment] step = -5e-05 is not a finite number > 0"),
    ("stop before start", "pendulum_case1", "start = 0.0", "start = 30.0",
     "copy.toml: [experiment] stop = 20.0 is not > start = 30"),
    ("a misspelt controller instance", "pendulum_case1", 'controller_instance = "controller"',
     'controller_instance = "controler"',
     "copy.toml: controller_instance = 'controler' is not a component (did you mean 'controller'?); "
     "valid: plant, reference, controller"),
    ("a signal role the scores do not know", "pendulum_case1", 'dym = "reference.dym"', 'dy = "reference.dym"',
     "copy.toml: [signals] unknown key 'dy' (did you mean 'dym'?); valid: e, de, ym, dym, u, d2e, d3e"),
    ("a signal the scores need left out", "pendulum_case1", 'dym = "reference.dym"', "",
     "copy.toml: [signals] missing key 'dym'"),
    ("a connection that is not INSTANCE.VARIABLE", "pendulum_case1", 'from = "plant.y"', 'from = "planty"',
     "copy.toml: [[connections]] 1: from = 'planty' is not a string \"INSTANCE.VARIABLE\""),
    ("a misspelt parameter (checked against the FMU)", "pendulum_case3", "{ mp = 1.0", "{ mpp = 1.0",
     "copy.toml: [components.plant.parameters] InvertedPendulum has no parameter 'mpp' (did you mean 'mp'?)"),
    ("a misspelt variable of a bound (checked against the FMU)", "pendulum_case1", '"plant.y" = ', '"plant.yy" = ',
     "copy.toml: [bounds] 'plant.yy': plant has no variable 'yy' (did you mean 'y'?); valid outputs: y, dy, d"),
]


@pytest.mark.parametrize("what,name,old,new,expected", ISSUE_CASES, ids=[c[0] for c in ISSUE_CASES])
def test_a_scenario_mistake_is_one_line_naming_file_table_and_key(fmu_paths, tmp_path, capsys, what, name, old, new,
                                                                  expected):
    path = edited(tmp_path, name, old, new)
    assert cli_main(["run", str(path), "--stop", "2"]) == 2, what
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    assert lines[0].startswith(f"error: {tmp_path}/copy.toml: "), lines[0]
    assert expected in lines[0], lines[0]
    assert captured.out == ""  # no run, no scores


def test_every_shipped_scenario_passes_the_schema_and_keeps_its_values():
    for name in scenarios.scenario_names():
        loaded = scenarios.load(name)
        assert loaded.name == name and loaded.start == 0.0 and loaded.stop == 20.0
        assert set(loaded.signals) >= {"e", "de", "ym", "dym", "u"} and set(loaded.signals.values()) <= set(loaded.record)
    case3 = scenarios.load("pendulum_case3")
    assert case3.components["plant"].parameters["mp"] == 1.0 and case3.divergence_bound == 1e8
    assert case3.bounds == {"plant.y": pytest.approx(1.5707963267948966), "controller.u": 1e4}


def test_defaults_come_from_the_schema():
    data = {"experiment": {"stop": 1.0, "step": 0.5}, "components": {"c": {"fmu": "TrackingReference"}},
            "signals": {role: "c.e" for role in ("e", "de", "ym", "dym", "u")}, "controller_instance": "c"}
    parsed = scenarios.parse(data)
    assert (parsed.name, parsed.description, parsed.start, parsed.divergence_bound) == ("scenario", "", 0.0, 1e8)
    assert parsed.connections == [] and parsed.record == [] and parsed.bounds == {}
    assert parsed.components["c"].parameters == {}
    with pytest.raises(ScenarioError, match=r"scenario: controller_instance = 'controller' is not a component; "
                                            r"valid: c"):
        scenarios.parse({**data, "controller_instance": "controller"})
    with pytest.raises(ScenarioError, match=r"\[components\] has no instance"):
        scenarios.parse({**data, "components": {}})
    for name in ("a.b", "a/b", "réf", "a b", "1st", "a-b", "<img>", ""):
        with pytest.raises(ScenarioError, match=rf"\[components\] instance name {re.escape(repr(name))} is not "
                                                r"allowed: use ASCII letters, digits and '_', not starting with a digit"):
            scenarios.parse({**data, "components": {name: {"fmu": "X"}}})
    assert scenarios.parse({**data, "components": {"c": {"fmu": "TrackingReference"}, "_plant2": {"fmu": "X"}}})
    with pytest.raises(ScenarioError, match=r"\[record\] variables: element 2 = 3 is not a string"):
        scenarios.parse({**data, "record": {"variables": ["c.e", 3]}})


def test_every_key_of_the_schema_is_checked_for_type(tmp_path):
    """Each declared key refuses a value of the wrong type with its own name in the message."""
    base = {"experiment": {"stop": 1.0, "step": 0.5}, "components": {"c": {"fmu": "TrackingReference"}},
            "signals": {role: "c.e" for role in ("e", "de", "ym", "dym", "u")}, "controller_instance": "c"}
    checked = 0
    for key in scenarios.SCHEMA:
        if key.name in scenarios.CHOSEN_NAMES or "." in key.table:
            continue
        data = {**base, "experiment": dict(base["experiment"]), "signals": dict(base["signals"]),
                "record": {}, "connections": [{"from": "c.e", "to": "c.y"}]}
        if key.table == "":
            target = data
        elif key.table == "connections":
            target = data["connections"][0]
        else:
            target = data.setdefault(key.table, {})
        target[key.name] = [1] if key.kind is not scenarios.DOTTED_LIST else [1, 2]
        with pytest.raises(ScenarioError, match=re.escape(key.name)):
            scenarios.parse(data)
        checked += 1
    assert checked >= 20


def test_the_record_must_fit_in_memory():
    gib = 1024 ** 3
    scenarios.check_record_memory(10_000_000, 15, 0.0, 1e-3, memory=4 * gib)  # 1.2 GiB of 4: fine
    with pytest.raises(ScenarioError) as refused:
        scenarios.check_record_memory(20_000_000, 15, 0.0, 1e-3, memory=4 * gib)  # 2.4 GiB > half of 4
    message = str(refused.value)
    assert message.startswith("stop = 20000 s at step 0.001 s is 2e+07 steps: the master keeps every step of "
                              "the 15 recorded signals and the time in memory (2.38 GiB), more than 50% of this "
                              "machine's 4 GiB; give a stop of at most 1.678e+04 s at this step"), message


def test_a_stop_too_long_for_memory_is_one_line_naming_the_limit(capsys):
    """--stop 1e9 was once numpy's 'Unable to allocate 218. TiB'."""
    assert cli_main(["run", "pendulum_case1", "--stop", "1e9"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Unable to allocate" not in err, err
    assert re.match(r"error: stop = 1e\+09 s at step 0.0005 s is 2e\+12 steps: the master keeps every step of the "
                    r"15 recorded signals and the time in memory \(233 TiB\), more than 50% of this machine's .*; "
                    r"give a stop of at most [0-9.e+]+ s at this step", err), err
