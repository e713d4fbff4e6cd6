"""Regression against the committed reference results: every scenario x variant, a mutation, the rules.

The 12 cases and the gamma mutation run once per session in a process pool
(every core, about a minute on 2 cores); the other tests use fabricated runs
and temporary reference folders, so they cost nothing.
"""
import json
import os

import numpy as np
import pytest

from harness import scenario as scenarios
from harness import variants
from harness.studies import regression
from harness.cli import main as cli_main
from harness.studies.regression import Case, CaseRun

MUTATION = Case("pendulum_case1", "vud", overrides=(("controller.gamma", 290.0),))


@pytest.fixture(scope="session")
def regression_runs(fmu_paths):
    """The 12 reference cases plus the mutated one, in parallel processes."""
    cases = regression.all_cases() + [MUTATION]
    runs = regression.run_cases(cases, workers=os.cpu_count(), fmu_paths=fmu_paths)
    return {run.case: run for run in runs}


def test_all_twelve_cases_stay_inside_their_reference_tubes(regression_runs, tmp_path):
    cases = regression.all_cases()
    paper = {(n, c) for n in ("pendulum_case1", "pendulum_case2", "pendulum_case3", "manipulator")
             for c in ("vud", "fixed", "fae")}
    assert paper <= {(c.scenario, c.controller) for c in cases}
    # every scenario file x every variant of the registry (the paper's 12 and motor_arm's 3)
    assert len(cases) == len(scenarios.scenario_names()) * len(variants.NAMES) >= 15
    outcome = regression.regress(cases, runs=[regression_runs[c] for c in cases], report_dir=tmp_path)
    table = "\n".join(" | ".join(map(str, row)) for row in regression.summary_rows(outcome.comparisons))
    assert outcome.passed, f"regression failed (see {tmp_path / 'report.md'}):\n{table}"
    assert f"{len(cases)}/{len(cases)} cases pass" in (tmp_path / "report.md").read_text()


def test_gamma_290_instead_of_300_fails_and_the_unchanged_case_passes(regression_runs, tmp_path):
    unchanged = Case("pendulum_case1", "vud")
    outcome = regression.regress([unchanged, MUTATION], runs=[regression_runs[unchanged], regression_runs[MUTATION]],
                                 report_dir=tmp_path)
    same, mutated = outcome.comparisons
    assert same.passed
    assert not mutated.passed and not outcome.passed
    failing = [s for s in mutated.signals if not s.passed]
    assert {"controller.theta1", "controller.u"} <= {s.signal for s in failing}
    for signal in failing:  # largest excursion and where, and a picture of it
        assert signal.max_error > 0 and 0 <= signal.t_max_error <= 20
        assert signal.plot is not None and signal.plot.exists() and signal.plot.stat().st_size > 10_000
    report = (tmp_path / "report.md").read_text()
    assert "1/2 cases pass" in report and "controller.gamma=290" in report and ".png" in report


# ------------------------------------------------------------- the rules
def fabricated_run(case=Case("pendulum_case1", "vud"), scale=1.0, step=None) -> CaseRun:
    """A run made from the committed reference (optionally scaled): no simulation."""
    reference = regression.read_reference(case)
    signals = {name: values * scale for name, values in reference.signals.items()}
    return CaseRun(case, reference.meta["start"], reference.meta["stop"], step or reference.meta["step"],
                   reference.time.copy(), signals, 0.0)


def test_every_reference_file_is_a_case_of_the_registries():
    """A reference without its scenario file or its variant row (harness/variants.py) is stale or orphaned."""
    expected = {path.name for case in regression.all_cases() for path in regression.reference_paths(case)}
    assert {path.name for path in regression.REFERENCE_DIR.glob("*_ref.*")} == expected


def test_every_reference_is_committed_small_and_described():
    for case in regression.all_cases():
        csv_path, json_path = regression.reference_paths(case)
        assert csv_path.exists() and json_path.exists(), f"missing reference for {case.name}"
        size = csv_path.stat().st_size + json_path.stat().st_size  # 15 cases once stayed under 5 MB together
        assert size < 3e5, f"{case.name}: {size} bytes of reference (the budget is 300 kB a case)"
        header = csv_path.read_text().splitlines()[0]
        assert header == ",".join(f'"{n}"' for n in ["time", *regression.SIGNALS])
        meta = json.loads(json_path.read_text())
        assert meta["start"] == 0.0 and meta["stop"] == 20.0 and meta["points"] == regression.POINTS
        assert set(meta["tools"]) >= {"python", "fmpy", "pythonfmu", "numpy"} and meta["date"]
        assert "git_commit" in meta and "step" in meta and meta["wall_s"] > 0
        assert meta["scenario_hash"] == regression.scenario_fingerprint(case)[0], \
            f"{case.scenario}.toml changed since its references: run `python -m harness regress {case.scenario} --update`"
        reference = regression.read_reference(case)
        assert len(reference.time) == regression.POINTS and reference.time[-1] == 20.0
        assert all(np.all(np.isfinite(v)) for v in reference.signals.values())


def test_missing_reference_fails_with_the_hint_and_a_plain_run_writes_nothing(tmp_path):
    run = fabricated_run()
    outcome = regression.regress([run.case], runs=[run], reference_dir=tmp_path / "refs", report_dir=None)
    assert not outcome.passed
    message = outcome.comparisons[0].message
    assert "no reference" in message and "--update" in message
    assert not (tmp_path / "refs").exists()  # references change only through --update


def test_update_writes_references_that_then_pass(tmp_path):
    run = fabricated_run()
    outcome = regression.regress([run.case], runs=[run], reference_dir=tmp_path, update=True, report_dir=None)
    assert sorted(p.name for p in outcome.written) == ["pendulum_case1_vud_ref.csv", "pendulum_case1_vud_ref.json"]
    again = regression.regress([run.case], runs=[run], reference_dir=tmp_path, report_dir=None)
    assert again.passed
    with pytest.raises(ValueError, match="never becomes a reference"):
        regression.regress([MUTATION], runs=[fabricated_run(MUTATION)], reference_dir=tmp_path, update=True)


def test_scaled_result_fails_and_changed_step_is_reported(tmp_path):
    outcome = regression.regress([Case("pendulum_case1", "vud")], runs=[fabricated_run(scale=1.01)],
                                 report_dir=tmp_path)
    failing = {s.signal for s in outcome.comparisons[0].signals if not s.passed}
    assert "controller.theta1" in failing and "plant.y" in failing
    changed = regression.compare_case(fabricated_run(step=1e-3), regression.read_reference(Case("pendulum_case1",
                                                                                                 "vud")))
    assert not changed.passed and "experiment changed: reference step" in changed.message


def test_tube_passes_small_shift_and_flags_a_bump_where_it_is():
    x = np.linspace(0, 10, 1001)
    y = np.sin(x)
    shifted = regression.compare_signal("s", x, y, x, np.sin(x - 2e-4))
    assert shifted.passed and shifted.max_error == 0
    bump = regression.compare_signal("s", x, y, x, y + 0.05 * np.exp(-((x - 6.0) / 0.05) ** 2))
    assert not bump.passed and bump.t_max_error == pytest.approx(6.0, abs=0.02)
    assert bump.max_error == pytest.approx(0.05 - 1e-3 * 2 - 1e-3 * abs(np.sin(6.0)), abs=5e-3)
    diverged = regression.compare_signal("s", x, y, x, np.where(x > 5, np.nan, y))
    assert not diverged.passed and "non-finite" in diverged.message


def test_cli_exit_codes_and_hint(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(regression.command, "run_cases", lambda cases, **kw: [fabricated_run(c) for c in cases])
    assert cli_main(["regress", "pendulum_case1", "--controller", "vud", "--report", str(tmp_path)]) == 0
    assert "1/1 cases pass" in capsys.readouterr().out
    monkeypatch.setattr(regression.references, "REFERENCE_DIR", tmp_path / "empty")
    assert cli_main(["regress", "pendulum_case1", "--controller", "vud", "--report", str(tmp_path)]) == 1
    captured = capsys.readouterr()
    assert "regress pendulum_case1 --update" in captured.err and "FAIL" in captured.out
    assert cli_main(["regress", "pendulum_case9"]) == 2


@pytest.mark.parametrize("edition", ["native", "native3"])
def test_the_references_hold_for_the_native_edition(edition, tmp_path, capsys):
    from harness.fmu_build import native as build_native

    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e '.[native]')")
    assert cli_main(["regress", "--edition", edition, "--report", str(tmp_path)]) == 0
    count = len(regression.all_cases())
    assert f"{count}/{count} cases pass" in capsys.readouterr().out


def test_model_exchange_holds_to_references_of_its_own(tmp_path, capsys):
    """The co-simulation's references carry its O(step) error, beyond the tube in the controller's transient;
    Model Exchange has its own (harness/references/model_exchange/)."""
    from harness.fmu_build import native as build_native

    if not build_native.compiler_available():
        pytest.skip("zig's C compiler is not installed (pip install -e '.[native]')")
    for case in regression.all_cases(algorithm="me"):
        csv_path, json_path = regression.reference_paths(case, regression.MODEL_EXCHANGE_REFERENCE_DIR)
        meta = json.loads(json_path.read_text())
        assert csv_path.exists() and meta["algorithm"] == "me" and meta["rtol"] > 0
    assert cli_main(["regress", "pendulum_case1", "manipulator", "--controller", "vud", "--algorithm", "me",
                     "--edition", "native", "--report", str(tmp_path)]) == 0
    assert "2/2 cases pass" in capsys.readouterr().out
    # against the co-simulation's references instead: outside the tube in the transient
    from harness.fmu_build import builder as build_fmu

    outcome = regression.regress([Case("pendulum_case1", "fixed", algorithm="me")], report_dir=None,
                                 reference_dir=regression.REFERENCE_DIR, fmu_paths=build_fmu.ensure_built(edition="native"))
    assert not outcome.passed
    failed = {s.signal for c in outcome.comparisons for s in c.signals if not s.passed}
    assert "controller.theta1" in failed
