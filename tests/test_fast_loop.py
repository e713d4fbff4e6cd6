"""The fast loop (``python -m pytest -q -m "not slow"``) still tests every module of the project.

Which test files test a module: the rows of tests/README.md (a cell names a module by its path, a
glob of paths, a folder, or a bare file name read in the folder the cell named last). A module is
held to a fast test when one of those files holds a test function that conftest.SLOW does not list.
Modules that hold nothing but a docstring (empty package files) need none. Nothing is imported but
conftest and test_architecture's lists of modules: the test functions are read with ``ast``.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

from tests import conftest
from tests.test_architecture import PACKAGES, TOP_LEVEL_MODULES  # the project's modules, as its import rules see them

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"


def project_modules(root: Path) -> list:
    """Every Python module of the project, as paths relative to ``root``, empty package files left out."""
    paths = [root / f"{name}.py" for name in TOP_LEVEL_MODULES] + \
        [path for package in PACKAGES for path in sorted((root / package).rglob("*.py"))]
    return [path.relative_to(root).as_posix() for path in paths
            if any(not isinstance(node, ast.Expr) for node in ast.parse(path.read_text()).body)]


def covering_files(readme: str, modules) -> dict:
    """{module: test files whose row in ``readme`` names it}."""
    covering = {module: set() for module in modules}
    for test_file, cell in re.findall(r"(?m)^\| \(?`(test_\w+\.py)`\)? \| (.*) \|$", readme):
        folder = ""
        for item in re.findall(r"`([^`]+)`", cell):
            if "/" in item:
                folder = item if item.endswith("/") else item.rsplit("/", 1)[0] + "/"
                pattern = item
            else:
                pattern = folder + item  # or a top-level module: both are tried
            if pattern.endswith("/"):
                pattern += "**"
            elif not re.search(r"\.py$|\*$", pattern):
                continue  # a function, a C file, a command
            patterns = {pattern, item} if "/" not in item else {pattern}
            for module in modules:
                if any(Path(module).match(p) and module.count("/") == p.count("/") or
                       (p.endswith("*") and module.startswith(p.rstrip("*"))) for p in patterns):
                    covering[module].add(test_file)
    return covering


def defined_tests(source: str) -> list:
    """The names of the test functions a test file defines (at module level or in a Test class)."""
    tree = ast.parse(source)
    names = [node.name for node in tree.body if isinstance(node, ast.FunctionDef) and node.name.startswith("test_")]
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name.startswith("Test"):
            names += [item.name for item in node.body
                      if isinstance(item, ast.FunctionDef) and item.name.startswith("test_")]
    return names


def fast_tests(test_file: str, source: str, slow: dict) -> list:
    listed = slow.get(test_file, ())
    return [] if listed == conftest.EVERY_TEST else [name for name in defined_tests(source) if name not in listed]


def modules_without_a_fast_test(root: Path, slow: dict) -> list:
    modules = project_modules(root)
    covering = covering_files((root / "tests" / "README.md").read_text(), modules)
    sources = {path.name: path.read_text() for path in (root / "tests").glob("test_*.py")}
    return [module for module in modules
            if not any(fast_tests(name, sources[name], slow) for name in covering[module] if name in sources)]


def test_every_module_keeps_a_fast_test():
    missing = modules_without_a_fast_test(ROOT, conftest.SLOW)
    assert not missing, (f"no fast test (tests/README.md's rows, conftest.SLOW) for {missing}: name the module in "
                         "the row of a test file, or give it a test that is not slow")


def test_every_slow_entry_names_a_test_that_exists():
    for test_file, listed in conftest.SLOW.items():
        path = TESTS / test_file
        assert path.exists(), f"conftest.SLOW: no test file {test_file}"
        if listed != conftest.EVERY_TEST:
            assert isinstance(listed, tuple), f"conftest.SLOW[{test_file!r}]: a tuple of names or EVERY_TEST"
            unknown = set(listed) - set(defined_tests(path.read_text()))
            assert not unknown, f"conftest.SLOW[{test_file!r}]: no test function {sorted(unknown)}"


def test_the_check_sees_a_module_whose_tests_are_all_slow(tmp_path):
    (tmp_path / "tests").mkdir()
    for name in TOP_LEVEL_MODULES:
        (tmp_path / f"{name}.py").write_text("X = 1\n")
    for package in PACKAGES:
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text('"""only a docstring"""\n')
    (tmp_path / "harness" / "sub").mkdir()
    (tmp_path / "harness" / "sub" / "a.py").write_text("def f():\n    return 1\n")
    (tmp_path / "harness" / "sub" / "b.py").write_text("def g():\n    return 2\n")
    rows = [f"| `test_{name}.py` | `{name}.py` |" for name in TOP_LEVEL_MODULES]
    rows.append("| `test_sub.py` | `harness/sub/a.py` and `b.py` |")
    (tmp_path / "tests" / "README.md").write_text("\n".join(rows) + "\n")
    for name in TOP_LEVEL_MODULES:
        (tmp_path / "tests" / f"test_{name}.py").write_text("def test_it():\n    pass\n")
    (tmp_path / "tests" / "test_sub.py").write_text("def test_one():\n    pass\n\n\nclass TestMore:\n"
                                                    "    def test_two(self):\n        pass\n")
    assert modules_without_a_fast_test(tmp_path, {}) == []
    assert modules_without_a_fast_test(tmp_path, {"test_sub.py": ("test_one",)}) == []
    assert modules_without_a_fast_test(tmp_path, {"test_sub.py": ("test_one", "test_two")}) == \
        ["harness/sub/a.py", "harness/sub/b.py"]
    assert modules_without_a_fast_test(tmp_path, {"test_build_fmu.py": conftest.EVERY_TEST}) == ["build_fmu.py"]
    (tmp_path / "harness" / "sub" / "c.py").write_text("Y = 3\n")  # a module no row names
    assert modules_without_a_fast_test(tmp_path, {}) == ["harness/sub/c.py"]


def test_the_slow_marker_is_registered_and_a_misspelt_one_is_an_error():
    assert "slow" in conftest.MARKERS
    assert re.search(r'(?m)^addopts = ".*--strict-markers', (ROOT / "pyproject.toml").read_text())


def test_the_readme_and_ci_run_the_whole_suite():
    """README's test command (what .ci/run calls) deselects nothing: the fast loop is for working only."""
    command = next(line for line in (ROOT / "README.md").read_text().splitlines()
                   if line.startswith("pip install -e '.[test]' && python -m pytest"))
    command = command.split("#", 1)[0].strip()
    assert command in (ROOT / ".ci" / "run").read_text(), f".ci/run does not run README's test command {command!r}"
    options = command.split("python -m pytest", 1)[1]
    assert not re.search(r"(^|\s)(-m|-k|--deselect|--lf|--last-failed)\b", options), \
        f"README's test command deselects tests: {command}"


def test_ci_requires_the_servers_the_tests_start(monkeypatch):
    """.ci/run installs PostgreSQL and sets AFC_REQUIRE_SERVERS=1: there the PostgreSQL and Dask fixtures fail
    where they would skip elsewhere, so that CI runs those tests or says why not."""
    import pytest

    ci = (ROOT / ".ci" / "run").read_text()
    assert re.search(r"(?m)^export AFC_REQUIRE_SERVERS=1$", ci), ".ci/run: export AFC_REQUIRE_SERVERS=1"
    assert re.search(r"apt-get install [^\n]*\bpostgresql\b", ci), ".ci/run: apt-get install postgresql"
    assert ci.index("AFC_REQUIRE_SERVERS=1") < ci.index("python -m pytest")
    outcomes = []
    for required in (True, False):
        monkeypatch.setattr(conftest, "REQUIRE_SERVERS", required)
        try:
            conftest._unavailable("no server")
        except (pytest.fail.Exception, pytest.skip.Exception) as outcome:  # a skip caught here, not the test's
            outcomes.append((type(outcome), str(outcome)))
    assert outcomes == [(pytest.fail.Exception, "no server; AFC_REQUIRE_SERVERS=1 (.ci/run) requires it"),
                        (pytest.skip.Exception, "no server")]
