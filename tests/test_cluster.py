"""The studies on a Dask cluster of separate processes, as a user runs one: ``dask scheduler`` and two ``dask
worker`` processes started with docs/studies.md's commands (tests/cluster_helpers.py, the ``dask_cluster``
fixture).  A sweep and a short tune give the local pool's rows; a worker killed with SIGKILL mid-sweep loses
nothing and counts nothing twice; the scheduler gone mid-run is one line, and the run resumes.  A short
Monte Carlo robustness study gives the local pool's rows, and a worker killed mid-study loses none.  The
recipe of a study of many short runs (docs/architecture.md, the Monte Carlo study's shape) runs as
written on the cluster: a worker killed and the run interrupted, then resumed, give the local pool's rows.
"""
from __future__ import annotations

import csv
import importlib.util
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness.cli import main as cli_main
from harness.executors import DaskPool, LocalPool, dask_pool, tasks
from harness.studies import robustness, sweep
from tests.cluster_helpers import SCHEDULER_COMMAND, WORKER_COMMAND

ROOT = Path(__file__).resolve().parents[1]
# short horizon, coarse step: a point takes ~0.1 s; gamma = 3e5 diverges for some points (rows with a reason)
SMALL = ["pendulum_case2", "--controller", "all", "--grid", "plant.mp=0.1:1:2", "--grid", "controller.gamma=300,300000",
         "--stop", "0.5", "--step", "1e-3", "--no-progress"]
# points of about a second each in the pythonfmu edition: long enough to kill something mid-sweep
LONG_GRIDS = ["plant.mp=0.1:2:6", "plant.dist_gain=0,2"]


def rows_of(path) -> dict:
    """{(controller, grid values...): CSV cells without the wall time}; a point twice is an error."""
    with open(path, newline="") as stream:
        table = list(csv.reader(stream))
    header, body = table[0], table[1:]
    wall = header.index("wall_s")
    names = header[1:header.index("ts")]
    keyed = {(r[0], *r[1:1 + len(names)]): r[:wall] + r[wall + 1:] for r in body}
    assert len(keyed) == len(body), "a point appears twice"
    return keyed


def test_the_docs_print_the_commands_the_tests_start():
    studies = (ROOT / "docs" / "studies.md").read_text()
    for command in (SCHEDULER_COMMAND, WORKER_COMMAND):
        assert command.format(port=8786) in studies, f"docs/studies.md: show `{command.format(port=8786)}`"


def test_a_sweep_on_the_cluster_gives_the_local_pools_rows_and_ships_the_fmus_once(dask_cluster, tmp_path):
    assert cli_main(["sweep", *SMALL, "--out", str(tmp_path / "local"), "--jobs", "2"]) == 0
    assert cli_main(["sweep", *SMALL, "--out", str(tmp_path / "dask"), "--scheduler", dask_cluster.address]) == 0
    local, remote = rows_of(tmp_path / "local" / "sweep.csv"), rows_of(tmp_path / "dask" / "sweep.csv")
    assert remote == local and len(local) == 12  # scores bit for bit, every point once
    cached = sorted((dask_cluster.temp / tasks.CACHE_FOLDER).glob("*/*.fmu"))
    assert len(cached) == 3  # the three FMUs, once for the host, by their SHA-256
    assert all(path.parent.name == tasks.sha256_of(path)[:20] for path in cached)


def test_a_worker_killed_mid_sweep_loses_nothing_and_counts_nothing_twice(dask_cluster, fmu_paths, tmp_path):
    plan = sweep.plan_sweep("pendulum_case2", ("vud",), [sweep.parse_grid(g) for g in LONG_GRIDS], stop=3, step=1e-3,
                            fmu_paths=fmu_paths)
    killed = []

    def kill_a_worker(row, done):
        if done == 2 and not killed:
            dask_cluster.kill_worker(dask_cluster.busy_worker())  # the nanny and its worker: a host lost mid-sweep
            killed.append(time.monotonic())

    summary = sweep.run_sweep(plan, tmp_path, scheduler=dask_cluster.address, progress=False, on_row=kill_a_worker,
                              plot=False)
    assert killed and sum(worker.poll() is None for worker in dask_cluster.workers) == 1
    assert (summary.computed, summary.lost, summary.scheduler_lost) == (12, 0, "")
    rows = rows_of(tmp_path / "sweep.csv")
    assert len(rows) == 12 and {cells[-2] for cells in rows.values()} <= {"ok", "diverged"}


def test_every_worker_lost_the_files_go_again_to_the_next_and_none_at_all_is_said(dask_cluster, fmu_paths, tmp_path,
                                                                                   monkeypatch):
    """Every worker killed at once takes the FMUs scattered to them along: sent again to a worker that comes,
    the sweep finishes; with no worker coming, the run says so instead of waiting forever."""
    monkeypatch.setattr(dask_pool, "WORKERLESS_S", 3.0)
    monkeypatch.setattr(dask_pool, "CHECK_S", 0.5)
    plan = sweep.plan_sweep("pendulum_case2", ("vud",), [sweep.parse_grid(g) for g in LONG_GRIDS], stop=3, step=1e-3,
                            fmu_paths=fmu_paths)

    def kill_every_worker(then_start_one: bool):
        def on_row(row, done):
            if done == 1:
                for index in range(len(dask_cluster.workers)):
                    if dask_cluster.workers[index].poll() is None:
                        dask_cluster.kill_worker(index)
                if then_start_one:
                    dask_cluster.start_worker(0)
        return on_row

    summary = sweep.run_sweep(plan, tmp_path / "again", scheduler=dask_cluster.address, progress=False,
                              on_row=kill_every_worker(True), plot=False)
    assert (summary.computed, summary.lost, summary.scheduler_lost) == (12, 0, "")
    assert len(rows_of(tmp_path / "again" / "sweep.csv")) == 12
    dask_cluster.wait_for_workers(1)
    summary = sweep.run_sweep(plan, tmp_path / "none", scheduler=dask_cluster.address, progress=False,
                              on_row=kill_every_worker(False), plot=False)
    assert summary.scheduler_lost.startswith(f"the Dask scheduler at {dask_cluster.address} has had no worker for 3 s")
    assert 1 <= summary.computed < 12 and len(rows_of(tmp_path / "none" / "sweep.csv")) == summary.computed


def test_the_scheduler_gone_mid_sweep_is_one_line_and_the_sweep_resumes(dask_cluster, tmp_path):
    out = tmp_path / "out"
    argv = ["pendulum_case2", "--controller", "vud", *[part for g in LONG_GRIDS for part in ("--grid", g)],
            "--stop", "3", "--step", "1e-3", "--no-progress", "--out", str(out)]
    command = subprocess.Popen([sys.executable, "-m", "harness", "sweep", *argv, "--scheduler", dask_cluster.address],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and command.poll() is None:
            path = out / "sweep.csv"
            if path.exists() and path.read_text().count("\n") >= 3:  # header + 2 rows
                dask_cluster.kill_scheduler()
                break
            time.sleep(0.05)
        stdout, stderr = command.communicate(timeout=120)
    finally:
        if command.poll() is None:
            os.killpg(command.pid, signal.SIGKILL)
            command.wait()
    errors = [line for line in stderr.splitlines() if "error" in line.lower()]
    assert command.returncode == 1 and "Traceback" not in stderr, stderr
    assert len(errors) == 1 and errors[0].startswith(f"error: lost the Dask scheduler at {dask_cluster.address} ("), stderr
    assert "point(s) not run, the finished ones are in" in errors[0] and "run the same command to resume" in errors[0]
    before = rows_of(out / "sweep.csv")
    assert 2 <= len(before) < 12
    assert cli_main(["sweep", *argv, "--jobs", "2"]) == 0  # resumed on the local pool
    after = rows_of(out / "sweep.csv")
    assert len(after) == 12 and all(after[key] == cells for key, cells in before.items())


def test_a_short_tune_on_the_cluster_finishes_as_the_local_pool_does(dask_cluster, postgres, tmp_path):
    """The trials as Dask tasks, the study in the PostgreSQL server: the local pool's finished count, no trial
    twice, none left running; a worker killed mid-study loses no trial, the scheduler gone later is one line,
    and another run completes the study."""
    import optuna

    base = ["tune", "pendulum_case1", "--stop", "0.3", "--trials", "10", "--quiet", "--held-out"]
    assert cli_main([*base, "--jobs", "2", "--out", str(tmp_path / "local")]) == 0
    url = postgres.url(postgres.create_database(f"cluster_{os.getpid()}"))
    assert cli_main([*base, "--scheduler", dask_cluster.address, "--storage", url, "--out", str(tmp_path / "dask")]) == 0
    local = optuna.load_study(study_name="pendulum_case1-vud-ITAE",
                              storage=f"sqlite:///{tmp_path / 'local' / 'pendulum_case1.db'}").get_trials()
    remote = optuna.load_study(study_name="pendulum_case1-vud-ITAE", storage=url).get_trials()
    finished = (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)
    for trials in (local, remote):
        assert sum(t.state in finished for t in trials) == 10
        assert not [t for t in trials if t.state == optuna.trial.TrialState.RUNNING]
        assert len({t.number for t in trials}) == len(trials)
    # the scheduler gone mid-study: one line, the finished trials kept, the study completed by another run
    long = ["tune", "pendulum_case1", "--stop", "2", "--trials", "40", "--quiet", "--held-out", "--study", "long",
            "--storage", url, "--out", str(tmp_path / "dask")]
    command = subprocess.Popen([sys.executable, "-m", "harness", *long, "--scheduler", dask_cluster.address],
                               cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    killed_at = 10 ** 6
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and command.poll() is None:
            try:
                trials = optuna.load_study(study_name="long", storage=url).get_trials()
            except KeyError:
                trials = []
            count = sum(t.state in finished for t in trials)
            if count >= 2 and killed_at > count:
                busy = dask_cluster.busy_worker(alive=lambda: command.poll() is None)
                if busy is None:  # the study ended first (the assertions below show how)
                    break
                dask_cluster.kill_worker(busy)  # its trial runs again on the other, told once
                killed_at = count
            if count >= killed_at + 3:
                dask_cluster.kill_scheduler()
                break
            time.sleep(0.2)
        stderr = command.communicate(timeout=120)[1]
    finally:
        if command.poll() is None:
            os.killpg(command.pid, signal.SIGKILL)
            command.wait()
    errors = [line for line in stderr.splitlines() if "error" in line.lower()]
    assert command.returncode == 1 and len(errors) == 1 and "Traceback" not in stderr, stderr
    assert errors[0].startswith(f"error: lost the Dask scheduler at {dask_cluster.address} (") and \
        "run the same command to resume" in errors[0], stderr
    assert postgres.password not in stderr
    assert killed_at < 10 ** 6 and sum(worker.poll() is None for worker in dask_cluster.workers) == 1
    trials = optuna.load_study(study_name="long", storage=url).get_trials()
    lost = [t.number for t in trials if "worker" in str(t.user_attrs.get("outcome", {}).get("reason", ""))]
    assert not lost, f"trials {lost} were lost with the worker"
    assert sum(t.state in finished for t in trials) >= killed_at + 3
    assert cli_main([*long, "--jobs", "2"]) == 0
    trials = optuna.load_study(study_name="long", storage=url).get_trials()
    assert sum(t.state in finished for t in trials) == 40
    assert not [t for t in trials if t.state == optuna.trial.TrialState.RUNNING]


def recipe_module(folder: Path):
    """The sketch of docs/architecture.md's "A study of many short runs" as a module of its own
    (``monte_carlo_sketch.py`` in ``folder``, where its rows go too)."""
    page = (ROOT / "docs" / "architecture.md").read_text()
    section = page[page.index("### A study of many short runs"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    path = folder / "monte_carlo_sketch.py"
    path.write_text(code)
    spec = importlib.util.spec_from_file_location("monte_carlo_sketch", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # the local pool's spawned workers import it by name (sys.path below)
    spec.loader.exec_module(module)
    module.ROWS = folder / "rows.csv"
    return module


def test_the_recipe_of_a_study_of_short_runs_survives_a_killed_worker_and_an_interrupt(dask_cluster, fmu_paths,
                                                                                     tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    sketch = recipe_module(tmp_path)
    monkeypatch.setattr(sketch, "DRAWS", 8)  # 16 runs: a worker killed mid-run still holds a task
    files = sketch.fmu_files()
    try:
        sketch.ROWS = tmp_path / "local.csv"
        with LocalPool(2, files) as pool:
            sketch.run(pool)
        local = sketch.ROWS.read_text().splitlines()
        assert len(local) == len(set(local)) == 16 and all(",ok," in line for line in local)

        sketch.ROWS = tmp_path / "dask.csv"
        streamed, killed = sketch.stream_tasks, []

        def kill_then_interrupt(*args, **kwargs):  # the sketch's loop, with a worker lost and a Ctrl-C
            for count, finished in enumerate(streamed(*args, **kwargs), 1):
                yield finished
                if count == 2:
                    busy = dask_cluster.busy_worker()
                    killed.append(pool.pending())
                    dask_cluster.kill_worker(busy)
                if count == 10:
                    raise KeyboardInterrupt

        monkeypatch.setattr(sketch, "stream_tasks", kill_then_interrupt)
        with pytest.raises(KeyboardInterrupt), DaskPool(dask_cluster.address, files) as pool:
            pool.client.upload_file(sketch.__file__)  # the study's module, as a user ships one to a cluster
            sketch.run(pool)
        assert killed and killed[0] > 0
        assert len(sketch.ROWS.read_text().splitlines()) == 10
        monkeypatch.setattr(sketch, "stream_tasks", streamed)
        with DaskPool(dask_cluster.address, files) as pool:  # resumed on the one worker left
            assert len(sketch.run(pool)) == 10
        with DaskPool(dask_cluster.address) as pool:  # a task's own error comes back as itself, as locally
            for key, item in enumerate((4.0, -1.0)):
                pool.submit(math.sqrt, item, key=key)
            done = {d.key: d for d in pool.as_completed()}
            assert done[0].value == 2.0 and isinstance(done[1].error, ValueError), done[1].error
        remote = sketch.ROWS.read_text().splitlines()
        assert len(remote) == len(set(remote)) == 16  # nothing lost, nothing twice
        assert sorted(remote) == sorted(local)  # the local pool's rows, bit for bit
    finally:
        sys.modules.pop("monte_carlo_sketch", None)


# ------------------------------------------------------------------ the Monte Carlo robustness study
ROBUST_PARAMS = ("plant.mp=loguniform:0.05:2", "plant.dist_gain=uniform:0:2")


def study_rows(path) -> dict:
    """{(sample, controller): the cells but the wall and loop times}; a run twice is an error."""
    with open(path, newline="") as stream:
        table = list(csv.DictReader(stream))
    keyed = {(row["sample"], row["controller"]): {k: v for k, v in row.items() if k not in ("wall_s", "loop_s", "cpu_s", "loop_cpu_s")}
             for row in table}
    assert len(keyed) == len(table), "a run appears twice"
    return keyed


def robustness_plan(fmu_paths, samples, controllers, stop):
    return robustness.plan_study("pendulum_case2", controllers, [robustness.parse_param(p) for p in ROBUST_PARAMS],
                                 samples, seed=5, stop=stop, step=1e-3, fmu_paths=fmu_paths)


def test_a_monte_carlo_study_on_the_cluster_gives_the_local_pools_rows(dask_cluster, fmu_paths, tmp_path):
    plan = robustness_plan(fmu_paths, 4, ("vud", "fixed", "fae"), 0.5)
    local = robustness.run_study(plan, tmp_path / "local", jobs=2, progress=False, plot=False)
    remote = robustness.run_study(plan, tmp_path / "dask", scheduler=dask_cluster.address, batch=3, progress=False,
                                  plot=False)
    assert (local.computed, remote.computed, remote.lost) == (12, 12, 0) and remote.executor.startswith("Dask")
    rows = study_rows(tmp_path / "dask" / "robustness.csv")
    assert rows == study_rows(tmp_path / "local" / "robustness.csv") and len(rows) == 12  # bit for bit
    assert remote.summary["controllers"] == local.summary["controllers"]


def test_a_worker_killed_mid_study_loses_no_run_and_counts_none_twice(dask_cluster, fmu_paths, tmp_path):
    plan = robustness_plan(fmu_paths, 8, ("vud",), 3)  # runs of about a second: a kill lands mid-run
    killed = []

    def kill_a_worker(row, computed):
        if computed == 2 and not killed:
            dask_cluster.kill_worker(dask_cluster.busy_worker())  # the nanny and its worker: a host lost mid-study
            killed.append(computed)

    outcome = robustness.run_study(plan, tmp_path / "dask", scheduler=dask_cluster.address, batch=1, progress=False,
                                   on_row=kill_a_worker, plot=False)
    assert killed and sum(worker.poll() is None for worker in dask_cluster.workers) == 1
    assert (outcome.computed, outcome.lost, outcome.scheduler_lost) == (8, 0, "")
    local = robustness.run_study(plan, tmp_path / "local", jobs=2, progress=False, plot=False)
    assert local.computed == 8
    assert study_rows(tmp_path / "dask" / "robustness.csv") == study_rows(tmp_path / "local" / "robustness.csv")
