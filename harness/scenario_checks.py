"""A scenario checked against its FMUs before anything is instantiated: which FMU file each component
names, its model description, and every name of the scenario (parameters, connections, record,
bounds, signals) against those descriptions.

Each mistake is one ScenarioError naming the file, the table and the key, with the close match of a
misspelt name and the valid names (docs/master.md); a parameter's range stays the FMU's to check.
"""
from __future__ import annotations

import math
import numbers
from pathlib import Path

from harness.fmu_build import builder as build_fmu

from .fmi import FmuFileError, ModelInfo
from .scenario import Scenario, ScenarioError, did_you_mean


def resolve_fmu(spec_fmu: str, scenario: Scenario, built: dict | None) -> Path:
    """The FMU file a component's ``fmu`` names: a path to an .fmu file (relative to the scenario
    file), or the name of a built FMU (``built``, else the current edition's, built if stale)."""
    if spec_fmu.endswith(".fmu"):
        path = Path(spec_fmu)
        if not path.is_absolute() and scenario.path is not None:
            path = scenario.path.parent / path
        if not path.exists():
            raise ScenarioError(f"FMU file not found: {path}")
        return path
    if built is None:
        built = build_fmu.ensure_built()
    if spec_fmu not in built:
        raise ScenarioError(f"unknown FMU {spec_fmu!r}; valid: {', '.join(sorted(built))} or a path to an .fmu file")
    return built[spec_fmu]


def _names(info: ModelInfo, causality: str) -> list:
    return [v.name for v in info.variables.values() if v.causality == causality]


def _article(word: str) -> str:
    return "an" if word[:1] in "aeiou" else "a"


def _where(scenario: Scenario) -> str:
    """How messages name the scenario: its file, else its name."""
    return str(scenario.path) if scenario.path is not None else scenario.name


def model_info(scenario: Scenario, instance: str, fmu_paths: dict | None) -> ModelInfo:
    """The model description of one component; a missing or broken FMU file is a ScenarioError
    naming the file, the component and its ``fmu`` key."""
    spec = scenario.components[instance]
    try:
        return ModelInfo.read(resolve_fmu(spec.fmu, scenario, fmu_paths))
    except (ScenarioError, FmuFileError, FileNotFoundError) as error:
        raise ScenarioError(f"{_where(scenario)}: [components.{instance}] fmu = {spec.fmu!r}: {error}") from None


def _check_variable(dotted: str, infos: dict, causality: str, role: str):
    instance, _, variable = dotted.partition(".")
    if instance not in infos:
        raise ScenarioError(f"{role} {dotted!r}: unknown instance {instance!r}{did_you_mean(instance, infos)}; "
                            f"valid: {', '.join(infos)}")
    info = infos[instance]
    found = info.variables.get(variable)
    wanted = _names(info, causality)
    if found is None:
        raise ScenarioError(f"{role} {dotted!r}: {instance} has no variable {variable!r}"
                            f"{did_you_mean(variable, wanted)}; valid {causality}s: {', '.join(wanted)}")
    if found.causality != causality:
        raise ScenarioError(f"{role} {dotted!r} is {_article(found.causality)} {found.causality}, "
                            f"not {_article(causality)} {causality}; "
                            f"valid {causality}s of {instance}: {', '.join(wanted)}")
    if found.type != "Real":
        raise ScenarioError(f"{role} {dotted!r} is of type {found.type}; connections and records are Real")


def _check_parameter_value(instance: str, parameter: str, value, kind: str):
    """A scenario value must be a number (not text, not a Boolean), integral for an Integer.

    Range checks stay with the FMU, which names the valid range; this only stops values
    that float()/int() would silently convert ("0.99") or truncate (1.5 -> 1).
    """
    where = f"[components.{instance}.parameters] {parameter} = {value!r}"
    if kind == "Boolean":
        if not isinstance(value, bool):
            raise ScenarioError(f"{where} is not a Boolean (true or false)")
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy numbers too
        raise ScenarioError(f"{where} is not a number")
    if kind == "Integer" and not (math.isfinite(value) and value == int(value)):
        raise ScenarioError(f"{where} is not an integer")


def validate(scenario: Scenario, infos: dict):
    """Check every name of the scenario against the model descriptions; a mistake is one
    ScenarioError naming the file, the table and the key (and the close match of a misspelt name)."""
    try:
        _validate(scenario, infos)
    except ScenarioError as error:
        raise ScenarioError(f"{_where(scenario)}: {error}") from None


def _validate(scenario: Scenario, infos: dict):
    for name, spec in scenario.components.items():
        info = infos[name]
        for parameter in spec.parameters:
            found = info.variables.get(parameter)
            if found is None or found.causality != "parameter":
                valid = _names(info, "parameter")
                raise ScenarioError(f"[components.{name}.parameters] {info.model_identifier} has no parameter "
                                    f"{parameter!r}"
                                    f"{did_you_mean(parameter, valid)}; valid: {', '.join(valid)}")
            _check_parameter_value(name, parameter, spec.parameters[parameter], found.type)
    targets = set()
    for index, connection in enumerate(scenario.connections):
        _check_variable(connection.source, infos, "output", f"[[connections]] {index + 1}: from =")
        _check_variable(connection.target, infos, "input", f"[[connections]] {index + 1}: to =")
        if connection.target in targets:
            raise ScenarioError(f"[[connections]] {index + 1}: input {connection.target!r} is connected twice")
        targets.add(connection.target)
    for dotted in scenario.record:
        _check_variable(dotted, infos, "output", "[record] variables:")
    connected = {c.source for c in scenario.connections}
    for dotted in scenario.bounds:
        _check_variable(dotted, infos, "output", "[bounds]")
        if dotted not in connected and dotted not in scenario.record:
            raise ScenarioError(f"[bounds] {dotted!r} is neither connected nor recorded, so it is never read")
    for role, dotted in scenario.signals.items():
        if dotted not in scenario.record:
            raise ScenarioError(f"[signals] {role} = {dotted!r} is not in [record] variables"
                                f"{did_you_mean(dotted, scenario.record)}; add it there")


__all__ = ["resolve_fmu", "model_info", "validate"]
