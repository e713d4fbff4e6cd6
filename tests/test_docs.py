"""The README's variable tables come from the FMUs' declaration tables and stay in sync."""
from pathlib import Path

import build_fmu

ROOT = Path(__file__).resolve().parents[1]


def test_readme_variable_tables_are_generated_from_the_declarations():
    readme = (ROOT / "README.md").read_text()
    assert build_fmu.readme_with_tables(readme) == readme, "run: python build_fmu.py --readme"


def test_readme_starts_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    commands = [line for line in lines[:8] if line.startswith("pip install")]
    assert commands[0].startswith("pip install -e . && python -m harness tables")
    assert commands[1].startswith("pip install -e '.[test]' && python -m pytest")
    assert "pip install -e '.[test]' && python -m pytest -q" in (ROOT / ".ci" / "run").read_text()
