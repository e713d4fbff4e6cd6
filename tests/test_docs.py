"""The documentation stands on its own: generated tables are current, links stay in the repository."""
import re
from pathlib import Path

from harness.fmu_build import builder as build_fmu
from harness import scenario as scenarios
from tests.test_model_citations import CITES_WORKING_NOTES, WORKING_NOTES

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "docs" / "model.md"
LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_model_doc_variable_tables_are_generated_from_the_declarations():
    text = MODEL.read_text()
    assert build_fmu.with_variable_tables(text) == text, "run: python build_fmu.py --docs"


def test_master_doc_scenario_keys_are_generated_from_the_schema():
    """docs/master.md's table of scenario keys is harness/scenario.py's SCHEMA, the one the check uses."""
    text = (ROOT / "docs" / "master.md").read_text()
    assert build_fmu.with_scenario_keys(text) == text, "run: python build_fmu.py --docs"
    for key in scenarios.SCHEMA:
        assert f"| `{key.name}` |" in text


def test_the_tables_cover_every_fmu_and_every_declared_variable():
    tables = build_fmu.variable_tables()
    for fmu in build_fmu.FMUS:
        assert f"### `{fmu.model_identifier}`" in tables
        for variable in build_fmu.model_class(fmu.model_identifier).VARIABLES:
            assert f"| `{variable.name}` |" in tables


def test_readme_points_to_the_model_doc_and_holds_no_copy_of_the_tables():
    readme = (ROOT / "README.md").read_text()
    assert "](docs/model.md" in readme
    assert build_fmu.TABLES_BEGIN not in readme and "| name | causality |" not in readme


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _markdown_files():
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _link_targets(document: Path) -> set:
    """The files (resolved) that a page links to, images included."""
    targets = set()
    for target in LINK.findall(document.read_text()):
        if target.startswith(("http://", "https://", "mailto:")):
            continue
        path_part = target.partition("#")[0]
        if path_part:
            targets.add((document.parent / path_part).resolve())
    return targets


def test_every_file_under_docs_is_linked_from_another_page():
    """Nothing in docs/ is an orphan: each file is linked from README.md or another page."""
    linked = {}
    for document in _markdown_files():
        for target in _link_targets(document):
            if target != document.resolve():
                linked.setdefault(target, []).append(document.name)
    files = [p for p in sorted((ROOT / "docs").rglob("*")) if p.is_file()]
    orphans = [str(p.relative_to(ROOT)) for p in files if p.resolve() not in linked]
    assert not orphans, f"files under docs/ that no page links to: {orphans}"


def test_the_contents_page_lists_every_page_and_the_readme_links_the_contents():
    listed = _link_targets(ROOT / "docs" / "index.md")
    pages = [p for p in sorted((ROOT / "docs").rglob("*.md")) if p.name != "index.md"]
    missing = [p.name for p in pages if p.resolve() not in listed]
    assert not missing, f"docs/index.md does not list {missing}"
    assert (ROOT / "docs" / "index.md").resolve() in _link_targets(ROOT / "README.md")


def test_no_page_cites_the_projects_working_notes():
    """A citation of the working notes (their spec file) points outside the repository: cite the
    docs/model.md section it means."""
    for document in _markdown_files():
        for number, line in enumerate(document.read_text().splitlines(), 1):
            assert not CITES_WORKING_NOTES.search(line), f"{document.relative_to(ROOT)}:{number}: {line.strip()}"


def test_readme_stays_a_readme():
    """The manual lives in docs/: the README stays short (at most about 150 lines)."""
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 160, f"README.md has {len(lines)} lines; move sections to docs/"


def test_every_link_of_the_docs_resolves_inside_the_repository():
    """No link leaves the repository (no ../shared): a clone must need nothing outside it."""
    for document in _markdown_files():
        text = document.read_text()
        assert "../shared" not in text and f"{WORKING_NOTES}.md" not in text, f"{document.name} refers outside the repository"
        for target in LINK.findall(text):
            if target.startswith(("http://", "https://", "mailto:")):
                continue
            path_part, _, anchor = target.partition("#")
            path = (document.parent / path_part).resolve() if path_part else document
            assert path.is_relative_to(ROOT), f"{document.name}: link {target} leaves the repository"
            assert path.exists(), f"{document.name}: link {target} points to a missing file"
            if anchor and path.suffix == ".md":
                anchors = {_slug(h) for h in re.findall(r"(?m)^#+ (.+)$", path.read_text())}
                assert anchor in anchors, f"{document.name}: link {target}: no heading with that anchor"


def test_model_doc_numbers_every_equation_of_the_paper():
    text = MODEL.read_text()
    for number in range(1, 40):  # the paper numbers its equations (1) to (39)
        assert re.search(rf"\({number}\)|\(\d+\)-\({number}\)|\({number}\)-\(\d+\)", text) or \
            any(int(a) <= number <= int(b) for a, b in re.findall(r"\((\d+)\)-\((\d+)\)", text)), \
            f"docs/model.md does not mention equation ({number})"


def test_readme_starts_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    commands = [line for line in lines[:20] if line.startswith("pip install")]
    assert commands[0].startswith("pip install -e . && python -m harness tables")
    assert commands[1].startswith("pip install -e '.[test]' && python -m pytest")
    assert "pip install -e '.[test]' && python -m pytest -q" in (ROOT / ".ci" / "run").read_text()


def test_model_doc_scenario_table_matches_the_scenario_files():
    from harness import scenario as scenarios

    rows = re.findall(r"(?m)^\| `(\w+)` \| [^|]+ \| [^|]+ \| ([0-9.e-]+) \| [^|]+ \|$", MODEL.read_text())
    assert sorted(name for name, _ in rows) == scenarios.scenario_names()
    for name, step in rows:
        configured = scenarios.load(name)
        assert float(step) == configured.step, f"docs/model.md: {name} step {step}, scenario file {configured.step}"
        assert configured.start == 0.0 and configured.stop == 20.0  # "All run from 0 to 20 s"


def test_the_tests_readme_maps_every_test_file():
    """tests/README.md "maps every file to what it covers": a new test file (a new study's, host's) gets its row."""
    text = (ROOT / "tests" / "README.md").read_text()
    rows = set(re.findall(r"(?m)^\| \(?`(test_\w+\.py)`\)? \|", text))
    files = {path.name for path in (ROOT / "tests").glob("test_*.py")}
    assert not files - rows, f"tests/README.md: no row for {sorted(files - rows)}"
    assert not rows - files, f"tests/README.md: rows for missing files {sorted(rows - files)}"
