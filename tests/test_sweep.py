"""Parameter sweeps: grids, validation, local pool vs Dask, streaming, kill and resume, heat map."""
import csv
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from harness import variants
from harness.studies import sweep
from harness.studies.sweep import csv_rows as sweep_csv
from harness.studies.sweep import executors as sweep_executors
from harness.studies.sweep import grid as sweep_grid
from harness.studies.sweep import heatmap as sweep_heatmap
from harness.cli import main as cli_main
from harness.executors import dask_pool, tasks
from harness.scenario import ScenarioError

ROOT = Path(__file__).resolve().parents[1]
# short horizon, coarse step: a point takes ~0.1 s; gamma = 3e5 diverges within 0.05 s for every controller
# at mp = 0.1 (the plant FMU or the master's bound stops it), and for vud also at mp = 1
SMALL = ["pendulum_case2", "--controller", "all", "--grid", "plant.mp=0.1:1:2",
         "--grid", "controller.gamma=300,300000", "--stop", "0.5", "--step", "1e-3", "--no-progress"]


def rows_of(path):
    """{(controller, grid values...): CSV cells without the wall time}, and the header."""
    with open(path, newline="") as stream:
        table = list(csv.reader(stream))
    header, body = table[0], table[1:]
    wall = header.index("wall_s")
    names = header[1:header.index("ts")]
    keyed = {(r[0], *r[1:1 + len(names)]): r[:wall] + r[wall + 1:] for r in body}
    assert len(keyed) == len(body), "a point appears twice"
    return header, keyed


# ------------------------------------------------------------------ grids
def test_grid_syntax():
    assert sweep_grid.parse_grid("plant.mp=0.1:2:5").values == tuple(np.linspace(0.1, 2, 5))
    assert sweep_grid.parse_grid("step=1e-4:1e-2:3:log").values == pytest.approx((1e-4, 1e-3, 1e-2))
    assert sweep_grid.parse_grid("controller.kappa1=1, 10,10,100").values == (1.0, 10.0, 100.0)
    assert sweep_grid.parse_grid("plant.mp=0.5:0.5:1").values == (0.5,)
    for bad in ["plant.mp", "plant.mp=1:2", "plant.mp=1:2:0", "plant.mp=a:2:3", "plant.mp=0:1:3:log",
                "=1:2:3", "plant.mp=1:2:3:lin", "plant.mp=nan"]:
        with pytest.raises(ScenarioError, match="grid"):
            sweep_grid.parse_grid(bad)


@pytest.mark.parametrize("grids,expected", [
    (["plant.mass=0.1:1:2"], "InvertedPendulum has no parameter 'mass'; valid: gv, mc, mp"),
    (["plnt.mp=0.1:1:2"], "instance one of plant, reference, controller"),
    (["speed=1:2:2"], "instance one of plant, reference, controller, or one of step, stop"),
    (["controller.kapa1=1:2:2"], "AdaptiveFuzzyController has no parameter 'kapa1' (did you mean 'kappa1'?); "
                                 "valid: variant, fls_input"),
    (["controller.variant=1:3:3"], "--controller"),
    (["plant.mp=1:2:2", "plant.mp=3:4:2"], "two --grid options"),
    (["controller.fls_input=1,1.5"], "is an Integer; give whole numbers"),
    (["stop=1e-5,1"], "shorter than one step"),
])
def test_grid_names_and_values_are_validated_before_anything_runs(fmu_paths, grids, expected):
    with pytest.raises(ScenarioError) as error:
        sweep_grid.plan_sweep("pendulum_case1", ("vud",), [sweep_grid.parse_grid(g) for g in grids], fmu_paths=fmu_paths)
    assert expected in str(error.value)


def test_cli_reports_a_bad_grid_name_as_one_clear_error(fmu_paths, tmp_path, capsys):
    code = cli_main(["sweep", "pendulum_case1", "--grid", "plant.mass=0.1:1:2", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("error:") == 1 and "valid: gv, mc, mp" in err
    assert not (tmp_path / "sweep.csv").exists()


def test_grid_over_step_and_integer_parameters_is_accepted(fmu_paths):
    plan = sweep_grid.plan_sweep("pendulum_case1", ("vud", "fae"), [sweep_grid.parse_grid("step=1e-3,2e-3"),
                                                               sweep_grid.parse_grid("controller.fls_input=1,2")],
                            stop=0.1, fmu_paths=fmu_paths)
    assert len(plan.points()) == 8
    assert plan.points()[:2] == [("vud", (1e-3, 1.0)), ("fae", (1e-3, 1.0))]
    assert "step" not in plan.settings() and plan.settings()["stop"] == 0.1  # a resume ignores the scenario's step


# ------------------------------------------------------ local pool vs Dask
@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("local")
    started = time.perf_counter()
    assert cli_main(["sweep", *SMALL, "--out", str(out), "--jobs", "2"]) == 0
    return out, time.perf_counter() - started


def test_local_pool_sweep_records_every_point_with_scores_or_a_reason(fmu_paths, local_sweep):
    out, _ = local_sweep
    header, rows = rows_of(out / "sweep.csv")
    assert header == ["controller", "plant.mp", "controller.gamma", "ts", "es1_pct", "es2_pct", "ITAE", "IAE",
                      "Ec", "umax", "tv_u", "wall_s", "status", "reason"]
    assert len(rows) == 4 * len(variants.NAMES)  # --controller all: every variant of the registry x 4 points
    assert {key[0] for key in rows} == set(variants.NAMES)
    statuses = {key: cells[-2] for key, cells in rows.items()}
    assert all(statuses[(c, m, "300.0")] == "ok" for c in ("vud", "fixed", "fae") for m in ("0.1", "1.0"))
    assert all(statuses[(c, "0.1", "300000.0")] == "diverged" for c in ("vud", "fixed", "fae"))
    for key, cells in rows.items():
        if cells[-2] == "ok":  # on 0.5 s: es1, es2 not defined, ts not settled: empty, not numbers
            assert all(math.isfinite(float(v)) for v in cells[6:11]) and cells[-1] == ""
            assert cells[4:6] == ["", ""] and (cells[3] == "" or math.isfinite(float(cells[3])))
        else:
            assert cells[3:11] == [""] * 8 and "diverged" in cells[-1]
    # the same point through the run command's path gives the same ITAE, bit for bit
    from harness import scenario as scenarios
    from harness.master import simulate
    from harness.scores import score_run

    point = (scenarios.load("pendulum_case2").with_controller("fae").with_parameter("plant.mp", 1.0)
             .with_parameter("controller.gamma", 300.0).with_parameter("stop", 0.5).with_parameter("step", 1e-3))
    assert rows[("fae", "1.0", "300.0")][6] == repr(score_run(simulate(point, fmu_paths=fmu_paths))["ITAE"])
    assert (out / "heatmap_ITAE.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_dask_cluster_gives_the_same_rows_as_the_local_pool(fmu_paths, local_sweep, tmp_path, monkeypatch):
    distributed = pytest.importorskip("distributed")
    import dask

    out, _ = local_sweep
    scratch = tmp_path / "temp"  # the workers' FMU cache and Dask's scratch space, removed with tmp_path
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    with dask.config.set({"temporary-directory": str(scratch)}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                     dashboard_address=None) as cluster:
        assert cli_main(["sweep", *SMALL, "--out", str(tmp_path), "--scheduler", cluster.scheduler_address]) == 0
    assert rows_of(tmp_path / "sweep.csv") == rows_of(out / "sweep.csv")  # scores bit-identical
    assert (scratch / tasks.CACHE_FOLDER).is_dir()  # the workers cached the FMUs here, not in the real temp folder


def test_unreachable_scheduler_is_a_clear_error(fmu_paths, tmp_path, capsys, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(dask_pool, "SCHEDULER_TIMEOUT", "1s")
    code = cli_main(["sweep", *SMALL, "--out", str(tmp_path), "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2 and "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in capsys.readouterr().err


def test_failed_points_are_recorded_and_the_sweep_goes_on(fmu_paths, tmp_path):
    plan = sweep_grid.plan_sweep("pendulum_case1", ("fixed",), [sweep_grid.parse_grid("controller.lambda_ce=0.99,1.0")],
                            stop=0.1, step=1e-3, fmu_paths=fmu_paths)
    summary = sweep.run_sweep(plan, tmp_path, jobs=1, progress=False)
    assert summary.counts["fixed"] == {"ok": 1, "diverged": 0, "failed": 1}
    _, rows = rows_of(tmp_path / "sweep.csv")
    assert "lambda_ce = 1.0 is invalid" in rows[("fixed", "1.0")][-1]


def crash_on_heavy_payload(task, files):
    """A worker that dies (as on a crash inside an FMU) on the points with mp > 0.5."""
    if task["values"][0] > 0.5:
        os._exit(3)
    return sweep_executors.run_point(task, files)


def test_a_lost_worker_loses_points_not_the_sweep_and_resume_runs_them(fmu_paths, tmp_path):
    plan = sweep_grid.plan_sweep("pendulum_case1", ("vud",), [sweep_grid.parse_grid("plant.mp=0.1,1")],
                            stop=0.1, step=1e-3, fmu_paths=fmu_paths)
    first = sweep.run_sweep(plan, tmp_path, jobs=1, progress=False, point_function=crash_on_heavy_payload)
    assert (first.computed, first.lost) == (1, 1)  # the crashing point, run again alone, is lost; not the other
    assert "WorkerLost" in first.lost_reason and "exited with status 3" in first.lost_reason
    rows = sweep_csv.read_rows(tmp_path / "sweep.csv", plan.names)
    assert all(row["values"] == [0.1] for row in rows)  # a lost point leaves no row behind
    second = sweep.run_sweep(plan, tmp_path, jobs=1, progress=False)
    assert (second.done_before, second.computed, second.lost) == (first.computed, 2 - first.computed, 0)


# ---------------------------------------------------------- kill and resume
KILLED = ["pendulum_case2", "--controller", "vud", "--grid", "plant.mp=0.1:1:4", "--grid", "plant.dist_gain=0:2:2",
          "--stop", "3", "--step", "1e-3", "--jobs", "1", "--no-progress"]


def test_a_killed_sweep_resumes_without_recomputing_finished_points(fmu_paths, tmp_path):
    csv_path = tmp_path / "sweep.csv"
    scratch = tmp_path / "temp"  # a killed run cannot clean up: its FMU extractions stay in tmp_path
    scratch.mkdir()
    process = subprocess.Popen([sys.executable, "-m", "harness", "sweep", *KILLED, "--out", str(tmp_path)],
                               cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                               start_new_session=True, env=dict(os.environ, TMPDIR=str(scratch)))
    deadline = time.monotonic() + 60
    try:
        while time.monotonic() < deadline and process.poll() is None:
            if csv_path.exists() and csv_path.read_text().count("\n") >= 3:  # header + 2 rows
                break
            time.sleep(0.01)
    finally:
        os.killpg(process.pid, signal.SIGKILL)  # the sweep and its worker, no clean-up
        process.wait()
    assert process.returncode == -signal.SIGKILL, process.stderr.read().decode()
    _, before = rows_of(csv_path)
    assert 2 <= len(before) < 8
    lines_before = csv_path.read_text().splitlines()

    plan = sweep_grid.plan_sweep("pendulum_case2", ("vud",), [sweep_grid.parse_grid("plant.mp=0.1:1:4"),
                                                         sweep_grid.parse_grid("plant.dist_gain=0:2:2")],
                            stop=3, step=1e-3, fmu_paths=fmu_paths)
    summary = sweep.run_sweep(plan, tmp_path, jobs=2, progress=False, plot=False)
    assert (summary.done_before, summary.computed, summary.total) == (len(before), 8 - len(before), 8)
    _, after = rows_of(csv_path)
    assert len(after) == 8
    assert csv_path.read_text().splitlines()[:len(lines_before)] == lines_before  # finished rows unchanged
    assert all(after[key] == cells for key, cells in before.items())
    # a second resume has nothing left to do
    again = sweep.run_sweep(plan, tmp_path, jobs=2, progress=False, plot=False)
    assert (again.done_before, again.computed) == (8, 0)


def test_an_interrupted_sweep_stops_cleanly_and_resumes(fmu_paths, tmp_path):
    plan = sweep_grid.plan_sweep("pendulum_case1", ("vud", "fixed"), [sweep_grid.parse_grid("plant.mp=0.1:1:3")],
                            stop=0.3, step=1e-3, fmu_paths=fmu_paths)

    def interrupt(row, done):
        if done == 2:
            raise KeyboardInterrupt

    first = sweep.run_sweep(plan, tmp_path, jobs=1, progress=False, on_row=interrupt)
    assert first.interrupted and first.computed == 2 and first.heatmap_path.exists()
    second = sweep.run_sweep(plan, tmp_path, jobs=2, progress=False)
    assert not second.interrupted and (second.done_before, second.computed) == (2, 4)
    assert sum(sum(c.values()) for c in second.counts.values()) == 6


def test_resume_drops_a_row_cut_short_and_refuses_other_settings(fmu_paths, tmp_path):
    names = ["plant.mp"]
    row = {"controller": "vud", "values": [0.1], "scores": {k: 1.5 for k in sweep_csv.SCORE_KEYS}, "wall_s": 0.25,
           "status": "ok", "reason": ""}
    sink = sweep_csv.CsvSink(tmp_path / "sweep.csv", names, [])
    sink.write(row)
    sink.close()
    with open(tmp_path / "sweep.csv", "a") as stream:
        stream.write("vud,0.2,1.0,2.0")  # killed while writing
    assert sweep_csv.read_rows(tmp_path / "sweep.csv", names) == [row]
    with pytest.raises(ScenarioError, match="holds a sweep over plant.mp, not over plant.dist_gain"):
        sweep_csv.read_rows(tmp_path / "sweep.csv", ["plant.dist_gain"])
    plan = sweep_grid.plan_sweep("pendulum_case1", ("vud",), [sweep_grid.parse_grid("plant.mp=0.1,0.2")], stop=0.1,
                            step=1e-3, fmu_paths=fmu_paths)
    (tmp_path / "sweep.json").write_text('{"scenario": "pendulum_case1", "stop": 0.2}')
    with pytest.raises(ScenarioError, match=r"other settings \(stop: 0.2 then, 0.1 now\)"):
        sweep.run_sweep(plan, tmp_path, jobs=1, progress=False)


# ------------------------------------------------------------------ heat map
def test_heat_map_takes_the_worst_case_over_further_axes_and_marks_failures(fmu_paths, tmp_path):
    plan = sweep_grid.plan_sweep("pendulum_case1", ("vud", "fae"), [sweep_grid.parse_grid(g) for g in
                            ("plant.mp=0.1,1", "plant.dist_gain=0,1", "controller.kappa1=1,10")],
                            stop=0.1, step=1e-3, fmu_paths=fmu_paths)

    def row(controller, values, status, itae):
        return {"controller": controller, "values": values, "status": status, "wall_s": 0.1, "reason": "",
                "scores": {"ITAE": itae if status == "ok" else math.nan}}

    rows = [row("vud", [0.1, 0, 1], "ok", 0.5), row("vud", [0.1, 0, 10], "ok", 2.0),
            row("vud", [1, 0, 1], "ok", 0.1), row("vud", [1, 0, 10], "diverged", 0),
            row("vud", [0.1, 1, 1], "failed", 0), row("fae", [1, 1, 10], "ok", 30.0)]
    metric, status = sweep_heatmap.heatmap_arrays(plan, rows, "vud")
    assert status.tolist() == [[1, 2], [3, 0]]  # rows: dist_gain 0, 1; columns: mp 0.1, 1
    assert metric[0, 0] == 2.0 and math.isnan(metric[0, 1])
    path = sweep_heatmap.plot_heatmap(plan, rows, tmp_path / "map.png")
    assert path.stat().st_size > 1000
