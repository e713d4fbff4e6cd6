"""Archives are unpacked bounded and inside their folder (harness/unpack.py), by our master, run-ssp and
fmpy's SSP path: a zip bomb, a symbolic link, an absolute or '..' path is one line naming the archive and
the entry (exit 2) before anything is unpacked, and nothing is left in the temporary folder.

The bombs are made in the test: a small archive whose entries declare gigabytes (their sizes patched in
the zip directory), and an honest one (zeros that compress a thousand times).
"""
from __future__ import annotations

import os
import stat
import struct
import tempfile
import zipfile
from pathlib import Path

import pytest

from harness import scenario as scenarios
from harness import unpack
from harness.cli import main as cli_main
from harness.fmi import FmuFileError, ModelInfo
from harness.hosts import engines
from harness.hosts.ssp import export_ssp

GiB = 1 << 30


@pytest.fixture
def temp_dir(tmp_path, monkeypatch):
    """An empty temporary folder of this test's own (Python's tempfile and TMPDIR)."""
    folder = tmp_path / "temp"
    folder.mkdir()
    monkeypatch.setenv("TMPDIR", str(folder))
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def copy_with(source: Path, target: Path, extra=()) -> Path:
    """The archive ``source`` with the entries ``extra`` ((ZipInfo or name, bytes)) added."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as new:
        for info in old.infolist():
            new.writestr(info, old.read(info))
        for info, data in extra:
            new.writestr(info, data, compress_type=zipfile.ZIP_DEFLATED)
    return target


def declare_size(path: Path, entry: str, size: int) -> Path:
    """Patch the zip directory of ``path`` so that ``entry`` declares ``size`` bytes unpacked (< 4 GiB): what a
    bomb's directory says, without writing the bytes."""
    data = bytearray(path.read_bytes())
    name = entry.encode()
    for signature, size_offset, name_offset in ((b"PK\x01\x02", 24, 46), (b"PK\x03\x04", 22, 30)):
        start = 0
        while (start := data.find(signature, start)) >= 0:
            if data[start + name_offset:start + name_offset + len(name)] == name:
                struct.pack_into("<I", data, start + size_offset, size)
            start += 4
    path.write_bytes(bytes(data))
    with zipfile.ZipFile(path) as archive:
        assert archive.getinfo(entry).file_size == size
    return path


def bomb_fmu(fmu_paths, tmp_path, declared: int = 3 * GiB) -> Path:
    """TrackingReference.fmu with one entry of 1 MiB of zeros that declares ``declared`` bytes."""
    folder = tmp_path / "bomb"
    folder.mkdir(exist_ok=True)
    target = copy_with(fmu_paths["TrackingReference"], folder / "TrackingReference.fmu",
                       [("resources/table.bin", bytes(1 << 20))])
    return declare_size(target, "resources/table.bin", declared)


def scenario_with(tmp_path, fmu: Path) -> Path:
    text = (scenarios.SCENARIO_DIR / "pendulum_case1.toml").read_text()
    path = tmp_path / "bomb_case.toml"
    path.write_text(text.replace('fmu = "TrackingReference"', f'fmu = "{fmu}"').replace("stop = 20.0", "stop = 0.01"))
    return path


def test_a_bomb_fmu_is_refused_before_anything_is_unpacked(fmu_paths, tmp_path, temp_dir, capsys):
    bomb = bomb_fmu(fmu_paths, tmp_path)
    assert bomb.stat().st_size < 2 * 1024 * 1024  # a small archive ...
    with pytest.raises(FmuFileError, match=r"TrackingReference.fmu: entry 'resources/table.bin' declares "
                                           r"3072.0 MiB unpacked; the limit is 1024.0 MiB per entry"):
        ModelInfo.read(bomb)  # ... refused before its model description is read
    assert cli_main(["run", str(scenario_with(tmp_path, bomb))]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("error: ") and "\n" not in error
    assert "TrackingReference.fmu: entry 'resources/table.bin' declares 3072.0 MiB" in error
    assert os.listdir(temp_dir) == []


def test_the_total_the_entries_and_the_ratio_are_each_bounded(fmu_paths, tmp_path, temp_dir):
    source = fmu_paths["TrackingReference"]
    many = copy_with(source, tmp_path / "many.fmu", [(f"resources/{k}.txt", b"x") for k in range(40)])
    with pytest.raises(unpack.ArchiveError, match=r"many.fmu: \d+ entries; the limit is 30"):
        unpack.check_archive(many, unpack.Limits(entries=30))
    two = copy_with(source, tmp_path / "two.fmu", [("resources/a.bin", bytes(1000)), ("resources/b.bin", bytes(1000))])
    declare_size(declare_size(two, "resources/a.bin", 700 * 1024 * 1024), "resources/b.bin", 700 * 1024 * 1024)
    with pytest.raises(unpack.ArchiveError, match=r"two.fmu declares 14\d\d.\d MiB unpacked in all; the limit is "
                                                  r"1024.0 MiB \(\$AFC_UNPACK_LIMIT_MB raises it\)"):
        unpack.check_archive(two, unpack.Limits(total_bytes=GiB, entry_bytes=GiB, ratio=1e12))
    zeros = copy_with(source, tmp_path / "zeros.fmu", [("resources/zeros.bin", bytes(64 << 20))])
    assert zeros.stat().st_size < (1 << 20)  # an honest bomb: 64 MiB that compress a thousand times
    with pytest.raises(unpack.ArchiveError, match=r"zeros.fmu: entry 'resources/zeros.bin' expands \d+ times "
                                                  r"\(.* to 64.0 MiB\); the limit is 200 times"):
        unpack.check_archive(zeros)
    assert unpack.check_archive(zeros, unpack.Limits(ratio=1e6)) > 64 << 20  # a ratio allowed: it passes


def test_the_limit_variable_raises_the_limits_and_a_bad_value_is_refused(fmu_paths, tmp_path, monkeypatch):
    bomb = bomb_fmu(fmu_paths, tmp_path, declared=1536 * 1024 * 1024)
    with pytest.raises(unpack.ArchiveError, match="per entry"):
        unpack.check_archive(bomb)
    monkeypatch.setenv("AFC_UNPACK_LIMIT_MB", "4096")
    with pytest.raises(unpack.ArchiveError, match="expands"):  # the size allowed, the ratio still not
        unpack.check_archive(bomb)
    monkeypatch.setenv("AFC_UNPACK_LIMIT_MB", "lots")
    with pytest.raises(unpack.ArchiveError, match=r"AFC_UNPACK_LIMIT_MB='lots': give a number of MiB > 0"):
        unpack.check_archive(bomb)


def link_entry(name: str, target: str):
    info = zipfile.ZipInfo(name)
    info.create_system = 3  # unix: the mode bits below are read
    info.external_attr = (stat.S_IFLNK | 0o777) << 16
    return info, target.encode()


@pytest.mark.parametrize("entry,data,expected", [
    (*link_entry("resources/passwd", "../../../../etc/passwd"),
     "entry 'resources/passwd' is a symbolic link (refused: it could point outside the folder)"),
    ("resources/../../escaped.txt", b"x", "entry 'resources/../../escaped.txt' has a '..' component (refused: it would land outside the folder)"),
    ("/tmp/absolute.txt", b"x", "entry '/tmp/absolute.txt' is an absolute path (refused: it would land outside the "
                                 "folder)"),
    ("C:/windows.txt", b"x", "entry 'C:/windows.txt' is an absolute path (refused: it would land outside the folder)"),
], ids=["symlink", "dot-dot", "absolute", "drive"])
def test_links_and_paths_leaving_the_folder_are_refused_naming_the_entry(fmu_paths, tmp_path, temp_dir, entry, data,
                                                                         expected):
    fmu = copy_with(fmu_paths["TrackingReference"], tmp_path / "TrackingReference.fmu", [(entry, data)])
    with pytest.raises(unpack.ArchiveError) as refused:
        unpack.extract_archive(fmu, tmp_path / "out")
    assert str(refused.value) == f"{fmu}: {expected}"
    with pytest.raises(FmuFileError) as refused_by_the_master:
        ModelInfo.read(fmu)  # what the master reads first
    assert str(refused_by_the_master.value) == f"{fmu}: {expected}"
    assert os.listdir(temp_dir) == [] and not (tmp_path / "escaped.txt").exists()


def test_an_archive_that_lies_about_its_sizes_unpacks_no_more_and_leaves_nothing(fmu_paths, tmp_path, temp_dir):
    """Declared 10 bytes, holding 1 MiB: zipfile reads no more than declared and its CRC check fails; what
    was unpacked before is removed."""
    liar = copy_with(fmu_paths["TrackingReference"], tmp_path / "liar.fmu", [("resources/zz_liar.bin", bytes(1 << 20))])
    declare_size(liar, "resources/zz_liar.bin", 10)
    folder = tmp_path / "out"
    folder.mkdir()
    with pytest.raises(unpack.ArchiveError, match=r"liar.fmu could not be unpacked into .*out: Bad CRC-32"):
        unpack.extract_archive(liar, folder)
    assert list(folder.iterdir()) == []


@pytest.fixture
def package(fmu_paths, tmp_path):
    return export_ssp(scenarios.configure("pendulum_case1", "vud", stop=0.01), tmp_path / "case.ssp",
                      fmu_paths=fmu_paths)


def test_run_ssp_refuses_a_bomb_fmu_inside_the_package_before_fmpy_unpacks_it(package, fmu_paths, tmp_path, temp_dir,
                                                                              capsys):
    with zipfile.ZipFile(package) as archive:
        source = next(name for name in archive.namelist() if name.endswith("TrackingReference.fmu"))
    bomb = bomb_fmu(fmu_paths, tmp_path)
    bombed = tmp_path / "bombed.ssp"
    with zipfile.ZipFile(package) as old, zipfile.ZipFile(bombed, "w", zipfile.ZIP_STORED) as new:
        for info in old.infolist():
            new.writestr(info, bomb.read_bytes() if info.filename == source else old.read(info))
    for engine in ("fmpy", "ecos"):
        assert cli_main(["run-ssp", str(bombed), "--engine", engine]) == 2
        error = capsys.readouterr().err.strip()
        assert error == (f"error: {bombed}: {source}: entry 'resources/table.bin' declares 3072.0 MiB unpacked; the "
                         "limit is 1024.0 MiB per entry ($AFC_UNPACK_LIMIT_MB raises it)")
    assert os.listdir(temp_dir) == []


def test_fmpys_ssp_path_leaves_nothing_when_a_run_fails(package, tmp_path, temp_dir):
    """fmpy's simulate_ssp unpacks the package and every FMU into folders of its own and removes none when an
    FMU fails: the adapter gives it a private temporary folder."""
    broken = tmp_path / "broken.ssp"
    with zipfile.ZipFile(package) as old, zipfile.ZipFile(broken, "w") as new:
        for info in old.infolist():
            data = old.read(info)
            if info.filename.endswith("InvertedPendulum.fmu"):  # its shared library gone: instantiation fails
                data = _without_binaries(data, tmp_path)
            new.writestr(info, data)
    with pytest.raises(Exception):
        engines.run_fmpy_ssp(broken)
    assert os.listdir(temp_dir) == []
    assert os.environ["TMPDIR"] == str(temp_dir) and tempfile.gettempdir() == str(temp_dir)


def _without_binaries(fmu: bytes, tmp_path) -> bytes:
    source, target = tmp_path / "with.fmu", tmp_path / "without.fmu"
    source.write_bytes(fmu)
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for info in old.infolist():
            if not info.filename.startswith("binaries/"):
                new.writestr(info, old.read(info))
    return target.read_bytes()


def test_the_unpack_folder_is_removed_at_exit_and_a_dead_processes_folder_by_the_next(tmp_path, temp_dir):
    import subprocess
    import sys

    script = ("from harness import unpack; import os; folder = unpack.unpack_folder('probe'); "
              "(folder / 'x').write_text('x'); print(folder)")
    environment = dict(os.environ, TMPDIR=str(temp_dir))
    completed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=environment,
                               check=True, cwd=Path(__file__).resolve().parents[1])
    made = Path(completed.stdout.strip())
    assert made.parent == temp_dir and made.name.startswith("afc-") and not made.exists()  # removed at exit
    killed = subprocess.run([sys.executable, "-c", script.replace("print(folder)", "print(folder); os._exit(9)")],
                            capture_output=True, text=True, env=environment, cwd=Path(__file__).resolve().parents[1])
    left = Path(killed.stdout.strip())
    assert left.exists()  # a killed process removes nothing ...
    unpack.remove_dead_folders()  # what the next process's first unpack folder does
    assert not left.exists()


def test_docs_master_quotes_the_limits():
    text = " ".join((Path(__file__).resolve().parents[1] / "docs" / "master.md").read_text().split())
    limits = unpack.Limits()
    assert (f"at most {limits.entries} entries, {limits.entry_bytes >> 30} GiB declared per entry and "
            f"{limits.total_bytes >> 30} GiB in all") in text
    assert f"more than {unpack.RATIO_FROM_BYTES >> 20} MiB expanding at most {limits.ratio:g} times" in text
    assert unpack.LIMIT_VARIABLE in text and unpack.UNPACK_DIR_VARIABLE in text
