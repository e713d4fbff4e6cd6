"""harness/studies/me_accuracy.py on a short horizon: Model Exchange at a tolerance ladder against the co-simulation
extrapolated to a zero step, every score, and the stuck-link evidence of the manipulator."""
from __future__ import annotations

import pytest

from harness.fmu_build import native as build_native
from harness import cli
from harness.studies import me_accuracy

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

STOP = 0.5  # s: the manipulator first stops at 0.183 s (vud) and slips again 5 ms later


@pytest.fixture(scope="module")
def study(monkeypatch_module):
    monkeypatch_module.setenv("AFC_EDITION", "native")
    return me_accuracy.accuracy_study([("pendulum_case1", "vud"), ("manipulator", "vud")], rtols=(1e-6, 1e-10),
                                      compare_rtol=1e-8, stop=STOP, jobs=2)


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as patch:
        yield patch


def test_the_tolerance_ladder_converges_to_the_co_simulation_limit(study):
    for row in study["rows"]:
        loose, tight = (me_accuracy.run_at(row, r)["error"] for r in (1e-6, 1e-10))
        assert all(abs(tight[m]) < abs(loose[m]) for m in ("ITAE", "IAE")), row["scenario"]
        assert me_accuracy.within_target(row, 1e-10, me_accuracy.METRICS), (row["scenario"], tight)
        assert me_accuracy.run_at(row, 1e-8)["steps"] > me_accuracy.run_at(row, 1e-6)["steps"]


def test_the_stuck_link_chatters_in_co_simulation_by_the_plant_step_against_the_step(study):
    """With one plant step per communication step the chatter of the stuck link is the same at h and h/4 (more
    zig-zags, each smaller: the same variation of u); more plant steps per communication step take u's variation
    inside the stop to Model Exchange's (docs/model_exchange_accuracy.md)."""
    (evidence,) = study["stick"]
    assert evidence["intervals"] and evidence["intervals"][0][0] == pytest.approx(0.183, abs=2e-3)
    runs = {(round(study["rows"][1]["step"] / c["step"]), c["plant_steps"]): c for c in evidence["co_simulation"]}
    assert set(runs) == set(me_accuracy.STICK_RUNS)
    coarse, fine = runs[(1, 1)], runs[(4, 1)]
    assert 0 < coarse["sign_changes"] < fine["sign_changes"] and fine["max_dy"] < coarse["max_dy"]
    me = evidence["me"]["tv_inside"]
    off = {key: abs(run["tv_inside"] - me) / me for key, run in runs.items()}
    assert off[(1, 1)] > 0.02 and off[(4, 1)] > 0.02  # h/4 alone does not remove it
    assert abs(coarse["tv_inside"] - fine["tv_inside"]) < 0.2 * abs(coarse["tv_inside"] - me)
    assert off[(1, 8)] < 0.25 * off[(1, 1)] and off[(1, 32)] < 0.25 * off[(1, 1)]  # more plant steps do
    assert evidence["me"]["scores"]["tv_u"] > 0 and all("scores" in run for run in runs.values())


def test_the_page_says_what_it_measured(study):
    text = me_accuracy.markdown(study)
    assert "## Every score at rtol 1e-08" in text and "## Where the link sticks" in text
    assert "of 2 cases at rtol 1e-10" in text


def test_apply_needs_the_full_horizon(tmp_path, capsys):
    status = cli.main(["me-accuracy", "pendulum_case1", "--controller", "vud", "--rtols", "1e-6", "--stop", "0.05",
                       "--edition", "native", "--out", str(tmp_path), "--apply"])
    assert status == 1 and "--apply needs the full horizon" in capsys.readouterr().err
    assert (tmp_path / "me_accuracy.md").exists()
