"""`python -m harness tune` (docs/tuning.md): search space, pruning, database, results.

Short horizons and few trials keep the file quick.
"""
import dataclasses
import hashlib
import json
import math
import os
import random
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

optuna = pytest.importorskip("optuna")

from harness.fmu_build import builder as build_fmu  # noqa: E402
from harness.fmu_build import catalog as fmu_catalog  # noqa: E402
from harness import scenario as scenarios  # noqa: E402
from harness import variants  # noqa: E402
from harness.cli import main as cli_main  # noqa: E402
from harness.scenario_toml import scenario_toml  # noqa: E402
from harness.studies.tune import candidate, comparison, config as tune_config, loop, space, storage  # noqa: E402
from harness.studies.tune import tune  # noqa: E402
from harness.studies.tune.summary import pareto_front  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONTROLLER = "AdaptiveFuzzyController"


@pytest.fixture(scope="module")
def edition():
    from harness.fmu_build import native as build_native

    return "native" if build_native.compiler_available() else "python"


@pytest.fixture(scope="module")
def paths(edition):
    return build_fmu.ensure_built(edition=edition)


def config(tmp_path, paths, edition, **changes):
    base = dict(scenario="pendulum_case1", controller="vud", trials=4, stop=0.3, jobs=1, edition=edition,
                out=tmp_path, fmu_paths=paths, held_out=())
    base.update(changes)
    return tune_config.TuneConfig(**base)


def trials_of(url, name):
    study = optuna.load_study(study_name=name, storage=url)
    return study.get_trials(deepcopy=False)


# ------------------------------------------------------------------ search space
def test_the_search_space_is_the_fmus_table_per_variant_and_order():
    names = {(c, n): [d.name for d in space.search_space(v, n)]
             for c, v in variants.CONTROLLER_VARIANTS.items() for n in (2, 3)}
    assert names[("vud", 2)] == ["k1", "k2", "q1", "q2", "gamma", "m_theta", "delta", "lambda_e", "1-lambda_ce",
                                 "kappa1", "kappa2", "mf_slope", "E1", "E2"]
    assert set(names[("fixed", 2)]) == set(names[("vud", 2)]) - {"1-lambda_ce", "kappa1", "kappa2"}
    assert set(names[("fae", 2)]) == set(names[("fixed", 2)]) | {"gamma_w"}
    assert set(names[("vud", 3)]) - set(names[("vud", 2)]) == {"k3_fraction", "q3", "kappa3", "E3"}
    table = space.declared_parameters()
    untuned = {name for name, v in table.items() if v.tuning is None}
    assert {"variant", "order", "sets", "fls_input", "theta0", "initial_error", "e0"} <= untuned


def test_every_declared_range_lies_in_the_valid_range_and_is_log_scaled_where_it_spans_decades():
    for name, variable in space.declared_parameters().items():
        tuning = variable.tuning
        if tuning is None:
            continue
        assert tuning.problem() is None, name
        if tuning.scale in ("linear", "log", "log1m"):
            assert variable.check(tuning.low) is None and variable.check(tuning.high) is None, name
        span = (1 - tuning.low) / (1 - tuning.high) if tuning.scale == "log1m" else tuning.high / tuning.low
        if span >= 10:
            assert tuning.scale != "linear", f"{name}: range spans {span:g}x on a linear scale"


@pytest.mark.parametrize("name", scenarios.scenario_names())
def test_the_shipped_scenarios_start_inside_the_search_space(name):
    scenario = scenarios.load(name)
    table = space.declared_parameters()
    values = {n: v.start for n, v in table.items()}
    values.update(scenario.components[scenario.controller_instance].parameters)
    assert space.paper_conditions(values, table) is None
    for controller, variant in variants.CONTROLLER_VARIANTS.items():
        dimensions = space.search_space(variant, int(values["order"]))
        for dimension, x in zip(dimensions, space.sample_of(dimensions, values).values()):
            low, high, _ = dimension.bounds()
            assert low <= x <= high, (name, controller, dimension.name, x)


@pytest.mark.parametrize("order", [3, 4])
def test_the_hurwitz_fraction_gives_exactly_the_hurwitz_gains(order):
    """Every fraction in (0, 1) gives a Hurwitz k (the FMU's own test), a fraction above 1 never does."""
    from fmu_src import afc_math

    generator = random.Random(order)
    dimensions = [space.Dimension(f"k{i}", 0.05, 50.0, "log") for i in (1, 2)]
    dimensions += [space.Dimension(f"k{i}", 0.001, 0.999, "hurwitz") for i in range(3, order + 1)]

    def hurwitz(k):
        try:
            return afc_math.is_positive_definite(afc_math.lyapunov_p(k, (1.0,) * len(k)))
        except ValueError:
            return False

    for _ in range(200):
        sample = {"k1": 10 ** generator.uniform(-1.3, 1.7), "k2": 10 ** generator.uniform(-1.3, 1.7)}
        fractions = [generator.uniform(0.001, 0.999) for _ in range(3, order + 1)]
        sample.update({f"k{i}_fraction": f for i, f in zip(range(3, order + 1), fractions)})
        values = space.parameter_values(dimensions, sample, {})
        k = tuple(values[f"k{i}"] for i in range(1, order + 1))
        assert hurwitz(k), (sample, k)
        assert space.sample_of(dimensions, values) == pytest.approx(sample, rel=1e-9)
        over = dict(sample, **{f"k{order}_fraction": 1.001})
        values = space.parameter_values(dimensions, over, {})
        assert not hurwitz(tuple(values[f"k{i}"] for i in range(1, order + 1))), over


def test_the_search_ranges_reach_neither_the_model_description_nor_the_c_tables(monkeypatch):
    from harness.fmu_build.native_stages.description import fmi2_description
    from harness.fmu_build.native_stages.header import variables_header

    cls = build_fmu.model_class(CONTROLLER)
    with_ranges_xml = fmi2_description(CONTROLLER, "{guid}")
    with_ranges_header = variables_header(CONTROLLER, "{guid}")
    assert sum(v.tuning is not None for v in cls.VARIABLES) >= 14
    monkeypatch.setattr(cls, "VARIABLES", tuple(dataclasses.replace(v, tuning=None) for v in cls.VARIABLES))
    from xml.etree import ElementTree as ET

    assert ET.tostring(fmi2_description(CONTROLLER, "{guid}")) == ET.tostring(with_ranges_xml)
    assert variables_header(CONTROLLER, "{guid}") == with_ranges_header


@pytest.mark.parametrize("name", scenarios.scenario_names())
def test_a_written_scenario_reads_back_as_itself_whatever_its_strings_hold(name):
    """The tuned scenario file's writer (harness/scenario_toml.py): the shipped files' layout, any string."""
    scenario = scenarios.configure(name, "fae")
    scenario.description += ' -- "quoted" \\ back, tab\t, lambda \u03bb, outside the BMP \U0001d706'
    text = scenario_toml(scenario, ["provenance", "", "first\nsecond"])
    assert text.startswith("# provenance\n#\n# first\n# second\nname = ")
    assert text.count("parameters = { ") == len(scenario.components)
    assert text.count("\n[[connections]]\n") == len(scenario.connections)
    back = scenarios.parse(scenarios.tomllib.loads(text), scenario.path)
    for key in ("name", "description", "controller_instance", "start", "stop", "step", "divergence_bound",
                "connections", "record", "signals", "bounds"):
        assert getattr(back, key) == getattr(scenario, key), key
    assert {n: (c.fmu, c.parameters) for n, c in back.components.items()} == \
        {n: (c.fmu, c.parameters) for n, c in scenario.components.items()}


def test_the_chatter_mark_is_the_controller_fmus_own_warning():
    from fmu_src import chatter_monitor

    state = chatter_monitor.new_state()
    assert candidate.CHATTER_MARK in chatter_monitor.warning(state, 1e-3)


def test_pareto_front_and_the_equal_effort_verdicts():
    points = [(1.0, 5.0), (2.0, 3.0), (1.5, 6.0), (3.0, 3.0), (4.0, 1.0)]
    assert pareto_front(points) == [0, 1, 4]
    row = lambda controller, value, error: {"controller": controller,  # noqa: E731
                                            "best": {"scores": {"ITAE": value}, "error": {"ITAE": error}}}
    beats = comparison.beats
    assert beats([row("fae", 0.5, 0.01), row("vud", 0.6, 0.01)], "best", "ITAE", "fae", "vud")["answer"] == "yes"
    assert beats([row("fae", 0.5, 0.1), row("vud", 0.6, 0.1)], "best", "ITAE", "fae", "vud")["answer"] \
        .startswith("undecided")
    assert beats([row("fae", 0.7, 0.01), row("vud", 0.6, 0.01)], "best", "ITAE", "fae", "vud")["answer"] == "no"
    result = comparison.smallest([row("vud", 0.1, 0.001), row("fixed", 0.2, 0.001), row("fae", 0.15, 0.06)], "best",
                                 "ITAE")
    assert result["controller"] == "vud" and not result["separated"]


# ------------------------------------------------------------------ bad input
@pytest.fixture(scope="module")
def existing_study(tmp_path_factory, paths, edition):
    folder = tmp_path_factory.mktemp("tune_db")
    summary = tune(config(folder, paths, edition, trials=2, stop=0.05), outputs=False)
    return folder, summary


def database_content(database: Path) -> str:
    """Every row of every table (SQL dump, read-only): the study's content.  Not the file's bytes: in WAL
    mode SQLite moves committed pages from the -wal file into the database file whenever a connection
    closes (a checkpoint), which an earlier test's connection may do at any time when it is collected."""
    connection = sqlite3.connect(f"file:{database}?mode=ro", uri=True)
    try:
        return hashlib.sha256("\n".join(connection.iterdump()).encode()).hexdigest()
    finally:
        connection.close()


@pytest.mark.parametrize("arguments,expected", [
    (["--params", "gama"], "has no parameter 'gama'; tunable: k1, k2"),
    (["--params", "order"], "parameter order is not tunable"),
    (["--params", "lambda_ce", "--controller", "fixed"], "no effect with controller fixed"),
    (["--range", "gamma=5:5"], "range [5, 5] is empty"),
    (["--range", "gamma=50:5"], "range [50, 5] is inverted"),
    (["--range", "lambda_ce=0.5:1.5"], "1.5 is outside the valid range (0, 1) of lambda_ce"),
    (["--objective", "ITEA"], "unknown score 'ITEA'; valid: ts, es1_pct"),
    (["--constraint", "umx<=20"], "unknown score 'umx'"),
    (["--objective", "es1"], "es1_pct is not defined on this run: the horizon 0.05 s is shorter than the reference"),
    (["--constraint", "es2<=1"], "es2_pct is not defined on this run"),
    (["--constraint", "umax=20"], "write SCORE<=LIMIT or SCORE>=LIMIT"),
    (["--storage", "sqlite:////nonexistent-folder/x/y.db"], "cannot open the database"),
    (["--stop", "0.1"], "was made with other settings: stop = 0.05 (now 0.1)"),
])
def test_bad_input_is_one_line_exit_2_and_leaves_the_database_untouched(existing_study, edition, capsys,
                                                                        arguments, expected):
    folder, summary = existing_study
    database = folder / "pendulum_case1.db"
    before = database_content(database)
    options = ["--stop", "0.05"] if "--stop" not in arguments else []
    status = cli_main(["tune", "pendulum_case1", "--trials", "3", "--jobs", "1", "--edition", edition, "--out",
                       str(folder), "--quiet", *options, *arguments])
    err = capsys.readouterr().err.strip()
    assert status == 2, err
    assert len(err.splitlines()) == 1 and expected in err, err
    assert database_content(database) == before
    assert len(trials_of(summary["storage"], summary["study"])) == 2


# ------------------------------------------------------------------ a study end to end
def test_a_study_writes_a_scenario_that_run_and_regress_take_and_run_reproduces_its_score_exactly(
        tmp_path, paths, edition, capsys, monkeypatch):
    summary = tune(config(tmp_path, paths, edition, trials=6, stop=0.5, held_out=("pendulum_case2",)))
    best = summary["best"]
    assert best is not None and best["half_step"] is not None
    assert summary["start"]["number"] == 0 and summary["finished"] == 6
    toml = Path(summary["study_file"])
    assert cli_main(["run", str(toml), "--controller", "vud", "--edition", edition, "--json"]) == 0
    run = json.loads(capsys.readouterr().out)
    assert run["ITAE"] == best["value"] and run["Ec"] == best["scores"]["Ec"]
    from harness.studies import regression
    from harness.cases import Case

    monkeypatch.chdir(tmp_path.parent)  # a relative path with a folder, as `regress results/tune/X.toml` gets
    case = Case(f"{tmp_path.name}/{toml.name}", "vud")
    assert case.name == f"{toml.stem}_vud"
    os.environ[fmu_catalog.EDITION_VARIABLE] = edition
    try:
        first = regression.regress([case], update=True, report_dir=None, reference_dir=tmp_path / "refs", workers=1)
        again = regression.regress([case], report_dir=None, reference_dir=tmp_path / "refs", workers=1)
    finally:
        os.environ.pop(fmu_catalog.EDITION_VARIABLE)
    assert first.written and again.passed
    report = (tmp_path / "report.md").read_text()
    for heading in ("### Best parameters", "### Parameter importances", "held-out scenarios", "pendulum_case2"):
        assert heading in report
    assert (tmp_path / f"{summary['study']}_pareto.png").stat().st_size > 1000
    assert (tmp_path / f"{summary['study']}_progress.png").stat().st_size > 1000


def test_the_report_says_plainly_when_no_trial_beat_the_start(tmp_path, paths, edition):
    """One trial, the starting parameters: the best is the start, and no trial beat it."""
    summary = tune(config(tmp_path, paths, edition, trials=1))
    assert summary["best"]["number"] == summary["start"]["number"] == 0 and summary["first_better"] is None
    report = (tmp_path / "report.md").read_text()
    assert "(trial #0); no trial beat the starting parameters." in report and "#None" not in report


@pytest.mark.parametrize("case", ["report.md is a folder", "--out under a file", "--compare, comparison.json a folder"])
def test_an_output_it_cannot_write_is_one_line_exit_2_before_any_trial(tmp_path, edition, capsys, case):
    """Every output is checked before the database opens (no trial runs); --storage elsewhere too."""
    out, database, extra = tmp_path / "out", tmp_path / "out" / "pendulum_case1.db", []
    if case == "--out under a file":
        (tmp_path / "a_file").write_text("")
        out, culprit = tmp_path / "a_file" / "tune", tmp_path / "a_file"
        database = tmp_path / "elsewhere.db"
        extra = ["--storage", f"sqlite:///{database}"]
    else:
        culprit = out / ("comparison.json" if "--compare" in case else "report.md")
        culprit.mkdir(parents=True)
        extra = ["--compare"] if "--compare" in case else []
    status = cli_main(["tune", "pendulum_case1", "--trials", "2", "--jobs", "1", "--stop", "0.05", "--edition", edition,
                       "--out", str(out), "--quiet", "--held-out", *extra])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1 and f"--out: {culprit} is a f" in err, err
    assert not database.exists()  # the database opens before the first trial


def test_diverging_and_chattering_candidates_are_pruned_with_the_reason(tmp_path, paths, edition):
    scenario = scenarios.configure("pendulum_case1", "vud", stop=0.3)
    task = {"scenario": scenario, "values": {}, "grid": [()], "fmu_paths": paths, "objective": "ITAE",
            "verify_below": -math.inf, "tolerance": 0.01}
    assert candidate.evaluate(task)["status"] == "ok"
    bounded = scenarios.configure("pendulum_case1", "vud", stop=0.3)
    bounded.bounds["controller.u"] = 1.0
    diverged = candidate.evaluate(dict(task, scenario=bounded))
    assert diverged["status"] == "diverged" and "controller.u" in diverged["reason"]
    coarse = scenarios.configure("pendulum_case1", "vud", step=1e-3, stop=5.0)  # chatters from t ~ 3 s
    chatter = candidate.evaluate(dict(task, scenario=coarse))
    assert chatter["status"] == "chatter" and "u chatters" in chatter["reason"]
    # through a study: the pruned trial is kept, with its reason, and counted
    path = tmp_path / "bounded.toml"
    path.write_text(scenario_toml(bounded))
    summary = tune(config(tmp_path, paths, edition, scenario=str(path), trials=3), outputs=False)
    trials = trials_of(summary["storage"], summary["study"])
    first = trials[0]
    assert first.state == optuna.trial.TrialState.PRUNED and first.user_attrs["start"]
    assert first.user_attrs["outcome"]["status"] == "diverged" and summary["finished"] == 3


def test_a_best_that_moves_at_half_the_step_is_pruned_not_reported(tmp_path, paths, edition):
    strict = tune(config(tmp_path, paths, edition, trials=1, tolerance=1e-12, study="strict"), outputs=False)
    assert strict["best"] is None and strict["counts"] == {"step-dependent": 1}
    loose = tune(config(tmp_path, paths, edition, trials=1, study="loose"), outputs=False)
    assert loose["best"]["number"] == 0 and loose["best"]["half_step"]["change"] < 0.01


def test_a_constraint_keeps_a_candidate_that_misses_it_from_being_best(tmp_path, paths, edition):
    free = tune(config(tmp_path, paths, edition, trials=1, study="free"), outputs=False)
    umax = free["best"]["scores"]["umax"]
    bound = tune(config(tmp_path, paths, edition, trials=1, study="bound",
                             constraints=(f"umax<={umax * 0.99}",)), outputs=False)
    assert bound["best"] is None
    trial = trials_of(bound["storage"], "bound")[0]
    assert trial.state == optuna.trial.TrialState.COMPLETE and not storage.is_feasible(trial)
    assert list(trial.constraints.values())[0] == pytest.approx(umax * 0.01)


def test_robust_scores_the_worst_case_over_the_grid(tmp_path, paths, edition):
    summary = tune(config(tmp_path, paths, edition, trials=1, vary=("plant.dist_gain=0,1",),
                               study="robust"), outputs=False)
    best = summary["best"]
    points = best["points"]
    assert [p["variation"] for p in points] == [[["plant.dist_gain", 0.0]], [["plant.dist_gain", 1.0]]]
    assert best["value"] == max(p["scores"]["ITAE"] for p in points)
    assert points[0]["scores"]["ITAE"] != points[1]["scores"]["ITAE"]


def test_the_same_seed_gives_the_same_trials(tmp_path, paths, edition):
    def params(name, seed):
        summary = tune(config(tmp_path / name, paths, edition, trials=13, stop=0.05, seed=seed),
                            outputs=False)
        return [t.params for t in trials_of(summary["storage"], summary["study"])]

    first = params("a", 3)
    assert params("b", 3) == first
    assert params("c", 4) != first


# ------------------------------------------------------------------ processes and the database
def _command(folder, edition, trials, *extra, quiet=True):
    return [sys.executable, "-m", "harness", "tune", "pendulum_case1", "--stop", "0.3", "--trials", str(trials),
            "--edition", edition, "--out", str(folder), *(["--quiet"] if quiet else []), "--held-out", *extra]


def _counts(database):
    try:
        with sqlite3.connect(f"file:{database}?mode=ro", uri=True, timeout=30) as connection:
            rows = connection.execute("SELECT state, count(*) FROM trials GROUP BY state").fetchall()
    except sqlite3.OperationalError:  # the tables are not there yet
        return {}
    return dict(rows)


def test_a_killed_run_resumes_with_every_finished_trial_kept(tmp_path, edition, paths):
    database = tmp_path / "pendulum_case1.db"
    command = _command(tmp_path, edition, 10, "--jobs", "1")
    process = subprocess.Popen(command, cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            time.sleep(0.05)
            counts = _counts(database) if database.exists() else {}
            if counts.get("COMPLETE", 0) + counts.get("PRUNED", 0) >= 3 and counts.get("RUNNING"):
                os.killpg(process.pid, signal.SIGKILL)
                break
            assert process.poll() is None, process.stderr.read().decode()
        else:
            pytest.fail("the study did not get going")
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        process.wait()
    url = f"sqlite:///{database}"
    study = "pendulum_case1-vud-ITAE"
    before = {t.number: t for t in trials_of(url, study)}
    finished = {n: t for n, t in before.items() if t.state.is_finished()}
    running = [t for t in before.values() if t.state == optuna.trial.TrialState.RUNNING]
    assert finished and running, {n: t.state for n, t in before.items()}
    resumed = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=180)
    assert resumed.returncode == 0, resumed.stderr
    after = {t.number: t for t in trials_of(url, study)}
    for number, trial in finished.items():  # kept as they were
        assert after[number].state == trial.state and after[number].params == trial.params
        assert after[number].value == trial.value
    for trial in running:  # failed, and run again with the same parameters as a new trial
        assert after[trial.number].state == optuna.trial.TrialState.FAIL
        retries = [t for t in after.values() if t.system_attrs.get("failed_trial") == trial.number]
        assert len(retries) == 1 and retries[0].state.is_finished()
        assert all(retries[0].params[name] == value for name, value in trial.params.items())
    assert sum(t.state.is_finished() and t.state != optuna.trial.TrialState.FAIL for t in after.values()) == 10


@pytest.mark.parametrize("race", ["table studies already exists", "database is locked",
                                  "An exception is raised during the commit. This typically happens due to invalid "
                                  "data in the commit, e.g. exceeding max length."])
def test_a_database_another_process_is_creating_is_opened_once_it_is_there(tmp_path, monkeypatch, race):
    """Two processes started together both create the schema: the one that loses the race retries."""
    real, calls = optuna.storages.RDBStorage, []

    def racing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise optuna.exceptions.StorageInternalError(race)
        return real(*args, **kwargs)

    monkeypatch.setattr(optuna.storages, "RDBStorage", racing)
    monkeypatch.setattr(storage.clock, "sleep", lambda seconds: None)
    storage.open_storage(f"sqlite:///{tmp_path / 'x.db'}")
    assert len(calls) == 2


def test_a_database_that_cannot_be_opened_is_one_line(tmp_path):
    with pytest.raises(storage.TuneError, match=r"^--storage sqlite:///.*: cannot open the database: "):
        storage.open_storage(f"sqlite:///{tmp_path / 'missing' / 'folder' / 'x.db'}")


def test_trials_of_dead_processes_are_failed_and_retried_those_of_live_ones_kept(tmp_path, monkeypatch):
    import socket

    database = storage.open_storage(f"sqlite:///{tmp_path / 'x.db'}")
    study = optuna.create_study(storage=database, study_name="s")
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    owners = {"dead": {"host": socket.gethostname(), "pid": int(dead.stdout)},
              "live": {"host": socket.gethostname(), "pid": os.getppid()},
              "elsewhere": {"host": "another-host", "pid": int(dead.stdout)}, "none": None}
    trials = {}
    for label, owner in owners.items():
        trial = study.ask()
        trial.suggest_float("x", 0.0, 1.0)
        if owner:
            trial.set_user_attr("owner", owner)
        trials[label] = trial.number
    recovered, waiting = storage.recover_dead_trials(study)
    assert recovered == [trials["dead"]] and waiting == 1  # the unclaimed one is young: it waits
    monkeypatch.setattr(storage, "ORPHAN_S", 0.0)
    recovered, waiting = storage.recover_dead_trials(study)
    assert recovered == [trials["none"]] and waiting == 0
    states = {t.number: t.state for t in study.get_trials()}
    assert states[trials["live"]] == states[trials["elsewhere"]] == optuna.trial.TrialState.RUNNING
    retried = [t for t in study.get_trials() if t.state == optuna.trial.TrialState.WAITING]
    assert sorted(t.system_attrs["failed_trial"] for t in retried) == sorted([trials["dead"], trials["none"]])


@pytest.fixture(params=["sqlite", "postgresql"])
def shared_database(request, tmp_path):
    """The URL of an empty database that several tune processes share: an SQLite file, or a database of
    the PostgreSQL server the tests start (tests/cluster_helpers.py)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'shared.db'}"
    server = request.getfixturevalue("postgres")
    return server.url(server.create_database(f"tune_{os.getpid()}_{random.randrange(10 ** 9)}"))


def finished_of(trials) -> list:
    return [t for t in trials if t.state in (optuna.trial.TrialState.COMPLETE, optuna.trial.TrialState.PRUNED)]


def test_two_processes_drive_one_study_to_exactly_its_budget(tmp_path, edition, paths, shared_database):
    """Started together, with different seeds on one study: one creates it, the other loads it; together
    they stop at the budget, no trial lost or run twice."""
    started = [subprocess.Popen(_command(tmp_path / f"out{seed}", edition, 12, "--jobs", "1", "--seed", str(seed),
                                         "--storage", shared_database, "--study", "shared"),
                                cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL) for seed in (0, 1)]
    for process in started:
        assert process.wait(timeout=240) == 0, process.stderr.read().decode()
    trials = trials_of(shared_database, "shared")
    owners = {t.user_attrs["owner"]["pid"] for t in trials}
    assert owners == {process.pid for process in started}
    assert len(finished_of(trials)) == 12 and len({t.number for t in trials}) == len(trials)
    assert not [t for t in trials if t.state == optuna.trial.TrialState.RUNNING]
    parameters = [tuple(sorted(t.params.items())) for t in finished_of(trials)]
    assert len(set(parameters)) == len(parameters)  # no candidate run twice (the seeds differ)
    assert sum(bool(t.user_attrs.get("start")) for t in trials) == 1


def kill_mid_trial(command: list, url: str, study: str, attempts: int = 4) -> None:
    """Run ``command`` (a tune process) and SIGKILL it while a trial of ``study`` runs, after two have
    finished; a kill that lands between two trials (they are short) is tried again with the same command."""
    for _ in range(attempts):
        process = subprocess.Popen(command, cwd=ROOT, start_new_session=True, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.PIPE)
        deadline = time.monotonic() + 180
        try:
            while time.monotonic() < deadline:
                time.sleep(0.05)
                assert process.poll() is None, process.stderr.read().decode()
                try:
                    trials = trials_of(url, study)
                except KeyError:  # the study is not there yet
                    continue
                if len(finished_of(trials)) >= 2 and any(t.state == optuna.trial.TrialState.RUNNING for t in trials):
                    os.killpg(process.pid, signal.SIGKILL)
                    break
            else:
                pytest.fail("the study did not get going")
        finally:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
            process.wait()
        if any(t.state == optuna.trial.TrialState.RUNNING for t in trials_of(url, study)):
            return
    pytest.fail(f"every one of {attempts} kills landed between two trials")


def test_a_run_killed_mid_trial_is_resumed_by_another_through_its_heartbeat(tmp_path, edition, paths,
                                                                              shared_database, monkeypatch):
    """SIGKILL mid-trial; its running trial, owned by a process another host cannot see, is failed once its
    heartbeat has been silent for the grace period and run again with the same parameters."""
    command = _command(tmp_path, edition, 16, "--jobs", "1", "--storage", shared_database, "--study", "shared",
                       "--stop", "5")  # trials long enough to be killed in one
    kill_mid_trial(command, shared_database, "shared")
    study = optuna.load_study(study_name="shared", storage=shared_database)
    running = [t for t in study.get_trials() if t.state == optuna.trial.TrialState.RUNNING]
    assert running, "killed between two trials"
    finished = {t.number: t for t in finished_of(study.get_trials())}
    for trial in running:  # as seen from another host: its process cannot be asked, only its heartbeat
        study._storage.set_trial_user_attr(trial._trial_id, "owner", {"host": "another-host", "pid": 1})
    monkeypatch.setattr(storage, "GRACE_S", 3)
    monkeypatch.setattr(storage, "HEARTBEAT_S", 1)
    monkeypatch.setattr(loop, "HEARTBEAT_S", 1)
    summary = tune(config(tmp_path / "resumer", paths, edition, trials=16, stop=5, storage=shared_database,
                          study="shared"), outputs=False)
    after = {t.number: t for t in trials_of(shared_database, "shared")}
    for number, trial in finished.items():  # kept as they were
        assert after[number].state == trial.state and after[number].params == trial.params
    for trial in running:  # failed, and run again with the same parameters as a new trial
        assert after[trial.number].state == optuna.trial.TrialState.FAIL
        retries = [t for t in after.values() if t.system_attrs.get("failed_trial") == trial.number]
        assert len(retries) == 1 and retries[0].state.is_finished()
        # the same parameters (a trial killed while it was being sampled holds only the first of them)
        assert all(retries[0].params[name] == value for name, value in trial.params.items())
    assert len(finished_of(after.values())) == 16 == summary["finished"]


class KilledHere(BaseException):
    """Stands for the SIGKILL of a tune process at one point of its code."""


def test_a_process_killed_right_after_claiming_its_trial_leaves_a_trial_that_goes_stale(tmp_path, monkeypatch):
    """Killed between writing its trial's owner and sampling it: another host sees a RUNNING trial it cannot
    ask about, so only the heartbeat can tell it dead; the trial must have one (Optuna ignores trials
    without) and is failed once the grace period has passed."""
    from types import SimpleNamespace

    monkeypatch.setattr(storage, "HEARTBEAT_S", 1)
    monkeypatch.setattr(storage, "GRACE_S", 1)
    url = f"sqlite:///{tmp_path / 'killed.db'}"
    study = optuna.create_study(study_name="killed", storage=storage.open_storage(url))
    claim = optuna.trial.Trial.set_user_attr

    def claim_then_die(trial, key, value):
        claim(trial, key, value)
        raise KilledHere

    monkeypatch.setattr(optuna.trial.Trial, "set_user_attr", claim_then_die)
    heartbeat = storage.Heartbeat(study._storage)
    prepared = SimpleNamespace(config=SimpleNamespace(sampler="random", seed=3, trials=4))
    with pytest.raises(KilledHere):
        loop._ask(study, prepared, heartbeat, {"host": "another-host", "pid": 1}, None, [], None, None, 0)
    heartbeat.close()  # the process is gone: no more beats
    monkeypatch.undo()
    time.sleep(2.5)
    optuna.storages.fail_stale_trials(study)
    trial = study.get_trials(deepcopy=False)[0]
    assert trial.state == optuna.trial.TrialState.FAIL, "a claimed trial without heartbeat never goes stale"


@pytest.mark.parametrize("problem", ["refused", "wrong password", "missing database", "missing driver"])
def test_a_database_server_that_cannot_be_used_is_one_line_exit_2_before_any_trial(postgres, tmp_path, edition,
                                                                                   capsys, monkeypatch, problem):
    from tests.cluster_helpers import free_port

    url = {"refused": postgres.url("postgres", port=free_port()),
           "wrong password": postgres.url("postgres").replace(postgres.password, "not-the-password"),
           "missing database": postgres.url("no_such_database"),
           "missing driver": postgres.url("postgres")}[problem]
    expected = {"refused": "Connection refused",
                "wrong password": 'password authentication failed for user "afc" (the password comes from the URL, '
                                  "PGPASSWORD or the password file",
                "missing database": 'database "no_such_database" does not exist (create it first',
                "missing driver": "the database driver psycopg is not installed: pip install -e '.[postgres]'"}[problem]
    if problem == "missing driver":
        monkeypatch.setitem(sys.modules, "psycopg", None)  # as if the postgres extra were not installed
    status = cli_main(["tune", "pendulum_case1", "--trials", "3", "--jobs", "1", "--edition", edition, "--stop", "0.05",
                       "--out", str(tmp_path), "--storage", url])
    captured = capsys.readouterr()
    assert status == 2, captured.err
    assert captured.err.count("\n") == 1 and captured.err.startswith("error: --storage postgresql+psycopg://afc:***@"), \
        captured.err
    assert expected in captured.err, captured.err
    assert "trial" not in captured.err and not list(tmp_path.iterdir())  # before any trial, nothing written
    assert postgres.password not in captured.out + captured.err and "not-the-password" not in captured.err


def test_the_password_reaches_no_terminal_log_or_file(postgres, tmp_path, edition, paths):
    """With the password in the URL, and from a password file as libpq reads it (~/.pgpass, PGPASSFILE):
    every output, every file written, masks or leaves it out."""
    database = postgres.create_database(f"secret_{os.getpid()}")
    password_file = tmp_path / "pgpass"
    password_file.write_text(f"127.0.0.1:{postgres.port}:{database}:{postgres.user}:{postgres.password}\n")
    password_file.chmod(0o600)
    runs = [(postgres.url(database), {}),
            (postgres.url(database, password=False), {"PGPASSFILE": str(password_file)})]
    outputs = []
    for index, (url, env) in enumerate(runs):
        out = tmp_path / f"out{index}"
        done = subprocess.run(_command(out, edition, 3 + index, "--jobs", "1", "--storage", url, quiet=False),
                              cwd=ROOT, capture_output=True, text=True, timeout=240, env={**os.environ, **env})
        text = done.stdout + done.stderr
        assert done.returncode == 0, text
        assert f"optuna-dashboard {postgres.url(database, password=False)}" in text
        outputs.append(text)
        for path in out.rglob("*"):
            if path.is_file():
                outputs.append(path.read_bytes().decode("latin-1"))
        assert any(path.suffix == ".toml" for path in out.iterdir()) and (out / "report.md").exists()
    assert "postgresql+psycopg://afc:***@127.0.0.1" in outputs[0]  # the first run names its database, masked
    assert all(postgres.password not in text for text in outputs)
    study = optuna.load_study(study_name="pendulum_case1-vud-ITAE", storage=postgres.url(database))
    assert len(finished_of(study.get_trials())) == 4  # the second run resumed the first's study


def test_another_seed_is_another_study_and_a_shared_study_says_whose_seed_it_samples(tmp_path, paths, edition):
    first = tune(config(tmp_path, paths, edition, trials=2, stop=0.05), outputs=False)
    again = tune(config(tmp_path, paths, edition, trials=3, stop=0.05, seed=999), outputs=False)
    assert (first["study"], again["study"]) == ("pendulum_case1-vud-ITAE", "pendulum_case1-vud-ITAE-seed999")
    assert again["finished"] == 3 and len(trials_of(first["storage"], first["study"])) == 2  # not resumed
    lines = []
    tune(config(tmp_path, paths, edition, trials=3, stop=0.05, seed=7, study="pendulum_case1-vud-ITAE"),
         log=lines.append, outputs=False)
    assert ("note: study 'pendulum_case1-vud-ITAE' was made with --seed 0; this process samples its trials with "
            "--seed 7 (processes sharing a study should differ in seed)") in lines
    assert len(trials_of(first["storage"], first["study"])) == 3


def test_an_sqlite_file_on_a_network_file_system_is_refused():
    mounts = "/dev/sda1 / ext4 rw 0 0\nserver:/export /shared nfs4 rw 0 0\ntmpfs /shared/tmp tmpfs rw 0 0\n"
    assert storage.file_system_of(Path("/shared/studies/x.db"), mounts) == "nfs4"
    assert storage.file_system_of(Path("/shared/tmp/x.db"), mounts) == "tmpfs"  # the longest mount point
    assert storage.file_system_of(Path("/home/me/x.db"), mounts) == "ext4"
    with pytest.raises(storage.TuneError, match=r"^--storage sqlite:////shared/studies/x.db: /shared/studies/x.db "
                                                r"is on a network file system \(nfs4\); SQLite's locks"):
        storage.refuse_shared_sqlite("sqlite:////shared/studies/x.db", mounts)
    storage.refuse_shared_sqlite("sqlite:////shared/tmp/x.db", mounts)  # a local file system: fine
    storage.refuse_shared_sqlite("postgresql+psycopg://u@h/db", mounts)  # a server: fine


def test_a_full_disk_mid_study_is_one_line_naming_the_database_and_keeps_the_trials(tmp_path, edition, paths):
    import resource

    def small_files():  # a file size limit: a write beyond it fails as on a full disk (Python ignores SIGXFSZ)
        resource.setrlimit(resource.RLIMIT_FSIZE, (400 * 1024, 400 * 1024))

    command = _command(tmp_path, edition, 200, "--jobs", "1", "--stop", "0.05")
    done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=240, preexec_fn=small_files)
    database = tmp_path / "pendulum_case1.db"
    assert done.returncode == 1, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: the study database {database} could not be written: "
                                                   "OperationalError: "), done.stderr
    assert "during the commit" not in lines[0] and "resume" in lines[0]
    kept = finished_of(trials_of(f"sqlite:///{database}", "pendulum_case1-vud-ITAE"))
    assert 0 < len(kept) < 200


def test_the_docs_page_shows_the_declared_search_space_and_its_tune_commands_parse():
    import re
    import shlex

    from harness.cli import build_parser

    text = (ROOT / "docs" / "tuning.md").read_text()
    block = text.split("<!-- search space: begin -->\n")[1].split("\n<!-- search space: end -->")[0]
    assert block == space.search_space_markdown(), \
        "docs/tuning.md: paste harness.studies.tune.space.search_space_markdown()"
    parser = build_parser()
    commands = re.findall(r"(?m)^python -m harness (tune [^#\n]*?)\s*(?:#.*)?$", text)
    commands += re.findall(r"`python -m harness (tune [^`]*)`", text)
    commands = [c for c in commands if ".toml" not in c]
    assert len(commands) >= 2
    for command in commands:
        parser.parse_args(shlex.split(command))
