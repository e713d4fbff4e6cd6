"""docs/ci.md's recipes run their commands: the GitHub Actions workflow and the GitLab CI job.

In a user's repository laid out by docs/ci.md's own block (the example plant of
tests/data/first_order_lag_fmu.py built by pythonfmu's builder, docs/ci/lag_loop.toml copied; the
afc-fmi checkout a link to this one), the page's first-references block runs, then
every ``run:`` of docs/ci/github-actions.yml (one shell per step, ``bash -e`` as GitHub runs them, with
the workflow's ``env``) and every line of the GitLab job's ``script:`` (one shell, stopping at the first
failing line, with its ``variables``). Two commands cannot run as written here: the checkout or clone
of afc-fmi becomes a link to this checkout, and ``pip install`` runs with ``--dry-run --no-deps`` (the
tests run in the installed project; a real install from a temporary folder would re-point it). The
files each job publishes must exist afterwards; the GitLab job must fail, with both editions run,
when the scenario changed. Both files validate against the services' schemas (check-jsonschema's
vendored copies), and docs/ci.md shows them as they are.
"""
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import pytest
import yaml

from harness.fmu_build import native as build_native
from tests.test_readme_commands import block_commands, readme_blocks

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "ci.md"
GITHUB = ROOT / "docs" / "ci" / "github-actions.yml"
GITLAB = ROOT / "docs" / "ci" / "gitlab-ci.yml"
BIN = Path(sys.executable).parent
PROJECT_LINK = "afc-fmi"  # where both recipes put the afc-fmi checkout

needs_native = pytest.mark.skipif(not build_native.compiler_available(),
                                  reason="the recipes build and run the native edition: zig's C compiler is needed")


def environment(extra: dict) -> dict:
    env = {key: value for key, value in os.environ.items() if not key.startswith(("AFC_", "PYTEST_"))}
    env["PATH"] = os.pathsep.join([str(BIN), env.get("PATH", "")])  # `python`, `pip`, `fmpy` of this environment
    env.pop("PYTHONPATH", None)
    return {**env, **{key: str(value) for key, value in extra.items()}}


def link_project(repo: Path):
    link = repo / PROJECT_LINK
    if not link.exists():
        link.symlink_to(ROOT)


def here(command: str) -> str:
    """A recipe's command as it runs in this test: pip install as a dry run."""
    if command.lstrip().startswith("pip install"):
        words = shlex.split(command)
        assert words[:3] == ["pip", "install", "-e"] and words[3] == f"./{PROJECT_LINK}", command
        return command + " --dry-run --no-deps"
    return command


def page_block(marker: str) -> list:
    """The commands of docs/ci.md's bash block that holds ``marker``."""
    block = next(b for b in readme_blocks(PAGE.read_text(), "docs/ci.md") if b.language == "bash" and marker in b.text)
    return [command.text for command in block_commands(block)]


def run_script(commands: list, folder: Path):
    completed = subprocess.run(["bash", "-c", "set -e\n" + "\n".join(commands)], cwd=folder, env=environment({}),
                               capture_output=True, text=True, timeout=600)
    assert completed.returncode == 0, completed.stdout + completed.stderr


@pytest.fixture(scope="module")
def repo(tmp_path_factory, fmu_paths):
    """A user's repository made by docs/ci.md's layout block, after its first-references block ran in it."""
    folder = tmp_path_factory.mktemp("ci_user_repo")
    link_project(folder)
    run_script(page_block("pythonfmu build"), folder)
    assert (folder / "plant" / "FirstOrderLag.fmu").is_file() and (folder / "ci" / "lag_loop.toml").is_file()
    run_script(page_block("--update"), folder)
    assert (folder / "ci/references/lag_loop_vud_ref.json").is_file()
    assert (folder / "results/junit.xml").is_file() and (folder / "results/regression/report.html").is_file()
    shutil.rmtree(folder / "results")  # what the jobs publish must come from the jobs
    return folder


def junit_counts(path: Path) -> tuple:
    root = ElementTree.parse(path).getroot()
    return int(root.get("tests")), int(root.get("failures"))


# ------------------------------------------------------------------- GitHub
def github_steps() -> tuple:
    workflow = yaml.safe_load(GITHUB.read_text())
    (job,) = workflow["jobs"].values()
    return workflow.get("env", {}), job["steps"]


@needs_native
def test_the_github_actions_workflow_runs_its_commands(repo):
    env, steps = github_steps()
    checkouts = [s for s in steps if s.get("uses", "").startswith("actions/checkout@")]
    assert len(checkouts) == 2 and "with" not in checkouts[0]  # the user's repository, then afc-fmi
    assert checkouts[1]["with"]["path"] == PROJECT_LINK and checkouts[1]["with"]["repository"]
    ran = []
    for step in steps:
        if step is checkouts[1]:
            link_project(repo)
        if "run" not in step:
            continue
        completed = subprocess.run(["bash", "-e", "-c", here(step["run"])], cwd=repo, env=environment(env),
                                   capture_output=True, text=True, timeout=600)
        assert completed.returncode == 0, f"{step.get('name')}: {completed.stdout}{completed.stderr}"
        ran.append(step["run"])
    assert len(ran) == 4 and any("--edition native" in command for command in ran)
    upload = next(s for s in steps if s.get("uses", "").startswith("actions/upload-artifact@"))
    for path in upload["with"]["path"].split():
        assert (repo / path / "report.html").is_file() and (repo / path / "report.md").is_file()
    junit = next(s for s in steps if "junit" in s.get("uses", ""))
    reports = sorted(repo.glob(junit["with"]["report_paths"]))
    assert len(reports) == 2 and all(junit_counts(path) == (1, 0) for path in reports)


# ------------------------------------------------------------------- GitLab
def gitlab_job() -> tuple:
    pipeline = yaml.safe_load(GITLAB.read_text())
    jobs = {name: job for name, job in pipeline.items() if isinstance(job, dict) and "script" in job}
    (job,) = jobs.values()
    return pipeline.get("variables", {}), job


def gitlab_script(job: dict, skip_setup: bool = False) -> str:
    """The job's script as one bash script stopping at the first failing line (as GitLab's runner does)."""
    lines = ["set -eo pipefail"]
    for line in job["script"]:
        if line.startswith("git clone"):
            assert line.split()[-1] == PROJECT_LINK, line
            lines.append(f"[ -e {PROJECT_LINK} ] || ln -s {shlex.quote(str(ROOT))} {PROJECT_LINK}")
        elif skip_setup and (line.startswith("pip install") or "build_fmu.py" in line):
            continue
        else:
            lines.append(here(line))
    return "\n".join(lines)


@needs_native
def test_the_gitlab_ci_job_runs_its_script(repo):
    variables, job = gitlab_job()
    completed = subprocess.run(["bash", "-c", gitlab_script(job)], cwd=repo, env=environment(variables),
                               capture_output=True, text=True, timeout=900)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    artifacts = job["artifacts"]
    assert artifacts["when"] == "always"
    for path in artifacts["paths"]:
        assert (repo / path / "report.html").is_file()
    for path in artifacts["reports"]["junit"]:
        assert junit_counts(repo / path) == (1, 0)


@needs_native
def test_the_gitlab_ci_job_fails_when_the_scenario_changed_and_runs_both_editions(repo, tmp_path):
    changed = tmp_path / "repo"
    shutil.copytree(repo / "ci", changed / "ci")
    shutil.copytree(repo / "plant", changed / "plant")
    scenario = changed / "ci/lag_loop.toml"
    scenario.write_text(scenario.read_text().replace("gamma = 50.0", "gamma = 45.0"))
    variables, job = gitlab_job()
    completed = subprocess.run(["bash", "-c", gitlab_script(job, skip_setup=True)], cwd=changed,
                               env=environment(variables), capture_output=True, text=True, timeout=900)
    assert completed.returncode == 1, completed.stdout + completed.stderr
    for path in job["artifacts"]["reports"]["junit"]:
        assert junit_counts(changed / path) == (1, 1)
        message = ElementTree.parse(changed / path).getroot().find("testsuite/testcase/failure").get("message")
        assert "components.controller.parameters.gamma: 50.0 -> 45.0" in message
        assert re.search(r"[\w.]+: outside the tube by up to", message), message


# ------------------------------------------------------------ the files
def check_schema(schema: str, path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(BIN / "check-jsonschema"), "--builtin-schema", schema, str(path)],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("schema, path", [("vendor.github-workflows", GITHUB), ("vendor.gitlab-ci", GITLAB)])
def test_both_files_validate_against_their_services_schemas(schema, path, tmp_path):
    completed = check_schema(schema, path)
    assert completed.returncode == 0, completed.stdout + completed.stderr
    broken = tmp_path / path.name  # the check can fail: a misspelt key
    broken.write_text(path.read_text().replace("runs-on:", "run-on:").replace("  script:", "  scripts:"))
    assert check_schema(schema, broken).returncode != 0


def test_the_page_shows_both_files_as_they_are_and_the_extras_they_install_exist():
    shown = [block.text for block in readme_blocks(PAGE.read_text(), "docs/ci.md") if block.language == "yaml"]
    assert shown == [GITHUB.read_text(), GITLAB.read_text()]
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    for text in shown:
        for extra in re.findall(r"\./afc-fmi\[(\w+)\]", text):
            assert extra in extras
