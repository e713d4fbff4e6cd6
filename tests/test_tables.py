"""End-to-end: `tables` on a shortened horizon (issue 5); the step study: tests/test_step_study.py."""
import csv
import re

from harness.cli import main as cli_main


def test_tables_writes_tables_report_and_figures(fmu_paths, tmp_path, capsys):
    code = cli_main(["tables", "--out", str(tmp_path), "--stop", "0.3", "--jobs", "2", "--refine", "0"])
    out = capsys.readouterr().out
    assert code == 0
    for name, scenarios in (("table1.csv", {"pendulum_case1", "pendulum_case2", "pendulum_case3"}),
                            ("table2.csv", {"manipulator"})):
        with open(tmp_path / name) as stream:
            header = stream.readline().strip()
            assert header.startswith("scenario,controller,ts,es1_pct,es2_pct,ITAE,IAE,Ec")
            stream.seek(0)
            rows = list(csv.DictReader(stream))
        assert {r["scenario"] for r in rows} == scenarios
        assert sorted(r["controller"] for r in rows) == sorted(["vud", "fixed", "fae"] * len(scenarios))
        assert all(r["status"] == "ok" and float(r["ITAE"]) > 0 for r in rows)
    report = (tmp_path / "report.md").read_text()
    assert "## Table I: inverted pendulum" in report and "## Table II" in report
    assert "## Claims of the paper, checked" in report
    verdicts = re.findall(r"(?m)^- \*\*([^*]+)\*\*: The ", report)
    assert len(verdicts) == 8, verdicts  # every claim has exactly one verdict...
    assert set(verdicts) <= {"reproduced", "not reproduced", "not decided at this accuracy"}, verdicts
    assert report.count(" ± ") >= 8 * 3  # ...stated with the numbers and their errors
    assert "(h = 0.0002 s" in report and "(h = 2.5e-05 s" in report  # decided on the h/2 runs
    assert "(h = 0.0004 s" not in report and "(h = 0.0001 s" not in report
    for name in ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator"):
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000
        assert f"({name}.png)" in report
    assert "claims (decided on the step ladders" in out
    with open(tmp_path / "table3_beyond_paper.csv") as stream:  # the third-order plant (issue 17)
        beyond = list(csv.DictReader(stream))
    assert sorted((r["controller"], r["sets"]) for r in beyond) == sorted(
        (c, m) for c in ("vud", "fixed", "fae") for m in ("2", "3"))
    assert all(r["scenario"] == "motor_arm" and r["status"] == "ok" and float(r["ITAE"]) > 0 for r in beyond)
    assert "## Beyond the paper: a third-order plant" in report and "| vud | 3 (27) |" in report



def test_tables_in_model_exchange_decide_the_claims_on_tolerance_ladders(tmp_path, capsys, monkeypatch):
    import pytest

    import build_native

    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e '.[native]')")
    code = cli_main(["tables", "--edition", "native", "--algorithm", "me", "--rtol", "1e-8", "--out", str(tmp_path),
                     "--stop", "0.3", "--jobs", "2", "--refine", "0"])
    assert code == 0, capsys.readouterr().err
    with open(tmp_path / "table2.csv") as stream:
        rows = list(csv.DictReader(stream))
    assert all(r["status"] == "ok" and r["validated_step"] == "" for r in rows)
    report = (tmp_path / "report.md").read_text()
    assert "one Model Exchange run (the native FMUs integrated together by CVODE, rtol 1e-08" in report
    assert "tolerance ladders" in report and report.count(" ± ") >= 8 * 3
    assert cli_main(["tables", "--rtol", "1e-8", "--out", str(tmp_path), "--stop", "0.1"]) == 2
    assert "--rtol is the tolerance of --algorithm me" in capsys.readouterr().err
