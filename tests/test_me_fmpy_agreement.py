"""Each FMU alone in fmpy's own Model Exchange simulation matches what our Model Exchange master recorded of it.

Our master (harness/me_master.py) runs the closed loop and records, on a fine output grid, every input each FMU
was given and every output it gave.  Then each FMU runs alone in ``fmpy simulate --interface-type ModelExchange``
(fmpy 0.3.32's option; ``fmi_type`` in its Python API) with those inputs as an input CSV and the scenario's
parameters as start values, and its outputs must be what our master recorded: two independent hosts (fmpy's
CVode and event handling, our CVODE over the coupled states) integrate the same FMU to the same trajectory.

fmpy hands an FMU its inputs only at its output points and events: they are held in between, while our master
sets the inputs at every derivative evaluation.  The agreement is therefore limited by fmpy's hold, O(grid), and
each FMU runs in fmpy at two output grids: the finer one must agree better, by about the ratio of the grids (the
difference is fmpy's hold, not a disagreement of the two integrations), and within ``agreement`` of the output's
range.  An FMU with event indicators (the manipulator) gets its inputs as a piecewise-constant CSV (a jump at
each grid time): fmpy's root function applies the inputs at the time it is evaluated, its right-hand side does
not, so linear inputs would make the two disagree inside a step (fmpy's CVode then stalls, mxstep reached).
The open-loop inverted pendulum amplifies any input difference (it is unstable), so its horizon is short.
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness import scenario as scenarios
from harness.fmi import MODEL_EXCHANGE, ModelInfo
from harness.me_master import ModelExchangeMaster

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

GRIDS = (1e-4, 2.5e-5)  # s: our master's output grid = fmpy's output interval = the input CSV's rows
#: (scenario, instance, horizon, outputs compared, largest difference at the finer grid relative to the range:
#: twice the largest measured, which was (at 0.1 ms / 25 us) pendulum y 1.7e-2 / 3.3e-3, controller theta3
#: 1.5e-2 / 4.7e-3 (u 2.5e-3 / 6.6e-4), manipulator y 5.0e-3 / 1.3e-3 (through its stop at 0.183-0.188 s),
#: motor arm y 3.1e-3 / 7.4e-4; the reference, which has no state, 0 at both: every difference shrinks 4x)
CASES = [
    ("pendulum_case2", "plant", 0.3, ("y", "dy"), 7e-3),
    ("pendulum_case2", "reference", 0.3, ("ym", "dym", "e", "de"), 1e-12),
    ("pendulum_case2", "controller", 0.5, ("u", "theta1", "theta2", "theta3", "theta4"), 1e-2),
    ("manipulator", "plant", 0.3, ("y", "dy"), 3e-3),
    ("motor_arm", "plant", 0.5, ("y", "dy", "d2y"), 2e-3),
]


@pytest.fixture(scope="module")
def native():
    return build_fmu.ensure_built(edition="native")


def recorded_loop(name: str, instance: str, outputs, native, grid: float, stop: float) -> tuple:
    """Our master's run with the instance's inputs (their sources) and outputs recorded on ``grid``."""
    scenario = scenarios.configure(name, "vud", grid, stop)
    incoming = [c for c in scenario.connections if c.target_instance == instance]
    scenario.record = list(dict.fromkeys([*scenario.record, *(c.source for c in incoming),
                                          *(f"{instance}.{o}" for o in outputs)]))
    result = ModelExchangeMaster(scenario, native).run()
    inputs = {c.target_variable: result.signal(c.source) for c in incoming}
    return scenario, result, inputs


def fmpy_alone(path, scenario, instance: str, inputs: dict, outputs, folder, piecewise: bool) -> np.ndarray:
    folder.mkdir(parents=True, exist_ok=True)
    time = scenario.start + np.arange(scenario.steps + 1) * scenario.step
    csv_path = folder / "inputs.csv"
    if inputs:
        table = np.column_stack([time, *inputs.values()])
        if piecewise:  # each value held until the next grid time, where it jumps (a repeated time stamp)
            rows = []
            for k in range(len(table) - 1):
                rows += [table[k], np.r_[table[k + 1, 0], table[k, 1:]]]
            table = np.array(rows + [table[-1]])
        np.savetxt(csv_path, table, delimiter=",", header=",".join(["time", *inputs]), comments="", fmt="%.17g")
    out = folder / "out.csv"
    parameters = scenario.components[instance].parameters
    command = [sys.executable, "-m", "fmpy", "simulate", str(path), "--interface-type", "ModelExchange",
               "--stop-time", repr(scenario.stop), "--relative-tolerance", "1e-10",
               "--output-interval", repr(scenario.step),
               "--output-file", str(out), "--timeout", "300", "--output-variables", *outputs,
               "--start-values", *[str(item) for pair in parameters.items() for item in pair]]
    if inputs:
        command += ["--input-file", str(csv_path)]
    completed = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    rows = np.genfromtxt(out, delimiter=",", names=True)
    times = rows["time"]
    keep = np.r_[times[1:] != times[:-1], True]  # fmpy records an event twice: the row after it counts
    return rows[keep]


@pytest.mark.parametrize("name, instance, stop, outputs, agreement", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_each_fmu_alone_in_fmpy_gives_what_our_master_recorded(native, tmp_path, name, instance, stop, outputs,
                                                              agreement):
    differences = []
    for grid in GRIDS:
        scenario, result, inputs = recorded_loop(name, instance, outputs, native, grid, stop)
        fmu = scenario.components[instance].fmu
        piecewise = ModelInfo.read(native[fmu], MODEL_EXCHANGE).event_indicators > 0
        rows = fmpy_alone(native[fmu], scenario, instance, inputs, outputs, tmp_path / f"{grid:g}", piecewise)
        worst = {}
        for output in outputs:
            ours = result.signal(f"{instance}.{output}")
            theirs = np.interp(result.time, rows["time"], rows[output])
            worst[output] = float(np.max(np.abs(theirs - ours))) / (float(np.ptp(ours)) or 1.0)
        differences.append(worst)
    coarse, fine = differences
    ratio = GRIDS[0] / GRIDS[1]
    for output in outputs:
        assert fine[output] < agreement, f"{instance}.{output}: {fine[output]:.3g} of its range"
        if coarse[output] > 1e-9:  # fmpy's hold: the difference shrinks like the grid (4x measured)
            assert fine[output] < coarse[output] * 2.0 / ratio, (output, coarse[output], fine[output])
