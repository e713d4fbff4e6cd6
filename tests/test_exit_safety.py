"""A host process that used our pythonfmu FMUs exits without touching freed memory.

pythonfmu 0.7's library keeps a static ``std::shared_ptr`` (``pyState``); at process exit the
C++ runtime destroys it and then the library's ELF destructor (``finalizePythonInterpreter``)
releases it a second time, decrementing a count inside the freed block: depending on the heap
state at exit, glibc aborts with "corrupted double-linked list" (seen intermittently in
tests/test_life_cycle.py's 200-cycle subprocess and at the exit of ``python -m harness``).
``fmu_src/afc_slave_base.py`` releases it from a Python atexit handler instead (Linux).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the exit-time defect is Linux's")

HOST_SCRIPT = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    from tests.fmu_helpers import Driven

    for k, (path, unzip_dir) in enumerate(zip(sys.argv[2::2], sys.argv[3::2])):
        fmu = Driven(path, f"exit{k}", unzip_dir=unzip_dir).initialize()
        fmu.slave.doStep(0.0, 1e-3)
        fmu.free()
    import afc_slave_base
    print(len(afc_slave_base._pythonfmu_finalizers))
""")


def host_command(fmu_paths, tmp_path, fmu_ids):
    """A Python host that instantiates, steps and frees each FMU (its own extraction) once."""
    from fmpy import extract
    script = tmp_path / "host.py"
    script.write_text(HOST_SCRIPT)
    arguments = []
    for fmu_id in fmu_ids:
        arguments += [str(fmu_paths[fmu_id]), extract(str(fmu_paths[fmu_id]), str(tmp_path / fmu_id))]
    return [sys.executable, str(script), str(ROOT), *arguments]


def test_each_loaded_copy_of_the_pythonfmu_library_is_released_before_the_c_exit_handlers(fmu_paths, tmp_path):
    """Two FMUs, two copies of the library: one atexit release for each."""
    done = subprocess.run(host_command(fmu_paths, tmp_path, ("InvertedPendulum", "Manipulator")),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["2"], done.stdout


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_exit_touches_no_freed_memory_of_the_pythonfmu_library_under_valgrind(fmu_paths, tmp_path):
    """valgrind reports no invalid access in pythonfmu's exit path (before the fix: an invalid
    read in finalizePythonInterpreter of a block freed by __run_exit_handlers, every run)."""
    log = tmp_path / "valgrind.log"
    command = ["valgrind", f"--log-file={log}", *host_command(fmu_paths, tmp_path, ("InvertedPendulum",))]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONMALLOC": "malloc"})
    assert done.returncode == 0, done.stderr
    report = log.read_text()
    assert "ERROR SUMMARY" in report, report[-2000:]
    assert "finalizePythonInterpreter" not in report, report[report.find("finalizePythonInterpreter") - 3000:][:4000]
