"""Every citation of docs/model.md in the code names a section (and choice) that exists there.

Code, tests and comments cite the model by its sections: ``docs/model.md section 9 (scores)``,
``docs/model.md sections 1-6 (the controller)``, ``docs/model.md section 10, choice 13 (settling
time)``.  The words in parentheses must appear in the cited heading (for a range: in one of its
headings; for a choice: in the choice's bold title), so a renumbered or renamed section breaks this
test instead of leaving the citation pointing at the wrong text.  Nothing cites the project's
working notes (their spec file, which the repository does not hold) any more.
"""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the working notes' name, spelt in two pieces so that the tests looking for it do not cite it themselves
WORKING_NOTES = "SP" + "EC"
CITES_WORKING_NOTES = re.compile(rf"\b{WORKING_NOTES}\b")
MODEL = ROOT / "docs" / "model.md"
SOURCES = [*ROOT.glob("*.py"), *[p for folder in ("harness", "plants", "fmu_src", "tests")
                                  for p in (ROOT / folder).rglob("*") if p.suffix in (".py", ".c", ".h", ".toml")]]
CITATION = re.compile(r"docs/model\.md,?((?:,? (?:and )?sections? \d+(?:-\d+)?(?:, choice \d+)?(?: \([^()]*\))?)+)")
PART = re.compile(r"sections? (\d+)(?:-(\d+))?(?:, choice (\d+))?(?: \(([^()]*)\))?")
STOP_WORDS = {"the", "a", "an", "of", "to", "and", "in"}


def headings() -> dict:
    """{section number: heading text} of docs/model.md's numbered sections."""
    return {int(n): title for n, title in re.findall(r"(?m)^## (\d+)\. (.+)$", MODEL.read_text())}


def choices() -> dict:
    """{choice number: its bold title} of the section "Choices where the paper is ambiguous"."""
    section = re.search(r"(?ms)^## \d+\. Choices .*?(?=^## )", MODEL.read_text()).group(0)
    return {int(n): title for n, title in re.findall(r"(?m)^(\d+)\. \*\*(.+?)\*\*", section)}


def citations(text: str) -> list:
    """(section, last section, choice, words) of every docs/model.md citation in ``text``."""
    found = []
    for match in CITATION.finditer(" ".join(text.split())):  # a citation may wrap across lines
        for first, last, choice, words in PART.findall(match.group(1)):
            found.append((int(first), int(last or first), int(choice) if choice else None, words))
    return found


def problems_in(text: str, sections: dict, choice_titles: dict) -> list:
    problems = []
    for first, last, choice, words in citations(text):
        cited = [sections.get(n) for n in range(first, last + 1)]
        if None in cited:
            problems.append(f"section {first}-{last}: docs/model.md has sections {sorted(sections)}")
            continue
        where = " ".join(cited).lower()
        if choice is not None:
            if choice not in choice_titles:
                problems.append(f"section {first}, choice {choice}: no such choice")
                continue
            where = choice_titles[choice].lower()
        missing = [w for w in re.findall(r"[\w'-]+", words.lower()) if w not in STOP_WORDS and w not in where]
        if missing:
            problems.append(f"section {first}{f', choice {choice}' if choice else ''} ({words}): "
                            f"{', '.join(missing)} not in {where!r}")
    return problems


def test_the_code_cites_the_model_and_not_the_working_notes():
    cited = [p for p in SOURCES if citations(p.read_text(errors="replace"))]
    assert len(cited) >= 15, [str(p.relative_to(ROOT)) for p in cited]
    notes = [str(p.relative_to(ROOT)) for p in SOURCES if CITES_WORKING_NOTES.search(p.read_text(errors="replace"))]
    assert not notes, f"cite docs/model.md sections instead of the working notes ({WORKING_NOTES}): {notes}"


@pytest.mark.parametrize("path", [p for p in SOURCES if "docs/model.md" in p.read_text(errors="replace")
                                  and p != Path(__file__)],  # this file's wrong citations are on purpose
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_every_citation_names_a_section_that_says_it(path):
    problems = problems_in(path.read_text(errors="replace"), headings(), choices())
    assert not problems, f"{path.relative_to(ROOT)}: " + "; ".join(problems)


def test_a_wrong_citation_is_caught():
    sections, choice_titles = headings(), choices()
    assert problems_in("docs/model.md section 9 (scores)", sections, choice_titles) == []
    assert problems_in("docs/model.md section 10, choice 13 (settling\n    time)", sections, choice_titles) == []
    assert problems_in("docs/model.md section 7 (scores)", sections, choice_titles)  # renumbered
    assert problems_in("docs/model.md section 99 (scores)", sections, choice_titles)
    assert problems_in("docs/model.md section 10, choice 99 (settling time)", sections, choice_titles)
    assert problems_in("docs/model.md section 7 (the plants) and section 11 (scores)", sections, choice_titles)


#: "issue 17", "issues 16, 22", "Issue #3": a ticket number a reader of the repository cannot open
CITES_AN_ISSUE = re.compile(r"(?i)\bissues? ?#?\d+")
DOCUMENTS = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "native_build").glob("*.py"),
             ROOT / ".ci" / "run"]


def issue_citations(paths) -> list:
    return [f"{p.relative_to(ROOT)}:{number}: {line.strip()}" for p in paths if p.exists()
            for number, line in enumerate(p.read_text(errors="replace").splitlines(), start=1)
            if CITES_AN_ISSUE.search(line)]


def test_nothing_cites_an_issue_number():
    """Comments, docstrings and docs say what a rule is, not which ticket asked for it."""
    found = issue_citations([p for p in [*SOURCES, *DOCUMENTS] if p != Path(__file__)])
    assert not found, "cite the rule or docs/, not an issue number:\n" + "\n".join(found)


def test_an_issue_citation_is_caught(tmp_path):
    source = tmp_path / "x.py"
    source.write_text('"""The sweep (issue 9)."""\nLIMIT = 3  # see issues 16, 22\nOK = "tissue 3"\n')
    found = [line for number, line in enumerate(source.read_text().splitlines(), 1) if CITES_AN_ISSUE.search(line)]
    assert found == ['"""The sweep (issue 9)."""', "LIMIT = 3  # see issues 16, 22"]
