"""Every output is written whole or not at all (harness/atomic_files.py): on a full disk the previous file is
intact, no partial file is left, and the error is one line naming the file.

The full disk is a file-size limit (``RLIMIT_FSIZE``): in a subprocess for ``run --out`` and ``export-ssp
--out``, around the call for ``regress --update``'s pair of reference files and the reports.  Python
ignores SIGXFSZ, so a write past the limit fails with EFBIG ("File too large") as on a full disk (ENOSPC).
"""
from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from harness import atomic_files
from harness.studies import regression
from harness.studies.regression import Case, CaseRun

resource = pytest.importorskip("resource")  # POSIX only (RLIMIT_FSIZE)
ROOT = Path(__file__).resolve().parents[1]
#: larger than any file a run writes before its output (the FMUs' binaries it unpacks, ~350 kB), smaller than
#: the outputs below
SUBPROCESS_LIMIT = 700 * 1024


def left_over(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(atomic_files.PARTIAL_SUFFIX))


def limited_run(arguments, limit: int, cwd: Path):
    """``python -m harness ARGUMENTS`` with a file-size limit of ``limit`` bytes."""
    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    environment = dict(os.environ, AFC_MASTER_LOOP="python", PYTHONDONTWRITEBYTECODE="1")
    return subprocess.run([sys.executable, "-m", "harness", *arguments], capture_output=True, text=True, cwd=cwd,
                          env=environment, preexec_fn=limit_file_size, timeout=600)


@contextlib.contextmanager
def file_size_limit(limit: int):
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))


def test_a_failing_writer_leaves_the_previous_file_and_no_partial_one(tmp_path):
    target = tmp_path / "table.csv"
    target.write_text("previous\n")
    with pytest.raises(ZeroDivisionError):
        with atomic_files.replacing(target) as stream:
            stream.write("half of a new ")
            1 / 0
    assert target.read_text() == "previous\n" and left_over(tmp_path) == []
    atomic_files.write_text(target, "new\n")
    assert target.read_text() == "new\n" and oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    with pytest.raises(atomic_files.OutputError, match=r"cannot write .*table.csv/x.csv: .*; no file was written"):
        atomic_files.write_text(target / "x.csv", "a file is not a folder")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_run_out_on_a_full_disk_keeps_the_previous_csv_and_names_it(fmu_paths, tmp_path):
    out = tmp_path / "run.csv"
    out.write_text("the previous result\n")
    completed = limited_run(["run", "pendulum_case1", "--stop", "2", "--out", str(out)], SUBPROCESS_LIMIT, tmp_path)
    error = completed.stderr.strip().splitlines()
    assert completed.returncode == 1, completed.stderr
    assert error[-1] == f"error: cannot write {out}: File too large; the previous file is unchanged"
    assert out.read_text() == "the previous result\n" and left_over(tmp_path) == []
    fine = limited_run(["run", "pendulum_case1", "--stop", "0.5", "--out", str(out)], SUBPROCESS_LIMIT, tmp_path)
    assert fine.returncode == 0, fine.stderr  # under the limit: written whole
    assert out.read_text().startswith('"time","plant.y"') and len(out.read_text().splitlines()) == 1 + 1001


def test_export_ssp_out_on_a_full_disk_keeps_the_previous_package(fmu_paths, tmp_path):
    out = tmp_path / "case.ssp"
    out.write_bytes(b"the previous package")
    completed = limited_run(["export-ssp", "pendulum_case1", "--stop", "0.1", "--out", str(out)], SUBPROCESS_LIMIT,
                            tmp_path)
    assert completed.returncode == 1, completed.stderr
    assert completed.stderr.strip().splitlines()[-1] == \
        f"error: cannot write {out}: File too large; the previous file is unchanged"
    assert out.read_bytes() == b"the previous package" and left_over(tmp_path) == []


def fabricated_run(scale: float = 1.0, scaled=None) -> CaseRun:
    """A run made from the committed reference, its signals (or those of ``scaled``) scaled: no simulation."""
    case = Case("pendulum_case1", "vud")
    reference = regression.read_reference(case)
    return CaseRun(case, reference.meta["start"], reference.meta["stop"], reference.meta["step"],
                   reference.time.copy(), {k: v * (scale if scaled is None or k in scaled else 1.0)
                                           for k, v in reference.signals.items()}, 0.0)


def test_regress_update_on_a_full_disk_keeps_both_reference_files(tmp_path):
    folder = tmp_path / "references"
    first = regression.regress([Case("pendulum_case1", "vud")], runs=[fabricated_run()], reference_dir=folder,
                               update=True, report_dir=None)
    csv_path, json_path = first.written
    before = (csv_path.read_bytes(), json_path.read_bytes())
    assert csv_path.stat().st_size > 100_000 > json_path.stat().st_size
    changed = fabricated_run(1.5)
    with file_size_limit(50_000), pytest.raises(atomic_files.OutputError) as failed:  # what --update writes
        regression.write_reference(changed, folder, previous=regression.read_reference(changed.case, folder).meta)
    assert str(failed.value) == f"cannot write {csv_path}: File too large; the previous file is unchanged"
    assert (csv_path.read_bytes(), json_path.read_bytes()) == before  # the pair: neither file replaced
    assert left_over(folder) == []


def test_the_reports_on_a_full_disk_keep_the_previous_ones(tmp_path):
    report = tmp_path / "report"
    runs = [fabricated_run(1.01, scaled=("plant.y",))]  # one failing signal: its figure
    regression.regress([Case("pendulum_case1", "vud")], runs=runs, report_dir=report, junit=tmp_path / "junit.xml")
    before = {path.name: path.read_bytes() for path in report.iterdir()}
    assert "report.md" in before and any(name.endswith(".png") for name in before)
    again = regression.regress([Case("pendulum_case1", "vud")], runs=runs, report_dir=None)
    references = [regression.read_reference(run.case) for run in runs]
    with file_size_limit(4_000), pytest.raises(atomic_files.OutputError, match=r"cannot write .*report.*: File too "
                                                                                 r"large; the previous file is "
                                                                                 r"unchanged"):
        regression.report.write_report(again.comparisons, runs, references, report, {})
    after = {path.name: path.read_bytes() for path in report.iterdir() if path.name in before}
    assert all(after[name] == before[name] for name in after) and left_over(report) == []
