"""A user's repository as docs/ci.md lays it out: their plant FMU, their scenario, their references.

    plant/FirstOrderLag.fmu   the user's plant (here the lag of tests/data/first_order_lag_fmu.py)
    ci/lag_loop.toml          their closed loop with our controller (a copy of docs/ci/lag_loop.toml)
    ci/references/            made by the first `regress --update` (not made here)
"""
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "docs" / "ci" / "lag_loop.toml"


def make_user_repo(folder: Path, plant_fmu: Path) -> Path:
    (folder / "plant").mkdir(parents=True, exist_ok=True)
    (folder / "ci").mkdir(exist_ok=True)
    shutil.copy(plant_fmu, folder / "plant" / "FirstOrderLag.fmu")
    shutil.copy(SCENARIO, folder / "ci" / "lag_loop.toml")
    return folder
