"""The plant registry: every folder of plants/ holding an ``fmu.py`` is one FMU (a plant, the tracking
reference, the sensor or the actuator).

A model folder ``plants/<name>/`` holds (as the Modelica Reference-FMUs do)

* ``fmu.py``: the declaration and the pythonfmu edition: its ``KIND`` (which shared base it is
  built on, :data:`KINDS`), the variable table ``VARIABLES``, the slave class ``<Name>`` (the
  folder's name in CamelCase is the model identifier), its Model Exchange interface
  ``model_exchange()`` and the tests' ``test_drive()`` (fmu_src/afc_declaration.py);
* ``model.c``: the C edition (the hooks of fmu_src/fmi_layer.h);
* ``model.py``: the pure model (an RK4 plant's derivative, with ``oracle(parameters)`` when the
  in-process oracle of harness/studies/oracle.py should know it; the sensor's measurement, the
  actuator's limits); the reference has none.

Both builds take their FMU tables from here through harness/fmu_build/catalog.py, the tests their per-FMU cases
from the declarations: a new plant is its folder, its scenario and references, and a docs row.
What a kind shares stays in plants/: every RK4 plant the integrator (plant_integration.py / .c) and
the slave base class (rk4_plant_slave.py / .c); the sampled FMUs the sampled chain
(sampled_chain.py / .c) and their slave base (sampled_slave.py / .c).
"""
from __future__ import annotations

import ast
import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

PLANTS_DIR = Path(__file__).resolve().parent
#: what every RK4 plant's pythonfmu edition carries besides its own files (in this order)
RK4_PROJECT_FILES = (PLANTS_DIR / "plant_integration.py", PLANTS_DIR / "rk4_plant_slave.py")
#: what every RK4 plant's C edition compiles and includes besides its own file (in this order)
RK4_C_SOURCES = (PLANTS_DIR / "rk4_plant_slave.c", PLANTS_DIR / "plant_integration.c")
RK4_C_HEADERS = (PLANTS_DIR / "plant_integration.h", PLANTS_DIR / "rk4_plant_slave.h")


@dataclass(frozen=True)
class Kind:
    """What the FMUs of one kind share: the files each carries besides its folder's own."""

    meaning: str
    project_files: tuple  # the pythonfmu edition's, after the folder's model.py
    c_sources: tuple  # compiled after the folder's model.c
    c_headers: tuple


#: the value of ``KIND`` in a folder's fmu.py and what it brings
KINDS = {
    "plant": Kind("a plant integrated by fixed-step RK4 (y, dy, ... from its states, input u)",
                  RK4_PROJECT_FILES, RK4_C_SOURCES, RK4_C_HEADERS),
    "reference": Kind("a function of time and of its inputs, no state (the tracking reference)", (), (), ()),
    "sampled": Kind("a sample-and-hold on a clock of its own with a delay line (the sensor, the actuator)",
                    (PLANTS_DIR / "sampled_chain.py", PLANTS_DIR / "sampled_slave.py"),
                    (PLANTS_DIR / "sampled_slave.c", PLANTS_DIR / "sampled_chain.c"),
                    (PLANTS_DIR / "sampled_chain.h", PLANTS_DIR / "sampled_slave.h")),
}


def declared_kind(script: Path) -> str:
    """The ``KIND = "..."`` of an fmu.py, read without importing it (the registry loads before any FMU
    module); a missing or unknown kind is one error naming the file and the valid kinds."""
    for node in ast.parse(script.read_text(), str(script)).body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
                and node.targets[0].id == "KIND" and isinstance(node.value, ast.Constant)):
            if node.value.value in KINDS:
                return node.value.value
            raise ValueError(f"{script}: KIND = {node.value.value!r} is unknown; valid: {', '.join(KINDS)}")
    raise ValueError(f"{script}: no KIND = \"...\" line; give one of {', '.join(KINDS)} (plants/registry.py, KINDS)")


@dataclass(frozen=True)
class OracleModel:
    """A second-order plant as the oracle integrates it: RK4 on ``derivative(t, x1, x2, u, params)``."""

    derivative: Callable
    params: tuple
    extra: Callable  # (t, x1, x2) -> {"plant.<output>": value} of the outputs beyond y, dy


def model_identifier(folder_name: str) -> str:
    """The model identifier of a model folder: its name in CamelCase (dc_motor_arm -> DcMotorArm)."""
    return "".join(word.capitalize() for word in folder_name.split("_"))


@dataclass(frozen=True)
class PlantFmu:
    """One model folder of plants/."""

    folder: Path

    @property
    def name(self) -> str:
        return self.folder.name

    @property
    def model_identifier(self) -> str:
        return model_identifier(self.name)

    @property
    def kind(self) -> str:
        """Its fmu.py's ``KIND``: a key of :data:`KINDS`."""
        return declared_kind(self.script)

    @property
    def integrated(self) -> bool:
        """An RK4 plant (with a model module and the shared integrator)."""
        return self.kind == "plant"

    @property
    def script(self) -> Path:
        return self.folder / "fmu.py"

    @property
    def model(self) -> Path:
        return self.folder / "model.py"

    @property
    def project_files(self) -> tuple[Path, ...]:
        """The pythonfmu edition's files besides the script and the shared base classes."""
        own = (self.model,) if self.model.is_file() else ()
        return (*own, *KINDS[self.kind].project_files)

    @property
    def c_sources(self) -> tuple[Path, ...]:
        return (self.folder / "model.c", *KINDS[self.kind].c_sources)

    @property
    def c_headers(self) -> tuple[Path, ...]:
        return KINDS[self.kind].c_headers

    def _oracle_adapter(self) -> Callable | None:
        """The model module's ``oracle(parameters) -> (derivative, params, extra)``, if it has one."""
        return getattr(importlib.import_module(f"plants.{self.name}.model"), "oracle", None) if self.integrated else None

    @property
    def has_oracle(self) -> bool:
        return self._oracle_adapter() is not None

    def oracle(self, parameters: dict) -> OracleModel:
        """The oracle's model with these parameter values."""
        return OracleModel(*self._oracle_adapter()(parameters))


def discovered(folder: Path = PLANTS_DIR) -> tuple[PlantFmu, ...]:
    """The model folders under ``folder`` (those holding an ``fmu.py``), in name order."""
    return tuple(PlantFmu(path) for path in sorted(folder.iterdir()) if (path / "fmu.py").is_file())


#: in the order of the built FMUs and of docs/model.md's variable tables: the folders' names
PLANT_FMUS = discovered()
BY_IDENTIFIER = {row.model_identifier: row for row in PLANT_FMUS}


def oracle_model(model_identifier: str, parameters: dict) -> OracleModel:
    """The oracle's model of a plant FMU with these parameter values."""
    row = BY_IDENTIFIER.get(model_identifier)
    if row is None or not row.has_oracle:
        known = " and ".join(r.model_identifier for r in PLANT_FMUS if r.has_oracle)
        raise ValueError(f"the oracle knows {known}, not {model_identifier!r}")
    return row.oracle(parameters)
