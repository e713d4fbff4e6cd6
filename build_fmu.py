"""Build every FMU of the project into build/fmus/ (pythonfmu 0.7).

    python build_fmu.py            # build the FMUs whose sources changed
    python build_fmu.py --force    # rebuild all
    python build_fmu.py --docs     # also rewrite the variable tables in docs/model.md

Each FMU is one script (unique file name: pythonfmu loads all FMUs into one
interpreter) plus its project files.  A build is stale when any source is
newer than the FMU.
"""
from __future__ import annotations

import argparse
import importlib
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent
FMU_DIR = ROOT / "build" / "fmus"
BASE = ROOT / "fmu_src" / "afc_slave_base.py"


@dataclass(frozen=True)
class FmuSource:
    model_identifier: str
    script: Path
    project_files: tuple[Path, ...]

    @property
    def fmu_path(self) -> Path:
        return FMU_DIR / f"{self.model_identifier}.fmu"

    @property
    def sources(self) -> tuple[Path, ...]:
        return (self.script, *self.project_files)


FMUS = (
    FmuSource("AdaptiveFuzzyController", ROOT / "fmu_src" / "adaptive_fuzzy_controller_fmu.py",
              (BASE, ROOT / "fmu_src" / "afc_math.py",
               ROOT / "fmu_src" / "initial_error_latch.py", ROOT / "fmu_src" / "chatter_monitor.py")),
    FmuSource("InvertedPendulum", ROOT / "plants" / "inverted_pendulum_fmu.py",
              (BASE, ROOT / "plants" / "inverted_pendulum_model.py",
               ROOT / "plants" / "plant_integration.py", ROOT / "plants" / "rk4_plant_slave.py")),
    FmuSource("Manipulator", ROOT / "plants" / "manipulator_fmu.py",
              (BASE, ROOT / "plants" / "manipulator_model.py",
               ROOT / "plants" / "plant_integration.py", ROOT / "plants" / "rk4_plant_slave.py")),
    FmuSource("TrackingReference", ROOT / "plants" / "tracking_reference_fmu.py", (BASE,)),
    FmuSource("DcMotorArm", ROOT / "plants" / "dc_motor_arm_fmu.py",
              (BASE, ROOT / "plants" / "dc_motor_arm_model.py",
               ROOT / "plants" / "plant_integration.py", ROOT / "plants" / "rk4_plant_slave.py")),
)


def is_stale(fmu: FmuSource) -> bool:
    if not fmu.fmu_path.exists():
        return True
    built = fmu.fmu_path.stat().st_mtime
    return any(source.stat().st_mtime > built for source in fmu.sources)


def build_script(script: Path, fmu_path: Path, project_files) -> Path:
    """Build one FMU with pythonfmu's builder in a fresh interpreter.

    A fresh process because a process that has loaded one of our FMUs may
    import ``pythonfmu`` from that FMU's resources (which hold no binaries).
    The folders of the project files go on PYTHONPATH, so the script's own
    imports resolve while the builder reads its model description.

    The builder writes a temporary file in the same folder, which then replaces
    ``fmu_path`` in one step (``os.replace``): a reader never sees a half-written
    FMU, and two builds at once each replace the file whole.
    """
    import tempfile

    fmu_path.parent.mkdir(parents=True, exist_ok=True)
    handle, partial = tempfile.mkstemp(dir=fmu_path.parent, prefix=f".{fmu_path.stem}.", suffix=".fmu")
    os.close(handle)
    try:
        _run_builder(script, Path(partial), project_files, fmu_path.name)
        ordinary_file_mode(partial)
        os.replace(partial, fmu_path)
    finally:
        if os.path.exists(partial):
            os.remove(partial)
    return fmu_path


def ordinary_file_mode(path) -> None:
    """Give a file made by mkstemp (private, 0600) the mode of an ordinary new file (0666 less the umask)."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def _run_builder(script: Path, fmu_path: Path, project_files, label: str):
    folders = list(dict.fromkeys(str(Path(p).resolve().parent) for p in (script, *project_files)))
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(folders + [os.environ.get("PYTHONPATH", "")]))
    code = ("import sys; from pythonfmu.builder import FmuBuilder; "
            "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2], project_files=sys.argv[3:], "
            "canGetAndSetFMUstate=True, canSerializeFMUstate=True)")
    completed = subprocess.run([sys.executable, "-c", code, str(script), str(fmu_path),
                                *map(str, project_files)], env=environment, capture_output=True, text=True)
    if completed.returncode != 0:
        raise RuntimeError(f"building {label} from {script} failed:\n{completed.stderr}")


def build(fmu: FmuSource) -> Path:
    return build_script(fmu.script, fmu.fmu_path, fmu.project_files)


EDITIONS = ("python", "native", "all")
#: the edition the harness runs (``--edition`` sets it for the process and its workers)
EDITION_VARIABLE = "AFC_EDITION"


def selected_edition() -> str:
    edition = os.environ.get(EDITION_VARIABLE, "python") or "python"
    if edition not in ("python", "native", "native3"):
        raise SystemExit(f"error: {EDITION_VARIABLE}={edition!r} is invalid; valid: python, native, native3")
    return edition


def ensure_built(force: bool = False, verbose: bool = False, edition: str | None = None) -> dict[str, Path]:
    """Build missing or stale FMUs; return {model identifier: path}.

    ``edition``: "python" (pythonfmu, build/fmus/), "native" (C, FMI 2.0,
    build/fmus/native/) or "native3" (C, FMI 3.0, build/fmus/native/fmi3/);
    default: $AFC_EDITION, else "python".
    """
    edition = edition or selected_edition()
    if edition in ("native", "native3"):
        import build_native
        version = 3 if edition == "native3" else 2
        return {name: paths[version]
                for name, paths in build_native.ensure_built(force=force, verbose=verbose).items()}
    paths = {}
    for fmu in FMUS:
        if force or is_stale(fmu):
            build(fmu)
            if verbose:
                print(f"built {fmu.fmu_path.relative_to(ROOT)}")
        paths[fmu.model_identifier] = fmu.fmu_path
    return paths


def model_class(model_identifier: str):
    """The slave class of an FMU, imported as the FMU imports it (top-level modules)."""
    fmu = next((f for f in FMUS if f.model_identifier == model_identifier), None)
    if fmu is None:
        raise KeyError(f"unknown FMU {model_identifier!r}; valid: {[f.model_identifier for f in FMUS]}")
    for folder in {str(p.parent) for p in fmu.sources}:
        if folder not in sys.path:
            sys.path.insert(0, folder)
    return getattr(importlib.import_module(fmu.script.stem), model_identifier)


def variable_tables() -> str:
    """The variable tables of every FMU in FMUS, generated from each FMU's declaration."""
    from fmu_src.afc_slave_base import markdown_table

    parts = []
    for fmu in FMUS:
        model = model_class(fmu.model_identifier)
        parts.append(f"### `{fmu.model_identifier}`\n\n{model.MODEL_DESCRIPTION}.\n\n"
                     f"{markdown_table(model.VARIABLES)}\n")
    return "\n".join(parts)


MODEL_DOC = ROOT / "docs" / "model.md"
TABLES_BEGIN = "<!-- variable tables: generated by `python build_fmu.py --docs` -->"
TABLES_END = "<!-- end of variable tables -->"


def with_variable_tables(text: str, where: str = "docs/model.md") -> str:
    """``text`` with the part between the table markers replaced by the current tables."""
    pattern = re.compile(re.escape(TABLES_BEGIN) + ".*?" + re.escape(TABLES_END), re.S)
    if not pattern.search(text):
        raise SystemExit(f"{where} lacks the markers {TABLES_BEGIN!r} ... {TABLES_END!r}")
    return pattern.sub(lambda _: f"{TABLES_BEGIN}\n\n{variable_tables()}\n{TABLES_END}", text)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--force", action="store_true", help="rebuild every FMU")
    parser.add_argument("--docs", "--readme", dest="docs", action="store_true",
                        help="rewrite the variable tables in docs/model.md (--readme: old name)")
    parser.add_argument("--edition", choices=EDITIONS, default=None,
                        help="python (pythonfmu), native (C, FMI 2.0 and 3.0, docs/native.md) or all "
                             "(default: all when zig's compiler is installed, else python)")
    args = parser.parse_args(argv)
    editions = ["python", "native"] if args.edition in (None, "all") else [args.edition]
    if "native" in editions:
        import build_native
        if not build_native.compiler_available():
            if args.edition == "native":
                print("error: the native edition needs zig's C compiler: pip install -e '.[native]'", file=sys.stderr)
                return 1
            editions.remove("native")
            print("note: native edition skipped (no C compiler): pip install -e '.[native]' to build it")
    for edition in editions:
        for identifier, path in ensure_built(force=args.force, verbose=True, edition=edition).items():
            print(f"{identifier} ({edition}): {path.relative_to(ROOT)}")
    if args.docs:
        text = MODEL_DOC.read_text()
        updated = with_variable_tables(text)
        MODEL_DOC.write_text(updated)
        print(f"{MODEL_DOC.relative_to(ROOT)}: variable tables "
              + ("updated" if updated != text else "already current"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
