"""Build the native edition of the FMUs: the same four models in C, FMI 2.0 and FMI 3.0.

    python build_fmu.py --edition native            # via the project's build script
    python build_native.py [--targets linux64,win64,darwin64] [--force]

From each FMU's declaration table (the ``VARIABLES`` of its pythonfmu class) this
module generates

* the FMI 2.0 modelDescription.xml: pythonfmu's own ``to_xml`` of the class (the very
  description of the pythonfmu edition), with the native FMU's GUID and capabilities;
* the FMI 3.0 modelDescription.xml, translated from that FMI 2.0 description (names,
  value references, causality, variability, start, units, min/max, output
  dependencies, DefaultExperiment);
* ``model_variables.h``: the variable table for the C layer (value references, names,
  starts, valid ranges and their wording), so the validation messages are the Python
  edition's;

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
    return root


def fmi3_description(fmi2_root: ET.Element) -> ET.Element:
    """The FMI 3.0 description translated from the FMI 2.0 one (same variables)."""
    attributes = {k: v for k, v in fmi2_root.attrib.items()
                  if k in ("modelName", "description", "author", "version", "generationTool")}
    root = ET.Element("fmiModelDescription", fmiVersion="3.0",
                      instantiationToken=fmi2_root.get("guid"), variableNamingConvention="structured",
                      **attributes)
    cosim2 = fmi2_root.find("CoSimulation")
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
    references = {}
    for index, scalar in enumerate(fmi2_root.find("ModelVariables"), start=1):
        typed = scalar[0]
        kind = {"Real": "Float64", "Integer": "Int32"}[typed.tag]
        element = ET.SubElement(variables, kind, name=scalar.get("name"),
                                valueReference=scalar.get("valueReference"))
        for key in ("description", "causality", "variability", "initial"):
            if scalar.get(key) is not None:
                element.set(key, scalar.get(key))
        for key in ("start", "unit", "min", "max"):
            if typed.get(key) is not None:
                element.set(key, typed.get(key))
        references[str(index)] = scalar.get("valueReference")
    # FMI 3.0 requires the independent variable; it takes the value reference after the table's
    time_reference = str(len(references))
    ET.SubElement(variables, "Float64", name="time", valueReference=time_reference, causality="independent",
                  variability="continuous", description="simulation time")
    structure = ET.SubElement(root, "ModelStructure")
    structure2 = fmi2_root.find("ModelStructure")
    outputs = structure2.find("Outputs")
    for unknown in (outputs if outputs is not None else ()):
        dependencies = (unknown.get("dependencies") or "").split()
        ET.SubElement(structure, "Output", valueReference=references[unknown.get("index")],
                      dependencies=" ".join(references[i] for i in dependencies))
    initial = structure2.find("InitialUnknowns")
    for unknown in (initial if initial is not None else ()):
        ET.SubElement(structure, "InitialUnknown", valueReference=references[unknown.get("index")])
    return root


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
    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        binaries = dict(zip(jobs_list, pool.map(
            lambda job: _compile(model, header_dir, job[0], job[1], zig_version), jobs_list)))
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
