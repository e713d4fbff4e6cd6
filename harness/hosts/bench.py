"""``python -m harness bench``: cost per communication step, side by side in one run.

On the same ``pendulum_case1``/``vud`` system at the same step:
1. our master (feedthrough and jacobi): microseconds per step, real-time factor;
2. fmpy's SSP simulator on the exported SSP;
3. Ecos on the same SSP;
4. the floor: a bare loop of raw fmpy setReal/doStep/getReal calls on FMUs of the
   same shape whose doStep does no work (built from ``NULL_SCRIPT``);
5. the in-process oracle (the same math, no FMI);
6. the native edition (C FMUs, docs/native.md): our master with them, and libcosim
   (libcosimpy) with either edition and no worker threads, on the same exported SSP,
   recording the scenario's signals at every step as our master does (and, for comparison,
   with a last-value observer, which makes libcosim read every variable at every step);
   our master's figures come with its compiled loop (harness/master_loop.py) and, beside
   them, with its Python loop;
each with its ratio to ours; and 7. each FMU alone (plant, reference, controller: the
master's raw calls on that one instance) next to its null twin, which shows where the
time of a step goes and what each FMU's Python adds to the FMI floor.  With ``--edition
native``, 8. our native master against a plain C host over the same FMUs and the math floor
at horizons of 1 s to 20 s (harness/hosts/bench_c_baselines.py; ``--instructions`` adds their
instructions per step under callgrind).  Speed targets live here, not in timed tests.
"""
from __future__ import annotations

import functools
import json
import math
import subprocess
import sys
import tempfile
import time as clock
from pathlib import Path

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness.fmu_build import toolchain as c_toolchain
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.staging import staged_module

from .. import cli_args, master_loop, variants
from .. import scenario as scenarios
from ..cases import default_jobs
from ..fmi import Component, ModelInfo
from ..master import Master
from ..me_master import ModelExchangeMaster
from ..scenario_checks import resolve_fmu
from ..studies.oracle import simulate_oracle
from . import bench_c_baselines, engines, ssp
from .libcosim import run_libcosim, with_algorithm

NULL_FMUS = {  # instance -> (model identifier, the FMU whose variables it copies)
    "plant": ("NullPendulum", "InvertedPendulum"),
    "reference": ("NullReference", "TrackingReference"),
    "controller": ("NullController", "AdaptiveFuzzyController"),
}
NULL_SCRIPT = '''"""Benchmark floor: an FMU with the variables of {shape} whose doStep does no work."""
from {module} import VARIABLES
# pythonfmu's C loader needs the literal "class X(Fmi2Slave):"
from afc_slave_base import TableSlave as Fmi2Slave


class {identifier}(Fmi2Slave):
    VARIABLES = VARIABLES
    MODEL_DESCRIPTION = "Benchmark floor: the variables of {shape}, no computation"

    def compute_outputs(self):
        self.outputs_stale = False

    def step(self, current_time, step_size):
        return True
'''


def build_null_fmus(folder: Path) -> dict:
    """The floor's FMUs, written from one template into ``folder`` and built there."""
    paths = {}
    for instance, (identifier, shape) in NULL_FMUS.items():
        source = fmu_catalog.fmu(shape)
        script = folder / f"null_{identifier.lower()}_fmu.py"  # a unique module name per FMU (harness/fmu_build/staging.py)
        script.write_text(NULL_SCRIPT.format(shape=shape, module=staged_module(source.script), identifier=identifier))
        paths[instance] = build_fmu.build_script(script, folder / f"{identifier}.fmu",
                                                 (source.script, *source.project_files))
    return paths


def _raw_calls(scenario, name: str, path) -> tuple:
    """(component, get_reals, set_reals, do_step, inputs array) of one initialised instance, as the master calls it."""
    component = Component(name, ModelInfo.read(path)).instantiate()
    component.setup(scenario.start, scenario.stop)
    component.exit_initialization()
    inputs = [c.target_variable for c in scenario.connections if c.target_instance == name]
    outputs = list(dict.fromkeys(
        [c.source_variable for c in scenario.connections if c.source_instance == name]
        + [d.split(".", 1)[1] for d in scenario.record if d.startswith(name + ".")]))
    writer = component.real_writer(inputs)
    return component, component.real_reader(outputs).call, writer.call, component.stepper(), writer.values


def floor_us_per_step(scenario, null_paths: dict) -> float:
    """A bare loop: per FMU and step one raw getReal, setReal and doStep, nothing else."""
    opened = [_raw_calls(scenario, name, null_paths[name]) for name in ("plant", "reference", "controller")]
    calls = [(get_reals, set_reals, do_step) for _, get_reals, set_reals, do_step, _ in opened]
    steps, step = scenario.steps, scenario.step
    started = clock.perf_counter()
    for n in range(steps):
        t = n * step
        for get_reals, set_reals, do_step in calls:
            get_reals()
            set_reals()
            do_step(t, step, 1)
    elapsed = clock.perf_counter() - started
    for component, *_ in opened:
        component.free()
    return 1e6 * elapsed / steps


def fmu_us_per_step(scenario, name: str, path) -> float:
    """One FMU alone (the master's raw getReal, setReal, doStep) with inputs 0.1 sin t: its cost per step."""
    component, get_reals, set_reals, do_step, inputs = _raw_calls(scenario, name, path)
    count = len(inputs)
    steps, step = scenario.steps, scenario.step
    try:
        started = clock.perf_counter()
        for n in range(steps):
            t = n * step
            get_reals()
            value = 0.1 * math.sin(t)
            for k in range(count):
                inputs[k] = value
            set_reals()
            do_step(t, step, 1)
        return 1e6 * (clock.perf_counter() - started) / steps
    finally:
        component.free()


def master_us_per_step(scenario, algorithm: str, fmu_paths: dict | None = None,
                       runs: dict | None = None, loop: str = "auto") -> tuple[float, float]:
    """(loop only, whole run incl. instantiation and initialisation) in microseconds per step.

    ``loop``: the master's compiled loop ("auto", when zig is installed) or its Python loop
    ("python"; harness/master_loop.py).  The timed run's result is kept in ``runs[algorithm]``
    (for the agreement check)."""
    result = Master(scenario, algorithm, fmu_paths, loop=loop).run()
    if runs is not None:
        runs[algorithm] = result
    return result.us_per_step, 1e6 * result.wall_s / scenario.steps


LIBCOSIM_OBSERVERS = ("none", "scored", "recorded", "every")


def me_us_per_row(scenario, fmu_paths: dict) -> tuple:
    """Our Model Exchange master (harness/me_master.py, default rtol): microseconds per output row of its
    integration loop, and of the whole run; it has no communication step, its rows are the scenario's grid."""
    began = clock.perf_counter()
    result = ModelExchangeMaster(scenario, fmu_paths).run()
    whole = clock.perf_counter() - began
    return 1e6 * result.loop_s / (result.rows - 1), 1e6 * whole / (result.rows - 1)


def libcosim_us_per_step(package_dir: Path, scenario, observer: str = "none") -> float:
    """libcosim's own stepping loop on a package made by harness/hosts/libcosim.py's with_algorithm.

    ``observer``: "none" (libcosim reads only the connected outputs), "scored" (a time-series
    observer of the signals the scores read: e, de, ym, dym, u), "recorded" (of every signal our
    master records), "every" (a last-value observer, which reads every variable at every step).
    """
    if observer not in LIBCOSIM_OBSERVERS:
        raise ValueError(f"observer {observer!r}; valid: {', '.join(LIBCOSIM_OBSERVERS)}")
    record = {"scored": tuple(scenario.signals.values()), "recorded": scenario.record}.get(observer, ())
    variables = scenario.record[:1] if observer == "every" else ()
    run = run_libcosim(package_dir, scenario.stop, scenario.step, variables=variables, record=record)
    if record and run.recorded_samples < run.steps:
        raise RuntimeError(f"libcosim's time-series observer holds {run.recorded_samples} of {run.steps} samples")
    return run.loop_us_per_step


def native_paths() -> dict | None:
    """{model identifier: native FMI 2.0 FMU}, or None when zig's compiler is not installed."""
    if not c_toolchain.compiler_available():
        return None
    return {name: paths[2] for name, paths in build_native.ensure_built().items()}


def oracle_us_per_step(scenario, runs: dict | None = None) -> float:
    started = clock.perf_counter()
    result = simulate_oracle(scenario)
    elapsed = clock.perf_counter() - started
    if runs is not None:
        runs["oracle"] = result
    return 1e6 * elapsed / scenario.steps


def oracle_disagreement(runs: dict) -> float | None:
    """Largest |master - oracle| over the recorded signals both have, on the timed runs
    (they compute the same loop, so this is rounding; a benchmark that timed a broken or
    different run would show it here)."""
    master, oracle = runs.get("feedthrough"), runs.get("oracle")
    if master is None or oracle is None:
        return None
    common = [name for name in master.columns if name in oracle]
    if len(master.time) != len(oracle["time"]) or not common:
        return float("inf")
    return max(float(abs(master.signal(name) - oracle[name]).max()) for name in common)


def fmpy_ssp_us_per_step(package: Path, scenario) -> float:
    """fmpy's SSP simulator, whole run (it gives no handle on its loop alone)."""
    return 1e6 * engines.run_fmpy_ssp(package, stop=scenario.stop, step=scenario.step).wall_s / scenario.steps


def ecos_us_per_step(package: Path, scenario) -> tuple[float, float]:
    """Ecos: (its own stepping loop alone, whole run) in microseconds per step."""
    ecospy = engines.import_ecospy()
    ecospy.EcosLib.set_log_level("warn")
    started = clock.perf_counter()
    with engines.ecos_temp_dir():
        simulation = ecospy.EcosSimulation(ssp_path=str(package), step_size=scenario.step)
        try:
            simulation.init(start_time=scenario.start, parameter_set=engines.read_package(package).parameter_set)
            loop_start = clock.perf_counter()
            simulation.step(scenario.steps)
            loop = clock.perf_counter() - loop_start
            simulation.terminate()
        finally:
            simulation.free()
    whole = clock.perf_counter() - started
    return 1e6 * loop / scenario.steps, 1e6 * whole / scenario.steps


def _best_of(figures: dict, notes: dict, measurements: dict, repeat: int):
    """Round-robin ``repeat`` times over every measurement; each figure is its best.

    Interleaving puts every figure through the same slow and fast periods of a shared
    machine (the cost per step of the same code varies up to 1.6x from second to second
    here), so the ratios stay fair.  A tuple result fills ``key_us`` and ``key_whole_us``;
    an engine that fails is reported in ``notes``, not fatal to the benchmark.
    """
    samples = {key: [] for key in measurements}
    for _ in range(repeat):
        for key, measure in measurements.items():
            if key in notes:
                continue
            try:
                samples[key].append(measure())
            except Exception as error:
                notes[key] = f"{type(error).__name__}: {error}"
    for key, values in samples.items():
        if not values:
            figures[f"{key}_us"] = None
        elif isinstance(values[0], tuple):
            figures[f"{key}_us"] = min(v[0] for v in values)
            figures[f"{key}_whole_us"] = min(v[1] for v in values)
        else:
            figures[f"{key}_us"] = min(values)


def bench(scenario_name="pendulum_case1", controller=variants.PROPOSED, stop=2.0, step=None, repeat=3) -> dict:
    """Every figure is the best (smallest) of ``repeat`` interleaved measurements.

    ``*_us`` is the stepping loop alone where it can be separated (ours, Ecos, the floor, the
    oracle); ``*_whole_us`` includes instantiation and initialisation, as fmpy's SSP simulator
    is measured (it offers no handle on its loop).
    """
    scenario = scenarios.configure(scenario_name, controller, step, stop)
    figures = {"scenario": scenario.name, "controller": controller, "step": scenario.step, "stop": scenario.stop,
               "steps": scenario.steps, "repeat": repeat,
               "master_loop": "compiled" if master_loop.library() else "python"}
    notes = {}
    runs = {}
    with tempfile.TemporaryDirectory(prefix="afc_bench_") as folder:
        folder = Path(folder)
        python_paths = build_fmu.ensure_built(edition="python")
        package = ssp.export_ssp(scenario, folder / f"{scenario.name}.ssp", fmu_paths=python_paths)
        null_paths = build_null_fmus(folder)
        real_paths = {name: resolve_fmu(spec.fmu, scenario, python_paths) for name, spec in scenario.components.items()}
        per_fmu = {f"fmu_{name}{kind}": functools.partial(fmu_us_per_step, scenario, name, paths[name])
                   for name in NULL_FMUS for kind, paths in (("", real_paths), ("_null", null_paths))}
        native = native_paths()
        libcosim_python = with_algorithm(package, folder / "libcosim_python", scenario.step, workers=0)
        measurements = {}
        if native is None:
            notes["native_feedthrough"] = notes["libcosim_native"] = "no C compiler: pip install -e ."
        else:
            native_package = ssp.export_ssp(scenario, folder / f"{scenario.name}_native.ssp", fmu_paths=native)
            libcosim_native = with_algorithm(native_package, folder / "libcosim_native", scenario.step, workers=0)
            measurements = {
                "native_feedthrough": lambda: master_us_per_step(scenario, "feedthrough", native),
                "native_feedthrough_python_loop": lambda: master_us_per_step(scenario, "feedthrough", native,
                                                                             loop="python"),
                "native_me": lambda: me_us_per_row(scenario, native),
                "libcosim_native": lambda: libcosim_us_per_step(libcosim_native, scenario),
                **{f"libcosim_native_{observer}": functools.partial(libcosim_us_per_step, libcosim_native, scenario,
                                                                    observer) for observer in LIBCOSIM_OBSERVERS[1:]},
            }
        measurements["libcosim_python"] = lambda: libcosim_us_per_step(libcosim_python, scenario)
        _best_of(figures, notes, {
            "ours_feedthrough": lambda: master_us_per_step(scenario, "feedthrough", runs=runs),
            "ours_feedthrough_python_loop": lambda: master_us_per_step(scenario, "feedthrough", loop="python"),
            "ours_jacobi": lambda: master_us_per_step(scenario, "jacobi"),
            "fmpy_ssp_whole": lambda: fmpy_ssp_us_per_step(package, scenario),
            "ecos": lambda: ecos_us_per_step(package, scenario),
            "floor": lambda: floor_us_per_step(scenario, null_paths),
            "oracle": lambda: oracle_us_per_step(scenario, runs),
            **measurements,
            **per_fmu,
        }, repeat)
    ours, ours_whole = figures["ours_feedthrough_us"], figures["ours_feedthrough_whole_us"]
    figures["real_time_factor"] = scenario.step / (ours * 1e-6)
    for key in ("ours_feedthrough_python_loop_us", "ours_jacobi_us", "ecos_us", "floor_us", "oracle_us",
                "native_feedthrough_us", "native_feedthrough_python_loop_us", "libcosim_native_us",
                *(f"libcosim_native_{observer}_us" for observer in LIBCOSIM_OBSERVERS[1:]), "libcosim_python_us"):
        figures[key.replace("_us", "_ratio_to_ours")] = figures[key] / ours if figures.get(key) else None
    for key in ("ours_jacobi_whole_us", "fmpy_ssp_whole_us", "ecos_whole_us"):
        figures[key.replace("_us", "_ratio_to_ours")] = figures[key] / ours_whole if figures.get(key) else None
    figures["target_floor_plus_oracle_x1_5_us"] = 1.5 * (figures["floor_us"] + figures["oracle_us"])
    figures["oracle_max_abs_difference"] = oracle_disagreement(runs)
    figures["notes"] = notes
    return figures


TABLES_TARGET_S = {"native": 10.0, "native_me": 10.0}  # `tables --edition native [--algorithm me]`


def tables_wall_seconds(edition: str, stop: float | None = None, algorithm: str | None = None) -> float:
    """Wall time of ``python -m harness tables --edition EDITION [--algorithm ALGORITHM]`` (a process of its
    own, output to a temporary folder), as a user runs it: the main job's figure, in the benchmark."""
    with tempfile.TemporaryDirectory(prefix="afc_bench_tables_") as folder:
        command = [sys.executable, "-m", "harness", "tables", "--edition", edition, "--out", folder]
        if algorithm:
            command += ["--algorithm", algorithm]
        if stop is not None:
            command += ["--stop", repr(stop)]
        started = clock.perf_counter()
        completed = subprocess.run(command, capture_output=True, text=True)
        seconds = clock.perf_counter() - started
    if completed.returncode != 0:
        last = (completed.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"tables --edition {edition} failed: {last}")
    return seconds


def bench_command(args) -> int:
    native_section = fmu_catalog.selected_edition() == "native"
    if args.instructions and not native_section:
        raise cli_args.UsageError("--instructions counts the native loops: add --edition native")
    figures = bench(args.scenario, args.controller, args.stop, args.step, args.repeat)
    if native_section:
        native = native_paths()
        if native is None:
            figures["notes"]["native_against_c"] = "no C compiler: pip install -e '.[native]'"
        else:
            figures["native_against_c"] = bench_c_baselines.measure(native, args.horizons, args.repeat)
            if args.instructions:
                figures["instructions_per_step"] = bench_c_baselines.instructions()
    if args.tables:
        for key, edition, algorithm in (("native", "native", None), ("native_me", "native", "me"),
                                        ("python", "python", None)):
            try:
                figures[f"tables_{key}_s"] = tables_wall_seconds(edition, algorithm=algorithm)
            except Exception as error:  # noqa: BLE001 - reported beside the figures, as the engines are
                figures[f"tables_{key}_s"] = None
                figures["notes"][f"tables_{key}"] = f"{type(error).__name__}: {error}"
    if args.json:
        print(json.dumps(figures))
        return 0
    print(f"{figures['scenario']}/{figures['controller']}, step {figures['step']:g} s, "
          f"{figures['steps']} steps ({figures['stop']:g} s), best of {figures['repeat']}; "
          f"our master's loop: {figures['master_loop']} (harness/master_loop.py)")
    ours, ours_whole = figures["ours_feedthrough_us"], figures["ours_feedthrough_whole_us"]
    print(f"  {'us per step':40s} {'loop':>9s} {'x ours':>7s} {'whole run':>10s} {'x ours':>7s}")
    rows = [("our master (feedthrough)", "ours_feedthrough"),
            ("  the same, Python loop", "ours_feedthrough_python_loop"), ("our master (jacobi)", "ours_jacobi"),
            ("fmpy SSP simulator", "fmpy_ssp"), ("Ecos", "ecos"),
            ("floor: bare fmpy calls, null FMUs", "floor"), ("oracle: same math, no FMI", "oracle"),
            ("native FMUs, our master (feedthrough)", "native_feedthrough"),
            ("  the same, Python loop", "native_feedthrough_python_loop"),
            ("native FMUs, Model Exchange (us per row)", "native_me"),
            ("libcosim, pythonfmu FMUs, 0 workers", "libcosim_python"),
            ("libcosim, native FMUs, 0 workers", "libcosim_native"),
            ("  + observing the 5 scored signals", "libcosim_native_scored"),
            ("  + observing every recorded signal", "libcosim_native_recorded"),
            ("  + last-value observer (all variables)", "libcosim_native_every")]

    def cell(value, reference):
        return f"{'':>9s} {'':>7s}" if value is None else f"{value:9.2f} {value / reference:7.2f}"

    for label, key in rows:
        loop, whole = figures.get(f"{key}_us"), figures.get(f"{key}_whole_us")
        if key == "fmpy_ssp":
            loop, whole = None, figures.get("fmpy_ssp_whole_us")
        note = figures["notes"].get(key) or figures["notes"].get(f"{key}_whole") or ""
        print(f"  {label:40s} {cell(loop, ours)} {cell(whole, ours_whole).rjust(18)} {note}")
    print(f"  real-time factor of ours: {figures['real_time_factor']:.2f}")
    print(f"  timed runs of ours and the oracle agree within {figures['oracle_max_abs_difference']:.2g} "
          "(largest difference of a recorded signal)")
    print(f"  target: ours <= 1.5 x (floor + oracle) = {figures['target_floor_plus_oracle_x1_5_us']:.2f} us/step; "
          f"ours {ours:.2f}")
    native, libcosim = figures.get("native_feedthrough_us"), figures.get("libcosim_native_us")
    if native:
        print(f"  target: native FMUs in our master <= 8 us/step: {native:.2f}")
    if libcosim:
        observed = {key: figures.get(f"libcosim_native_{key}_us") or float("nan") for key in LIBCOSIM_OBSERVERS[1:]}
        print(f"  target: native FMUs in libcosim (0 workers) <= 2 us/step: {libcosim:.2f} with no observer, "
              f"{observed['scored']:.2f} observing the scored signals, {observed['recorded']:.2f} observing what "
              f"our master records (like for like), {observed['every']:.2f} with a last-value observer")
    print(f"  {'one FMU alone, us per step':40s} {'FMU':>9s} {'null FMU':>9s} {'difference':>10s}")
    for name in NULL_FMUS:
        own, null = figures.get(f"fmu_{name}_us"), figures.get(f"fmu_{name}_null_us")
        if own is not None and null is not None:
            print(f"  {name:40s} {own:9.2f} {null:9.2f} {own - null:10.2f}")
    if args.tables:
        text = {key: "failed" if figures.get(f"tables_{key}_s") is None else f"{figures[f'tables_{key}_s']:.1f} s"
                for key in ("native", "native_me", "python")}
        print(f"  target: `tables --edition native` (the Table I/II report, {default_jobs()} processes) <= "
              f"{TABLES_TARGET_S['native']:g} s wall: {text['native']}; pythonfmu edition: {text['python']} "
              f"{figures['notes'].get('tables_native', '')}{figures['notes'].get('tables_python', '')}")
        print(f"  target: `tables --edition native --algorithm me` (Model Exchange) <= "
              f"{TABLES_TARGET_S['native_me']:g} s wall: {text['native_me']} {figures['notes'].get('tables_native_me', '')}")
    else:
        print("  (`--tables` also times `tables` in both editions: the main job)")
    fmpy_whole = figures.get("fmpy_ssp_whole_us")
    if fmpy_whole:
        print(f"  target: ours at least 2x faster than fmpy's SSP simulator (whole runs): "
              f"{fmpy_whole / ours_whole:.2f}x")
    if figures.get("native_against_c"):
        bench_c_baselines.print_section(figures["native_against_c"], args.repeat, figures.get("instructions_per_step"))
    elif native_section:
        print(f"  the native master against a plain C host: {figures['notes']['native_against_c']}")
    return 0


def register(commands):
    parser = commands.add_parser("bench", help="cost per step: ours vs fmpy SSP, Ecos, the FMI floor, the oracle")
    parser.add_argument("--scenario", default="pendulum_case1", type=cli_args.scenario, help=cli_args.scenario_help())
    parser.add_argument("--controller", default=variants.PROPOSED, choices=variants.NAMES)
    parser.add_argument("--stop", type=cli_args.positive_float, default=2.0, help="simulated seconds per measurement")
    parser.add_argument("--step", type=cli_args.positive_float, help="communication step (default: the scenario's)")
    parser.add_argument("--repeat", type=cli_args.positive_int, default=3, help="measurements per figure; the best counts")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--tables", action="store_true",
                        help="also time `tables` (the Table I/II report, full horizon) in both editions and with "
                             "--algorithm me: about 5 s native, 10 s native Model Exchange, 50 s pythonfmu")
    parser.add_argument("--horizons", type=bench_c_baselines.horizons, default=bench_c_baselines.HORIZONS,
                        help="--edition native: the horizons (s, comma-separated) at which our master, the plain C "
                             "host and the math floor are timed (default 1,2,5,10,20)")
    parser.add_argument("--instructions", action="store_true",
                        help="--edition native: also count the three loops' instructions per step with valgrind's "
                             "callgrind (about 5 min; needs valgrind)")
    parser.set_defaults(handler=bench_command)

