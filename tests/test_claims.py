"""The verdict logic of the claims check (harness/studies/claims.py) on synthetic step ladders."""
import math

import pytest

from harness.studies import claims, tables
from harness.studies.claims import NOT_REPRODUCED, REPRODUCED, UNDECIDED, Estimate

STEP = 4e-4
METRICS = ("ts", "es1_pct", "es2_pct", "ITAE", "IAE", "Ec", "tv_u")
# a comfortable default: vud clearly best in every score, smooth, unchanged by the disturbance
DEFAULT = {"vud": 1.0, "fixed": 2.0, "fae": 3.0}


def outcome(name, controller, step, plant=None, **scores):
    """A run at the communication step ``step`` with the plant's internal step ``plant`` (default: the step)."""
    return {"scenario": name, "controller": controller, "step": step, "plant_step": plant or step, "status": "ok",
            **scores}


def ladders(overrides=None, change=1e-4):
    """{(scenario, controller): [row at h, row at h/2, row at h with half the plant step]}; every score
    DEFAULT[controller] at h/2 and that plus ``change`` at h (and at h with half the plant step), except
    ``overrides[(scenario, controller, metric)] = (at h, at h/2[, at h with half the plant step])``."""
    overrides = overrides or {}
    result = {}
    for name in claims.ALL_SCENARIOS:
        for controller in claims.CONTROLLERS:
            coarse, fine, plant = {}, {}, {}
            for metric in METRICS:
                values = overrides.get((name, controller, metric), (DEFAULT[controller] + change, DEFAULT[controller]))
                coarse[metric], fine[metric] = values[:2]
                plant[metric] = values[2] if len(values) > 2 else values[0]
            result[(name, controller)] = [outcome(name, controller, STEP, **coarse),
                                          outcome(name, controller, STEP / 2, **fine),
                                          outcome(name, controller, STEP, STEP / 2, **plant)]
    return result


def claim_on(ladder_set, metric):
    label = {"ts": "settling time", "es1_pct": "es1", "es2_pct": "es2", "ITAE": "smallest ITAE",
             "IAE": "smallest IAE", "Ec": "control energy", "tv_u": "smooth"}[metric]
    return next(c for c in claims.claims_check(ladder_set) if label in c.label)


# ------------------------------------------------------------------ estimates
def test_an_estimate_is_the_finest_value_with_the_changes_of_both_axes():
    """Value at the finest step; error 1.25 x (change over the last halving + 2 x the change the plant's half
    internal step makes at h)."""
    rows = [outcome("s", "vud", 4e-4, Ec=418.234), outcome("s", "vud", 2e-4, Ec=418.222),
            outcome("s", "vud", 4e-4, 2e-4, Ec=418.230)]  # any order
    found = claims.estimate(rows[::-1], "Ec")
    assert found.value == 418.222 and found.step == 2e-4 and found.plant_step == 2e-4
    assert found.error == pytest.approx(claims.SAFETY_FACTOR * (0.012 + 2 * 0.004))  # first order: 2 x to h_p / 2
    assert claims.SAFETY_FACTOR == 1.25
    coarser = [outcome("s", "vud", 4e-4, 1e-4, Ec=418.234), outcome("s", "vud", 2e-4, 5e-5, Ec=418.222),
               outcome("s", "vud", 4e-4, 2e-4, Ec=418.242)]  # h holds four plant steps: the axis runs 2 h_p
    found = claims.estimate(coarser, "Ec")
    assert found.plant_step == 5e-5 and found.error == pytest.approx(1.25 * (0.012 + 0.008))  # the change itself


def test_a_smooth_plant_has_no_plant_axis_and_no_plant_error_of_its_own():
    """Rows that say their plant is smooth (``plant_axis`` False): the error is the communication axis' alone; the
    same rows from a plant that switches, without their plant-axis run, have an unknown error."""
    rows = [dict(outcome("s", "vud", 4e-4, Ec=418.234), plant_axis=False),
            dict(outcome("s", "vud", 2e-4, Ec=418.222), plant_axis=False)]
    found = claims.estimate(rows, "Ec")
    assert found.value == 418.222 and found.error == pytest.approx(claims.SAFETY_FACTOR * 0.012) and not found.note
    switching = [dict(row, plant_axis=True) for row in rows]
    assert claims.estimate(switching, "Ec").error == math.inf
    assert claims.estimate(switching, "Ec").note == "no run at another plant step"


def test_the_plant_axis_sees_what_halving_the_step_with_the_plant_step_cannot():
    """The manipulator's stuck phases: the same h_p / h at h and h/2 gives the same chatter (a change of 0.04),
    half the plant step at h removes most of it (1.44): the error is the plant's, not the step's."""
    rows = [outcome("manipulator", "vud", 5e-5, tv_u=10.476), outcome("manipulator", "vud", 2.5e-5, tv_u=10.432),
            outcome("manipulator", "vud", 5e-5, 2.5e-5, tv_u=9.036)]
    found = claims.estimate(rows, "tv_u")
    assert found.value == 10.432 and found.error > 10.432 - 8.4693  # bounds the distance to the continuous value
    assert found.error == pytest.approx(1.25 * (0.044 + 2 * 1.44))


def test_three_halvings_must_show_convergence_or_the_error_is_unknown():
    def rows(*values):
        steps = [4e-4, 2e-4, 1e-4][:len(values)]
        return [outcome("s", "vud", h, Ec=v) for h, v in zip(steps, values)] + [outcome("s", "vud", 4e-4, 2e-4,
                                                                                         Ec=values[0])]
    first_order = claims.estimate(rows(418.234, 418.222, 418.216), "Ec")  # changes 0.012, 0.006
    assert first_order.value == 418.216 and first_order.error == pytest.approx(1.25 * 0.006)
    slow = claims.estimate(rows(418.234, 418.224, 418.216), "Ec")  # 0.010, 0.008: q = 0.8, error 4 x the change
    assert slow.error == pytest.approx(1.25 * 0.008 * 0.8 / 0.2)
    growing = claims.estimate(rows(418.234, 418.230, 418.220), "Ec")  # 0.004, 0.010: no convergence shown
    assert growing.error == math.inf and "no convergence shown" in growing.note
    assert claims.compare(growing, Estimate(500.0, 0.0, STEP))[0] == claims.OPEN


def test_an_estimate_without_its_rungs_has_an_infinite_error_and_a_failed_run_none():
    assert claims.estimate([outcome("s", "vud", 2e-4, Ec=1.0)], "Ec").error == math.inf
    assert claims.estimate([outcome("s", "vud", 8e-4, Ec=1.0), outcome("s", "vud", 2e-4, Ec=1.0)],
                           "Ec").error == math.inf  # no plant-axis run
    no_plant = claims.estimate([outcome("s", "vud", 4e-4, Ec=1.0), outcome("s", "vud", 2e-4, Ec=1.0)], "Ec")
    assert no_plant.error == math.inf and no_plant.note == "no run at another plant step"
    failed = [outcome("s", "vud", 4e-4, Ec=1.0), {"scenario": "s", "controller": "vud", "step": 2e-4,
                                                  "status": "diverged"}]
    assert claims.estimate(failed, "Ec") is None
    plant_failed = [outcome("s", "vud", 4e-4, Ec=1.0), outcome("s", "vud", 2e-4, Ec=1.0),
                    dict(outcome("s", "vud", 4e-4, 2e-4), status="failed")]
    assert claims.estimate(plant_failed, "Ec").error == math.inf


def test_settling_time_is_quantised_to_the_grid_so_its_error_is_at_least_one_step():
    rows = [outcome("s", "vud", 4e-4, ts=0.6984), outcome("s", "vud", 2e-4, ts=0.6984),
            outcome("s", "vud", 4e-4, 2e-4, ts=0.6984)]
    assert claims.estimate(rows, "ts").error == 2e-4
    assert claims.estimate(rows, "ts").value == 0.6984
    # a change of one grid step after none is quantisation, not a ladder that fails to converge
    rows += [outcome("s", "vud", 1e-4, 1e-4, ts=0.6983)]
    assert claims.estimate(rows, "ts").error == pytest.approx(1.25 * 1e-4)


def test_a_run_not_settled_within_the_horizon_settles_after_every_run_that_does():
    """pendulum_case3 / fixed: |e| enters the band too late to stay in it for a reference period (ts None on a
    20 s horizon): vud, which settles, is below it; two unsettled runs decide nothing and ask no finer run."""
    ladder_set = ladders()
    for row in ladder_set[("pendulum_case3", "fixed")]:
        row.update(ts=None, start=0.0, stop=20.0)
    claim = claim_on(ladder_set, "ts")
    line = next(d for d in claim.details if d.startswith("pendulum_case3"))
    assert "fixed not settled within the horizon" in line and "fixed does not settle within the horizon" in line
    assert line.endswith(": reproduced"), line
    for row in ladder_set[("pendulum_case3", "vud")]:
        row.update(ts=None, start=0.0, stop=20.0)
    claim = claim_on(ladder_set, "ts")
    line = next(d for d in claim.details if d.startswith("pendulum_case3"))
    assert "neither vud nor fixed settles within the horizon" in line and claim.verdict == NOT_REPRODUCED
    assert not {key for key in claim.open_cases if key[0] == "pendulum_case3"}


def test_compare_needs_the_gap_to_exceed_the_sum_of_both_errors():
    assert claims.compare(Estimate(1.0, 0.1, STEP), Estimate(1.3, 0.1, STEP))[0] == claims.BELOW
    assert claims.compare(Estimate(1.3, 0.1, STEP), Estimate(1.0, 0.1, STEP))[0] == claims.ABOVE
    assert claims.compare(Estimate(1.0, 0.1, STEP), Estimate(1.15, 0.1, STEP))[0] == claims.OPEN
    assert claims.compare(Estimate(1.0, 0.0, STEP), Estimate(1.0, 0.0, STEP))[0] == claims.OPEN  # a tie


# ------------------------------------------------------------------ verdicts
def test_clear_win_everywhere_is_reproduced():
    for claim in claims.claims_check(ladders()):
        assert claim.verdict == REPRODUCED, claim
        assert not claim.open_cases


def test_clear_loss_in_one_scenario_is_not_reproduced():
    ladder_set = ladders({("manipulator", "fae", "ITAE"): (0.5001, 0.5)})  # fae below vud's 1.0
    claim = claim_on(ladder_set, "ITAE")
    assert claim.verdict == NOT_REPRODUCED
    assert "manipulator: vud 1.0" in claim.details[-1] and "clearly above" in claim.details[-1]
    assert not claim.open_cases  # nothing a finer step could change


def test_a_tie_is_not_decided():
    ladder_set = ladders({("pendulum_case2", "fixed", "IAE"): (1.0001, 1.0)})  # fixed equal to vud
    claim = claim_on(ladder_set, "IAE")
    assert claim.verdict == UNDECIDED
    assert claim.open_cases == {("pendulum_case2", "vud"), ("pendulum_case2", "fixed")}


def test_a_gap_below_the_numerical_error_is_not_decided_the_issue_case_1_ec():
    """The step study's numbers: vud 418.234 -> 418.222, fae 418.322 -> 418.169 (0.4 -> 0.2 ms)."""
    ladder_set = ladders({("pendulum_case1", "vud", "Ec"): (418.234, 418.222),
                          ("pendulum_case1", "fixed", "Ec"): (430.500, 430.485),
                          ("pendulum_case1", "fae", "Ec"): (418.322, 418.169)})
    claim = claim_on(ladder_set, "Ec")
    assert claim.verdict == UNDECIDED
    line = claim.details[0]
    assert "vud 418.222 ± 0.015" in line and "fae 418.17 ± 0.19" in line, line  # 1.25 x the changes
    assert "undecided: gap 0.053 <= error 0.206" in line, line
    assert claim.open_cases == {("pendulum_case1", "vud"), ("pendulum_case1", "fae")}
    assert claims.undecided_cases(claims.claims_check(ladder_set)) == claim.open_cases
    # the same gap with small errors is decided: the logic is not "never decide"
    for row in ladder_set[("pendulum_case1", "fae")][::2]:  # at h, and at h with half the plant step
        row["Ec"] = 418.170
    assert claim_on(ladder_set, "Ec").verdict == NOT_REPRODUCED


def test_a_finer_run_decides_what_h_and_h_half_left_open():
    """Appending the 0.1 ms runs (converged: fae ahead) turns case-1 Ec into not reproduced."""
    ladder_set = ladders({("pendulum_case1", "vud", "Ec"): (418.234, 418.222),
                          ("pendulum_case1", "fae", "Ec"): (418.322, 418.169)})
    ladder_set[("pendulum_case1", "vud")].append(outcome("pendulum_case1", "vud", STEP / 4, Ec=418.217))
    ladder_set[("pendulum_case1", "fae")].append(outcome("pendulum_case1", "fae", STEP / 4, Ec=418.096))
    for controller in ("vud", "fae"):  # the other scores of the finer run: unchanged
        ladder_set[("pendulum_case1", controller)][-1].update(
            {m: DEFAULT[controller] for m in METRICS if m != "Ec"})
    claim = claim_on(ladder_set, "Ec")
    assert claim.verdict == NOT_REPRODUCED
    assert "h = 0.0001 s" in claim.details[0]


def test_one_open_comparison_among_wins_leaves_the_claim_open_and_a_loss_closes_it():
    open_one = {("pendulum_case3", "fae", "es1_pct"): (1.2, 1.0)}  # vud 1.0 +- 1e-4 vs 1.0 +- 0.2
    assert claim_on(ladders(open_one), "es1_pct").verdict == UNDECIDED
    with_loss = {**open_one, ("pendulum_case1", "fixed", "es1_pct"): (0.5, 0.5)}
    claim = claim_on(ladders(with_loss), "es1_pct")
    assert claim.verdict == NOT_REPRODUCED and not claim.open_cases


def test_a_failed_run_leaves_its_comparisons_undecided():
    ladder_set = ladders()
    ladder_set[("pendulum_case2", "fae")][1]["status"] = "diverged"
    claim = claim_on(ladder_set, "ITAE")
    assert claim.verdict == UNDECIDED
    assert any("pendulum_case2: no ITAE (fae: run diverged)" in d for d in claim.details)


def test_disturbance_claim_within_outside_and_at_the_tolerance():
    def with_case2(itae_h, itae_half):
        return ladders({("pendulum_case2", "vud", "ITAE"): (itae_h, itae_half)})

    disturbance = lambda s: next(c for c in claims.claims_check(s) if "disturbance" in c.label)  # noqa: E731
    assert disturbance(with_case2(1.05, 1.05)).verdict == REPRODUCED  # +5 % +- 0 against 1.0
    assert disturbance(with_case2(1.20, 1.20)).verdict == NOT_REPRODUCED  # +20 %
    undecided = disturbance(with_case2(1.12, 1.09))  # +9 % +- 3 %
    assert undecided.verdict == UNDECIDED
    assert undecided.open_cases == {("pendulum_case1", "vud"), ("pendulum_case2", "vud")}
    assert "ITAE +9 % ± 3.8 %" in undecided.details[0], undecided.details[0]


def test_smoothness_allows_ten_percent_above_the_smoother_comparison_controller():
    smooth = ladders({("manipulator", "vud", "tv_u"): (2.1, 2.1)})  # 1.05 x fixed's 2.0
    assert claim_on(smooth, "tv_u").verdict == REPRODUCED
    rough = ladders({("manipulator", "vud", "tv_u"): (2.4, 2.4)})  # 1.2 x fixed
    assert claim_on(rough, "tv_u").verdict == NOT_REPRODUCED
    assert "1.1 x fixed 2.2" in claim_on(rough, "tv_u").details[-1]


def test_report_lines_name_each_verdict_exactly_once_per_claim():
    ladder_set = ladders({("pendulum_case1", "fae", "Ec"): (1.5, 0.9)})
    lines = claims.claims_markdown(claims.claims_check(ladder_set))
    bullets = [line for line in lines if line.startswith("- **")]
    assert len(bullets) == 8
    assert sum(line.startswith(f"- **{UNDECIDED}**") for line in bullets) == 1
    assert sum(line.startswith(f"- **{REPRODUCED}**") for line in bullets) == 7


def test_plus_minus_keeps_two_digits_of_the_error():
    assert claims.plus_minus(418.2224523, 0.0114751) == "418.222 ± 0.011"
    assert claims.plus_minus(0.3208236, 1.1e-5) == "0.320824 ± 1.1e-05"
    assert claims.plus_minus(1.0, 0.0) == "1 ± 0"
    assert claims.plus_minus(1.0, math.inf) == "1 ± ?"


# ------------------------------------------------------------------ refinement (tables --refine)
def test_refinement_runs_the_open_cases_at_half_their_finest_step_and_decides_again(monkeypatch):
    """refine_open_claims asks for exactly the cases of open comparisons, at half their finest
    step, appends their runs and decides again; it stops when nothing is open."""
    ladder_set = ladders({("pendulum_case1", "vud", "Ec"): (418.234, 418.222),
                          ("pendulum_case1", "fixed", "Ec"): (430.500, 430.485),
                          ("pendulum_case1", "fae", "Ec"): (418.322, 418.169)})
    for case in (2, 3):  # vud least in the other cases
        for controller in ("fixed", "fae"):
            for row in ladder_set[(f"pendulum_case{case}", controller)]:
                row["Ec"] = 500.0
    assert [c.verdict for c in claims.claims_check(ladder_set) if "control energy" in c.label] == [UNDECIDED]
    finer = {"vud": 418.217, "fae": 418.096}  # the 0.1 ms runs of the step study
    requested = []

    native = {"Manipulator": "native/Manipulator.fmu"}  # the FMUs the ladders run on, handed through

    def fake_run_cases(cases, jobs=None, description="", progress=None, fmu_paths=None):
        assert fmu_paths is native
        requested.append([(c.scenario, c.controller, c.step) for c in cases])
        return [outcome(c.scenario, c.controller, c.step,
                        **{m: DEFAULT[c.controller] for m in METRICS if m != "Ec"}, Ec=finer[c.controller])
                for c in cases]

    monkeypatch.setattr(tables, "run_cases", fake_run_cases)
    found, refined = tables.refine_open_claims(ladder_set, stop=None, jobs=1, levels=3, fmu_paths=native)
    assert len(requested) == 1  # one level was enough
    assert sorted(requested[0]) == [("pendulum_case1", "fae", STEP / 4), ("pendulum_case1", "vud", STEP / 4)]
    assert sorted(refined) == sorted(requested[0])
    assert [c.verdict for c in found if "control energy" in c.label] == [NOT_REPRODUCED]
    assert all(c.verdict != UNDECIDED for c in found)
    requested.clear()
    assert tables.refine_open_claims(ladders(), stop=None, jobs=1, levels=3)[1] == []
    assert requested == []  # nothing open: nothing run


# ------------------------------------------------------------------ close margins, undefined scores
def test_a_comparison_decided_by_a_small_margin_says_close():
    """Numbers like case 1 Ec of a run of ours: fae below vud by a gap of 0.02 %, beyond both errors."""
    ladder_set = ladders({("pendulum_case1", "vud", "Ec"): (418.2253, 418.2182),
                          ("pendulum_case1", "fixed", "Ec"): (430.5, 430.5),
                          ("pendulum_case1", "fae", "Ec"): (418.180, 418.114)})
    claim = claim_on(ladder_set, "Ec")
    assert claim.verdict == NOT_REPRODUCED
    assert ("fae 418.114 ± 0.083 (h = 0.0002 s, plant step 0.0002 s; vud just above (close: by 0.025 %): gap 0.104 > "
            "error 0.0914)") in claim.details[0], claim.details[0]
    assert claim.close == ["pendulum_case1 (Ec: vud vs fae by 0.025 %)"]
    bullet = next(line for line in claims.claims_markdown([claim]) if line.startswith("- **"))
    assert bullet.endswith("(close: decided by a margin under 1 % of the values, beyond the numerical error: "
                           "pendulum_case1 (Ec: vud vs fae by 0.025 %))"), bullet
    clear = claim_on(ladders({("pendulum_case1", "fae", "Ec"): (0.5001, 0.5)}), "Ec")  # fae at half of vud
    assert clear.verdict == NOT_REPRODUCED and clear.close == [] and "clearly above" in clear.details[0]
    wins = claims.claims_check(ladders())  # 1.0 against 2.0 and 3.0: nothing close
    assert all(not c.close for c in wins)
    assert all("close" not in line for line in claims.claims_markdown(wins))


def test_a_score_the_horizon_does_not_define_decides_nothing_and_asks_no_finer_run():
    """On a 0.3 s run es1, es2 are n/a in the tables, so the claims must not decide them."""
    ladder_set = ladders()
    for rows in ladder_set.values():
        for row in rows:
            row.update(start=0.0, stop=0.3, es1_pct=None, es2_pct=None)
    for metric in ("es1_pct", "es2_pct"):
        claim = claim_on(ladder_set, metric)
        assert claim.verdict == UNDECIDED and not claim.open_cases
        assert claim.details[0] == (f"pendulum_case1: no {metric} (vud, fixed, fae: the horizon 0.3 s is shorter than "
                                    "the reference period, 2 pi s, over which es1 and es2 are taken)")
    unsettled = ladders()
    unsettled[("manipulator", "vud")][1].update(ts=None, start=0.0, stop=0.3)
    claim = claim_on(unsettled, "ts")
    assert claim.verdict == UNDECIDED and not claim.open_cases
    assert claim.details[-1].startswith("manipulator: no ts (vud: |e| does not stay inside the 5 % band of max|ym| "
                                        "for one reference period (2 pi s) before the stop time 0.3 s"), claim.details[-1]


# ------------------------------------------------------------------ the runs of a ladder (harness/studies/ladders.py)
@pytest.mark.parametrize("name, step, internal", [("manipulator", 5e-5, 6.25e-6), ("pendulum_case1", 5e-4, 2.5e-4),
                                                  ("pendulum_case3", 4e-4, 4e-4)])
def test_the_ladder_halves_the_step_with_the_plant_step_and_the_plant_step_alone(name, step, internal):
    """The communication axis keeps h_p / h (the manipulator's chatter is set by it), the plant axis doubles h_p at
    h (halves it where h holds one plant step); each run's row says its plant step; a finer rung halves both."""
    from harness.cases import Case
    from harness.studies import ladders as ladder_runs

    case = Case(name, "vud", figure_interval=0.01)
    assert ladder_runs.plant_step(case.build()) == pytest.approx(internal, rel=1e-12)
    switching = name == "manipulator"  # Coulomb friction: the only plant whose right-hand side switches
    half, *plant_axis = ladder_runs.ladder_cases(case)
    assert len(plant_axis) == switching and ladder_runs.needs_plant_axis(case.build()) == switching
    plant = plant_axis[0] if switching else ladder_runs.plant_step_case(case, smooth_too=True)
    other = 2 * internal if step >= 2 * internal else internal / 2  # the cheaper run where h holds two
    for run, expected in ((half, (step / 2, internal / 2)), (plant, (step, other))):
        built = run.build()
        assert (built.step, ladder_runs.plant_step(built)) == pytest.approx(expected, rel=1e-12), run.label
        assert run.figure_interval is None and run.controller == "vud"
        row = ladder_runs.ladder_row(run, {"step": built.step})
        assert row["plant_step"] == pytest.approx(expected[1]) and row["plant_axis"] == switching
    rows = [ladder_runs.ladder_row(c, {"step": c.build().step}) for c in (case, half, plant)]
    finer = ladder_runs.finer_case(name, "vud", rows, None).build()
    assert (finer.step, ladder_runs.plant_step(finer)) == pytest.approx((step / 4, internal / 4), rel=1e-12)


def test_a_model_exchange_ladder_is_a_looser_tolerance_and_has_no_plant_axis():
    from harness.cases import Case
    from harness.studies import ladders as ladder_runs

    case = Case("manipulator", "vud", algorithm="me", rtol=1e-10)
    (looser,) = ladder_runs.ladder_cases(case)
    assert looser.algorithm == "me" and looser.rtol == pytest.approx(1e-9)
    assert ladder_runs.ladder_row(case, {"step": 5e-5})["plant_step"] is None
    assert ladder_runs.finer_case("manipulator", "vud", [{"rtol": 1e-10}, {"rtol": 1e-9}], None).rtol == \
        pytest.approx(1e-11)
