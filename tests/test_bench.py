"""The benchmark runs and reports every figure (speed targets are read from its output, not asserted)."""
import json

from harness.cli import main as cli_main


def test_bench_json_reports_every_figure(fmu_paths, capsys):
    assert cli_main(["bench", "--stop", "0.2", "--repeat", "1", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    for key in ("ours_feedthrough_us", "ours_jacobi_us", "floor_us", "oracle_us", "real_time_factor",
                "floor_ratio_to_ours", "target_floor_plus_oracle_x1_5_us", "fmu_plant_us", "fmu_controller_null_us"):
        assert figures[key] > 0, key
    assert figures["ours_feedthrough_whole_us"] >= figures["ours_feedthrough_us"]
    for key in ("fmpy_ssp_whole", "ecos"):  # an engine that fails is reported with a note, not hidden
        assert figures[f"{key}_us"] is not None or key in figures["notes"]
