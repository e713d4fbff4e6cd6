"""The co-simulation master: oracle agreement, delays, failures, scenario mistakes."""
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.fmu_build import builder as build_fmu
from harness import scenario as scenarios
from harness import variants
from harness.cli import main as cli_main
from harness.master import Master, SimulationFailed, simulate
from harness.studies.oracle import simulate_oracle
from harness.scenario import ScenarioError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("controller", ["vud", "fixed", "fae"])
@pytest.mark.parametrize("name", ["pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator"])
def test_cosimulation_matches_the_oracle(fmu_paths, name, controller):
    scenario = scenarios.load(name).with_controller(controller).with_parameter("stop", 2.0)
    result = simulate(scenario, fmu_paths=fmu_paths)
    oracle = simulate_oracle(scenario)
    assert result.complete and result.rows == scenario.steps + 1
    np.testing.assert_array_equal(result.time, oracle["time"])
    for column in result.columns:
        np.testing.assert_allclose(result.signal(column), oracle[column], rtol=0, atol=1e-9, err_msg=column)
    assert np.max(np.abs(result.signal("controller.theta1"))) > 0.1  # the controller learned


@pytest.mark.parametrize("name", ["pendulum_case2", "manipulator"])
def test_jacobi_matches_the_delayed_oracle(fmu_paths, name):
    scenario = scenarios.load(name).with_controller("vud").with_parameter("stop", 0.5)
    result = simulate(scenario, algorithm="jacobi", fmu_paths=fmu_paths)
    oracle = simulate_oracle(scenario, algorithm="jacobi")
    for column in result.columns:
        np.testing.assert_allclose(result.signal(column), oracle[column], rtol=0, atol=1e-9, err_msg=column)


def test_default_has_no_delay_and_jacobi_delays_each_connection_one_step(fmu_paths):
    scenario = scenarios.load("pendulum_case1").with_controller("vud").with_parameter("stop", 0.2)
    default = simulate(scenario, fmu_paths=fmu_paths)
    jacobi = simulate(scenario, algorithm="jacobi", fmu_paths=fmu_paths)
    y, ym, e = default.signal("plant.y"), default.signal("reference.ym"), default.signal("reference.e")
    assert np.array_equal(e, ym - y)  # e(t_n) sees y(t_n): no delay on the chain
    jy, jym, je = jacobi.signal("plant.y"), jacobi.signal("reference.ym"), jacobi.signal("reference.e")
    assert np.array_equal(je[1:], jym[1:] - jy[:-1])  # e(t_n) sees y(t_n-1): one step late
    assert not np.array_equal(je[1:], jym[1:] - jy[1:])
    # and the controller's u at t_n in jacobi is computed from the e set at t_n-1
    assert not np.allclose(default.signal("controller.u"), jacobi.signal("controller.u"))


def test_csv_is_in_cross_check_style_and_thinned_on_request(fmu_paths, tmp_path):
    scenario = scenarios.load("pendulum_case1").with_controller("fixed").with_parameter("stop", 0.1)
    result = simulate(scenario, fmu_paths=fmu_paths)
    path = result.write_csv(tmp_path / "r.csv", output_interval=0.01)
    header = path.read_text().splitlines()[0]
    assert header.startswith('"time","plant.y","plant.dy"')
    table = np.genfromtxt(path, delimiter=",", skip_header=1)
    assert table.shape == (11, 1 + len(result.columns))
    np.testing.assert_allclose(table[:, 0], np.arange(11) * 0.01, atol=1e-12)


def test_run_json_prints_exactly_one_object_with_the_keys(fmu_paths, capsys):
    assert cli_main(["run", "pendulum_case1", "--controller", "fae", "--stop", "0.2", "--json"]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    summary = json.loads(out[0])
    assert list(summary) == ["scenario", "controller", "step", "ts", "es1_pct", "es2_pct", "ITAE", "IAE",
                             "Ec", "umax", "tv_u", "wall_s", "us_per_step", "warnings"]
    assert summary["scenario"] == "pendulum_case1" and summary["controller"] == "fae"
    # a score the run cannot give is null, with its reason, never a number
    assert summary["ts"] is None and summary["es1_pct"] is None and summary["es2_pct"] is None  # 0.2 s
    assert summary["warnings"] == [
        "ts not settled: |e| is outside the 5 % band of max|ym| at the stop time 0.2 s, or enters it only at the "
        "last step",
        "es1_pct n/a: the horizon 0.2 s is shorter than the reference period, 2 pi s, over which es1 and es2 are taken",
        "es2_pct n/a: the horizon 0.2 s is shorter than the reference period, 2 pi s, over which es1 and es2 are taken"]
    assert cli_main(["run", "pendulum_case1", "--stop", "2", "--json"]) == 0
    settled = json.loads(capsys.readouterr().out)
    assert settled["ts"] == pytest.approx(0.735) and settled["es1_pct"] is None and len(settled["warnings"]) == 2


def test_console_script_and_module_entry_point_run():
    result = subprocess.run([sys.executable, "-m", "harness", "run", "pendulum_case2", "--controller", "vud",
                             "--stop", "0.05", "--json"], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["ITAE"] > 0


# ----------------------------------------------------------------- failures
@pytest.fixture(scope="module")
def faulty_fmu(tmp_path_factory):
    pendulum = next(f for f in build_fmu.FMUS if f.model_identifier == "InvertedPendulum")
    return build_fmu.build_script(ROOT / "tests" / "data" / "faulty_pendulum_fmu.py",
                                  tmp_path_factory.mktemp("faulty") / "FaultyPendulum.fmu", pendulum.sources)


def scenario_file(tmp_path, edit):
    text = (scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text()
    path = tmp_path / "edited.toml"
    path.write_text(edit(text))
    return path


def test_fmu_fault_stops_the_run_naming_instance_function_time_and_log(faulty_fmu, tmp_path, capsys):
    path = scenario_file(tmp_path, lambda t: re.sub(r"(?m)^step = [^ ]*", "step = 1e-3",
                                                    t.replace('fmu = "InvertedPendulum"', f'fmu = "{faulty_fmu}"')))
    out = tmp_path / "partial.csv"
    code = cli_main(["run", str(path), "--controller", "vud", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1  # a failed run (2 is for usage errors)
    assert "plant: " in err and "(in fmi2DoStep at t = 0.5)" in err and len(err.strip().splitlines()) == 1, err
    assert "injected fault at t = 0.5" in err  # the FMU's own log
    table = np.genfromtxt(out, delimiter=",", skip_header=1)
    assert table[-1, 0] == pytest.approx(0.5) and table.shape[0] == 501  # every row to 0.5 s
    assert np.all(np.isfinite(table))


def test_divergence_stops_with_message_and_partial_result(fmu_paths, tmp_path, capsys):
    out = tmp_path / "diverged.csv"
    code = cli_main(["run", "pendulum_case3", "--controller", "vud", "--step", "0.02", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 1  # a failed run (2 is for usage errors)
    assert "diverged at t = " in err and "with step 0.02" in err and "try a smaller step" in err
    table = np.genfromtxt(out, delimiter=",", skip_header=1)
    assert 10 < table.shape[0] < 1000


def test_divergence_keeps_the_partial_result_in_the_exception(fmu_paths):
    scenario = scenarios.load("manipulator").with_controller("vud").with_parameter("step", 0.05)
    with pytest.raises(SimulationFailed) as failed:
        simulate(scenario, fmu_paths=fmu_paths)
    partial = failed.value.result
    assert not partial.complete and 0 < partial.rows < scenario.steps
    assert np.all(np.isfinite(partial.values))


@pytest.mark.parametrize("edit,expected", [
    (lambda t: t.replace('fmu = "TrackingReference"', 'fmu = "NoSuchModel"'),
     "unknown FMU 'NoSuchModel'; valid: Actuator, AdaptiveFuzzyController, DcMotorArm, InvertedPendulum"),
    (lambda t: t.replace('fmu = "TrackingReference"', 'fmu = "missing/Reference.fmu"'), "FMU file not found"),
    (lambda t: t.replace('from = "plant.y"', 'from = "plnt.y"'),
     "[[connections]] 1: from = 'plnt.y': unknown instance 'plnt' (did you mean 'plant'?); valid: plant, reference, "
     "controller"),
    (lambda t: t.replace('from = "plant.y"', 'from = "plant.angle"'),
     "plant has no variable 'angle'; valid outputs: y, dy, d"),
    (lambda t: t.replace('to = "reference.y"', 'to = "reference.e"'),
     "'reference.e' is an output, not an input; valid inputs of reference: y, dy"),
    (lambda t: t.replace('from = "plant.y"', 'from = "plant.u"'), "is an input, not an output"),
    (lambda t: t.replace('parameters = { mp = 0.1,', 'parameters = { mass = 0.1,'),
     "InvertedPendulum has no parameter 'mass'; valid: gv, mc, mp"),
    (lambda t: t.replace('"plant.y", "plant.dy"', '"plant.y", "plant.speed"'), "no variable 'speed'"),
])
def test_scenario_mistakes_give_one_clear_error(fmu_paths, tmp_path, capsys, edit, expected):
    path = scenario_file(tmp_path, edit)
    assert cli_main(["run", str(path), "--stop", "0.01"]) == 2
    err = capsys.readouterr().err
    assert expected in err, err
    assert err.count("error:") == 1


def test_algebraic_loop_is_a_clear_error(fmu_paths, tmp_path):
    # controller.u feeds back into the reference through a direct-feedthrough path
    path = scenario_file(tmp_path, lambda t: t.replace('from = "plant.y"\nto = "reference.y"',
                                                       'from = "controller.u"\nto = "reference.y"'))
    with pytest.raises(ScenarioError, match="algebraic loop"):
        Master(scenarios.load(path).with_controller("vud"), fmu_paths=fmu_paths)._prepare_plan()


def test_unknown_scenario_and_controller_list_valid_names():
    names = scenarios.scenario_names()  # every scenario file, sorted; the variant registry's names, in its order
    assert {"manipulator", "motor_arm", "pendulum_case1"} <= set(names) and names == sorted(names)
    with pytest.raises(ScenarioError, match=f"; valid: {re.escape(', '.join(names))} or a .toml path$"):
        scenarios.load("pendulum_case9")
    assert variants.NAMES[:3] == ("vud", "fixed", "fae")
    with pytest.raises(ScenarioError, match=f"; valid: {re.escape(', '.join(variants.NAMES))}$"):
        scenarios.load("pendulum_case1").with_controller("pid")
