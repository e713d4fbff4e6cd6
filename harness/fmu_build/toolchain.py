"""The C toolchain: zig's C compiler from the ziglang wheel (``pip install -e .``).

Used by the native edition's build (harness/fmu_build/native.py: the FMUs' shared libraries for every
platform) and, through :func:`host_library`, by the master's compiled loop (harness/master_loop.py)
and by the tests of the C math: one shared library for the machine running the harness, cached in
build/native/obj by the hash of its sources, headers and flags.  Imports no project module.
"""
from __future__ import annotations

import hashlib
import os
import platform
import subprocess
import sys
import tempfile
from importlib import metadata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository (harness/fmu_build/ is two levels down)
WORK_DIR = ROOT / "build" / "native"  # object cache (obj/) and zig's own cache (zig-cache/)
# IEEE arithmetic exactly as written (no fused multiply-add, no fast-math): the native
# results then match the Python edition's to the last bit where the libm agrees.
CFLAGS = ("-std=c11", "-O2", "-ffp-contract=off", "-fno-fast-math", "-fvisibility=hidden",
          "-Wall", "-Wextra", "-Werror", "-Wno-unused-parameter", "-Wno-unused-function", "-Wno-unused-const-variable")


# the FMUs' binaries on ELF (Linux): no frame pointer, which zig keeps by default, so that every FMI function's
# entry and exit are two instructions shorter (the per-step path is nine FMI calls); Apple's and Windows' ABIs
# keep theirs, and so do the host-side libraries of this machine (host_library)
ELF_FLAGS = ("-fomit-frame-pointer",)


class NativeBuildError(RuntimeError):
    """C code cannot be built (no compiler, a compile error)."""


def compiler_available() -> bool:
    try:
        import ziglang  # noqa: F401 - optional: the native and test extras install it, the core does not
    except ImportError:
        return False
    return True


def zig(*args: str) -> list[str]:
    """The command line of zig with ``args`` (zig runs as ``python -m ziglang``)."""
    return [sys.executable, "-m", "ziglang", *args]


def ziglang_version() -> str:
    """The installed ziglang package's version (no subprocess), or "" without it."""
    try:
        return metadata.version("ziglang")
    except metadata.PackageNotFoundError:
        return ""


def zig_version() -> str:
    """zig's own version (a subprocess)."""
    return subprocess.run(zig("version"), capture_output=True, text=True, check=True).stdout.strip()


def compile_cached(cached: Path, output_name: str, arguments, what: str) -> Path:
    """Run ``zig ARGUMENTS`` (``{output}`` in them: the file to write) and move its output to ``cached``.

    zig writes into a scratch folder beside ``cached`` (under the name ``output_name``: the name a
    shared library records for itself), which then replaces ``cached`` in one step, so concurrent
    builders each write their own scratch copy and a reader never sees half a library.  zig keeps
    its cache in build/native/zig-cache unless ZIG_GLOBAL_CACHE_DIR / ZIG_LOCAL_CACHE_DIR say otherwise.
    """
    cached.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cached.parent) as scratch:
        output = Path(scratch) / output_name
        environment = dict(os.environ)
        environment.setdefault("ZIG_GLOBAL_CACHE_DIR", str(WORK_DIR / "zig-cache"))
        environment.setdefault("ZIG_LOCAL_CACHE_DIR", str(WORK_DIR / "zig-cache"))
        command = zig(*(str(output) if argument == "{output}" else argument for argument in arguments))
        completed = subprocess.run(command, capture_output=True, text=True, env=environment, cwd=scratch)
        if completed.returncode != 0:
            raise NativeBuildError(f"compiling {what} failed:\n{completed.stderr}")
        try:
            os.replace(output, cached)
        except OSError:
            if not cached.exists():  # Windows refuses to replace a DLL another process has loaded
                raise
    return cached


def host_target() -> str | None:
    """zig's target for a library this machine loads: the linux64 FMUs' target on x86-64 Linux
    (its libc stubs are then already in zig's cache), else zig's own host target."""
    if sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64"):
        return "x86_64-linux-gnu.2.17"
    return None


def host_library(name: str, sources, headers=()) -> Path:
    """``sources`` compiled into one shared library for this machine (not an FMU), cached in
    build/native/obj by the hash of sources, headers and flags; for the tests of the C math
    and for the master's compiled loop."""
    sources = tuple(Path(p) for p in sources)
    target = host_target()
    extension = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
    flags = [f for f in CFLAGS if f != "-fvisibility=hidden"]
    if target is None:
        flags.append("-mcpu=baseline")  # not the build machine's CPU: a shared build folder stays usable
    digest = hashlib.sha256(" ".join([*flags, str(target), ziglang_version()]).encode())
    for path in (*sources, *headers):
        digest.update(Path(path).read_bytes())
    library = WORK_DIR / "obj" / f"{name}-{digest.hexdigest()[:16]}{extension}"
    if library.exists():
        return library
    if not compiler_available():
        raise NativeBuildError(f"building {name} needs zig's C compiler: pip install ziglang "
                               "(or pip install -e .)")
    arguments = ["cc", *(["-target", target] if target else []), "-shared", "-fPIC", *flags,
                 "-o", "{output}", *map(str, sources), "-lm"]
    return compile_cached(library, library.name, arguments, name)
