"""Determinism: the same run gives the same bytes in two processes and in this one."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from harness.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
CLI_TIMEOUT_S = 60


# ------------------------------------------------------------------ determinism
def test_two_runs_give_bit_identical_csvs(fmu_paths, tmp_path):
    """Two processes (different hash seeds) and one in-process run write the same bytes."""
    command = ["run", "manipulator", "--controller", "fae", "--step", "0.001", "--stop", "1.0"]
    processes = []
    for seed in ("1", "2"):
        out = tmp_path / f"run{seed}.csv"
        processes.append((out, subprocess.Popen([sys.executable, "-m", "harness", *command, "--out", str(out)],
                                                cwd=ROOT, env=dict(os.environ, PYTHONHASHSEED=seed),
                                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)))
    assert cli_main([*command, "--out", str(tmp_path / "in_process.csv")]) == 0
    for out, process in processes:
        _, stderr = process.communicate(timeout=CLI_TIMEOUT_S)
        assert process.returncode == 0, stderr
    first = (tmp_path / "run1.csv").read_bytes()
    assert len(first.splitlines()) == 1002
    assert (tmp_path / "run2.csv").read_bytes() == first
    assert (tmp_path / "in_process.csv").read_bytes() == first


