"""The FMU archives: modelDescription.xml, the sources, one binary per platform folder (a fat
Mach-O for FMI 2.0's darwin64), the FMI-LS-REF files, zipped reproducibly and written atomically."""
from __future__ import annotations

import io
import struct
import sys
import zipfile
from pathlib import Path

from harness.fmu_build import catalog as fmu_catalog
from harness.fmu_build.native_stages import LAYER, ls_ref


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



def write_entries(archive: zipfile.ZipFile, files: dict[str, bytes]) -> None:
    """``files`` into ``archive`` in name order, with a fixed date and mode: the same bytes on every build."""
    for name in sorted(files):
        info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.external_attr = 0o644 << 16
        archive.writestr(info, files[name])


def zip_archive(files: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        write_entries(archive, files)
    return buffer.getvalue()


def embed_ls_ref(fmu: Path, model: str) -> None:
    """Append the FMI-LS-REF files (harness.fmu_build.native_stages.ls_ref) to a built FMU archive in place: the pythonfmu
    edition's build, whose archive comes from pythonfmu."""
    with zipfile.ZipFile(fmu) as archive:
        files = {name: archive.read(name) for name in archive.namelist() if not name.endswith("/")}
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as archive:
        write_entries(archive, ls_ref.ls_ref_files(ls_ref.load(model), files))


if __name__ == "__main__":  # python -m harness.fmu_build.native_stages.package FMU MODEL (build_fmu.py: in a fresh interpreter)
    embed_ls_ref(Path(sys.argv[1]), sys.argv[2])



def fmu_files(model: fmu_catalog.FmuSource, descriptions: dict[int, bytes], header: Path, binaries: dict,
              targets, generated: dict[int, dict[str, bytes]] | None = None) -> dict[int, dict[str, bytes]]:
    """{FMI version: {archive path: bytes}}: the description, the sources (the layer, the model's C
    files, its generated header), each target's binary (``binaries[(version, target)]``), the
    ``generated`` files of each version (harness.fmu_build.native_stages.sources: what compiles the sources) and, where
    the FMU runs on this machine, its FMI-LS-REF files."""
    name = model.model_identifier
    sources = {f"sources/{fmu_catalog.archive_name(p)}": p.read_bytes() for p in (*LAYER, *model.c_sources, *model.c_headers, header)}
    files = {version: {"modelDescription.xml": descriptions[version], **sources,
                       **(generated or {}).get(version, {})} for version in (2, 3)}
    darwin = [binaries[(2, t)].read_bytes() for t in targets if t.platform == "darwin64"]
    for target in targets:
        if target.platform != "darwin64":
            files[2][f"binaries/{target.platform}/{name}{target.extension}"] = binaries[(2, target)].read_bytes()
        files[3][f"binaries/{target.fmi3_folder}/{name}{target.extension}"] = binaries[(3, target)].read_bytes()
    if darwin:
        files[2][f"binaries/darwin64/{name}.dylib"] = fat_macho(darwin)
    stored = name in ls_ref.stored_models()  # not yet for a new FMU's first build (harness.fmu_build.builder.ls_ref_model)
    for version in (2, 3):  # FMI-LS-REF: the reference is this machine's run of the FMU (harness.fmu_build.native_stages.ls_ref)
        if stored and ls_ref.runs_here(files[version], version):
            files[version].update(ls_ref.ls_ref_files(ls_ref.load(name), files[version]))
    return files
