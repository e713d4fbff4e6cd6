"""The plant registry: one row per FMU of plants/ (the plants and the tracking reference).

A row names the files of one FMU by their common stem (``plants/<stem>_fmu.py``, the pythonfmu
script; ``plants/<stem>_model.py``, its pure model; ``plants/<stem>.c``, its C edition) and what
the harness needs to know of it: the plant's order and the in-process oracle's model (harness/
studies/oracle.py).  Both builds take their FMU tables from here through fmu_catalog.py, so a new
plant is its own three files, a scenario file, its references, and one row below (with its oracle
model, when the oracle should know it).

Every RK4 plant shares the integrator (plant_integration.py / .c) and the slave base class
(rk4_plant_slave.py / .c); the reference has no state to integrate and no model module.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from . import inverted_pendulum_model, manipulator_model

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


@dataclass(frozen=True)
class PlantFmu:
    model_identifier: str
    stem: str
    order: int | None  # states of the plant (None: the tracking reference, not a plant)
    oracle: Callable | None = None  # parameters {name: value} -> OracleModel; None: the oracle does not know it

    @property
    def integrated(self) -> bool:
        """An RK4 plant (with a model module and the shared integrator)."""
        return self.order is not None

    @property
    def script(self) -> Path:
        return PLANTS_DIR / f"{self.stem}_fmu.py"

    @property
    def project_files(self) -> tuple[Path, ...]:
        """The pythonfmu edition's files besides the script and the shared base class."""
        return (PLANTS_DIR / f"{self.stem}_model.py", *RK4_PROJECT_FILES) if self.integrated else ()

    @property
    def c_sources(self) -> tuple[Path, ...]:
        return (PLANTS_DIR / f"{self.stem}.c", *(RK4_C_SOURCES if self.integrated else ()))

    @property
    def c_headers(self) -> tuple[Path, ...]:
        return RK4_C_HEADERS if self.integrated else ()


# ------------------------------------------------------------------- oracle models
def pendulum_oracle(p: dict) -> OracleModel:
    params = inverted_pendulum_model.pendulum_params(p["gv"], p["mc"], p["mp"], p["lp"], p["dist_gain"])

    def extra(t, x1, x2):
        return {"plant.d": inverted_pendulum_model.pendulum_disturbance(t, p["dist_gain"])}

    return OracleModel(inverted_pendulum_model.pendulum_derivative, params, extra)


def manipulator_oracle(p: dict) -> OracleModel:
    params = manipulator_model.manipulator_params(p["gv"], p["lr"], p["dr"], p["cr"], p["vr"], p["mr0"], p["mr1"])

    def extra(t, x1, x2):
        mr = manipulator_model.manipulator_payload(t, p["mr0"], p["mr1"])
        inertia = manipulator_model.manipulator_inertia(mr, p["lr"])
        return {"plant.d": manipulator_model.manipulator_friction(x2, inertia, p["cr"], p["vr"]), "plant.mr": mr}

    return OracleModel(manipulator_model.manipulator_derivative, params, extra)


# ------------------------------------------------------------------- the rows
#: in the order of the built FMUs and of docs/model.md's variable tables
PLANT_FMUS = (
    PlantFmu("InvertedPendulum", "inverted_pendulum", order=2, oracle=pendulum_oracle),
    PlantFmu("Manipulator", "manipulator", order=2, oracle=manipulator_oracle),
    PlantFmu("TrackingReference", "tracking_reference", order=None),
    PlantFmu("DcMotorArm", "dc_motor_arm", order=3),  # the third-order plant of docs/general_order.md
)
BY_IDENTIFIER = {row.model_identifier: row for row in PLANT_FMUS}


def oracle_model(model_identifier: str, parameters: dict) -> OracleModel:
    """The oracle's model of a plant FMU with these parameter values."""
    row = BY_IDENTIFIER.get(model_identifier)
    if row is None or row.oracle is None:
        known = " and ".join(r.model_identifier for r in PLANT_FMUS if r.oracle is not None)
        raise ValueError(f"the oracle knows {known}, not {model_identifier!r}")
    return row.oracle(parameters)
