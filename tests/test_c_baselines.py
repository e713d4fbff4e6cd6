"""The benchmark's two C baselines (harness/hosts/c_baselines.py) compute the master's loop: the plain C host
over the native FMUs and the math floor without FMI reproduce the master's 15 recorded signals bit for bit;
they refuse a loop they do not know and report a failed FMI call with the call, the FMU and its message.
The instruction counts (harness/hosts/instruction_counts.py) read callgrind's format as it is written."""
from __future__ import annotations

import numpy as np
import pytest

from harness import scenario as scenarios
from harness.fmu_build import native as build_native
from harness.hosts import c_baselines, instruction_counts
from harness.master import Master

pytestmark = pytest.mark.skipif(not build_native.c_toolchain.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e '.[native]')")


@pytest.fixture(scope="module")
def native_fmus():
    return {name: paths[2] for name, paths in build_native.ensure_built().items()}


def bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values).view(np.uint64)


def assert_bit_identical(record: np.ndarray, master: np.ndarray):
    assert record.shape == master.shape
    different = np.argwhere(bits(record) != bits(master))
    if len(different):
        row, column = different[0]
        raise AssertionError(f"{len(different)} values differ; first: row {row}, {c_baselines.COLUMNS[column]} = "
                             f"{record[row, column]!r}, the master's {master[row, column]!r}")


def test_the_c_host_and_the_floor_reproduce_the_masters_record_bit_for_bit(native_fmus, stop=2.0):
    scenario = scenarios.configure("pendulum_case1", "vud", None, stop)
    master = Master(scenario, "feedthrough", native_fmus).run()
    assert tuple(master.columns) == c_baselines.COLUMNS and master.complete
    host, floor = c_baselines.plain_host(scenario, native_fmus), c_baselines.math_floor(scenario)
    for run in (host, floor):
        assert run.loop_s > 0 and run.loop_cpu_s > 0 and run.us_per_step() == 1e6 * run.loop_s / scenario.steps
        assert_bit_identical(run.record, master.values)
    assert np.ptp(master.signal("controller.u")) > 1.0 and np.ptp(master.signal("controller.theta4")) > 0.1


def test_the_c_host_and_the_floor_reproduce_the_masters_record_over_the_whole_horizon(native_fmus):
    test_the_c_host_and_the_floor_reproduce_the_masters_record_bit_for_bit(native_fmus, stop=20.0)


def test_the_floor_follows_the_parameters_it_is_given(native_fmus):
    """Not a copy of one run: other gains, universes and start state still match the master bit for bit."""
    scenario = scenarios.configure("pendulum_case1", "vud", None, 1.0)
    scenario.components["controller"].parameters.update(gamma=150.0, E1=0.8, kappa2=4.0, theta0=0.5, lambda_e=3.0)
    scenario.components["plant"].parameters.update(x1_start=-0.1, mp=0.3)
    master = Master(scenario, "feedthrough", native_fmus).run()
    assert_bit_identical(c_baselines.math_floor(scenario).record, master.values)
    assert_bit_identical(c_baselines.plain_host(scenario, native_fmus).record, master.values)


@pytest.mark.parametrize("controller", ["fixed", "fae"])
def test_the_host_wires_every_connection_as_the_master(native_fmus, controller):
    """The FLS input of the state (fls_input 2) reads ym and dym too, the other variants w_hat: every value the
    host hands along is seen in the record."""
    scenario = scenarios.configure("pendulum_case1", controller, None, 1.0)
    scenario.components["controller"].parameters["fls_input"] = 2
    master = Master(scenario, "feedthrough", native_fmus).run()
    assert_bit_identical(c_baselines.plain_host(scenario, native_fmus).record, master.values)


def test_the_baselines_refuse_a_loop_they_do_not_know(native_fmus):
    with pytest.raises(c_baselines.BaselineError, match="run the loop of pendulum_case1 .*manipulator is another loop"):
        c_baselines.plain_host(scenarios.configure("manipulator", "vud", None, 0.01), native_fmus)
    with pytest.raises(c_baselines.BaselineError, match=r"inlines pendulum_case1/vud: controller.variant = 3, "
                                                        "it knows 1 only"):
        c_baselines.math_floor(scenarios.configure("pendulum_case1", "fae", None, 0.01))
    with pytest.raises(c_baselines.BaselineError, match="plant.dist_gain = 1.0, it knows 0.0 only"):
        c_baselines.math_floor(scenarios.configure("pendulum_case2", "vud", None, 0.01))


def test_the_host_reports_a_failed_call_with_the_fmus_message(native_fmus):
    scenario = scenarios.configure("pendulum_case1", "vud", None, 0.01)
    scenario.components["controller"].parameters["lambda_ce"] = 1.0
    with pytest.raises(c_baselines.BaselineError, match=r"fmi2ExitInitializationMode of controller returned 3: "
                                                        r"controller: parameter lambda_ce = 1 is invalid"):
        c_baselines.plain_host(scenario, native_fmus)


def test_the_host_runs_fmi2_binaries_only():
    fmi3 = {name: paths[3] for name, paths in build_native.ensure_built().items()}
    with pytest.raises(c_baselines.BaselineError, match=r"the plain C host runs FMI 2.0 FMUs; .*InvertedPendulum.fmu "
                                                        r"is FMI 3.0"):
        c_baselines.plain_host(scenarios.configure("pendulum_case1", "vud", None, 0.01), fmi3)


CALLGRIND = """# callgrind format
version: 1
positions: line
events: Ir
summary: 1000
ob=(1) /usr/lib/x86_64-linux-gnu/libm.so.6
fl=(1) s_sin.c
fn=(1) __sin_fma
10 300
ob=(2) /tmp/afc_plant_x/binaries/linux64/InvertedPendulum.so
fl=(2) ???
fn=(2) fmi2DoStep
0 200
cob=(1)
cfi=(1)
cfn=(1)
calls=3 0
0 300
fn=(3) 0x5f30
0 40
ob=(3) /work/build/native/obj/master_loop-0123.so
fl=(3) harness/master_loop.c
fn=(4) 0x6250
1 100
fi=(4) harness/loop_interface.h
+2 150
cob=(2)
cfn=(2)
calls=1 0
* 540
fe=(3)
3 60
ob=(1)
fl=(1)
fn=(1)
11 110
totals: 960
"""


def test_self_costs_read_callgrinds_format(tmp_path):
    """Self cost by object and file; a call's inclusive cost is not counted twice; compressed names resolve."""
    path = tmp_path / "callgrind.out"
    path.write_text(CALLGRIND)
    assert instruction_counts.self_costs(path) == {"libm": 410, "fmus": 240, "loop": 310, "other": 0}


def test_instructions_per_step_are_the_difference_of_two_horizons():
    costs = {1.0: (2000, {"libm": 3_000_000, "fmus": 5_000_000, "loop": 900_000, "other": 100_000}),
             3.0: (6000, {"libm": 9_000_000, "fmus": 13_000_000, "loop": 2_100_000, "other": 100_000})}
    figures = instruction_counts.per_step("master", 1.0, 3.0, counts=lambda loop, stop: costs[stop])
    assert figures == {"libm": 1500.0, "fmus": 2000.0, "loop": 300.0, "other": 0.0, "total": 3800.0}
    with pytest.raises(ValueError, match="more steps than the short one"):
        instruction_counts.per_step("master", 3.0, 1.0, counts=lambda loop, stop: costs[stop])


@pytest.mark.skipif(instruction_counts.shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_callgrind_counts_the_floors_instructions_per_step():
    """A real count (two short runs of the floor under valgrind): all of it in the floor's C and libm."""
    figures = instruction_counts.per_step("floor", 0.02, 0.06)
    assert 1000 < figures["total"] < 5000 and figures["fmus"] == 0 and figures["other"] < 5
    assert 0.3 < figures["libm"] / figures["total"] < 0.9
