"""Run an exported SSP package (harness/hosts/ssp.py) unchanged in FMI engines that are not ours.

* :func:`run_fmpy_ssp`: fmpy's SSP simulator, ``fmpy.ssp.simulation.simulate_ssp``
  (fmpy 0.3.x).
* :func:`run_ecos`: the Ecos co-simulation engine through ``ecospy``.
* :func:`run_master`: our own master on the same scenario, for comparison.

Every adapter returns an :class:`EngineResult` whose ``time`` is the time
the values belong to (see the conventions below) and whose columns are named
``instance.variable`` like our master's.

Conventions found (each shown in tests/test_engines.py)
-------------------------------------------------------
fmpy's SSP simulator (``simulate_ssp``)
  * applies no parameter binding of the package by itself: it takes one
    ``parameter_set`` argument with names ``instance.variable``.  The adapter
    reads the package's component ParameterBindings (``read_ssd`` parses the
    .ssv files) and passes them, so the package runs unchanged.
  * starts every connector at 0 and never propagates values before
    ``fmi2ExitInitializationMode``: a controller whose start inputs are not
    set sees e = de = 0 at initialisation and re-latches e(0), de(0) from the
    first inputs that agree with their derivatives, two steps late, with a
    warning (docs/host_robustness.md).  ``export-ssp`` therefore writes
    consistent start values of the connected inputs (``--start-inputs``,
    default).  Even then the connectors are 0 during the first two steps (the
    reference sees y = 0 at the first step); the controller then goes back
    to the start values and restarts its adaptation, so no trace is left.
  * each step sets inputs, calls doStep and reads outputs component by
    component, then copies along the connections: every connection is
    delayed by one step (Jacobi, like our ``--algorithm jacobi``).
  * row k is stamped with the time *before* step k but holds the outputs
    *after* it (at t_k + h); there is no row with the start values, and the
    loop ``while time < stop`` on an accumulated float time makes one step
    too many (2 s at 1e-4: 20001 rows, last values at 2.0001 s).  The adapter
    stamps rows with t_k + h (``raw_time`` keeps fmpy's stamps) and drops
    rows past the stop time.
Ecos (ecospy 0.7)
  * needs ``libtbb.so.12`` loaded before ``import ecospy``: :func:`load_tbb`
    loads it from the ``tbb`` wheel's files with ``RTLD_GLOBAL``.
  * applies a package's parameter sets only when ``init`` is given their
    name: ``sim.init(parameter_set="initialValues")``; without it every
    parameter keeps its FMU default (variant 1, ...) silently.
  * propagates values along the connections during initialisation (a fixed
    number of set/get/transfer sweeps), so the controller latches the true
    e(0), de(0) without any start value.
  * steps every instance, then transfers along the connections (one step
    delay per connection, as our jacobi), then sets inputs and reads outputs
    once more: a recorded feedthrough output (reference.e) is therefore
    consistent with the recorded inputs at the same time, while our jacobi
    records the e that the controller was given (computed from y one step
    earlier).  The closed-loop trajectories agree.
  * variable identifiers are ``instance::variable``; its CSV writer prints
    6 decimals, so the adapter reads values with ``get_real`` instead.
  * time is accumulated (t + h per step); the adapter stamps rows with
    start + k h.
"""
from __future__ import annotations

import ctypes
import functools
import importlib.metadata
import sys
import tempfile
import time as clock
import xml.etree.ElementTree as ElementTree
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from fmpy.ssp.simulation import simulate_ssp
from fmpy.ssp.ssd import Parameter, ParameterSet, find_components, read_ssd

from harness.fmu_build import builder as build_fmu

from .. import cli_args, variants
from .. import scenario as scenarios
from .. import atomic_files, unpack
from ..cases import parallel_map
from ..master import simulate
from ..scores import control_energy, iae, itae, score
from ..studies.regression import compare_signal
from .ssp import export_ssp

AFC_NS = "https://afc-fmi.invalid/ssp/experiment"
SSD_NS = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC_NS = "http://ssp-standard.org/SSP1/SystemStructureCommon"


class EngineUnavailable(RuntimeError):
    """A third-party engine cannot be loaded (with the reason and the fix)."""


@dataclass
class EngineResult:
    engine: str
    time: np.ndarray  # the time the values of each row belong to
    columns: list
    values: np.ndarray  # rows x columns
    wall_s: float
    raw_time: np.ndarray | None = None  # the engine's own time stamps, where they differ
    notes: list = field(default_factory=list)

    def signal(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.columns.index(name)]
        except ValueError:
            raise KeyError(f"{name!r} not in the {self.engine} result; columns: {', '.join(self.columns)}") from None

    def write_csv(self, path) -> Path:
        path = Path(path)
        header = ",".join(f'"{name}"' for name in ["time", *self.columns])
        with atomic_files.replacing(path, "w", newline="") as stream:
            np.savetxt(stream, np.column_stack([self.time, self.values]), delimiter=",", header=header, comments="",
                       fmt="%.17g")
        return path


@dataclass
class Package:
    """What the adapters need to know of an SSP package."""

    path: Path
    components: dict  # instance -> {"source": ..., "connectors": [(name, kind)], "parameters": {name: (type, text)}}
    connections: list  # (source "i.v", target "i.v")
    start: float
    stop: float | None
    step: float | None
    parameter_set: str | None

    @property
    def outputs(self) -> list:
        return [f"{i}.{n}" for i, c in self.components.items() for n, kind in c["connectors"] if kind == "output"]

    @property
    def inputs(self) -> list:
        return [f"{i}.{n}" for i, c in self.components.items() for n, kind in c["connectors"] if kind == "input"]


class PackageError(cli_args.UsageError):
    """An SSP package that cannot be read: the message names the file, the entry and what is wrong."""


def _xml(package: zipfile.ZipFile, path: Path, entry: str):
    """The root element of the XML file ``entry`` of the package, or a PackageError naming both."""
    try:
        text = package.read(entry)
    except KeyError:
        raise PackageError(f"{path}: the package has no {entry}") from None
    try:
        return ElementTree.fromstring(text)
    except ElementTree.ParseError as error:
        raise PackageError(f"{path}: {entry} is not well-formed XML: {error}") from None


def read_package(path) -> Package:
    """Read SystemStructure.ssd and the .ssv files it binds (stdlib XML: no engine involved); the archive and
    the FMUs in it are checked first (sizes, links, paths: harness/unpack.py)."""
    path = Path(path)
    ns = {"ssd": SSD_NS, "ssc": SSC_NS, "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}
    unpack.check_archive(path, nested=(".fmu",))
    with zipfile.ZipFile(path) as package:
        root = _xml(package, path, "SystemStructure.ssd")
        system = root.find("ssd:System", ns)
        if system is None:
            found = root.tag.split("}")[-1]
            raise PackageError(f"{path}: SystemStructure.ssd has no <System> in the SSP 1.0 namespace {SSD_NS} "
                               f"(its root is <{found}>); an SSP package describes one system")
        components, parameter_set = {}, None
        for element in system.findall("ssd:Elements/ssd:Component", ns):
            connectors = [(c.get("name"), c.get("kind")) for c in element.findall("ssd:Connectors/ssd:Connector", ns)]
            parameters = {}
            for binding in element.findall("ssd:ParameterBindings/ssd:ParameterBinding", ns):
                if binding.get("source"):
                    parameter_root = _xml(package, path, binding.get("source"))
                else:
                    parameter_root = binding.find("ssd:ParameterValues/ssv:ParameterSet", ns)
                if parameter_root is None:
                    raise PackageError(f"{path}: component {element.get('name')!r} has a ParameterBinding with "
                                       "neither a source nor a ParameterSet")
                parameter_set = parameter_root.get("name")
                for parameter in parameter_root.findall("ssv:Parameters/ssv:Parameter", ns):
                    value = list(parameter)[0]
                    parameters[parameter.get("name")] = (value.tag.split("}")[1], value.get("value"))
            source = element.get("source")
            if not source or source not in package.namelist():
                raise PackageError(f"{path}: component {element.get('name')!r} names the source {source!r}, which "
                                   "the package does not hold")
            components[element.get("name")] = {"source": source, "connectors": connectors, "parameters": parameters}
        if not components:
            raise PackageError(f"{path}: SystemStructure.ssd's system has no component")
        connections = [(f"{c.get('startElement')}.{c.get('startConnector')}",
                        f"{c.get('endElement')}.{c.get('endConnector')}")
                       for c in system.findall("ssd:Connections/ssd:Connection", ns)]
        experiment = root.find("ssd:DefaultExperiment", ns)
        start, stop, step = 0.0, None, None
        try:
            if experiment is not None:
                start = float(experiment.get("startTime", 0.0))
                stop = float(experiment.get("stopTime")) if experiment.get("stopTime") else None
                ours = experiment.find(f"ssd:Annotations/ssc:Annotation/{{{AFC_NS}}}Experiment", ns)
                if ours is not None and ours.get("stepSize"):
                    step = float(ours.get("stepSize"))
        except ValueError as error:
            raise PackageError(f"{path}: SystemStructure.ssd's DefaultExperiment: {error}") from None
    return Package(path, components, connections, start, stop, step, parameter_set)


def _experiment(package: Package, stop, step) -> tuple[float, float, float, int]:
    stop = package.stop if stop is None else float(stop)
    step = package.step if step is None else float(step)
    if stop is None or step is None:
        raise cli_args.UsageError(f"{package.path.name}: give --stop and --step (the package has no default for them)")
    steps = round((stop - package.start) / step)
    if steps < 1:
        raise cli_args.UsageError(f"stop - start = {stop - package.start} is shorter than one step {step}")
    return package.start, stop, step, steps


# --------------------------------------------------------------------- fmpy
def run_fmpy_ssp(ssp_path, stop: float | None = None, step: float | None = None,
                 apply_package_parameters: bool = True) -> EngineResult:
    """Run the package in fmpy's SSP simulator; rows restamped to the time their values belong to."""
    package = read_package(ssp_path)
    start, stop, step, steps = _experiment(package, stop, step)
    parameter_set = None
    if apply_package_parameters:
        # simulate_ssp ignores the ParameterBindings it parses: hand them over, named instance.variable
        parameter_set = ParameterSet(name=package.parameter_set or "package")
        for component in find_components(read_ssd(str(ssp_path)).system):
            for binding in component.parameterBindings:
                for values in binding.parameterValues:
                    for p in values.parameters:
                        parameter_set.parameters.append(Parameter(name=f"{component.name}.{p.name}", type=p.type,
                                                                  value=p.value))
    wall = clock.perf_counter()
    # fmpy unpacks the package and each FMU into folders of its own and removes none of them when a run fails
    with unpack.private_temporary_folder("fmpy-ssp"):
        table = simulate_ssp(str(ssp_path), start_time=start, stop_time=stop, step_size=step,
                             parameter_set=parameter_set)
    wall = clock.perf_counter() - wall
    columns = [name for name in table.dtype.names[1:] if name in package.outputs]
    raw_time = np.asarray(table["time"], dtype=float)
    values = np.column_stack([np.asarray(table[name], dtype=float) for name in columns])
    rows = np.arange(len(raw_time))
    time = start + (rows + 1) * step  # row k holds the outputs after step k
    keep = time <= stop + 0.5 * step
    notes = []
    if len(raw_time) != steps:
        notes.append(f"fmpy made {len(raw_time)} steps for {steps} (float time accumulation); "
                     f"{int((~keep).sum())} row(s) past stop dropped")
    notes.append("no row at the start time: connectors start at 0")
    return EngineResult("fmpy", time[keep], columns, values[keep], wall, raw_time=raw_time[keep], notes=notes)


# --------------------------------------------------------------------- Ecos
_TBB = None


def load_tbb():
    """Load libtbb.so.12 from the installed ``tbb`` wheel with RTLD_GLOBAL (before ``import ecospy``)."""
    global _TBB
    if _TBB is not None:
        return _TBB
    try:
        files = importlib.metadata.distribution("tbb").files or []
    except importlib.metadata.PackageNotFoundError:
        raise EngineUnavailable("Ecos needs the PyPI package 'tbb' (libtbb.so.12), in the hosts extra: "
                                "pip install -e '.[hosts]'") from None
    candidates = [f for f in files if Path(str(f)).name in ("libtbb.so.12", "tbb12.dll", "libtbb.12.dylib")]
    if not candidates:
        raise EngineUnavailable("the installed 'tbb' package holds no libtbb.so.12")
    path = Path(candidates[0].locate()).resolve()
    mode = getattr(ctypes, "RTLD_GLOBAL", 0)
    _TBB = ctypes.CDLL(str(path), mode=mode)
    return _TBB


def import_ecospy():
    load_tbb()
    try:
        import ecospy  # here, not at module level: it loads only after load_tbb()
    except ImportError as error:
        raise EngineUnavailable(f"Ecos needs ecospy, in the hosts extra: pip install -e '.[hosts]' ({error})") from error
    return ecospy


def ecos_temp_dir():
    """A private temporary folder for one Ecos run, removed afterwards with all it holds.

    Ecos unpacks the SSP and every FMU into ``ecos_*`` folders of the temporary
    directory (``TMPDIR``) and leaves them there (about 20 MB a run).  TMPDIR points
    at a folder of our own while the simulation lives; then it is restored and the
    folder removed, so nothing is left and no other process's folders are touched.
    """
    return unpack.private_temporary_folder("ecos")


def run_ecos(ssp_path, stop: float | None = None, step: float | None = None, variables=None,
             parameter_set: str | None = "package", log_level: str = "warn") -> EngineResult:
    """Run the package in Ecos; values read with get_real after init and after every step.

    ``parameter_set="package"`` applies the package's own parameter set
    (``initialValues``); ``None`` applies none, as ``sim.init()`` does.
    """
    package = read_package(ssp_path)  # the package checked before Ecos is loaded
    ecospy = import_ecospy()
    start, stop, step, steps = _experiment(package, stop, step)
    columns = list(variables or package.outputs + package.inputs)
    identifiers = [name.replace(".", "::", 1) for name in columns]
    if parameter_set == "package":
        parameter_set = package.parameter_set
    ecospy.EcosLib.set_log_level(log_level)
    values = np.empty((steps + 1, len(columns)))
    raw_time = np.empty(steps + 1)
    wall = clock.perf_counter()
    with ecos_temp_dir():
        simulation = ecospy.EcosSimulation(ssp_path=str(ssp_path), step_size=step)
        try:
            if parameter_set is None:
                simulation.init(start_time=start)
            else:
                simulation.init(start_time=start, parameter_set=parameter_set)
            get_real = simulation.get_real
            for k in range(steps + 1):
                if k:
                    raw_time[k] = simulation.step(1)
                else:
                    raw_time[k] = simulation.get_time()
                values[k] = [get_real(identifier) for identifier in identifiers]
            simulation.terminate()
        finally:
            simulation.free()
    wall = clock.perf_counter() - wall
    time = start + np.arange(steps + 1) * step
    return EngineResult("ecos", time, columns, values, wall, raw_time=raw_time,
                        notes=[f"parameter set: {parameter_set!r}"])


# ------------------------------------------------------------------ ours
def run_master(scenario, algorithm: str = "feedthrough", fmu_paths=None) -> EngineResult:
    result = simulate(scenario, algorithm=algorithm, fmu_paths=fmu_paths)
    return EngineResult("master" if algorithm == "feedthrough" else algorithm, result.time, list(result.columns),
                        result.values, result.wall_s)


def run_package(engine: str, ssp_path, stop=None, step=None) -> EngineResult:
    if engine == "fmpy":
        return run_fmpy_ssp(ssp_path, stop, step)
    if engine == "ecos":
        return run_ecos(ssp_path, stop, step)
    raise ValueError(f"unknown engine {engine!r}; valid: fmpy, ecos")


# ------------------------------------------------------- side by side
#: where each engine's row k holds the control u applied over [t_k, t_k + h]: our master records the u it
#: hands to the plant, fmpy's output connector is what the plant gets next, while Ecos re-reads
#: controller.u after setting the controller's next inputs, so the applied u is the plant's input there.
APPLIED_U = {"master": "controller.u", "jacobi": "controller.u", "fmpy": "controller.u", "ecos": "plant.u"}
COMPARED = ("plant.y", "plant.dy", "controller.u", "controller.theta1", "controller.theta2", "controller.theta3",
            "controller.theta4", "reference.e", "reference.de")


def applied(result: EngineResult, name: str) -> np.ndarray:
    """A signal, with controller.u read where the engine keeps the u that was applied."""
    if name == "controller.u":
        return result.signal(APPLIED_U.get(result.engine, "controller.u"))
    return result.signal(name)


def engine_scores(result: EngineResult) -> dict:
    """ITAE, IAE from the true error e = ym - y (the plant's and reference's outputs), Ec from the applied u."""
    e = result.signal("reference.ym") - result.signal("plant.y")
    de = result.signal("reference.dym") - result.signal("plant.dy")
    u = applied(result, "controller.u")
    return {"ITAE": itae(result.time, e, de), "IAE": iae(result.time, e, de), "Ec": control_energy(result.time, u)}


def compare_results(reference: EngineResult, test: EngineResult, signals=COMPARED, tolerances=None,
                    from_time: float | None = None, every: int = 1) -> dict:
    """Tube comparison (pyfunnel, regression tolerances) on the common time range, from ``from_time`` on.

    ``every`` > 1 thins both series (every n-th row) to keep pyfunnel fast on long runs.
    """
    first = max(reference.time[0], test.time[0], -np.inf if from_time is None else from_time)
    last = min(reference.time[-1], test.time[-1])
    eps = 1e-9 * max(1.0, abs(last))
    keep_ref = (reference.time >= first - eps) & (reference.time <= last + eps)
    keep_test = (test.time >= first - eps) & (test.time <= last + eps)
    rows_ref, rows_test = np.flatnonzero(keep_ref), np.flatnonzero(keep_test)
    rows_ref = np.union1d(rows_ref[::every], rows_ref[-1:])
    rows_test = np.union1d(rows_test[::every], rows_test[-1:])
    x_ref, x_test = reference.time[rows_ref], test.time[rows_test].copy()
    x_test[0], x_test[-1] = x_ref[0], x_ref[-1]  # pyfunnel wants identical end points
    return {name: compare_signal(name, x_ref, applied(reference, name)[rows_ref], x_test,
                                 applied(test, name)[rows_test], tolerances) for name in signals}


def max_deviation(reference: EngineResult, test: EngineResult, name: str, from_time: float = 0.0) -> float:
    keep = test.time >= from_time - 1e-12
    values = np.interp(test.time[keep], reference.time, applied(reference, name))
    return float(np.max(np.abs(applied(test, name)[keep] - values)))


def run_all(scenario, directory, workers: int | None = None, fmu_paths=None) -> dict:
    """Export ``scenario`` and run it in our master (feedthrough, jacobi), Ecos and fmpy's SSP simulator."""
    if fmu_paths is None:
        fmu_paths = build_fmu.ensure_built()
    package = export_ssp(scenario, Path(directory) / f"{scenario.name}.ssp", fmu_paths=fmu_paths)
    # spawned workers: Ecos's thread pool and the loaded FMUs stay out of the parent
    jobs = {"master": functools.partial(run_master, scenario, "feedthrough", fmu_paths),
            "jacobi": functools.partial(run_master, scenario, "jacobi", fmu_paths),
            "ecos": functools.partial(run_ecos, package), "fmpy": functools.partial(run_fmpy_ssp, package)}
    results = parallel_map(_call, list(jobs.values()), workers)
    return dict(zip(jobs, results))


def _call(function):
    return function()


SIDE_BY_SIDE_HEADER = ["engine", "rows", "first t [s]", "wall [s]", "ITAE", "IAE", "Ec", "max |dy|", "max |du|",
                       "max |dtheta|", "signals in tube"]


def side_by_side(results: dict, reference: str = "jacobi", from_time: float | None = None,
                 every: int | None = None) -> list:
    """One row per engine: scores, largest deviations from ``reference`` and the tube verdict.

    The tube is checked on at most about 20001 rows per run (``every``: every n-th row).
    """
    rows = []
    base = results[reference]
    every = every or max(1, -(-len(base.time) // 20001))
    for name, result in results.items():
        scores = engine_scores(result)
        start = max(result.time[0], base.time[0]) if from_time is None else from_time
        tube = compare_results(base, result, from_time=from_time, every=every)
        theta = max(max_deviation(base, result, f"controller.theta{k}", start) for k in range(1, 5))
        rows.append([name, len(result.time), f"{result.time[0]:.3g}", f"{result.wall_s:.1f}",
                     f"{scores['ITAE']:.6f}", f"{scores['IAE']:.6f}", f"{scores['Ec']:.4f}",
                     f"{max_deviation(base, result, 'plant.y', start):.2e}",
                     f"{max_deviation(base, result, 'controller.u', start):.2e}", f"{theta:.2e}",
                     f"{sum(c.passed for c in tube.values())}/{len(tube)}"])
    return rows


# ------------------------------------------------------------------ CLI
def compare_command(args) -> int:
    scenario = scenarios.configure(args.scenario, args.controller, args.step, args.stop)
    for note in scenario.notes:
        print(f"note: {note}", file=sys.stderr)
    with tempfile.TemporaryDirectory(prefix="afc_engines_") as directory:
        results = run_all(scenario, directory, workers=args.workers)
    start = scenario.start + args.skip_steps * scenario.step if args.skip_steps else None
    print(f"{scenario.name} / {args.controller}, 0 - {scenario.stop:g} s, step {scenario.step:g} s; deviations "
          f"and tube against our jacobi run" + (f", from t = {start:g} s" if start else ""))
    lines = ["| " + " | ".join(SIDE_BY_SIDE_HEADER) + " |", "|" + "---|" * len(SIDE_BY_SIDE_HEADER)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in side_by_side(results, from_time=start)]
    print("\n".join(lines))
    for name, result in results.items():
        for note in result.notes:
            print(f"  {name}: {note}")
    return 0


def run_ssp_command(args) -> int:
    result = run_package(args.engine, args.ssp, stop=args.stop, step=args.step)
    if args.out:
        result.write_csv(args.out)
    print(f"{Path(args.ssp).name} in {args.engine}: {len(result.time)} rows, t = {result.time[0]:g} .. "
          f"{result.time[-1]:g} s, {result.wall_s:.2f} s wall")
    for note in result.notes:
        print(f"  note: {note}")
    needed = ("plant.y", "plant.dy", "reference.ym", "reference.dym", "controller.u")
    if all(name in result.columns for name in needed):
        # the true error from the plant's outputs, the same way for every engine
        e = result.signal("reference.ym") - result.signal("plant.y")
        de = result.signal("reference.dym") - result.signal("plant.dy")
        scores = score(result.time, e, de, result.signal("reference.ym"), result.signal("reference.dym"),
                       result.signal("controller.u"))
        for key in ("ITAE", "IAE", "Ec", "umax"):
            print(f"  {key:8s} {scores[key]:.6g}")
    if args.out:
        print(f"  result   {args.out}")
    return 0


def register(commands):
    run = commands.add_parser("run-ssp", help="run an exported SSP package in fmpy's SSP simulator or in Ecos")
    run.add_argument("ssp", type=cli_args.ssp_file, help="the .ssp file (python -m harness export-ssp ...)")
    run.add_argument("--engine", choices=("ecos", "fmpy"), default="ecos")
    run.add_argument("--stop", type=cli_args.positive_float, help="stop time (default: the package's DefaultExperiment)")
    run.add_argument("--step", type=cli_args.positive_float, help="communication step (default: the package's)")
    run.add_argument("--out", help="write the result CSV here (time = the time the values belong to)")
    run.set_defaults(handler=run_ssp_command)
    compare = commands.add_parser("compare-engines", help="export a scenario and run it in our master (feedthrough, "
                                                          "jacobi), Ecos and fmpy's SSP simulator, side by side")
    compare.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    compare.add_argument("--controller", choices=variants.NAMES, default=variants.PROPOSED)
    compare.add_argument("--stop", type=cli_args.positive_float, default=2.0, help="stop time (default 2 s)")
    compare.add_argument("--step", type=cli_args.positive_float, help="communication step (default: the scenario's)")
    compare.add_argument("--skip-steps", type=cli_args.non_negative_int, default=0,
                         help="compare from t = start + N steps (fmpy's start transient lasts 2 steps)")
    compare.add_argument("--workers", type=cli_args.positive_int, help="processes (default: every core)")
    compare.set_defaults(handler=compare_command)
