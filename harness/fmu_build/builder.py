"""Build every FMU of the project into build/fmus/ (pythonfmu 0.7).

    python build_fmu.py            # build the FMUs whose sources changed
    python build_fmu.py --force    # rebuild all
    python build_fmu.py --docs     # also rewrite the generated tables of docs/ (FMU variables, scenario keys)

Each FMU is one script plus its project files, staged under top-level names
unique across the FMUs (harness/fmu_build/staging.py: pythonfmu loads all FMUs into one
interpreter).  A build is stale when any source is newer than the FMU.
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from harness.fmu_build import native as build_native
from harness.fmu_build.native_stages import ls_ref
from harness.atomic_files import ordinary_file_mode
from harness.atomic_files import write_text as atomic_write_text
from harness.fmu_build.catalog import FMUS, FmuSource, model_class, selected_edition
from harness.fmu_build.staging import stage
from harness.scenario import keys_markdown

ROOT = Path(__file__).resolve().parents[2]  # the repository (harness/fmu_build/ is two levels down)


def is_stale(fmu: FmuSource) -> bool:
    if not fmu.fmu_path.exists():
        return True
    built = fmu.fmu_path.stat().st_mtime
    return any(source.stat().st_mtime > built for source in (*fmu.sources, *ls_ref.EXPERIMENTS.glob("*")))


def build_script(script: Path, fmu_path: Path, project_files, ls_ref_model: str | None = None) -> Path:
    """Build one FMU with pythonfmu's builder in a fresh interpreter.

    A fresh process because a process that has loaded one of our FMUs may
    import ``pythonfmu`` from that FMU's resources (which hold no binaries).
    The script and its project files are staged under their names inside the
    FMU (harness/fmu_build/staging.py), so the script's own imports resolve while the builder
    reads its model description.

    The builder writes a temporary file in the same folder, which then replaces
    ``fmu_path`` in one step (``os.replace``): a reader never sees a half-written
    FMU, and two builds at once each replace the file whole.
    """
    fmu_path.parent.mkdir(parents=True, exist_ok=True)
    handle, partial = tempfile.mkstemp(dir=fmu_path.parent, prefix=f".{fmu_path.stem}.", suffix=".fmu")
    os.close(handle)
    try:
        _run_builder(script, Path(partial), project_files, fmu_path.name)
        if ls_ref_model is not None:  # the catalog's FMUs carry FMI-LS-REF (harness/fmu_build/native_stages/ls_ref.py)
            _embed_ls_ref(Path(partial), ls_ref_model, fmu_path.name)
        ordinary_file_mode(partial)
        os.replace(partial, fmu_path)
    finally:
        if os.path.exists(partial):
            os.remove(partial)
    return fmu_path


def _run_builder(script: Path, fmu_path: Path, project_files, label: str):
    """pythonfmu's builder on the files staged under their FMU names (harness/fmu_build/staging.py) in a scratch folder,
    which alone is on PYTHONPATH: the script imports them as the FMU will."""
    with tempfile.TemporaryDirectory(prefix=".stage-", dir=fmu_path.parent) as folder:
        staged_script, *staged_files = stage((script, *project_files), Path(folder))
        environment = dict(os.environ, PYTHONPATH=os.pathsep.join([folder, os.environ.get("PYTHONPATH", "")]))
        code = ("import sys; from pythonfmu.builder import FmuBuilder; "
                "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2], project_files=sys.argv[3:], "
                "canGetAndSetFMUstate=True, canSerializeFMUstate=True)")
        completed = subprocess.run([sys.executable, "-c", code, str(staged_script), str(fmu_path),
                                    *map(str, staged_files)], env=environment, capture_output=True, text=True,
                                   cwd=folder)
    if completed.returncode != 0:
        raise RuntimeError(f"building {label} from {script} failed:\n{completed.stderr}")


def _embed_ls_ref(fmu_path: Path, model: str, label: str):
    """Append the FMU's FMI-LS-REF files (harness/fmu_build/native_stages/ls_ref.py, written by harness/fmu_build/native_stages/package.py), in a
    fresh interpreter for the reason above: making the reference runs the FMU."""
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    completed = subprocess.run([sys.executable, "-m", "harness.fmu_build.native_stages.package", str(fmu_path), model], cwd=ROOT,
                               env=environment, capture_output=True, text=True)
    if completed.returncode != 0:
        raise RuntimeError(f"adding FMI-LS-REF to {label} failed:\n{completed.stderr}")


def build(fmu: FmuSource) -> Path:
    return build_script(fmu.script, fmu.fmu_path, fmu.project_files, ls_ref_model(fmu.model_identifier))


def ls_ref_model(model: str) -> str | None:
    """``model`` when its FMI-LS-REF experiment is stored, else None with a note: a new FMU's first build,
    before ``python -m harness compat --ls-ref-experiments`` can run its closed loop (docs/architecture.md,
    Add a plant; tests/test_ls_ref.py fails while an FMU lacks its FMI-LS-REF files)."""
    if model in ls_ref.stored_models():
        return model
    print(f"note: {model}: no FMI-LS-REF experiment stored yet; built without FMI-LS-REF (write it with "
          f"python -m harness compat --ls-ref-experiments --fmu {model}, then build again)", file=sys.stderr)
    return None


BUILD_EDITIONS = ("python", "native", "all")  # what this script builds (native: FMI 2.0 and 3.0)


def ensure_built(force: bool = False, verbose: bool = False, edition: str | None = None) -> dict[str, Path]:
    """Build missing or stale FMUs; return {model identifier: path}.

    ``edition``: "python" (pythonfmu, build/fmus/), "native" (C, FMI 2.0,
    build/fmus/native/) or "native3" (C, FMI 3.0, build/fmus/native/fmi3/);
    default: $AFC_EDITION, else "python".
    """
    edition = edition or selected_edition()
    if edition in ("native", "native3"):
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


def markdown_table(variables) -> str:
    """The docs/model.md table of an FMU's variables (its VARIABLES rows)."""
    lines = ["| name | causality | type | start | valid range | unit | meaning |",
             "|---|---|---|---|---|---|---|"]
    for v in variables:
        valid = v.valid_range() if v.causality == "parameter" else ""
        if v.causality == "output":
            valid = "depends on " + (", ".join(v.depends_on) if v.depends_on else "no input")
        start = f"{v.start:.6g}" if v.causality != "output" else ""
        lines.append(f"| `{v.name}` | {v.causality} | {v.kind} | {start} | {valid} | {v.unit} | {v.description} |")
    return "\n".join(lines)


def variable_tables() -> str:
    """The variable tables of every FMU in FMUS, generated from each FMU's declaration."""
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


MASTER_DOC = ROOT / "docs" / "master.md"
KEYS_BEGIN = "<!-- scenario keys: generated by `python build_fmu.py --docs` from harness/scenario.py's SCHEMA -->"
KEYS_END = "<!-- end of scenario keys -->"


def with_scenario_keys(text: str, where: str = "docs/master.md") -> str:
    """``text`` with the part between the scenario-key markers replaced by the table of harness/scenario.py."""
    pattern = re.compile(re.escape(KEYS_BEGIN) + ".*?" + re.escape(KEYS_END), re.S)
    if not pattern.search(text):
        raise SystemExit(f"{where} lacks the markers {KEYS_BEGIN!r} ... {KEYS_END!r}")
    return pattern.sub(lambda _: f"{KEYS_BEGIN}\n\n{keys_markdown()}\n\n{KEYS_END}", text)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--force", action="store_true", help="rebuild every FMU")
    parser.add_argument("--docs", "--readme", dest="docs", action="store_true",
                        help="rewrite the generated tables of docs/: the variable tables in docs/model.md, the "
                             "scenario keys in docs/master.md (--readme: old name)")
    parser.add_argument("--edition", choices=BUILD_EDITIONS, default=None,
                        help="python (pythonfmu), native (C, FMI 2.0 and 3.0, docs/native.md) or all "
                             "(default: all when zig's compiler is installed, else python)")
    parser.add_argument("--targets", default=None,
                        help="the native edition only: comma-separated platforms among "
                             f"{', '.join(build_native.PLATFORMS)} (default: all)")
    args = parser.parse_args(argv)
    if args.targets is not None:
        if args.edition != "native":
            parser.error("--targets selects the native edition's platforms: give it with --edition native")
        try:
            return build_native.main(["--targets", args.targets] + (["--force"] if args.force else []))
        except build_native.NativeBuildError as error:
            print(f"error: {error}", file=sys.stderr)
            return 1
    editions = ["python", "native"] if args.edition in (None, "all") else [args.edition]
    if "native" in editions:
        if not build_native.compiler_available():
            if args.edition == "native":
                print("error: the native edition needs zig's C compiler: pip install -e '.[native]'", file=sys.stderr)
                return 1
            editions.remove("native")
            print("note: native edition skipped (no C compiler): pip install -e '.[native]' to build it")
    for edition in editions:
        try:
            built = ensure_built(force=args.force, verbose=True, edition=edition)
        except build_native.NativeBuildError as error:  # a declaration missing, the compiler's complaint
            print(f"error: {error}", file=sys.stderr)
            return 1
        for identifier, path in built.items():
            print(f"{identifier} ({edition}): {path.relative_to(ROOT)}")
    if args.docs:
        for page, rewrite, what in ((MODEL_DOC, with_variable_tables, "variable tables"),
                                    (MASTER_DOC, with_scenario_keys, "scenario keys")):
            text = page.read_text()
            updated = rewrite(text)
            atomic_write_text(page, updated)
            print(f"{page.relative_to(ROOT)}: {what} " + ("updated" if updated != text else "already current"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
