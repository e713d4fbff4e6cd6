"""Cost of one communication step of each plant FMU, through fmpy's low-level API.

    python plants/bench_plants.py [--steps 20000] [--step-size 1e-4]

For each FMU: instantiate with fmpy's FMU2Slave, initialise with the default
parameters, then time ``steps`` iterations of
setReal(u) + doStep(t, h) + getReal(y, dy)  (TrackingReference: setReal(y, dy)
+ doStep + getReal(e, de)), two ways:

* ``fmpy``: fmpy's wrapper methods (they build ctypes arrays on every call);
* ``raw``: fmpy's underlying ctypes functions with arrays prepared once, as a
  lean master does.

For comparison ``pure`` is the in-process cost of the same step without FMI:
one ``plant_integration.rk4_advance`` call on the model's derivative.
Prints microseconds per step.  The FMUs are built first if stale.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PLANTS = ("InvertedPendulum", "Manipulator", "TrackingReference")


def _inputs(name):
    return ("y", "dy") if name == "TrackingReference" else ("u",)


def _outputs(name):
    return ("e", "de") if name == "TrackingReference" else ("y", "dy")


def _open(path, unzip_dir, name):
    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=unzip_dir,
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"bench_{name}")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return slave, vr


def bench_fmpy(path, unzip_dir, name, steps, h):
    slave, vr = _open(path, unzip_dir, name)
    ins = [vr[n] for n in _inputs(name)]
    outs = [vr[n] for n in _outputs(name)]
    try:
        begin = time.perf_counter()
        for k in range(steps):
            t = k * h
            slave.setReal(ins, [0.5 * math.sin(t)] * len(ins))
            slave.doStep(t, h)
            slave.getReal(outs)
        return (time.perf_counter() - begin) / steps * 1e6
    finally:
        slave.terminate()
        slave.freeInstance()


def bench_raw(path, unzip_dir, name, steps, h):
    from fmpy.fmi2 import fmi2Real, fmi2ValueReference

    slave, vr = _open(path, unzip_dir, name)
    names_in, names_out = _inputs(name), _outputs(name)
    vr_in = (fmi2ValueReference * len(names_in))(*[vr[n] for n in names_in])
    vr_out = (fmi2ValueReference * len(names_out))(*[vr[n] for n in names_out])
    values_in = (fmi2Real * len(names_in))()
    values_out = (fmi2Real * len(names_out))()
    component = slave.component
    set_real, do_step, get_real = slave.fmi2SetReal, slave.fmi2DoStep, slave.fmi2GetReal
    n_in, n_out = len(names_in), len(names_out)
    try:
        begin = time.perf_counter()
        for k in range(steps):
            t = k * h
            for i in range(n_in):
                values_in[i] = 0.5 * math.sin(t)
            set_real(component, vr_in, n_in, values_in)
            do_step(component, t, h, 1)
            get_real(component, vr_out, n_out, values_out)
        return (time.perf_counter() - begin) / steps * 1e6
    finally:
        slave.terminate()
        slave.freeInstance()


def bench_pure(name, steps, h):
    from plants import inverted_pendulum_model, manipulator_model, plant_integration

    if name == "InvertedPendulum":
        derivative = inverted_pendulum_model.pendulum_derivative
        params = inverted_pendulum_model.pendulum_params(9.8, 1.0, 0.1, 0.5, 0.0)
        x1, x2 = math.pi / 12, 0.0
    elif name == "Manipulator":
        derivative = manipulator_model.manipulator_derivative
        params = manipulator_model.manipulator_params(9.8, 0.25, 2.0, 1.5, 0.3, 5.0, 4.0)
        x1, x2 = math.pi / 6, 0.0
    else:
        return None
    advance = plant_integration.rk4_advance
    begin = time.perf_counter()
    for k in range(steps):
        t = k * h
        x1, x2 = advance(derivative, t, x1, x2, 0.5 * math.sin(t), h, 1e-4, params)
    return (time.perf_counter() - begin) / steps * 1e6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--step-size", type=float, default=1e-4)
    args = parser.parse_args(argv)

    import build_fmu
    from fmpy import extract

    paths = build_fmu.ensure_built()
    print(f"{args.steps} steps of h = {args.step_size:g} s, microseconds per step "
          f"(max_internal_step = 1e-4 s: {math.ceil(args.step_size / 1e-4 - 1e-12)} RK4 step(s) per doStep)")
    print(f"{'FMU':<20}{'fmpy':>10}{'raw':>10}{'pure':>10}")
    for name in PLANTS:
        unzip_dir = extract(str(paths[name]))
        via_fmpy = bench_fmpy(paths[name], unzip_dir, name, args.steps, args.step_size)
        via_raw = bench_raw(paths[name], unzip_dir, name, args.steps, args.step_size)
        pure = bench_pure(name, args.steps, args.step_size)
        pure_text = f"{pure:10.1f}" if pure is not None else f"{'-':>10}"
        print(f"{name:<20}{via_fmpy:10.1f}{via_raw:10.1f}{pure_text}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
