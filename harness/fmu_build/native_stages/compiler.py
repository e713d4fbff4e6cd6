"""One shared library per model, FMI version and target, compiled by zig's C compiler and cached
under build/native/obj by the hash of everything that goes into it."""
from __future__ import annotations

import hashlib
from pathlib import Path

import fmpy

from harness.fmu_build import toolchain as c_toolchain
from harness.fmu_build.toolchain import CFLAGS, WORK_DIR, NativeBuildError, compile_cached
from harness.fmu_build.catalog import FmuSource, archive_name
from harness.fmu_build.native_stages import LAYER, ROOT
from harness.fmu_build.native_stages.targets import Target


def fmi_headers() -> Path:
    """fmpy's copy of the FMI 2.0 and 3.0 headers."""
    folder = Path(fmpy.__file__).parent / "c-code"
    if not (folder / "fmi3Functions.h").exists():
        raise NativeBuildError(f"the FMI headers are missing from {folder} (fmpy >= 0.3.20 ships them)")
    return folder



def named_sources(model: FmuSource, header_dir: Path) -> tuple[Path, ...]:
    """The model's C sources under the names they have in the FMU's sources/ (fmu_catalog.archive_name:
    a model folder's model.c is copied into ``header_dir`` as <folder>.c), so the binary is the one a
    build of the FMU's own sources makes (the linker's output follows the file names)."""
    named = []
    for path in model.c_sources:
        name = archive_name(path)
        if name != path.name:
            copy = header_dir / name
            if not copy.exists() or copy.read_bytes() != path.read_bytes():
                copy.write_bytes(path.read_bytes())
            path = copy
        named.append(path)
    return tuple(named)


def compile_binary(model: FmuSource, header_dir: Path, fmi_version: int, target: Target, zig_version: str) -> Path:
    """One shared library, cached by the hash of everything that goes into it."""
    sources = named_sources(model, header_dir)
    includes = (header_dir, fmi_headers(), LAYER[0].parent, *{p.parent for p in model.c_sources})
    arguments = ["cc", "-target", target.zig, "-shared", *CFLAGS, f"-DFMI_VERSION={fmi_version}",
                 "-g0", "-s"]  # no debug information, no symbol table beyond the exports: no build paths inside
    if target.extension == ".so":
        # link-time optimisation: the per-step path's calls across files (the layer into the model, the model
        # into afc_math.c or plant_integration.h's users) are inlined as within one file; the arithmetic is the
        # same with or without it (-ffp-contract=off, no fast-math).  ELF only: zig links Windows and macOS
        # binaries with linkers that have no LTO
        arguments += ["-fPIC", "-lm", "-flto", *c_toolchain.ELF_FLAGS]
    if target.extension == ".dylib":  # the name a host sees, not the scratch file's path
        arguments.append(f"-Wl,-install_name,@rpath/{model.model_identifier}.dylib")
    arguments += [f"-I{folder}" for folder in includes]
    digest = hashlib.sha256("\0".join([zig_version, *arguments[:-len(includes)]]).encode())
    for path in (*LAYER, *sources, *model.c_headers, header_dir / "model_variables.h",
                 fmi_headers() / f"fmi{fmi_version}Functions.h"):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    cached = WORK_DIR / "obj" / f"{model.model_identifier}-fmi{fmi_version}-{target.zig}-{digest.hexdigest()[:16]}{target.extension}"
    if cached.exists():
        return cached
    return compile_cached(cached, f"{model.model_identifier}{target.extension}",
                          [*arguments, "-o", "{output}", str(LAYER[0]), *map(str, sources)],
                          f"{model.model_identifier} (FMI {fmi_version}, {target.zig})")


def math_library() -> Path:
    """The controller's pure C modules (afc_math, initial_error_latch, chatter_monitor) as one
    shared library, for their tests through ctypes."""
    sources = [ROOT / "fmu_src" / f"{name}.c" for name in ("afc_math", "initial_error_latch", "chatter_monitor")]
    return c_toolchain.host_library("afc_math", sources, [p.with_suffix(".h") for p in sources])

