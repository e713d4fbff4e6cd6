"""The interface of the masters' compiled loops: harness/loop_interface.h against its Python mirror.

1. The layout: every struct of the header has a ctypes structure of the same name with the same
   fields in the same order, and the compiler's sizeof, offsetof and field sizes equal ctypes'; the
   LOOP_ and ACTION_ codes have the values of harness/loop_interface.py.  The check compiles a
   small library from the header itself, and is run on broken copies of the header too, so it is
   seen to fail.
2. The loader: both loops include the header, a changed header makes another library (a stale one
   is never loaded), and the installed package ships every file the loops are built from.
"""
from __future__ import annotations

import ctypes
import fnmatch
import re
from pathlib import Path

import pytest

from harness.fmu_build import native as build_native
from harness.fmu_build import toolchain as c_toolchain
from harness import compiled_loop, loop_interface, master_loop, me_loop

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

pytestmark = pytest.mark.skipif(not build_native.compiler_available(),
                                reason="zig's C compiler is not installed (pip install -e .)")

ROOT = Path(__file__).resolve().parents[1]
CODE_PREFIXES = ("LOOP_", "ACTION_")


# ------------------------------------------------------------------ reading the header
def _without_comments(text: str) -> str:
    return re.sub(r"//[^\n]*", "", re.sub(r"/\*.*?\*/", "", text, flags=re.DOTALL))


def header_structs(text: str) -> dict:
    """{struct name: [field names in order]} of every ``typedef struct { ... } Name;`` of the header."""
    structs = {}
    for body, name in re.findall(r"typedef\s+struct\s*\{(.*?)\}\s*(\w+)\s*;", _without_comments(text), re.DOTALL):
        structs[name] = [re.search(r"(\w+)\s*(\[[^\]]*\])?\s*$", declaration.strip()).group(1)
                         for declaration in body.split(";") if declaration.strip()]
    return structs


def header_codes(text: str) -> list:
    """The names of the header's LOOP_ and ACTION_ enumerators, in the header's order."""
    names = []
    for body in re.findall(r"enum\s*\{(.*?)\}", _without_comments(text), re.DOTALL):
        names += [name for name in re.findall(r"(\w+)\s*(?:=[^,]*)?(?:,|$)", body.strip())
                  if name.startswith(CODE_PREFIXES)]
    return names


def python_codes() -> dict:
    codes = {f"LOOP_{code.name}": code.value for code in loop_interface.LoopOutcome}
    codes.update(ACTION_READ=loop_interface.ACTION_READ, ACTION_WRITE=loop_interface.ACTION_WRITE)
    return codes


# ------------------------------------------------------------------ the compiler's view
def _layout_entries() -> list:
    """(what, C expression, ctypes' value) of every figure the layout check compares."""
    entries = []
    for name, structure in loop_interface.STRUCTS.items():
        entries.append((f"sizeof({name})", f"sizeof({name})", ctypes.sizeof(structure)))
        for field, _ in structure._fields_:
            descriptor = getattr(structure, field)
            entries.append((f"offsetof({name}, {field})", f"offsetof({name}, {field})", descriptor.offset))
            entries.append((f"sizeof({name}.{field})", f"sizeof((({name} *)0)->{field})", descriptor.size))
    entries += [(code, code, value) for code, value in python_codes().items()]
    return entries


def compiled_layout(header: Path, scratch: Path) -> list:
    """The values of the entries' C expressions, compiled from ``header`` (copied beside the generated
    source, so the same header always makes the same cached library)."""
    entries = _layout_entries()
    folder = scratch / "layout"
    folder.mkdir(exist_ok=True)
    copy = folder / "loop_interface.h"
    copy.write_bytes(header.read_bytes())
    source = folder / "loop_layout.c"
    source.write_text('#include "loop_interface.h"\n\n'
                      "EXPORT const int64_t loop_layout[] = {\n"
                      + "".join(f"    (int64_t)({expression}),\n" for _, expression, _ in entries) + "};\n")
    library = ctypes.CDLL(str(c_toolchain.host_library("loop_layout", (source,), (copy,))))
    return list((ctypes.c_int64 * len(entries)).in_dll(library, "loop_layout"))


def layout_mismatches(header: Path, scratch: Path) -> list:
    """Every difference between the header and harness/loop_interface.py, one line each."""
    text = header.read_text()
    problems = []
    structs = header_structs(text)
    for name in sorted(set(structs) | set(loop_interface.STRUCTS)):
        python = [field for field, _ in loop_interface.STRUCTS[name]._fields_] if name in loop_interface.STRUCTS else None
        if python != structs.get(name):
            problems.append(f"struct {name}: header fields {structs.get(name)}, loop_interface.py fields {python}")
    codes = header_codes(text)
    if sorted(codes) != sorted(python_codes()):
        problems.append(f"codes: header {sorted(codes)}, loop_interface.py {sorted(python_codes())}")
    if problems:  # a name only one side knows would not compile
        return problems
    for (what, _, expected), compiled in zip(_layout_entries(), compiled_layout(header, scratch)):
        if compiled != expected:
            problems.append(f"{what}: {compiled} in the header, {expected} in loop_interface.py")
    return problems


# ------------------------------------------------------------------ 1. the layout
def test_the_python_layouts_and_codes_are_the_headers(tmp_path):
    assert layout_mismatches(loop_interface.HEADER, tmp_path) == []


def test_the_header_is_read_whole():
    """The reader sees every struct and code the loops use (a reader that found nothing would pass)."""
    text = loop_interface.HEADER.read_text()
    assert set(header_structs(text)) == {"Action", "Stepper", "Timer", "Block", "Outcome", "MeLoop"}
    assert header_structs(text)["Action"][:2] == ["kind", "fmi_version"]
    assert header_structs(text)["MeLoop"][-2:] == ["failure", "evaluations"]
    assert header_codes(text)[:3] == ["ACTION_READ", "ACTION_WRITE", "LOOP_DONE"]
    assert header_codes(text)[-1] == "LOOP_OUT_OF_MEMORY"


BROKEN = [  # (what is changed in a copy of the header, the mismatch it must give)
    ("    int32_t status;\n    int64_t row;", "    int64_t status;\n    int64_t row;",
     "offsetof(Outcome, status): 8 in the header, 4 in loop_interface.py"),
    ("    size_t first_column;\n    size_t recorded;", "    size_t recorded;\n    size_t first_column;",
     "struct Action: header fields"),
    ("    int32_t fmi_version;\n    void *instance;\n    void *do_step;",
     "    int32_t fmi_version;\n    int32_t spare;\n    void *instance;\n    void *do_step;", "struct Stepper: header fields"),
    ("LOOP_EVENT = 11,", "LOOP_EVENT = 12,", "LOOP_EVENT: 12 in the header, 11 in loop_interface.py"),
    ("    LOOP_OUT_OF_MEMORY = 12,", "    LOOP_OUT_OF_MEMORY = 12,\n    LOOP_PAUSED = 13,", "codes: header"),
    ("    double step;\n    Outcome failure;", "    float step;\n    Outcome failure;",
     "sizeof(MeLoop.step): 4 in the header, 8 in loop_interface.py"),
]


@pytest.mark.parametrize("old, new, expected", BROKEN)
def test_a_header_out_of_step_with_python_is_found(tmp_path, old, new, expected):
    text = loop_interface.HEADER.read_text()
    assert old in text
    broken = tmp_path / "loop_interface.h"
    broken.write_text(text.replace(old, new))
    problems = layout_mismatches(broken, tmp_path)
    assert any(problem.startswith(expected) for problem in problems), problems


# ------------------------------------------------------------------ 2. the loader
@pytest.mark.parametrize("library", [master_loop.LIBRARY, me_loop.LIBRARY], ids=["master_loop", "me_loop"])
def test_both_loops_are_built_from_the_shared_header(library):
    assert compiled_loop.local_headers(library.source) == (loop_interface.HEADER,)


def test_a_changed_header_makes_another_library(tmp_path):
    """The cache key covers the included header: a library built from an older header is not reused."""
    source = tmp_path / master_loop.SOURCE.name
    header = tmp_path / loop_interface.HEADER.name
    source.write_text(master_loop.SOURCE.read_text())
    header.write_text(loop_interface.HEADER.read_text())
    library = compiled_loop.CompiledLibrary("master_loop", source, "the master", lambda loaded: None)
    assert compiled_loop.local_headers(source) == (header,)
    before = library.path()
    header.write_text(header.read_text() + "/* changed */\n")
    after = library.path()
    assert after != before and after.exists() and before.exists()
    assert library.path() == after  # and the same header finds the same library


def test_local_headers_follows_nested_includes(tmp_path):
    (tmp_path / "a.c").write_text('#include <math.h>\n#include "b.h"\n')
    (tmp_path / "b.h").write_text('  #  include "c.h"\n')
    (tmp_path / "c.h").write_text("/* no include */\n")
    assert compiled_loop.local_headers(tmp_path / "a.c") == (tmp_path / "b.h", tmp_path / "c.h")


def test_the_package_ships_every_file_the_loops_are_built_from():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["harness"]
    for library in (master_loop.LIBRARY, me_loop.LIBRARY):
        for path in (library.source, *compiled_loop.local_headers(library.source)):
            name = path.relative_to(ROOT / "harness").as_posix()
            assert any(fnmatch.fnmatch(name, pattern) for pattern in patterns), f"{name} is not in package-data"
