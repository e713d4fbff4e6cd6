"""Build the native edition of the FMUs: the same four models in C, FMI 2.0 and FMI 3.0.

    python build_fmu.py --edition native            # via the project's build script
    python build_native.py [--targets linux64,win64,darwin64] [--force]

From each FMU's declaration table (the ``VARIABLES`` of its pythonfmu class) this
module generates

* the FMI 2.0 modelDescription.xml: pythonfmu's own ``to_xml`` of the class (the very
  description of the pythonfmu edition), with the native FMU's GUID and capabilities, plus
  Model Exchange from the model's ``ModelExchange`` declaration (:func:`model_exchange`:
  its continuous states, their derivatives der(x), event indicators and what each depends
  on; docs/model_exchange.md);
* the FMI 3.0 modelDescription.xml, translated from that FMI 2.0 description (names,
  value references, causality, variability, start, units, min/max, derivatives, the whole
  ModelStructure with dependencies, DefaultExperiment);
* ``model_variables.h``: the variable table for the C layer (value references, names,
  starts, valid ranges and their wording), so the validation messages are the Python
  edition's, and the counts and value references of the Model Exchange variables;

then compiles ``fmu_src/fmi_layer.c`` with the model's C files with zig's C compiler
(``pip install ziglang``, the ``native`` extra) for

=========  ===================================  ==========================  ==========================
platform   zig target                           FMI 2.0 folder              FMI 3.0 folder
=========  ===================================  ==========================  ==========================
linux64    x86_64-linux-gnu.2.17 (glibc 2.17)   binaries/linux64            binaries/x86_64-linux
win64      x86_64-windows-gnu (UCRT)            binaries/win64              binaries/x86_64-windows
darwin64   x86_64-macos.10.13, aarch64-macos.11 binaries/darwin64 (fat:     binaries/x86_64-darwin,
                                                both architectures)         binaries/aarch64-darwin
=========  ===================================  ==========================  ==========================

Compiled binaries are cached under build/native/obj by a hash of their inputs (sources,
generated header, flags, compiler version), so a rebuild compiles only what changed;
zig keeps its own cache in build/native/zig-cache (set ZIG_GLOBAL_CACHE_DIR to share
one).  FMUs go to build/fmus/native/<Model>.fmu (FMI 2.0) and
build/fmus/native/fmi3/<Model>.fmu (FMI 3.0), written atomically.
"""
from __future__ import annotations

import argparse
import hashlib
import io
import os
import re
import struct
import sys
import tempfile
import uuid
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from xml.dom import minidom
from xml.etree import ElementTree as ET

import fmpy

import c_toolchain
import fmu_catalog
from c_toolchain import CFLAGS, WORK_DIR, NativeBuildError, compile_cached, compiler_available
from fmu_src.afc_slave_base import INPUT, OUTPUT, PARAMETER, _unknown, initial_dependencies
from fmu_catalog import FMI3_DIR, NATIVE_DIR, FmuSource, model_class
from plants import registry as plant_registry

ROOT = Path(__file__).resolve().parent
LAYER = (ROOT / "fmu_src" / "fmi_layer.c", ROOT / "fmu_src" / "fmi_layer.h")
GENERATION_TOOL = "afc-fmi native edition (build_native.py)"


def models() -> tuple[FmuSource, ...]:
    """The FMUs of fmu_catalog.py that have a C edition (their ``c_sources``, compiled with the layer)."""
    return tuple(m for m in fmu_catalog.FMUS if m.c_sources)


@dataclass(frozen=True)
class Target:
    platform: str       # the FMI 2.0 platform this binary belongs to
    zig: str            # zig target triple
    fmi3_folder: str    # FMI 3.0 platform folder
    extension: str


TARGETS = (
    Target("linux64", "x86_64-linux-gnu.2.17", "x86_64-linux", ".so"),
    Target("win64", "x86_64-windows-gnu", "x86_64-windows", ".dll"),
    Target("darwin64", "x86_64-macos.10.13", "x86_64-darwin", ".dylib"),
    Target("darwin64", "aarch64-macos.11.0", "aarch64-darwin", ".dylib"),
)
PLATFORMS = ("linux64", "win64", "darwin64")
# ------------------------------------------------------------------ compiler
def fmi_headers() -> Path:
    """fmpy's copy of the FMI 2.0 and 3.0 headers."""
    folder = Path(fmpy.__file__).parent / "c-code"
    if not (folder / "fmi3Functions.h").exists():
        raise NativeBuildError(f"the FMI headers are missing from {folder} (fmpy >= 0.3.20 ships them)")
    return folder


# ---------------------------------------------------------- model description
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


def _pretty(root: ET.Element) -> bytes:
    text = ET.tostring(root, encoding="unicode")
    return minidom.parseString(text).toprettyxml(indent="  ", encoding="UTF-8")


def fmi2_description(model_identifier: str, guid: str) -> ET.Element:
    root = _pythonfmu_description(model_identifier)
    root.set("guid", guid)
    root.set("generationTool", GENERATION_TOOL)
    root.attrib.pop("generationDateAndTime", None)
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
                  if k in ("modelName", "description", "author", "version", "generationTool")}
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
    for indicator in _event_indicator_elements(fmi2_root):
        element = ET.SubElement(structure, "EventIndicator", valueReference=indicator.get("valueReference"))
        pairs = sorted((int(vrs[known]), kind) for known, kind in declared[indicator.get("name")].depends_on)
        element.set("dependencies", " ".join(str(vr) for vr, _ in pairs))
        if pairs:
            element.set("dependenciesKind", " ".join(kind for _, kind in pairs))
    return root


# ------------------------------------------------------------------ model exchange
@dataclass(frozen=True)
class Derivative:
    """der(state): the right-hand side of one continuous state."""
    state: str  # the table variable that is the state
    depends_on: tuple  # ((known, dependenciesKind), ...): the states and inputs it depends on
    parameters: tuple = ()  # the parameters it depends on (its value in initialization mode)
    description: str = ""


@dataclass(frozen=True)
class EventIndicator:
    name: str
    description: str
    depends_on: tuple = ()  # ((known, dependenciesKind), ...): states and inputs


@dataclass(frozen=True)
class ModelExchange:
    """What a native FMU declares for Model Exchange beside its table (docs/model_exchange.md).

    The continuous states are table variables (the plants' y, dy, ...; the controller's theta_j
    and w_hat), in the order of ``derivatives``; the description adds der(<state>), the event
    indicators and the model's other ``locals`` (discrete) after the table, with the value
    references N + 1, ... (N, the table's length, is FMI 3.0's time).  ``output_states`` gives
    the states an output depends on (Model Exchange knowns beside the inputs); ``reinit`` the
    states an event may reset.  The C model file's hooks (fmi_layer.h) follow the same order.
    """
    derivatives: tuple = ()
    output_states: tuple = ()  # ((output, ((state, dependenciesKind), ...)), ...)
    event_indicators: tuple = ()
    locals: tuple = ()  # ((name, description), ...)
    reinit: tuple = ()

    @property
    def states(self) -> tuple:
        return tuple(d.state for d in self.derivatives)

    def extra_names(self) -> list:
        """The names of the variables after the table, in value-reference order."""
        return ([f"der({d.state})" for d in self.derivatives] + [e.name for e in self.event_indicators]
                + [name for name, _ in self.locals])


MODEL_EXCHANGE = {
    "InvertedPendulum": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2 (37)"),
                     Derivative("dy", (("y", "dependent"), ("dy", "dependent"), ("u", "dependent")),
                                ("gv", "mc", "mp", "lp", "dist_gain"), "dx2 of (37) with d(t)"))),
    "Manipulator": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2 (38)"),
                     Derivative("dy", (("y", "dependent"), ("dy", "dependent"), ("u", "dependent")),
                                ("gv", "lr", "dr", "cr", "vr", "mr0", "mr1"),
                                "dx2 of (38, 39) in the friction mode (0 while stuck)")),
        output_states=(("d", (("dy", "dependent"),)),),
        event_indicators=(
            EventIndicator("z_slip", "slip indicator: friction_mode x2 + 1e-10 rad/s while slipping (zero when "
                                     "the link comes to rest), 1e-10 while stuck", (("dy", "discrete"),)),
            EventIndicator("z_stick", "stick indicator: cr while slipping; cr - |u - mr gv lr cos x1| while "
                                      "stuck (zero at break-away)", (("y", "dependent"), ("u", "dependent")))),
        locals=(("friction_mode", "Model Exchange friction mode: 1 slipping forwards, -1 backwards, 0 stuck "
                                  "(co-simulation: sgn(x2))"),),
        reinit=("dy",)),
    "DcMotorArm": ModelExchange(
        derivatives=(Derivative("y", (("dy", "constant"),), (), "dx1 = x2"),
                     Derivative("dy", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed")),
                                ("J", "b", "m", "lc", "gv", "Kt"), "dx2 = (Kt x3 - b x2 - m gv lc sin x1) / J"),
                     Derivative("i", (("dy", "fixed"), ("i", "fixed"), ("u", "fixed")), ("Ke", "R", "L"),
                                "dx3 = (u - R x3 - Ke x2) / L")),
        output_states=(("d2y", (("y", "dependent"), ("dy", "fixed"), ("i", "fixed"))),)),
    "TrackingReference": ModelExchange(),
}


def _controller_model_exchange() -> ModelExchange:
    """theta1..thetaN (N = the table's rule weights) and w_hat: dtheta_j = gamma tau xi_j with the
    projection (31), dw_hat = gamma_w tau (variant 3; else 0); tau and xi depend on every input."""
    table = model_class("AdaptiveFuzzyController").VARIABLES
    inputs = tuple((v.name, "dependent") for v in table if v.causality == INPUT)
    parameters = tuple(v.name for v in table if v.causality == PARAMETER)
    thetas = [v.name for v in table if v.causality == OUTPUT and v.name.startswith("theta") and v.name[5:].isdigit()]
    derivatives = tuple(Derivative(name, ((name, "dependent"), *inputs), parameters,
                                   f"d{name} of the adaptive law with projection (31)") for name in thetas)
    derivatives += (Derivative("w_hat", inputs, parameters, "dw_hat = gamma_w tau (variant 3; else 0)"),)
    return ModelExchange(derivatives=derivatives,
                         output_states=(("u", (*((name, "dependent") for name in thetas), ("w_hat", "fixed"))),))


def model_exchange(model_identifier: str) -> ModelExchange:
    """The Model Exchange declaration of a native FMU."""
    if model_identifier == "AdaptiveFuzzyController":
        return _controller_model_exchange()
    if model_identifier not in MODEL_EXCHANGE:  # a plant row of plants/registry.py without its entry here
        raise NativeBuildError(f"build_native.py: MODEL_EXCHANGE has no entry for {model_identifier!r} (every FMU "
                               "of plants/registry.py needs one: its continuous states and their derivatives, "
                               "docs/model_exchange.md)")
    return MODEL_EXCHANGE[model_identifier]


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


def _event_indicator_elements(fmi2_root: ET.Element) -> list:
    """The FMI 2.0 description's event indicator variables: the first numberOfEventIndicators
    locals that are not derivatives (add_model_exchange writes them after the derivatives)."""
    count = int(fmi2_root.get("numberOfEventIndicators") or 0)
    return [s for s in fmi2_root.find("ModelVariables")
            if s.get("causality") == "local" and s[0].get("derivative") is None][:count]


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _c_double(value) -> str:
    return repr(float(value)) if value is not None else "0.0"


def numbered_families(variables) -> dict[str, list[int]]:
    """{family: value references of its members 1, 2, ...} for names numbered from 1 without gaps:
    k1, k2 -> "k"; theta1.. -> "theta"; x1_start, x2_start -> "x_start"."""
    numbered = {}
    for vr, v in enumerate(variables):
        match = re.fullmatch(r"([A-Za-z_]+?)(\d+)((?:_[A-Za-z]+)?)", v.name)  # k1, theta12, x3_start
        if match:
            numbered.setdefault(match.group(1) + match.group(3), {})[int(match.group(2))] = vr
    families = {}
    for prefix, members in numbered.items():
        count = 0
        while count + 1 in members:
            count += 1
        if count:
            families[prefix] = [members[i] for i in range(1, count + 1)]
    return families


def variables_header(model_identifier: str, guid: str) -> str:
    """model_variables.h: the declaration table for the C layer."""
    variables = model_class(model_identifier).VARIABLES
    causality = {"parameter": "CAUSALITY_PARAMETER", "input": "CAUSALITY_INPUT", "output": "CAUSALITY_OUTPUT"}
    feedthrough = any(v.depends_on for v in variables if v.causality == "output")
    lines = [f"/* Generated by build_native.py from the VARIABLES table of {model_identifier}: do not edit. */",
             "#ifndef AFC_MODEL_VARIABLES_H", "#define AFC_MODEL_VARIABLES_H", "",
             f"#define MODEL_IDENTIFIER {_c_string(model_identifier)}",
             f"#define MODEL_GUID {_c_string(guid)}",
             f"#define N_VARIABLES {len(variables)}",
             f"#define MODEL_FEEDTHROUGH {int(feedthrough)}", ""]
    lines += [f"#define VR_{v.name} {vr}" for vr, v in enumerate(variables)]
    lines += ["", "/* numbered families (k1, k2, ...; theta1..thetaN): count and value references */"]
    for prefix, references in numbered_families(variables).items():
        lines.append(f"#define N_{prefix} {len(references)}")
        lines.append(f"static const int VRS_{prefix}[] = {{{', '.join(map(str, references))}}};")
    declaration = model_exchange(model_identifier)
    extras = declaration.extra_names()
    lines += ["", "/* model exchange (build_native.model_exchange): the states, in the order of der(x), are "
              + (", ".join(declaration.states) or "none") + " */",
              f"#define N_STATES {len(declaration.states)}",
              f"#define N_EVENT_INDICATORS {len(declaration.event_indicators)}",
              f"#define N_LOCALS {len(declaration.locals)}",
              f"#define VR_FIRST_DERIVATIVE {len(variables) + 1}",
              "#define VR_FIRST_EVENT_INDICATOR (VR_FIRST_DERIVATIVE + N_STATES)",
              "#define VR_FIRST_LOCAL (VR_FIRST_EVENT_INDICATOR + N_EVENT_INDICATORS)",
              "#define VR_END (VR_FIRST_LOCAL + N_LOCALS)",
              "#if defined(__GNUC__)", "__attribute__((unused))", "#endif",
              "static const char *const EXTRA_NAMES[] = {"
              + ", ".join(_c_string(name) for name in extras or ["(none)"]) + "};"]
    lines += ["", "#if defined(__GNUC__)", "__attribute__((unused))", "#endif",
              "static const VariableInfo MODEL_VARIABLES[N_VARIABLES] = {"]
    for v in variables:
        lines.append("    {" + ", ".join((
            _c_string(v.name), causality[v.causality], str(int(v.kind == "Integer")), _c_double(v.start),
            str(int(v.minimum is not None)), str(int(v.exclusive_minimum)), _c_double(v.minimum),
            str(int(v.maximum is not None)), str(int(v.exclusive_maximum)), _c_double(v.maximum),
            _c_string(v.valid_range()))) + "},")
    lines += ["};", "", "#endif", ""]
    return "\n".join(lines)


# ------------------------------------------------------------------- compile
def _atomic_write(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
        fmu_catalog.ordinary_file_mode(temporary)
        os.replace(temporary, path)
    except BaseException:
        if os.path.exists(temporary):
            os.unlink(temporary)
        raise


def _compile(model: FmuSource, header_dir: Path, fmi_version: int, target: Target, zig_version: str) -> Path:
    """One shared library, cached by the hash of everything that goes into it."""
    includes = (header_dir, fmi_headers(), LAYER[0].parent, *{p.parent for p in model.c_sources})
    arguments = ["cc", "-target", target.zig, "-shared", *CFLAGS, f"-DFMI_VERSION={fmi_version}",
                 "-g0", "-s"]  # no debug information, no symbol table beyond the exports: no build paths inside
    if target.extension == ".so":
        arguments += ["-fPIC", "-lm"]
    if target.extension == ".dylib":  # the name a host sees, not the scratch file's path
        arguments.append(f"-Wl,-install_name,@rpath/{model.model_identifier}.dylib")
    arguments += [f"-I{folder}" for folder in includes]
    digest = hashlib.sha256("\0".join([zig_version, *arguments[:-len(includes)]]).encode())
    for path in (*LAYER, *model.c_sources, *model.c_headers, header_dir / "model_variables.h",
                 fmi_headers() / f"fmi{fmi_version}Functions.h"):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    cached = WORK_DIR / "obj" / f"{model.model_identifier}-fmi{fmi_version}-{target.zig}-{digest.hexdigest()[:16]}{target.extension}"
    if cached.exists():
        return cached
    return compile_cached(cached, f"{model.model_identifier}{target.extension}",
                          [*arguments, "-o", "{output}", str(LAYER[0]), *map(str, model.c_sources)],
                          f"{model.model_identifier} (FMI {fmi_version}, {target.zig})")


def math_library() -> Path:
    """The controller's pure C modules (afc_math, initial_error_latch, chatter_monitor) as one
    shared library, for their tests through ctypes."""
    sources = [ROOT / "fmu_src" / f"{name}.c" for name in ("afc_math", "initial_error_latch", "chatter_monitor")]
    return c_toolchain.host_library("afc_math", sources, [p.with_suffix(".h") for p in sources])


def fat_macho(binaries: list[bytes]) -> bytes:
    """A universal (fat) Mach-O file holding the given thin binaries (what lipo -create does)."""
    alignment = 14  # 2^14: the page size of arm64 macOS
    header = struct.pack(">II", 0xCAFEBABE, len(binaries))
    offset = 1 << alignment
    entries, payload = b"", b""
    for binary in binaries:
        cpu_type, cpu_subtype = struct.unpack("<ii", binary[4:12])
        entries += struct.pack(">iiIII", cpu_type, cpu_subtype & 0x00FFFFFF, offset, len(binary), alignment)
        padded = binary + b"\0" * (-len(binary) % (1 << alignment))
        payload += padded
        offset += len(padded)
    head = header + entries
    return head + b"\0" * ((1 << alignment) - len(head)) + payload


# --------------------------------------------------------------------- build
def _selected(platforms) -> tuple[Target, ...]:
    unknown = set(platforms) - set(PLATFORMS)
    if unknown:
        raise NativeBuildError(f"unknown platform(s) {sorted(unknown)}; valid: {list(PLATFORMS)}")
    return tuple(t for t in TARGETS if t.platform in platforms)


def fmu_paths() -> dict[str, dict[int, Path]]:
    return {m.model_identifier: {2: NATIVE_DIR / f"{m.model_identifier}.fmu",
                                 3: FMI3_DIR / f"{m.model_identifier}.fmu"} for m in models()}


def _zip(files: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name in sorted(files):
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, files[name])
    return buffer.getvalue()


def build_model(model: FmuSource, platforms=PLATFORMS, jobs: int = 2, zig_version: str | None = None,
                verbose: bool = False) -> dict[int, Path]:
    """Build one model's FMI 2.0 and 3.0 FMUs; return {2: path, 3: path}."""
    zig_version = zig_version or c_toolchain.zig_version()
    guid = model_guid(model.model_identifier)
    description2 = fmi2_description(model.model_identifier, guid)
    description3 = fmi3_description(description2)
    header_dir = WORK_DIR / "generated" / model.model_identifier
    header = header_dir / "model_variables.h"
    text = variables_header(model.model_identifier, guid)
    if not header.exists() or header.read_text() != text:
        _atomic_write(header, text.encode())
    targets = _selected(platforms)
    jobs_list = [(version, target) for version in (2, 3) for target in targets]

    def say(text):  # one write per line: the compiling threads' lines never run into each other
        if verbose:
            sys.stderr.write(f"native: {text}\n")
            sys.stderr.flush()

    say(f"{model.model_identifier}: {len(jobs_list)} binaries (FMI 2.0 and 3.0 for "
        f"{', '.join(t.zig for t in targets)}), {max(1, jobs)} at a time")

    def compile_one(job):  # each binary says what it was when it is there: a cold zig cache takes minutes
        from time import time as wall_clock  # here: only the build's lines need it

        version, target = job
        began = wall_clock()
        binary = _compile(model, header_dir, version, target, zig_version)
        how = f"compiled in {wall_clock() - began:.1f} s" if binary.stat().st_mtime >= began - 1 else "from the cache"
        say(f"{model.model_identifier} FMI {version}.0 {target.zig}: {how}")
        return binary

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        binaries = dict(zip(jobs_list, pool.map(compile_one, jobs_list)))
    name = model.model_identifier
    sources = {f"sources/{p.name}": p.read_bytes() for p in (*LAYER, *model.c_sources, *model.c_headers, header)}
    files2 = {"modelDescription.xml": _pretty(description2), **sources}
    files3 = {"modelDescription.xml": _pretty(description3), **sources}
    darwin = [binaries[(2, t)].read_bytes() for t in targets if t.platform == "darwin64"]
    for target in targets:
        if target.platform != "darwin64":
            files2[f"binaries/{target.platform}/{name}{target.extension}"] = binaries[(2, target)].read_bytes()
        files3[f"binaries/{target.fmi3_folder}/{name}{target.extension}"] = binaries[(3, target)].read_bytes()
    if darwin:
        files2[f"binaries/darwin64/{name}.dylib"] = fat_macho(darwin)
    paths = fmu_paths()[name]
    _atomic_write(paths[2], _zip(files2))
    _atomic_write(paths[3], _zip(files3))
    if verbose:
        print(f"built {paths[2].relative_to(ROOT)} and {paths[3].relative_to(ROOT)} ({', '.join(platforms)})")
    return paths


def _stamp(model: FmuSource, platforms) -> str:
    """What a built FMU depends on: sources, declaration, platforms."""
    digest = hashlib.sha256(",".join(sorted(platforms)).encode())
    # this module, the toolchain's flags and the FMU tables are inputs too
    for path in (*LAYER, *model.c_sources, *model.c_headers, *model.sources, Path(__file__),
                 Path(c_toolchain.__file__), Path(fmu_catalog.__file__), Path(plant_registry.__file__)):
        digest.update(path.read_bytes())
    return digest.hexdigest()


def ensure_built(platforms=None, force: bool = False, verbose: bool = False, jobs: int = 2) -> dict[str, dict[int, Path]]:
    """Build the native FMUs whose inputs changed; return {model identifier: {2: path, 3: path}}.

    ``platforms`` defaults to $AFC_NATIVE_PLATFORMS (comma-separated) or all three.
    """
    if not compiler_available():
        raise NativeBuildError("the native edition needs zig's C compiler: pip install ziglang "
                               "(or pip install -e '.[native]')")
    if platforms is None:
        chosen = os.environ.get("AFC_NATIVE_PLATFORMS", "")
        platforms = tuple(p for p in chosen.split(",") if p) or PLATFORMS
    platforms = tuple(platforms)
    zig_version = None
    result = {}
    for model in models():
        paths = fmu_paths()[model.model_identifier]
        stamp_file = WORK_DIR / "stamps" / f"{model.model_identifier}.stamp"
        stamp = _stamp(model, platforms)
        fresh = (not force and all(p.exists() for p in paths.values()) and stamp_file.exists()
                 and stamp_file.read_text() == stamp)
        if not fresh:
            zig_version = zig_version or c_toolchain.zig_version()
            build_model(model, platforms, jobs=jobs, zig_version=zig_version, verbose=verbose)
            _atomic_write(stamp_file, stamp.encode())
        elif verbose:
            print(f"native: {model.model_identifier}: up to date", file=sys.stderr, flush=True)
        result[model.model_identifier] = paths
    return result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--targets", default=",".join(PLATFORMS),
                        help=f"comma-separated platforms among {', '.join(PLATFORMS)} (default: all)")
    parser.add_argument("--force", action="store_true", help="rebuild every native FMU")
    parser.add_argument("--jobs", type=int, default=2, help="parallel compilations (default 2)")
    args = parser.parse_args(argv)
    try:
        ensure_built(tuple(p for p in args.targets.split(",") if p), force=args.force, verbose=True, jobs=args.jobs)
    except NativeBuildError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
