"""Every command in README.md runs as written and does what the text says.

How README blocks are run (keep to this when adding a section):

* Fenced blocks tagged ``bash``, ``sh`` or ``console`` are commands and are run; ``python``
  blocks are run with this Python; ``text`` or untagged blocks are not commands (synopses,
  output) and are not run.
* Blocks run in README order in one temporary working directory that links every file and
  folder of the repository (so ``build_fmu.py``, ``docs/...``, ``tests/...`` resolve) except
  ``results/`` and ``build/``, which start empty (``build/fmus`` links the built FMUs). A block
  may use what an earlier block wrote. Every file a block writes must land in a folder that
  .gitignore covers (checked with ``git check-ignore``).
* In a ``console`` block, the lines starting with ``$ `` are the commands; the other lines are
  sample output and are not compared.
* A command's trailing comment is what the text promises, and is checked: ``exit N`` in it means
  the command must exit with status N (default 0); each "double-quoted text" in it must appear
  in the command's output (stdout and stderr).
* An HTML comment right before the block's fence adjusts the run, one directive per line::

    <!-- test
    skip: REASON              the block is not run (say why: e.g. it needs other hosts)
    sub: OLD => NEW           replace the first OLD in the block before it runs (OLD must occur)
    append: PREFIX => ARGS    ARGS appended to every command that starts with PREFIX
    omit: PREFIX => REASON    commands starting with PREFIX are not run
    files: PATH ...           these files exist afterwards (relative to the working directory)
    output: TEXT              the block's output contains TEXT (repeatable)
    output-re: REGEX          the block's output matches REGEX (repeatable)
    requires: PROGRAM ...     skip the block (saying so) when a program is not on PATH (e.g. cc)
    timeout: SECONDS          default 300
    -->

  Use ``sub``/``append`` only to shorten a run (``--stop``, fewer grid points, fewer cases), not
  to change what a command does.
"""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RUN_LANGUAGES = ("bash", "sh", "console", "python")
NOT_LINKED = {".git", ".venv", "build", "results", ".pytest_cache", "__pycache__"}
OWN_FOLDERS = ("results", "build")


@dataclass
class Block:
    line: int  # 1-based line of the opening fence
    language: str
    text: str
    skip: str = ""
    subs: list = field(default_factory=list)
    appends: list = field(default_factory=list)
    omits: list = field(default_factory=list)
    files: list = field(default_factory=list)
    outputs: list = field(default_factory=list)
    patterns: list = field(default_factory=list)
    requires: list = field(default_factory=list)
    timeout: float = 300.0

    @property
    def name(self) -> str:
        return f"README.md:{self.line}"


def _directives(comment: str, block: Block):
    for raw in comment.splitlines():
        line = raw.strip()
        if not line or line.startswith("<!--") or line == "-->":
            continue
        key, colon, value = line.partition(":")
        key, value = key.strip(), value.strip()
        if not colon:
            raise ValueError(f"{block.name}: directive {line!r} lacks 'key:'")
        if key == "skip":
            if not value:
                raise ValueError(f"{block.name}: 'skip:' needs a reason")
            block.skip = value
        elif key in ("sub", "append", "omit"):
            old, arrow, new = value.partition(" =>")
            if not arrow:
                raise ValueError(f"{block.name}: write '{key}: OLD => NEW'")
            pair = (old.strip(), new.strip())
            if key == "omit" and not pair[1]:
                raise ValueError(f"{block.name}: 'omit:' needs a reason after '=>'")
            {"sub": block.subs, "append": block.appends, "omit": block.omits}[key].append(pair)
        elif key == "files":
            block.files += value.split()
        elif key == "output":
            block.outputs.append(value)
        elif key == "output-re":
            block.patterns.append(value)
        elif key == "requires":
            block.requires += value.split()
        elif key == "timeout":
            block.timeout = float(value)
        else:
            raise ValueError(f"{block.name}: unknown directive {key!r}")


def readme_blocks(text: str) -> list:
    """Every fenced block of the README with its language and its test directives."""
    lines = text.splitlines()
    blocks, comment, index = [], None, 0
    while index < len(lines):
        line = lines[index]
        if line.startswith("<!-- test"):
            start = index
            while "-->" not in lines[index]:
                index += 1
            comment = "\n".join(lines[start:index + 1])
            index += 1
            continue
        fence = re.match(r"^```(\w*)\s*$", line)
        if fence:
            body_start = index + 1
            index += 1
            while not lines[index].startswith("```"):
                index += 1
            block = Block(body_start, fence.group(1), "\n".join(lines[body_start:index]) + "\n")
            if comment is not None:
                _directives(comment, block)
            blocks.append(block)
            comment = None
        elif line.strip() and comment is not None and not line.startswith("<!--"):
            raise ValueError(f"README.md:{index + 1}: a '<!-- test' comment must come right before a code block")
        index += 1
    return blocks


def _strip_comment(line: str) -> tuple:
    """(command, comment) of a shell line: a '#' after whitespace and outside quotes starts a comment."""
    quote = None
    for position, char in enumerate(line):
        if quote:
            if char == quote:
                quote = None
        elif char in "'\"":
            quote = char
        elif char == "#" and (position == 0 or line[position - 1].isspace()):
            return line[:position].rstrip(), line[position + 1:].strip()
    return line.rstrip(), ""


@dataclass
class Command:
    text: str  # possibly several lines joined by backslash continuations
    comment: str

    @property
    def expected_exit(self) -> int:
        found = re.search(r"\bexit (\d+)", self.comment)
        return int(found.group(1)) if found else 0

    @property
    def promised_outputs(self) -> list:
        return re.findall(r'"([^"]+)"', self.comment)


def block_commands(block: Block) -> list:
    """The commands of a shell block after substitutions, appends and omissions."""
    text = block.text
    for old, new in block.subs:
        assert old in text, f"{block.name}: 'sub: {old} => ...' matches nothing (stale directive?)"
        text = text.replace(old, new, 1)
    lines = text.splitlines()
    if block.language == "console":
        kept, following = [], False
        for line in lines:
            if line.startswith("$ "):
                kept.append(line[2:])
                following = line.rstrip().endswith("\\")
            elif following:
                kept.append(line)
                following = line.rstrip().endswith("\\")
        lines = kept
    commands, pending, comment = [], [], ""
    for line in lines:
        code, note = _strip_comment(line)
        if not pending and not code:
            continue
        comment = " ".join(filter(None, [comment, note]))
        pending.append(code)
        if code.endswith("\\"):
            continue
        commands.append(Command("\n".join(pending).lstrip(), comment))
        pending, comment = [], ""
    assert not pending, f"{block.name}: a command ends with a backslash"
    kept = []
    for command in commands:
        if any(command.text.startswith(prefix) for prefix, _ in block.omits):
            continue
        for prefix, extra in block.appends:
            if command.text.startswith(prefix):
                command.text += " " + extra
        kept.append(command)
    for prefix, _ in block.omits + block.appends:
        assert any(c.text.startswith(prefix) for c in commands), \
            f"{block.name}: directive prefix {prefix!r} matches no command (stale directive?)"
    for command in kept:  # an editable install from the test's temporary folder would re-point the venv there
        assert "pip install" not in command.text, \
            f"{block.name}: '{command.text}' would reinstall the project; remove it with 'sub:' or 'omit:'"
    return kept


BLOCKS = readme_blocks(README.read_text())
RUN_BLOCKS = [b for b in BLOCKS if b.language in RUN_LANGUAGES]


def test_every_block_is_either_run_or_skipped_with_a_reason():
    """Shell-looking blocks must be tagged: an untagged block holding a command would escape the test."""
    for block in BLOCKS:
        if block.language in ("", "text"):
            first = block.text.lstrip().split("\n", 1)[0]
            assert not first.startswith(("python ", "pip ", "fmpy ", "cc ")) or block.language == "text", \
                f"{block.name}: a command in an untagged block; tag it bash (run) or text (synopsis)"
    assert len(RUN_BLOCKS) >= 8 and all(b.skip or block_commands(b) or b.language == "python" for b in RUN_BLOCKS)


def test_a_block_that_would_reinstall_the_project_is_refused():
    block = readme_blocks("```bash\npip install -e '.[native]' && python build_fmu.py\n```\n")[0]
    with pytest.raises(AssertionError, match="would reinstall the project"):
        block_commands(block)


def test_the_directive_parser_reads_the_convention():
    text = ('<!-- test\nsub: --stop 20 => --stop 1\nappend: python -m harness run => --stop 0.1\n'
            'omit: python -m pytest => the suite itself\nfiles: results/a.csv results/b.md\noutput: ITAE\n-->\n'
            '```bash\npython -m harness run x --stop 20   # scores: "ITAE", must fail (exit 1)\n'
            'python -m harness run y \\\n    --json\npython -m pytest -q\n```\n\n```text\nnot run\n```\n')
    first, second = readme_blocks(text)
    assert second.language == "text"
    commands = block_commands(first)
    assert [c.text for c in commands] == ["python -m harness run x --stop 1 --stop 0.1",
                                          "python -m harness run y \\\n    --json --stop 0.1"]
    assert commands[0].expected_exit == 1 and commands[0].promised_outputs == ["ITAE"]
    assert commands[1].expected_exit == 0 and first.files == ["results/a.csv", "results/b.md"]
    with pytest.raises(AssertionError, match="matches nothing"):
        block_commands(readme_blocks("<!-- test\nsub: absent => x\n-->\n```bash\nls\n```\n")[0])
    with pytest.raises(ValueError, match="needs a reason"):
        readme_blocks("<!-- test\nskip:\n-->\n```bash\nls\n```\n")


@pytest.fixture(scope="module")
def workspace(tmp_path_factory, fmu_paths):
    """A working directory that looks like the repository, with its own results/ and build/."""
    work = tmp_path_factory.mktemp("readme")
    for entry in ROOT.iterdir():
        if entry.name in NOT_LINKED or entry.name.endswith(".egg-info"):
            continue
        (work / entry.name).symlink_to(entry)
    (work / "build").mkdir()
    (work / "build" / "fmus").symlink_to(ROOT / "build" / "fmus")
    return work


def _written_files(work: Path) -> set:
    """Files (not links) under the working directory: what the blocks wrote."""
    found = set()
    for folder, directories, files in os.walk(work):
        directories[:] = [d for d in directories if not os.path.islink(os.path.join(folder, d))]
        for name in files:
            path = os.path.join(folder, name)
            if not os.path.islink(path):
                found.add(os.path.relpath(path, work))
    return found


def _not_ignored(paths) -> list:
    """The paths that .gitignore does not cover (empty when git is unavailable)."""
    if not paths or shutil.which("git") is None or not (ROOT / ".git").exists():
        return []
    completed = subprocess.run(["git", "check-ignore", "--no-index", "--stdin"], cwd=ROOT, text=True,
                               input="\n".join(sorted(paths)) + "\n", capture_output=True)
    ignored = set(completed.stdout.split())
    return sorted(p for p in paths if p not in ignored)


def _environment(work: Path, scratch: Path) -> dict:
    environment = dict(os.environ)
    environment["PATH"] = os.pathsep.join([str(Path(sys.executable).parent), environment.get("PATH", "")])
    environment["PYTHONPATH"] = str(work)
    environment.pop("MPLBACKEND", None)
    scratch.mkdir(exist_ok=True)  # what a block's programs leave in the temporary folder (Ecos's ecos_ssp_*)
    environment["TMPDIR"] = str(scratch)  # stays in the test's own tmp_path
    return environment


@pytest.mark.parametrize("block", RUN_BLOCKS, ids=[b.name for b in RUN_BLOCKS])
def test_readme_block_runs_as_written(block, workspace, tmp_path):
    if block.skip:
        pytest.skip(f"{block.name}: {block.skip}")
    missing = [program for program in block.requires if shutil.which(program) is None]
    if missing:
        pytest.skip(f"{block.name}: needs {', '.join(missing)} on PATH")
    before = _written_files(workspace)
    logs = tmp_path / "logs"
    logs.mkdir()
    if block.language == "python":
        script = tmp_path / "block.py"
        script.write_text(block.text)
        commands = [Command(f"{sys.executable} {script}", "")]
    else:
        commands = block_commands(block)
    lines = []
    for number, command in enumerate(commands):
        lines += ["{", command.text, f'}} > "{logs}/{number}.out" 2>&1', f'echo $? > "{logs}/{number}.rc"']
    completed = subprocess.run(["bash", "-c", "\n".join(lines)], cwd=workspace, env=_environment(workspace, tmp_path / "tmp"),
                               timeout=block.timeout, capture_output=True, text=True)
    assert completed.returncode == 0, completed.stderr
    everything = []
    for number, command in enumerate(commands):
        output = (logs / f"{number}.out").read_text()
        status = int((logs / f"{number}.rc").read_text())
        everything.append(output)
        where = f"{block.name}: `{command.text}`"
        assert "Traceback" not in output, f"{where} printed a traceback:\n{output}"
        assert status == command.expected_exit, f"{where} exited {status}, expected {command.expected_exit}:\n{output}"
        for promised in command.promised_outputs:
            assert promised in output, f"{where}: the README promises {promised!r}; output:\n{output}"
    output = "\n".join(everything)
    for text in block.outputs:
        assert text in output, f"{block.name}: expected {text!r} in the output:\n{output}"
    for pattern in block.patterns:
        assert re.search(pattern, output), f"{block.name}: expected a match of {pattern!r} in:\n{output}"
    for name in block.files:
        assert (workspace / name).is_file(), f"{block.name}: the block should have written {name}"
    written = _written_files(workspace) - before
    assert not _not_ignored(written), \
        f"{block.name} wrote files that .gitignore does not cover: {_not_ignored(written)}"
