"""The source FMU: what an importer needs to compile the binary from the FMU's own ``sources/``.

FMI 2.0 lists the compilation units in ``<SourceFiles>`` of ``<ModelExchange>`` and ``<CoSimulation>``
and has no way to pass a preprocessor definition, so the FMI layer's version comes from a generated
unit, ``fmi2_layer.c``, which defines ``FMI_VERSION`` 2 and includes ``fmi_layer.c``. FMI 3.0 has
``sources/buildDescription.xml``: the same units with ``fmi_layer.c`` itself, the definition
``FMI_VERSION=3``, the language and the include folder (``sources/`` itself, where the model's
headers and ``model_variables.h`` sit). The FMI headers are the importer's (the standard's rule).
"""
from __future__ import annotations

from xml.etree import ElementTree as ET

from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.native_stages import LAYER
from harness.fmu_build.native_stages.description import pretty_xml

FMI2_UNIT = "fmi2_layer.c"
LANGUAGE = "C11"  # c_toolchain.CFLAGS: -std=c11
INCLUDE_DIRECTORY = "."  # relative to sources/


def fmi2_unit_text() -> bytes:
    """``fmi2_layer.c``: the FMI layer for FMI 2.0 as one compilation unit."""
    return (f"/* The FMI 2.0 build of {LAYER[0].name} (FMI 2.0 source FMUs pass no preprocessor definitions). */\n"
            f"#define FMI_VERSION 2\n#include \"{LAYER[0].name}\"\n").encode()


def compilation_units(model: fmu_catalog.FmuSource, fmi_version: int) -> tuple[str, ...]:
    """The files of ``sources/`` compiled one by one into the FMU's binary, the layer first."""
    layer = FMI2_UNIT if fmi_version == 2 else LAYER[0].name
    return (layer, *(fmu_catalog.archive_name(path) for path in model.c_sources))


def add_source_files(fmi2_root: ET.Element, model: fmu_catalog.FmuSource) -> None:
    """FMI 2.0: ``<SourceFiles>`` in each interface element (its only child the schema allows)."""
    for interface in ("ModelExchange", "CoSimulation"):
        element = fmi2_root.find(interface)
        if element is None:
            continue
        files = ET.SubElement(element, "SourceFiles")
        for name in compilation_units(model, 2):
            ET.SubElement(files, "File", name=name)


def build_description(model: fmu_catalog.FmuSource) -> bytes:
    """FMI 3.0: ``sources/buildDescription.xml``, one build configuration for every platform."""
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    configuration = ET.SubElement(root, "BuildConfiguration", modelIdentifier=model.model_identifier)
    file_set = ET.SubElement(configuration, "SourceFileSet", language=LANGUAGE)
    for name in compilation_units(model, 3):
        ET.SubElement(file_set, "SourceFile", name=name)
    ET.SubElement(file_set, "PreprocessorDefinition", name="FMI_VERSION", value="3",
                  description="the FMI version the layer implements")
    ET.SubElement(file_set, "IncludeDirectory", name=INCLUDE_DIRECTORY)
    return pretty_xml(root)


def source_files(model: fmu_catalog.FmuSource) -> dict[int, dict[str, bytes]]:
    """{FMI version: {archive path: bytes}}: the generated files each edition adds to ``sources/``."""
    return {2: {f"sources/{FMI2_UNIT}": fmi2_unit_text()},
            3: {"sources/buildDescription.xml": build_description(model)}}
