"""The plant registry: every folder of plants/ holding an ``fmu.py`` is one FMU (a plant or the tracking reference).

A model folder ``plants/<name>/`` holds (as the Modelica Reference-FMUs do)

* ``fmu.py``: the declaration and the pythonfmu edition: the variable table ``VARIABLES``, the
  slave class ``<Name>`` (the folder's name in CamelCase is the model identifier), its Model
  Exchange interface ``model_exchange()`` and the tests' ``test_drive()`` (fmu_src/afc_declaration.py);
* ``model.c``: the C edition (the hooks of fmu_src/fmi_layer.h);
* ``model.py``: the pure model of an RK4 plant (its derivative; ``oracle(parameters)`` when the
  in-process oracle of harness/studies/oracle.py should know it); the reference has none.

Both builds take their FMU tables from here through harness/fmu_build/catalog.py, the tests their per-FMU cases
from the declarations: a new plant is its folder, its scenario and references, and a docs row.
Every RK4 plant shares the integrator (plant_integration.py / .c) and the slave base class
(rk4_plant_slave.py / .c), which stay in plants/.
"""
from __future__ import annotations

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
    def integrated(self) -> bool:
        """An RK4 plant (with a model module and the shared integrator); the reference has neither."""
        return (self.folder / "model.py").is_file()

    @property
    def script(self) -> Path:
        return self.folder / "fmu.py"

    @property
    def model(self) -> Path:
        return self.folder / "model.py"

    @property
    def project_files(self) -> tuple[Path, ...]:
        """The pythonfmu edition's files besides the script and the shared base classes."""
        return (self.model, *RK4_PROJECT_FILES) if self.integrated else ()

    @property
    def c_sources(self) -> tuple[Path, ...]:
        return (self.folder / "model.c", *(RK4_C_SOURCES if self.integrated else ()))

    @property
    def c_headers(self) -> tuple[Path, ...]:
        return RK4_C_HEADERS if self.integrated else ()

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
