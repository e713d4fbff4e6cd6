"""The figures of docs/performance.md's section on sweeps over executors (run by hand, not a test):

    python -m tests.scaling [--edition python|native] [--points N] [--stop T] [--tasks N] [--no-sweep]

The same sweep on a local pool of 1 and of 2 processes and on a Dask cluster of a scheduler and two
workers started as separate processes (tests/cluster_helpers.py): wall time and parallel efficiency
(T1 / (2 T2)); then what a task costs each executor beside the work, from tasks that do nothing
(submission to result, per task, with the pool already started), against one run's cost; and what an item costs through harness/executors/stream.py at one item per task
and at ten (``--no-sweep``: these figures alone). The load average is printed beside every figure: the
machine is shared.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from harness.executors import DaskPool, LocalPool, stream_tasks  # noqa: E402
from harness.fmu_build import builder as build_fmu  # noqa: E402
from harness.studies import sweep  # noqa: E402
from tests.cluster_helpers import DaskCluster  # noqa: E402


def nothing(item, files=None):
    return item


def load() -> str:
    return "load average " + " ".join(f"{value:.1f}" for value in os.getloadavg())


def children_cpu_s() -> float:
    """CPU seconds of this process's ended children (a local pool's workers once it is closed)."""
    times = os.times()
    return times.children_user + times.children_system


def timed_sweep(plan, scheduler=None, jobs=None) -> tuple:
    out = Path(tempfile.mkdtemp(prefix="afc-scaling-"))
    try:
        began = time.perf_counter()
        summary = sweep.run_sweep(plan, out, jobs=jobs, scheduler=scheduler, progress=False, plot=False)
        wall = time.perf_counter() - began
        rows = sweep.current_rows(plan, sweep.run.read_rows(out / "sweep.csv", plan.names))
        assert summary.computed == len(plan.points()) and len(rows) == summary.computed, summary
        return wall, [row["wall_s"] for row in rows]
    finally:
        shutil.rmtree(out, ignore_errors=True)


def per_task(executor, count: int) -> float:
    """Seconds per do-nothing task, submission to result, the workers already started."""
    for item in range(executor.slots * 2):  # warm: workers spawned, imports done
        executor.submit(nothing, item)
    list(executor.as_completed())
    began = time.perf_counter()
    for item in range(count):
        executor.submit(nothing, item)
    done = list(executor.as_completed())
    assert len(done) == count and all(d.ok for d in done)
    return (time.perf_counter() - began) / count


def per_item(executor, count: int, batch: int) -> float:
    """Seconds per do-nothing item streamed ``batch`` to a task, the workers already started."""
    list(stream_tasks(executor, nothing, ((item, item) for item in range(executor.slots * 2))))  # warm
    began = time.perf_counter()
    done = list(stream_tasks(executor, nothing, ((item, item) for item in range(count)), batch=batch))
    assert len(done) == count and all(d.ok for d in done)
    return (time.perf_counter() - began) / count


def streams(executors: dict, count: int) -> None:
    for name, executor in executors.items():
        costs = {batch: per_item(executor, count, batch) for batch in (1, 10)}
        print(f"  a do-nothing item through stream_tasks on {name}: "
              + ", ".join(f"{1e3 * cost:.3f} ms at {batch} per task" for batch, cost in costs.items())
              + f" ({load()})", flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--edition", default="python")
    parser.add_argument("--points", type=int, default=16)
    parser.add_argument("--stop", type=float, default=5.0)
    parser.add_argument("--tasks", type=int, default=2000, help="do-nothing tasks per executor")
    parser.add_argument("--no-sweep", action="store_true", help="the stream's figures only")
    args = parser.parse_args(argv)
    if args.no_sweep:
        with DaskCluster(2) as cluster, DaskPool(cluster.address) as dask, LocalPool(2) as local:
            streams({"a local pool of 2": local, "Dask, 2 workers": dask}, args.tasks)
        return 0
    os.environ["AFC_EDITION"] = args.edition
    fmu_paths = build_fmu.ensure_built(edition=args.edition)
    grids = [sweep.parse_grid(f"plant.mp=0.1:2:{args.points // 2}"), sweep.parse_grid("plant.dist_gain=0,2")]
    plan = sweep.plan_sweep("pendulum_case2", ("vud",), grids, stop=args.stop, step=1e-3, fmu_paths=fmu_paths)
    points = len(plan.points())
    print(f"sweep pendulum_case2/vud, {points} points of {args.stop:g} s at 1 ms, {args.edition} edition")
    walls = {}
    for label, jobs in (("local pool, 1 process", 1), ("local pool, 2 processes", 2)):
        print(f"  {label:28s} ({load()})", flush=True)
        cpu = children_cpu_s()
        walls[label], runs = timed_sweep(plan, jobs=jobs)
        print(f"  {label:28s} {walls[label]:7.2f} s wall; a point {statistics.median(runs):.3f} s wall (median); "
              f"the workers' CPU {children_cpu_s() - cpu:.1f} s  ({load()})")
    cpu = children_cpu_s()
    with DaskCluster(2) as cluster:
        label = "Dask, 2 workers (1 thread)"
        walls[label], runs = timed_sweep(plan, scheduler=cluster.address)
        print(f"  {label:28s} {walls[label]:7.2f} s wall; a point {statistics.median(runs):.3f} s (median)  ({load()})")
        one = walls["local pool, 1 process"]
        for name, wall in walls.items():
            if "1 process" not in name:
                print(f"  parallel efficiency, {name}: T1 / (2 T) = {one / (2 * wall):.2f}")
        began = time.perf_counter()
        pool = DaskPool(cluster.address, {k: str(v) for k, v in plan.fmu_files.items()})
        opened = time.perf_counter() - began
        try:
            dask_task = per_task(pool, max(200, args.tasks // 4))
            streams({"Dask, 2 workers": pool}, max(200, args.tasks // 4))
        finally:
            pool.close()
        print(f"  Dask client: connect, check the workers, scatter the FMUs: {opened:.2f} s ({load()})")
    print(f"  the Dask cluster's processes, from start to stop: CPU {children_cpu_s() - cpu:.1f} s")
    began = time.perf_counter()
    with LocalPool(2) as pool:
        for item in range(2):
            pool.submit(nothing, item)
        list(pool.as_completed())
        started = time.perf_counter() - began
        local_task = per_task(pool, args.tasks)
        streams({"a local pool of 2": pool}, args.tasks)
    print(f"  starting a local pool of 2 (spawn, imports, a first task each): {started:.2f} s ({load()})")
    print(f"  a do-nothing task, submission to result: local pool {1e3 * local_task:.3f} ms, "
          f"Dask {1e3 * dask_task:.2f} ms ({load()})")
    print(f"  against one point's run: {100 * local_task / statistics.median(runs):.2f} % (local), "
          f"{100 * dask_task / statistics.median(runs):.2f} % (Dask)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
