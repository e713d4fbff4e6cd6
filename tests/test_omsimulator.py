"""OpenModelica's OMSimulator as a host (harness/hosts/omsimulator.py, the host matrix's omsimulator-* rows).

OMSimulator cannot be installed from the package registries here; the tests use the build in
../shared/tools/omsimulator (or ../../shared/tools/omsimulator from a worktree in a folder of worktrees; its
env.sh unpacks it once and names its Python package) and skip where that folder is absent.  What they hold
(docs/hosts.md):

* its C API (``oms_importFile``) takes the co-simulation step from our package's ``org.openmodelica`` annotation
  and its co-simulation master gives our feedthrough master's trajectory to the last digits;
* its Python API reads no step annotation (it runs at 1 ms unless ``setFixedStepSize`` is called);
* its strongly coupled mode runs an ``export-ssp --algorithm me`` package (CVODE over the Model Exchange FMUs,
  through the manipulator's friction events); its results are first order in its maximum step (its
  communication interval, where it also writes results): over 0.5 s of the pendulum Ec is 0.46 %, 0.11 %,
  0.022 % off our Model Exchange result at 0.5 ms, 0.1 ms, 25 us (over 20 s at 0.5 ms: ITAE -0.022 %);
* FMI 3.0: its co-simulation master runs the FMI 3.0 FMUs; its strongly coupled mode refuses them;
* nothing is printed after a process that ran it ends (it printed its count of logged errors at exit, after
  pytest's summary line: harness/hosts/omsimulator.py's flush_log_counts).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness import scenario as scenarios
from harness.hosts import matrix as hosts
from harness.hosts import omsimulator
from harness.hosts.ssp import export_ssp
from harness.master import simulate

ROOT = Path(__file__).resolve().parents[1]
SHARED = next((folder / "shared" / "tools" / "omsimulator" for folder in (ROOT.parent, ROOT.parent.parent)
               if (folder / "shared" / "tools" / "omsimulator" / "env.sh").exists()),
              ROOT.parent / "shared" / "tools" / "omsimulator")
NAMES = ["plant.y", "plant.dy", "reference.ym", "reference.dym", "controller.u"]

pytestmark = [pytest.mark.skipif(not (SHARED / "env.sh").exists(), reason="../shared/tools/omsimulator is absent"),
              pytest.mark.skipif(not build_native.compiler_available(), reason="zig's C compiler is not installed")]


@pytest.fixture(scope="module")
def oms():
    """OMSimulator's Python package on sys.path (worker processes inherit it)."""
    command = f'. "{SHARED}/env.sh" && "{sys.executable}" -c "import OMSimulator, os; ' \
              'print(os.path.dirname(os.path.dirname(OMSimulator.__file__)))"'
    completed = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr
    path = completed.stdout.strip().splitlines()[-1]
    if path not in sys.path:
        sys.path.insert(0, path)
    assert omsimulator.unavailable() is None
    return path


@pytest.fixture(scope="module")
def native():
    return build_fmu.ensure_built(edition="native")


def test_its_c_api_takes_the_step_from_the_package_and_matches_our_master(oms, native, tmp_path):
    scenario = scenarios.configure("pendulum_case1", "vud", 5e-4, 0.5)
    package = export_ssp(scenario, tmp_path / "p.ssp", fmu_paths=native)
    time, columns = omsimulator.run_c_api(package, scenario.stop, NAMES)
    assert np.allclose(np.diff(time), 5e-4)  # the annotation's step, not its 1 ms default
    ours = simulate(scenario, fmu_paths=native)
    for name in NAMES:
        assert np.max(np.abs(columns[name] - ours.signal(name))) < 1e-9 * max(1.0, np.ptp(ours.signal(name))), name


def test_its_python_api_reads_no_step_annotation(oms, native, tmp_path):
    scenario = scenarios.configure("pendulum_case1", "vud", 5e-4, 0.05)
    package = export_ssp(scenario, tmp_path / "p.ssp", fmu_paths=native)
    time, _ = omsimulator.run_python_api(package, scenario.stop, NAMES)
    assert np.allclose(np.diff(time), 1e-3)  # what a user gets unless they call setFixedStepSize
    time, _ = omsimulator.run_python_api(package, scenario.stop, NAMES, fixed_step=5e-4)
    assert np.allclose(np.diff(time), 5e-4)


@pytest.mark.parametrize("name", ["pendulum_case1", "manipulator"])
def test_its_matrix_rows_are_within_1_percent_without_warnings(oms, name):
    """Over 0.5 s (the manipulator stops at 0.183 s and slips again: two state events in the strongly coupled
    mode), against our converged result over the same horizon; the 20 s rows: docs/hosts.md."""
    matrix = hosts.hosts_matrix([name], ("vud",), ["omsimulator-wc", "omsimulator-wc-capi", "omsimulator-sc"],
                                ("validated",), stop=0.5, jobs=2)
    assert not matrix["skipped"], matrix["skipped"]
    assert {r["host"] for r in matrix["rows"]} == {"omsimulator-wc", "omsimulator-wc-capi", "omsimulator-sc"}
    for row in matrix["rows"]:
        assert row["status"] == "ok", row.get("reason")
        assert row["warnings"] == [], row["warnings"]
        assert hosts.within(row), (row["host"], row["error"])


def test_its_strongly_coupled_mode_is_first_order_in_its_maximum_step(oms, native, tmp_path):
    """Our Model Exchange master has no such step: its result does not depend on the output grid."""
    from harness.me_master import simulate as simulate_me
    from harness.scores import control_energy

    scenario = scenarios.configure("pendulum_case1", "vud", 5e-4, 0.5)
    ours = simulate_me(scenario, native, rtol=1e-10)
    reference = control_energy(ours.time, ours.signal("controller.u"))
    package = export_ssp(scenario, tmp_path / "me.ssp", fmu_paths=native, rtol=1e-8)
    errors = []
    for step in (5e-4, 1.25e-4):
        time, columns = omsimulator.run_python_api(package, scenario.stop, NAMES, output_step=step)
        u = np.interp(ours.time, time, columns["controller.u"])
        errors.append(abs(control_energy(ours.time, u) / reference - 1))
    assert 2e-3 < errors[0] < 1e-2 and 2.5 < errors[0] / errors[1] < 6, errors


def test_fmi3_co_simulation_runs_and_its_strongly_coupled_mode_refuses_it(oms, tmp_path):
    native3 = build_fmu.ensure_built(edition="native3")
    scenario = scenarios.configure("pendulum_case1", "vud", 5e-4, 0.05)
    time, columns = omsimulator.run_python_api(export_ssp(scenario, tmp_path / "cs.ssp", fmu_paths=native3),
                                               scenario.stop, NAMES, fixed_step=5e-4)
    ours = simulate(scenario, fmu_paths=native3)
    assert np.max(np.abs(columns["controller.u"] - ours.signal("controller.u"))) < 1e-9
    package = export_ssp(scenario, tmp_path / "me.ssp", fmu_paths=native3, rtol=1e-8)
    with pytest.raises(RuntimeError, match="oms_addSubModel"):
        omsimulator.run_python_api(package, scenario.stop, NAMES, output_step=5e-4)


AFTER_THE_END = """
import sys
sys.path.insert(0, sys.argv[1])
from harness import scenario as scenarios
from harness.fmu_build import builder as build_fmu
from harness.hosts import omsimulator
from harness.hosts.ssp import export_ssp
scenario = scenarios.configure("pendulum_case1", "vud", 5e-4, 0.01)
package = export_ssp(scenario, sys.argv[2], fmu_paths=build_fmu.ensure_built(edition="native3"), rtol=1e-8)
try:
    omsimulator.run_python_api(package, scenario.stop, ["plant.y"], output_step=5e-4)
except RuntimeError as error:
    print("refused:", error)
print("THE END", flush=True)
"""


def test_nothing_is_printed_after_a_process_that_ran_it_ends(oms, tmp_path):
    """A run OMSimulator logged an error in (its strongly coupled mode refusing FMI 3.0) printed 'info:    0
    warnings' and 'info:    1 errors' when the process exited: after pytest's summary line in a green run."""
    build_fmu.ensure_built(edition="native3")
    completed = subprocess.run([sys.executable, "-c", AFTER_THE_END, oms, str(tmp_path / "me.ssp")], cwd=ROOT,
                               capture_output=True, text=True, timeout=300)
    assert completed.returncode == 0, completed.stderr
    output = completed.stdout
    assert "refused: Failed to add oms_addSubModel" in output
    assert output.rstrip().endswith("THE END"), output[output.find("THE END"):]
