"""Build the native edition of the FMUs: the same four models in C, FMI 2.0 and FMI 3.0.

    python build_fmu.py --edition native [--targets linux64,win64,darwin64,aarch64-linux] [--force]

From each FMU's declaration table (the ``VARIABLES`` of its pythonfmu class) the
stages of :mod:`harness.fmu_build.native_stages` (one module each) generate

* the FMI 2.0 modelDescription.xml: pythonfmu's own ``to_xml`` of the class (the very
  description of the pythonfmu edition), with the native FMU's GUID and capabilities, plus
  Model Exchange from the model's ``ModelExchange`` declaration (:func:`model_exchange`:
  its continuous states, their derivatives der(x), event indicators and what each depends
  on; docs/model_exchange.md);
* the FMI 3.0 modelDescription.xml, translated from that FMI 2.0 description (names,
  value references, causality, variability, start, units, min/max, derivatives, the whole
  ModelStructure with dependencies, DefaultExperiment);
* ``model_variables.h``: the variable table for the C layer (value references, names,
  starts, valid ranges and their wording), so the validation messages are the Python
  edition's, and the counts and value references of the Model Exchange variables;

then compiles ``fmu_src/fmi_layer.c`` with the model's C files with zig's C compiler
(``pip install ziglang``, the ``native`` extra) for

=============  ===================================  ==========================  ==========================
platform       zig target                           FMI 2.0 folder              FMI 3.0 folder
=============  ===================================  ==========================  ==========================
linux64        x86_64-linux-gnu.2.17 (glibc 2.17)   binaries/linux64            binaries/x86_64-linux
win64          x86_64-windows-gnu (UCRT)            binaries/win64              binaries/x86_64-windows
darwin64       x86_64-macos.10.13, aarch64-macos.11 binaries/darwin64 (fat:     binaries/x86_64-darwin,
                                                    both architectures)         binaries/aarch64-darwin
aarch64-linux  aarch64-linux-gnu.2.17 (glibc 2.17)  binaries/aarch64-linux      binaries/aarch64-linux
=============  ===================================  ==========================  ==========================

Compiled binaries are cached under build/native/obj by a hash of their inputs (sources,
generated header, flags, compiler version), so a rebuild compiles only what changed;
zig keeps its own cache in build/native/zig-cache (set ZIG_GLOBAL_CACHE_DIR to share
one).  FMUs go to build/fmus/native/<Model>.fmu (FMI 2.0) and
build/fmus/native/fmi3/<Model>.fmu (FMI 3.0), written atomically.
"""
from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from harness.fmu_build import toolchain as c_toolchain
from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.toolchain import WORK_DIR, NativeBuildError, compiler_available
from harness.fmu_build.catalog import FMI3_DIR, NATIVE_DIR, FmuSource
from harness.fmu_build.native_stages import LAYER, ROOT, ls_ref
from harness.fmu_build.native_stages.compiler import compile_binary
from harness.fmu_build.native_stages.description import fmi2_description, fmi3_description, model_guid, pretty_xml
from harness.fmu_build.native_stages.header import variables_header
from harness.atomic_files import write_bytes as atomic_write
from harness.fmu_build.native_stages.package import fmu_files, zip_archive
from harness.fmu_build.native_stages.sources import add_source_files, source_files
from harness.fmu_build.native_stages.targets import PLATFORMS, selected_targets
from plants import registry as plant_registry

__all__ = ["PLATFORMS", "NativeBuildError", "WORK_DIR", "build_model", "chosen_platforms", "compiler_available",
           "ensure_built", "fmu_paths", "is_fresh", "main", "models", "stale_models"]
STAGES = tuple(sorted((Path(__file__).parent / "native_stages").glob("*.py")))  # the build's own modules: inputs of every FMU


def models() -> tuple[FmuSource, ...]:
    """The FMUs of harness/fmu_build/catalog.py that have a C edition (their ``c_sources``, compiled with the layer)."""
    return tuple(m for m in fmu_catalog.FMUS if m.c_sources)



def fmu_paths() -> dict[str, dict[int, Path]]:
    return {m.model_identifier: {2: NATIVE_DIR / f"{m.model_identifier}.fmu",
                                 3: FMI3_DIR / f"{m.model_identifier}.fmu"} for m in models()}



def build_model(model: FmuSource, platforms=PLATFORMS, jobs: int = 2, zig_version: str | None = None,
                verbose: bool = False) -> dict[int, Path]:
    """Build one model's FMI 2.0 and 3.0 FMUs; return {2: path, 3: path}."""
    zig_version = zig_version or c_toolchain.zig_version()
    guid = model_guid(model.model_identifier)
    description2 = fmi2_description(model.model_identifier, guid)
    description3 = fmi3_description(description2)
    add_source_files(description2, model)  # after the translation: FMI 3.0 has buildDescription.xml instead
    header_dir = WORK_DIR / "generated" / model.model_identifier
    header = header_dir / "model_variables.h"
    text = variables_header(model.model_identifier, guid)
    if not header.exists() or header.read_text() != text:
        atomic_write(header, text.encode())
    targets = selected_targets(platforms)
    jobs_list = [(version, target) for version in (2, 3) for target in targets]

    def say(text):  # one write per line: the compiling threads' lines never run into each other
        if verbose:
            sys.stderr.write(f"native: {text}\n")
            sys.stderr.flush()

    say(f"{model.model_identifier}: {len(jobs_list)} binaries (FMI 2.0 and 3.0 for "
        f"{', '.join(t.zig for t in targets)}), {max(1, jobs)} at a time")

    def compile_one(job):  # each binary says what it was when it is there: a cold zig cache takes minutes
        version, target = job
        began = time.time()
        binary = compile_binary(model, header_dir, version, target, zig_version)
        how = f"compiled in {time.time() - began:.1f} s" if binary.stat().st_mtime >= began - 1 else "from the cache"
        say(f"{model.model_identifier} FMI {version}.0 {target.zig}: {how}")
        return binary

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        binaries = dict(zip(jobs_list, pool.map(compile_one, jobs_list)))
    files = fmu_files(model, {2: pretty_xml(description2), 3: pretty_xml(description3)}, header, binaries, targets,
                      source_files(model))
    paths = fmu_paths()[model.model_identifier]
    atomic_write(paths[2], zip_archive(files[2]))
    atomic_write(paths[3], zip_archive(files[3]))
    if verbose:
        print(f"built {paths[2].relative_to(ROOT)} and {paths[3].relative_to(ROOT)} ({', '.join(platforms)})")
    return paths


def _stamp(model: FmuSource, platforms) -> str:
    """What a built FMU depends on: sources, declaration, platforms."""
    digest = hashlib.sha256(",".join(sorted(platforms)).encode())
    # this module, the build's stages, the toolchain's flags and the FMU tables are inputs too
    for path in (*LAYER, *model.c_sources, *model.c_headers, *model.sources, Path(__file__), *STAGES,
                 Path(c_toolchain.__file__), Path(fmu_catalog.__file__), Path(plant_registry.__file__),
                 *sorted(ls_ref.EXPERIMENTS.glob("*"))):  # the stored FMI-LS-REF experiments
        digest.update(path.read_bytes())
    return digest.hexdigest()


def chosen_platforms(platforms=None) -> tuple:
    """``platforms``, else $AFC_NATIVE_PLATFORMS (comma-separated), else all of PLATFORMS."""
    if platforms is None:
        chosen = os.environ.get("AFC_NATIVE_PLATFORMS", "")
        platforms = tuple(p for p in chosen.split(",") if p) or PLATFORMS
    return tuple(platforms)


def _stamp_file(model: FmuSource) -> Path:
    return WORK_DIR / "stamps" / f"{model.model_identifier}.stamp"


def is_fresh(model: FmuSource, platforms=None) -> bool:
    """Whether the model's FMUs exist and were built from its inputs as they are now for ``platforms``."""
    platforms = chosen_platforms(platforms)
    stamp_file = _stamp_file(model)
    return (all(p.exists() for p in fmu_paths()[model.model_identifier].values()) and stamp_file.exists()
            and stamp_file.read_text() == _stamp(model, platforms))


def stale_models(platforms=None) -> list:
    """The models ensure_built would build now."""
    return [model for model in models() if not is_fresh(model, platforms)]


def ensure_built(platforms=None, force: bool = False, verbose: bool = False, jobs: int = 2,
                 announce=None) -> dict[str, dict[int, Path]]:
    """Build the native FMUs whose inputs changed; return {model identifier: {2: path, 3: path}}.

    ``platforms`` defaults to $AFC_NATIVE_PLATFORMS (comma-separated) or all of PLATFORMS; ``announce(model,
    targets)``, if given, is called before a model is built (targets: the zig target names).
    """
    if not compiler_available():
        raise NativeBuildError("the native edition needs zig's C compiler: pip install ziglang "
                               "(or pip install -e '.[native]')")
    platforms = chosen_platforms(platforms)
    zig_version = None
    result = {}
    for model in models():
        paths = fmu_paths()[model.model_identifier]
        stamp = _stamp(model, platforms)
        if force or not is_fresh(model, platforms):
            zig_version = zig_version or c_toolchain.zig_version()
            if announce is not None:
                announce(model, [t.zig for t in selected_targets(platforms)])
            build_model(model, platforms, jobs=jobs, zig_version=zig_version, verbose=verbose)
            atomic_write(_stamp_file(model), stamp.encode())
        elif verbose:
            print(f"native: {model.model_identifier}: up to date", file=sys.stderr, flush=True)
        result[model.model_identifier] = paths
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--targets", default=",".join(PLATFORMS),
                        help=f"comma-separated platforms among {', '.join(PLATFORMS)} (default: all)")
    parser.add_argument("--force", action="store_true", help="rebuild every native FMU")
    parser.add_argument("--jobs", type=int, default=2, help="parallel compilations (default 2)")
    args = parser.parse_args(argv)
    try:
        ensure_built(tuple(p for p in args.targets.split(",") if p), force=args.force, verbose=True, jobs=args.jobs)
    except NativeBuildError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
