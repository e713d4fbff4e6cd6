"""The import architecture of the project, read from the sources with ``ast`` (nothing is imported).

Rules (docs/architecture.md draws them):

* no import cycle among the project's modules (harness/, plants/, fmu_src/ and the build command
  build_fmu.py), whether the imports are at module level or inside functions;
* no function-local import of a project module: every project import sits at module level, where
  a reader finds it (optional third-party packages may be imported where they are used);
* imports run one way: ``harness.hosts`` -> ``harness.studies`` -> the harness core; the core
  imports no study and no host runner (except ``harness/cli.py``, the composition root that
  registers every subcommand), and no study imports a host runner;
* the harness's top level holds the core only (studies in harness/studies/, host runners in
  harness/hosts/, the FMU builds in harness/fmu_build/, which import neither studies nor hosts);
* a chain of modules (``CHAINS``: the tune and regression studies' sub-packages, the host matrix's
  modules, the native build's stages) reads
  from the bottom up: each module imports only the chain's modules before it, and a new module of
  harness/studies/tune/ or harness/studies/regression/ takes its place in the chain;
* the native build ``harness.fmu_build.native`` (and its stages, ``harness.fmu_build.native_stages``) never
  reaches the build command ``harness.fmu_build.builder`` (which may import the native build), and
  the masters' compiled loops reach no FMU build and no FMU source: ``harness.master_loop`` and
  ``harness.me_loop`` (with their loader ``harness.compiled_loop`` and ``harness.loop_interface``)
  import only the C toolchain helper ``harness.fmu_build.toolchain`` (and the core beside them), which
  imports no project module.

Every rule is also run on small synthetic source trees that break it, so each check is seen to fail.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOP_LEVEL_MODULES = ("build_fmu",)  # the build command at the root; its code is harness/fmu_build/
PACKAGES = ("harness", "plants", "fmu_src")
BUILD = "harness.fmu_build"
BUILDER, NATIVE_BUILD, NATIVE_STAGES = f"{BUILD}.builder", f"{BUILD}.native", f"{BUILD}.native_stages"
TOOLCHAIN = f"{BUILD}.toolchain"
#: the co-simulation core at the top of harness/ (docs/architecture.md); anything else goes in a sub-package
CORE = {"harness", "harness.__main__", "harness.cli", "harness.cli_args", "harness.scenario", "harness.variants",
        "harness.fmi", "harness.scenario_checks", "harness.master", "harness.compiled_loop", "harness.loop_interface",
        "harness.master_loop", "harness.scores", "harness.cases", "harness.units", "harness.me_master",
        "harness.me_loop", "harness.cvode", "harness.scenario_toml", "harness.progress", "harness.termination",
        "harness.unpack", "harness.atomic_files", "harness.executors", "harness.executors.tasks",
        "harness.executors.local_pool", "harness.executors.dask_pool", "harness.executors.choose",
        "harness.executors.stream"}
COMPOSITION_ROOT = "harness.cli"
STUDIES, HOSTS = "harness.studies", "harness.hosts"
#: what the master's compiled loop may never reach, directly or through other modules
LOOP_FORBIDDEN = (NATIVE_BUILD, NATIVE_STAGES, BUILDER, f"{BUILD}.catalog", f"{BUILD}.staging", "plants", "fmu_src")
#: modules of one idea each that build on one another: each imports only those before it in its chain
#: (harness/studies/tune/__init__.py, harness/studies/regression/__init__.py and harness/hosts/matrix.py say what
#: each holds)
CHAINS = {
    "harness.studies.tune": ("errors", "space", "objective", "candidate", "config", "storage", "loop",
                             "scenario_file", "summary", "report", "comparison", "study", "command_line"),
    "harness.studies.regression": ("runs", "references", "comparison", "figures", "report", "command"),
    "harness.executors": ("tasks", "local_pool", "dask_pool", "choose", "stream"),
    "harness.studies.sweep": ("grid", "csv_rows", "executors", "heatmap", "run", "command_line"),
    "harness.hosts": ("trajectory", "console_capture", "plain_fmpy", "host_runners", "host_registry", "matrix_row",
                      "matrix_prose", "matrix_report", "matrix"),
    NATIVE_STAGES: ("targets", "model_exchange", "description", "header", "compiler", "sources", "ls_ref", "package"),
}
#: packages whose every module is in their chain (harness/hosts/ holds other hosts' bindings beside its chain)
WHOLE_CHAINS = ("harness.executors", "harness.studies.tune", "harness.studies.regression", "harness.studies.sweep",
                NATIVE_STAGES)


@dataclass(frozen=True)
class Import:
    source: str  # the importing module
    target: str  # the imported project module
    line: int
    local: bool  # inside a function


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_files(root: Path) -> dict:
    """{module name: path} of every project module under ``root``."""
    files = {name: root / f"{name}.py" for name in TOP_LEVEL_MODULES if (root / f"{name}.py").exists()}
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            files[module_name(root, path)] = path
    return files


def _resolve(name: str, modules: set) -> str | None:
    """The project module ``name`` denotes (the longest known prefix), or None for another package."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    """The absolute name of ``from <node.module>`` written in ``module`` (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(module: str, path: Path, modules: set) -> list:
    """Every import of a project module in one file, with its line and whether it sits in a function."""
    tree = ast.parse(path.read_text(), str(path))
    found = []

    def visit(node, local):
        for child in ast.iter_child_nodes(node):
            inside = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    target = _resolve(alias.name, modules)
                    if target:
                        found.append(Import(module, target, child.lineno, local))
            elif isinstance(child, ast.ImportFrom):
                base = _absolute(module, path.name == "__init__.py", child)
                for alias in child.names:  # "from harness import cli": the module harness.cli
                    target = _resolve(f"{base}.{alias.name}", modules) or _resolve(base, modules)
                    if target:
                        found.append(Import(module, target, child.lineno, local))
            visit(child, inside)

    visit(tree, False)
    return [i for i in found if i.target != module]


def import_graph(root: Path) -> list:
    files = project_files(root)
    modules = set(files)
    return [found for name, path in files.items() for found in imports_of(name, path, modules)]


def _edges(imports) -> dict:
    edges: dict = {}
    for found in imports:
        edges.setdefault(found.source, set()).add(found.target)
    return edges


def cycles(imports) -> list:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    edges = _edges(imports)
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    counter = [0]

    def connect(node):
        index[node] = low[node] = counter[0]
        counter[0] += 1
        stack.append(node)
        on_stack.add(node)
        for target in sorted(edges.get(node, ())):
            if target not in index:
                connect(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(edges):
        if node not in index:
            connect(node)
    return sorted(found)


def reachable(imports, start: str) -> set:
    edges = _edges(imports)
    seen, pending = set(), [start]
    while pending:
        for target in edges.get(pending.pop(), ()):
            if target not in seen:
                seen.add(target)
                pending.append(target)
    return seen


def _layer(module: str) -> str:
    if module == STUDIES or module.startswith(STUDIES + "."):
        return "studies"
    if module == HOSTS or module.startswith(HOSTS + "."):
        return "hosts"
    if module == BUILD or module.startswith(BUILD + "."):
        return "build"
    if module == "harness" or module.startswith("harness."):
        return "core"
    return "outside"


#: (importing layer, imported layer) pairs that go the wrong way
WRONG_WAY = {("core", "studies"), ("core", "hosts"), ("studies", "hosts"), ("build", "studies"), ("build", "hosts")}


def chain_problems(files: dict, imports, root: Path) -> list:
    """Imports that go up a chain of ``CHAINS``; modules of a ``WHOLE_CHAINS`` package outside its chain."""
    problems = []
    for package, chain in CHAINS.items():
        position = {f"{package}.{name}": index for index, name in enumerate(chain)}
        for i in imports:
            if i.source in position and i.target in position and position[i.target] >= position[i.source]:
                problems.append(f"{files[i.source].relative_to(root)}:{i.line}: {i.source} imports {i.target}, "
                                f"which comes after it in the chain of {package} ({', '.join(chain)}): a module "
                                "imports only those before it")
        if package in WHOLE_CHAINS:
            for name in sorted(files):
                if name.startswith(package + ".") and name not in position:
                    problems.append(f"{files[name].relative_to(root)}: {name} is not in the chain of {package}: "
                                    "give it its place in CHAINS (tests/test_architecture.py) and in the package's "
                                    "text")
    return problems


def violations(root: Path = ROOT) -> list:
    """Every broken rule, one line each (empty: the architecture holds)."""
    files = project_files(root)
    imports = import_graph(root)
    problems = [f"import cycle: {' <-> '.join(component)}" for component in cycles(imports)]
    problems += [f"{files[i.source].relative_to(root)}:{i.line}: function-local import of {i.target} "
                 "(import it at module level)" for i in imports if i.local]
    for i in imports:
        direction = (_layer(i.source), _layer(i.target))
        if direction in WRONG_WAY and i.source != COMPOSITION_ROOT:
            problems.append(f"{files[i.source].relative_to(root)}:{i.line}: {i.source} ({direction[0]}) imports "
                            f"{i.target} ({direction[1]}): imports run hosts -> studies -> core, and the "
                            "builds import neither studies nor hosts")
    for name in sorted(files):
        if _layer(name) == "core" and name not in CORE:
            problems.append(f"{files[name].relative_to(root)}: not part of the co-simulation core: move it to "
                            "harness/studies/ or harness/hosts/ (or add it to the core deliberately)")
    if BUILDER in reachable(imports, NATIVE_BUILD):
        problems.append(f"{NATIVE_BUILD} reaches {BUILDER} (the builder may import the native build, not the reverse)")
    for loop in ("harness.master_loop", "harness.me_loop", "harness.compiled_loop", "harness.loop_interface"):
        if loop not in files:
            continue
        reached = reachable(imports, loop)
        for forbidden in LOOP_FORBIDDEN:
            hits = sorted(m for m in reached if m == forbidden or m.startswith(forbidden + "."))
            if hits:
                problems.append(f"{loop} reaches {', '.join(hits)}: the compiled loop needs only "
                                f"{TOOLCHAIN}")
    problems += chain_problems(files, imports, root)
    if TOOLCHAIN in files:
        own = sorted({i.target for i in imports if i.source == TOOLCHAIN})
        if own:
            problems.append(f"{TOOLCHAIN} imports project modules {', '.join(own)}: it stands alone")
    return problems


def test_the_project_keeps_its_import_architecture():
    problems = violations()
    assert not problems, f"{len(problems)} broken rule(s):\n" + "\n".join(problems)


def test_the_graph_sees_the_imports_it_must_see():
    """A sanity check of the reader itself on the real tree: known imports are found."""
    imports = {(i.source, i.target) for i in import_graph(ROOT)}
    assert ("harness.master", "harness.master_loop") in imports
    assert ("harness.master_loop", "harness.compiled_loop") in imports
    assert ("harness.compiled_loop", TOOLCHAIN) in imports
    assert (BUILDER, NATIVE_BUILD) in imports
    assert ("build_fmu", BUILDER) in imports
    assert ("harness.cli", "harness.studies.tables") in imports
    assert ("harness.hosts.matrix", "harness.studies.step_study") in imports
    assert ("harness.studies.tune.study", "harness.studies.tune.loop") in imports
    assert ("harness.studies.regression.command", "harness.studies.regression.comparison") in imports
    assert ("harness.hosts.host_registry", "harness.hosts.host_runners") in imports


# ------------------------------------------------------- each rule on a tree that breaks it
def _tree(root: Path, files: dict) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    for package in ("harness", "harness/studies", "harness/studies/tune", "harness/hosts", "harness/fmu_build",
                    "plants", "fmu_src"):
        (root / package).mkdir(parents=True, exist_ok=True)
        (root / package / "__init__.py").touch()
    return root


GOOD = {"harness/scenario.py": "import math\n",
        "harness/master.py": "from . import master_loop\nfrom .scenario import math\n",
        "harness/master_loop.py": "from . import compiled_loop\n",
        "harness/compiled_loop.py": "from .fmu_build import toolchain\n",
        "harness/cli.py": "from .studies import tables\nfrom .hosts import matrix\n",
        "harness/studies/tables.py": "from .. import master\n",
        "harness/hosts/matrix.py": "from ..studies.tables import master\nfrom . import matrix_report\n\n\n"
                                   "def f():\n    import numpy\n",
        "harness/hosts/matrix_report.py": "from .matrix_row import within\n",
        "harness/hosts/matrix_row.py": "import math\n",
        "harness/hosts/engines.py": "from .matrix import f\n",
        "harness/studies/tune/space.py": "from .errors import TuneError\n",
        "harness/studies/tune/errors.py": "from ... import cli_args\n",
        "harness/studies/tune/command_line.py": "from .space import x\nfrom .errors import y\n",
        "harness/fmu_build/toolchain.py": "import os\n",
        "harness/fmu_build/native.py": "from . import toolchain\nfrom . import catalog\n",
        "harness/fmu_build/builder.py": "from . import native\nfrom . import catalog\nfrom .. import scenario\n",
        "harness/fmu_build/catalog.py": "from plants import registry\n",
        "build_fmu.py": "from harness.fmu_build.builder import main\n",
        "plants/registry.py": "import math\n"}


def test_a_tree_that_keeps_the_rules_passes(tmp_path):
    assert violations(_tree(tmp_path, GOOD)) == []


@pytest.mark.parametrize("file,text,expected", [
    ("harness/fmu_build/native.py", "from . import toolchain\nfrom . import builder\n",
     "import cycle: harness.fmu_build.builder <-> harness.fmu_build.native"),
    ("harness/fmu_build/native.py", "from . import toolchain\n\n\ndef f():\n    from . import builder\n",
     "function-local import of harness.fmu_build.builder"),
    ("harness/fmu_build/catalog.py", "from . import builder\n",
     "harness.fmu_build.native reaches harness.fmu_build.builder"),
    ("harness/fmu_build/catalog.py", "from ..studies import tables\n",
     "harness.fmu_build.catalog (build) imports harness.studies.tables (studies)"),
    ("harness/master.py", "from . import master_loop\n\n\ndef f():\n    from .scenario import math\n",
     "harness/master.py:5: function-local import of harness.scenario"),
    ("harness/master.py", "from . import master_loop\nfrom .studies import tables\n",
     "harness.master (core) imports harness.studies.tables (studies)"),
    ("harness/scenario.py", "from harness.hosts.matrix import x\n",
     "harness.scenario (core) imports harness.hosts.matrix (hosts)"),
    ("harness/studies/tables.py", "from .. import master\nfrom ..hosts import matrix\n",
     "harness.studies.tables (studies) imports harness.hosts.matrix (hosts)"),
    ("harness/master_loop.py", "from .fmu_build import native\n",
     "harness.master_loop reaches harness.fmu_build.native"),
    ("harness/compiled_loop.py", "from .fmu_build import toolchain, builder\n",
     "harness.master_loop reaches harness.fmu_build.builder"),
    ("harness/fmu_build/toolchain.py", "from . import catalog\n",
     "harness.fmu_build.toolchain imports project modules harness.fmu_build.catalog"),
    ("harness/sweep.py", "import math\n", "harness/sweep.py: not part of the co-simulation core"),
    ("harness/studies/tune/errors.py", "from .space import x\n",
     "harness.studies.tune.errors imports harness.studies.tune.space, which comes after it in the chain"),
    ("harness/studies/tune/space.py", "from .errors import x\nfrom .command_line import y\n",
     "harness.studies.tune.space imports harness.studies.tune.command_line, which comes after it"),
    ("harness/hosts/matrix_row.py", "from .matrix_report import percent\n",
     "harness.hosts.matrix_row imports harness.hosts.matrix_report, which comes after it in the chain"),
    ("harness/studies/tune/helpers.py", "import math\n",
     "harness.studies.tune.helpers is not in the chain of harness.studies.tune"),
])
def test_each_rule_fails_on_a_tree_that_breaks_it(tmp_path, file, text, expected):
    problems = violations(_tree(tmp_path, {**GOOD, file: text}))
    assert any(expected in problem for problem in problems), problems
