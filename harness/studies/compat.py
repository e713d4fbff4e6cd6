"""The FMUs' compatibility information in the FMI cross-check layout: ``python -m harness compat --out DIR``.

What the FMI project asks of an exporting tool (the FMI Cross-Check rules, 9.1.4 and 9.2.4, which
fmpy's ``fmpy.cross_check.validate_vendor_repo`` checks), for every FMU of both editions:

* ``fmus/<FMI version>/<cs|me>/<platform>/<tool>/<tool version>/<Model>/``: ``<Model>.fmu``,
  ``<Model>_in.csv`` (the inputs), ``<Model>_ref.csv`` (the reference result, time first, at most
  ``MAX_SIGNALS`` signals), ``<Model>_ref.opt`` (start, stop, step, tolerance) and ``README.md``;
* ``results/<FMI version>/<cs|me>/<platform>/FMPy/<fmpy version>/<tool>/<tool version>/<Model>/``:
  ``passed`` or ``failed``, ``<Model>_out.csv`` and ``README.md``: the FMU re-simulated with
  ``fmpy simulate`` from ``_in.csv`` and compared with ``_ref.csv``.

The tools are ``afc-fmi-pythonfmu`` (the reference edition, FMI 2.0 co-simulation) and
``afc-fmi-native`` (the C edition, FMI 2.0 and 3.0); the interfaces of each FMU are those its
modelDescription.xml declares (``CoSimulation``, and ``ModelExchange`` where the FMU has it).

The experiment of an FMU comes from a closed loop of ours: a scenario that uses the FMU with its
parameters at their defaults (the values an importing tool gets: the FMU's instance has its parameters
cleared) runs on our master; the FMU's connected inputs at each communication point are its
``_in.csv``. The co-simulation reference is the FMU alone, driven through the harness's FMI layer
(harness/fmi.py) as an importer replays an input file: at t_k the inputs of ``_in.csv`` row k, doStep
from t_k to t_k+1, the outputs read at t_k+1. A Model Exchange entry is held to the same reference
(the co-simulation result of the same model), re-simulated by fmpy with CVode.
"""
from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import math
import shutil
import subprocess
import sys
import time as clock
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy import platform as FMPY_PLATFORM
from fmpy import read_model_description
from fmpy.cross_check import validate_result
from fmpy.cross_check.validate_vendor_repo import (read_csv, validate_cross_check_result, validate_repo,
                                                   validate_test_fmu)

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.native_stages import ls_ref

from .. import atomic_files, cli_args
from .. import scenario as scenarios
from ..cases import default_jobs
from ..fmi import Component, ModelInfo
from ..master import simulate

TOOLS = {"python": "afc-fmi-pythonfmu", "native": "afc-fmi-native", "native3": "afc-fmi-native"}
EDITIONS = ("python", "native", "native3")
IMPORTER = "FMPy"
HORIZON = 1.0  # s: the experiment covers the first second of the closed loop (the transient) ...
MAX_STEPS = 4000  # ... in at most this many communication steps (CSV files under 1 MB)
MAX_SIGNALS = 9  # outputs in _ref.csv besides time ("about 10 signals")
MAX_CSV_BYTES = 1_000_000
ME_TOLERANCE = 1e-12  # CVode's relative tolerance for the Model Exchange re-simulation
#: what a co-simulation re-simulation must reproduce (largest |out - ref| over the signal's range): the
#: same binary, inputs and calls give the same numbers; 1e-12 leaves room for nothing but printing
CS_AGREEMENT = 1e-12
#: scenarios tried, in order, for an FMU's experiment (the first that uses it with its defaults wins)
PREFERRED_SCENARIOS = ("pendulum_case1", "manipulator", "motor_arm")


def tool_version() -> str:
    try:
        return importlib.metadata.version("afc-fmi")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


def platform_folder() -> str:
    """The cross-check layout's platform name of this machine (linux64, win64, darwin64)."""
    return FMPY_PLATFORM


# -------------------------------------------------------------- experiments
@dataclass
class Experiment:
    """An FMU's experiment: its inputs at each communication point, the outputs to record."""

    model: str
    scenario: str
    instance: str
    start: float
    step: float
    steps: int
    every: int  # the experiment's step is this many steps of the closed loop
    inputs: tuple  # the FMU's input variables (the connected ones)
    outputs: tuple  # the FMU's outputs in _ref.csv
    input_table: np.ndarray  # rows: time, then the inputs

    @property
    def stop(self) -> float:
        return self.start + self.steps * self.step

    def times(self) -> np.ndarray:
        """t_k = start + k h, computed as fmpy computes its communication points."""
        return np.array([self.start + k * self.step for k in range(self.steps + 1)])


def _choose_scenario(model: str) -> tuple[str, str]:
    """(scenario, instance) for an FMU: the first preferred scenario (then any) that has an instance of it,
    preferring one whose instance keeps every parameter at its default."""
    names = list(PREFERRED_SCENARIOS) + [n for n in scenarios.scenario_names() if n not in PREFERRED_SCENARIOS]
    defaults = {v.name: v.start for v in fmu_catalog.model_class(model).VARIABLES}
    found = []
    for name in names:
        scenario = scenarios.load(name)
        for instance, spec in scenario.components.items():
            if spec.fmu == model:
                found.append((name, instance, all(defaults.get(k) == v for k, v in spec.parameters.items())))
    if not found:
        raise RuntimeError(f"no scenario of harness/scenarios/ uses {model}; add one (docs/architecture.md)")
    return next(((n, i) for n, i, at_defaults in found if at_defaults), found[0][:2])


def closed_loop_experiments(models, fmu_paths: dict) -> dict:
    """{model: Experiment}: each model's experiment from one closed-loop run per scenario."""
    chosen = {model: _choose_scenario(model) for model in models}
    experiments = {}
    for scenario_name in sorted({name for name, _ in chosen.values()}):
        published = {model: instance for model, (name, instance) in chosen.items() if name == scenario_name}
        scenario = scenarios.load(scenario_name)
        every = max(1, math.ceil(HORIZON / scenario.step / MAX_STEPS))
        steps = min(MAX_STEPS, round(HORIZON / (scenario.step * every)))
        for instance in published.values():
            scenario.components[instance].parameters = {}  # the FMU's defaults: what an importer gets
        wiring = {instance: [(c.target_variable, c.source) for c in scenario.connections
                             if c.target_instance == instance] for instance in published.values()}
        recorded = {instance: [name.split(".", 1)[1] for name in scenario.record
                               if name.split(".", 1)[0] == instance][:MAX_SIGNALS]
                    for instance in published.values()}
        scenario.record = list(dict.fromkeys(
            [source for pairs in wiring.values() for _, source in pairs]
            + [f"{i}.{o}" for i, outputs in recorded.items() for o in outputs]
            + list(scenario.signals.values())))  # the master records what the scores read
        scenario = scenario.with_parameter("stop", scenario.start + steps * every * scenario.step)
        result = simulate(scenario, fmu_paths=fmu_paths)
        step = float(f"{scenario.step * every:.12g}")  # 0.0005, not 0.0005000000000000001
        for model, instance in published.items():
            columns = [result.signal(source)[::every][:steps + 1] for _, source in wiring[instance]]
            experiment = Experiment(model, scenario_name, instance, scenario.start, step, steps, every,
                                    tuple(target for target, _ in wiring[instance]), tuple(recorded[instance]),
                                    np.empty((0, 0)))
            # the loop's values at its communication points, on the experiment's own time grid (the same
            # points up to rounding): an importer then reads each row at exactly its time
            experiment.input_table = np.column_stack([experiment.times(), *columns])
            experiments[model] = experiment
    return experiments


def ls_ref_experiment(experiment: Experiment) -> ls_ref.Experiment:
    """The experiment as every FMU carries it (FMI-LS-REF): the same grid, signals and _in.csv text."""
    stimuli = ls_ref.csv_text(["time", *experiment.inputs], experiment.input_table)
    return ls_ref.Experiment(experiment.model, experiment.scenario, experiment.instance, experiment.start,
                             experiment.step, experiment.steps, experiment.inputs, experiment.outputs, stimuli)


def write_ls_ref_experiments(models=None) -> list:
    """Store every FMU's experiment where the builds read it (harness/fmu_build/native_stages/ls_ref_experiments/)."""
    models = list(models or [row.model_identifier for row in fmu_catalog.FMUS])
    experiments = closed_loop_experiments(models, build_fmu.ensure_built(edition="python"))
    stored = [ls_ref_experiment(experiments[model]) for model in models]
    ls_ref.write(stored)
    return stored


# --------------------------------------------------------------- references
def replay(fmu_path: Path, experiment: Experiment, table: np.ndarray | None = None,
           outputs_with: str = "previous") -> np.ndarray:
    """The FMU alone driven by ``table`` (default: the experiment's inputs, one row per communication point),
    through the harness's FMI layer: rows time, then the experiment's outputs.

    Inputs are held over each step (row k from t_k to t_k+1). ``outputs_with="previous"``: the outputs at
    t_k+1 are read right after doStep, with the inputs of t_k still set, as an importer replays an input
    file in co-simulation (fmpy, the FMU Compliance Checker); ``"current"``: with the inputs of t_k+1 set
    first, the continuous-time output y(t) = g(x(t), u(t)) that a Model Exchange importer records."""
    if outputs_with not in ("previous", "current"):
        raise ValueError(f"outputs_with={outputs_with!r}; valid: previous, current")
    table = experiment.input_table if table is None else table
    component = Component(experiment.instance, ModelInfo.read(fmu_path)).instantiate()
    try:
        component.setup(experiment.start, experiment.stop)
        writer = component.real_writer(list(experiment.inputs)) if experiment.inputs else None
        reader = component.real_reader(list(experiment.outputs))
        times = experiment.times()

        def set_inputs(k):
            if writer is not None:
                writer.values[:] = [float(v) for v in table[k, 1:]]
                status = writer.call()
                if status > 1:
                    component.fail("fmi2SetReal", status, times[k])

        def outputs(k):
            status = reader.call()
            if status > 1:
                component.fail("fmi2GetReal", status, times[k])
            return list(reader.values)

        set_inputs(0)
        component.exit_initialization()
        rows = [[times[0], *outputs(0)]]
        step = component.stepper()
        for k in range(experiment.steps):
            set_inputs(k)
            status = step(float(times[k]), float(times[k + 1] - times[k]), 1)
            if status > 1:
                component.fail("fmi2DoStep", status, times[k])
            if outputs_with == "current":
                set_inputs(k + 1)
            rows.append([times[k + 1], *outputs(k + 1)])
    finally:
        component.free()
    return np.array(rows)


def held(table: np.ndarray) -> np.ndarray:
    """An input table held over each step as an input file says it: row k at t_k and again at t_k+1 before
    row k+1 (repeated times mark the steps; fmpy applies the value after such an event)."""
    if len(table) < 2:
        return table
    rows = [table[0]]
    for k in range(1, len(table)):
        rows.append(np.concatenate([table[k, :1], table[k - 1, 1:]]))
        rows.append(table[k])
    return np.array(rows)


def write_csv(path: Path, names, table: np.ndarray):
    """A cross-check CSV: quoted names, time first, numbers as the shortest text that reads back exactly."""
    atomic_files.write_bytes(path, ls_ref.csv_text(names, table))


# ------------------------------------------------------------------ entries
@dataclass
class Entry:
    model: str
    edition: str
    fmi_version: str  # "2.0" or "3.0"
    interface: str  # "cs" or "me"
    fmu: Path
    experiment: Experiment
    folder: Path | None = None  # the fmus/... folder
    result_folder: Path | None = None  # the results/... folder
    passed: bool = False
    agreement: dict = field(default_factory=dict)  # signal -> max |out - ref| / range
    problem: str = ""
    fmpy_wall_s: float = 0.0

    @property
    def tool(self) -> str:
        return TOOLS[self.edition]

    @property
    def label(self) -> str:
        return f"{self.fmi_version}/{self.interface}/{self.tool}/{self.model}"


def interfaces(fmu: Path) -> list:
    """The interfaces the model description declares: "cs", and "me" where it has ModelExchange."""
    description = read_model_description(str(fmu))
    return [name for name, declared in (("cs", description.coSimulation), ("me", description.modelExchange))
            if declared is not None]


def entries_for(editions, models, experiments: dict) -> list:
    entries = []
    for edition in editions:
        paths = build_fmu.ensure_built(edition=edition)
        version = "3.0" if edition == "native3" else "2.0"
        for model in models:
            for interface in interfaces(paths[model]):
                entries.append(Entry(model, edition, version, interface, paths[model], experiments[model]))
    return entries


def readme(entry: Entry, reference_rows: int) -> str:
    e = entry.experiment
    description = read_model_description(str(entry.fmu)).description or ""
    edition = ("the reference edition, built with pythonfmu 0.7: the host needs Python 3 with the packages "
               "of afc-fmi's pyproject.toml (a host that is not Python preloads libpython)"
               if entry.edition == "python" else
               "the native C edition: no Python needed (binaries for linux64, win64, darwin64, aarch64-linux)")
    replay_text = ("at t_k the inputs of row k of the _in.csv, doStep from t_k to t_k+1, the outputs read at t_k+1 "
                   "(as fmpy and the FMU Compliance Checker replay an input file)")
    lines = [f"# {e.model}: {description}", "",
             f"Exported by afc-fmi {tool_version()} ({edition}), FMI {entry.fmi_version}, "
             f"{'co-simulation' if entry.interface == 'cs' else 'model exchange'}, platform {platform_folder()}.", "",
             "## The experiment", "",
             f"The FMU's connected inputs ({', '.join(e.inputs) or 'none'}) as our master set them in the first "
             f"{e.stop - e.start:g} s of the closed loop `{e.scenario}` (harness/scenarios/{e.scenario}.toml of "
             f"afc-fmi), instance `{e.instance}`, with this FMU's parameters at their defaults, sampled every "
             f"{e.step:g} s ({e.steps} steps).", "",
             f"`{e.model}_ref.csv` ({reference_rows} rows: {', '.join(e.outputs)}) is the co-simulation result of "
             f"the FMU alone driven through afc-fmi's FMI layer: {replay_text}."]
    if entry.interface == "me":
        lines[-1] = (f"`{e.model}_ref.csv` ({reference_rows} rows: {', '.join(e.outputs)}) is the result of the "
                     "same model run by its co-simulation interface through afc-fmi's FMI layer, inputs held over "
                     "each step, the outputs at t_k read with the inputs of t_k set: y(t) = g(x(t), u(t)).")
        lines += ["", f"`{e.model}_in.csv` holds each input over its step: a row at t_k+1 repeats the value of t_k "
                      "before the row with the new value (a step change, which fmpy applies as an input event). "
                      "An importer integrates the model with its own solver (fmpy: CVode, relative tolerance "
                      f"{ME_TOLERANCE:g}), the co-simulation interface with its own fixed-step integrator: expect "
                      "agreement within the cross-check's band, not to the last digit."]
    lines += ["", "## Reproduce with fmpy", "", "```", resimulation_command(entry, Path("."), Path(f"{e.model}_out.csv"),
                                                                           relative=True), "```", ""]
    return "\n".join(lines)


def _opt_text(entry: Entry) -> str:
    e = entry.experiment
    step = 0.0 if entry.interface == "me" else e.step
    tolerance = ME_TOLERANCE if entry.interface == "me" else 1e-6
    return (f"StartTime, {e.start!r}\nStopTime, {e.stop!r}\nStepSize, {step!r}\nRelTol, {tolerance!r}\n"
            f"OutputIntervalLength, {e.step!r}\n")


def write_entry(entry: Entry, out: Path) -> Path:
    e = entry.experiment
    folder = out / "fmus" / entry.fmi_version / entry.interface / platform_folder() / entry.tool / tool_version() / e.model
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(entry.fmu, folder / f"{e.model}.fmu")
    # co-simulation: one row per communication point (an importer sets row k at t_k); model exchange: the
    # same values held over each step, which an ODE solver needs said (it interpolates between rows)
    inputs = held(e.input_table) if entry.interface == "me" else e.input_table
    if e.inputs:
        write_csv(folder / f"{e.model}_in.csv", ["time", *e.inputs], inputs)
        written = np.genfromtxt(folder / f"{e.model}_in.csv", delimiter=",", skip_header=1, ndmin=2)
        table = written[::2] if entry.interface == "me" else written  # the rows at t_0, t_1, ... of each step
    else:
        table = None
    # the reference: the FMU replays exactly the inputs written (read back from the file)
    reference = replay(entry.fmu, e, table, "current" if entry.interface == "me" else "previous")
    write_csv(folder / f"{e.model}_ref.csv", ["time", *e.outputs], reference)
    atomic_files.write_text(folder / f"{e.model}_ref.opt", _opt_text(entry))
    atomic_files.write_text(folder / "README.md", readme(entry, len(reference)))
    entry.folder = folder
    return folder


# ------------------------------------------------------------ re-simulation
def resimulation_command(entry: Entry, folder: Path, output: Path, relative: bool = False) -> str:
    return " ".join(resimulation_arguments(entry, folder, output, relative))


def resimulation_arguments(entry: Entry, folder: Path, output: Path, relative: bool = False) -> list:
    e = entry.experiment
    where = (lambda name: name) if relative else (lambda name: str(folder / name))
    arguments = ["fmpy", "simulate", where(f"{e.model}.fmu"), "--start-time", repr(e.start), "--stop-time",
                 repr(e.stop), "--output-interval", repr(e.step)]
    if e.inputs:
        arguments += ["--input-file", where(f"{e.model}_in.csv")]
    if entry.interface == "me":
        arguments += ["--interface-type", "ModelExchange", "--solver", "CVode", "--relative-tolerance",
                      repr(ME_TOLERANCE), "--dont-record-events"]
    else:
        arguments += ["--interface-type", "CoSimulation"]
    return arguments + ["--output-variables", *e.outputs, "--output-file", str(output)]


def resimulate(entry: Entry, out: Path, timeout: float = 600) -> Entry:
    """fmpy simulate from _in.csv; compare with _ref.csv; write passed/failed, _out.csv and a README."""
    return judge(run_fmpy(entry, out, timeout))


def run_fmpy(entry: Entry, out: Path, timeout: float = 600) -> Entry:
    """``fmpy simulate`` of the entry's FMU on its _in.csv into results/.../<Model>_out.csv (a process of its
    own: runs of several entries can go in threads)."""
    e = entry.experiment
    folder = (out / "results" / entry.fmi_version / entry.interface / platform_folder() / IMPORTER
              / importlib.metadata.version("fmpy") / entry.tool / tool_version() / e.model)
    folder.mkdir(parents=True, exist_ok=True)
    for marker in ("passed", "failed"):
        (folder / marker).unlink(missing_ok=True)
    output = folder / f"{e.model}_out.csv"
    arguments = resimulation_arguments(entry, entry.folder, output)
    arguments[0] = str(Path(sys.executable).with_name("fmpy"))  # the fmpy command of this environment
    started = clock.perf_counter()
    completed = subprocess.run(arguments, capture_output=True, text=True, timeout=timeout)
    entry.fmpy_wall_s = clock.perf_counter() - started
    entry.problem = "" if completed.returncode == 0 and output.exists() else \
        cli_args.one_line(RuntimeError(completed.stderr or completed.stdout or "fmpy wrote no output"))
    entry.result_folder = folder
    return entry


def judge(entry: Entry) -> Entry:
    """Compare fmpy's result with _ref.csv; write passed or failed and the result's README."""
    e, folder = entry.experiment, entry.result_folder
    if not entry.problem:
        entry.agreement, entry.problem = compare_with_reference(entry.folder / f"{e.model}_ref.csv",
                                                                folder / f"{e.model}_out.csv", e)
        if entry.interface == "cs" and not entry.problem:
            worst = max(entry.agreement.values(), default=0.0)
            if worst > CS_AGREEMENT:
                entry.problem = f"co-simulation result differs from the reference by {worst:.3g} of a signal's range"
    entry.passed = not entry.problem
    atomic_files.write_text(folder / ("passed" if entry.passed else "failed"), "")
    lines = [f"# {e.model} ({entry.tool} {tool_version()}) imported by {IMPORTER} "
             f"{importlib.metadata.version('fmpy')}", "",
             f"Result: **{'passed' if entry.passed else 'failed'}**" + (f": {entry.problem}" if entry.problem else ""),
             "", "Command (from the FMU's folder in fmus/):", "", "```",
             resimulation_command(entry, Path("."), Path(f"{e.model}_out.csv"), relative=True), "```", "",
             f"Largest |out - ref| over each signal's range (fmpy ran {entry.fmpy_wall_s:.1f} s):", ""]
    lines += [f"- {name}: {value:.3g}" for name, value in entry.agreement.items()]
    atomic_files.write_text(folder / "README.md", "\n".join(lines) + "\n")
    return entry


def compare_with_reference(reference_csv: Path, output_csv: Path, experiment: Experiment) -> tuple[dict, str]:
    """({signal: max |out - ref| / range}, problem): fmpy's cross-check criterion (validate_result) and the
    largest deviation of each signal on the reference's time grid."""
    reference, result = read_csv(str(reference_csv)), read_csv(str(output_csv))
    with warnings.catch_warnings():  # fmpy 0.3.32 imports scipy.ndimage.filters, deprecated in SciPy 1.x
        warnings.simplefilter("ignore", DeprecationWarning)
        problem = validate_result(result=result, reference=reference, t_start=experiment.start,
                                  t_stop=experiment.stop)
    agreement = {}
    t_ref, t_out = reference[reference.dtype.names[0]], result[result.dtype.names[0]]
    for name in reference.dtype.names[1:]:
        if name not in result.dtype.names:
            return agreement, f'variable "{name}" is missing from the result'
        y_ref = reference[name]
        y_out = np.interp(t_ref, t_out, result[name])
        scale = float(np.ptp(y_ref)) or max(float(np.max(np.abs(y_ref))), 1.0)
        agreement[name] = float(np.max(np.abs(y_out - y_ref))) / scale
    return agreement, problem or ""


# --------------------------------------------------------------- validation
def validate(out: Path) -> "Validation":
    """fmpy's validate_vendor_repo, plus the same checks on the FMI 3.0 folders, which fmpy 0.3's
    validator walks but skips (it knows FMI 1.0 and 2.0 only); and the layout's size limits."""
    with warnings.catch_warnings():  # see compare_with_reference
        warnings.simplefilter("ignore", DeprecationWarning)
        return _validate(out)


def _validate(out: Path) -> "Validation":
    fmu_count, result_count, problems = validate_repo(str(out))
    problems = list(problems)
    fmi3 = sorted((out / "fmus" / "3.0").glob("*/*/*/*/*"))
    fmi3_results = sorted((out / "results" / "3.0").glob("*/*/*/*/*/*/*"))
    for folder in fmi3:
        problems += validate_test_fmu(str(folder))
    for folder in fmi3_results:
        problems += validate_cross_check_result(str(folder))
    for path in sorted(out.rglob("*.csv")):
        if path.stat().st_size > MAX_CSV_BYTES:
            problems.append(f"{path} is larger than 1 MB")
    for path in sorted(out.rglob("*_ref.csv")):
        columns = path.open().readline().count(",")
        if columns > MAX_SIGNALS + 1:
            problems.append(f"{path} has {columns} signals (at most about 10)")
    return Validation(fmu_count, result_count, len(fmi3), len(fmi3_results), problems)


@dataclass
class Validation:
    fmus: int  # FMU folders fmpy's validate_repo walked (its checks skip FMI 3.0)
    results: int
    fmi3_fmus: int  # FMI 3.0 FMU folders checked here with fmpy's validate_test_fmu
    fmi3_results: int  # FMI 3.0 result folders checked here with validate_cross_check_result
    problems: list


# --------------------------------------------------------------- top level
@dataclass
class CompatOutcome:
    entries: list
    validation: Validation

    @property
    def passed(self) -> bool:
        return not self.validation.problems and all(entry.passed for entry in self.entries)


def compat(out: Path, editions=EDITIONS, models=None, jobs: int | None = None) -> CompatOutcome:
    """Write and check the compatibility information of ``models`` (default every FMU) of ``editions``."""
    out = Path(out)
    models = list(models or [row.model_identifier for row in fmu_catalog.FMUS])
    experiments = closed_loop_experiments(models, build_fmu.ensure_built(edition="python"))
    entries = entries_for(editions, models, experiments)
    for entry in entries:
        write_entry(entry, out)
    with ThreadPoolExecutor(max_workers=jobs or default_jobs()) as pool:  # each fmpy runs in its own process
        list(pool.map(lambda entry: run_fmpy(entry, out), entries))
    for entry in entries:
        judge(entry)
    validation = validate(out)
    summary = {"tool_version": tool_version(), "fmpy": importlib.metadata.version("fmpy"),
               "platform": platform_folder(),
               "entries": [{"entry": entry.label, "passed": entry.passed, "problem": entry.problem,
                            "max_relative_deviation": max(entry.agreement.values(), default=None)}
                           for entry in entries],
               "validation": dataclasses.asdict(validation)}
    atomic_files.write_text(out / "compat.json", json.dumps(summary, indent=2) + "\n")
    return CompatOutcome(entries, validation)


def compat_command(args) -> int:
    editions = EDITIONS if args.edition in (None, "all") else (args.edition,)
    if any(e != "python" for e in editions) and not build_native.compiler_available():
        raise cli_args.UsageError("the native edition needs zig's C compiler: pip install -e '.[native]' "
                                  "(or --edition python)")
    if args.ls_ref_experiments:
        stored = write_ls_ref_experiments(args.fmu)
        print(f"wrote the FMI-LS-REF experiments of {', '.join(e.model for e in stored)} to "
              f"{ls_ref.EXPERIMENTS.relative_to(ls_ref.ROOT)}/ (rebuild the FMUs to embed them)")
        return 0
    out = Path(args.out)
    cli_args.refuse_tracked([out])
    if out.exists() and any(out.iterdir()) and not (out / "compat.json").exists():
        raise cli_args.UsageError(f"--out {out} is a folder with other files; give an empty or new folder")
    if out.exists():
        for part in ("fmus", "results"):
            shutil.rmtree(out / part, ignore_errors=True)
    started = clock.perf_counter()
    outcome = compat(out, editions, args.fmu, args.jobs)
    for entry in outcome.entries:
        worst = max(entry.agreement, key=entry.agreement.get, default=None)
        agreement = (f"largest |fmpy - reference| {entry.agreement[worst]:.3g} of the range ({worst})"
                     if worst else "no comparison")
        print(f"{'passed' if entry.passed else 'FAILED'}  {entry.label}: {agreement}"
              + (f"; {entry.problem}" if entry.problem else ""))
    check = outcome.validation
    print(f"fmpy.cross_check.validate_vendor_repo: {check.fmus} FMUs, {check.results} results "
          f"({check.fmi3_fmus} FMI 3.0 FMUs and {check.fmi3_results} results through its functions), "
          f"{len(check.problems)} problems")
    for problem in check.problems:
        print(f"  {problem}")
    passed = sum(entry.passed for entry in outcome.entries)
    print(f"{passed}/{len(outcome.entries)} FMUs re-simulated by fmpy match their _ref.csv; wrote {out}/ "
          f"(fmus/, results/, compat.json) in {clock.perf_counter() - started:.0f} s")
    return 0 if outcome.passed else 1


def register(commands):
    parser = commands.add_parser(
        "compat", help="write the FMUs' compatibility information (FMI cross-check layout) and check it")
    parser.add_argument("--out", default="build/compat",
                        help="folder to write fmus/, results/ and compat.json into (default build/compat)")
    parser.add_argument("--fmu", nargs="+", choices=[row.model_identifier for row in fmu_catalog.FMUS],
                        help="only these FMUs (default: every FMU)")
    parser.add_argument("--jobs", type=cli_args.positive_int, help="fmpy processes at once (default: every core)")
    parser.add_argument("--ls-ref-experiments", action="store_true",
                        help="only store the FMUs' experiments where the builds embed them as FMI-LS-REF "
                             "(harness/fmu_build/native_stages/ls_ref_experiments/)")
    parser.set_defaults(handler=compat_command)
