"""`regress` on a user's own scenario, and its outputs (harness/studies/regression/).

The plant is one the project does not ship: a first-order lag made with plain pythonfmu in the test
(tests/data/first_order_lag_fmu.py), wired to our controller by docs/ci/lag_loop.toml in a user's
repository laid out as docs/ci.md says (tests/user_repo.py). Through the command line: the first
``--update`` creates the references with the scenario's hash, ``--junit`` passes, a changed
controller parameter fails with the JUnit failure naming the signal, and the HTML report shows the
failing signals first with their plots; its links and images resolve, and headless Chromium renders
it with every image loaded (where Chromium is installed). Through the API, on the same runs: per-signal
tolerances from the reference's metadata, the wall-time flag, a changed scenario file.
"""
import contextlib
import io
import json
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ElementTree
from html.parser import HTMLParser
from pathlib import Path

import pytest

from harness.cli import main as cli_main
from harness.studies import regression
from harness.studies.regression import Case
from tests.user_repo import make_user_repo

MUTATION = ("controller.gamma", 40.0)  # docs/ci/lag_loop.toml has gamma = 50


def run_cli(arguments, folder: Path) -> tuple:
    """(exit status, stdout, stderr) of ``python -m harness ARGUMENTS`` run in ``folder`` (in this process)."""
    out, err = io.StringIO(), io.StringIO()
    before = os.getcwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = cli_main(arguments)
    finally:
        os.chdir(before)
    return status, out.getvalue(), err.getvalue()


REGRESS = ["regress", "ci/lag_loop.toml", "--controller", "vud", "--references", "ci/references"]


@pytest.fixture(scope="module")
def flow(tmp_path_factory, lag_plant_fmu, fmu_paths):
    """The user's flow on the command line: --update, a passing --junit run, a mutated --junit run."""
    repo = make_user_repo(tmp_path_factory.mktemp("user_repo"), lag_plant_fmu)
    update = run_cli([*REGRESS, "--update", "--report", "results/update"], repo)
    passing = run_cli([*REGRESS, "--junit", "results/pass.xml", "--report", "results/pass"], repo)
    failing = run_cli([*REGRESS, "--set", f"{MUTATION[0]}={MUTATION[1]:g}", "--junit", "results/fail.xml",
                       "--report", "results/fail"], repo)
    return {"repo": repo, "update": update, "pass": passing, "fail": failing}


def junit(path: Path) -> ElementTree.Element:
    return ElementTree.parse(path).getroot()


def test_the_first_update_creates_the_references_with_the_scenarios_hash(flow):
    repo = flow["repo"]
    status, out, _ = flow["update"]
    assert status == 0 and "reference lag_loop_vud: new" in out
    csv_path, json_path = repo / "ci/references/lag_loop_vud_ref.csv", repo / "ci/references/lag_loop_vud_ref.json"
    assert csv_path.is_file() and json_path.is_file()
    meta = json.loads(json_path.read_text())
    case = Case(str(repo / "ci/lag_loop.toml"), "vud")
    assert meta["scenario_hash"] == regression.scenario_fingerprint(case)[0] and len(meta["scenario_hash"]) == 64
    assert meta["scenario_file"] == "ci/lag_loop.toml"
    recorded = ["plant.y", "reference.ym", "reference.dym", "reference.e", "reference.de", "controller.u",
                "controller.theta1", "controller.theta2", "controller.theta3"]
    assert meta["signals"] == recorded  # a user's scenario compares what it records
    assert csv_path.read_text().splitlines()[0] == ",".join(f'"{n}"' for n in ["time", *recorded])
    assert meta["tolerances"] == regression.DEFAULT_TOLERANCES and meta["signal_tolerances"] == {}
    assert meta["wall_s"] > 0 and meta["stop"] == 10.0


def test_a_plain_run_passes_and_writes_junit(flow):
    repo = flow["repo"]
    status, out, _ = flow["pass"]
    assert status == 0, out
    assert "1/1 cases pass" in out and "results/pass/report.html" in out and "JUnit XML: results/pass.xml" in out
    root = junit(repo / "results/pass.xml")
    assert root.tag == "testsuites" and root.get("tests") == "1" and root.get("failures") == "0"
    (suite,) = root.findall("testsuite")
    (case,) = suite.findall("testcase")
    assert case.get("classname") == "regress.lag_loop" and case.get("name") == "lag_loop_vud"
    assert case.find("failure") is None and float(case.get("time")) > 0
    report = suite.find("properties/property[@name='report']").get("value")
    assert (repo / report).is_file() and report.endswith("report.html")
    assert "report: results/pass/report.html" in case.find("system-out").text
    # the wall times are numbers; a run slower than SLOW_FACTOR x its reference (a loaded machine) adds a
    # property in words beside them
    walls = {p.get("name"): float(p.get("value")) for p in case.findall("properties/property")
             if p.get("name").endswith("_s")}
    assert walls["wall_s"] > 0 and walls["reference_wall_s"] > 0


def test_a_changed_controller_parameter_fails_and_the_junit_failure_names_the_signal(flow):
    repo = flow["repo"]
    status, out, _ = flow["fail"]
    assert status == 1 and "0/1 cases pass" in out
    root = junit(repo / "results/fail.xml")
    assert root.get("failures") == "1"
    case = root.find("testsuite/testcase")
    assert case.get("name") == "lag_loop_vud [controller.gamma=40]"
    failure = case.find("failure")
    message = failure.get("message")
    found = re.match(r"^([\w.]+): outside the tube by up to ([0-9.e+-]+) at t = ([0-9.e+-]+) s", message)
    assert found, message
    signal, excursion, time = found.group(1), float(found.group(2)), float(found.group(3))
    assert signal in {"plant.y", "reference.e", "controller.u", "controller.theta1", "controller.theta2",
                      "controller.theta3"} and excursion > 0 and 0 <= time <= 10
    assert {"controller.u", "controller.theta1"} <= set(re.findall(r"^([\w.]+): outside", failure.text, re.M))
    assert "report: results/fail/report.html" in case.find("system-out").text


class Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.images, self.ids, self.order = [], [], set(), []

    def handle_starttag(self, tag, attributes):
        attributes = dict(attributes)
        if "id" in attributes:
            self.ids.add(attributes["id"])
            self.order.append(attributes["id"])
        if tag == "a" and "href" in attributes:
            self.links.append(attributes["href"])
        if tag == "img":
            self.images.append(attributes.get("src"))
            assert attributes.get("alt"), "every image has a text alternative"


def unresolved(page: Path) -> list:
    """The links and images of ``page`` that point at nothing: a missing file beside it or a missing anchor."""
    parser = Links()
    parser.feed(page.read_text())
    missing = []
    for target in parser.links + parser.images:
        if target.startswith("#"):
            if target[1:] not in parser.ids:
                missing.append(target)
        elif re.match(r"^[a-z]+:", target) or target.startswith("/"):
            missing.append(target)  # the report is a folder that travels: nothing absolute, nothing online
        elif not (page.parent / target.split("#")[0]).is_file():
            missing.append(target)
    return missing


def test_the_html_report_shows_failing_signals_first_with_their_plots_and_every_link_resolves(flow):
    page = flow["repo"] / "results/fail/report.html"
    parser = Links()
    parser.feed(page.read_text())
    assert not unresolved(page)
    failing = [i for i in parser.order if i.startswith("case-") and "--" in i]
    assert len(failing) == 6 and len(parser.images) == 6  # six signals fail, each with its plot
    assert parser.order.index("failures") < parser.order.index(failing[0]) < parser.order.index("passing")
    assert all(parser.order.index(i) < parser.order.index("passing") for i in failing)
    for image in parser.images:
        assert (page.parent / image).stat().st_size > 10_000
    text = page.read_text()
    assert text.index("Failing (6 signals") < text.index("Passing signals (3)")
    assert "report.md" in parser.links and (page.parent / "report.md").is_file()
    passing_page = flow["repo"] / "results/pass/report.html"
    assert not unresolved(passing_page) and "None: every signal of every case lies inside its tube" in \
        passing_page.read_text()


def test_the_link_check_sees_a_missing_image(flow, tmp_path):
    copy = tmp_path / "report"
    shutil.copytree(flow["repo"] / "results/fail", copy)
    next(copy.glob("*.png")).unlink()
    assert len(unresolved(copy / "report.html")) == 1


CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
#: as root, without a network: no sandbox, no background connections (docs/ci.md)
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]
IMAGE_CHECK = ("<script>window.addEventListener('load', function () { var bad = []; "
               "for (var i = 0; i < document.images.length; i++) { var im = document.images[i]; "
               "if (!(im.complete && im.naturalWidth > 0)) bad.push(im.getAttribute('src')); } "
               "document.body.setAttribute('data-images', bad.length ? 'BROKEN:' + bad.join(',') "
               ": 'LOADED:' + document.images.length); });</script>")


def render(page: Path, work: Path) -> str:
    """What headless Chromium says of the images of ``page`` once loaded (a copy with a checking script)."""
    probe = page.with_name("probe.html")
    probe.write_text(page.read_text().replace("</body>", IMAGE_CHECK + "</body>"))
    completed = subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={work / 'profile'}",
                                "--virtual-time-budget=10000", "--dump-dom", probe.as_uri()],
                               capture_output=True, text=True, timeout=120)
    found = re.search(r'data-images="([^"]*)"', completed.stdout)
    return found.group(1) if found else f"no verdict (exit {completed.returncode}): {completed.stderr[-500:]}"


@pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (Debian: apt-get install chromium)")
def test_headless_chromium_renders_the_report_with_every_plot(flow, tmp_path):
    copy = tmp_path / "report"
    shutil.copytree(flow["repo"] / "results/fail", copy)
    assert render(copy / "report.html", tmp_path) == "LOADED:6"
    screenshot = tmp_path / "report.png"
    subprocess.run([CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1280,2000",
                    f"--screenshot={screenshot}", (copy / "report.html").as_uri()], capture_output=True, timeout=120)
    assert screenshot.stat().st_size > 50_000  # a page with text and plots, not a blank one
    next(copy.glob("*.png")).unlink()  # the check can fail: a missing plot is seen
    assert render(copy / "report.html", tmp_path).startswith("BROKEN:")


# ------------------------------------------------- the same runs through the API
@pytest.fixture(scope="module")
def mutated_run(flow, fmu_paths):
    case = Case(str(flow["repo"] / "ci/lag_loop.toml"), "vud", overrides=(MUTATION,))
    return regression.run_cases([case], workers=1, fmu_paths=fmu_paths)[0]


def references_copy(flow, folder: Path) -> Path:
    shutil.copytree(flow["repo"] / "ci/references", folder)
    return folder


def edit_meta(folder: Path, **changes):
    path = folder / "lag_loop_vud_ref.json"
    meta = json.loads(path.read_text())
    meta.update(changes)
    path.write_text(json.dumps(meta))


def test_per_signal_tolerances_in_the_reference_metadata_decide_each_signal(flow, mutated_run, tmp_path):
    folder = references_copy(flow, tmp_path / "refs")
    strict = regression.regress([mutated_run.case], runs=[mutated_run], reference_dir=folder, report_dir=None)
    failing = {s.signal for s in strict.comparisons[0].signals if not s.passed}
    assert {"controller.u", "controller.theta1"} <= failing
    loose = {name: {"rtoly": 0.5} for name in failing}  # half the range: the mutation fits
    edit_meta(folder, signal_tolerances=loose)
    outcome = regression.regress([mutated_run.case], runs=[mutated_run], reference_dir=folder,
                                 report_dir=tmp_path / "report")
    assert outcome.passed
    by_name = {s.signal: s for s in outcome.comparisons[0].signals}
    assert all(by_name[name].tolerances["rtoly"] == 0.5 for name in failing)
    assert by_name["plant.y"].tolerances["rtoly"] == 0.5 and by_name["reference.ym"].tolerances["rtoly"] == 1e-3
    assert "rtoly = 0.5" in (tmp_path / "report" / "report.md").read_text()
    edit_meta(folder, signal_tolerances={"controller.u": {"rtoly": 0.5}})  # one signal only: the others fail
    partly = regression.regress([mutated_run.case], runs=[mutated_run], reference_dir=folder, report_dir=None)
    still = {s.signal for s in partly.comparisons[0].signals if not s.passed}
    assert still == failing - {"controller.u"}
    # the command line's tolerances override the metadata's, for every signal
    override = regression.regress([mutated_run.case], runs=[mutated_run], reference_dir=folder, report_dir=None,
                                  tolerances={"rtoly": 1e-3})
    assert "controller.u" in {s.signal for s in override.comparisons[0].signals if not s.passed}


def test_an_update_keeps_the_tolerances_of_the_metadata(flow, tmp_path, fmu_paths):
    folder = references_copy(flow, tmp_path / "refs")
    edit_meta(folder, signal_tolerances={"controller.u": {"rtoly": 0.01}}, tolerances={"atolx": 0.002})
    case = Case(str(flow["repo"] / "ci/lag_loop.toml"), "vud")
    reference = regression.read_reference(case, folder)
    run = regression.CaseRun(case, 0.0, 10.0, 0.001, reference.time, dict(reference.signals), 1.0)
    regression.regress([case], runs=[run], reference_dir=folder, report_dir=None, update=True)
    meta = json.loads((folder / "lag_loop_vud_ref.json").read_text())
    assert meta["signal_tolerances"] == {"controller.u": {"rtoly": 0.01}}
    assert meta["tolerances"]["atolx"] == 0.002 and meta["tolerances"]["rtoly"] == 1e-3


@pytest.mark.parametrize("changes, culprit", [
    ({"signal_tolerances": {"controller.thetaX": {"rtoly": 0.1}}}, "'controller.thetaX', which is not compared"),
    ({"signal_tolerances": {"controller.u": {"rtol": 0.1}}}, "unknown tolerance 'rtol'; valid: atolx"),
    ({"signal_tolerances": {"controller.u": {"rtoly": -1}}}, "rtoly = -1 is invalid; give a finite number >= 0"),
    ({"tolerances": {"atolx": "big"}}, "tolerances: atolx = 'big' is invalid"),
])
def test_a_mistake_in_the_metadata_tolerances_is_one_line_exit_2(flow, tmp_path, changes, culprit):
    repo = tmp_path / "repo"
    shutil.copytree(flow["repo"] / "ci", repo / "ci")
    shutil.copytree(flow["repo"] / "plant", repo / "plant")
    edit_meta(repo / "ci/references", **changes)
    status, out, err = run_cli(REGRESS, repo)
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert "lag_loop_vud_ref.json" in lines[0] and culprit in lines[0]
    assert not (repo / "results").exists()  # said before any run


def test_a_run_more_than_twice_as_slow_as_its_reference_is_flagged(flow, mutated_run, tmp_path):
    folder = references_copy(flow, tmp_path / "refs")
    case = Case(str(flow["repo"] / "ci/lag_loop.toml"), "vud")
    reference = regression.read_reference(case, folder)
    run = regression.CaseRun(case, 0.0, 10.0, 0.001, reference.time, dict(reference.signals), 3.0)
    edit_meta(folder, wall_s=1.4)  # 3.0 / 1.4 = 2.14 > 2
    outcome = regression.regress([case], runs=[run], reference_dir=folder, report_dir=tmp_path / "report",
                                 junit=tmp_path / "junit.xml")
    comparison = outcome.comparisons[0]
    assert comparison.passed and comparison.slowdown == pytest.approx(3.0 / 1.4)
    assert "2.1x slower than the reference run" in regression.slowness(comparison)
    slow = junit(tmp_path / "junit.xml").find("testsuite/testcase/properties/property[@name='slow']")
    assert slow is not None and slow.get("value").startswith("2.1x slower")
    assert "2.1x slower" in (tmp_path / "report" / "report.html").read_text()
    edit_meta(folder, wall_s=1.6)  # 1.9x: not flagged
    outcome = regression.regress([case], runs=[run], reference_dir=folder, report_dir=None)
    assert regression.slowness(outcome.comparisons[0]) == ""


def test_an_edited_scenario_file_is_detected_by_its_hash_and_the_change_is_named(flow, fmu_paths, tmp_path):
    repo = tmp_path / "repo"
    shutil.copytree(flow["repo"] / "ci", repo / "ci")
    shutil.copytree(flow["repo"] / "plant", repo / "plant")
    scenario = repo / "ci/lag_loop.toml"
    case = Case(str(scenario), "vud")
    reference = regression.read_reference(case, repo / "ci/references")
    run = regression.CaseRun(case, 0.0, 10.0, 0.001, reference.time, dict(reference.signals), 1.0)
    scenario.write_text(scenario.read_text().replace("# A user's closed loop", "# a comment changed\n# A user's"))
    same = regression.regress([case], runs=[run], reference_dir=repo / "ci/references", report_dir=None)
    assert same.passed  # comments do not count
    scenario.write_text(scenario.read_text().replace("gamma = 50.0", "gamma = 45.0"))
    changed = regression.regress([case], runs=[run], reference_dir=repo / "ci/references", report_dir=None,
                                 junit=tmp_path / "junit.xml")
    message = changed.comparisons[0].message
    assert not changed.passed and "scenario changed since the reference" in message
    assert "components.controller.parameters.gamma: 50.0 -> 45.0" in message
    assert "scenario changed" in junit(tmp_path / "junit.xml").find("testsuite/testcase/failure").get("message")


def test_junit_with_update_and_a_file_as_references_are_usage_errors(flow):
    status, _, err = run_cli([*REGRESS, "--update", "--junit", "x.xml"], flow["repo"])
    assert status == 2 and "--junit with --update" in err
    status, _, err = run_cli([*REGRESS[:-1], "ci/lag_loop.toml"], flow["repo"])
    assert status == 2 and "not a folder" in err


# ------------------------------------------------------------ names that hold HTML or shell syntax
HOSTILE = "<img src=y onerror=alert(1)>"  # a scenario file's name (the case's), in a folder a shell would split


def hostile_case(tmp_path) -> tuple:
    """A user's scenario file HOSTILE.toml in a folder named with a space, a quote, '&' and '<b>'."""
    from harness import scenario as scenarios

    folder = tmp_path / "it's & <b>mine"
    folder.mkdir()
    path = folder / f"{HOSTILE}.toml"
    path.write_text((scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text())
    return Case(str(path), "vud"), path


def fabricated(case, scale: float = 1.0) -> "regression.CaseRun":
    """A run of ``case`` made from the committed reference of pendulum_case1 (no simulation), plant.y scaled."""
    reference = regression.read_reference(Case("pendulum_case1", "vud"))
    signals = {name: reference.signals[name] * (scale if name == "plant.y" else 1.0)
               for name in regression.case_signals(case) if name in reference.signals}
    return regression.CaseRun(case, 0.0, 20.0, 0.0005, reference.time.copy(), signals, 1.0)


def test_report_md_shows_html_in_names_as_text_and_the_html_report_escapes_it(tmp_path):
    case, _ = hostile_case(tmp_path)
    folder = tmp_path / "references"
    regression.regress([case], runs=[fabricated(case)], reference_dir=folder, update=True, report_dir=None)
    outcome = regression.regress([case], runs=[fabricated(case, 1.01)], reference_dir=folder,
                                 report_dir=tmp_path / "report")
    assert not outcome.passed
    markdown = (tmp_path / "report" / "report.md").read_text()
    assert HOSTILE.split()[0] not in markdown and "<" not in markdown  # no raw HTML at all
    assert markdown.count("&lt;img src=y onerror=alert(1)&gt;") >= 10  # the name, shown as written, in every row
    assert "![](" in markdown and "**FAIL**" in markdown  # the report's own Markdown is kept
    page = (tmp_path / "report" / "report.html").read_text()
    assert HOSTILE not in page and "&lt;img src=y onerror=alert(1)&gt;" in page


def test_the_missing_references_hint_is_a_command_a_shell_runs_as_printed(tmp_path, monkeypatch, capsys):
    import shlex

    case, path = hostile_case(tmp_path)
    monkeypatch.setattr(regression.command, "run_cases", lambda cases, **kw: [fabricated(c) for c in cases])
    empty = tmp_path / "no refs & <here>"
    assert cli_main(["regress", str(path), "--controller", "vud", "--references", str(empty), "--report",
                     str(tmp_path / "report")]) == 1
    hint = capsys.readouterr().err.strip().splitlines()[-1]
    command = re.fullmatch(r"missing references: create them with `(.*)`", hint).group(1)
    assert shlex.split(command) == ["python", "-m", "harness", "regress", str(path), "--update", "--references",
                                    str(empty)]
    message = regression.compare_case(fabricated(case), None, reference_dir=empty).message
    quoted = re.search(r"run (`+) ?(.*?) ?\1 to create it", message).group(2)
    assert shlex.split(quoted) == ["python", "-m", "harness", "regress", str(path), "--controller", "vud", "--update",
                                   "--references", str(empty)]


@pytest.mark.parametrize("name", ["../../escaped", "a/b", ".hidden"])
def test_a_scenario_name_that_would_put_references_elsewhere_is_refused(tmp_path, name):
    from harness import scenario as scenarios

    scenario = scenarios.load("pendulum_case1")
    scenario.name = name  # a Scenario built in Python: its name, not a file's stem, names the case
    with pytest.raises(regression.references.cli_args.UsageError, match=f"scenario name {re.escape(repr(name))} "
                                                                         "cannot name a reference file"):
        regression.reference_paths(Case(scenario, "vud"), tmp_path / "references")
