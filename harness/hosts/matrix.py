"""The host matrix: ``python -m harness hosts`` runs the closed loops in every FMI host this machine has.

Each row is one scenario x controller x host x step, scored the same way for every host and
compared with our converged result over the same horizon.  One idea per module, each importing only
those above it (harness/hosts/):

===================  ===================================================================
``trajectory``       what every host yields, scored the same way for every host
``console_capture``  the warnings of a host that prints them (stdout and stderr captured)
``plain_fmpy``       the plain fmpy script: Jacobi or Gauss-Seidel, no initial-value propagation
``host_runners``     one function per host that runs the closed loop in it
``host_registry``    one ``Host`` row per host: its runner, what it needs, whether it can run here
``matrix_row``       one row: run, score, compare with our converged values; its verdict
``matrix_prose``     the prose of docs/hosts.md
``matrix_report``    docs/hosts.md from a matrix
``matrix``           the rows planned and run in parallel; the ``hosts`` command
===================  ===================================================================

Nothing the repository tracks is written unless asked: the matrix goes to
``results/hosts/`` (``--out``); ``--apply`` also writes docs/hosts.md.
"""
from __future__ import annotations

import json
import math
import shutil
import sys
import time as clock
from pathlib import Path

from harness.fmu_build import builder as build_fmu
from harness.fmu_build import native as build_native

from .. import atomic_files, cli_args, unpack, variants
from .. import scenario as scenarios
from ..cases import parallel_map
from ..studies.step_study import load_convergence, validated_step
from .host_registry import HOSTS_BY_KEY, host_available
from .matrix_report import matrix_markdown, percent
from .matrix_row import ACCURACY, METRICS, converged_values, host_row, within
from .ssp import export_ssp

ROOT = Path(__file__).resolve().parents[2]
HOSTS_MD = ROOT / "docs" / "hosts.md"
DEFAULT_OUT = Path("results") / "hosts"  # under the working directory, like tables and regress


def plan(names, controllers, host_keys, step_kinds, convergence) -> list:
    """(host, scenario, controller, step, step kind) of every row."""
    rows = []
    for name in names:
        scenario_step = scenarios.load(name).step
        for controller in controllers:
            for key in host_keys:
                host = HOSTS_BY_KEY[key]
                steps = {}
                if host.model_exchange:  # no communication step: the scenario's step is the output grid
                    rows.append((key, name, controller, scenario_step, "output grid"))
                    continue
                if "validated" in step_kinds:
                    validated = validated_step(convergence, name, controller, host.family)
                    if validated is None:
                        print(f"note: {name}/{controller}: no {host.family} validated step in the study; "
                              f"using the scenario's step", file=sys.stderr)
                        validated = scenario_step
                    steps[validated] = "validated"
                if "scenario" in step_kinds:
                    steps.setdefault(scenario_step, "scenario")
                for step, kind in steps.items():
                    rows.append((key, name, controller, step, kind))
    return rows


def hosts_matrix(names, controllers=(variants.PROPOSED,), host_keys=None, step_kinds=("validated", "scenario"),
                 stop=None, jobs: int | None = None, convergence: dict | None = None) -> dict:
    """The rows of the matrix; ``stop``: one horizon for every scenario, or {scenario: horizon} (None: 20 s)."""
    stops = stop if isinstance(stop, dict) else {name: stop for name in names}
    convergence = load_convergence() if convergence is None else convergence
    folder = unpack.unpack_folder("hosts")  # SSP packages and a private copy of the FMUs
    fmu_paths = {name: Path(shutil.copy(path, folder / path.name)) for name, path in build_fmu.ensure_built().items()}
    host_keys = list(host_keys or HOSTS_BY_KEY)
    native_paths = None
    if any(HOSTS_BY_KEY[k].edition == "native" for k in host_keys) and build_native.compiler_available():
        (folder / "native").mkdir()
        native_paths = {name: Path(shutil.copy(path, folder / "native" / path.name))
                        for name, path in build_fmu.ensure_built(edition="native").items()}
    skipped = {}
    for key in list(host_keys):
        reason = host_available(HOSTS_BY_KEY[key])
        if reason:
            skipped[key] = reason
            host_keys.remove(key)
    began = clock.perf_counter()
    planned = plan(names, controllers, host_keys, step_kinds, convergence)
    try:
        references = {}
        tasks = []
        for key, name, controller, step, kind in planned:
            package = None
            host = HOSTS_BY_KEY[key]
            full = stops.get(name) or scenarios.load(name).stop
            stop = None if host.horizon(full, step) == full else host.horizon(full, step)
            stop = stops.get(name) if stop is None else stop
            if (name, controller, stop) not in references:
                references[(name, controller, stop)] = converged_values(name, controller, stop, fmu_paths, convergence)
            paths = native_paths if host.edition == "native" else fmu_paths
            if host.needs_ssp:
                interface = f"me{host.ssp_rtol:g}" if host.ssp_rtol else "cs"
                package = folder / f"{name}_{controller}_{step:g}_{stop}_{interface}_{host.edition or 'selected'}.ssp"
                if not package.exists():
                    export_ssp(scenarios.configure(name, controller, step, stop), package,
                               fmu_paths=paths, rtol=host.ssp_rtol)
            tasks.append((key, name, controller, step, stop, references[(name, controller, stop)], paths,
                          package, kind))
        tasks.sort(key=lambda t: t[3])  # the finest steps (longest runs) first
        rows = parallel_map(host_row, tasks, jobs, description="host matrix", progress=None)
    finally:
        unpack.remove_folder(folder)
    order = {key: i for i, key in enumerate(HOSTS_BY_KEY)}
    rows.sort(key=lambda r: (names.index(r["scenario"]), r["controller"], order[r["host"]], r["step"]))
    return {"rows": rows, "skipped": skipped, "wall_s": clock.perf_counter() - began, "stops": stops,
            "accuracy": ACCURACY}


def hosts_command(args) -> int:
    cli_args.refuse_tracked([Path(args.out) / "hosts.json", Path(args.out) / "hosts.md"])
    names = args.scenarios or ["pendulum_case1", "manipulator"]
    for name in names:
        scenarios.load(name)
    keys = args.host or list(HOSTS_BY_KEY)
    for key in keys:
        if key not in HOSTS_BY_KEY:
            print(f"error: unknown host {key!r}; valid: {', '.join(HOSTS_BY_KEY)}", file=sys.stderr)
            return 2
    stops = {}
    for item in args.stop or []:
        name, _, value = item.rpartition("=")
        try:
            seconds = float(value)
        except ValueError:
            seconds = math.nan
        if not (math.isfinite(seconds) and seconds > 0) or (name and name not in names):
            print(f"error: --stop {item!r}: give seconds > 0, or SCENARIO=seconds with SCENARIO one of "
                  f"{', '.join(names)}", file=sys.stderr)
            return 2
        for target in ([name] if name else names):
            stops[target] = seconds
    if args.from_json:  # rewrite the outputs (and --apply them) from a matrix already run
        matrix = json.loads(Path(args.from_json).read_text())
    else:
        matrix = hosts_matrix(names, tuple(args.controller), keys, tuple(args.steps),
                              {name: stops.get(name) for name in names}, args.jobs)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_files.write_text(out / "hosts.json", json.dumps(matrix, indent=1))
    text = matrix_markdown(matrix)
    atomic_files.write_text(out / "hosts.md", text)
    written = [out / "hosts.json", out / "hosts.md"]
    if args.apply:
        atomic_files.write_text(HOSTS_MD, text)
        written.append(HOSTS_MD)
    for row in matrix["rows"]:
        error = row.get("error")
        summary = " / ".join(percent(error[m]) for m in METRICS) if error else row.get("reason", row["status"])
        print(f"{row['scenario']:15s} {row['controller']:5s} {row['host']:38s} {row['step']:<8g} {summary}"
              f"{'  ok' if within(row) else ''}  warnings: {len(row['warnings'])}  [{row['wall_s']:.0f} s]")
    for key, reason in matrix["skipped"].items():
        print(f"skipped {key}: {reason}")
    print(f"host matrix: {len(matrix['rows'])} rows in {matrix['wall_s']:.1f} s wall")
    print("written: " + ", ".join(str(p) for p in written))
    return 0


def register(commands):
    command = commands.add_parser("hosts", help="run the closed loops in every FMI host installed here and compare "
                                                "with our converged result")
    command.add_argument("scenarios", nargs="*", type=cli_args.scenario, help="default: pendulum_case1 manipulator")
    command.add_argument("--controller", nargs="+", choices=variants.NAMES, default=[variants.PROPOSED])
    command.add_argument("--host", nargs="+", help=f"hosts to run (default all): {', '.join(HOSTS_BY_KEY)}")
    command.add_argument("--steps", nargs="+", choices=("validated", "scenario"), default=["validated", "scenario"],
                         help="which steps: the host scheme's validated step, the scenario's step (default both)")
    command.add_argument("--stop", nargs="+", metavar="[SCENARIO=]SECONDS",
                         help="shorter horizon, for every scenario or one (compared with our converged result over "
                              "the same horizon); default the scenarios' 20 s")
    command.add_argument("--jobs", type=cli_args.positive_int, help="parallel processes (default: every core)")
    command.add_argument("--out", default=str(DEFAULT_OUT),
                         help=f"output folder (default {DEFAULT_OUT}/ under the working directory)")
    command.add_argument("--from-json", type=cli_args.existing_file,
                         help="do not run: rewrite the outputs from this matrix's hosts.json")
    command.add_argument("--apply", action="store_true", help="also write docs/hosts.md (a tracked file)")
    command.set_defaults(handler=hosts_command)
