"""The benchmark measures what it says (speed targets are read from its output, not asserted):
every figure is present, finite and positive, the ratios are the figures' ratios, and the
master run it times computes the same loop as the oracle it times.  No figure is compared
with another (floor < ours holds on a quiet machine, not on a loaded one: not a test)."""
import json
import math

import pytest

from harness.cli import main as cli_main

STOP, STEP = 0.2, 5e-4  # pendulum_case1's step (docs/convergence.md)


def test_bench_json_reports_every_figure_and_times_the_right_runs(fmu_paths, capsys):
    assert cli_main(["bench", "--stop", str(STOP), "--repeat", "1", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["steps"] == round(STOP / figures["step"]) and figures["step"] == STEP
    assert figures["master_loop"] in ("compiled", "python")
    for key in ("ours_feedthrough_us", "ours_feedthrough_whole_us", "ours_jacobi_us", "ours_jacobi_whole_us",
                "floor_us", "oracle_us", "real_time_factor", "floor_ratio_to_ours", "oracle_ratio_to_ours",
                "ours_jacobi_ratio_to_ours", "target_floor_plus_oracle_x1_5_us",
                *(f"fmu_{name}{kind}_us" for name in ("plant", "reference", "controller") for kind in ("", "_null"))):
        value = figures[key]
        assert isinstance(value, float) and math.isfinite(value) and value > 0, (key, value)
    ours = figures["ours_feedthrough_us"]
    assert figures["ours_feedthrough_whole_us"] >= ours  # the whole run includes the loop
    assert math.isclose(figures["real_time_factor"], figures["step"] / (ours * 1e-6))
    for key in ("floor", "oracle", "ours_jacobi"):
        assert math.isclose(figures[f"{key}_ratio_to_ours"], figures[f"{key}_us"] / ours), key
    assert math.isclose(figures["target_floor_plus_oracle_x1_5_us"],
                        1.5 * (figures["floor_us"] + figures["oracle_us"]))
    # the timed master run and the timed oracle run are the same closed loop (to rounding)
    assert figures["oracle_max_abs_difference"] is not None and figures["oracle_max_abs_difference"] < 1e-9
    for key in ("fmpy_ssp_whole", "ecos", "native_feedthrough", "libcosim_native", "libcosim_python",
                "ours_feedthrough_python_loop", "native_feedthrough_python_loop", "libcosim_native_scored",
                "libcosim_native_recorded", "libcosim_native_every"):
        # an engine that fails (or a native edition without compiler) is reported with a note, not hidden
        value = figures[f"{key}_us"]
        if value is None:
            assert key in figures["notes"] and figures["notes"][key], key
        else:
            assert math.isfinite(value) and value > 0, key


def test_bench_times_the_main_job_in_both_editions_when_asked(monkeypatch, capsys):
    from harness.hosts import bench

    monkeypatch.setattr(bench, "bench", lambda *args: {**FAKE_FIGURES, "notes": {}})
    timed = []
    monkeypatch.setattr(bench, "tables_wall_seconds", lambda edition, algorithm=None: timed.append((edition, algorithm))
                        or {("native", None): 5.4, ("native", "me"): 6.1}[(edition, algorithm)])
    assert cli_main(["bench", "--tables"]) == 0
    output = capsys.readouterr().out
    assert timed == [("native", None), ("native", "me"), ("python", None)]
    assert "target: `tables --edition native` (the Table I/II report, " in output
    assert "<= 10 s wall: 5.4 s; pythonfmu edition: failed KeyError: ('python', None)" in output
    assert "target: `tables --edition native --algorithm me` (Model Exchange) <= 10 s wall: 6.1 s" in output


def test_the_main_job_is_timed_as_a_user_runs_it(fmu_paths):
    from harness.hosts import bench

    assert bench.tables_wall_seconds("python", stop=0.05) > 0
    with pytest.raises(RuntimeError, match=r"tables --edition native failed: .*--stop"):
        bench.tables_wall_seconds("native", stop=-1.0)  # the command really runs, and its failure is said


FAKE_FIGURES = {"scenario": "pendulum_case1", "controller": "vud", "step": 5e-4, "stop": 0.1, "steps": 200,
                "repeat": 1, "master_loop": "python", "ours_feedthrough_us": 10.0, "ours_feedthrough_whole_us": 12.0,
                "real_time_factor": 50.0, "oracle_max_abs_difference": 0.0, "target_floor_plus_oracle_x1_5_us": 20.0}


# ------------------------------------------------ the native master against a plain C host and the floor
def test_the_native_section_times_ours_the_c_host_and_the_floor_at_each_horizon(monkeypatch):
    """Every figure of every horizon is measured (finite, > 0), the ratios are the figures' ratios, the cold run
    is a `run` of its own process; a figure is the best of its repeats."""
    from harness.fmu_build import native as build_native
    from harness.hosts import bench_c_baselines

    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed")
    native = {name: paths[2] for name, paths in build_native.ensure_built().items()}
    colds = []
    cold = bench_c_baselines.cold_run_us_per_step
    monkeypatch.setattr(bench_c_baselines, "cold_run_us_per_step", lambda stop: colds.append(stop) or cold(stop))
    rows = bench_c_baselines.measure(native, (0.05, 0.1), repeat=2)
    assert [row["stop"] for row in rows] == [0.05, 0.1] and [row["steps"] for row in rows] == [100, 200]
    assert colds == [0.05, 0.1, 0.05, 0.1]  # one cold run per horizon and repeat (at most COLD_REPEAT)
    for row in rows:
        for key in ("ours_us", "ours_cold_us", "host_us", "floor_us", "ours_cpu_us", "host_cpu_us", "floor_cpu_us"):
            assert math.isfinite(row[key]) and row[key] > 0, (key, row)
        assert math.isclose(row["ours_to_host"], row["ours_us"] / row["host_us"])
        assert math.isclose(row["ours_cold_to_host"], row["ours_cold_us"] / row["host_us"])
        assert math.isclose(row["host_to_floor"], row["host_us"] / row["floor_us"])
        assert math.isclose(row["ours_to_host_cpu"], row["ours_cpu_us"] / row["host_cpu_us"])
        assert math.isclose(row["host_to_floor_cpu"], row["host_cpu_us"] / row["floor_cpu_us"])


def test_the_native_section_prints_every_figure_and_the_worst_ratios(capsys):
    from harness.hosts import bench_c_baselines

    rows = [{"stop": 1.0, "steps": 2000, "ours_us": 0.41, "ours_cold_us": 0.52, "host_us": 0.38, "floor_us": 0.27,
             "ours_cpu_us": 0.40, "host_cpu_us": 0.37, "floor_cpu_us": 0.26},
            {"stop": 20.0, "steps": 40000, "ours_us": 0.44, "ours_cold_us": None, "host_us": 0.40, "floor_us": 0.30,
             "ours_cpu_us": 0.39, "host_cpu_us": 0.36, "floor_cpu_us": 0.25}]
    for row in rows:
        row.update(ours_to_host=row["ours_us"] / row["host_us"], host_to_floor=row["host_us"] / row["floor_us"],
                   ours_cold_to_host=row["ours_cold_us"] / row["host_us"] if row["ours_cold_us"] else None,
                   ours_to_host_cpu=row["ours_cpu_us"] / row["host_cpu_us"],
                   host_to_floor_cpu=row["host_cpu_us"] / row["floor_cpu_us"])
    counts = {loop: {"total": total, "libm": 1609.0, "fmus": 1700.0, "loop": total - 3309.0, "other": 0.0}
              for loop, total in (("ours", 3780.0), ("host", 3445.0), ("floor", 2209.0 + 3309.0 - 1609.0 - 1700.0))}
    counts["floor"].update(fmus=0.0, loop=600.0, total=2209.0)
    bench_c_baselines.print_section(rows, 7, counts)
    out = capsys.readouterr().out
    assert "best of 7 interleaved (cold runs: of 5)" in out
    assert "       1s  2000   0.41   0.52   0.38   0.27      1.08      1.37       1.41   0.40   0.37   0.26      1.08" in out
    assert "      20s 40000   0.44          0.40   0.30      1.10                 1.33" in out  # no cold run: blank
    assert "worst 1.10 wall, 1.08 CPU, 1.37 for a cold `run`" in out
    assert "the C host <= 1.4 x the floor at every horizon: worst 1.41 wall, 1.44 CPU" in out
    assert "instructions: ours / C host 1.097, C host / floor 1.560" in out  # to 0.001: 1.4 is a target
    assert "     ours    3780    1609    1700     471       0" in out


@pytest.mark.parametrize("text", ["", "1,,2", "0,1", "1,inf", "one"])
def test_a_bad_horizon_list_is_one_line(text, capsys):
    assert cli_main(["bench", "--edition", "native", "--horizons", text]) == 2
    assert "argument --horizons:" in capsys.readouterr().err


def test_instruction_counts_need_the_native_edition(capsys):
    assert cli_main(["bench", "--edition", "python", "--instructions"]) == 2
    assert "--instructions counts the native loops: add --edition native" in capsys.readouterr().err
