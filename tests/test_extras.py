"""What an install pulls in: the core install (`pip install -e .`) is what the main job
and the FMUs need; the host studies, the cluster, the native edition and the tests are extras, and a
command that needs a missing extra says which, in one line.

"Not installed" is simulated in a child process: a sitecustomize.py on PYTHONPATH sets
``sys.modules[name] = None`` for each package named in AFC_TEST_UNINSTALLED, so importing it fails
and ``importlib.util.find_spec`` finds nothing, as without the package (worker processes inherit it).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: import names of every package only an extra brings (pytest: this test runs under it, but no command may need it)
EXTRA_MODULES = ("ecospy", "libcosimpy", "fmu_manipulation_toolbox", "dask", "distributed", "ziglang", "scipy", "lief",
                 "pytest")


def names(requirements) -> set:
    return {re.split(r"[\[<>=!;~ ]", requirement, maxsplit=1)[0].lower() for requirement in requirements}


def test_the_core_install_is_what_the_main_job_and_the_fmus_need():
    core = names(PROJECT["dependencies"])
    assert core == {"fmpy", "pythonfmu", "numpy", "tqdm", "matplotlib", "pyfunnel", "tomli"}, core
    extras = {extra: names(requirements) for extra, requirements in PROJECT["optional-dependencies"].items()}
    assert extras["hosts"] == {"ecospy", "tbb", "libcosimpy", "fmu-manipulation-toolbox"}
    assert extras["native"] == {"ziglang"} and extras["cluster"] == {"dask"}
    assert {"pytest", "scipy", "lief"} <= extras["test"]
    # the suite runs every study: the test extra brings every other extra (as itself: afc-fmi[hosts,native,cluster])
    test_with = next(r for r in PROJECT["optional-dependencies"]["test"] if r.startswith(PROJECT["name"] + "["))
    assert {"hosts", "native", "cluster"} <= set(test_with.split("[", 1)[1].rstrip("]").split(","))


def uninstalled(tmp_path, packages, *argv, timeout=600) -> subprocess.CompletedProcess:
    """``python -m harness ARGV`` (or ``python ARGV`` for a .py) as if ``packages`` were not installed."""
    folder = tmp_path / "uninstalled"
    folder.mkdir(exist_ok=True)
    (folder / "sitecustomize.py").write_text(
        "import os, sys\n"
        "for _name in filter(None, os.environ.get('AFC_TEST_UNINSTALLED', '').split(',')):\n"
        "    sys.modules[_name] = None\n")
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join([str(folder), str(ROOT)]),
                   "AFC_TEST_UNINSTALLED": ",".join(packages)}
    environment.pop("AFC_EDITION", None)
    command = [sys.executable, *argv] if argv[0].endswith(".py") else [sys.executable, "-m", "harness", *argv]
    return subprocess.run(command, cwd=tmp_path, env=environment, capture_output=True, text=True, timeout=timeout)


def test_the_main_job_runs_on_the_core_install_alone(fmu_paths, tmp_path):
    done = uninstalled(tmp_path, EXTRA_MODULES, "tables", "--stop", "0.05", "--refine", "0", "--jobs", "1",
                       "--out", str(tmp_path / "results"))
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "results" / "report.md").is_file() and "Traceback" not in done.stderr
    run = uninstalled(tmp_path, EXTRA_MODULES, "run", "pendulum_case1", "--stop", "0.05", "--json")
    assert run.returncode == 0 and '"ITAE"' in run.stdout, run.stderr


@pytest.fixture(scope="module")
def ssp_package(fmu_paths, tmp_path_factory):
    path = tmp_path_factory.mktemp("ssp") / "p.ssp"
    from harness.cli import main

    assert main(["export-ssp", "pendulum_case1", "--out", str(path)]) == 0
    return path


@pytest.mark.parametrize("what,packages,argv,extra", [
    ("compare-engines without ecospy", ("ecospy",), ("compare-engines", "pendulum_case1", "--stop", "0.01"), "hosts"),
    ("run-ssp in Ecos without ecospy", ("ecospy",), ("run-ssp", "{ssp}", "--stop", "0.01"), "hosts"),
    ("sweep on a cluster without dask", ("dask", "distributed"),
     ("sweep", "pendulum_case1", "--grid", "plant.mp=0.1", "--stop", "0.01", "--scheduler", "tcp://localhost:1",
      "--out", "{tmp}/sweep"), "cluster"),
    ("tune on a cluster without dask", ("dask", "distributed"),
     ("tune", "pendulum_case1", "--stop", "0.05", "--trials", "1", "--scheduler", "tcp://localhost:1",
      "--out", "{tmp}/tune"), "cluster"),
    ("tune on PostgreSQL without its driver", ("psycopg",),
     ("tune", "pendulum_case1", "--stop", "0.05", "--trials", "1", "--storage",
      "postgresql+psycopg://afc@127.0.0.1:1/tune", "--out", "{tmp}/tune"), "postgres"),
    ("mutate without pytest", ("pytest",), ("mutate", "--only", "theta_euler_sign"), "test"),
    ("the native build without zig", ("ziglang",), ("build_fmu.py", "--edition", "native"), "native"),
])
def test_a_command_that_needs_a_missing_extra_says_which_in_one_line(fmu_paths, ssp_package, tmp_path, what, packages,
                                                                      argv, extra):
    argv = [part.format(ssp=ssp_package, tmp=tmp_path) for part in argv]
    if argv[0].endswith(".py"):
        argv[0] = str(ROOT / argv[0])
    done = uninstalled(tmp_path, packages, *argv, timeout=300)
    errors = [line for line in done.stderr.splitlines() if "error" in line.lower()]
    assert done.returncode != 0, f"{what}: exit 0\n{done.stdout}{done.stderr}"
    assert len(errors) == 1 and "Traceback" not in done.stderr, f"{what}:\n{done.stderr}"
    assert f"pip install -e '.[{extra}]'" in errors[0], f"{what}: {errors[0]}"


def test_the_host_matrix_skips_a_host_whose_extra_is_missing_and_says_so(fmu_paths, tmp_path):
    done = uninstalled(tmp_path, ("ecospy", "libcosimpy"), "hosts", "pendulum_case1", "--host", "ecos", "libcosim-ssp",
                       "--stop", "0.01", "--out", str(tmp_path / "hosts"))
    assert done.returncode == 0, done.stderr
    assert "skipped ecos: ecospy is not installed (pip install -e '.[hosts]')" in done.stdout + done.stderr
    assert "skipped libcosim-ssp: libcosimpy is not installed (pip install -e '.[hosts]')" in done.stdout + done.stderr
