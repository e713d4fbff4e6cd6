"""The Model Exchange part of a native FMU's description: its XML, from the model's declaration
(the ``model_exchange()`` of its script, fmu_src/afc_declaration.py; docs/model_exchange.md)."""
from __future__ import annotations

from xml.etree import ElementTree as ET

from harness.fmu_build.toolchain import NativeBuildError
from harness.fmu_build.catalog import ROOT, declaration, fmu, model_class
from fmu_src.afc_declaration import Derivative, EventIndicator, ModelExchange
from fmu_src.afc_slave_base import _unknown, initial_dependencies

__all__ = ["Derivative", "EventIndicator", "ModelExchange", "add_model_exchange", "event_indicator_elements",
           "model_exchange"]


def model_exchange(model_identifier: str) -> ModelExchange:
    """The Model Exchange declaration of a native FMU: its script's ``model_exchange()``."""
    declared = getattr(declaration(model_identifier), "model_exchange", None)
    if declared is None:  # a model folder whose fmu.py lacks it
        raise NativeBuildError(f"{fmu(model_identifier).script.relative_to(ROOT)}: "
                               f"{model_identifier} declares no model_exchange() (every FMU with a C edition needs "
                               "one: its continuous states and their derivatives, docs/model_exchange.md)")
    return declared()


def _derivative_unit(unit: str) -> str:
    """The unit of der(x) for x in ``unit``: rad -> rad/s, rad/s -> rad/s2, A -> A/s."""
    if not unit:
        return ""
    if unit.endswith("/s"):
        return unit + "2"
    if unit.endswith("/s2"):
        return unit[:-1] + "3"
    return unit + "/s"


def add_model_exchange(root: ET.Element, model_identifier: str) -> ET.Element:
    """Model Exchange beside Co-Simulation in the FMI 2.0 description ``root`` (in place).

    <ModelExchange>, numberOfEventIndicators, der(<state>) and the other variables after the table,
    reinit on the states an event may reset, and the ModelStructure: the outputs' dependencies on
    states, <Derivatives>, and the derivatives' <InitialUnknowns> (their knowns in initialization
    mode: the initial dependencies of the states they depend on, their inputs and parameters).
    """
    declaration = model_exchange(model_identifier)
    table = model_class(model_identifier).VARIABLES
    rows = {v.name: v for v in table}
    index = {v.name: i + 1 for i, v in enumerate(table)}
    cosim = root.find("CoSimulation")
    root.set("numberOfEventIndicators", str(len(declaration.event_indicators)))
    me = ET.Element("ModelExchange", modelIdentifier=cosim.get("modelIdentifier"), needsExecutionTool="false",
                    completedIntegratorStepNotNeeded="true", canBeInstantiatedOnlyOncePerProcess="false",
                    canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true",
                    canSerializeFMUstate="true")
    root.insert(list(root).index(cosim), me)
    variables = root.find("ModelVariables")
    for scalar in variables:
        if scalar.get("name") in declaration.reinit:
            scalar[0].set("reinit", "true")
    definitions = root.find("UnitDefinitions")
    units = {unit.get("name") for unit in definitions} if definitions is not None else set()
    first = len(table) + 1  # value reference N is FMI 3.0's time
    extras = declaration.extra_names()

    def add(name, description, variability, **real):
        vr = first + extras.index(name)
        index[name] = len(variables) + 1
        scalar = ET.SubElement(variables, "ScalarVariable", name=name, valueReference=str(vr),
                               description=description, causality="local", variability=variability,
                               initial="calculated")
        ET.SubElement(scalar, "Real", **{k: v for k, v in real.items() if v})

    for derivative in declaration.derivatives:
        add(f"der({derivative.state})", derivative.description or f"derivative of {derivative.state}", "continuous",
            derivative=str(index[derivative.state]), unit=_derivative_unit(rows[derivative.state].unit))
    for indicator in declaration.event_indicators:
        add(indicator.name, indicator.description, "continuous")
    for name, description in declaration.locals:
        add(name, description, "discrete")
    for name in sorted({_derivative_unit(rows[state].unit) for state in declaration.states} - units - {""}):
        ET.SubElement(definitions, "Unit", name=name)  # e.g. A/s for der(i)
    structure = root.find("ModelStructure")
    outputs = structure.find("Outputs")
    states = dict(declaration.output_states)
    for unknown in (outputs if outputs is not None else ()):
        name = table[int(unknown.get("index")) - 1].name
        if name not in states:
            continue
        known = [int(i) for i in unknown.get("dependencies", "").split()]
        kinds = (unknown.get("dependenciesKind") or " ".join(["dependent"] * len(known))).split()
        pairs = list(zip(known, kinds)) + [(index[state], kind) for state, kind in states[name]]
        pairs.sort()
        unknown.set("dependencies", " ".join(str(i) for i, _ in pairs))
        unknown.set("dependenciesKind", " ".join(kind for _, kind in pairs))
    if declaration.derivatives:
        derivatives = ET.Element("Derivatives")
        structure.insert(list(structure).index(structure.find("InitialUnknowns")), derivatives)
        initial = structure.find("InitialUnknowns")
        for derivative in declaration.derivatives:
            _unknown(derivatives, index[f"der({derivative.state})"], [index[n] for n, _ in derivative.depends_on],
                     [kind for _, kind in derivative.depends_on])
            knowns = set(derivative.parameters)
            for name, _ in derivative.depends_on:
                knowns |= set(initial_dependencies(table, rows[name])) if name in declaration.states else {name}
            _unknown(initial, index[f"der({derivative.state})"], sorted(index[n] for n in knowns))
    return root


def event_indicator_elements(fmi2_root: ET.Element) -> list:
    """The FMI 2.0 description's event indicator variables: the first numberOfEventIndicators
    locals that are not derivatives (add_model_exchange writes them after the derivatives)."""
    count = int(fmi2_root.get("numberOfEventIndicators") or 0)
    return [s for s in fmi2_root.find("ModelVariables")
            if s.get("causality") == "local" and s[0].get("derivative") is None][:count]

