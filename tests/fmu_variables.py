"""Helpers for the tests that go over every FMU and every declared variable (through fmpy).

pythonfmu 0.7 reports every Python exception as fmi2Fatal, so failures are asserted as
"status >= fmi2Error" (``FMI_ERROR``).  The ``unzipped`` fixture (tests/conftest.py) extracts each
FMU once per test module.
"""
from __future__ import annotations

from harness.fmu_build import catalog as fmu_catalog
from tests.fmu_helpers import Driven

FMU_IDS = tuple(f.model_identifier for f in fmu_catalog.FMUS)
VARIABLES = {fmu_id: {v.name: v for v in fmu_catalog.model_class(fmu_id).VARIABLES} for fmu_id in FMU_IDS}
FMI_ERROR = 3


def driven(fmu_paths, unzipped, fmu_id, name="instance"):
    return Driven(fmu_paths[fmu_id], name, unzip_dir=unzipped[fmu_id])


def outputs_of(fmu_id):
    return [n for n, v in VARIABLES[fmu_id].items() if v.causality == "output"]


def inputs_of(fmu_id):
    return [n for n, v in VARIABLES[fmu_id].items() if v.causality == "input"]


def errors(instance):
    return [message for status, message in instance.messages if status >= FMI_ERROR]
