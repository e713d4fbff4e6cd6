"""The Monte Carlo robustness study (harness/studies/robustness/, docs/studies.md): its distributions and
their strict schema, the design (scipy.stats.qmc) and common random numbers, the FMU instances kept and
reset between samples (the same scores as a fresh run), the rows streamed and resumed, changed settings
refused, and every number of the summary recomputed here from the streamed rows (Wilson intervals by
their closed form, quantiles, bootstrap intervals, the paired differences, the spec, the influence
ranking).  The runs are the native edition's (a few ms each); tests/test_cluster.py runs the study on
separate Dask processes.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from harness.cases import Case, run_case
from harness.cli import main as cli_main
from harness.cli_args import UsageError
from harness.fmu_build import builder as build_fmu
from harness.scenario import ScenarioError
from harness.studies import robustness
from harness.studies.robustness import draws, influence, rows as rows_module, statistics
from harness.studies.robustness.distributions import combine, load_file, parse_param
from harness.studies.robustness.sample_run import SampleRunner
from harness.studies.robustness.spec import parse_spec

PARAMS = ("plant.mp=loguniform:0.05:2", "plant.lp=uniform:0.4:0.6", "plant.dist_gain=truncnormal:1:0.5:0:2")
USER_SPEC = "ITAE<0.082,umax<20"
SAMPLES = 80  # enough completed runs for RBD-FAST (influence.MIN_RUNS)


@pytest.fixture(scope="module")
def native_paths():
    return build_fmu.ensure_built(edition="native")


def make_plan(paths, samples=SAMPLES, seed=3, sampler="sobol", stop=1.0, controllers=("vud", "fixed", "fae")):
    return robustness.plan_study("pendulum_case2", controllers, [parse_param(p) for p in PARAMS], samples,
                                 sampler=sampler, seed=seed, stop=stop, step=1e-3, fmu_paths=paths)


@pytest.fixture(scope="module")
def study(native_paths, tmp_path_factory):
    """One study run to its end on a local pool of two processes: (plan, outcome, folder)."""
    out = tmp_path_factory.mktemp("robustness")
    plan = make_plan(native_paths)
    outcome = robustness.run_study(plan, out, jobs=2, spec=parse_spec(USER_SPEC), progress=False)
    return plan, outcome, out


def table(path) -> list:
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))


def without_times(path) -> dict:
    """{(sample, controller): every cell but the wall and loop times}; a key twice is an error."""
    found = {}
    for row in table(path):
        key = (int(row["sample"]), row["controller"])
        assert key not in found, f"{key} is written twice"
        found[key] = {k: v for k, v in row.items() if k not in ("wall_s", "loop_s", "cpu_s", "loop_cpu_s")}
    return found


# ------------------------------------------------------------------ distributions, spec, design
@pytest.mark.parametrize("text,kind,support", [
    ("plant.mp=uniform:0.5:1.5", "uniform", (0.5, 1.5)),
    ("plant.mp=loguniform:0.05:2", "loguniform", (0.05, 2.0)),
    ("plant.mp=truncnormal:1:0.5:0.2:1.3", "truncnormal", (0.2, 1.3)),
])
def test_a_distribution_draws_within_its_support_and_maps_the_design_through_its_quantiles(text, kind, support):
    distribution = parse_param(text)
    low, high = distribution.support()
    assert distribution.kind == kind and math.isclose(low, support[0], rel_tol=1e-6) \
        and math.isclose(high, support[1], rel_tol=1e-6)
    u = np.array([[0.1], [0.5], [0.9]])
    assert np.allclose(draws.parameter_values([distribution], u)[:, 0], distribution.frozen().ppf(u[:, 0]))
    if kind == "loguniform":  # the median of a log-uniform is the geometric mean of its ends
        assert math.isclose(draws.parameter_values([distribution], np.array([[0.5]]))[0, 0], math.sqrt(0.05 * 2))


@pytest.mark.parametrize("text,message", [
    ("plant.mp=gauss:1:0.1", "unknown distribution 'gauss'"),
    ("plant.mp=uniform:1", "uniform takes 2 values (low:high), got 1"),
    ("plant.mp=uniform:2:1", "low = 2, high = 1; valid: low < high"),
    ("plant.mp=normal:1:0", "std = 0; valid: std > 0"),
    ("plant.mp=loguniform:0:2", "valid for loguniform: 0 < low < high"),
    ("plant.mp=uniform:a:2", "are not all numbers"),
    ("mp=uniform:0:1", "write instance.parameter=KIND:VALUES"),
    ("plant.mp=truncnormal:1:0.1:5:6", "more than 8 std from the mean"),
])
def test_a_bad_param_is_one_line_naming_it(text, message, capsys):
    assert cli_main(["robustness", "pendulum_case2", "--samples", "4", "--param", text, "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and text in err[0], err


@pytest.mark.parametrize("body,message", [
    ('["plant.mp"]\ndistribution = "uniform"\nlow = 0.1\nhgih = 1.0\n', "unknown key 'hgih' (did you mean 'high'?)"),
    ('["plant.mp"]\ndistribution = "unifrom"\nlow = 0.1\nhigh = 1.0\n', "unknown distribution 'unifrom' (did you mean"),
    ('["plant.mp"]\ndistribution = "normal"\nmean = 0.1\n', "normal needs mean, std; missing std"),
    ('["plant.mp"]\nlow = 0.1\nhigh = 1.0\n', "no distribution key"),
    ('["plant.mp"]\ndistribution = "uniform"\nlow = "a"\nhigh = 1.0\n', "low = 'a' is not a number"),
    ('mp = 3\n', "is not a table named instance.parameter"),
    ('["plant.mp" = 3\n', "not TOML"),
])
def test_a_mistake_in_a_distributions_file_is_one_line_naming_file_and_key(body, message, tmp_path, capsys):
    path = tmp_path / "uncertain.toml"
    path.write_text(body)
    assert cli_main(["robustness", "pendulum_case2", "--samples", "4", "--distributions", str(path), "--out",
                     str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and str(path) in err[0], err


def test_the_example_distributions_file_reads_and_a_parameter_given_twice_is_refused():
    example = Path(__file__).resolve().parents[1] / "docs" / "examples" / "pendulum_uncertainty.toml"
    found = load_file(example)
    assert {d.name for d in found} >= {"plant.mp", "plant.lp", "plant.dist_gain"}
    with pytest.raises(UsageError, match="given twice"):
        combine(found, [parse_param("plant.mp=uniform:0.1:1")])


@pytest.mark.parametrize("text,message", [
    ("ITAE<0.6,umx<50", "unknown score 'umx' (did you mean 'umax'?)"),
    ("ITAE=0.6", "is not SCORE<VALUE"),
    ("ITAE<inf", "not a finite number"),
])
def test_a_bad_spec_is_one_line(text, message, capsys):
    assert cli_main(["robustness", "pendulum_case2", "--samples", "4", "--param", PARAMS[0], "--spec", text,
                     "--out", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_a_spec_is_met_by_a_completed_run_within_every_bound():
    spec = parse_spec("ITAE<0.6, umax<=50")
    assert spec.met({"status": "ok", "scores": {"ITAE": 0.5, "umax": 50.0}})
    assert not spec.met({"status": "ok", "scores": {"ITAE": 0.6, "umax": 10.0}})  # strict
    assert not spec.met({"status": "ok", "scores": {"ITAE": math.nan, "umax": 10.0}})
    assert not spec.met({"status": "diverged", "scores": {"ITAE": 0.1, "umax": 10.0}})


def test_a_sobol_design_grows_by_its_prefix_and_a_latin_hypercube_fills_every_stratum():
    small, large = draws.unit_design("sobol", 3, 5, seed=7), draws.unit_design("sobol", 3, 12, seed=7)
    assert np.array_equal(small, large[:5])  # a rerun with more samples adds samples, changes none
    assert not np.array_equal(small, draws.unit_design("sobol", 3, 5, seed=8))
    lhs = draws.unit_design("lhs", 2, 10, seed=1)
    for column in lhs.T:
        assert sorted(np.floor(column * 10).astype(int)) == list(range(10))
    assert np.array_equal(draws.noise_seeds(4, 3), draws.noise_seeds(4, 9)[:3])
    assert (draws.noise_seeds(4, 1000) <= draws.SEED_MAX).all()


@pytest.mark.parametrize("param,message", [
    ("plant.mp=normal:0.5:0.2", "a truncnormal bounds them"),  # a normal can draw a negative mass
    ("plant.mass=uniform:0.1:1", "plant has no parameter 'mass'"),
    ("controller.variant=uniform:1:2", "chosen with --controller"),
])
def test_a_distribution_that_can_draw_an_invalid_value_is_refused_before_any_run(native_paths, param, message):
    with pytest.raises(ScenarioError, match=message):
        robustness.plan_study("pendulum_case2", ("vud",), [parse_param(param)], 4, fmu_paths=native_paths)


# ------------------------------------------------------------------ kept instances
def test_kept_instances_reset_between_samples_give_the_scores_of_a_fresh_run(native_paths):
    plan = make_plan(native_paths, samples=4, stop=0.5)
    context = robustness.run.context_of(plan)
    runner = SampleRunner(context, {k: str(v) for k, v in plan.fmu_files.items()})
    (_, (_, first)), (_, (_, second)) = list(plan.items())[0], list(plan.items())[3]
    try:
        rows = [runner.run("vud", first), runner.run("fae", second), runner.run("vud", first)]
        assert runner.master.reused > 0 and runner.master.made == 3  # one instance per FMU, reset since
    finally:
        runner.close()
    fresh = run_case(Case(plan.scenario, "vud", overrides=tuple(zip(plan.names, first)),
                          fmu_files=tuple((k, str(v)) for k, v in plan.fmu_files.items())))
    assert rows[0]["scores"] == rows[2]["scores"]
    assert rows[0]["scores"] == {key: fresh[key] for key in rows[0]["scores"]}  # bit for bit
    assert rows[1]["scores"] != rows[0]["scores"]


# ------------------------------------------------------------------ the study and its summary
def test_every_controller_runs_on_the_same_draws_the_plan_gives(study):
    plan, outcome, out = study
    assert (outcome.computed, outcome.lost, outcome.done_before) == (3 * SAMPLES, 0, 0)
    values, _ = plan.draws()
    found = table(out / rows_module.CSV_NAME)
    assert len(found) == 3 * SAMPLES
    for row in found:
        drawn = [float(row[name]) for name in plan.names]
        assert drawn == [float(v) for v in values[int(row["sample"])]]  # common random numbers, bit for bit


def _wilson(count, total, z=stats.norm.ppf(0.975)):
    """The Wilson score interval in its closed form (the test's oracle)."""
    share = count / total
    centre = (share + z * z / (2 * total)) / (1 + z * z / total)
    half = z / (1 + z * z / total) * math.sqrt(share * (1 - share) / total + z * z / (4 * total * total))
    return centre - half, centre + half


def test_the_summary_is_recomputed_from_the_streamed_rows(study):
    plan, outcome, out = study
    found = table(out / rows_module.CSV_NAME)
    summary = outcome.summary
    spec = parse_spec(USER_SPEC)
    assert summary["samples"] == SAMPLES
    for controller in plan.controllers:  # in sample order, as the summary takes them (the file's is the finish order)
        mine = sorted((row for row in found if row["controller"] == controller), key=lambda row: int(row["sample"]))
        entry = summary["controllers"][controller]
        assert entry["runs"] == len(mine) == SAMPLES
        diverged = sum(row["status"] == "diverged" for row in mine)
        met = sum(row["status"] == "ok" and all(
            row[b.score] != "" and {"<": float.__lt__, "<=": float.__le__}[b.operator](float(row[b.score]), b.value)
            for b in spec.bounds) for row in mine)
        for name, count in (("diverged", diverged), ("spec", met),
                            ("chattered", sum(row["chatter"] == "1" for row in mine))):
            low, high = _wilson(count, len(mine))
            assert entry[name]["count"] == count
            assert math.isclose(entry[name]["low"], low, abs_tol=1e-12) and math.isclose(entry[name]["high"], high,
                                                                                           abs_tol=1e-12), name
        for score in ("ITAE", "umax", "tv_u"):
            values = np.array([float(row[score]) for row in mine if row["status"] == "ok" and row[score] != ""])
            quantiles = entry["scores"][score]
            assert quantiles["n"] == len(values)
            assert math.isclose(quantiles["median"]["value"], np.median(values), rel_tol=1e-12)
            assert quantiles["q05"]["value"] == np.quantile(values, 0.05)
            assert quantiles["q95"]["value"] == np.quantile(values, 0.95)
            interval = stats.bootstrap((values,), lambda x, axis: np.quantile(x, 0.5, axis=axis), n_resamples=1000,
                                       method="percentile", rng=plan.seed).confidence_interval
            # the same resamples (seeded): the median's interval as scipy gives it for the median alone
            assert math.isclose(quantiles["median"]["low"], interval.low) and \
                math.isclose(quantiles["median"]["high"], interval.high)
            assert quantiles["q05"]["low"] <= quantiles["q05"]["value"] <= quantiles["q05"]["high"]
    assert any(e["spec"]["count"] not in (0, SAMPLES) for e in summary["controllers"].values()), \
        "choose a USER_SPEC that some runs meet and others do not"


def test_the_summary_does_not_depend_on_the_order_the_rows_finished_in(study):
    """Workers finish in any order (a Dask cluster's differs from the local pool's): the same rows in
    another order give the same summary, bootstrap intervals included."""
    from harness.studies.robustness.rows import read_rows
    from harness.studies.robustness.run import current_rows, row_names, summarise

    plan, outcome, out = study
    rows = current_rows(plan, read_rows(out / rows_module.CSV_NAME, row_names(plan)))
    shuffled = rows[::-1][1::2] + rows[::-1][0::2]
    assert [r["sample"] for r in shuffled] != [r["sample"] for r in rows]
    spec = parse_spec(USER_SPEC)
    assert summarise(plan, shuffled, spec) == summarise(plan, rows, spec) == outcome.summary


def test_the_paired_differences_pair_each_sample_with_itself(study):
    plan, outcome, out = study
    found = table(out / rows_module.CSV_NAME)
    itae = {(int(r["sample"]), r["controller"]): float(r["ITAE"]) for r in found if r["status"] == "ok"}
    for pair in outcome.summary["paired"]:
        a, b = pair["a"], pair["b"]
        differences = np.array([itae[(s, a)] - itae[(s, b)] for s in range(SAMPLES)
                                if (s, a) in itae and (s, b) in itae])
        assert pair["paired"] == len(differences)
        assert pair["median"]["value"] == np.median(differences) and math.isclose(pair["mean"]["value"],
                                                                                 np.mean(differences))
        assert pair["a_lower"]["count"] == int(np.sum(differences < 0))
        interval = stats.bootstrap((differences,), lambda x, axis: np.median(x, axis=axis), n_resamples=1000,
                                   method="percentile", rng=plan.seed).confidence_interval
        assert math.isclose(pair["median"]["low"], interval.low) and math.isclose(pair["median"]["high"], interval.high)
        decided = interval.high < 0 or interval.low > 0
        assert (pair["verdict"] != "not decided") == decided
        if decided:
            assert pair["verdict"] == f"{a if interval.high < 0 else b} lower"


def test_the_influence_ranking_is_salibs_rbd_fast_on_the_completed_runs(study):
    from SALib.analyze import rbd_fast

    plan, outcome, out = study
    found = table(out / rows_module.CSV_NAME)
    for controller in plan.controllers:
        ok = [r for r in found if r["controller"] == controller and r["status"] == "ok" and r["ITAE"] != ""]
        x = np.array([[float(r[name]) for name in plan.names] for r in ok])
        y = np.array([float(r["ITAE"]) for r in ok])
        problem = {"num_vars": 3, "names": list(plan.names), "bounds": [list(d.support()) for d in plan.distributions]}
        direct = rbd_fast.analyze(problem, x, y, M=10, seed=plan.seed)
        ranking = outcome.summary["influence"][controller]["ranking"]
        assert [e["name"] for e in ranking] == [plan.names[i] for i in np.argsort(-np.asarray(direct["S1"]))]
        assert np.allclose(sorted(e["S1"] for e in ranking), sorted(direct["S1"]))
    # the disturbance's gain dominates the tracking error of the fixed-universe controller on this band
    assert outcome.summary["influence"]["fixed"]["ranking"][0]["name"] == "plant.dist_gain"


def test_influence_ranks_the_parameter_that_drives_the_objective_first():
    rng = np.random.default_rng(0)
    x = rng.random((200, 3))
    rows = [{"status": "ok", "values": list(v), "scores": {"ITAE": 5 * v[2] ** 2 + 1.5 * v[0]}} for v in x]
    ranked = influence.rank_parameters(rows, ("a", "b", "c"), [(0, 1)] * 3, "ITAE", seed=1)
    assert [e["name"] for e in ranked["ranking"]][:2] == ["c", "a"]
    assert "RBD-FAST needs" in influence.rank_parameters(rows[:10], ("a", "b", "c"), [(0, 1)] * 3, "ITAE", 1)["reason"]


def test_the_figure_and_the_summary_file_are_written(study):
    _, outcome, out = study
    assert outcome.figure_path == out / "robustness_ITAE.png" and outcome.figure_path.stat().st_size > 10_000
    assert (out / "summary.json").is_file()


# ------------------------------------------------------------------ resume and refusal
def test_an_interrupted_study_resumes_with_only_the_missing_runs_and_the_same_rows(study, native_paths, tmp_path):
    plan, _, whole = study
    small = make_plan(native_paths, samples=12)

    def stop_after(row, computed):
        if computed == 7:
            raise KeyboardInterrupt

    first = robustness.run_study(small, tmp_path, jobs=2, progress=False, on_row=stop_after)
    assert first.interrupted and first.computed == 7
    written = without_times(tmp_path / rows_module.CSV_NAME)
    assert len(written) == 7
    with open(tmp_path / rows_module.CSV_NAME, "a") as stream:  # a line cut short by a kill
        stream.write("8,vud,0.3")
    second = robustness.run_study(small, tmp_path, jobs=2, progress=False)
    assert (second.done_before, second.computed, second.interrupted) == (7, 36 - 7, False)
    resumed = without_times(tmp_path / rows_module.CSV_NAME)
    reference = {key: cells for key, cells in without_times(whole / rows_module.CSV_NAME).items() if key[0] < 12}
    assert resumed == reference  # every run once, the values of the uninterrupted study bit for bit
    grown = robustness.run_study(make_plan(native_paths, samples=14), tmp_path, jobs=1, progress=False, plot=False)
    assert (grown.done_before, grown.computed) == (36, 6)  # a Sobol' design grows: only the new samples run


@pytest.mark.parametrize("change,message", [
    (dict(seed=4), "seed: 3 then, 4 now"),
    (dict(stop=0.5), "stop: 1.0 then, 0.5 now"),
    (dict(sampler="lhs"), "sampler"),
])
def test_a_rerun_with_other_settings_is_refused_in_one_line(native_paths, tmp_path, change, message):
    robustness.run_study(make_plan(native_paths, samples=2, controllers=("vud",)), tmp_path, jobs=1, progress=False,
                         plot=False)
    before = (tmp_path / rows_module.CSV_NAME).read_text()
    with pytest.raises(ScenarioError, match=message) as refused:
        robustness.run_study(make_plan(native_paths, **{"samples": 2, "controllers": ("vud",), **change}), tmp_path,
                             jobs=1, progress=False)
    assert "\n" not in str(refused.value) and "use another --out" in str(refused.value)
    assert (tmp_path / rows_module.CSV_NAME).read_text() == before  # nothing overwritten


def test_the_command_prints_the_summary_and_resumes(native_paths, tmp_path, capsys):
    argv = ["robustness", "pendulum_case2", "--samples", "3", "--param", PARAMS[0], "--stop", "0.5", "--step", "1e-3",
            "--spec", "ITAE<0.05", "--edition", "native", "--jobs", "1", "--no-progress", "--out", str(tmp_path)]
    assert cli_main(argv) == 0
    printed = capsys.readouterr().out
    assert "9 runs computed" in printed and "diverged   0.0 %" in printed and "meets ITAE<0.05" in printed
    assert "vud - fixed (ITAE, 3 paired samples)" in printed and "not decided (3 paired samples" in printed
    assert cli_main(argv) == 0
    assert "0 runs computed (nothing to run) " in capsys.readouterr().out and \
        len(table(tmp_path / rows_module.CSV_NAME)) == 9


def test_on_a_rig_the_noise_seed_is_drawn_per_sample_and_shared_by_the_controllers(native_paths, tmp_path):
    plan = robustness.plan_study("pendulum_case2_hardware", ("vud", "fae"), [parse_param("plant.mp=uniform:0.1:0.2")],
                                 3, seed=2, stop=0.2, fmu_paths=native_paths)
    assert plan.seed_parameter == "sensor.seed"
    outcome = robustness.run_study(plan, tmp_path, jobs=1, progress=False, plot=False)
    assert outcome.computed == 6 and not outcome.lost
    found = table(tmp_path / rows_module.CSV_NAME)
    seeds = {}
    for row in found:
        seeds.setdefault(int(row["sample"]), set()).add(row["sensor.seed"])
    assert all(len(values) == 1 for values in seeds.values())  # the same noise for every controller
    assert len({next(iter(values)) for values in seeds.values()}) == 3  # another for every sample
    assert [int(next(iter(seeds[s]))) for s in range(3)] == [int(v) for v in draws.noise_seeds(2, 3)]
    with pytest.raises(ScenarioError, match="drawn per sample by the study"):
        robustness.plan_study("pendulum_case2_hardware", ("vud",), [parse_param("sensor.seed=uniform:1:9")], 3,
                              fmu_paths=native_paths)
