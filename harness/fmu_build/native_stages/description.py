"""The native FMUs' modelDescription.xml: FMI 2.0 from pythonfmu's own description of the class,
with Model Exchange added, and FMI 3.0 translated from it; the GUID fixed by their inputs."""
from __future__ import annotations

import datetime
import hashlib
import os
import subprocess
import uuid
from xml.dom import minidom
from xml.etree import ElementTree as ET

from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.catalog import model_class
from harness.fmu_build.native_stages import LAYER, ROOT
from harness.fmu_build.native_stages.model_exchange import add_model_exchange, event_indicator_elements, model_exchange

GENERATION_TOOL = "afc-fmi native edition (harness/fmu_build/native.py)"


def model_sources(model_identifier: str) -> tuple:
    """Every file the native FMU is made from: its Python declaration, the FMI layer, its C sources."""
    model = fmu_catalog.fmu(model_identifier)
    return (*model.sources, *LAYER, *model.c_sources, *model.c_headers)


def generation_date_and_time(model_identifier: str) -> str:
    """The FMU's generationDateAndTime, fixed by its sources so that a rebuild is bit-identical:
    SOURCE_DATE_EPOCH (seconds since 1970, UTC) when set, else the date of the last commit that
    touched one of its sources, else the newest modification time of those files; in UTC, to the second."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    if epoch is not None:
        if not epoch.strip().isdigit():
            raise ValueError(f"SOURCE_DATE_EPOCH = {epoch!r} is invalid; valid: a whole number of seconds >= 0")
        seconds = int(epoch)
    else:
        paths = [str(p) for p in model_sources(model_identifier)]
        try:
            found = subprocess.run(["git", "log", "-1", "--format=%ct", "--", *paths], cwd=ROOT,
                                   capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            found = ""
        seconds = int(found) if found else int(max(os.path.getmtime(p) for p in paths))
    stamp = datetime.datetime.fromtimestamp(seconds, datetime.timezone.utc)
    return stamp.isoformat(timespec="seconds").replace("+00:00", "Z")


def _pythonfmu_description(model_identifier: str) -> ET.Element:
    """pythonfmu's modelDescription.xml of the class: the pythonfmu edition's own."""
    cls = model_class(model_identifier)
    instance = cls(instance_name="native-edition", resources=str(ROOT))
    return instance.to_xml()


def model_guid(model_identifier: str) -> str:
    """A GUID fixed by the declaration and the C sources (same for FMI 2.0 and 3.0)."""
    model = fmu_catalog.fmu(model_identifier)
    digest = hashlib.sha256()
    root = _pythonfmu_description(model_identifier)
    root.attrib.pop("guid", None)
    root.attrib.pop("generationDateAndTime", None)
    digest.update(ET.tostring(root))
    digest.update(repr(model_exchange(model_identifier)).encode())
    for path in (*LAYER, *model.c_sources, *model.c_headers):
        digest.update(path.read_bytes())
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16], version=5)) + "}"


def pretty_xml(root: ET.Element) -> bytes:
    text = ET.tostring(root, encoding="unicode")
    return minidom.parseString(text).toprettyxml(indent="  ", encoding="UTF-8")


def fmi2_description(model_identifier: str, guid: str) -> ET.Element:
    root = _pythonfmu_description(model_identifier)
    root.set("guid", guid)
    root.set("generationTool", GENERATION_TOOL)
    root.set("generationDateAndTime", generation_date_and_time(model_identifier))
    cosim = root.find("CoSimulation")
    cosim.set("needsExecutionTool", "false")
    cosim.set("canNotUseMemoryManagementFunctions", "true")
    cosim.set("canBeInstantiatedOnlyOncePerProcess", "false")
    cosim.set("canGetAndSetFMUstate", "true")  # fmi_layer.c: get/set/free and (de)serialize the state
    cosim.set("canSerializeFMUstate", "true")
    add_model_exchange(root, model_identifier)
    return root


def fmi3_description(fmi2_root: ET.Element) -> ET.Element:
    """The FMI 3.0 description translated from the FMI 2.0 one (same variables)."""
    attributes = {k: v for k, v in fmi2_root.attrib.items()
                  if k in ("modelName", "description", "author", "version", "generationTool",
                            "generationDateAndTime")}
    root = ET.Element("fmiModelDescription", fmiVersion="3.0",
                      instantiationToken=fmi2_root.get("guid"), variableNamingConvention="structured",
                      **attributes)
    cosim2 = fmi2_root.find("CoSimulation")
    if fmi2_root.find("ModelExchange") is not None:
        ET.SubElement(root, "ModelExchange", modelIdentifier=cosim2.get("modelIdentifier"),
                      needsExecutionTool="false", canBeInstantiatedOnlyOncePerProcess="false",
                      canGetAndSetFMUState="true", canSerializeFMUState="true", needsCompletedIntegratorStep="false")
    ET.SubElement(root, "CoSimulation", modelIdentifier=cosim2.get("modelIdentifier"),
                  canHandleVariableCommunicationStepSize="true", canGetAndSetFMUState="true",
                  canSerializeFMUState="true", canBeInstantiatedOnlyOncePerProcess="false",
                  hasEventMode="false", providesIntermediateUpdate="false")
    units = fmi2_root.find("UnitDefinitions")
    if units is not None:
        unit_definitions = ET.SubElement(root, "UnitDefinitions")
        for unit in units:
            ET.SubElement(unit_definitions, "Unit", name=unit.get("name"))
    types = fmi2_root.find("TypeDefinitions")
    if types is not None:
        type_definitions = ET.SubElement(root, "TypeDefinitions")
        for simple in types:
            ET.SubElement(type_definitions, "Float64Type", name=simple.get("name"),
                          description=simple.get("description"), quantity=simple[0].get("quantity"))
    categories = fmi2_root.find("LogCategories")
    if categories is not None:
        log_categories = ET.SubElement(root, "LogCategories")
        for category in categories:
            ET.SubElement(log_categories, "Category", dict(category.attrib))
    experiment = fmi2_root.find("DefaultExperiment")
    if experiment is not None:
        ET.SubElement(root, "DefaultExperiment", dict(experiment.attrib))
    variables = ET.SubElement(root, "ModelVariables")
    references = {str(index): scalar.get("valueReference")
                  for index, scalar in enumerate(fmi2_root.find("ModelVariables"), start=1)}
    for scalar in fmi2_root.find("ModelVariables"):
        typed = scalar[0]
        kind = {"Real": "Float64", "Integer": "Int32"}[typed.tag]
        element = ET.SubElement(variables, kind, name=scalar.get("name"),
                                valueReference=scalar.get("valueReference"))
        for key in ("description", "causality", "variability", "initial"):
            if scalar.get(key) is not None:
                element.set(key, scalar.get(key))
        if typed.get("declaredType") is not None:
            element.set("declaredType", typed.get("declaredType"))
        for key in ("start", "unit", "min", "max", "reinit"):
            if typed.get(key) is not None:
                element.set(key, typed.get(key))
        if typed.get("derivative") is not None:  # FMI 2.0: the state's index; FMI 3.0: its value reference
            element.set("derivative", references[typed.get("derivative")])
    # FMI 3.0 requires the independent variable; it takes the value reference after the table's
    # (the first one free: the Model Exchange variables follow it)
    used = {int(vr) for vr in references.values()}
    time_reference = str(min(set(range(len(used) + 1)) - used))
    ET.SubElement(variables, "Float64", name="time", valueReference=time_reference, causality="independent",
                  variability="continuous", description="simulation time")
    structure = ET.SubElement(root, "ModelStructure")
    structure2 = fmi2_root.find("ModelStructure")
    # Outputs, Derivatives, InitialUnknowns in that order (FMI 3.0's), then the event indicators
    for list_name, element_name in (("Outputs", "Output"), ("Derivatives", "ContinuousStateDerivative"),
                                    ("InitialUnknowns", "InitialUnknown")):
        unknowns = structure2.find(list_name)
        for unknown in (unknowns if unknowns is not None else ()):
            element = ET.SubElement(structure, element_name, valueReference=references[unknown.get("index")])
            if unknown.get("dependencies") is not None:
                element.set("dependencies", " ".join(references[i] for i in unknown.get("dependencies").split()))
            if unknown.get("dependenciesKind") is not None:
                element.set("dependenciesKind", unknown.get("dependenciesKind"))
    vrs = {scalar.get("name"): scalar.get("valueReference") for scalar in fmi2_root.find("ModelVariables")}
    declared = {e.name: e for e in model_exchange(cosim2.get("modelIdentifier")).event_indicators}
    for indicator in event_indicator_elements(fmi2_root):
        element = ET.SubElement(structure, "EventIndicator", valueReference=indicator.get("valueReference"))
        pairs = sorted((int(vrs[known]), kind) for known, kind in declared[indicator.get("name")].depends_on)
        element.set("dependencies", " ".join(str(vr) for vr, _ in pairs))
        if pairs:
            element.set("dependenciesKind", " ".join(kind for _, kind in pairs))
    return root

