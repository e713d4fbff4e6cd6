"""Parameter sweeps: ``python -m harness sweep SCENARIO --grid NAME=START:STOP:N ...`` (issue 9).

The cartesian product of the grids (any parameter of any instance, or the
communication ``step`` / the ``stop`` time) times the chosen controllers,
one co-simulation per point, on a local process pool (default: every core)
or on an existing ``dask.distributed`` scheduler (``--scheduler ADDRESS``).

Rows stream to ``DIR/sweep.csv`` as points finish: the controller, the grid
values, every score of SPEC section 7, the wall time of the point, its status
(``ok``, ``diverged``, ``failed``) and the reason.  Run the same command again
after an interruption: points already in the CSV (same controller and grid
values) are skipped.  ``DIR/sweep.json`` holds the settings of the sweep
(scenario, horizon, step, fixed parameters) so a resume with different
settings is refused rather than mixed in.  At the end ``DIR/heatmap_METRIC.png``
shows the metric over the first two grid axes, one panel per controller.

Grid values must be bit-identical wherever the point runs: the parent computes
them, hands them over as Python floats and writes them with ``repr``; workers
run the same FMU files (a Dask worker receives their bytes from the client and
caches them by content hash), so a point gives the same scores on any host.
"""
from __future__ import annotations

import csv
import hashlib
import io
import itertools
import json
import math
import os
import signal
import sys
import tempfile
import time as clock
from dataclasses import dataclass, field
from pathlib import Path

from . import scenario as scenarios
from .scenario import CONTROLLER_VARIANTS, Scenario, ScenarioError
from .scores import SCORE_KEYS

CSV_NAME = "sweep.csv"
SETTINGS_NAME = "sweep.json"
STATUSES = ("ok", "diverged", "failed")
TRAILING_COLUMNS = (*SCORE_KEYS, "wall_s", "status", "reason")
SCENARIO_SETTINGS = ("step", "stop")  # sweepable scenario settings besides instance parameters
KEY_DIGITS = 12  # grid values match on resume when equal to 12 significant digits
SCHEDULER_TIMEOUT = "20s"  # how long to try reaching a Dask scheduler
DOCS_DIR = Path(__file__).resolve().parents[1] / "docs"  # where --apply copies a sweep's CSV and heat map


# ------------------------------------------------------------------ grids
@dataclass(frozen=True)
class Grid:
    name: str  # "instance.parameter", "step" or "stop"
    values: tuple

    def __len__(self):
        return len(self.values)


def parse_grid(text: str) -> Grid:
    """``NAME=START:STOP:N`` (linspace), ``NAME=START:STOP:N:log`` (geomspace) or ``NAME=V1,V2,...``."""
    import numpy as np

    name, equals, spec = text.partition("=")
    name, spec = name.strip(), spec.strip()
    usage = (f"--grid {text!r}: write NAME=START:STOP:N (N evenly spaced values), NAME=START:STOP:N:log "
             "(geometric) or NAME=V1,V2,... with NAME instance.parameter, step or stop")
    if not equals or not name or not spec:
        raise ScenarioError(usage)
    try:
        if ":" in spec:
            fields = spec.split(":")
            if len(fields) not in (3, 4) or (len(fields) == 4 and fields[3] != "log"):
                raise ValueError
            start, stop, count = float(fields[0]), float(fields[1]), int(fields[2])
            if count < 1:
                raise ValueError
            if len(fields) == 4:
                if start <= 0 or stop <= 0:
                    raise ScenarioError(f"--grid {text!r}: a log grid needs START > 0 and STOP > 0")
                values = np.geomspace(start, stop, count)
            else:
                values = np.linspace(start, stop, count)
        else:
            values = [float(v) for v in spec.split(",") if v.strip()]
    except ValueError:
        raise ScenarioError(usage) from None
    values = tuple(dict.fromkeys(float(v) for v in values))  # unique, in order
    if not values or not all(math.isfinite(v) for v in values):
        raise ScenarioError(f"--grid {text!r}: need at least one finite value")
    return Grid(name, values)


def value_key(value: float) -> float:
    """Grid values compare equal on resume when they agree to KEY_DIGITS significant digits."""
    return float(f"{float(value):.{KEY_DIGITS}g}")


def point_key(controller: str, values) -> tuple:
    return (controller, *(value_key(v) for v in values))


# ---------------------------------------------------------------- settings
@dataclass
class SweepPlan:
    scenario: Scenario  # with --stop/--step applied, before the grid values
    controllers: tuple
    grids: tuple
    metric: str
    algorithm: str = "feedthrough"
    fmu_files: dict = field(default_factory=dict)  # instance -> absolute Path of its FMU

    @property
    def names(self) -> list:
        return [g.name for g in self.grids]

    def points(self) -> list:
        """(controller, values) for every point: grid-major, controllers innermost."""
        return [(controller, values) for values in itertools.product(*(g.values for g in self.grids))
                for controller in self.controllers]

    def settings(self) -> dict:
        scenario = self.scenario
        parameters = {name: {k: v for k, v in spec.parameters.items()
                             if not (name == scenario.controller_instance and k == "variant")}
                      for name, spec in scenario.components.items()}
        settings = {"scenario": scenario.name, "start": scenario.start, "stop": scenario.stop, "step": scenario.step,
                    "algorithm": self.algorithm, "grid": self.names, "parameters": parameters}
        for name in SCENARIO_SETTINGS:
            if name in self.names:  # a grid axis: the scenario's own value plays no part
                del settings[name]
        return settings


def _scenario_point(scenario: Scenario, controller: str, names, values) -> Scenario:
    point = scenario.with_controller(controller)
    for name, value in zip(names, values):
        point = point.with_parameter(name, value)
    return point


def plan_sweep(scenario_name, controllers, grids, metric="ITAE", stop=None, step=None,
               algorithm="feedthrough", fmu_paths=None) -> SweepPlan:
    """Validate everything against the scenario and the FMUs before any point runs."""
    from .master import ALGORITHMS, Master, resolve_fmu

    scenario = scenarios.configure(scenario_name, step=step, stop=stop)
    controllers = tuple(dict.fromkeys(controllers))
    for controller in controllers:
        if controller not in CONTROLLER_VARIANTS:
            raise ScenarioError(f"unknown controller {controller!r}; valid: {', '.join(CONTROLLER_VARIANTS)}, all")
    if metric not in SCORE_KEYS:
        raise ScenarioError(f"unknown metric {metric!r}; valid: {', '.join(SCORE_KEYS)}")
    if algorithm not in ALGORITHMS:
        raise ScenarioError(f"unknown algorithm {algorithm!r}; valid: {', '.join(ALGORITHMS)}")
    if not grids:
        raise ScenarioError("give at least one --grid NAME=START:STOP:N")
    names = [g.name for g in grids]
    if len(set(names)) != len(names):
        raise ScenarioError(f"a parameter appears in two --grid options: {', '.join(names)}")
    overridden = {"stop": stop, "step": step}
    for grid in grids:
        if grid.name in overridden and overridden[grid.name] is not None:
            raise ScenarioError(f"--grid {grid.name} and --{grid.name} both set the {grid.name}: drop one")
        if grid.name == f"{scenario.controller_instance}.variant":
            raise ScenarioError(f"{grid.name} is chosen with --controller (vud, fixed, fae, all), not --grid")
        if "." not in grid.name and grid.name not in SCENARIO_SETTINGS:
            raise ScenarioError(f"unknown grid name {grid.name!r}: write instance.parameter with instance one of "
                                f"{', '.join(scenario.components)}, or one of {', '.join(SCENARIO_SETTINGS)}")
        if grid.name in SCENARIO_SETTINGS and min(grid.values) <= 0:
            raise ScenarioError(f"--grid {grid.name}: values must be > 0")
    # the master validates every name against the model descriptions on construction
    first = _scenario_point(scenario, controllers[0], names, [g.values[0] for g in grids])
    try:
        master = Master(first, algorithm, fmu_paths)
    except ScenarioError as error:
        raise ScenarioError(f"--grid {', '.join(names)}: {error}") from None
    for grid in grids:
        instance, _, parameter = grid.name.partition(".")
        if not parameter:  # step or stop: every value must leave at least one step
            for value in grid.values:
                _ = _scenario_point(scenario, controllers[0], [grid.name], [value]).steps
            continue
        kind = master.infos[instance].variables[parameter].type
        if kind in ("Integer", "Boolean", "Enumeration") and any(v != int(v) for v in grid.values):
            raise ScenarioError(f"--grid {grid.name}: {instance}.{parameter} is an {kind}; "
                                f"give whole numbers (got {', '.join(map(repr, grid.values))})")
    fmu_files = {name: resolve_fmu(spec.fmu, scenario, fmu_paths).resolve()
                 for name, spec in scenario.components.items()}
    return SweepPlan(scenario, controllers, tuple(grids), metric, algorithm, fmu_files)


# --------------------------------------------------------------- one point
def _one_line(text: str, limit: int = 600) -> str:
    line = " | ".join(part.strip() for part in str(text).splitlines() if part.strip())
    return line if len(line) <= limit else line[:limit - 3] + "..."


def _status_of(error) -> str:
    from .fmi import FmiError
    from .master import Divergence

    cause = getattr(error, "cause", error)
    if isinstance(cause, Divergence):
        return "diverged"
    # the plant FMUs stop a run themselves when their state blows up inside doStep
    if isinstance(cause, FmiError) and any("state diverged" in line for line in cause.log):
        return "diverged"
    return "failed"


def run_point(task: dict, fmu_blobs: dict | None = None) -> dict:
    """Run one point; never raises for a failing simulation (the row says why).

    ``task``: scenario (grid values, controller and FMU file per instance
    already set), controller, values.  ``fmu_blobs`` (Dask): {sha256: bytes}
    of the FMUs, written once per host into a cache and used from there.
    """
    from .master import simulate
    from .scores import score_run

    scenario = task["scenario"]
    if fmu_blobs is not None:
        scenario = _with_cached_fmus(scenario, task["fmu_hashes"], fmu_blobs)
    row = {"controller": task["controller"], "values": list(task["values"])}
    wall_start = clock.perf_counter()
    try:
        result = simulate(scenario, algorithm=task["algorithm"])
        scores = score_run(result)
        row.update(scores=scores, status="ok", reason="")
    except Exception as error:  # noqa: BLE001 - every failure of a point is a row, the sweep goes on
        message = str(error) or type(error).__name__
        status = _status_of(error)
        if status == "failed" and not hasattr(error, "cause"):
            message = f"{type(error).__name__}: {message}"
        row.update(scores={}, status=status, reason=_one_line(message))
    row["wall_s"] = clock.perf_counter() - wall_start
    return row


def _fmu_cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / "afc-sweep-fmus"


def _with_cached_fmus(scenario: Scenario, hashes: dict, blobs: dict) -> Scenario:
    """Write the FMUs received from the client to this host's cache; point the scenario at them."""
    import copy

    scenario = copy.deepcopy(scenario)
    for instance, (digest, filename) in hashes.items():
        path = _fmu_cache_dir() / digest[:20] / filename
        if not path.exists():
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_name(f".{filename}.{os.getpid()}.part")
            partial.write_bytes(blobs[digest])
            os.replace(partial, path)  # atomic: other worker processes see all or nothing
        scenario.components[instance].fmu = str(path)
    return scenario


def _task(plan: SweepPlan, controller: str, values) -> dict:
    point = _scenario_point(plan.scenario, controller, plan.names, values)
    for instance, path in plan.fmu_files.items():
        point.components[instance].fmu = str(path)
    return {"scenario": point, "controller": controller, "values": tuple(values), "algorithm": plan.algorithm}


# ------------------------------------------------------------------- CSV
def csv_columns(names) -> list:
    return ["controller", *names, *TRAILING_COLUMNS]


def _format(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return repr(float(value))


def row_cells(row: dict) -> list:
    return [row["controller"], *(_format(v) for v in row["values"]),
            *(_format(row["scores"].get(k)) for k in SCORE_KEYS),
            f"{row['wall_s']:.4f}", row["status"], row["reason"]]


def parse_cells(cells: list, names) -> dict | None:
    """A row from its CSV cells; None if the row is incomplete (e.g. cut by a kill)."""
    if len(cells) != len(csv_columns(names)):
        return None
    n = len(names)
    try:
        controller = cells[0]
        values = [float(v) for v in cells[1:1 + n]]
        scores = {k: (float(v) if v != "" else math.nan) for k, v in zip(SCORE_KEYS, cells[1 + n:1 + n + len(SCORE_KEYS)])}
        wall, status, reason = cells[1 + n + len(SCORE_KEYS):]
        wall_s = float(wall)
    except ValueError:
        return None
    if controller not in CONTROLLER_VARIANTS or status not in STATUSES:
        return None
    return {"controller": controller, "values": values, "scores": scores, "wall_s": wall_s,
            "status": status, "reason": reason}


def read_rows(path, names) -> list:
    """Every complete row of a sweep CSV (a last line cut short by a kill is left out)."""
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return []
    with open(path, newline="") as stream:
        text = stream.read()
    lines = list(csv.reader(io.StringIO(text)))
    if not lines:
        return []
    header = lines[0]
    if header != csv_columns(names):
        theirs = header[1:header.index("ts")] if "ts" in header else header
        raise ScenarioError(f"{path} holds a sweep over {', '.join(theirs) or 'nothing'}, not over "
                            f"{', '.join(names)}: use another --out, or remove it to start over")
    complete_text = text if text.endswith("\n") else text[:text.rfind("\n") + 1]
    complete = list(csv.reader(io.StringIO(complete_text)))[1:]
    return [row for row in (parse_cells(cells, names) for cells in complete) if row is not None]


class CsvSink:
    """Append rows one at a time, flushed, so a killed sweep loses at most the row being written."""

    def __init__(self, path: Path, names, kept_rows: list):
        self.path = Path(path)
        self.names = list(names)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # rewrite the file with its complete rows only: a row cut short by a kill is dropped here
        partial = self.path.with_name(self.path.name + ".part")
        with open(partial, "w", newline="") as stream:
            writer = csv.writer(stream, lineterminator="\n")
            writer.writerow(csv_columns(self.names))
            for row in kept_rows:
                writer.writerow(row_cells(row))
        os.replace(partial, self.path)
        self.stream = open(self.path, "a", newline="")

    def write(self, row: dict):
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\n").writerow(row_cells(row))
        self.stream.write(buffer.getvalue())
        self.stream.flush()
        os.fsync(self.stream.fileno())

    def close(self):
        self.stream.close()


def _check_settings(path: Path, settings: dict):
    if not path.exists():
        return
    try:
        previous = json.loads(path.read_text())
    except (OSError, ValueError):
        return
    differing = [key for key in settings if key in previous and previous[key] != settings[key]]
    if differing:
        what = "; ".join(f"{key}: {previous[key]!r} then, {settings[key]!r} now" for key in differing)
        raise ScenarioError(f"{path.parent} holds a sweep with other settings ({what}); "
                            "use another --out, or remove the directory to start over")


# -------------------------------------------------------------- executors
def _ignore_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and cancels


def _outcome(future) -> tuple:
    """(row, None), or (None, error) when the worker itself was lost (the point is not recorded)."""
    try:
        return future.result(), None
    except Exception as error:  # noqa: BLE001 - a crashed or killed worker, a pickling error...
        return None, error


class LocalPool:
    """A process pool on this machine (spawned workers: no state inherited from the parent)."""

    def __init__(self, jobs: int, function=None):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.jobs = jobs
        self.function = function or run_point  # tests swap in a module-level wrapper
        self.executor = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                            initializer=_ignore_sigint)

    def describe(self) -> str:
        return f"local pool, {self.jobs} process{'es' if self.jobs != 1 else ''}"

    def run(self, tasks):
        from concurrent.futures import as_completed

        futures = [self.executor.submit(self.function, task) for task in tasks]
        for future in as_completed(futures):
            yield _outcome(future)

    def close(self, cancel: bool = False):
        if cancel:  # stop the points under way too: they are not recorded and rerun on resume
            for process in list((getattr(self.executor, "_processes", None) or {}).values()):
                process.terminate()
        self.executor.shutdown(wait=True, cancel_futures=cancel)


class DaskPool:
    """Points go to an existing dask.distributed scheduler; the FMUs travel with them, once per worker."""

    def __init__(self, address: str, plan: SweepPlan):
        try:
            from distributed import Client
        except ImportError:
            raise ScenarioError("--scheduler needs dask.distributed: pip install 'afc-fmi[cluster]' "
                                "(or pip install 'dask[distributed]')") from None
        try:
            self.client = Client(address, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError) as error:
            raise ScenarioError(f"cannot reach the Dask scheduler at {address!r}: {error}") from None
        self.address = address

        def worker_can_run():  # defined here so cloudpickle ships it by value
            import importlib.util

            return all(importlib.util.find_spec(module) is not None for module in ("harness", "fmpy", "numpy"))

        checks = self.client.run(worker_can_run)
        if not checks:
            self.client.close()
            raise ScenarioError(f"the Dask scheduler at {address!r} has no workers")
        missing = [worker for worker, ok in checks.items() if not ok]
        if missing:
            self.client.close()
            raise ScenarioError(f"Dask workers {', '.join(missing)} cannot import harness, fmpy and numpy: "
                                "install this project on every worker host (pip install '.[cluster]')")
        self.workers = len(checks)
        blobs, self.hashes = {}, {}
        for instance, path in plan.fmu_files.items():
            data = Path(path).read_bytes()
            digest = hashlib.sha256(data).hexdigest()
            blobs[digest] = data
            self.hashes[instance] = (digest, Path(path).name)
        self.blobs = self.client.scatter(blobs, broadcast=True)  # one future: a dict {sha256: bytes}

    def describe(self) -> str:
        return f"Dask scheduler {self.address}, {self.workers} worker{'s' if self.workers != 1 else ''}"

    def run(self, tasks):
        from distributed import as_completed

        self.futures = []
        for task in tasks:
            task = dict(task, fmu_hashes=self.hashes)
            self.futures.append(self.client.submit(run_point, task, self.blobs, pure=False))
        for future in as_completed(self.futures):
            yield _outcome(future)

    def close(self, cancel: bool = False):
        if cancel and getattr(self, "futures", None):
            self.client.cancel(self.futures)
        self.client.close()


# ------------------------------------------------------------------- sweep
@dataclass
class SweepSummary:
    csv_path: Path
    heatmap_path: Path | None
    total: int
    done_before: int
    computed: int
    counts: dict  # controller -> {status: n}
    wall_s: float
    interrupted: bool
    executor: str
    lost: int = 0  # points whose worker was lost (crash, killed worker): not recorded, rerun on resume
    lost_reason: str = ""


def run_sweep(plan: SweepPlan, out, jobs: int | None = None, scheduler: str | None = None,
              progress: bool = True, on_row=None, plot: bool = True, point_function=None) -> SweepSummary:
    """Run every point of the plan not yet in ``out/sweep.csv``; stream rows; draw the heat map.

    ``on_row(row, done)`` is called after each row is written (tests interrupt
    the sweep from there by raising KeyboardInterrupt).  A point whose worker
    is lost (a crash in an FMU, a killed Dask worker) is not recorded: the
    summary counts it and a resume runs it again.  ``point_function``
    replaces ``run_point`` on the local pool (tests).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, settings_path = out / CSV_NAME, out / SETTINGS_NAME
    settings = plan.settings()
    _check_settings(settings_path, settings)
    kept = read_rows(csv_path, plan.names)
    wanted = {point_key(c, v): (c, v) for c, v in plan.points()}
    done = {point_key(row["controller"], row["values"]) for row in kept}
    todo = [(c, v) for key, (c, v) in wanted.items() if key not in done]
    done_before = len(wanted) - len(todo)
    settings_path.write_text(json.dumps({**settings, "grid_values": {g.name: list(g.values) for g in plan.grids},
                                         "controllers": list(plan.controllers), "metric": plan.metric}, indent=2))
    sink = CsvSink(csv_path, plan.names, kept)
    wall_start = clock.perf_counter()
    interrupted, computed, pool, lost, lost_reason = False, 0, None, 0, ""
    from tqdm import tqdm

    if todo:
        try:
            pool = (DaskPool(scheduler, plan) if scheduler else
                    LocalPool(min(jobs or os.cpu_count() or 1, len(todo)), point_function))
        except BaseException:
            sink.close()
            raise
    bar = tqdm(total=len(wanted), initial=done_before, desc=f"sweep {plan.scenario.name}", unit="pt",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    previous_sigterm = _sigterm_as_interrupt()
    try:
        if todo:
            troubled = 0
            for row, error in pool.run([_task(plan, c, v) for c, v in todo]):
                bar.update(1)
                if error is not None:
                    lost += 1
                    lost_reason = lost_reason or _one_line(f"{type(error).__name__}: {error}", 300)
                    bar.set_postfix(not_ok=troubled, lost=lost)
                    continue
                sink.write(row)
                computed += 1
                troubled += row["status"] != "ok"
                if troubled:
                    bar.set_postfix(not_ok=troubled, lost=lost)
                if on_row is not None:
                    on_row(row, computed)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)
        bar.close()
        sink.close()
        if pool is not None:
            pool.close(cancel=interrupted)
    wall_s = clock.perf_counter() - wall_start
    rows = current_rows(plan, read_rows(csv_path, plan.names))
    counts = {c: {s: 0 for s in STATUSES} for c in plan.controllers}
    for row in rows:
        counts[row["controller"]][row["status"]] += 1
    heatmap_path = None
    if plot and rows:
        heatmap_path = plot_heatmap(plan, rows, out / f"heatmap_{plan.metric}.png")
    return SweepSummary(csv_path, heatmap_path, len(wanted), done_before, computed, counts, wall_s,
                        interrupted, pool.describe() if pool else "nothing to run", lost, lost_reason)


def _sigterm_as_interrupt():
    """SIGTERM stops the sweep as Ctrl-C does (the previous handler, or None off the main thread)."""
    def handler(signum, frame):
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # signals can only be handled in the main thread
        return None


def current_rows(plan: SweepPlan, rows: list) -> list:
    """The rows of the CSV that belong to the plan's points (a CSV may hold more after a grid change)."""
    wanted = {point_key(c, v) for c, v in plan.points()}
    return [row for row in rows if point_key(row["controller"], row["values"]) in wanted]


# ---------------------------------------------------------------- heat map
def heatmap_arrays(plan: SweepPlan, rows: list, controller: str):
    """(metric, status) arrays over the first two grid axes (axis 0 along x); worst over the other axes.

    status: 0 missing, 1 ok, 2 diverged, 3 failed.  A cell is diverged or
    failed (and its metric NaN) if any point folded into it is; otherwise
    its metric is the largest (all the scores are "lower is better").
    """
    import numpy as np

    grids = plan.grids
    nx = len(grids[0])
    ny = len(grids[1]) if len(grids) > 1 else 1
    metric = np.full((ny, nx), np.nan)
    status = np.zeros((ny, nx), dtype=int)
    index_x = {value_key(v): i for i, v in enumerate(grids[0].values)}
    index_y = {value_key(v): i for i, v in enumerate(grids[1].values)} if len(grids) > 1 else None
    code = {"ok": 1, "diverged": 2, "failed": 3}
    for row in rows:
        if row["controller"] != controller:
            continue
        i = index_x[value_key(row["values"][0])]
        j = index_y[value_key(row["values"][1])] if index_y else 0
        status[j, i] = max(status[j, i], code[row["status"]])
        value = row["scores"].get(plan.metric, math.nan)
        if row["status"] == "ok" and math.isfinite(value):
            metric[j, i] = value if math.isnan(metric[j, i]) else max(metric[j, i], value)
    metric[status > 1] = np.nan
    return metric, status


def plot_heatmap(plan: SweepPlan, rows: list, path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.colors import LogNorm, Normalize

    from .units import score_units, variable_unit, with_unit

    def axis_label(name: str) -> str:  # step and stop in s, a parameter in its FMU's unit
        return with_unit(name, "s" if name in SCENARIO_SETTINGS else variable_unit(plan.scenario, name))

    panels = [(c, *heatmap_arrays(plan, rows, c)) for c in plan.controllers]
    finite = np.concatenate([m[np.isfinite(m)] for _, m, _ in panels])
    positive = finite[finite > 0]
    if positive.size and positive.max() / positive.min() > 20:
        norm, scale = LogNorm(positive.min(), positive.max()), "log"
    elif finite.size:
        low, high = float(finite.min()), float(finite.max())
        norm, scale = Normalize(low, high if high > low else low + 1), "linear"
    else:
        norm, scale = Normalize(0, 1), "linear"
    gx = plan.grids[0]
    gy = plan.grids[1] if len(plan.grids) > 1 else None
    ny, nx = panels[0][1].shape
    cell = max(0.3, min(0.6, 4.0 / max(nx, ny)))  # inches per cell
    width = max(len(panels) * (nx * cell + 0.7) + 1.6, 6.0)  # room for the title over one small panel
    height = ny * cell + 1.7
    figure, axes = plt.subplots(1, len(panels), figsize=(width, height), squeeze=False, constrained_layout=True)
    cmap = matplotlib.colormaps["viridis"].with_extremes(bad="white")
    image = None
    annotate = nx * ny <= 100
    for axis, (controller, metric, status) in zip(axes[0], panels):
        shown = np.ma.masked_invalid(np.where(metric > 0, metric, np.nan) if scale == "log" else metric)
        image = axis.imshow(shown, origin="lower", cmap=cmap, norm=norm, aspect="auto")
        for j in range(ny):
            for i in range(nx):
                if status[j, i] in (2, 3):
                    axis.add_patch(plt.Rectangle((i - 0.5, j - 0.5), 1, 1, facecolor="#d9d9d9" if status[j, i] == 2
                                                 else "#f4a6a6", edgecolor="white", hatch="xx", linewidth=0.5))
                    axis.text(i, j, "div" if status[j, i] == 2 else "fail", ha="center", va="center",
                              fontsize=7, color="black")
                elif status[j, i] == 0:
                    axis.text(i, j, "-", ha="center", va="center", fontsize=7, color="grey")
                elif annotate and np.isfinite(metric[j, i]):
                    rgba = cmap(norm(metric[j, i])) if metric[j, i] > 0 or scale == "linear" else (1, 1, 1, 1)
                    light = 0.299 * rgba[0] + 0.587 * rgba[1] + 0.114 * rgba[2] > 0.5
                    axis.text(i, j, f"{metric[j, i]:.3g}", ha="center", va="center", fontsize=6.5,
                              color="black" if light else "white")
        ok = int(np.sum(status == 1))
        axis.set_title(f"{controller}: {ok}/{nx * ny} ok", fontsize=10)
        axis.set_xticks(range(nx), [f"{v:.3g}" for v in gx.values], fontsize=7,
                        rotation=45 if nx > 8 else 0)
        axis.set_xlabel(axis_label(gx.name))
        if gy is not None:
            axis.set_yticks(range(ny), [f"{v:.3g}" for v in gy.values], fontsize=7)
            if axis is axes[0][0]:
                axis.set_ylabel(axis_label(gy.name))
        else:
            axis.set_yticks([])
    rest = [g.name for g in plan.grids[2:]]
    horizon = ", ".join(f"{name} {getattr(plan.scenario, name):g} s" for name in SCENARIO_SETTINGS
                        if name not in plan.names)
    title = f"{plan.scenario.name}: {plan.metric} ({scale} colour scale)" + (f", {horizon}" if horizon else "")
    if rest:
        title += f"\nworst case over {', '.join(rest)}"
    figure.suptitle(title, fontsize=10)
    if image is not None:
        figure.colorbar(image, ax=axes[0].tolist(), shrink=0.9,
                        label=with_unit(plan.metric, score_units(plan.scenario)[plan.metric]))
    path = Path(path)
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


# --------------------------------------------------------------------- CLI
def sweep_command(args) -> int:
    grids = [parse_grid(text) for text in args.grid]
    controllers = tuple(CONTROLLER_VARIANTS) if args.controller == "all" else (args.controller,)
    import build_fmu

    plan = plan_sweep(args.scenario, controllers, grids, metric=args.metric, stop=args.stop, step=args.step,
                      algorithm=args.algorithm, fmu_paths=build_fmu.ensure_built())
    out = Path(args.out) if args.out else Path("build") / "sweeps" / plan.scenario.name
    if args.jobs is not None and args.jobs < 1:
        raise ScenarioError(f"--jobs {args.jobs}: need at least 1")
    from . import cli_args

    cli_args.refuse_tracked([out / CSV_NAME, out / SETTINGS_NAME, out / f"heatmap_{plan.metric}.png"])
    parameters = [g for g in plan.grids if "." in g.name]
    for pick in (min, max):  # valid ranges are intervals: the ends of each axis decide
        cli_args.check_assignments(plan.scenario, [(g.name, pick(g.values)) for g in parameters],
                                   plan_fmu_paths(plan), option="--grid")
    shortest = min(plan.grids[plan.names.index("stop")].values) if "stop" in plan.names else plan.scenario.stop
    if shortest - plan.scenario.start < 2 * math.pi:
        print(f"warning: stop {shortest:g} s < 2 pi: es1_pct and es2_pct (over the last reference period) "
              "mean nothing in these rows", file=sys.stderr)
    total = len(plan.points())
    fixed = ", ".join(f"{name} {getattr(plan.scenario, name):g} s" for name in SCENARIO_SETTINGS
                      if name not in plan.names)  # a grid axis has no single value
    print(f"sweep {plan.scenario.name}: {' x '.join(f'{g.name} ({len(g)})' for g in plan.grids)} x "
          f"{len(controllers)} controller{'s' if len(controllers) > 1 else ''} = {total} points"
          + (f", {fixed}" if fixed else "") + f" -> {out}", file=sys.stderr)
    summary = run_sweep(plan, out, jobs=args.jobs, scheduler=args.scheduler,
                        progress=not args.no_progress and sys.stderr.isatty())
    print(f"{summary.computed} points computed ({summary.executor}) in {summary.wall_s:.1f} s, "
          f"{summary.done_before} already done" + (", INTERRUPTED: run the same command to resume"
                                                     if summary.interrupted else ""))
    rows = current_rows(plan, read_rows(summary.csv_path, plan.names))
    for controller in controllers:
        values = sorted(r["scores"][plan.metric] for r in rows if r["controller"] == controller
                        and r["status"] == "ok" and math.isfinite(r["scores"][plan.metric]))
        counts = summary.counts[controller]
        spread = (f"; {plan.metric} min {values[0]:.4g}, median {values[len(values) // 2]:.4g}, max {values[-1]:.4g}"
                  if values else "")
        print(f"  {controller:5s} ok {counts['ok']}, diverged {counts['diverged']}, failed {counts['failed']} "
              f"of {total // len(controllers)}{spread}")
    print(f"  rows     {summary.csv_path}")
    if summary.heatmap_path:
        print(f"  heat map {summary.heatmap_path}")
    if summary.lost:
        print(f"error: {summary.lost} point(s) not run, their worker was lost ({summary.lost_reason}); "
              "run the same command to retry them", file=sys.stderr)
    if args.apply and not (summary.interrupted or summary.lost):
        for path in apply_to_docs(plan, summary):
            print(f"  applied  {path}")
    return 130 if summary.interrupted else 1 if summary.lost else 0


def plan_fmu_paths(plan: SweepPlan) -> dict:
    """{model identifier or file: path} of the plan's FMUs, as ``resolve_fmu`` takes them."""
    return {plan.scenario.components[instance].fmu: path for instance, path in plan.fmu_files.items()}


def apply_to_docs(plan: SweepPlan, summary: SweepSummary) -> list:
    """Copy the sweep's CSV and heat map into docs/ as docs/sweep_SCENARIO_AXES.csv and ..._METRIC.png."""
    import shutil

    axes = "_".join(name.rpartition(".")[2].split("_")[0] for name in plan.names)  # plant.dist_gain -> dist
    stem = DOCS_DIR / f"sweep_{plan.scenario.name}_{axes}"
    written = [shutil.copyfile(summary.csv_path, stem.with_name(stem.name + ".csv"))]
    if summary.heatmap_path:
        written.append(shutil.copyfile(summary.heatmap_path, stem.with_name(f"{stem.name}_{plan.metric}.png")))
    return [Path(path) for path in written]


def register(commands):
    from . import cli_args

    sweep = commands.add_parser(
        "sweep", help="run a scenario over a grid of parameters (process pool or Dask) and draw heat maps",
        description="One co-simulation per point of the cartesian product of the grids, for each controller. "
                    "Rows stream to OUT/sweep.csv; rerun the same command to resume an interrupted sweep.")
    sweep.add_argument("scenario", type=cli_args.scenario, help=cli_args.scenario_help())
    sweep.add_argument("--controller", choices=(*CONTROLLER_VARIANTS, "all"), default="vud")
    sweep.add_argument("--grid", action="append", required=True, metavar="NAME=START:STOP:N",
                       help="a grid axis: instance.parameter (e.g. plant.mp, controller.kappa1), step or stop; "
                            "N evenly spaced values from START to STOP, START:STOP:N:log for geometric spacing, "
                            "or V1,V2,... (repeat --grid for more axes; the heat map uses the first two)")
    sweep.add_argument("--metric", default="ITAE", choices=SCORE_KEYS, help="the score of the heat map (ITAE)")
    sweep.add_argument("--stop", type=cli_args.positive_float, help="stop time in s (default: the scenario's)")
    sweep.add_argument("--step", type=cli_args.positive_float, help="communication step in s (default: the scenario's)")
    sweep.add_argument("--algorithm", choices=("feedthrough", "jacobi"), default="feedthrough")
    sweep.add_argument("--out", help="output directory (default: build/sweeps/SCENARIO, ignored by git)")
    sweep.add_argument("--apply", action="store_true",
                       help="also copy the CSV and the heat map into docs/ as sweep_SCENARIO_AXES.csv and "
                            "sweep_SCENARIO_AXES_METRIC.png (the README's examples)")
    where = sweep.add_mutually_exclusive_group()
    where.add_argument("--jobs", type=cli_args.positive_int, help="local worker processes (default: every core)")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run the points on this dask.distributed scheduler (e.g. tcp://host:8786)")
    sweep.add_argument("--no-progress", action="store_true",
                       help="no progress bar (there is none either when stderr is not a terminal)")
    sweep.set_defaults(handler=sweep_command)
