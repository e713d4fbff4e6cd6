"""The wheel holds every file the builds and the harness read: each plant folder, the C sources of
both editions, the native build's stages and stored experiments (a non-editable install builds
every FMU from it)."""
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def shipped_sources() -> set:
    """The project's files a wheel must hold (what git tracks under the packages, but the tests)."""
    tracked = subprocess.run(["git", "ls-files", "fmu_src", "plants", "harness/fmu_build", "harness/*.py", "harness/*.c",
                              "harness/*.h", "harness/hosts/*.c", "harness/scenarios", "harness/references"], cwd=ROOT,
                             capture_output=True, text=True, check=True).stdout.split()
    return set(tracked)


@pytest.fixture(scope="module")
def wheel_names(tmp_path_factory):
    """The wheel of a copy of the tracked files (the checkout's build/ would lend it stale copies)."""
    tree, folder = tmp_path_factory.mktemp("tree"), tmp_path_factory.mktemp("wheel")
    for name in subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split():
        if (ROOT / name).is_file():
            (tree / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, tree / name)
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(folder), str(tree)],
                   check=True, capture_output=True, timeout=600)
    (wheel,) = folder.glob("*.whl")
    return set(zipfile.ZipFile(wheel).namelist())


def test_the_wheel_holds_every_source_the_builds_read(wheel_names):
    missing = sorted(shipped_sources() - wheel_names)
    assert not missing, f"pyproject.toml's packages or package-data leave out: {missing}"


def test_a_plant_folder_is_found_as_a_package(wheel_names):
    folders = sorted(p.parent.name for p in (ROOT / "plants").glob("*/fmu.py"))
    assert len(folders) >= 4
    for name in folders:
        assert {f"plants/{name}/fmu.py", f"plants/{name}/model.c"} <= wheel_names, name


def test_the_wheel_puts_only_the_projects_packages_at_the_top_of_site_packages(wheel_names):
    """The builds live in harness/fmu_build/: pip puts no top-level module of ours beside the packages
    (build_fmu.py is the checkout's command, not an installed module)."""
    top = {name.split("/")[0] for name in wheel_names if not name.split("/")[0].endswith(".dist-info")}
    assert top == {"fmu_src", "plants", "harness"}, f"top-level names in the wheel: {sorted(top)}"
