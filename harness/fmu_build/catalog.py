"""The FMUs of the project, declared once for both builds (build_fmu.py, harness/fmu_build/native.py) and the harness.

One row per FMU: its model identifier, its pythonfmu script and the project files that travel with
it (the reference edition), its C sources and headers (the native edition).  The controller's row
is here; the plants' rows come from the plant registry (plants/registry.py), one per model folder.
Each script is also the FMU's declaration (:func:`declaration`): its variable table, its Model
Exchange interface and its test drive (fmu_src/afc_declaration.py).  Also declared here:
the editions the harness runs, the folder each is built into, and the environment variable that
selects one (``--edition`` sets it for a command and its worker processes).
"""
from __future__ import annotations

import importlib
import os
from dataclasses import dataclass
from pathlib import Path

from harness.fmu_build.staging import module_name
from plants import registry as plant_registry

ROOT = Path(__file__).resolve().parents[2]  # the repository (harness/fmu_build/ is two levels down)
FMU_SRC = ROOT / "fmu_src"
BASE = FMU_SRC / "afc_slave_base.py"  # the slave base class every pythonfmu FMU carries
DECLARATION = FMU_SRC / "afc_declaration.py"  # what a script declares beside its table (every FMU carries it)

#: the editions the harness runs and where each is built: pythonfmu (the reference edition),
#: C for FMI 2.0, C for FMI 3.0 (docs/native.md)
FMU_DIR = ROOT / "build" / "fmus"
NATIVE_DIR = FMU_DIR / "native"
FMI3_DIR = NATIVE_DIR / "fmi3"
EDITIONS = ("python", "native", "native3")
#: the edition the harness runs (``--edition`` sets it for the process and its workers)
EDITION_VARIABLE = "AFC_EDITION"


@dataclass(frozen=True)
class FmuSource:
    model_identifier: str
    script: Path  # the pythonfmu script and declaration (harness/fmu_build/staging.py gives it a unique name inside the FMU)
    project_files: tuple[Path, ...]  # what travels with the script (the base class first)
    c_sources: tuple[Path, ...] = ()  # compiled with fmu_src/fmi_layer.c into the native edition
    c_headers: tuple[Path, ...] = ()

    @property
    def fmu_path(self) -> Path:
        """The pythonfmu edition's FMU."""
        return FMU_DIR / f"{self.model_identifier}.fmu"

    @property
    def sources(self) -> tuple[Path, ...]:
        """The pythonfmu edition's sources (a build is stale when one is newer than the FMU)."""
        return (self.script, *self.project_files)


CONTROLLER = FmuSource(
    "AdaptiveFuzzyController", FMU_SRC / "adaptive_fuzzy_controller_fmu.py",
    (BASE, DECLARATION, FMU_SRC / "afc_math.py", FMU_SRC / "initial_error_latch.py", FMU_SRC / "chatter_monitor.py"),
    (FMU_SRC / "adaptive_fuzzy_controller.c", FMU_SRC / "afc_math.c", FMU_SRC / "initial_error_latch.c",
     FMU_SRC / "chatter_monitor.c"),
    (FMU_SRC / "afc_math.h", FMU_SRC / "initial_error_latch.h", FMU_SRC / "chatter_monitor.h"))

FMUS = (CONTROLLER, *(FmuSource(row.model_identifier, row.script, (BASE, DECLARATION, *row.project_files), row.c_sources,
                                row.c_headers) for row in plant_registry.PLANT_FMUS))


def fmu(model_identifier: str) -> FmuSource:
    for row in FMUS:
        if row.model_identifier == model_identifier:
            return row
    raise KeyError(f"unknown FMU {model_identifier!r}; valid: {[f.model_identifier for f in FMUS]}")


def declaration(model_identifier: str):
    """The module of an FMU's script: ``VARIABLES``, the slave class, ``model_exchange()``, ``test_drive()``."""
    return importlib.import_module(module_name(fmu(model_identifier).script))


def model_class(model_identifier: str):
    """The slave class of an FMU (the class named by its model identifier in its script)."""
    module = declaration(model_identifier)
    if not hasattr(module, model_identifier):
        raise KeyError(f"{fmu(model_identifier).script.relative_to(ROOT)} defines no class {model_identifier} "
                       "(a model folder's name in CamelCase names its slave class)")
    return getattr(module, model_identifier)


def archive_name(path: Path) -> str:
    """A C source's name inside the native FMUs: a model folder's ``model.c`` is ``<folder>.c``, so
    the FMU's sources name the model; every other file keeps its name."""
    path = Path(path)
    return f"{path.parent.name}.c" if path.name == "model.c" else path.name


def selected_edition() -> str:
    """$AFC_EDITION, else "python"; an invalid value is one clear error."""
    edition = os.environ.get(EDITION_VARIABLE, "python") or "python"
    if edition not in EDITIONS:
        raise SystemExit(f"error: {EDITION_VARIABLE}={edition!r} is invalid; valid: {', '.join(EDITIONS)}")
    return edition


