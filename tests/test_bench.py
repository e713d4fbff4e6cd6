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
