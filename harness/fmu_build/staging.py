"""The pythonfmu edition's files under the top-level module names they take inside an FMU.

In the repository the FMU sources are modules of packages (``fmu_src.afc_math``,
``plants.inverted_pendulum.fmu``) that import one another by those names; inside an FMU they
are top-level modules in its resources folder, and pythonfmu loads every FMU into one
interpreter, so each name must be unique across the FMUs.  The rule: a file's name inside the
FMU is its package path without the top package, joined by ``_`` (``plants/inverted_pendulum/
fmu.py`` -> ``inverted_pendulum_fmu.py``, ``fmu_src/afc_math.py`` -> ``afc_math.py``), and its
imports of the other staged files are rewritten to those names.  Each file thus has one module
name in the repository and one inside the FMU, never two in one process.
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository (harness/fmu_build/ is two levels down)
PACKAGES = ("fmu_src", "plants")  # the packages whose modules travel inside FMUs


def module_name(path: Path) -> str:
    """The module name of a project file in the repository: ``plants.inverted_pendulum.fmu``."""
    return ".".join(Path(path).resolve().relative_to(ROOT).with_suffix("").parts)


def staged_module(path: Path) -> str:
    """The top-level module name of a file inside an FMU: ``inverted_pendulum_fmu``; a file
    outside the FMU packages keeps its own name."""
    path = Path(path).resolve()
    try:
        parts = path.relative_to(ROOT).with_suffix("").parts
    except ValueError:
        return path.stem
    return "_".join(parts[1:]) if parts[0] in PACKAGES else path.stem


def _rewritten(node: ast.stmt, staged: dict, path: Path) -> str | None:
    """The import statement ``node`` with the staged modules' names, None if it imports none of them."""
    if isinstance(node, ast.Import):
        names = [alias for alias in node.names if alias.name in staged]
        if not names:
            return None
        if len(names) != len(node.names) or any(alias.asname is None for alias in names):
            raise ValueError(f"{path}:{node.lineno}: write `import {names[0].name} as NAME` on a line of its own "
                             "(a staged module is imported under one name)")
        return "\n".join(f"import {staged[a.name]} as {a.asname}" for a in names)
    if not isinstance(node, ast.ImportFrom) or node.level or not node.module:
        return None
    if node.module in staged:
        aliases = ", ".join(a.name if a.asname is None else f"{a.name} as {a.asname}" for a in node.names)
        return f"from {staged[node.module]} import {aliases}"
    modules = [f"{node.module}.{a.name}" in staged for a in node.names]
    if not any(modules):
        return None
    if not all(modules):
        raise ValueError(f"{path}:{node.lineno}: import the staged modules and other names on separate lines")
    lines = []
    for alias in node.names:
        target, name = staged[f"{node.module}.{alias.name}"], alias.asname or alias.name
        lines.append(f"import {target}" if target == name else f"import {target} as {name}")
    return "\n".join(lines)


def staged_source(path: Path, staged: dict) -> str:
    """The text of ``path`` with its imports of ``staged`` ({repository module: FMU module}) rewritten;
    an import of another module of the FMU packages is an error naming the file and line."""
    text = Path(path).read_text()
    lines = text.splitlines(keepends=True)
    for node in reversed(ast.parse(text, str(path)).body):
        replacement = _rewritten(node, staged, path)
        if replacement is None:
            module = getattr(node, "module", None) or ""
            names = [a.name for a in getattr(node, "names", ())] if isinstance(node, ast.Import) else [module]
            if any(name.split(".")[0] in PACKAGES for name in names):
                raise ValueError(f"{path}:{node.lineno}: imports {names[0]}, which is not among the FMU's files")
            continue
        lines[node.lineno - 1:node.end_lineno] = [replacement + "\n"]
    return "".join(lines)


def stage(files, folder: Path) -> list[Path]:
    """Write ``files`` (the script first) into ``folder`` under their FMU names, imports rewritten;
    return the written paths in the same order."""
    files = [Path(f).resolve() for f in files]
    staged = {module_name(f): staged_module(f) for f in files if _in_packages(f)}
    written = []
    for path in files:
        target = Path(folder) / f"{staged_module(path)}{path.suffix}"
        if target in written:
            raise ValueError(f"two files of one FMU stage as {target.name}: rename one")
        target.write_text(staged_source(path, staged) if path.suffix == ".py" else path.read_text())
        written.append(target)
    return written


def _in_packages(path: Path) -> bool:
    try:
        return path.relative_to(ROOT).parts[0] in PACKAGES
    except ValueError:
        return False
