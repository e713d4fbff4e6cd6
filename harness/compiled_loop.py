"""How a master gets its compiled loop: the choice between the compiled and the Python loop, and one
loader that builds, caches and loads a loop's library once per process.

A loop's library is compiled on first use with zig's C compiler (the ``native`` and ``test``
extras) for the machine running the harness and cached in build/native/obj under the hash of its
source, of every header the source includes (harness/loop_interface.h) and of the flags, so a
library built from another header is never loaded.  With no compiler, or with
``AFC_MASTER_LOOP=python``, the master keeps its Python loop; ``AFC_MASTER_LOOP=c`` requires the
compiled one.
"""
from __future__ import annotations

import ctypes
import os
import re
import sys
from pathlib import Path

from harness.fmu_build import toolchain as c_toolchain

ENVIRONMENT_SWITCH = "AFC_MASTER_LOOP"  # "python": always the Python loop; "c": the compiled one or an error
CHOICES = ("auto", "python", "c")
_NO_COMPILER = "zig's C compiler is not installed (pip install -e .)"
_LOCAL_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)


class LoopUnavailable(RuntimeError):
    """The compiled loop cannot be built or loaded here (an error only when it was required)."""


def choice(loop: str = "auto") -> str:
    """``loop`` unless it is "auto", else $AFC_MASTER_LOOP, else "auto"."""
    if loop not in CHOICES:
        raise ValueError(f"loop {loop!r} is not valid; valid: {', '.join(CHOICES)}")
    if loop != "auto":
        return loop
    value = os.environ.get(ENVIRONMENT_SWITCH, "auto") or "auto"
    if value not in CHOICES:
        raise LoopUnavailable(f"{ENVIRONMENT_SWITCH}={value!r} is not valid; valid: {', '.join(CHOICES)}")
    return value


def local_headers(source: Path) -> tuple:
    """Every header ``source`` includes with quotes, and the ones they include, found beside the file
    that includes it (where the C compiler looks first)."""
    found, pending = [], [Path(source)]
    while pending:
        including = pending.pop()
        for name in _LOCAL_INCLUDE.findall(including.read_text()):
            header = including.parent / name
            if header not in found:
                found.append(header)
                pending.append(header)
    return tuple(found)


class CompiledLibrary:
    """One compiled loop's shared library: ``get`` builds (or finds in the cache) and loads it once.

    ``declare(library)`` gives the library's functions their ctypes signatures; ``master`` is how the
    fallback warning names the master whose loop it is.
    """

    def __init__(self, name: str, source: Path, master: str, declare):
        self.name, self.source, self.master, self.declare = name, Path(source), master, declare
        self.loaded = None
        self.unavailable = None  # why it could not be built or loaded here (said once)

    def path(self) -> Path:
        """The library built from the source and its headers as they are now (built if not cached)."""
        return c_toolchain.host_library(self.name, (self.source,), local_headers(self.source))

    def get(self, loop: str = "auto"):
        """The loaded library, or None for the Python loop.

        None when ``loop`` (or $AFC_MASTER_LOOP) is "python", or when it is "auto" and the library
        cannot be had here (zig not installed, the build or the load failed: said once on stderr).
        "c" raises LoopUnavailable instead of falling back.
        """
        wanted = choice(loop)
        if wanted == "python":
            return None
        if self.loaded is None and self.unavailable is None:
            try:
                self.loaded = self._load()
            except LoopUnavailable as error:
                self.unavailable = str(error)
                if wanted == "auto" and self.unavailable != _NO_COMPILER:
                    print(f"warning: {self.master} runs its Python loop: {self.unavailable}", file=sys.stderr)
        if self.loaded is None and wanted == "c":
            raise LoopUnavailable(f"{ENVIRONMENT_SWITCH}=c: {self.unavailable}")
        return self.loaded

    def _load(self):
        if not c_toolchain.compiler_available():
            raise LoopUnavailable(_NO_COMPILER)
        try:
            library = ctypes.CDLL(str(self.path()))
        except (c_toolchain.NativeBuildError, OSError) as error:
            raise LoopUnavailable(f"the compiled loop {self.source.name} cannot be built or loaded: "
                                  f"{str(error).strip().splitlines()[0]}") from error
        self.declare(library)
        return library


def function_address(library, name: str) -> int:
    """The address of the library's function ``name`` (for a C caller such as CVODE)."""
    return ctypes.cast(getattr(library, name), ctypes.c_void_p).value


__all__ = ["CompiledLibrary", "LoopUnavailable", "choice", "local_headers", "function_address",
           "ENVIRONMENT_SWITCH", "CHOICES"]
