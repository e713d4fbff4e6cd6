"""``python -m harness bench``: cost per communication step, side by side in one run.

On the same ``pendulum_case1``/``vud`` system at the same step:
1. our master (feedthrough and jacobi): microseconds per step, real-time factor;
2. fmpy's SSP simulator on the exported SSP;
3. Ecos on the same SSP;
4. the floor: a bare loop of raw fmpy setReal/doStep/getReal calls on FMUs of the
   same shape whose doStep does no work (``harness/null_fmus``);
5. the in-process oracle (the same math, no FMI);
each with its ratio to ours.  Speed targets live here, not in timed tests.
"""
from __future__ import annotations

import json
import tempfile
import time as clock
from pathlib import Path

from . import scenario as scenarios
from .fmi import Component, ModelInfo
from .master import Master
from .oracle import simulate_oracle

NULL_DIR = Path(__file__).resolve().parent / "null_fmus"
NULL_FMUS = {  # instance -> (script, model identifier, the FMU whose shape it copies)
    "plant": ("null_pendulum_fmu.py", "NullPendulum", "InvertedPendulum"),
    "reference": ("null_reference_fmu.py", "NullReference", "TrackingReference"),
    "controller": ("null_controller_fmu.py", "NullController", "AdaptiveFuzzyController"),
}


def build_null_fmus(folder: Path) -> dict:
    import build_fmu

    paths = {}
    for instance, (script, identifier, shape) in NULL_FMUS.items():
        source = next(f for f in build_fmu.FMUS if f.model_identifier == shape)
        paths[instance] = build_fmu.build_script(NULL_DIR / script, folder / f"{identifier}.fmu",
                                                 (source.script, *source.project_files))
    return paths


def floor_us_per_step(scenario, null_paths: dict) -> float:
    """A bare loop: per FMU and step one raw getReal, setReal and doStep, nothing else."""
    components, calls = [], []
    for name in ("plant", "reference", "controller"):
        component = Component(name, ModelInfo.read(null_paths[name])).instantiate()
        component.setup(scenario.start, scenario.stop)
        component.exit_initialization()
        inputs = [c.target_variable for c in scenario.connections if c.target_instance == name]
        outputs = list(dict.fromkeys(
            [c.source_variable for c in scenario.connections if c.source_instance == name]
            + [d.split(".", 1)[1] for d in scenario.record if d.startswith(name + ".")]))
        components.append(component)
        calls.append((component.real_reader(outputs)[1], component.real_writer(inputs)[1], component.stepper()))
    steps, step = scenario.steps, scenario.step
    started = clock.perf_counter()
    for n in range(steps):
        t = n * step
        for get_reals, set_reals, do_step in calls:
            get_reals()
            set_reals()
            do_step(t, step, 1)
    elapsed = clock.perf_counter() - started
    for component in components:
        component.free()
    return 1e6 * elapsed / steps


def master_us_per_step(scenario, algorithm: str) -> float:
    result = Master(scenario, algorithm).run()
    return result.us_per_step


def oracle_us_per_step(scenario) -> float:
    started = clock.perf_counter()
    simulate_oracle(scenario)
    return 1e6 * (clock.perf_counter() - started) / scenario.steps


def engine_us_per_step(engine: str, scenario, folder: Path):
    """fmpy's SSP simulator or Ecos on the exported SSP, timed by the engine adapter; None if unavailable."""
    from . import engines, ssp

    package = ssp.export_ssp(scenario, folder / f"{scenario.name}.ssp")
    try:
        result = engines.run_package(engine, package, stop=scenario.stop, step=scenario.step)
    except Exception as error:  # an engine's own failure is reported, not fatal to the benchmark
        return None, f"{type(error).__name__}: {error}"
    return 1e6 * result.wall_s / scenario.steps, ""


def bench(scenario_name="pendulum_case1", controller="vud", stop=2.0, step=None, repeat=3) -> dict:
    """Every figure is the best (smallest) of ``repeat`` measurements, to keep load noise out."""
    scenario = scenarios.configure(scenario_name, controller, step, stop)
    figures = {"scenario": scenario.name, "controller": controller, "step": scenario.step, "stop": scenario.stop,
               "steps": scenario.steps, "repeat": repeat}
    notes = {}

    def best(measure):
        values = [measure() for _ in range(repeat)]
        return min(values)

    figures["ours_feedthrough_us"] = best(lambda: master_us_per_step(scenario, "feedthrough"))
    figures["ours_jacobi_us"] = best(lambda: master_us_per_step(scenario, "jacobi"))
    with tempfile.TemporaryDirectory(prefix="afc_bench_") as folder:
        folder = Path(folder)
        for engine, key in (("fmpy", "fmpy_ssp"), ("ecos", "ecos")):
            runs = [engine_us_per_step(engine, scenario, folder) for _ in range(repeat)]
            measured = [us for us, _ in runs if us is not None]
            figures[f"{key}_us"] = min(measured) if measured else None
            notes[key] = next((note for _, note in runs if note), "")
        null_paths = build_null_fmus(folder)
        figures["floor_us"] = best(lambda: floor_us_per_step(scenario, null_paths))
    figures["oracle_us"] = best(lambda: oracle_us_per_step(scenario))
    ours = figures["ours_feedthrough_us"]
    figures["real_time_factor"] = scenario.step / (ours * 1e-6)
    for key in ("ours_jacobi_us", "fmpy_ssp_us", "ecos_us", "floor_us", "oracle_us"):
        figures[key.replace("_us", "_ratio_to_ours")] = figures[key] / ours if figures[key] else None
    figures["target_floor_plus_oracle_x1_5_us"] = 1.5 * (figures["floor_us"] + figures["oracle_us"])
    figures["notes"] = {k: v for k, v in notes.items() if v}
    return figures


def bench_command(args) -> int:
    figures = bench(args.scenario, args.controller, args.stop, args.step, args.repeat)
    if args.json:
        print(json.dumps(figures))
        return 0
    ours = figures["ours_feedthrough_us"]
    print(f"{figures['scenario']}/{figures['controller']}, step {figures['step']:g} s, "
          f"{figures['steps']} steps ({figures['stop']:g} s), best of {figures['repeat']}")
    rows = [("our master (feedthrough)", "ours_feedthrough_us"), ("our master (jacobi)", "ours_jacobi_us"),
            ("fmpy SSP simulator", "fmpy_ssp_us"), ("Ecos", "ecos_us"),
            ("floor: bare fmpy calls, null FMUs", "floor_us"), ("oracle: same math, no FMI", "oracle_us")]
    print(f"  {'':36s} {'us/step':>10s} {'x ours':>8s}")
    for label, key in rows:
        value = figures[key]
        if value is None:
            print(f"  {label:36s} {'n/a':>10s}   {figures['notes'].get(key[:-3], '')}")
        else:
            print(f"  {label:36s} {value:10.2f} {value / ours:8.2f}")
    print(f"  real-time factor of ours: {figures['real_time_factor']:.2f}")
    print(f"  target: ours <= 1.5 x (floor + oracle) = {figures['target_floor_plus_oracle_x1_5_us']:.2f} us/step")
    return 0


def register(commands):
    parser = commands.add_parser("bench", help="cost per step: ours vs fmpy SSP, Ecos, the FMI floor, the oracle")
    parser.add_argument("--scenario", default="pendulum_case1")
    parser.add_argument("--controller", default="vud", choices=tuple(scenarios.CONTROLLER_VARIANTS))
    parser.add_argument("--stop", type=float, default=2.0, help="simulated seconds per measurement")
    parser.add_argument("--step", type=float, help="communication step (default: the scenario's)")
    parser.add_argument("--repeat", type=int, default=3, help="measurements per figure; the best counts")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(handler=bench_command)

